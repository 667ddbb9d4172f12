"""Numba kernels that split one rational Bezier piece of a NURBS patch by the planes of a
Cartesian grid and integrate every part exactly.

The piece ``Pw`` is a homogeneous Bernstein net ``(p + 1, q + 1, 4)`` over the local square
``(s, t) in [0, 1]^2``. A grid plane ``x_k = c`` cuts it along the zero set of the polynomial
``F = Pw[..., k] - c Pw[..., 3]`` (same zeros and sign as ``x_k - c`` because ``w > 0``).

Cells of the parameter square are processed from a stack. In a cell, a plane whose ``F`` has
Bernstein coefficients of one sign misses it. The others must each be, for one common
*inner* direction, either strictly monotone along it (its zero set is a graph over the outer
direction, one root per inner line) or constant along it (its zero set is a line
``outer = const``); otherwise the cell is split in two. With that structure the cell is
integrated by iterated Gauss quadrature: the outer interval is split at every place where the
root pattern changes (a graph root reaching the cell's inner boundary, a constant-along-inner
root, two graph roots crossing), and every inner line is split at its roots. Each inner
segment lies in one grid element. The result is exact up to the Gauss error of smooth
integrands; only cells that reach ``max_depth`` (tangencies, measure zero) are integrated
approximately and counted.

Outputs per emitted surface point: local ``(s, t)``, position, area weight, unit normal and
the grid element ``(i, j, k)``; per point of a trimming curve on a grid plane ``x = c``
(needed for exact volume moments): position, length weight, ``m_y`` (the y component of the
in-plane unit normal pointing out of the solid's section) and the plane index.
"""

from __future__ import annotations

import numpy as np
from numba import njit

MAX_FUNCS = 16
MAX_ROOTS = 64


@njit(cache=True)
def _binom(n, k):
    c = 1.0
    for j in range(1, k + 1):
        c = c * (n - k + j) / j
    return c


@njit(cache=True)
def bernstein(n, x, B, dB):
    """Bernstein basis of degree ``n`` at ``x`` into ``B`` and its derivative into ``dB``."""
    for i in range(n + 1):
        B[i] = _binom(n, i) * x**i * (1.0 - x) ** (n - i)
    if n == 0:
        dB[0] = 0.0
        return
    for i in range(n + 1):
        a = _binom(n - 1, i - 1) * x ** (i - 1) * (1.0 - x) ** (n - i) if i >= 1 else 0.0
        b = _binom(n - 1, i) * x**i * (1.0 - x) ** (n - 1 - i) if i <= n - 1 else 0.0
        dB[i] = n * (a - b)


@njit(cache=True)
def point_derivs(net, s, t, x, xs, xt):
    """Rational point ``x`` and first derivatives ``xs, xt`` of Bernstein net ``net`` at
    local ``(s, t)``."""
    p = net.shape[0] - 1
    q = net.shape[1] - 1
    Bu = np.empty(p + 1)
    dBu = np.empty(p + 1)
    Bv = np.empty(q + 1)
    dBv = np.empty(q + 1)
    bernstein(p, s, Bu, dBu)
    bernstein(q, t, Bv, dBv)
    S = np.zeros(4)
    Ss = np.zeros(4)
    St = np.zeros(4)
    for i in range(p + 1):
        for j in range(q + 1):
            for c in range(4):
                v = net[i, j, c]
                S[c] += Bu[i] * Bv[j] * v
                Ss[c] += dBu[i] * Bv[j] * v
                St[c] += Bu[i] * dBv[j] * v
    w = S[3]
    for c in range(3):
        x[c] = S[c] / w
        xs[c] = (Ss[c] - Ss[3] * x[c]) / w
        xt[c] = (St[c] - St[3] * x[c]) / w


@njit(cache=True)
def _split_net(net, axis, a):
    """de Casteljau subdivision of ``net`` at local ``a`` along ``axis`` (0 or 1)."""
    left = net.copy()
    right = net.copy()
    n = net.shape[axis] - 1
    other = net.shape[1 - axis]
    tmp = np.empty((n + 1, 4))
    for o in range(other):
        for i in range(n + 1):
            for c in range(4):
                tmp[i, c] = net[i, o, c] if axis == 0 else net[o, i, c]
        for r in range(n + 1):
            for c in range(4):
                if axis == 0:
                    left[r, o, c] = tmp[0, c]
                    right[n - r, o, c] = tmp[n - r, c]
                else:
                    left[o, r, c] = tmp[0, c]
                    right[o, n - r, c] = tmp[n - r, c]
            for i in range(n - r):
                for c in range(4):
                    tmp[i, c] = (1.0 - a) * tmp[i, c] + a * tmp[i + 1, c]
    return left, right


