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
the grid element ``(i, j, k)``; per point of a trimming curve on a grid plane ``x_k = c``
of any axis ``k`` (needed for the exact volume rules of cut elements): position, length
weight, the in-plane unit normal pointing out of the solid's section, the axis and the plane
index.

A second grid (``origin2``, ``h2 > 0``) adds its planes to the cuts: every part then lies in
one element of each grid (the contact rule split at the master's element faces,
:mod:`cgfem.contact.rule`). Elements are still those of the first grid, and the second
grid's planes emit no trimming points.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cgfem.embedding._bernstein import _inner_root, _split_net, net_work, point_derivs, univariate_roots
from cgfem.embedding._partition_roots import (_boundary_coef, _classify, _crossing, _line_segments,
                                              _map_st, _root_sum)
from cgfem.geometry._bezier import bezier_derivs

MAX_FUNCS = 16
#: uniform samples of the root difference of two planes per interval (crossing search)
CROSSING_SAMPLES = 32
#: a grid plane closer than TOUCH * h to a cell's whole control net only touches it
TOUCH = 1e-12
#: fewest Gauss points along the outer direction of an interval crossed by a trimming curve
N_CURVE = 5
#: the adaptive check of trimming curves accepts errors of this many times the tolerance
CURVE_TOL_FACTOR = 10.0
#: outer intervals shorter than this (piece coordinates) are not halved further
MIN_INTERVAL = 1e-9
MAX_ROOTS = 64


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
def _material_element(pnet, s, t, origin, h, shape, work, x, xs, xt, ijk):
    """Element of the surface point at ``(s, t)``, looked up a hair (1e-9 h) inside the
    material, so that a surface lying in a grid plane belongs to the element it bounds."""
    point_derivs(pnet, s, t, work, x, xs, xt)
    n = np.empty(3)
    n[0] = xs[1] * xt[2] - xs[2] * xt[1]
    n[1] = xs[2] * xt[0] - xs[0] * xt[2]
    n[2] = xs[0] * xt[1] - xs[1] * xt[0]
    norm = np.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
    y = np.empty(3)
    for a in range(3):
        y[a] = x[a] - (1e-9 * h * n[a] / norm if norm > 0.0 else 0.0)
    _element_of(y, origin, h, shape, ijk)


@njit(cache=True)
def _emit_surface(pnet, s, t, weight, ijk, work, out_st, out_x, out_w, out_n, out_e, counts):
    """Append one surface point at local ``(s, t)`` with parametric weight ``weight``."""
    i = counts[0]
    if i >= out_w.shape[0]:
        counts[3] = 1
        return
    D = work.SKL
    bezier_derivs(pnet, s, t, 1, work, D)
    x = D[0, 0]
    xs = D[1, 0]
    xt = D[0, 1]
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
def _emit_trim(x, normal, tangent, weight, axis, plane, s, t, trim_x, trim_w, trim_m, trim_axis,
               trim_plane, trim_st, counts):
    """Append one point of a trimming curve on the grid plane ``x_axis = origin + plane h``;
    its in-plane unit normal (out of the solid's section) is the surface normal without its
    ``axis`` component, normalised."""
    i = counts[1]
    if i >= trim_w.shape[0]:
        counts[3] = 1
        return
    length = np.sqrt(tangent[0] ** 2 + tangent[1] ** 2 + tangent[2] ** 2)
    norm_in = np.sqrt(max(normal[0] ** 2 + normal[1] ** 2 + normal[2] ** 2 - normal[axis] ** 2, 0.0))
    for c in range(3):
        trim_x[i, c] = x[c]
        trim_m[i, c] = 0.0 if (c == axis or norm_in == 0.0) else normal[c] / norm_in
    trim_w[i] = weight * length
    trim_axis[i] = axis
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
    work = net_work(pnet)
    _material_element(pnet, 0.5 * (sa + sb), 0.5 * (ta + tb), origin, h, shape, work, x, xs, xt, ijk)
    for a in range(ns):
        s = sa + GX[ns, a] * (sb - sa)
        for b in range(nt):
            t = ta + GX[nt, b] * (tb - ta)
            _emit_surface(pnet, s, t, GW[ns, a] * GW[nt, b] * (sb - sa) * (tb - ta), ijk, work,
                          out_st, out_x, out_w, out_n, out_e, counts)


