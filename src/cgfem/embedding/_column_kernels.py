"""Numba kernels of the positive volume rules of cut elements (:mod:`cgfem.embedding.columns`).

Per cut element: the exact column rule of its material part (positive, every point in the
material), then Caratheodory recombination to at most ``(degree + 1)^3`` points with the same
moments, the tensor Legendre polynomials of degree <= ``degree`` in each variable. The
degree is an argument of every kernel that needs it; Gauss tables come from the caller.
Arrays are flat; the Python layer groups the inputs.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from cgfem._parallel import parallel_kernel
from cgfem.embedding import _cone_kernels as _cones
from cgfem.embedding._face_kernels import face_key, line_intervals

#: a normal component of this size (or less) of the wrong sign still counts as a graph
SIGN_EPS = 1e-12
#: relative rank threshold of the elimination in the recombination
RANK_TOL = 1e-12
#: accepted moment error of the recombined rule, relative to the element's material measure
MOMENT_TOL = 1e-10
#: most elements in the stack of :func:`_stack_rule`
MAX_STACK = 8

OK, NO_DIRECTION, NOT_RECOMBINED, CONES = 0, 1, 2, 3


@njit(cache=True)
def legendre_row(xi, degree, out):
    """The ``(degree + 1)^3`` tensor Legendre values ``L_a(xi0) L_b(xi1) L_c(xi2)``,
    ``a, b, c <= degree``, at local coordinates ``xi`` (3,) -> ``out``, ``a`` slowest.
    ``L_2 = (3 x^2 - 1) / 2`` is written out, higher ones follow Bonnet's recurrence
    ``(k + 1) L_{k+1} = (2 k + 1) x L_k - k L_{k-1}``."""
    n = degree + 1
    L = np.empty((3, max(n, 3)))
    for d in range(3):
        L[d, 0] = 1.0
        L[d, 1] = xi[d]
        L[d, 2] = 1.5 * xi[d] * xi[d] - 0.5
        for k in range(2, degree):
            L[d, k + 1] = ((2 * k + 1) * xi[d] * L[d, k] - k * L[d, k - 1]) / (k + 1)
    k = 0
    for a in range(n):
        for b in range(n):
            for c in range(n):
                out[k] = L[0, a] * L[1, b] * L[2, c]
                k += 1


@njit(cache=True)
def _null_space_svd(phi, rows, n, tol):
    """Orthonormal null vectors (f, n) of the matrix whose columns are ``phi[rows[:n]]``:
    the left singular vectors of its transpose beyond the singular values above ``tol``
    times the largest (the robust, slower variant of :func:`_null_space`)."""
    d = phi.shape[1]
    M = np.empty((n, d))
    for j in range(n):
        for r in range(d):
            M[j, r] = phi[rows[j], r]
    U, S, _ = np.linalg.svd(M)
    rank = 0
    for r in range(S.shape[0]):
        if S[r] > tol * S[0]:
            rank += 1
    return np.ascontiguousarray(U[:, rank:].T)


@njit(cache=True)
def _null_space(phi, rows, n, tol):
    """Null vectors (f, n) of the matrix whose columns are ``phi[rows[:n]]``: Gauss-Jordan
    elimination with complete pivoting (stable on the nearly dependent columns of clustered
    points, where partial pivoting loses accuracy in the moments; cheaper than an SVD),
    stopped when the largest remaining entry is below ``tol`` times the largest entry; one
    vector per free column."""
    d = phi.shape[1]
    M = np.empty((d, n))
    scale = 0.0
    for j in range(n):
        for r in range(d):
            M[r, j] = phi[rows[j], r]
            scale = max(scale, abs(M[r, j]))
    perm = np.arange(n)
    rank = 0
    for step in range(min(d, n)):
        best = 0.0
        br = step
        bc = step
        for r in range(step, d):
            for c in range(step, n):
                if abs(M[r, c]) > best:
                    best = abs(M[r, c])
                    br = r
                    bc = c
        if best <= tol * scale:
            break
        for j in range(n):
            M[step, j], M[br, j] = M[br, j], M[step, j]
        for r in range(d):
            M[r, step], M[r, bc] = M[r, bc], M[r, step]
        perm[step], perm[bc] = perm[bc], perm[step]
        pivot = M[step, step]
        # columns before ``step`` are unit vectors already: the pivot row is zero there
        for j in range(step, n):
            M[step, j] /= pivot
        for r in range(d):
            f = M[r, step]
            if r != step and f != 0.0:
                for j in range(step, n):
                    M[r, j] -= f * M[step, j]
        rank += 1
    V = np.zeros((n - rank, n))
    for k in range(n - rank):
        V[k, perm[rank + k]] = 1.0
        for r in range(rank):
            V[k, perm[r]] = -M[r, rank + k]
    return V


@njit(cache=True)
def caratheodory(phi, rows, n, w, robust=False):
    """Make at most ``rank`` of the positive weights ``w[:n]`` of the points ``rows[:n]``
    (moment vectors ``phi[rows]``) nonzero, keeping ``sum w phi`` and ``w >= 0``: each null
    vector of the moment matrix moves the weights until one of them vanishes."""
    if n <= 1:
        return
    V = _null_space_svd(phi, rows, n, RANK_TOL) if robust else _null_space(phi, rows, n, RANK_TOL)
    for k in range(V.shape[0]):
        v = V[k]
        positive = False
        for i in range(n):
            if v[i] > 0.0:
                positive = True
                break
        if not positive:
            for i in range(n):
                v[i] = -v[i]
        alpha = np.inf
        drop = -1
        for i in range(n):
            if v[i] > 0.0 and w[i] / v[i] < alpha:
                alpha = w[i] / v[i]
                drop = i
        if drop < 0:
            continue
        for i in range(n):
            w[i] = max(w[i] - alpha * v[i], 0.0)
        w[drop] = 0.0
        for j in range(k + 1, V.shape[0]):
            f = V[j, drop] / v[drop]
            if f != 0.0:
                for i in range(n):
                    V[j, i] -= f * v[i]
            V[j, drop] = 0.0


@njit(cache=True)
def recombine(phi, w, robust=False):
    """Positive weights ``w`` (N,) of points with moment vectors ``phi`` (N, d) -> weights
    with at most d nonzero and the same moments (in place). Groups of points are recombined
    first (2 d groups, each represented by its weighted mean), which halves the support per
    round at the cost of one small elimination."""
    N, d = phi.shape
    idx = np.flatnonzero(w > 0.0)
    while idx.size > 2 * d:
        G = 2 * d
        bounds = np.empty(G + 1, np.int64)
        for g in range(G + 1):
            bounds[g] = (g * idx.size) // G
        mean = np.zeros((G, d))
        W = np.zeros(G)
        for g in range(G):
            for t in range(bounds[g], bounds[g + 1]):
                i = idx[t]
                W[g] += w[i]
                for r in range(d):
                    mean[g, r] += w[i] * phi[i, r]
            for r in range(d):
                mean[g, r] /= W[g]
        Wn = W.copy()
        caratheodory(mean, np.arange(G), G, Wn, robust)
        for g in range(G):
            f = Wn[g] / W[g]
            for t in range(bounds[g], bounds[g + 1]):
                w[idx[t]] *= f
        idx = np.flatnonzero(w > 0.0)
    wi = w[idx].copy()
    caratheodory(phi, idx, idx.size, wi, robust)
    for t in range(idx.size):
        w[idx[t]] = wi[t]


@njit(cache=True)
def moments(phi, w):
    """``sum_i w_i phi_i`` (d,)."""
    out = np.zeros(phi.shape[1])
    for i in range(w.shape[0]):
        for r in range(phi.shape[1]):
            out[r] += w[i] * phi[i, r]
    return out


@njit(cache=True)
def recombine_checked(phi, w, full):
    """:func:`recombine` of the weights ``w`` with moments ``full`` using the fast null
    vectors, checked: if the moments moved by more than ``MOMENT_TOL`` of the measure
    ``full[0]``, again with the SVD ones. Returns the new weights and whether the check
    passed (``w`` itself is kept)."""
    for attempt in range(2):
        out = w.copy()
        recombine(phi, out, attempt == 1)
        got = moments(phi, out)
        err = 0.0
        for r in range(phi.shape[1]):
            err = max(err, abs(got[r] - full[r]))
        if np.count_nonzero(out) <= phi.shape[1] and err <= MOMENT_TOL * max(abs(full[0]), 1e-300):
            return out, True
    return w.copy(), False


@njit(cache=True)
def _graph_sign(normals, weights, first, stop, axis):
    """+1 (or -1) if the ``axis`` component of every normal ``first:stop`` with a positive
    weight is >= -eps (<= eps), preferring the sign of the weighted sum; 0 if neither."""
    lo = np.inf
    hi = -np.inf
    total = 0.0
    for i in range(first, stop):
        if weights[i] > 0.0:
            lo = min(lo, normals[i, axis])
            hi = max(hi, normals[i, axis])
            total += weights[i] * normals[i, axis]
    up = lo >= -SIGN_EPS
    down = hi <= SIGN_EPS
    if up and (total >= 0.0 or not down):
        return 1
    if down:
        return -1
    return 0


@njit(cache=True)
def _one_sign(normals, weights, first, stop, axis, sigma):
    """Whether ``sigma`` times the ``axis`` component of every normal ``first:stop`` with a
    positive weight is >= -eps."""
    for i in range(first, stop):
        if weights[i] > 0.0 and sigma * normals[i, axis] < -SIGN_EPS:
            return False
    return True


@njit(cache=True)
def _surface_columns(s_x, s_w, s_n, first, stop, a, sigma, lo, h, gx, gw, x, w, m):
    """Columns along ``a`` between the boundary points ``first:stop`` and the element face
    on the ``-sigma`` side, clipped to the element ``[lo, lo + h]`` (points of elements
    further along a stack give full columns), weighted by ``dA |n_a|``; appended to ``x, w``
    from row ``m``; returns the new row count."""
    for i in range(first, stop):
        if s_w[i] <= 0.0:
            continue
        c0 = lo[a] if sigma > 0 else max(s_x[i, a], lo[a])
        c1 = min(s_x[i, a], lo[a] + h) if sigma > 0 else lo[a] + h
        if c1 <= c0:
            continue
        for g in range(gx.shape[0]):
            x[m, 0] = s_x[i, 0]
            x[m, 1] = s_x[i, 1]
            x[m, 2] = s_x[i, 2]
            x[m, a] = c0 + gx[g] * (c1 - c0)
            w[m] = s_w[i] * abs(s_n[i, a]) * gw[g] * (c1 - c0)
            m += 1
    return m


@njit(cache=True)
def _stack_rule(e_ijk, a, sigma, h, lo, shape, node_shape, element_ids, s_x, s_w, s_n, s_off,
                t_key, l_start, l_off, l_coord, gx, gw):
    """Column rule of a cut element along ``a`` from the boundary points of the *stack* of
    elements above it (``sigma > 0``; below it for ``sigma < 0``), up to the first whose far
    face holds no material: every column ends at its one boundary crossing in the stack,
    so the columns of the points beyond the element are full. Needs every normal of the
    stack to have the sign ``sigma`` along ``a``; empty arrays otherwise."""
    first = np.empty(MAX_STACK, np.int64)
    stop = np.empty(MAX_STACK, np.int64)
    intervals = np.empty((8, 2))
    n_ranges = 0
    total = 0
    cur = e_ijk.copy()
    closed = False
    b = (a + 1) % 3
    for depth in range(MAX_STACK):
        if cur[a] < 0 or cur[a] >= shape[a]:
            break
        eid = (cur[0] * shape[1] + cur[1]) * shape[2] + cur[2]
        r = np.searchsorted(element_ids, eid)
        if r < element_ids.shape[0] and element_ids[r] == eid:
            if not _one_sign(s_n, s_w, s_off[r], s_off[r + 1], a, sigma):
                break
            first[n_ranges] = s_off[r]
            stop[n_ranges] = s_off[r + 1]
            n_ranges += 1
            total += s_off[r + 1] - s_off[r]
        key = face_key(cur, a, sigma, shape)
        t0 = np.searchsorted(t_key, key)
        if t0 == t_key.shape[0] or t_key[t0] != key:
            # no trimming curve: the far face is all material or none, as its edge along b
            nodes = cur.copy()
            nodes[a] += 1 if sigma > 0 else 0
            if line_intervals(l_start, l_off, l_coord, node_shape, b, nodes,
                               lo[b], lo[b] + h, intervals) == 0:
                closed = True
                break
        cur[a] += sigma
    if not closed:
        return np.empty((0, 3)), np.empty(0)
    ng = gx.shape[0]
    x = np.empty((ng * total, 3))
    w = np.empty(ng * total)
    m = 0
    for r in range(n_ranges):
        m = _surface_columns(s_x, s_w, s_n, first[r], stop[r], a, sigma, lo, h, gx, gw, x, w, m)
    return x[:m], w[:m]


@njit(cache=True)
def _column_rule(e_ijk, origin, h, shape, node_shape, element_ids, s_x, s_w, s_n, s_off, row,
                 t_key, t_x, t_w, t_n, l_start, l_off, l_coord, gx, gw):
    """The exact column rule of one cut element: points (N, 3) and positive weights (N,),
    or empty arrays when no axis makes its boundary a graph.

    With the height axis ``a`` along which every outward surface normal has the sign
    ``sigma`` (the boundary piece is a graph with the material on the ``-sigma`` side), the
    material part is the union of the columns from each surface point to the element face
    opposite to ``sigma``, and of the full columns over the material region ``R`` of the
    face on the ``sigma`` side. ``R`` is split the same way in the face plane: strips from
    each trimming point along an in-plane axis ``b`` (whose normal components have one sign
    ``tau``) to the face edge, and full strips over the material intervals of the edge on
    the ``tau`` side (a grid line). Where no in-plane axis makes ``R``'s trimming curves a
    graph, the columns come from the stack of elements instead (:func:`_stack_rule`).
    Columns and strips carry the Gauss rule ``gx, gw`` on [0, 1]; ``n`` points make the rule
    exact for polynomials of degree <= ``2 n - 1`` along them.
    """
    s0 = s_off[row]
    s1 = s_off[row + 1]
    lo = np.empty(3)
    for d in range(3):
        lo[d] = origin[d] + e_ijk[d] * h
    score = np.zeros(3)  # axes by the size of the projected area, largest first
    for d in range(3):
        for i in range(s0, s1):
            score[d] += s_w[i] * s_n[i, d]
    order = np.argsort(-np.abs(score))
    intervals = np.empty((8, 2))
    for oa in range(3):
        a = order[oa]
        sigma = _graph_sign(s_n, s_w, s0, s1, a)
        if sigma == 0:
            continue
        # trims of the face on the sigma side (none on the grid's boundary)
        key = face_key(e_ijk, a, sigma, shape)
        t0 = np.searchsorted(t_key, key)
        t1 = np.searchsorted(t_key, key + 1)
        for ob in range(2):
            b = (a + 1 + ob) % 3
            c = (a + 2 - ob) % 3
            tau = _graph_sign(t_n, t_w, t0, t1, b)
            if tau == 0:
                continue
            # the edge of the face on the tau side, a grid line along c
            nodes = e_ijk.copy()
            nodes[a] += 1 if sigma > 0 else 0
            nodes[b] += 1 if tau > 0 else 0
            n_int = line_intervals(l_start, l_off, l_coord, node_shape, c, nodes,
                                    lo[c], lo[c] + h, intervals)
            ng = gx.shape[0]
            cap = ng * (s1 - s0) + ng * ng * (t1 - t0) + ng * ng * ng * n_int
            x = np.empty((cap, 3))
            w = np.empty(cap)
            # columns under (sigma > 0) or over the surface points
            m = _surface_columns(s_x, s_w, s_n, s0, s1, a, sigma, lo, h, gx, gw, x, w, 0)
            # the face region R: 2D points (b, c) with weights, then full columns along a
            n2 = ng * (t1 - t0) + ng * ng * n_int
            p2 = np.empty((n2, 2))
            w2 = np.empty(n2)
            k2 = 0
            for i in range(t0, t1):
                if t_w[i] <= 0.0:
                    continue
                yb = t_x[i, b]
                b0 = lo[b] if tau > 0 else yb
                b1 = yb if tau > 0 else lo[b] + h
                for g in range(ng):
                    p2[k2, 0] = b0 + gx[g] * (b1 - b0)
                    p2[k2, 1] = t_x[i, c]
                    w2[k2] = t_w[i] * abs(t_n[i, b]) * gw[g] * (b1 - b0)
                    k2 += 1
            for r in range(n_int):
                span = intervals[r, 1] - intervals[r, 0]
                for gc in range(ng):
                    for gb in range(ng):
                        p2[k2, 0] = lo[b] + gx[gb] * h
                        p2[k2, 1] = intervals[r, 0] + gx[gc] * span
                        w2[k2] = gw[gb] * h * gw[gc] * span
                        k2 += 1
            for k in range(k2):
                for g in range(ng):
                    x[m, a] = lo[a] + gx[g] * h
                    x[m, b] = p2[k, 0]
                    x[m, c] = p2[k, 1]
                    w[m] = w2[k] * gw[g] * h
                    m += 1
            return x[:m], w[:m]
        x, w = _stack_rule(e_ijk, a, sigma, h, lo, shape, node_shape, element_ids, s_x, s_w, s_n,
                           s_off, t_key, l_start, l_off, l_coord, gx, gw)
        if w.shape[0] > 0:
            return x, w
    return np.empty((0, 3)), np.empty(0)


@parallel_kernel
def column_rules(element_ids, elements_ijk, origin, h, shape, node_shape, s_x, s_w, s_n, s_off,
                 t_key, t_x, t_w, t_n, l_start, l_off, l_coord, gx, gw, cone_tables, degree, rows,
                 out_x, out_w, out_count, out_status, out_full, out_moments):
    """Positive rules of at most ``M = (degree + 1)^3`` points, with the moments of the
    tensor Legendre polynomials of degree <= ``degree`` per variable, for every cut element
    (ids ``element_ids``, ascending, indices ``elements_ijk``; boundary points of row ``e``
    are ``s_off[e]:s_off[e + 1]``). ``gx, gw``: Gauss rule on [0, 1] of the columns and
    strips (exact for ``degree`` along them); ``cone_tables``: the radial and edge rules of
    :func:`cgfem.embedding._cone_kernels.cone_rule`. Only the rows ``rows`` (r,) of
    ``element_ids`` get rules (the others serve the stacks of :func:`_stack_rule`); row
    ``q`` of the outputs is element ``rows[q]``: ``out_x`` (r, M, 3), ``out_w`` (r, M),
    ``out_count`` (r,), ``out_status`` (r,) OK / CONES / NO_DIRECTION / NOT_RECOMBINED,
    ``out_full`` (r,) the size of the exact column rule and ``out_moments`` (r, M) its
    local Legendre moments."""
    half = 0.5 * h
    n_moments = (degree + 1) ** 3
    for q in prange(rows.shape[0]):
        e = rows[q]
        ijk = elements_ijk[e].copy()
        x, w = _column_rule(ijk, origin, h, shape, node_shape, element_ids, s_x, s_w, s_n, s_off, e,
                            t_key, t_x, t_w, t_n, l_start, l_off, l_coord, gx, gw)
        kind = OK
        if w.shape[0] == 0:
            x, w = _cones.cone_rule(ijk, origin, h, shape, node_shape, s_x, s_w, s_n, s_off[e], s_off[e + 1],
                                    t_key, t_x, t_w, t_n, l_start, l_off, l_coord, cone_tables)
            kind = CONES
        n = w.shape[0]
        out_full[q] = n
        out_count[q] = 0
        if n == 0:
            out_status[q] = NO_DIRECTION
            continue
        centre = np.empty(3)
        for d in range(3):
            centre[d] = origin[d] + (ijk[d] + 0.5) * h
        phi = np.empty((n, n_moments))
        xi = np.empty(3)
        wl = np.empty(n)
        for i in range(n):
            for d in range(3):
                xi[d] = (x[i, d] - centre[d]) / half
            legendre_row(xi, degree, phi[i])
            wl[i] = w[i] / half**3
        full = moments(phi, wl)
        out_moments[q, :] = full
        wl, ok = recombine_checked(phi, wl, full)
        if not ok:
            out_status[q] = NOT_RECOMBINED
            continue
        k = 0
        for i in range(n):
            if wl[i] > 0.0:
                for d in range(3):
                    out_x[q, k, d] = x[i, d]
                out_w[q, k] = wl[i] * half**3
                k += 1
        out_count[q] = k
        out_status[q] = kind


@parallel_kernel
def recombine_groups(x, w, centre, half, offsets, degree, out_w):
    """Caratheodory recombination of every group ``offsets[g]:offsets[g + 1]`` of points
    ``x`` (n, 3) with weights ``w`` (n,) -> ``out_w`` (n,): at most ``(degree + 1)^3``
    positive weights per group with the group's moments of the tensor Legendre polynomials
    of degree <= ``degree`` per variable in the local coordinates ``(x - centre[g]) / half``."""
    n_moments = (degree + 1) ** 3
    for g in prange(offsets.shape[0] - 1):
        a = offsets[g]
        b = offsets[g + 1]
        if b - a <= n_moments:
            for i in range(a, b):
                out_w[i] = w[i]
            continue
        phi = np.empty((b - a, n_moments))
        xi = np.empty(3)
        wl = np.empty(b - a)
        for i in range(a, b):
            for d in range(3):
                xi[d] = (x[i, d] - centre[g, d]) / half
            legendre_row(xi, degree, phi[i - a])
            wl[i - a] = max(w[i], 0.0)
        wl, ok = recombine_checked(phi, wl, moments(phi, wl))
        for i in range(a, b):
            out_w[i] = wl[i - a]  # the group unreduced if the recombination failed