@njit(cache=True)
def _casteljau(coef, x):
    """Value and derivative of the univariate Bernstein polynomial ``coef`` at ``x``."""
    n = coef.shape[0] - 1
    if n == 0:
        return coef[0], 0.0
    b = coef.copy()
    for r in range(1, n):
        for i in range(n - r + 1):
            b[i] = (1.0 - x) * b[i] + x * b[i + 1]
    value = (1.0 - x) * b[0] + x * b[1]
    return value, n * (b[1] - b[0])


@njit(cache=True)
def _bracketed_root(coef, lo, hi):
    """The root of ``coef`` in ``[lo, hi]`` (values of opposite sign at the ends), by
    Newton steps safeguarded with bisection."""
    flo, _ = _casteljau(coef, lo)
    x = 0.5 * (lo + hi)
    for _ in range(100):
        f, df = _casteljau(coef, x)
        if f == 0.0:
            return x
        if (f < 0.0) == (flo < 0.0):
            lo = x
            flo = f
        else:
            hi = x
        xn = x - f / df if df != 0.0 else 0.5 * (lo + hi)
        if not (lo < xn < hi):
            xn = 0.5 * (lo + hi)
        if abs(xn - x) <= 1e-16 + 2e-16 * abs(x) or hi - lo <= 4e-16:
            return xn
        x = xn
    return x


@njit(cache=True)
def _sign_changes(coef):
    changes = 0
    prev = coef[0] >= 0.0
    for i in range(1, coef.shape[0]):
        cur = coef[i] >= 0.0
        if cur != prev:
            changes += 1
        prev = cur
    return changes


@njit(cache=True)
def univariate_roots(coef, roots):
    """Roots in ``[0, 1)`` of the Bernstein polynomial ``coef`` (ascending) into ``roots``;
    returns their number. Isolation by subdivision (a single sign change of the Bernstein
    coefficients means exactly one root), refinement by safeguarded Newton."""
    n = coef.shape[0] - 1
    count = 0
    stack_c = np.empty((64, n + 1))
    stack_a = np.empty(64)
    stack_b = np.empty(64)
    stack_d = np.empty(64, np.int64)
    top = 0
    stack_c[0] = coef
    stack_a[0] = 0.0
    stack_b[0] = 1.0
    stack_d[0] = 0
    top = 1
    while top > 0:
        top -= 1
        c = stack_c[top].copy()
        a = stack_a[top]
        b = stack_b[top]
        d = stack_d[top]
        ch = _sign_changes(c)
        if ch == 0:
            continue
        if ch == 1 or d >= 48:
            if ch == 1:
                r = _bracketed_root(c, 0.0, 1.0)
            else:
                r = 0.5
            x = a + r * (b - a)
            if x < 1.0 and count < roots.shape[0]:
                roots[count] = x
                count += 1
            continue
        # split at the middle: right half pushed first so the left is processed first
        left = c.copy()
        right = c.copy()
        tmp = c.copy()
        for r in range(n + 1):
            left[r] = tmp[0]
            right[n - r] = tmp[n - r]
            for i in range(n - r):
                tmp[i] = 0.5 * (tmp[i] + tmp[i + 1])
        m = 0.5 * (a + b)
        if top + 2 > 64:
            continue
        stack_c[top] = right
        stack_a[top] = m
        stack_b[top] = b
        stack_d[top] = d + 1
        top += 1
        stack_c[top] = left
        stack_a[top] = a
        stack_b[top] = m
        stack_d[top] = d + 1
        top += 1
    # ascending order
    for i in range(1, count):
        v = roots[i]
        j = i - 1
        while j >= 0 and roots[j] > v:
            roots[j + 1] = roots[j]
            j -= 1
        roots[j + 1] = v
    return count


