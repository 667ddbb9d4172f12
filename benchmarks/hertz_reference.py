"""Converged 2D plane-strain reference for the finite-geometry Hertz line-contact problem.

Problem (x horizontal, z vertical; m, Pa): body A, the lower half disc {x^2 + (z-R)^2 <= R^2,
z <= R}, touches z = 0 at x = 0; its flat face z = R gets (u_x, u_z) = (0, -delta). Body B,
the block [-W, W] x [-D, 0], is clamped at z = -D, free elsewhere. Linear elastic, small
strain, plane strain, E = 1e7, nu = 0.3. Frictionless contact of A's arc on B's top, gap =
VERTICAL distance of a point of A's arc above B's deformed top at the same current x (deformed
configuration). Symmetry: only x >= 0 is modelled (u_x = 0 on x = 0); P is the full-width load.

Method: 9-node quads on 2:1-balanced quadtrees in a reference rectangle, mapped exactly (B:
identity; A: (s, rho) -> ((R-rho) sin(s/R), R - (R-rho) cos(s/R)), so the arc is exact);
hanging nodes tied conformingly. Level-0 size h_c on x <= 1.3 a_pilot, h_c/4 within +-6% of the
pilot's contact edge, h_c at the singular corners (W, -D) of B and (R, R) of A, growing by 0.5
per unit distance; level k = level 0 with every element split k times. Contact: quadratic
mortar, A's arc slave, multiplier p_h = sum p_i N_i (vertical pressure per unit current x),
constraints int N_i g dx >= 0 integrated on segments between all slave/master element ends,
enforced exactly: Lagrange multipliers, primal-dual active set (semi-smooth Newton), geometry
re-linearised every iteration until the active set is unchanged and the update < 1e-11 delta.
Solver: SuperLU of a regularised KKT matrix preconditioning defect correction on the exact
system, Woodbury updates for active-set changes; each level starts from the previous solution.

Measured: P; a_edge = p^2 ~ (a - x) extrapolated from the last two contact nodes, clamped to
[last contact node, first open node]; a_F = root of a quadratic LSQ fit of F^(2/3), F(x) =
int_x p dx ~ (a-x)^1.5, on [0.9, 1] x last contact node (much less noisy); a_moment = 2 sqrt(int
p x^2 / int p); p_max = p(0); each over Hertz at the measured P; Richardson on the last three.

Usage: python3 -m benchmarks.hertz_reference [--R 1] [--delta 0.05] [--width 1] [--depth 1]
       [--E-ratio 1] [--levels 4] [--h-contact H] [--pressure-out FILE.csv]
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from cgfem.reference.elements import lagrange_1d as lag2, plane_strain_matrix

E_MOD, NU = 1.0e7, 0.3
GRADE0, EDGE_RATIO, CORNER = 0.5, 4, 1.0   # level-0 size growth; edge-band, corner size / h_c
Arr = np.ndarray
LA, LB = np.array([0, 1, 2] * 3), np.repeat([0, 1, 2], 3)   # Q9 local node (a, b), index 3b + a


def quadtree(n0: Arr, lo: Arr, hi: Arr, segs: list[tuple[float, float, float, float]], grade: float) -> Arr:
    """Leaves (level, i, j) of size <= min over segs (h + grade * distance to the horizontal
    segment [x0, x1] x {y}), segs = (x0, x1, y, h) in reference coordinates; 2:1-balanced."""
    s0 = (hi - lo) / n0
    ii, jj = np.meshgrid(np.arange(n0[0]), np.arange(n0[1]), indexing="ij")
    cells, out = np.stack([0 * ii.ravel(), ii.ravel(), jj.ravel()], 1), []
    while len(cells):
        sz = s0[None, :] / 2.0 ** cells[:, :1]
        c0 = lo + cells[:, 1:] * sz
        need = np.zeros(len(cells), bool)
        for x0, x1, y, h in segs:
            dx = np.maximum(0.0, np.maximum(c0[:, 0] - x1, x0 - c0[:, 0] - sz[:, 0]))
            dy = np.maximum(0.0, np.maximum(c0[:, 1] - y, y - c0[:, 1] - sz[:, 1]))
            need |= sz.max(1) > h + grade * np.hypot(dx, dy)
        out.append(cells[~need])
        c = cells[need]
        cells = np.concatenate([np.stack([c[:, 0] + 1, 2 * c[:, 1] + a, 2 * c[:, 2] + b], 1)
                                for a in (0, 1) for b in (0, 1)])
    leaves, changed = set(map(tuple, np.concatenate(out).tolist())), True
    while changed:   # split any leaf two or more levels coarser than an edge neighbour
        changed = False
        for lv, i, j in list(leaves):
            for a, b in ((i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)):
                if (lv, i, j) not in leaves or not (0 <= a < n0[0] << lv and 0 <= b < n0[1] << lv):
                    continue
                key = next((m, a >> (lv - m), b >> (lv - m)) for m in range(lv, -2, -1)
                           if m < 0 or (m, a >> (lv - m), b >> (lv - m)) in leaves)
                if 0 <= key[0] <= lv - 2:
                    leaves.remove(key)
                    leaves.update((key[0] + 1, 2 * key[1] + p, 2 * key[2] + q) for p in (0, 1) for q in (0, 1))
                    changed = True
    return np.array(sorted(leaves))


def split(leaves: Arr, k: int) -> Arr:
    """Every leaf split k times (nested refinement; keeps the 2:1 balance)."""
    f = 1 << k
    a, b = [x.ravel() for x in np.meshgrid(np.arange(f), np.arange(f), indexing="ij")]
    lv, i, j = (x[:, None] for x in leaves.T)
    return np.stack([(lv + k + 0 * a).ravel(), (i * f + a).ravel(), (j * f + b).ravel()], 1)


@dataclass
class Body:   # K on independent dofs (hanging eliminated), T: full <- independent; surf, srng:
    # contact-edge element sides (nodes, reference range), in order; el: elements (= leaves)
    X: Arr
    K: sp.csr_matrix
    T: sp.csr_matrix
    pres: Arr
    upres: Arr
    surf: Arr
    srng: Arr
    leaves: Arr
    el: Arr
    ind: Arr


def make_body(leaves: Arr, n0: Arr, lo: Arr, hi: Arr, R: float, polar: bool, delta: float,
              E: float = E_MOD) -> Body:
    """Q9 mesh, stiffness (Young's modulus E), hanging-node ties and boundary conditions of
    body A (polar) or B."""
    lv, ci, cj = leaves.T
    Lm = int(lv.max()) + 1
    NJ, f = 2 * n0[1] * (1 << Lm) + 1, 1 << (Lm - lv)
    I, J = (2 * ci[:, None] + LA) * f[:, None], (2 * cj[:, None] + LB) * f[:, None]
    raw = np.unique(I * NJ + J)   # integer lattice keys of all nodes
    hk, mk, cf, fq = [], [], [], f // 2   # hanging: quarter points of a leaf side that are nodes
    w13 = np.array([[0.375, 0.75, -0.125], [-0.125, 0.75, 0.375]])
    for side in range(4):
        if side < 2:
            jj = (2 * cj + 2 * side) * f
            ends, qs = [(2 * ci + t) * f * NJ + jj for t in (0, 1, 2)], [(4 * ci + q) * fq * NJ + jj for q in (1, 3)]
        else:
            ii = (2 * ci + 2 * side - 4) * f
            ends, qs = [ii * NJ + (2 * cj + t) * f for t in (0, 1, 2)], [ii * NJ + (4 * cj + q) * fq for q in (1, 3)]
        for q in range(2):
            ok = np.isin(qs[q], raw)
            hk, mk = hk + [qs[q][ok]], mk + [np.stack([e[ok] for e in ends], 1)]
            cf.append(np.tile(w13[q], (ok.sum(), 1)))
    hk, first = np.unique(np.concatenate(hk), return_index=True)
    mk, cf = np.concatenate(mk)[first], np.concatenate(cf)[first]
    canon = np.where((raw % NJ == NJ - 1) & polar, NJ - 1, raw)   # A: rho = R is one node
    keys = np.unique(canon)
    nid = np.searchsorted(keys, canon)
    node = lambda k: nid[np.searchsorted(raw, k)]  # noqa: E731
    n, hang = len(keys), np.zeros(len(keys), bool)
    hang[node(hk)] = True
    ij = (np.r_[np.repeat(node(hk), 3), np.arange(n)], np.r_[node(mk).ravel(), np.arange(n)])
    Cn = sp.coo_matrix((np.r_[cf.ravel(), (~hang).astype(float)], ij), (n, n)).tocsr()
    while abs(Cn[:, np.flatnonzero(hang)]).sum() > 0:   # ties whose masters hang themselves
        Cn = (Cn @ Cn).tocsr()
        Cn.eliminate_zeros()
    T = sp.kron(Cn[:, np.flatnonzero(~hang)], sp.eye(2)).tocsr()
    KI, KJ = keys // NJ, keys % NJ

    def phi(q: Arr) -> tuple[Arr, Arr]:   # physical points and d(x, z)/d(reference)
        if not polar:
            return q.copy(), np.broadcast_to(np.eye(2), q.shape[:-1] + (2, 2))
        th, r = q[..., 0] / R, R - q[..., 1]
        Jm = np.stack([np.stack([r / R * np.cos(th), -np.sin(th)], -1),
                       np.stack([r / R * np.sin(th), np.cos(th)], -1)], -2)
        return np.stack([r * np.sin(th), R - r * np.cos(th)], -1), Jm

    X = phi(lo + np.stack([KI, KJ], 1) * (hi - lo) / (2 * n0 * (1 << Lm)))[0]
    el = nid[np.searchsorted(raw, I * NJ + J)]
    sz = (hi - lo) / n0 / 2.0 ** lv[:, None]
    c0 = lo + np.stack([ci, cj], 1) * sz
    Dm = plane_strain_matrix(E, NU)
    gp, gw = np.polynomial.legendre.leggauss(3)
    Ke = np.zeros((len(el), 18, 18))
    for xa, wa in zip(gp, gw):
        for xb, wb in zip(gp, gw):
            (Na, dNa), (Nb, dNb) = lag2(xa), lag2(xb)
            Jt = phi(c0 + sz * (np.array([xa, xb]) + 1) / 2)[1] * (sz / 2)[:, None, :]
            g = np.einsum("ak,ekl->eal", np.stack([dNa[LA] * Nb[LB], Na[LA] * dNb[LB]], 1), np.linalg.inv(Jt))
            B = np.zeros((len(el), 3, 18))
            B[:, 0, 0::2], B[:, 1, 1::2], B[:, 2, 0::2], B[:, 2, 1::2] = g[..., 0], g[..., 1], g[..., 1], g[..., 0]
            Ke += (wa * wb * np.linalg.det(Jt))[:, None, None] * (B.transpose(0, 2, 1) @ (Dm @ B))
    dof = (2 * el[:, :, None] + np.arange(2)).reshape(len(el), 18)
    K = sp.coo_matrix((Ke.ravel(), (np.repeat(dof, 18, 1).ravel(), np.tile(dof, 18).ravel())), (2 * n, 2 * n))
    ind = np.flatnonzero(~hang)
    KI, KJ = KI[ind], KJ[ind]   # A: u = (0, -delta) on the flat face and its centre; B: 0 at the bottom
    pz = ((KI == KI.max()) | (KJ == NJ - 1)) if polar else KJ == 0
    pres = np.stack([(KI == 0) | pz, pz], 1).ravel()   # u_x = 0 on the symmetry line
    upres = np.stack([0.0 * pz, (-delta if polar else 0.0) * pz], 1).ravel()
    row = cj == (0 if polar else (n0[1] << lv) - 1)   # leaves on the contact edge
    order = np.argsort(ci[row] * f[row])
    s_lo = c0[row, 0]
    return Body(X, (T.T @ K.tocsr() @ T).tocsr(), T, pres, upres, el[row][:, [0, 1, 2] if polar else [6, 7, 8]][order],
                np.stack([s_lo, s_lo + sz[row, 0]], 1)[order], leaves, el, ind)


def prolong(old: Body, uold: Arr, new: Body) -> Arr:
    """Nodal values on `new` (= `old` split once) of the Q9 field uold (n_old, 2) of `old`."""
    code = lambda L: (L[:, 0] << 42) | (L[:, 1] << 21) | L[:, 2]  # noqa: E731
    oc = code(old.leaves)
    srt = np.argsort(oc)
    pe = srt[np.searchsorted(oc[srt], code(np.c_[new.leaves[:, 0] - 1, new.leaves[:, 1:] >> 1]))]
    nx = lag2(-1 + (new.leaves[:, 1:2] & 1) + LA / 2)[0]
    ny = lag2(-1 + (new.leaves[:, 2:3] & 1) + LB / 2)[0]
    u = np.zeros((len(new.X), 2))
    u[new.el] = np.einsum("enp,epc->enc", nx[..., LA] * ny[..., LB], uold[old.el[pe]])
    return u


def contact(A: Body, B: Body, uA: Arr, uB: Arr, R: float, xmax: float, ng: int = 5) -> tuple:
    """Weighted vertical gaps g_i = int N_i g dx at the slave nodes, their linearisation (dg =
    du_zA - du_zB - slope_B (du_xA - du_xB)) and quadrature data; Gauss segments between all
    slave and master element ends in the current x."""
    keep = R * np.sin(A.srng[:, 1] / R) <= xmax
    sl, sr, ms, mr = A.surf[keep], A.srng[keep], B.surf, B.srng

    def side(t: Arr, e: Arr, slave: bool) -> tuple[Arr, ...]:   # current x, z, dx/dt of edge e at t
        N, dN = lag2(t)
        nd, lo, hi, u = (sl, sr[e, 0], sr[e, 1], uA) if slave else (ms, mr[e, 0], mr[e, 1], uB)
        q = lo + (t + 1) * (hi - lo) / 2
        X, Z, dX = (R * np.sin(q / R), R * (1 - np.cos(q / R)), np.cos(q / R)) if slave else (q, 0 * q, 1 + 0 * q)
        return (X + (N * u[nd[e], 0]).sum(-1), Z + (N * u[nd[e], 1]).sum(-1),
                dX * (hi - lo) / 2 + (dN * u[nd[e], 0]).sum(-1), N, dN)

    ends = [side(np.full(len(r), v), np.arange(len(r)), m)[0] for m, r in ((True, sr), (False, mr)) for v in (-1, 1)]
    bp = np.unique(np.clip(np.concatenate(ends), 0.0, min(ends[1][-1], ends[3][-1])))
    t, w = np.polynomial.legendre.leggauss(ng)
    xg, wx = (bp[:-1, None] + bp[1:, None]) / 2 + np.diff(bp)[:, None] / 2 * t, np.diff(bp)[:, None] / 2 * w
    par = []
    for m, st, en in ((True, ends[0], ends[1]), (False, ends[2], ends[3])):
        e = np.clip(np.searchsorted(st, xg[:, :1], "right") - 1, 0, len(st) - 1) + 0 * xg.astype(int)
        xi = 2 * (xg - st[e]) / (en[e] - st[e]) - 1
        for _ in range(8):   # Newton: parameter of the point at current x = xg
            xc, _, dx, _, _ = side(xi, e, m)
            xi = xi - (xc - xg) / dx
        par.append((e, side(xi, e, m)))
    (eA, (_, zA, _, N, _)), (eB, (_, zB, dxB, Nm, dNm)) = par
    slope, gap, nodes = (dNm * uB[ms[eB], 1]).sum(-1) / dxB, zA - zB, np.unique(sl)
    ci = np.searchsorted(nodes, sl)[eA]   # (S, ng, 3) constraint rows
    fac = N * wx[..., None]               # N_i dx
    gt = np.bincount(ci.ravel(), (fac * gap[..., None]).ravel(), len(nodes))
    rows = np.broadcast_to(ci[..., :, None], fac.shape + (3,)).ravel()

    def mat(Nj: Arr, nd: Arr, sgn: float, n: int) -> sp.csr_matrix:
        f, col = sgn * fac[..., None] * Nj[..., None, :], np.broadcast_to(nd[..., None, :], fac.shape + (3,)).ravel()
        return sp.coo_matrix((np.r_[f.ravel(), (-f * slope[..., None, None]).ravel()],
                              (np.r_[rows, rows], np.r_[2 * col + 1, 2 * col])), (len(nodes), 2 * n)).tocsr()

    return gt, mat(N, sl[eA], 1.0, len(uA)), mat(Nm, ms[eB], -1.0, len(uB)), nodes, (ci, N, xg, wx, bp)


class KKTPrec:
    """SuperLU of the regularised (quasi-definite: no pivoting needed) KKT matrix of a reference
    active set, with a Woodbury correction for rows whose status changed since (rank 2 each)."""

    def __init__(self, M: sp.csr_matrix, n: int, active: Arr, reg: float = 1e-6 * E_MOD):
        self.n, self.ref, self.reg, self.cache, self.W = n, active.copy(), reg, {}, None
        self.rows = M[n:, :n].tocsr()
        self.lu = splu((M - sp.diags(np.r_[np.zeros(n), reg * active])).tocsc(), permc_spec="MMD_AT_PLUS_A",
                       diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))

    def update(self, active: Arr, Ga: sp.csr_matrix) -> bool:
        ch = np.flatnonzero(active != self.ref)
        if len(ch) > 24:
            return False
        for i in ch:
            if i not in self.cache:   # row/column n+i switches between "constraint" and "mu_i = 0"
                U = np.zeros((self.n + len(active), 2))
                U[self.n + i, 0] = 1.0
                U[:self.n, 1] = (Ga[i] if active[i] else -self.rows[i]).toarray().ravel()
                c = -E_MOD if active[i] else E_MOD + self.reg
                self.cache[i] = (U, np.c_[self.lu.solve(U[:, 0]), self.lu.solve(U[:, 1])],
                                 np.linalg.inv(np.array([[c, 1.0], [1.0, 0.0]])))
        self.W = None
        if len(ch):
            U, PU = (np.hstack([self.cache[i][k] for i in ch]) for k in (0, 1))
            self.W = (U, PU, np.linalg.inv(sp.block_diag([self.cache[i][2] for i in ch]).toarray() + U.T @ PU))
        return True

    def solve(self, r: Arr) -> Arr:
        y = self.lu.solve(r)
        if self.W is not None:
            U, PU, S = self.W
            y -= PU @ (S @ (U.T @ y))
        return y


def solve_level(A: Body, B: Body, R: float, delta: float, xmax: float, active0: float,
                u0: tuple[Arr, Arr] | None = None) -> dict:
    """Active-set + geometry iteration on one mesh pair; returns the measured quantities."""
    fA, fB = ~A.pres, ~B.pres
    nA = int(fA.sum())
    Kff = sp.block_diag([A.K[fA][:, fA], B.K[fB][:, fB]]).tocsr()
    rhs = -np.r_[A.K[fA][:, A.pres] @ A.upres[A.pres], B.K[fB][:, B.pres] @ B.upres[B.pres]]
    n = Kff.shape[0]
    uf = np.zeros(n) if u0 is None else np.r_[u0[0][A.ind].ravel()[fA], u0[1][B.ind].ravel()[fB]]
    active, lu, nfac = None, None, 0

    def full(v: Arr) -> tuple[Arr, Arr, Arr, Arr]:
        uiA, uiB = A.upres.copy(), B.upres.copy()
        uiA[fA], uiB[fB] = v[:nA], v[nA:]
        return uiA, uiB, (A.T @ uiA).reshape(-1, 2), (B.T @ uiB).reshape(-1, 2)

    for it in range(1, 100):
        uA, uB = full(uf)[2:]
        gt, GA, GB, nodes, quad = contact(A, B, uA, uB, R, xmax)
        GAi, GBi = (GA @ A.T).tocsc(), (GB @ B.T).tocsc()
        G = sp.hstack([GAi[:, fA], GBi[:, fB]]).tocsr()
        if active is None:   # initial guess: current x < active0; rows scaled to ~E
            active, mu = A.X[nodes, 0] + uA[nodes, 0] < active0, np.zeros(len(nodes))
            ws = abs(GA).sum(1).A1
            dsc = E_MOD / np.maximum(ws, 1e-9 * ws.max())
        # KKT on all candidate rows: active rows G u = G u_k - g(u_k), inactive rows mu_i = 0
        Ga = sp.diags(dsc * active) @ G
        M = sp.bmat([[Kff, Ga.T], [Ga, sp.diags(E_MOD * ~active)]]).tocsr()
        b, x = np.r_[rhs, np.where(active, Ga @ uf - dsc * gt, 0.0)], np.r_[uf, mu]
        if lu is None or not lu.update(active, Ga):
            lu, nfac = KKTPrec(M, n, active), nfac + 1
        r = b - M @ x   # defect correction on the exact system (factor may be of an older geometry)
        r0 = rn = np.linalg.norm(r)
        for _ in range(4):
            x += lu.solve(r)
            r, rp = b - M @ x, rn
            rn = np.linalg.norm(r)
            if rn < 1e-4 * r0 or rn < 1e-14 * np.linalg.norm(b):
                break
        if rn > 0.3 * rp:   # stale factor: refactorise at the next iteration
            lu = None
        lam, glin = -dsc * x[n:] * active, gt + G @ (x[:n] - uf)
        du, uf, mu = np.abs(x[:n] - uf).max(), x[:n], np.where(active, x[n:], 0.0)
        new = (active & (lam > 0)) | (~active & (glin < 0))
        if (new == active).all() and du < 1e-11 * delta:
            break
        active = new
    ci, N, xg, wx, bp = quad   # measurements (geometry moved by < 1e-11 delta since)
    pw = (lam[ci] * N).sum(-1) * wx
    P, amom = 2 * pw.sum(), 2 * math.sqrt((pw * xg ** 2).sum() / pw.sum())
    xs = A.X[nodes, 0] + uA[nodes, 0]
    k = int(np.flatnonzero(active).max())
    p1, p2 = lam[k - 1], lam[k]   # p^2 ~ (a - x): extrapolate, clamp to [last contact, first open]
    a_edge = min(max(xs[k] + p2 ** 2 * (xs[k] - xs[k - 1]) / max(p1 ** 2 - p2 ** 2, 1e-300), xs[k]), xs[k + 1])
    F = np.cumsum(pw.sum(1)[::-1])[::-1]   # int_x p dx at the segment starts bp[:-1]
    m = (bp[:-1] > 0.9 * xs[k]) & (bp[:-1] < xs[k]) & (F > 0)
    rts = np.roots(np.polyfit(bp[:-1][m], F[m] ** (2 / 3), 2)) if m.sum() >= 5 else np.array([])
    rts = rts[abs(rts.imag) < 1e-12].real
    a_F = rts[np.argmin(abs(rts - xs[k]))] if len(rts) else float("nan")
    uiA, uiB, uA, uB = full(uf)   # equilibrium: contact forces vs reactions (A's flat face, B's bottom)
    Fc = (GA.T @ lam)[1::2].sum()
    reac = [(bd.K @ ui - Gi.T @ lam)[1::2][bd.pres[1::2]].sum() for bd, Gi, ui in ((A, GAi, uiA), (B, GBi, uiB))]
    eq = max(abs(reac[0] + Fc), abs(reac[1] - Fc), abs((GB.T @ lam)[1::2].sum() + Fc)) / abs(Fc)
    top = np.unique(B.surf)   # u_x of both surfaces at the last contact node (current x = X + u_x)
    ux = (uA[nodes[k], 0], np.interp(xs[k], B.X[top, 0] + uB[top, 0], uB[top, 0]))
    return dict(P=P, a_edge=a_edge, a_F=a_F, a_mom=amom, pmax=lam[0], it=it, nf=nfac, eq=eq, u=(uA, uB), ux=ux,
                unknowns=n + int(active.sum()), x=xs, p=lam, active=active)


def run(R: float, delta: float, W: float, D: float, h_c: float, lvl: int, zone: float, grade: float,
        edge: float = 0.0, e_ratio: float = 1.0) -> list[Body]:
    """Bodies A, B of level `lvl`: level 0 has size h_c on [0, zone], h_c/EDGE_RATIO on
    [0.94, 1.06] * edge (if edge > 0), growth `grade`; level k = level 0 split k times.
    A's Young's modulus is `e_ratio` times B's."""
    r0 = min(W, D, R) / 2
    n0B = np.array([max(1, round(W / r0)), max(1, round(D / r0))])
    boxes = [(np.array([3, 2]), np.array([0.0, 0.0]), np.array([math.pi * R / 2, R]), True),
             (n0B, np.array([0.0, -D]), np.array([W, 0.0]), False)]
    segs = [(0.0, zone, h_c)] + ([(0.94 * edge, 1.06 * edge, h_c / EDGE_RATIO)] if edge > 0 else [])
    out = []
    for n0, lo, hi, polar in boxes:
        if polar:   # contact edge rho = 0 (s = R asin x/R); corner (R, R) of the arc and flat face
            sg = [(R * math.asin(min(x0 / R, 1)), R * math.asin(min(x1 / R, 1)), 0.0, h) for x0, x1, h in segs]
            sg.append((hi[0], hi[0], 0.0, h_c * CORNER))
        else:       # contact edge z = 0; corner (W, -D) between free side and clamped bottom
            sg = [(x0, x1, 0.0, h) for x0, x1, h in segs] + [(W, W, -D, h_c * CORNER)]
        out.append(make_body(split(quadtree(n0, lo, hi, sg, grade), lvl), n0, lo, hi, R, polar, delta,
                             E_MOD * (e_ratio if polar else 1.0)))
    return out


def hertz(P: float, R: float, e_ratio: float = 1.0) -> tuple[float, float]:
    """Hertz half-width and peak pressure at load P, 1/E* = (1 - nu^2) (1/E_A + 1/E_B) with
    E_A = e_ratio E_B (equal materials: E* = E/(2(1-nu^2)))."""
    aH = math.sqrt(4 * P * R / (math.pi * E_MOD / ((1 - NU ** 2) * (1 + 1 / e_ratio))))
    return aH, 2 * P / (math.pi * aH)


def richardson(q: list[float]) -> tuple[float, float, float]:
    """Extrapolated value, observed order and |value - finest| from the last three values (ratio
    2); if they do not converge monotonically: finest value, nan, spread of the three."""
    d1, d2 = q[-2] - q[-3], q[-1] - q[-2]
    if not (d1 * d2 > 0 and abs(d2) < abs(d1)):
        return q[-1], float("nan"), max(q[-3:]) - min(q[-3:])
    p = math.log2(d1 / d2)
    return q[-1] + d2 / (2 ** p - 1), p, abs(d2 / (2 ** p - 1))


def fitted_ellipse(x: Arr, p: Arr) -> tuple[float, float]:
    """(p0, a) of the weighted least-squares ellipse the cgFEM tests fit to their contact
    points (``tests/hertz_setup.fit_ellipse``), here over nodal pressures at x >= 0 sampled
    linearly at 20001 even points and mirrored to x < 0."""
    from tests.support.hertz_setup import fit_ellipse
    xs = np.linspace(0.0, x.max(), 20001)
    ps = np.interp(xs, x, p)
    w = np.full(xs.size, xs[1] - xs[0])
    w[-1] *= 0.5
    X, P, W = np.r_[-xs[:0:-1], xs], np.r_[ps[:0:-1], ps], np.r_[w[:0:-1], w]
    return fit_ellipse(X, P, W, 2.0 * math.sqrt(np.sum(W * P * X**2) / np.sum(W * P)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    for name, val, hlp in (("--R", 1.0, "cylinder radius"), ("--delta", 0.05, "approach of the flat face"),
                           ("--width", 1.0, "block half-width W"), ("--depth", 1.0, "block depth D")):
        ap.add_argument(name, type=float, default=val, help=hlp)
    ap.add_argument("--levels", type=int, default=4)
    ap.add_argument("--E-ratio", type=float, default=1.0, help="the cylinder's Young's modulus over the block's")
    ap.add_argument("--h-contact", type=float, default=None,
                    help="element size on the contact zone of the first (coarsest) level; default a/25")
    ap.add_argument("--pressure-out", default=None, help="CSV of nodal pressures of the finest mesh")
    a = ap.parse_args()
    R, delta, W, D = a.R, a.delta, a.width, a.depth
    xmax, t0 = 0.9 * min(W, R), time.perf_counter()
    z0 = math.sqrt(2 * R * delta)   # half-width of the geometric overlap (over-estimates a)
    pil = solve_level(*run(R, delta, W, D, z0 / 20, 0, z0, 0.5, e_ratio=a.E_ratio), R, delta, xmax, z0)
    a0 = pil["a_edge"]
    zone, h_c = 1.3 * a0, a.h_contact or a0 / 25
    print(f"# R={R} delta={delta} W={W} D={D} E={E_MOD:g} (cylinder x {a.E_ratio:g}) nu={NU}; plane strain, frictionless, vertical gap in "
          f"the deformed configuration; half model (x>=0, symmetry), P = full width\n# pilot a={a0:.5f} "
          f"({time.perf_counter() - t0:.1f}s); level 0: h_c={h_c:.4g} on x<={zone:.4f}, h_c/{EDGE_RATIO} on "
          f"[0.94,1.06]*{a0:.4f}, growth {GRADE0}; each level splits every element in 4")
    print("# it: active-set/geometry iterations, LU: factorisations, eq.err: max |contact force -+ reaction at A's "
          "flat face / B's bottom| / (P/2)\nlvl      h_c unknowns      P [N/m]    a_edge       a_F  a_moment      "
          "p_max    aE/aH    aF/aH    aM/aH pmax/p0H it LU  eq.err  t[s]")
    rows: list[dict] = []
    prev: list[Body] = []
    for k in range(a.levels):
        t1 = time.perf_counter()
        A, B = run(R, delta, W, D, h_c, k, zone, GRADE0, a0, a.E_ratio)
        u0 = (prolong(prev[0], rows[-1]["u"][0], A), prolong(prev[1], rows[-1]["u"][1], B)) if rows else None
        r = solve_level(A, B, R, delta, xmax, rows[-1]["a_edge"] if rows else a0, u0)
        prev = [A, B]
        aH, p0H = hertz(r["P"], R, a.E_ratio)
        r.update(ae=r["a_edge"] / aH, af=r["a_F"] / aH, am=r["a_mom"] / aH, pp=r["pmax"] / p0H)
        rows.append(r)
        if k == 0 and not 0.94 * a0 < r["a_edge"] < 1.06 * a0:
            print("# WARNING: the contact edge is outside the pilot's refined band; results less accurate")
        print(f"{k:3d} {h_c / 2 ** k:8.2e} {r['unknowns']:8d} {r['P']:12.5f} {r['a_edge']:9.7f} {r['a_F']:9.7f} "
              f"{r['a_mom']:9.7f} {r['pmax']:10.2f} {r['ae']:8.6f} {r['af']:8.6f} {r['am']:8.6f} {r['pp']:8.6f} "
              f"{r['it']:2d} {r['nf']:2d} {r['eq']:7.1e} {time.perf_counter() - t1:5.1f}", flush=True)
    ux = rows[-1]["ux"]
    print(f"# all x are current (deformed) coordinates; at the contact edge u_x = {ux[0]:.4e} (A), {ux[1]:.4e} (B), "
          f"so in reference coordinates a_F - u_x = {rows[-1]['a_F'] - ux[0]:.6f} (A), "
          f"{rows[-1]['a_F'] - ux[1]:.6f} (B)")
    if len(rows) >= 3:
        print("# Richardson (last three levels): value, observed order, |value - finest| (nan: not monotone;"
              " then finest value and spread of the three)")
        for key, name in (("P", "P [N/m]"), ("ae", "a_edge/a_H"), ("af", "a_F/a_H"), ("am", "a_moment/a_H"),
                          ("pp", "p_max/p0_H"), ("a_F", "a_F [m]"), ("a_mom", "a_moment [m]"), ("pmax", "p_max [Pa]")):
            print("  {:13s} {:14.8g}   order {:5.2f}   {:.2g}".format(name, *richardson([r[key] for r in rows])))
    p0_fit, a_fit = fitted_ellipse(rows[-1]["x"], rows[-1]["p"])
    print(f"# the cgFEM tests' estimators on the finest profile (tests/hertz_setup.py): fitted ellipse "
          f"p0 = {p0_fit:.1f} Pa, a = {a_fit:.6f} m; second moment a = {rows[-1]['a_mom']:.6f} m")
    if a.pressure_out:   # nodal pressures (mortar multipliers) of the finest level, current x
        r, (aH, p0H) = rows[-1], hertz(rows[-1]["P"], R, a.E_ratio)
        ph = p0H * np.sqrt(np.maximum(0, 1 - (r["x"] / aH) ** 2))
        np.savetxt(a.pressure_out, np.c_[r["x"], r["p"], r["active"], ph], delimiter=",",
                   header="x,p,active,p_hertz_at_measured_P", comments="", fmt="%.9g")
    print(f"# total {time.perf_counter() - t0:.1f}s")


if __name__ == "__main__":
    main()