@njit(cache=True)
def _curve_point(pnet, pn, k, c, sigma, ia, ib, swapped, icoef, work, x, xs, xt, tangent):
    """Point, surface derivatives and tangent ``dX/d sigma`` of the curve ``x_k = c`` at the
    outer coordinate ``sigma``; returns the local ``(s, t)``, or (-1, -1) if it has no root."""
    r = _inner_root(pn, k, c, sigma, ia, ib, icoef)
    if r < 0.0:
        return -1.0, -1.0
    s, t = _map_st(sigma, r, swapped)
    point_derivs(pnet, s, t, work, x, xs, xt)
    if swapped:
        xo = xt
        xi = xs
    else:
        xo = xs
        xi = xt
    slope = -xo[k] / xi[k]
    for k in range(3):
        tangent[k] = xo[k] + xi[k] * slope
    return s, t


@njit(cache=True)
def _curve_length(pnet, pn, k, c, a, b, n, ia, ib, swapped, GX, GW, icoef, work):
    """n-point Gauss estimate of the length of the curve ``x_k = c`` over ``[a, b]``."""
    x = np.empty(3)
    xs = np.empty(3)
    xt = np.empty(3)
    tangent = np.empty(3)
    total = 0.0
    for g in range(n):
        s, t = _curve_point(pnet, pn, k, c, a + GX[n, g] * (b - a), ia, ib, swapped, icoef, work, x, xs,
                            xt, tangent)
        if s >= 0.0:
            total += GW[n, g] * (b - a) * np.sqrt(tangent[0] ** 2 + tangent[1] ** 2 + tangent[2] ** 2)
    return total


@njit(cache=True)
def _push_halves(stack, depth, top, a, b, d):
    """Push the halves of ``[a, b]`` (left on top) at depth ``d + 1``; returns the new top."""
    m = 0.5 * (a + b)
    stack[top, 0] = m
    stack[top, 1] = b
    depth[top] = d + 1
    stack[top + 1, 0] = a
    stack[top + 1, 1] = m
    depth[top + 1] = d + 1
    return top + 2


@njit(cache=True)
def _trim_curve(pnet, pn, k, c, plane, x0, x1, ia, ib, swapped, GX, GW, rule, icoef,
                trim_x, trim_w, trim_m, trim_axis, trim_plane, trim_st, counts):
    """Quadrature of the trimming curve ``x_k = c`` over the outer interval ``[x0, x1]``:
    Gauss rules on intervals halved until the length estimates of an interval and its two
    halves agree to ``CURVE_TOL_FACTOR`` times the tolerance (relative)."""
    log_tol = rule[0]
    tol = CURVE_TOL_FACTOR * np.exp(log_tol)
    x = np.empty(3)
    xs = np.empty(3)
    xt = np.empty(3)
    tangent = np.empty(3)
    normal = np.empty(3)
    stack = np.empty((64, 2))
    depth = np.empty(64, np.int64)
    work = net_work(pnet)
    stack[0, 0] = x0
    stack[0, 1] = x1
    depth[0] = 0
    top = 1
    while top > 0:
        top -= 1
        a = stack[top, 0]
        b = stack[top, 1]
        d = depth[top]
        n = max(gauss_order(b - a, log_tol, int(rule[1]), int(rule[2]) - 2), N_CURVE)
        if d < 48 and top + 2 <= 64 and b - a > MIN_INTERVAL:
            coarse = _curve_length(pnet, pn, k, c, a, b, n, ia, ib, swapped, GX, GW, icoef, work)
            fine = _curve_length(pnet, pn, k, c, a, b, n + 2, ia, ib, swapped, GX, GW, icoef, work)
            if abs(coarse - fine) > tol * abs(fine):
                top = _push_halves(stack, depth, top, a, b, d)
                continue
        n = n + 2
        for g in range(n):
            s, t = _curve_point(pnet, pn, k, c, a + GX[n, g] * (b - a), ia, ib, swapped, icoef,
                                work, x, xs, xt, tangent)
            if s < 0.0:
                continue
            _unit_cross(xs, xt, normal)
            _emit_trim(x, normal, tangent, GW[n, g] * (b - a), k, plane, s, t,
                       trim_x, trim_w, trim_m, trim_axis, trim_plane, trim_st, counts)