@njit(cache=True)
def _line_coef(pnet, axis_k, c, sigma, coef):
    """Bernstein coefficients along the inner direction of ``x_k - c`` (times w) on the
    line ``outer = sigma`` of the (possibly transposed) piece net ``pnet``."""
    p = pnet.shape[0] - 1
    q = pnet.shape[1] - 1
    B = np.empty(p + 1)
    dB = np.empty(p + 1)
    bernstein(p, sigma, B, dB)
    for j in range(q + 1):
        acc = 0.0
        for i in range(p + 1):
            acc += B[i] * (pnet[i, j, axis_k] - c * pnet[i, j, 3])
        coef[j] = acc


@njit(cache=True)
def _inner_root(pnet, axis_k, c, sigma, lo, hi, coef):
    """Root in ``[lo, hi]`` of plane ``x_k = c`` on the inner line at ``sigma``, or -1 if
    the values at ``lo`` and ``hi`` have the same sign."""
    _line_coef(pnet, axis_k, c, sigma, coef)
    flo, _ = _casteljau(coef, lo)
    fhi, _ = _casteljau(coef, hi)
    if (flo >= 0.0) == (fhi >= 0.0):
        return -1.0
    return _bracketed_root(coef, lo, hi)


@njit(cache=True)
def gauss_order(length, log_tol, n_min, n_max):
    """Gauss points for an interval of ``length`` (in units of the Bezier piece) so that the
    error model ``(length / 4)^(2 n)`` of the rational integrands stays below the tolerance
    ``exp(log_tol)``; the model was fitted on the rational quadratic circle."""
    if length >= 3.9:
        return n_max
    n = int(np.ceil(-log_tol / (2.0 * np.log(4.0 / length))))
    return min(max(n, n_min), n_max)


@njit(cache=True)
def _element_of(x, origin, h, shape, ijk):
    for a in range(3):
        i = int(np.floor((x[a] - origin[a]) / h))
        ijk[a] = min(max(i, 0), shape[a] - 1)


@njit(cache=True)
def _emit_surface(pnet, s, t, weight, ijk, out_st, out_x, out_w, out_n, out_e, counts):
    """Append one surface point at local ``(s, t)`` with parametric weight ``weight``."""
    i = counts[0]
    if i >= out_w.shape[0]:
        counts[3] = 1
        return
    x = np.empty(3)
    xs = np.empty(3)
    xt = np.empty(3)
    point_derivs(pnet, s, t, x, xs, xt)
    nx = xs[1] * xt[2] - xs[2] * xt[1]
    ny = xs[2] * xt[0] - xs[0] * xt[2]
    nz = xs[0] * xt[1] - xs[1] * xt[0]
    jac = np.sqrt(nx * nx + ny * ny + nz * nz)
    out_st[i, 0] = s
    out_st[i, 1] = t
    for c in range(3):
        out_x[i, c] = x[c]
        out_e[i, c] = ijk[c]
    out_w[i] = weight * jac
    if jac > 0.0:
        out_n[i, 0] = nx / jac
        out_n[i, 1] = ny / jac
        out_n[i, 2] = nz / jac
    else:
        out_n[i, 0] = 0.0
        out_n[i, 1] = 0.0
        out_n[i, 2] = 0.0
    counts[0] = i + 1


@njit(cache=True)
def _emit_trim(x, normal, tangent, weight, plane, s, t, trim_x, trim_w, trim_my, trim_plane, trim_st, counts):
    """Append one point of a trimming curve on the grid plane ``x = origin + plane h``."""
    i = counts[1]
    if i >= trim_w.shape[0]:
        counts[3] = 1
        return
    length = np.sqrt(tangent[0] ** 2 + tangent[1] ** 2 + tangent[2] ** 2)
    norm_yz = np.sqrt(normal[1] ** 2 + normal[2] ** 2)
    for c in range(3):
        trim_x[i, c] = x[c]
    trim_w[i] = weight * length
    trim_my[i] = normal[1] / norm_yz if norm_yz > 0.0 else 0.0
    trim_plane[i] = plane
    trim_st[i, 0] = s
    trim_st[i, 1] = t
    counts[1] = i + 1


