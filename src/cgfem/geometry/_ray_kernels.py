"""Numba kernels of the ray query of :mod:`cgfem.geometry.query` (box and slab tests over
the BVH, subdivision of each leaf's net projected on two planes through the ray, Newton on
the pieces that hold one root; see that module's docstring).

The BVH arrays arrive as one :class:`~cgfem.geometry.bvh.BvhArrays` ``bvh``; derivatives of
a leaf are in the layout ``D[k, l] = d^{k+l} S / ds^k dt^l`` of
:func:`~cgfem.geometry._bezier.bezier_derivs`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from cgfem._parallel import parallel_kernel
from cgfem.geometry._bezier import (CHUNK, MAX_NEWTON, STACK, BezierWork, bezier_derivs, bezier_work, clamp01,
                                    cross_into, dist2, leaf_net, norm3)

#: Roots within this distance (in local parameters) outside a leaf's box are kept.
BOX_TOL = 1e-11
#: Most halvings of a leaf's net.
MAX_DEPTH = 16
#: Largest parameter aspect ratio of a piece of a leaf.
ASPECT = 4.0
#: A Newton root this close (local parameters) to a sub-box belongs to it.
SUB_PAD = 1e-9


class _RayScratch(NamedTuple):
    """Per-thread scratch of :func:`_ray_roots` (``pmax`` the largest leaf degree, ``K`` the
    hits stored per ray)."""

    work: BezierWork
    D: np.ndarray  # (3, 3, 3) derivatives
    nv: np.ndarray  # (3,)
    n1: np.ndarray  # (3,) first plane through the ray
    n2: np.ndarray  # (3,) second plane
    pts: np.ndarray  # (K, 3) hits of the current ray
    nets: np.ndarray  # (MAX_DEPTH + 2, pmax + 1, pmax + 1, 2) stack of projected nets
    boxes: np.ndarray  # (MAX_DEPTH + 2, 4) their parameter boxes
    depth: np.ndarray  # (MAX_DEPTH + 2,) their depths
    left: np.ndarray  # (pmax + 1, pmax + 1, 2)
    angles: np.ndarray  # ((pmax + 1)^2,)
    stack: np.ndarray  # (STACK,) BVH traversal


@njit(cache=True)
def _ray_hits_box(lo, hi, o, d, t_min, t_max):
    """Slab test: does ``o + t d``, ``t_min <= t <= t_max``, meet the box ``[lo, hi]``?"""
    t0 = t_min
    t1 = t_max
    for c in range(3):
        if d[c] == 0.0:
            if o[c] < lo[c] or o[c] > hi[c]:
                return False
        else:
            a = (lo[c] - o[c]) / d[c]
            b = (hi[c] - o[c]) / d[c]
            if a > b:
                a, b = b, a
            if a > t0:
                t0 = a
            if b < t1:
                t1 = b
            if t0 > t1:
                return False
    return True


@njit(cache=True)
def _ray_planes(d, n1, n2):
    """Two unit vectors ``n1``, ``n2`` spanning the plane perpendicular to ``d``."""
    k = 0
    if abs(d[1]) < abs(d[k]):
        k = 1
    if abs(d[2]) < abs(d[k]):
        k = 2
    e = np.zeros(3)
    e[k] = 1.0
    ln = cross_into(d, e, 1.0, n1)
    for c in range(3):
        n1[c] /= ln
    ln = cross_into(d, n1, 1.0, n2)
    for c in range(3):
        n2[c] /= ln


@njit(cache=True)
def _excluded(G, p, q, angles):
    """The net ``G`` (p + 1, q + 1, 2) cannot vanish: its convex hull misses the origin, i.e.
    the directions of its points leave an angular gap larger than pi. Scratch ``angles``
    ((p + 1) (q + 1),)."""
    m = 0
    for i in range(p + 1):
        for j in range(q + 1):
            if G[i, j, 0] == 0.0 and G[i, j, 1] == 0.0:
                return False
            a = np.arctan2(G[i, j, 1], G[i, j, 0])
            k = m
            while k > 0 and angles[k - 1] > a:
                angles[k] = angles[k - 1]
                k -= 1
            angles[k] = a
            m += 1
    gap = 2.0 * np.pi - (angles[m - 1] - angles[0])
    for k in range(1, m):
        gap = max(gap, angles[k] - angles[k - 1])
    return gap > np.pi


@njit(cache=True)
def _injective(G, p, q, tiny):
    """Sufficient test that the planar Bezier map of the net ``G`` is one-to-one: every
    s-difference ``a`` and t-difference ``b`` of the net (the generators of the cones of
    ``G_s`` and ``G_t``) have ``det(a, b)`` of one strict sign. Differences shorter than
    ``tiny`` (a collapsed edge) are skipped."""
    sign = 0
    for i in range(p):
        for j in range(q + 1):
            a0 = G[i + 1, j, 0] - G[i, j, 0]
            a1 = G[i + 1, j, 1] - G[i, j, 1]
            if abs(a0) + abs(a1) <= tiny:
                continue
            for k in range(p + 1):
                for l in range(q):
                    b0 = G[k, l + 1, 0] - G[k, l, 0]
                    b1 = G[k, l + 1, 1] - G[k, l, 1]
                    if abs(b0) + abs(b1) <= tiny:
                        continue
                    det = a0 * b1 - a1 * b0
                    if det > 0.0:
                        if sign < 0:
                            return False
                        sign = 1
                    elif det < 0.0:
                        if sign > 0:
                            return False
                        sign = -1
                    else:
                        return False
    return sign != 0


@njit(cache=True)
def _halve(G, p, q, direction, left, right):
    """de Casteljau at 1/2 of the net ``G`` (p + 1, q + 1, 2) along s (``direction`` 0) or t
    into ``left`` and ``right``."""
    n = p if direction == 0 else q
    m = q if direction == 0 else p
    tmp = np.empty(n + 1)
    for j in range(m + 1):
        for comp in range(2):
            for i in range(n + 1):
                tmp[i] = G[i, j, comp] if direction == 0 else G[j, i, comp]
            for r in range(n + 1):
                if r > 0:
                    for i in range(n - r + 1):
                        tmp[i] = 0.5 * (tmp[i] + tmp[i + 1])
                if direction == 0:
                    left[r, j, comp] = tmp[0]
                    right[n - r, j, comp] = tmp[n - r]
                else:
                    left[j, r, comp] = tmp[0]
                    right[j, n - r, comp] = tmp[n - r]


@njit(cache=True)
def _ray_newton(net, o, d, s, t, work, D, n):
    """Newton on ``S(s, t) - o - tau d = 0`` from ``(s, t)`` (``tau`` from the projection of
    ``S(s, t)`` on the ray). Returns ``(ok, s, t, tau)``; fails when an iterate leaves ``[-0.5, 1.5]^2``.
    Scratch ``n`` (3,)."""
    dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    bezier_derivs(net, s, t, 0, work, D)
    tau = ((D[0, 0, 0] - o[0]) * d[0] + (D[0, 0, 1] - o[1]) * d[1] + (D[0, 0, 2] - o[2]) * d[2]) / dd
    for it in range(MAX_NEWTON):
        bezier_derivs(net, s, t, 1, work, D)
        f0 = o[0] + tau * d[0] - D[0, 0, 0]  # -F
        f1 = o[1] + tau * d[1] - D[0, 0, 1]
        f2 = o[2] + tau * d[2] - D[0, 0, 2]
        # J = [S_s, S_t, -d]: Cramer's rule for J y = -F
        cross_into(D[1, 0], D[0, 1], 1.0, n)
        det = -(n[0] * d[0] + n[1] * d[1] + n[2] * d[2])
        scale = norm3(D[1, 0]) * norm3(D[0, 1]) * np.sqrt(dd)
        if not abs(det) > 1e-14 * scale:
            return False, s, t, tau
        bx = -(D[0, 1, 1] * d[2] - D[0, 1, 2] * d[1])  # S_t x (-d)
        by = -(D[0, 1, 2] * d[0] - D[0, 1, 0] * d[2])
        bz = -(D[0, 1, 0] * d[1] - D[0, 1, 1] * d[0])
        y0 = (f0 * bx + f1 * by + f2 * bz) / det
        cx = -(f1 * d[2] - f2 * d[1])  # (-F) x (-d)
        cy = -(f2 * d[0] - f0 * d[2])
        cz = -(f0 * d[1] - f1 * d[0])
        y1 = (D[1, 0, 0] * cx + D[1, 0, 1] * cy + D[1, 0, 2] * cz) / det
        ex = D[0, 1, 1] * f2 - D[0, 1, 2] * f1  # S_t x (-F)
        ey = D[0, 1, 2] * f0 - D[0, 1, 0] * f2
        ez = D[0, 1, 0] * f1 - D[0, 1, 1] * f0
        y2 = (D[1, 0, 0] * ex + D[1, 0, 1] * ey + D[1, 0, 2] * ez) / det
        s += y0
        t += y1
        tau += y2
        if not (-0.5 <= s <= 1.5 and -0.5 <= t <= 1.5):  # heading away from this leaf
            return False, s, t, tau
        if max(abs(y0), abs(y1)) <= 1e-14:
            size = norm3(D[1, 0]) + norm3(D[0, 1])
            bezier_derivs(net, s, t, 0, work, D)
            res = np.sqrt((o[0] + tau * d[0] - D[0, 0, 0]) ** 2 + (o[1] + tau * d[1] - D[0, 0, 1]) ** 2
                          + (o[2] + tau * d[2] - D[0, 0, 2]) ** 2)
            return res <= 1e-9 * size, s, t, tau
    return False, s, t, tau


@njit(cache=True)
def _ray_slab(axis, slab, o, d, t_min, t_max):
    """Does ``o + t d``, ``t_min <= t <= t_max``, meet the slab ``slab[0] <= axis . y <= slab[1]``?"""
    h = axis[0] * o[0] + axis[1] * o[1] + axis[2] * o[2]
    rate = axis[0] * d[0] + axis[1] * d[1] + axis[2] * d[2]
    if rate == 0.0:
        return slab[0] <= h <= slab[1]
    a = (slab[0] - h) / rate
    b = (slab[1] - h) / rate
    if a > b:
        a, b = b, a
    return max(a, t_min) <= min(b, t_max)


@parallel_kernel
def ray_kernel(bvh, origins, directions, t_min, t_max, merge, out_t, out_leaf, out_st, out_count):
    """All roots of every ray ``origins[i] + t directions[i]`` (n, 3) with the leaves of
    ``bvh`` (:class:`~cgfem.geometry.bvh.BvhArrays`) into ``out_t``, ``out_leaf``,
    ``out_st`` (n, K[, 2]) sorted by ``t``; ``out_count`` (n,) their number (larger than K
    when the buffers were too small: only K are stored then). Parallel over chunks of
    ``CHUNK`` rays."""
    n = origins.shape[0]
    K = out_t.shape[1]
    pmax = bvh.leaf_degree.max()
    for chunk in prange((n + CHUNK - 1) // CHUNK):
        scratch = _RayScratch(bezier_work(pmax), np.empty((3, 3, 3)), np.empty(3), np.empty(3), np.empty(3),
                              np.empty((K, 3)), np.empty((MAX_DEPTH + 2, pmax + 1, pmax + 1, 2)),
                              np.empty((MAX_DEPTH + 2, 4)), np.empty(MAX_DEPTH + 2, dtype=np.int64),
                              np.empty((pmax + 1, pmax + 1, 2)), np.empty((pmax + 1) * (pmax + 1)),
                              np.empty(STACK, dtype=np.int64))
        for i in range(chunk * CHUNK, min(n, (chunk + 1) * CHUNK)):
            _ray_roots(bvh, origins[i], directions[i], t_min, t_max, merge, i, out_t, out_leaf, out_st,
                       out_count, scratch)


@njit(cache=True)
def _ray_roots(bvh, o, d, t_min, t_max, merge, i, out_t, out_leaf, out_st, out_count, scratch):
    """The roots of one ray into row ``i`` of the outputs (see :func:`ray_kernel`);
    ``scratch`` a :class:`_RayScratch`.

    In a leaf that the ray meets (box and slab tests), the homogeneous net is projected on
    two planes through the ray, ``G_ij = (n_k . (P_ij - o)) w_ij`` (a polynomial Bezier map
    whose zeros are the hits), and subdivided (de Casteljau) until a sub-box is excluded (a
    component of ``G`` has one sign) or ``G`` is one-to-one there (:func:`_injective`); then
    Newton from the sub-box centre (or its corners) finds its root."""
    work, D, nv, n1, n2, pts, nets, boxes, depth, left, angles, stack = scratch
    K = out_t.shape[1]
    _ray_planes(d, n1, n2)
    o1 = n1[0] * o[0] + n1[1] * o[1] + n1[2] * o[2]
    o2 = n2[0] * o[0] + n2[1] * o[1] + n2[2] * o[2]
    count = 0
    stored = 0
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if not _ray_hits_box(bvh.node_lo[node], bvh.node_hi[node], o, d, t_min, t_max):
            continue
        if bvh.node_child[node, 0] >= 0:
            stack[sp] = bvh.node_child[node, 1]
            stack[sp + 1] = bvh.node_child[node, 0]
            sp += 2
            continue
        for k in range(bvh.node_start[node], bvh.node_start[node] + bvh.node_count[node]):
            if not _ray_hits_box(bvh.leaf_lo[k], bvh.leaf_hi[k], o, d, t_min, t_max):
                continue
            if not _ray_slab(bvh.leaf_axis[k], bvh.leaf_slab[k], o, d, t_min, t_max):
                continue
            p = bvh.leaf_degree[k, 0]
            q = bvh.leaf_degree[k, 1]
            off = bvh.leaf_offset[k]
            net = leaf_net(bvh.control, off, p, q)
            size = 0.0
            for c in range(3):
                size = max(size, bvh.leaf_hi[k, c] - bvh.leaf_lo[k, c])
            for a in range(p + 1):
                for b in range(q + 1):
                    r = off + a * (q + 1) + b
                    w = bvh.control[r, 3]
                    nets[0, a, b, 0] = n1[0] * bvh.control[r, 0] + n1[1] * bvh.control[r, 1] + n1[2] * bvh.control[r, 2] - o1 * w
                    nets[0, a, b, 1] = n2[0] * bvh.control[r, 0] + n2[1] * bvh.control[r, 1] + n2[2] * bvh.control[r, 2] - o2 * w
            boxes[0, 0] = 0.0
            boxes[0, 1] = 1.0
            boxes[0, 2] = 0.0
            boxes[0, 3] = 1.0
            depth[0] = 0
            top = 1
            while top > 0:
                top -= 1
                G = nets[top]
                if _excluded(G, p, q, angles):
                    continue
                s0 = boxes[top, 0]
                s1 = boxes[top, 1]
                t0 = boxes[top, 2]
                t1 = boxes[top, 3]
                at_limit = depth[top] >= MAX_DEPTH
                if at_limit or _injective(G, p, q, 1e-13 * size):
                    # at most one root here: Newton from the centre (at the depth limit also from the
                    # corners); subdivide further unless it lands inside
                    found = False
                    for attempt in range(5 if at_limit else 1):
                        ss = 0.5 * (s0 + s1) if attempt == 0 else (s0 if attempt % 2 == 1 else s1)
                        tt = 0.5 * (t0 + t1) if attempt == 0 else (t0 if attempt <= 2 else t1)
                        ok, s, t, tau = _ray_newton(net, o, d, ss, tt, work, D, nv)
                        if not ok:
                            continue
                        found = s0 - SUB_PAD <= s <= s1 + SUB_PAD and t0 - SUB_PAD <= t <= t1 + SUB_PAD
                        if (-BOX_TOL <= s <= 1.0 + BOX_TOL and -BOX_TOL <= t <= 1.0 + BOX_TOL
                                and t_min <= tau <= t_max):
                            s = clamp01(s)
                            t = clamp01(t)
                            bezier_derivs(net, s, t, 0, work, D)
                            duplicate = False
                            for h in range(stored):
                                if dist2(pts[h], D[0, 0]) <= merge * merge:
                                    duplicate = True
                            if not duplicate:
                                count += 1
                                if stored < K:
                                    out_t[i, stored] = tau
                                    out_leaf[i, stored] = k
                                    out_st[i, stored, 0] = s
                                    out_st[i, stored, 1] = t
                                    for c in range(3):
                                        pts[stored, c] = D[0, 0, c]
                                    stored += 1
                        if found and not at_limit:
                            break
                    if found or at_limit:
                        continue
                # halve along the direction in which the net is longer, keeping the parameter
                # aspect ratio below ASPECT (so that two roots near a fold get separated)
                ls = 0.0
                lt = 0.0
                for a in range(p + 1):
                    for b in range(q + 1):
                        if a < p:
                            ls += abs(G[a + 1, b, 0] - G[a, b, 0]) + abs(G[a + 1, b, 1] - G[a, b, 1])
                        if b < q:
                            lt += abs(G[a, b + 1, 0] - G[a, b, 0]) + abs(G[a, b + 1, 1] - G[a, b, 1])
                direction = 0 if ls * q >= lt * p else 1
                if s1 - s0 > ASPECT * (t1 - t0):
                    direction = 0
                elif t1 - t0 > ASPECT * (s1 - s0):
                    direction = 1
                _halve(G, p, q, direction, left, nets[top + 1])
                for a in range(p + 1):
                    for b in range(q + 1):
                        for c in range(2):
                            G[a, b, c] = left[a, b, c]
                depth[top + 1] = depth[top] + 1
                depth[top] += 1
                for c in range(4):
                    boxes[top + 1, c] = boxes[top, c]
                if direction == 0:
                    boxes[top, 1] = 0.5 * (s0 + s1)
                    boxes[top + 1, 0] = 0.5 * (s0 + s1)
                else:
                    boxes[top, 3] = 0.5 * (t0 + t1)
                    boxes[top + 1, 2] = 0.5 * (t0 + t1)
                top += 2
    # insertion sort of the stored hits by t
    for a in range(1, stored):
        b = a
        while b > 0 and out_t[i, b - 1] > out_t[i, b]:
            out_t[i, b - 1], out_t[i, b] = out_t[i, b], out_t[i, b - 1]
            out_leaf[i, b - 1], out_leaf[i, b] = out_leaf[i, b], out_leaf[i, b - 1]
            for c in range(2):
                out_st[i, b - 1, c], out_st[i, b, c] = out_st[i, b, c], out_st[i, b - 1, c]
            b -= 1
    out_count[i] = count