@njit(cache=True)
def _integrate_cell(pnet, pn, onet, oa, ob, ia, ib, swapped, fk, fc, fplane, kinds, nf,
                    origin, h, shape, GX, GW, rule,
                    out_st, out_x, out_w, out_n, out_e,
                    trim_x, trim_w, trim_m, trim_axis, trim_plane, trim_st, counts):
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
    # crossings of graph roots of planes of different axes, found by sign changes of the
    # root difference at samples that crowd toward the ends (a root may only exist a hair
    # inside its interval)
    samples = np.empty(CROSSING_SAMPLES + 7)
    ends = np.array([1e-12, 1e-9, 1e-6, 1e-3])
    samples[:4] = ends
    for k in range(1, CROSSING_SAMPLES):
        samples[3 + k] = k / CROSSING_SAMPLES
    samples[CROSSING_SAMPLES + 3:] = 1.0 - ends[::-1]
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
                have_prev = False
                prev_d = 0.0
                prev_x = 0.0
                for k in range(samples.shape[0]):
                    x = x0 + (x1 - x0) * samples[k]
                    ra = _inner_root(pn, fk[a], fc[a], x, ia, ib, icoef)
                    rb = _inner_root(pn, fk[b], fc[b], x, ia, ib, icoef)
                    if ra < 0.0 or rb < 0.0:
                        continue  # a root at the very end of its interval of existence
                    d = ra - rb
                    if have_prev and (d > 0.0) != (prev_d > 0.0) and nextra < extra.shape[0]:
                        extra[nextra] = _crossing(pn, fk[a], fc[a], fk[b], fc[b], prev_x, x, ia, ib, icoef)
                        nextra += 1
                    have_prev = True
                    prev_d = d
                    prev_x = x
    allbp = np.empty(nbp + nextra)
    allbp[:nbp] = bp[:nbp]
    allbp[nbp:] = extra[:nextra]
    allbp.sort()
    ijk = np.empty(3, np.int64)
    work = net_work(pnet)
    x = np.empty(3)
    xs = np.empty(3)
    xt = np.empty(3)
    rts = np.empty(MAX_FUNCS)
    rfs = np.empty(MAX_FUNCS, np.int64)
    seg = np.empty(MAX_FUNCS + 2)
    normal = np.empty(3)
    log_tol = rule[0]
    n_min = int(rule[1])
    n_max = int(rule[2])
    tol_roots = CURVE_TOL_FACTOR * np.exp(log_tol)
    istack = np.empty((64, 2))
    idepth = np.empty(64, np.int64)
    for iv in range(allbp.shape[0] - 1):
        if allbp[iv + 1] - allbp[iv] <= 1e-14:
            continue
        # adaptive: an interval is accepted when n- and (n+2)-point rules agree on the
        # integral of the inner roots (what splits the surface between elements)
        istack[0, 0] = allbp[iv]
        istack[0, 1] = allbp[iv + 1]
        idepth[0] = 0
        itop = 1
        while itop > 0:
            itop -= 1
            x0 = istack[itop, 0]
            x1 = istack[itop, 1]
            dd = idepth[itop]
            span = x1 - x0
            for f in range(nf):
                if kinds[f] != 1:
                    continue
                r0 = _inner_root(pn, fk[f], fc[f], x0 + 1e-9 * (x1 - x0), ia, ib, icoef)
                r1 = _inner_root(pn, fk[f], fc[f], x1 - 1e-9 * (x1 - x0), ia, ib, icoef)
                if r0 >= 0.0 and r1 >= 0.0:
                    span = max(span, abs(r1 - r0))
            no = gauss_order(span, log_tol, n_min, n_max - 2)
            if dd < 48 and itop + 2 <= 64 and x1 - x0 > MIN_INTERVAL:
                lo_sum = _root_sum(pn, fk, fc, kinds, nf, x0, x1, no, GX, GW, ia, ib, icoef, rts, rfs)
                hi_sum = _root_sum(pn, fk, fc, kinds, nf, x0, x1, no + 2, GX, GW, ia, ib, icoef, rts, rfs)
                if abs(lo_sum - hi_sum) > tol_roots * (x1 - x0):
                    itop = _push_halves(istack, idepth, itop, x0, x1, dd)
                    continue
            no = no + 2
            for g in range(no):
                sigma = x0 + GX[no, g] * (x1 - x0)
                wsig = GW[no, g] * (x1 - x0)
                n = _line_segments(pn, fk, fc, kinds, nf, sigma, ia, ib, icoef, rts, rfs, seg)
                for sgi in range(n + 1):
                    t0 = seg[sgi]
                    t1 = seg[sgi + 1]
                    if t1 <= t0:
                        continue
                    s, t = _map_st(sigma, 0.5 * (t0 + t1), swapped)
                    _material_element(pnet, s, t, origin, h, shape, work, x, xs, xt, ijk)
                    ni = gauss_order(t1 - t0, log_tol, n_min, n_max)
                    for gg in range(ni):
                        s, t = _map_st(sigma, t0 + GX[ni, gg] * (t1 - t0), swapped)
                        _emit_surface(pnet, s, t, wsig * GW[ni, gg] * (t1 - t0), ijk, work,
                                      out_st, out_x, out_w, out_n, out_e, counts)
        # trimming curves on the grid planes, each integrated adaptively
        x0 = allbp[iv]
        x1 = allbp[iv + 1]
        xm = 0.5 * (x0 + x1)
        for f in range(nf):
            if kinds[f] != 1 or fplane[f] < 0:
                continue
            if _inner_root(pn, fk[f], fc[f], xm, ia, ib, icoef) < 0.0:
                continue
            _trim_curve(pnet, pn, fk[f], fc[f], fplane[f], x0, x1, ia, ib, swapped, GX, GW, rule, icoef,
                        trim_x, trim_w, trim_m, trim_axis, trim_plane, trim_st, counts)
    # trimming lines of planes constant along the inner direction
    for v in range(nv):
        f = vfunc[v]
        if fplane[f] < 0:
            continue
        sigma = vroot[v]
        n = _line_segments(pn, fk, fc, kinds, nf, sigma, ia, ib, icoef, rts, rfs, seg)
        for sgi in range(n + 1):
            t0 = seg[sgi]
            t1 = seg[sgi + 1]
            if t1 <= t0:
                continue
            ni = gauss_order(t1 - t0, log_tol, n_min, n_max)
            for gg in range(ni):
                s, t = _map_st(sigma, t0 + GX[ni, gg] * (t1 - t0), swapped)
                point_derivs(pnet, s, t, work, x, xs, xt)
                xi = xs if swapped else xt
                _unit_cross(xs, xt, normal)
                _emit_trim(x, normal, xi, GW[ni, gg] * (t1 - t0), fk[f], fplane[f], s, t,
                           trim_x, trim_w, trim_m, trim_axis, trim_plane, trim_st, counts)


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
def _cutting_planes(cnet, lo, hi, og, hg, second, origin, h, touch, fk, fc, fplane, nf):
    """Append to ``fk, fc, fplane`` (from ``nf``) the planes ``x_a = og_a + i hg`` of one grid
    that cut the cell of control net ``cnet`` (bounding box ``lo, hi``); a plane of the
    ``second`` grid gets ``fplane = -1`` and is skipped where it coincides (within
    ``touch``) with a plane of the first grid ``(origin, h)``. Returns ``(nf, too_many)``."""
    p = cnet.shape[0] - 1
    q = cnet.shape[1] - 1
    for a in range(3):
        i0 = int(np.floor((lo[a] - og[a]) / hg))
        i1 = int(np.ceil((hi[a] - og[a]) / hg))
        for ip in range(i0, i1 + 1):
            c = og[a] + ip * hg
            if not (lo[a] + touch < c < hi[a] - touch):
                continue
            if second:
                near = origin[a] + np.floor((c - origin[a]) / h + 0.5) * h
                if abs(c - near) <= touch:
                    continue
            # a plane that only touches the control net (within ``touch``, e.g. tangent
            # to the surface along a knot line) does not cut the cell
            pos = True
            neg = True
            for i in range(p + 1):
                for j in range(q + 1):
                    v = cnet[i, j, a] / cnet[i, j, 3] - c
                    if not v > -touch:
                        pos = False
                    if not v < touch:
                        neg = False
            if pos or neg:
                continue
            if nf == MAX_FUNCS:
                return nf, True
            fk[nf] = a
            fc[nf] = c
            fplane[nf] = -1 if second else ip
            nf += 1
    return nf, False