@njit(cache=True)
def _emit_cell(pnet, sa, sb, ta, tb, origin, h, shape, GX, GW, rule,
               out_st, out_x, out_w, out_n, out_e, counts):
    """Tensor Gauss rule on a cell that lies in one element (found from its centre)."""
    ns = gauss_order(sb - sa, rule[0], int(rule[1]), int(rule[2]))
    nt = gauss_order(tb - ta, rule[0], int(rule[1]), int(rule[2]))
    x = np.empty(3)
    xs = np.empty(3)
    xt = np.empty(3)
    ijk = np.empty(3, np.int64)
    point_derivs(pnet, 0.5 * (sa + sb), 0.5 * (ta + tb), x, xs, xt)
    _element_of(x, origin, h, shape, ijk)
    for a in range(ns):
        s = sa + GX[ns, a] * (sb - sa)
        for b in range(nt):
            t = ta + GX[nt, b] * (tb - ta)
            _emit_surface(pnet, s, t, GW[ns, a] * GW[nt, b] * (sb - sa) * (tb - ta), ijk,
                          out_st, out_x, out_w, out_n, out_e, counts)


@njit(cache=True)
def _classify(cnet, fk, fc, nf, inner, kinds):
    """For each function: 1 if strictly monotone along ``inner``, 2 if constant along it;
    returns False if some function is neither."""
    p = cnet.shape[0] - 1
    q = cnet.shape[1] - 1
    for f in range(nf):
        k = fk[f]
        c = fc[f]
        pos = True
        neg = True
        big = 0.0
        var = 0.0
        for i in range(p + 1):
            for j in range(q + 1):
                v = cnet[i, j, k] - c * cnet[i, j, 3]
                big = max(big, abs(v))
                if inner == 1 and j < q:
                    d = (cnet[i, j + 1, k] - c * cnet[i, j + 1, 3]) - v
                elif inner == 0 and i < p:
                    d = (cnet[i + 1, j, k] - c * cnet[i + 1, j, 3]) - v
                else:
                    continue
                var = max(var, abs(d))
                if not d > 0.0:
                    pos = False
                if not d < 0.0:
                    neg = False
        if pos or neg:
            kinds[f] = 1
        elif var <= 1e-13 * big:
            kinds[f] = 2
        else:
            return False
    return True


@njit(cache=True)
def _boundary_coef(onet, f_k, f_c, side, coef):
    """Coefficients along the outer direction of ``x_k - c`` (times w) on the cell's inner
    boundary ``side`` (0: first, 1: last) of the outer-major cell net ``onet``."""
    j = 0 if side == 0 else onet.shape[1] - 1
    for i in range(onet.shape[0]):
        coef[i] = onet[i, j, f_k] - f_c * onet[i, j, 3]


@njit(cache=True)
def _roots_at(pn, fk, fc, kinds, nf, sigma, ia, ib, coef, rts, rfs):
    """Sorted inner roots of the graph functions on the inner line ``sigma``."""
    n = 0
    for f in range(nf):
        if kinds[f] != 1:
            continue
        r = _inner_root(pn, fk[f], fc[f], sigma, ia, ib, coef)
        if r >= 0.0:
            rts[n] = r
            rfs[n] = f
            n += 1
    for i in range(1, n):
        v = rts[i]
        fv = rfs[i]
        j = i - 1
        while j >= 0 and rts[j] > v:
            rts[j + 1] = rts[j]
            rfs[j + 1] = rfs[j]
            j -= 1
        rts[j + 1] = v
        rfs[j + 1] = fv
    return n


@njit(cache=True)
def _crossing(pn, ka, ca, kb, cb, lo, hi, ia, ib, coef):
    """Outer coordinate in ``[lo, hi]`` where the inner roots of two planes coincide (their
    difference changes sign between ``lo`` and ``hi``), by the Illinois method."""
    ra = _inner_root(pn, ka, ca, lo, ia, ib, coef)
    rb = _inner_root(pn, kb, cb, lo, ia, ib, coef)
    dlo = ra - rb
    ra = _inner_root(pn, ka, ca, hi, ia, ib, coef)
    rb = _inner_root(pn, kb, cb, hi, ia, ib, coef)
    dhi = ra - rb
    side = 0
    x = 0.5 * (lo + hi)
    for _ in range(200):
        x = (lo * dhi - hi * dlo) / (dhi - dlo) if dhi != dlo else 0.5 * (lo + hi)
        if not (lo < x < hi):
            x = 0.5 * (lo + hi)
        ra = _inner_root(pn, ka, ca, x, ia, ib, coef)
        rb = _inner_root(pn, kb, cb, x, ia, ib, coef)
        d = ra - rb
        if d == 0.0 or hi - lo <= 1e-15 * max(1.0, abs(x)):
            return x
        if (d > 0.0) == (dlo > 0.0):
            lo = x
            dlo = d
            if side == -1:
                dhi *= 0.5
            side = -1
        else:
            hi = x
            dhi = d
            if side == 1:
                dlo *= 0.5
            side = 1
    return x


