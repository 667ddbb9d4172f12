"""Converged 2D plane-strain reference for the finite-geometry Hertz line-contact problem.

Problem (x horizontal, z vertical, m / Pa). Body A, the lower half disc
{x^2 + (z-R)^2 <= R^2, z <= R}, touches z = 0 at x = 0; its flat face z = R is moved by
(u_x, u_z) = (0, -delta). Body B, the block [-W, W] x [-D, 0], is clamped at z = -D; its sides
and top are free. Both: linear elastic, small strain, plane strain, E = 1e7, nu = 0.3.
Frictionless contact between A's arc and B's top, with the gap measured in the DEFORMED
configuration as the VERTICAL distance of a point of A's arc above B's deformed top at the same
current x. Symmetry about x = 0 is used: only x >= 0 is modelled, with u_x = 0 on x = 0 in
both bodies; forces are doubled when reported.

Method. Biquadratic 9-node quadrilaterals on 2:1-balanced quadtree meshes built in a reference
rectangle and mapped exactly: B is the identity map; A uses polar coordinates (s, rho) ->
((R-rho) sin(s/R), R - (R-rho) cos(s/R)), s in [0, pi R/2], rho in [0, R] (the edge rho = R
collapses to the centre of the flat face), so the arc is represented exactly (no sagitta
error) and elements are evaluated with the exact map. Hanging nodes are tied conformingly.
Element size is h_c on the contact zone and grows as h_c + g*dist away from it (g = 0.3 on
level 0); level k is level 0 with every element split k times, so h_c and g halve together
(a nested sequence, as Richardson extrapolation wants). Contact: standard quadratic mortar,
A's arc is the slave, multiplier p_h = sum_i p_i N_i (nodal vertical pressures, Pa) and
weighted gaps g_i = int N_i g dx (Gauss points on the slave projected vertically onto B).
The constraint is enforced exactly by Lagrange multipliers: a primal-dual active-set
(semi-smooth Newton) loop that re-linearises the deformed geometry every iteration and stops
when the active set is unchanged and the displacement update is < 1e-11 delta. Each iteration
solves the saddle-point system with scipy's sparse LU. A coarse pilot solve fixes the contact
zone that the meshes refine (1.3 times the pilot's half-width).

Output per mesh: unknowns, contact load P (N/m, full width), a_edge (where p^2, linear in x
near a square-root edge, extrapolated from the last two contact nodes reaches 0, clamped to the
interval up to the first open node), a_moment = 2 sqrt(int p x^2 / int p), p_max = p(0), the
same over Hertz at the measured P (E* = E/(2(1-nu^2)), a_H = sqrt(4PR/(pi E*)),
p0_H = 2P/(pi a_H)), the equilibrium check and the wall time; then Richardson extrapolation
(with observed order) from the last three meshes.

Usage: python3 benchmarks/hertz_reference.py [--R 1] [--delta 0.05] [--width 1] [--depth 1]
       [--levels 4] [--h-contact H] [--pressure-out FILE.csv]
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, gmres, splu

E_MOD, NU, GRADE0 = 1.0e7, 0.3, 0.3
Arr = np.ndarray


def lag2(t: Arr) -> tuple[Arr, Arr]:
    """1D quadratic Lagrange basis on nodes -1, 0, 1 and its derivative; shape (..., 3)."""
    t = np.asarray(t, float)
    return (np.stack([0.5 * t * (t - 1), 1 - t * t, 0.5 * t * (t + 1)], -1),
            np.stack([t - 0.5, -2 * t, t + 0.5], -1))


def quadtree(n0: Arr, lo: Arr, hi: Arr, h_c: float, grade: float, zone: float, top: bool) -> Arr:
    """Leaves (level, i, j), size <= h_c + grade*dist to the segment [0, zone] on the bottom
    (top=False) or top edge of the reference box, then 2:1-balanced across edges."""
    s0 = (hi - lo) / n0
    ii, jj = np.meshgrid(np.arange(n0[0]), np.arange(n0[1]), indexing="ij")
    cells, out = np.stack([0 * ii.ravel(), ii.ravel(), jj.ravel()], 1), []
    while len(cells):
        sz = s0[None, :] / 2.0 ** cells[:, :1]
        c0 = lo + cells[:, 1:] * sz
        e = hi[1] if top else lo[1]
        dy = np.maximum(0.0, np.maximum(c0[:, 1] - e, e - c0[:, 1] - sz[:, 1]))
        need = sz.max(1) > h_c + grade * np.hypot(np.maximum(0.0, c0[:, 0] - zone), dy)
        out.append(cells[~need])
        c = cells[need]
        cells = np.concatenate([np.stack([c[:, 0] + 1, 2 * c[:, 1] + a, 2 * c[:, 2] + b], 1)
                                for a in (0, 1) for b in (0, 1)])
    leaves, changed = set(map(tuple, np.concatenate(out).tolist())), True
    while changed:
        changed = False
        for (lv, i, j) in list(leaves):
            if (lv, i, j) not in leaves:
                continue
            for a, b in ((i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)):
                if not (0 <= a < n0[0] << lv and 0 <= b < n0[1] << lv):
                    continue
                for m in range(lv, -1, -1):
                    key = (m, a >> (lv - m), b >> (lv - m))
                    if key in leaves:
                        if m <= lv - 2:
                            leaves.remove(key)
                            leaves.update((m + 1, 2 * key[1] + p, 2 * key[2] + q)
                                          for p in (0, 1) for q in (0, 1))
                            changed = True
                        break
    return np.array(sorted(leaves))


def split(leaves: Arr, k: int) -> Arr:
    """Every leaf split k times (nested refinement; preserves the 2:1 balance)."""
    f = 1 << k
    a, b = [x.ravel() for x in np.meshgrid(np.arange(f), np.arange(f), indexing="ij")]
    lv, i, j = (x[:, None] for x in leaves.T)
    return np.stack([(lv + k + 0 * a).ravel(), (i * f + a).ravel(), (j * f + b).ravel()], 1)


@dataclass
class Body:
    X: Arr            # (n, 2) physical node coordinates
    K: sp.csr_matrix  # stiffness on independent dofs (hanging nodes eliminated)
    T: sp.csr_matrix  # full dofs <- independent dofs
    pres: Arr         # (n_ind,) bool, prescribed independent dof
    upres: Arr        # (n_ind,) prescribed values (0 where free)
    surf: Arr         # (m, 3) surface-edge nodes, ordered along the edge
    srng: Arr         # (m, 2) reference parameter range of each surface edge
    leaves: Arr       # (ne, 3) quadtree leaves (level, i, j) = elements
    el: Arr           # (ne, 9) element nodes
    ind: Arr          # independent (non-hanging) nodes, in dof order


def prolong(old: Body, uold: Arr, new: Body) -> Arr:
    """Nodal values on `new` (old mesh split once) of the Q9 field uold (n_old, 2) of `old`."""
    code = lambda L: (L[:, 0] << 42) | (L[:, 1] << 21) | L[:, 2]  # noqa: E731
    oc = code(old.leaves)
    srt = np.argsort(oc)
    pe = srt[np.searchsorted(oc[srt], code(np.c_[new.leaves[:, 0] - 1, new.leaves[:, 1:] >> 1]))]
    la, lb = np.array([0, 1, 2] * 3), np.repeat([0, 1, 2], 3)
    nx = lag2(-1 + (new.leaves[:, 1:2] & 1) + la / 2)[0]
    ny = lag2(-1 + (new.leaves[:, 2:3] & 1) + lb / 2)[0]
    u = np.zeros((len(new.X), 2))
    u[new.el] = np.einsum("enp,epc->enc", nx[..., la] * ny[..., lb], uold[old.el[pe]])
    return u


def make_body(leaves: Arr, n0: Arr, lo: Arr, hi: Arr, R: float, polar: bool, delta: float) -> Body:
    lv, ci, cj = leaves.T
    Lm = int(lv.max()) + 1
    NJ = 2 * n0[1] * (1 << Lm) + 1
    f = 1 << (Lm - lv)
    la, lb = np.array([0, 1, 2] * 3), np.repeat([0, 1, 2], 3)
    I, J = (2 * ci[:, None] + la) * f[:, None], (2 * cj[:, None] + lb) * f[:, None]
    raw = np.unique(I * NJ + J)
    # hanging nodes: quarter points of a leaf edge that exist as nodes of finer neighbours
    hk, mk, cf = [], [], []
    fq, c = f // 2, lv < Lm
    w13 = np.array([[0.375, 0.75, -0.125], [-0.125, 0.75, 0.375]])
    for side in range(4):
        if side < 2:   # edges along the first axis (bottom, top)
            jj = ((2 * cj + 2 * side) * f)[c]
            ends = [((2 * ci + t) * f)[c] * NJ + jj for t in (0, 1, 2)]
            qs = [((4 * ci + q) * fq)[c] * NJ + jj for q in (1, 3)]
        else:
            ii = ((2 * ci + 2 * (side - 2)) * f)[c]
            ends = [ii * NJ + ((2 * cj + t) * f)[c] for t in (0, 1, 2)]
            qs = [ii * NJ + ((4 * cj + q) * fq)[c] for q in (1, 3)]
        for q in range(2):
            ok = np.isin(qs[q], raw)
            hk.append(qs[q][ok])
            mk.append(np.stack([e[ok] for e in ends], 1))
            cf.append(np.tile(w13[q], (ok.sum(), 1)))
    hk, first = np.unique(np.concatenate(hk), return_index=True)
    mk, cf = np.concatenate(mk)[first], np.concatenate(cf)[first]
    canon = np.where((raw % NJ == NJ - 1) & polar, NJ - 1, raw)   # collapse rho = R in A
    keys = np.unique(canon)
    nid = np.searchsorted(keys, canon)   # raw index -> node id
    node = lambda k: nid[np.searchsorted(raw, k)]  # noqa: E731
    n = len(keys)
    Cn = sp.coo_matrix((np.r_[cf.ravel(), np.ones(n)],
                        (np.r_[np.repeat(node(hk), 3), np.arange(n)], np.r_[node(mk).ravel(), np.arange(n)])),
                       shape=(n, n)).tocsr()
    hang = np.zeros(n, bool)
    hang[node(hk)] = True
    Cn = Cn - sp.diags(hang.astype(float)) @ sp.diags(Cn.diagonal())
    while abs(Cn[:, np.flatnonzero(hang)]).sum() > 0:
        Cn = (Cn @ Cn).tocsr()
        Cn.eliminate_zeros()
    Tn = Cn[:, np.flatnonzero(~hang)]
    Tn.data[abs(Tn.data) < 1e-14] = 0.0
    T = sp.kron(Tn, sp.eye(2)).tocsr()
    unit = (hi - lo) / (2 * n0 * (1 << Lm))
    KI, KJ = keys // NJ, keys % NJ
    ref = lo + np.stack([KI, KJ], 1) * unit

    def phi(q: Arr) -> tuple[Arr, Arr]:   # physical points and d(x,z)/d(s,rho)
        if not polar:
            return q.copy(), np.broadcast_to(np.eye(2), q.shape[:-1] + (2, 2))
        th, r = q[..., 0] / R, R - q[..., 1]
        Jm = np.stack([np.stack([r / R * np.cos(th), -np.sin(th)], -1),
                       np.stack([r / R * np.sin(th), np.cos(th)], -1)], -2)
        return np.stack([r * np.sin(th), R - r * np.cos(th)], -1), Jm

    X = phi(ref)[0]
    el = nid[np.searchsorted(raw, I * NJ + J)]
    c0, sz = lo + np.stack([ci, cj], 1) * ((hi - lo) / n0) / 2.0 ** lv[:, None], (hi - lo) / n0 / 2.0 ** lv[:, None]
    lam, mu = E_MOD * NU / ((1 + NU) * (1 - 2 * NU)), E_MOD / (2 * (1 + NU))
    Dm = np.array([[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]])
    gp, gw = np.polynomial.legendre.leggauss(3)
    Ke = np.zeros((len(el), 18, 18))
    for xa, wa in zip(gp, gw):
        for xb, wb in zip(gp, gw):
            (Na, dNa), (Nb, dNb) = lag2(xa), lag2(xb)
            dref = np.stack([dNa[la] * Nb[lb], Na[la] * dNb[lb]], 1)   # (9, 2)
            _, Jp = phi(c0 + sz * (np.array([xa, xb]) + 1) / 2)
            Jt = Jp * (sz / 2)[:, None, :]
            g = np.einsum("ak,ekl->eal", dref, np.linalg.inv(Jt))
            B = np.zeros((len(el), 3, 18))
            B[:, 0, 0::2], B[:, 1, 1::2] = g[..., 0], g[..., 1]
            B[:, 2, 0::2], B[:, 2, 1::2] = g[..., 1], g[..., 0]
            Ke += (wa * wb * np.linalg.det(Jt))[:, None, None] * (B.transpose(0, 2, 1) @ (Dm @ B))
    dof = (2 * el[:, :, None] + np.arange(2)).reshape(len(el), 18)
    K = sp.coo_matrix((Ke.ravel(), (np.repeat(dof, 18, 1).ravel(), np.tile(dof, 18).ravel())),
                      shape=(2 * n, 2 * n)).tocsr()
    ind = np.flatnonzero(~hang)
    ux0, xmax, zz = KI[ind] == 0, KI[ind] == KI.max(), KJ[ind]
    pz = (xmax | (zz == NJ - 1)) if polar else zz == 0      # A: flat face (+ centre), B: bottom
    pres = np.stack([ux0 | pz, pz], 1).ravel()
    upres = np.stack([0.0 * pz, (-delta if polar else 0.0) * pz], 1).ravel()
    row = cj == (0 if polar else (n0[1] << lv) - 1)          # leaves on the contact edge
    loc = [0, 1, 2] if polar else [6, 7, 8]
    order = np.argsort(ci[row] * f[row])
    s_lo = lo[0] + ci[row] * sz[row, 0]
    return Body(X, (T.T @ K @ T).tocsr(), T, pres, upres, el[row][:, loc][order],
                np.stack([s_lo, s_lo + sz[row, 0]], 1)[order], leaves, el, ind)


def contact(A: Body, B: Body, uA: Arr, uB: Arr, R: float, xmax: float, ng: int = 8):
    """Weighted vertical gaps, their linearisation (rows: slave nodes) and integration data."""
    keep = R * np.sin(A.srng[:, 1] / R) <= xmax
    sl, sr = A.surf[keep], A.srng[keep]
    nodes = np.unique(sl)
    ci = np.searchsorted(nodes, sl)
    t, w = np.polynomial.legendre.leggauss(ng)
    N, dN = lag2(t)
    s = sr[:, :1] + (t + 1) / 2 * (sr[:, 1:] - sr[:, :1])
    xA = R * np.sin(s / R) + uA[sl, 0] @ N.T
    zA = R * (1 - np.cos(s / R)) + uA[sl, 1] @ N.T
    jac = np.cos(s / R) * (sr[:, 1:] - sr[:, :1]) / 2 + uA[sl, 0] @ dN.T
    ms, mr = B.surf, B.srng
    x0 = mr[:, 0] + uB[ms[:, 0], 0]
    e = np.clip(np.searchsorted(x0, xA, "right") - 1, 0, len(ms) - 1)
    valid = (xA >= x0[0]) & (xA <= mr[-1, 1] + uB[ms[-1, 2], 0])
    hm, ubx, ubz = (mr[:, 1] - mr[:, 0])[e], uB[ms[e], 0], uB[ms[e], 1]
    eta = np.zeros_like(xA)
    for _ in range(10):
        Nm, dNm = lag2(eta)
        dxe = hm / 2 + (dNm * ubx).sum(-1)
        eta = eta - (mr[e, 0] + (eta + 1) * hm / 2 + (Nm * ubx).sum(-1) - xA) / dxe
    Nm, dNm = lag2(eta)
    dxe = hm / 2 + (dNm * ubx).sum(-1)
    slope = (dNm * ubz).sum(-1) / dxe
    gap = zA - (Nm * ubz).sum(-1)
    fac = N[None, :, :] * (w * jac * valid)[..., None]          # (m, ng, 3): N_i w dx
    gt = np.bincount(ci.ravel(), (fac * gap[..., None]).sum(1).ravel(), len(nodes))
    nc, rows = len(nodes), np.broadcast_to(ci[:, None, :, None], fac.shape + (3,))
    fA = fac[..., None] * N[None, :, None, :]                    # (m, ng, i, j)
    fB = fac[..., None] * Nm[:, :, None, :]
    colA, colB = np.broadcast_to(sl[:, None, None, :], fA.shape), np.broadcast_to(ms[e][:, :, None, :], fB.shape)
    sl4 = slope[..., None, None]

    def mat(f: Arr, col: Arr, sgn: float, n: int) -> sp.csr_matrix:
        v = np.r_[(sgn * f).ravel(), (-sgn * f * sl4).ravel()]
        return sp.coo_matrix((v, (np.r_[rows.ravel(), rows.ravel()],
                                  np.r_[2 * col.ravel() + 1, 2 * col.ravel()])), shape=(nc, 2 * n)).tocsr()

    GA, GB = mat(fA, colA, 1.0, len(uA)), mat(fB, colB, -1.0, len(uB))
    return gt, GA, GB, nodes, (sl, ci, N, xA, w * jac * valid)


def solve_level(A: Body, B: Body, R: float, delta: float, xmax: float, active0: float, u0=None):
    """Active-set / geometry iteration; returns results dict."""
    fA, fB = ~A.pres, ~B.pres
    nA = fA.sum()
    Kff = sp.block_diag([A.K[fA][:, fA], B.K[fB][:, fB]]).tocsr()
    rhs = -np.r_[A.K[fA][:, A.pres] @ A.upres[A.pres], B.K[fB][:, B.pres] @ B.upres[B.pres]]
    n = Kff.shape[0]
    uf, active, lu, nfac, nsol = np.zeros(n), None, None, 0, 0
    if u0 is not None:   # start from the previous level's solution, prolonged
        uf = np.r_[u0[0][A.ind].ravel()[fA], u0[1][B.ind].ravel()[fB]]
    for it in range(1, 100):
        uiA, uiB = A.upres.copy(), B.upres.copy()
        uiA[fA], uiB[fB] = uf[:nA], uf[nA:]
        uA, uB = (A.T @ uiA).reshape(-1, 2), (B.T @ uiB).reshape(-1, 2)
        gt, GA, GB, nodes, quad = contact(A, B, uA, uB, R, xmax)
        GAi, GBi = (GA @ A.T).tocsc(), (GB @ B.T).tocsc()
        G = sp.hstack([GAi[:, fA], GBi[:, fB]]).tocsr()
        if active is None:   # row scaling: scaled multipliers ~ E * displacements
            active, mu = A.X[nodes, 0] < active0, np.zeros(len(nodes))
            dsc = E_MOD / np.maximum(abs(GA).sum(1).A1, 1e-300)
        # KKT on all candidate rows: active rows G u = G u_k - g, inactive rows mu_i = 0
        Ga = sp.diags(dsc * active) @ G
        M = sp.bmat([[Kff, Ga.T], [Ga, sp.diags(E_MOD * ~active)]]).tocsr()
        b = np.r_[rhs, np.where(active, Ga @ uf - dsc * gt, 0.0)]
        x = np.r_[uf, mu]
        r = b - M @ x
        if lu is None:   # quasi-definite regularised KKT, factorised without pivoting
            Mr = (M - sp.diags(np.r_[np.zeros(n), 1e-6 * E_MOD * active])).tocsc()
            lu = splu(Mr, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
            nfac += 1
        # defect correction against the exact system; the factor may belong to an older geometry
        r0 = rn = np.linalg.norm(r)
        for _ in range(4):
            x += lu.solve(r)
            r, rp = b - M @ x, rn
            rn, nsol = np.linalg.norm(r), nsol + 1
            if rn < 1e-4 * r0 or rn < 1e-14 * np.linalg.norm(b):
                break
        if rn > 0.05 * rp:   # slow: refactorise at the next iteration
            lu = None
        lam = -dsc * x[n:] * active
        glin = gt + G @ (x[:n] - uf)
        du = np.abs(x[:n] - uf).max()
        uf, mu = x[:n], np.where(active, x[n:], 0.0)
        new = (active & (lam > 0)) | (~active & (glin < 0))
        if (new == active).all() and du < 1e-11 * delta:
            break
        if (new != active).any():
            active, lu = new, None
    # post-processing on the converged state (geometry of the last linearisation)
    sl, ci, N, xA, wj = quad
    ph = np.einsum("mi,gi->mg", lam[ci], N)
    uiA[fA], uiB[fB] = uf[:nA], uf[nA:]
    P = 2 * (wj * ph).sum()
    amom = 2 * math.sqrt((wj * ph * xA ** 2).sum() / (wj * ph).sum())
    xs = A.X[nodes, 0] + uA[nodes, 0]
    k = int(np.flatnonzero(active).max())
    p1, p2 = lam[k - 1], lam[k]
    a_edge = xs[k] + p2 ** 2 * (xs[k] - xs[k - 1]) / max(p1 ** 2 - p2 ** 2, 1e-300)
    a_edge = min(max(a_edge, xs[k]), xs[k + 1])
    eq = []
    for b, Gi, free, ui in ((A, GAi, fA, uiA), (B, GBi, fB, uiB)):
        r = b.K @ ui - Gi.T @ lam
        fz = np.zeros(len(free), bool)
        fz[1::2] = True
        eq.append(r[b.pres & fz].sum())
    Fc = (GA.T @ lam)[1::2].sum()
    eqerr = max(abs(eq[0] + Fc), abs(eq[1] - Fc), abs((GB.T @ lam)[1::2].sum() + Fc)) / abs(Fc)
    return dict(P=P, a_edge=a_edge, a_mom=amom, pmax=lam[0], it=it, eq=eqerr, nact=int(active.sum()), nf=nfac, ngm=nsol, u=(uA, uB),
                ndof=len(uf), x=xs, p=lam, active=active)


def run(R: float, delta: float, W: float, D: float, h_c: float, lvl: int, zone: float, grade: float):
    """Level `lvl` of the nested sequence whose level 0 has size h_c on [0, zone]."""
    r0 = min(W, D, R) / 2
    n0B = np.array([max(1, round(W / r0)), max(1, round(D / r0))])
    boxes = [(np.array([3, 2]), np.array([0.0, 0.0]), np.array([math.pi * R / 2, R]), True),
             (n0B, np.array([0.0, -D]), np.array([W, 0.0]), False)]
    bodies = []
    for n0, lo, hi, polar in boxes:
        z = R * math.asin(min(zone / R, 1.0)) if polar else zone
        leaves = split(quadtree(n0, lo, hi, h_c, grade, z, top=not polar), lvl)
        bodies.append(make_body(leaves, n0, lo, hi, R, polar, delta))
    return bodies


def hertz(P: float, R: float) -> tuple[float, float]:
    es = E_MOD / (2 * (1 - NU ** 2))
    aH = math.sqrt(4 * P * R / (math.pi * es))
    return aH, 2 * P / (math.pi * aH)


def richardson(q: list[float]) -> tuple[float, float]:
    d1, d2 = q[-2] - q[-3], q[-1] - q[-2]
    if d1 * d2 <= 0 or d2 == 0:
        return q[-1], float("nan")
    p = math.log2(d1 / d2)
    return q[-1] + d2 / (2 ** p - 1), p


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--R", type=float, default=1.0)
    ap.add_argument("--delta", type=float, default=0.05)
    ap.add_argument("--width", type=float, default=1.0, help="block half-width W")
    ap.add_argument("--depth", type=float, default=1.0, help="block depth D")
    ap.add_argument("--levels", type=int, default=4)
    ap.add_argument("--h-contact", type=float, default=None,
                    help="element size on the contact zone of the first (coarsest) level; default a/25")
    ap.add_argument("--pressure-out", default=None, help="CSV of nodal pressures on the finest mesh")
    a = ap.parse_args()
    R, delta, W, D = a.R, a.delta, a.width, a.depth
    xmax = 0.9 * min(W, R)
    t0 = time.perf_counter()
    z0 = math.sqrt(2 * R * delta)
    A, B = run(R, delta, W, D, z0 / 12, 0, z0, 0.5)
    pil = solve_level(A, B, R, delta, xmax, z0)
    zone = 1.3 * pil["a_edge"]
    h_c = a.h_contact or pil["a_edge"] / 25
    print(f"# R={R} delta={delta} W={W} D={D} E={E_MOD:g} nu={NU}; vertical gap, deformed geometry, "
          f"symmetry x=0 used (half model, P doubled)")
    print(f"# pilot a={pil['a_edge']:.5f} ({time.perf_counter() - t0:.1f}s); refined zone x<={zone:.4f}, "
          f"level-0 h_c={h_c:.5g}, grading g={GRADE0}")
    hdr = (f"{'lvl':>3} {'h_c':>9} {'a/h':>5} {'unknowns':>9} {'P [N/m]':>14} {'a_edge':>10} {'a_moment':>10}"
           f" {'p_max':>12} {'aE/aH':>9} {'aM/aH':>9} {'pmax/p0H':>9} {'it':>3} {'LU':>2} {'gm':>4} {'eq.err':>8} {'t[s]':>6}")
    print(hdr)
    rows, prev = [], z0
    for k in range(a.levels):
        t1 = time.perf_counter()
        A, B = run(R, delta, W, D, h_c, k, zone, GRADE0)
        u0 = None if k == 0 else (prolong(Ap, r["u"][0], A), prolong(Bp, r["u"][1], B))
        r = solve_level(A, B, R, delta, xmax, prev, u0)
        Ap, Bp = A, B
        prev = r["a_edge"]
        aH, p0H = hertz(r["P"], R)
        r.update(ae=r["a_edge"] / aH, am=r["a_mom"] / aH, pp=r["pmax"] / p0H)
        rows.append(r)
        hk = h_c / 2 ** k
        print(f"{k:3d} {hk:9.3e} {r['a_edge'] / hk:5.0f} {r['ndof'] + r['nact']:9d} {r['P']:14.7e} "
              f"{r['a_edge']:10.7f} {r['a_mom']:10.7f} {r['pmax']:12.6e} {r['ae']:9.6f} {r['am']:9.6f} "
              f"{r['pp']:9.6f} {r['it']:3d} {r['nf']:2d} {r['ngm']:4d} {r['eq']:8.1e} {time.perf_counter() - t1:6.1f}", flush=True)
    if len(rows) >= 3:
        print("# Richardson (last three meshes, ratio 2): value, observed order")
        for key, name in (("P", "P [N/m]"), ("ae", "a_edge/a_H"), ("am", "a_moment/a_H"), ("pp", "p_max/p0_H"),
                          ("a_edge", "a_edge [m]"), ("a_mom", "a_moment [m]"), ("pmax", "p_max [Pa]")):
            v, p = richardson([r[key] for r in rows])
            print(f"  {name:14s} {v:.7g}   order {p:.2f}")
    if a.pressure_out:
        r, (aH, p0H) = rows[-1], hertz(rows[-1]["P"], R)
        with open(a.pressure_out, "w") as fh:
            fh.write("x,p,active,p_hertz_at_measured_P\n")
            for x, p, act in zip(r["x"], r["p"], r["active"]):
                fh.write(f"{x:.9g},{p:.9g},{int(act)},{p0H * math.sqrt(max(0.0, 1 - (x / aH) ** 2)):.9g}\n")
    print(f"# total {time.perf_counter() - t0:.1f}s")


if __name__ == "__main__":
    main()
