"""Numba kernels of the sub-tetrahedra rule of a cut element (second strategy of
:mod:`cgfem.embedding.columns`).

The material part ``V`` of the element is split into cones from its centroid ``p`` over its
boundary: over every boundary point ``y`` (weight ``dA``, outward normal ``n``) a cone of
height ``(y - p) . n``. These are the curved sub-tetrahedra whose base is the exact surface
(NEFEM-style, each surface cell with the apex), plus straight-sided ones over the material
regions of the element's faces, which are split the same way in 2D: cones from each face
region's centroid over its trimming curves and the material intervals of its edges. The
divergence theorem makes the split exact for any ``V``; the weights are positive exactly
when ``V`` is star-shaped from ``p`` (and every face region from its centroid), and then all
points lie in the material. Centroids come from the boundary too:
``|V| = 1/3 oint (x - o) . n`` and ``int_V (x - o) = 1/4 oint (x - o) ((x - o) . n)`` (in 2D,
1/2 and 1/3).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cgfem.embedding._face_kernels import face_key, line_intervals

#: a cone height below -HEIGHT_EPS * h is a negative weight (not star-shaped)
HEIGHT_EPS = 1e-12


def _gauss01(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n-point Gauss-Legendre rule on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def radial_points(degree: int) -> tuple[int, int, int]:
    """Gauss points ``(3D radial, 2D radial, edge)`` for the moments of degree <= ``degree``
    per variable (total degree ``3 degree``): ``s^2 f(s)`` of degree ``3 degree + 2`` along
    the 3D cones, ``s f(s)`` of degree ``3 degree + 1`` along the 2D cones, ``3 degree`` on
    the edge intervals; ``n`` points integrate degree ``2 n - 1``. Degree 2: (5, 4, 4)."""
    return (3 * degree + 2) // 2 + 1, (3 * degree + 1) // 2 + 1, (3 * degree) // 2 + 1


def cone_tables(degree: int) -> tuple[np.ndarray, ...]:
    """The rules on [0, 1] of :func:`radial_points` as the tuple ``(g3, gw3, g2, gw2, ge,
    gwe)`` that :func:`cone_rule` takes."""
    n3, n2, ne = radial_points(degree)
    return (*_gauss01(n3), *_gauss01(n2), *_gauss01(ne))


@njit(cache=True)
def _append(x, w, n, first, stop, out_x, out_w, out_n, k):
    """Append the rows ``first:stop`` of positive weight to ``out_*`` from row ``k``;
    returns the new row count."""
    for i in range(first, stop):
        if w[i] > 0.0:
            for d in range(3):
                out_x[k, d] = x[i, d]
                out_n[k, d] = n[i, d]
            out_w[k] = w[i]
            k += 1
    return k


@njit(cache=True)
def _centroid(z, wz, mz, k, o, dim):
    """Measure and centroid of the region whose boundary rule is ``z, wz, mz`` (first ``k``
    rows), from ``oint (x - o) . n = dim |R|`` and ``oint (x - o)((x - o) . n) =
    (dim + 1) int_R (x - o)``."""
    measure = 0.0
    first = np.zeros(3)
    for i in range(k):
        height = 0.0
        for d in range(3):
            height += (z[i, d] - o[d]) * mz[i, d]
        measure += wz[i] * height / dim
        for d in range(3):
            first[d] += wz[i] * height * (z[i, d] - o[d]) / (dim + 1)
    q = np.empty(3)
    for d in range(3):
        q[d] = o[d] + (first[d] / measure if measure > 0.0 else 0.0)
    return measure, q


@njit(cache=True)
def _cones(z, wz, mz, k, q, gr, gwr, power, tol):
    """Cones from ``q`` over the boundary rule ``z, wz, mz`` (first ``k`` rows) with the
    radial rule ``gr, gwr`` and the radial weight ``s^power`` -> points, weights; empty
    arrays if a cone height is below ``-tol`` (the region is not star-shaped from ``q``)."""
    n = gr.shape[0]
    x = np.empty((k * n, 3))
    w = np.empty(k * n)
    m = 0
    for i in range(k):
        height = 0.0
        for d in range(3):
            height += (z[i, d] - q[d]) * mz[i, d]
        if height < -tol:
            return np.empty((0, 3)), np.empty(0)
        for g in range(n):
            for d in range(3):
                x[m, d] = q[d] + gr[g] * (z[i, d] - q[d])
            w[m] = wz[i] * max(height, 0.0) * gwr[g] * gr[g] ** power
            m += 1
    return x, w


@njit(cache=True)
def face_region(e_ijk, axis, side, lo, h, shape, node_shape, t_key, t_x, t_w, t_n,
                l_start, l_off, l_coord, g2, gw2, ge, gwe):
    """2D rule of the material region of the face ``side`` (0: low, 1: high) normal to
    ``axis`` of element ``e_ijk``: (points (k, 3), weights (k,), ok), with the radial rule
    ``g2, gw2`` and the edge rule ``ge, gwe`` on [0, 1]. ``ok`` is False when the region is
    not star-shaped from its centroid; an empty region gives no points."""
    b = (axis + 1) % 3
    c = (axis + 2) % 3
    key = face_key(e_ijk, axis, 1 if side == 1 else -1, shape)
    t0 = np.searchsorted(t_key, key)
    t1 = np.searchsorted(t_key, key + 1)
    n_edge = ge.shape[0]
    intervals = np.empty((8, 2))
    cap = (t1 - t0) + 4 * 8 * n_edge
    z = np.empty((cap, 3))
    wz = np.empty(cap)
    mz = np.zeros((cap, 3))
    plane = lo[axis] + side * h
    k = _append(t_x, t_w, t_n, t0, t1, z, wz, mz, 0)
    # the four edges: along c at b = lo or hi, along b at c = lo or hi
    for along in range(2):
        line_axis = c if along == 0 else b
        across = b if along == 0 else c
        for end in range(2):
            nodes = e_ijk.copy()
            nodes[axis] += side
            nodes[across] += end
            n_int = line_intervals(l_start, l_off, l_coord, node_shape, line_axis, nodes,
                                    lo[line_axis], lo[line_axis] + h, intervals)
            for r in range(n_int):
                span = intervals[r, 1] - intervals[r, 0]
                for g in range(n_edge):
                    z[k, axis] = plane
                    z[k, across] = lo[across] + end * h
                    z[k, line_axis] = intervals[r, 0] + ge[g] * span
                    wz[k] = gwe[g] * span
                    for d in range(3):
                        mz[k, d] = 0.0
                    mz[k, across] = 1.0 if end == 1 else -1.0
                    k += 1
    if k == 0:
        return np.empty((0, 3)), np.empty(0), True
    # centroid from the boundary, about the face centre o
    o = np.empty(3)
    for d in range(3):
        o[d] = lo[d] + 0.5 * h
    o[axis] = plane
    area, q = _centroid(z, wz, mz, k, o, 2.0)
    if area <= 0.0:
        return np.empty((0, 3)), np.empty(0), area > -1e-12 * h * h
    q[axis] = plane
    x, w = _cones(z, wz, mz, k, q, g2, gw2, 1, HEIGHT_EPS * h)
    return x, w, w.shape[0] > 0


@njit(cache=True)
def cone_rule(e_ijk, origin, h, shape, node_shape, s_x, s_w, s_n, s0, s1,
              t_key, t_x, t_w, t_n, l_start, l_off, l_coord, tables):
    """The sub-tetrahedra rule of one cut element (module docstring): points (N, 3) and
    positive weights (N,), or empty arrays when the element is not star-shaped from its
    centroid. ``tables``: the Gauss rules on [0, 1] ``(g3, gw3, g2, gw2, ge, gwe)`` of the 3D
    cones, the 2D cones and the edge intervals (:func:`cone_tables`)."""
    g3, gw3, g2, gw2, ge, gwe = tables
    lo = np.empty(3)
    for d in range(3):
        lo[d] = origin[d] + e_ijk[d] * h
    # the boundary: surface points, then the six face regions' 2D rules
    faces_x = []
    faces_w = []
    n_face = 0
    for axis in range(3):
        for side in range(2):
            fx, fw, ok = face_region(e_ijk, axis, side, lo, h, shape, node_shape, t_key, t_x, t_w,
                                     t_n, l_start, l_off, l_coord, g2, gw2, ge, gwe)
            if not ok:
                return np.empty((0, 3)), np.empty(0)
            faces_x.append(fx)
            faces_w.append(fw)
            n_face += fw.shape[0]
    n = (s1 - s0) + n_face
    y = np.empty((n, 3))
    wy = np.empty(n)
    ny = np.zeros((n, 3))
    k = _append(s_x, s_w, s_n, s0, s1, y, wy, ny, 0)
    f = 0
    for axis in range(3):
        for side in range(2):
            fx = faces_x[f]
            fw = faces_w[f]
            f += 1
            for i in range(fw.shape[0]):
                for d in range(3):
                    y[k, d] = fx[i, d]
                    ny[k, d] = 0.0
                ny[k, axis] = 1.0 if side == 1 else -1.0
                wy[k] = fw[i]
                k += 1
    # centroid of the material part, about the element centre o
    o = np.empty(3)
    for d in range(3):
        o[d] = lo[d] + 0.5 * h
    volume, p = _centroid(y, wy, ny, k, o, 3.0)
    if volume <= 0.0:
        return np.empty((0, 3)), np.empty(0)
    return _cones(y, wy, ny, k, p, g3, gw3, 2, HEIGHT_EPS * h)