@njit(cache=True)
def _map_st(sigma, tau, swapped):
    if swapped:
        return tau, sigma
    return sigma, tau


@njit(cache=True)
def _integrate_cell(pnet, pn, onet, oa, ob, ia, ib, swapped, fk, fc, fplane, kinds, nf,
                    origin, h, shape, GX, GW, rule,
                    out_st, out_x, out_w, out_n, out_e,
                    trim_x, trim_w, trim_my, trim_plane, trim_st, counts):
    """Iterated Gauss quadrature of a cell whose functions are all graphs over, or lines
    across, the outer direction (see the module docstring)."""
    po = onet.shape[0] - 1
    qi = pn.shape[1] - 1
    ocoef = np.empty(po + 1)
    icoef = np.empty(qi + 1)
    rr = np.empty(MAX_ROOTS)
    bp = np.empty(4 * MAX_ROOTS)
    nbp = 0
    bp[nbp] = oa
    nbp += 1
    bp[nbp] = ob
    nbp += 1
    vroot = np.empty(MAX_ROOTS)
    vfunc = np.empty(MAX_ROOTS, np.int64)
    nv = 0
    for f in range(nf):
        for side in range(2):
            if kinds[f] == 2 and side == 1:
                continue
            _boundary_coef(onet, fk[f], fc[f], side, ocoef)
            n = univariate_roots(ocoef, rr)
            for r in range(n):
                x = oa + rr[r] * (ob - oa)
                if nbp < bp.shape[0]:
                    bp[nbp] = x
                    nbp += 1
                if kinds[f] == 2 and nv < MAX_ROOTS:
                    vroot[nv] = x
                    vfunc[nv] = f
                    nv += 1
    bp[:nbp].sort()
    # crossings of graph roots of planes of different axes
    K = 8
    extra = np.empty(4 * MAX_ROOTS)
    nextra = 0
    for iv in range(nbp - 1):
        x0 = bp[iv]
        x1 = bp[iv + 1]
        if x1 - x0 <= 1e-14:
            continue
        for a in range(nf):
            if kinds[a] != 1:
                continue
            for b in range(a + 1, nf):
                if kinds[b] != 1 or fk[a] == fk[b]:
                    continue
                prev_d = 0.0
                prev_x = 0.0
                ok = True
                for k in range(K + 1):
                    if k == 0:
                        x = x0 + 1e-12 * (x1 - x0)
                    elif k == K:
                        x = x1 - 1e-12 * (x1 - x0)
                    else:
                        x = x0 + (x1 - x0) * k / K
                    ra = _inner_root(pn, fk[a], fc[a], x, ia, ib, icoef)
                    rb = _inner_root(pn, fk[b], fc[b], x, ia, ib, icoef)
                    if ra < 0.0 or rb < 0.0:
                        ok = False
                        break
                    d = ra - rb
                    if k > 0 and (d > 0.0) != (prev_d > 0.0) and nextra < extra.shape[0]:
                        extra[nextra] = _crossing(pn, fk[a], fc[a], fk[b], fc[b], prev_x, x, ia, ib, icoef)
                        nextra += 1
                    prev_d = d
                    prev_x = x
                if not ok:
                    continue
    allbp = np.empty(nbp + nextra)
    allbp[:nbp] = bp[:nbp]
    allbp[nbp:] = extra[:nextra]
    allbp.sort()
    ijk = np.empty(3, np.int64)
    x = np.empty(3)
    xs = np.empty(3)
    xt = np.empty(3)
    rts = np.empty(MAX_FUNCS)
    rfs = np.empty(MAX_FUNCS, np.int64)
    seg = np.empty(MAX_FUNCS + 2)
    normal = np.empty(3)
    tangent = np.empty(3)
    log_tol = rule[0]
    n_min = int(rule[1])
    n_max = int(rule[2])
    for iv in range(allbp.shape[0] - 1):
        x0 = allbp[iv]
        x1 = allbp[iv + 1]
        if x1 - x0 <= 1e-14:
            continue
        no = gauss_order(x1 - x0, log_tol, n_min, n_max)
        for g in range(no):
            sigma = x0 + GX[no, g] * (x1 - x0)
            wsig = GW[no, g] * (x1 - x0)
            n = _roots_at(pn, fk, fc, kinds, nf, sigma, ia, ib, icoef, rts, rfs)
            seg[0] = ia
            for r in range(n):
                seg[r + 1] = rts[r]
            seg[n + 1] = ib
            for sgi in range(n + 1):
                t0 = seg[sgi]
                t1 = seg[sgi + 1]
                if t1 <= t0:
                    continue
                s, t = _map_st(sigma, 0.5 * (t0 + t1), swapped)
                point_derivs(pnet, s, t, x, xs, xt)
                _element_of(x, origin, h, shape, ijk)
                ni = gauss_order(t1 - t0, log_tol, n_min, n_max)
                for gg in range(ni):
                    s, t = _map_st(sigma, t0 + GX[ni, gg] * (t1 - t0), swapped)
                    _emit_surface(pnet, s, t, wsig * GW[ni, gg] * (t1 - t0), ijk,
                                  out_st, out_x, out_w, out_n, out_e, counts)
            for r in range(n):
                f = rfs[r]
                if fk[f] != 0:
                    continue
                s, t = _map_st(sigma, rts[r], swapped)
                point_derivs(pnet, s, t, x, xs, xt)
                if swapped:
                    xo = xt
                    xi = xs
                else:
                    xo = xs
                    xi = xt
                slope = -xo[0] / xi[0]
                for c in range(3):
                    tangent[c] = xo[c] + xi[c] * slope
                _unit_cross(xs, xt, normal)
                _emit_trim(x, normal, tangent, wsig, fplane[f], s, t,
                           trim_x, trim_w, trim_my, trim_plane, trim_st, counts)
    # trimming lines of planes constant along the inner direction
    for v in range(nv):
        f = vfunc[v]
        if fk[f] != 0:
            continue
        sigma = vroot[v]
        n = _roots_at(pn, fk, fc, kinds, nf, sigma, ia, ib, icoef, rts, rfs)
        seg[0] = ia
        for r in range(n):
            seg[r + 1] = rts[r]
        seg[n + 1] = ib
        for sgi in range(n + 1):
            t0 = seg[sgi]
            t1 = seg[sgi + 1]
            if t1 <= t0:
                continue
            ni = gauss_order(t1 - t0, log_tol, n_min, n_max)
            for gg in range(ni):
                s, t = _map_st(sigma, t0 + GX[ni, gg] * (t1 - t0), swapped)
                point_derivs(pnet, s, t, x, xs, xt)
                xi = xs if swapped else xt
                _unit_cross(xs, xt, normal)
                _emit_trim(x, normal, xi, GW[ni, gg] * (t1 - t0), fplane[f], s, t,
                           trim_x, trim_w, trim_my, trim_plane, trim_st, counts)