@njit(cache=True)
def partition_piece(pnet, origin, h, shape, origin2, h2, GX, GW, rule, max_depth,
                    out_st, out_x, out_w, out_n, out_e,
                    trim_x, trim_w, trim_m, trim_axis, trim_plane, trim_st, counts):
    """Split the Bezier piece ``pnet`` by the grid planes and integrate it (module docstring);
    ``origin2`` (3,), ``h2``: a second grid whose planes also cut (none if ``h2 <= 0``).

    ``GX[n, :n], GW[n, :n]``: n-point Gauss rules on [0, 1]; ``rule`` = (log of the
    tolerance, fewest points, most points) per interval (:func:`gauss_order`). ``counts`` (4,) int64 receives the numbers of surface
    points, trimming points and approximate cells, and an overflow flag (rerun with larger
    buffers).
    """
    p = pnet.shape[0] - 1
    q = pnet.shape[1] - 1
    # writable copies of both orientations (the given net may be read-only): one compiled
    # version of _integrate_cell and of _emit_cell's callees serves both
    pnW = pnet.copy()
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
    touch = TOUCH * h
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
        for g in range(2):
            og = origin if g == 0 else origin2
            hg = h if g == 0 else h2
            if hg <= 0.0 or too_many:
                continue
            nf, too_many = _cutting_planes(cnet, lo, hi, og, hg, g == 1, origin, h, touch, fk, fc, fplane, nf)
        if nf == 0 and not too_many:
            _emit_cell(pnW, sa, sb, ta, tb, origin, h, shape, GX, GW, rule,
                       out_st, out_x, out_w, out_n, out_e, counts)
            continue
        if not too_many:
            if _classify(cnet, fk, fc, nf, 1, kinds):
                _integrate_cell(pnW, pnW, cnet, sa, sb, ta, tb, False, fk, fc, fplane, kinds, nf,
                                origin, h, shape, GX, GW, rule, out_st, out_x, out_w, out_n, out_e,
                                trim_x, trim_w, trim_m, trim_axis, trim_plane, trim_st, counts)
                continue
            if _classify(cnet, fk, fc, nf, 0, kinds):
                onet = np.ascontiguousarray(cnet.transpose(1, 0, 2))
                _integrate_cell(pnW, pnT, onet, ta, tb, sa, sb, True, fk, fc, fplane, kinds, nf,
                                origin, h, shape, GX, GW, rule, out_st, out_x, out_w, out_n, out_e,
                                trim_x, trim_w, trim_m, trim_axis, trim_plane, trim_st, counts)
                continue
        if d >= max_depth:
            counts[2] += 1
            _emit_cell(pnW, sa, sb, ta, tb, origin, h, shape, GX, GW, rule,
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
