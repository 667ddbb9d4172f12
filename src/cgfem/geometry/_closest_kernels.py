"""Numba kernels of the closest-point query of :mod:`cgfem.geometry.query` (branch and
bound over the BVH, projected Newton on each candidate leaf; see that module's docstring).

The BVH arrays arrive as one :class:`~cgfem.geometry.bvh.BvhArrays` ``bvh``; a leaf's net is
a view of ``bvh.control`` (:func:`~cgfem.geometry._bezier.leaf_net`), evaluated by
:func:`~cgfem.geometry._bezier.bezier_derivs` into derivative arrays ``(3, 3, 3)`` in the
layout ``D[k, l] = d^{k+l} S / ds^k dt^l``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from cgfem._parallel import parallel_kernel
from cgfem.geometry._bezier import (CHUNK, MAX_NEWTON, STACK, bezier_derivs, bezier_work, clamp01, dist2,
                                    leaf_net, leaf_normal)

#: Newton stops when a step moves less than this in local parameters.
STEP_TOL = 1e-15
#: Samples per direction of the seed grid of the projection.
SEED_GRID = 3


@njit(cache=True)
def _box_distance2(lo, hi, x):
    """Squared distance from ``x`` to the box ``[lo, hi]`` (0 inside)."""
    acc = 0.0
    for c in range(3):
        if x[c] < lo[c]:
            acc += (lo[c] - x[c]) ** 2
        elif x[c] > hi[c]:
            acc += (x[c] - hi[c]) ** 2
    return acc


@njit(cache=True)
def _seed_on_leaf(net, x, work, D):
    """Best ``(s, t)`` of a ``SEED_GRID^2`` grid of samples including the corners."""
    g = SEED_GRID
    best = np.inf
    bs = 0.5
    bt = 0.5
    for i in range(g):
        s = i / (g - 1.0)
        for j in range(g):
            t = j / (g - 1.0)
            bezier_derivs(net, s, t, 0, work, D)
            f = dist2(D[0, 0], x)
            if f < best:
                best = f
                bs = s
                bt = t
    return bs, bt


@njit(cache=True)
def _project_on_leaf(net, x, s, t, work, D, Dn):
    """Projected Newton for ``min |S(s, t) - x|^2`` on ``[0, 1]^2`` from ``(s, t)``.

    Returns ``(s, t, f)``; ``D`` (3, 3, 3) holds the derivatives at the result. ``Dn`` is
    scratch for trial points."""
    bezier_derivs(net, s, t, 2, work, D)
    f = dist2(D[0, 0], x)
    for it in range(MAX_NEWTON):
        r0 = D[0, 0, 0] - x[0]
        r1 = D[0, 0, 1] - x[1]
        r2 = D[0, 0, 2] - x[2]
        gs = D[1, 0, 0] * r0 + D[1, 0, 1] * r1 + D[1, 0, 2] * r2
        gt = D[0, 1, 0] * r0 + D[0, 1, 1] * r1 + D[0, 1, 2] * r2
        a = D[1, 0, 0] ** 2 + D[1, 0, 1] ** 2 + D[1, 0, 2] ** 2
        b = D[1, 0, 0] * D[0, 1, 0] + D[1, 0, 1] * D[0, 1, 1] + D[1, 0, 2] * D[0, 1, 2]
        c = D[0, 1, 0] ** 2 + D[0, 1, 1] ** 2 + D[0, 1, 2] ** 2
        hss = a + D[2, 0, 0] * r0 + D[2, 0, 1] * r1 + D[2, 0, 2] * r2
        hst = b + D[1, 1, 0] * r0 + D[1, 1, 1] * r1 + D[1, 1, 2] * r2
        htt = c + D[0, 2, 0] * r0 + D[0, 2, 1] * r1 + D[0, 2, 2] * r2
        mu = 1e-12 * (a + c) + 1e-300
        free_s = not ((s <= 0.0 and gs > 0.0) or (s >= 1.0 and gs < 0.0))
        free_t = not ((t <= 0.0 and gt > 0.0) or (t >= 1.0 and gt < 0.0))
        ds = 0.0
        dt = 0.0
        newton = False
        if free_s and free_t:
            det = hss * htt - hst * hst
            if hss > 0.0 and htt > 0.0 and det > 1e-12 * hss * htt:
                ds = -(htt * gs - hst * gt) / det
                dt = -(hss * gt - hst * gs) / det
                newton = True
            else:  # not convex here: Gauss-Newton (J^T J, Levenberg-damped)
                aa = a + mu
                cc = c + mu
                det = aa * cc - b * b
                if det <= 0.0:
                    det = aa * cc
                ds = -(cc * gs - b * gt) / det
                dt = -(aa * gt - b * gs) / det
        elif free_s:
            if hss > 1e-12 * a:
                ds = -gs / hss
                newton = True
            else:
                ds = -gs / (a + mu)
        elif free_t:
            if htt > 1e-12 * c:
                dt = -gt / htt
                newton = True
            else:
                dt = -gt / (c + mu)
        else:
            break
        size = max(abs(ds), abs(dt))
        if size > 0.5:
            ds *= 0.5 / size
            dt *= 0.5 / size
            size = 0.5
        if not size > 0.0:
            break
        alpha = 1.0
        accepted = False
        sn = s
        tn = t
        fn = f
        for ls in range(60):
            sn = clamp01(s + alpha * ds)
            tn = clamp01(t + alpha * dt)
            bezier_derivs(net, sn, tn, 2, work, Dn)
            fn = dist2(Dn[0, 0], x)
            # Near a minimum round-off hides the decrease of f: trust small Newton steps.
            if fn <= f or (newton and alpha * size < 1e-6):
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            break
        moved = max(abs(sn - s), abs(tn - t))
        s = sn
        t = tn
        f = fn
        for kk in range(3):
            for ll in range(3 - kk):
                for cc3 in range(3):
                    D[kk, ll, cc3] = Dn[kk, ll, cc3]
        if moved <= STEP_TOL:
            break
    return s, t, f


@njit(cache=True)
def _slab_distance(axis, slab, x):
    """Distance from ``x`` to the slab ``slab[0] <= axis . y <= slab[1]`` (0 inside)."""
    h = axis[0] * x[0] + axis[1] * x[1] + axis[2] * x[2]
    if h < slab[0]:
        return slab[0] - h
    if h > slab[1]:
        return h - slab[1]
    return 0.0


@njit(cache=True)
def _corner_distance(ctrl, off, p, q, x):
    """Smallest distance from ``x`` to the four corner control points of a Bezier leaf (they
    lie on the surface: an upper bound of the distance to the leaf)."""
    best = np.inf
    for r in (off, off + q, off + p * (q + 1), off + p * (q + 1) + q):
        w = ctrl[r, 3]
        d2 = (ctrl[r, 0] / w - x[0]) ** 2 + (ctrl[r, 1] / w - x[1]) ** 2 + (ctrl[r, 2] / w - x[2]) ** 2
        if d2 < best:
            best = d2
    return np.sqrt(best)


@njit(cache=True)
def _closest_point(bvh, x, tie, i, out_leaf, out_st, out_point, out_dist, out_normal, work, D, Dn, E, nrm,
                   stack, cand, cand_lb):
    """Branch and bound for one point ``x``, results into row ``i`` of the outputs (see
    :func:`closest_points_kernel`); the rest is scratch (``cand``, ``cand_lb`` (n_leaf,)).

    Phase 1 walks the tree (nearer child first) and collects the leaves whose lower bound
    (distance to box and slab) is below the upper bound given by the leaves' corners; phase 2
    projects on them in order of lower bound until the bound exceeds the best distance."""
    ub = np.inf
    n_cand = 0
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        lim = ub + tie
        if _box_distance2(bvh.node_lo[node], bvh.node_hi[node], x) > lim * lim:
            continue
        c0 = bvh.node_child[node, 0]
        if c0 >= 0:
            c1 = bvh.node_child[node, 1]
            if (_box_distance2(bvh.node_lo[c0], bvh.node_hi[c0], x)
                    <= _box_distance2(bvh.node_lo[c1], bvh.node_hi[c1], x)):
                stack[sp] = c1
                stack[sp + 1] = c0
            else:
                stack[sp] = c0
                stack[sp + 1] = c1
            sp += 2
            continue
        for k in range(bvh.node_start[node], bvh.node_start[node] + bvh.node_count[node]):
            lb = max(np.sqrt(_box_distance2(bvh.leaf_lo[k], bvh.leaf_hi[k], x)),
                     _slab_distance(bvh.leaf_axis[k], bvh.leaf_slab[k], x))
            if lb > ub + tie:
                continue
            cd = _corner_distance(bvh.control, bvh.leaf_offset[k], bvh.leaf_degree[k, 0], bvh.leaf_degree[k, 1], x)
            if cd < ub:
                ub = cd
            # insertion into the candidates sorted by lower bound
            j = n_cand
            while j > 0 and cand_lb[j - 1] > lb:
                cand[j] = cand[j - 1]
                cand_lb[j] = cand_lb[j - 1]
                j -= 1
            cand[j] = k
            cand_lb[j] = lb
            n_cand += 1
    min_d = np.inf
    best_d = np.inf
    best_cos = -1.0
    best_leaf = -1
    for j in range(n_cand):
        lim = min_d + tie
        if cand_lb[j] > lim:
            break
        k = cand[j]
        net = leaf_net(bvh.control, bvh.leaf_offset[k], bvh.leaf_degree[k, 0], bvh.leaf_degree[k, 1])
        s, t = _seed_on_leaf(net, x, work, D)
        s, t, f = _project_on_leaf(net, x, s, t, work, D, Dn)
        d = np.sqrt(f)
        if d > lim:
            continue
        leaf_normal(net, s, t, D, work, E, nrm)
        if d > 0.0:
            cos = abs((x[0] - D[0, 0, 0]) * nrm[0] + (x[1] - D[0, 0, 1]) * nrm[1]
                      + (x[2] - D[0, 0, 2]) * nrm[2]) / d
        else:
            cos = 1.0
        if d < min_d:
            min_d = d
        if best_leaf < 0 or best_d > min_d + tie or cos > best_cos:
            best_d = d
            best_cos = cos
            best_leaf = k
            out_st[i, 0] = s
            out_st[i, 1] = t
            for c in range(3):
                out_point[i, c] = D[0, 0, c]
                out_normal[i, c] = nrm[c]
    out_leaf[i] = best_leaf
    out_dist[i] = best_d


@parallel_kernel
def closest_points_kernel(bvh, points, tie, out_leaf, out_st, out_point, out_dist, out_normal):
    """Branch and bound over the BVH ``bvh`` (:class:`~cgfem.geometry.bvh.BvhArrays`) for
    every row of ``points`` (n, 3); results into ``out_leaf`` (n,), ``out_st`` (n, 2) local
    parameters, ``out_point`` (n, 3), ``out_dist`` (n,), ``out_normal`` (n, 3). Lower bounds:
    distance to a node's box, to a leaf's box and slab. Candidates within ``tie`` of the
    smallest distance compete by ``|cos|`` of the angle between ``x - foot`` and their normal.
    Parallel over chunks of ``CHUNK`` points."""
    n = points.shape[0]
    n_leaf = bvh.leaf_degree.shape[0]
    for chunk in prange((n + CHUNK - 1) // CHUNK):
        work = bezier_work(bvh.leaf_degree.max())
        D = np.empty((3, 3, 3))
        Dn = np.empty((3, 3, 3))
        E = np.empty((3, 3, 3))
        nrm = np.empty(3)
        stack = np.empty(STACK, dtype=np.int64)
        cand = np.empty(n_leaf, dtype=np.int64)
        cand_lb = np.empty(n_leaf)
        for i in range(chunk * CHUNK, min(n, (chunk + 1) * CHUNK)):
            _closest_point(bvh, points[i], tie, i, out_leaf, out_st, out_point, out_dist, out_normal, work,
                           D, Dn, E, nrm, stack, cand, cand_lb)