@njit(cache=True)
def _unit_cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    n = np.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2)
    if n > 0.0:
        for c in range(3):
            out[c] /= n


@njit(cache=True)
def partition_piece(pnet, origin, h, shape, GX, GW, rule, max_depth,
                    out_st, out_x, out_w, out_n, out_e,
                    trim_x, trim_w, trim_my, trim_plane, trim_st, counts):
    """Split the Bezier piece ``pnet`` by the grid planes and integrate it (module docstring).

    ``GX[n, :n], GW[n, :n]``: n-point Gauss rules on [0, 1]; ``rule`` = (log of the
    tolerance, fewest points, most points) per interval (:func:`gauss_order`). ``counts`` (4,) int64 receives the numbers of surface
    points, trimming points and approximate cells, and an overflow flag (rerun with larger
    buffers).
    """
    p = pnet.shape[0] - 1
    q = pnet.shape[1] - 1
    pnT = np.ascontiguousarray(pnet.transpose(1, 0, 2))
    cap = 2 * max_depth + 8
    nets = np.empty((cap, p + 1, q + 1, 4))
    box = np.empty((cap, 4))
    depth = np.empty(cap, np.int64)
    nets[0] = pnet
    box[0, 0] = 0.0
    box[0, 1] = 1.0
    box[0, 2] = 0.0
    box[0, 3] = 1.0
    depth[0] = 0
    top = 1
    fk = np.empty(MAX_FUNCS, np.int64)
    fc = np.empty(MAX_FUNCS)
    fplane = np.empty(MAX_FUNCS, np.int64)
    kinds = np.empty(MAX_FUNCS, np.int64)
    lo = np.empty(3)
    hi = np.empty(3)
    while top > 0:
        if counts[3] != 0:
            return
        top -= 1
        cnet = nets[top].copy()
        sa = box[top, 0]
        sb = box[top, 1]
        ta = box[top, 2]
        tb = box[top, 3]
        d = depth[top]
        for a in range(3):
            lo[a] = np.inf
            hi[a] = -np.inf
        for i in range(p + 1):
            for j in range(q + 1):
                for a in range(3):
                    v = cnet[i, j, a] / cnet[i, j, 3]
                    lo[a] = min(lo[a], v)
                    hi[a] = max(hi[a], v)
        nf = 0
        too_many = False
        for a in range(3):
            i0 = int(np.floor((lo[a] - origin[a]) / h))
            i1 = int(np.ceil((hi[a] - origin[a]) / h))
            for ip in range(i0, i1 + 1):
                c = origin[a] + ip * h
                if not (lo[a] < c < hi[a]):
                    continue
                pos = True
                neg = True
                for i in range(p + 1):
                    for j in range(q + 1):
                        v = cnet[i, j, a] - c * cnet[i, j, 3]
                        if not v > 0.0:
                            pos = False
                        if not v < 0.0:
                            neg = False
                if pos or neg:
                    continue
                if nf == MAX_FUNCS:
                    too_many = True
                    break
                fk[nf] = a
                fc[nf] = c
                fplane[nf] = ip
                nf += 1
        if nf == 0 and not too_many:
            _emit_cell(pnet, sa, sb, ta, tb, origin, h, shape, GX, GW, rule,
                       out_st, out_x, out_w, out_n, out_e, counts)
            continue
        if not too_many:
            if _classify(cnet, fk, fc, nf, 1, kinds):
                _integrate_cell(pnet, pnet, cnet, sa, sb, ta, tb, False, fk, fc, fplane, kinds, nf,
                                origin, h, shape, GX, GW, rule, out_st, out_x, out_w, out_n, out_e,
                                trim_x, trim_w, trim_my, trim_plane, trim_st, counts)
                continue
            if _classify(cnet, fk, fc, nf, 0, kinds):
                onet = np.ascontiguousarray(cnet.transpose(1, 0, 2))
                _integrate_cell(pnet, pnT, onet, ta, tb, sa, sb, True, fk, fc, fplane, kinds, nf,
                                origin, h, shape, GX, GW, rule, out_st, out_x, out_w, out_n, out_e,
                                trim_x, trim_w, trim_my, trim_plane, trim_st, counts)
                continue
        if d >= max_depth:
            counts[2] += 1
            _emit_cell(pnet, sa, sb, ta, tb, origin, h, shape, GX, GW, rule,
                       out_st, out_x, out_w, out_n, out_e, counts)
            continue
        # split the cell along its longer side (measured on the control net)
        len_s = 0.0
        len_t = 0.0
        for j in range(q + 1):
            dd = 0.0
            for a in range(3):
                dd += (cnet[p, j, a] / cnet[p, j, 3] - cnet[0, j, a] / cnet[0, j, 3]) ** 2
            len_s = max(len_s, dd)
        for i in range(p + 1):
            dd = 0.0
            for a in range(3):
                dd += (cnet[i, q, a] / cnet[i, q, 3] - cnet[i, 0, a] / cnet[i, 0, 3]) ** 2
            len_t = max(len_t, dd)
        axis = 0 if len_s >= len_t else 1
        left, right = _split_net(cnet, axis, 0.5)
        for child in range(2):
            nets[top] = left if child == 0 else right
            if axis == 0:
                ms = 0.5 * (sa + sb)
                box[top, 0] = sa if child == 0 else ms
                box[top, 1] = ms if child == 0 else sb
                box[top, 2] = ta
                box[top, 3] = tb
            else:
                mt = 0.5 * (ta + tb)
                box[top, 0] = sa
                box[top, 1] = sb
                box[top, 2] = ta if child == 0 else mt
                box[top, 3] = mt if child == 0 else tb
            depth[top] = d + 1
            top += 1
