"""Numba kernel of the facets ray test (:class:`cgfem.contact.surfaces.FacetSurface`).

A ray ``x1 + g n1`` meets the flat triangle ``v0 + l1 (v1 - v0) + l2 (v2 - v0)`` where
``[v1 - v0, v2 - v0, -n1] (l1, l2, g) = x1 - v0`` (eq. 11 on a displaced triangle). The
kernel solves that 3x3 system per (ray, triangle) pair, by the same elimination as the NURBS+FE
ray Newton (:func:`cgfem.contact._ray_kernels.solve3`), instead of materializing the pairs'
matrices in numpy.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cgfem.contact._ray_kernels import solve3


@njit(cache=True)
def triangle_hits(x1, n1, rows, tris, verts, band, max_gap, det_tol):
    """Admissible hits of the pairs (ray ``rows[k]``, triangle ``tris[k]``).

    ``x1``, ``n1`` (n, 3) ray origins and unit directions; ``verts`` (m, 3, 3) current
    triangle vertices; ``band`` how far outside the triangle (barycentric) a hit still counts:
    (n_pairs,) one per pair, or (1,) the same for all; ``det_tol`` > 0. A pair hits when the
    triangle's normal ``e1 x e2`` is against ``n1`` by more than ``det_tol`` (that is also
    ``det [e1, e2, -n1] = -(e1 x e2) . n1``, so the system is solvable), ``l1, l2 >= -band``,
    ``l1 + l2 <= 1 + band`` and ``|g| <= max_gap``. Returns ``hit`` (n_pairs,) bool and
    ``sol`` (n_pairs, 3): ``(l1, l2, g)`` where ``hit``."""
    n_pairs = rows.size
    per_pair = band.size == n_pairs
    hit = np.zeros(n_pairs, np.bool_)
    sol = np.zeros((n_pairs, 3))
    J = np.empty((3, 3))
    F = np.empty(3)
    step = np.empty(3)
    for k in range(n_pairs):
        r, t = rows[k], tris[k]
        nx, ny, nz = n1[r, 0], n1[r, 1], n1[r, 2]
        ax = verts[t, 1, 0] - verts[t, 0, 0]
        ay = verts[t, 1, 1] - verts[t, 0, 1]
        az = verts[t, 1, 2] - verts[t, 0, 2]
        bx = verts[t, 2, 0] - verts[t, 0, 0]
        by = verts[t, 2, 1] - verts[t, 0, 1]
        bz = verts[t, 2, 2] - verts[t, 0, 2]
        # a triangle facing the ray's way (or edge-on) is no hit whatever the solve would give
        facing = (ay * bz - az * by) * nx + (az * bx - ax * bz) * ny + (ax * by - ay * bx) * nz
        if not -facing > det_tol:
            continue
        J[0, 0], J[1, 0], J[2, 0] = ax, ay, az
        J[0, 1], J[1, 1], J[2, 1] = bx, by, bz
        J[0, 2], J[1, 2], J[2, 2] = -nx, -ny, -nz
        for i in range(3):
            F[i] = verts[t, 0, i] - x1[r, i]          # step = -J^{-1} F = J^{-1} (x1 - v0)
        if not solve3(J, F, step):
            continue
        l1, l2, g = step[0], step[1], step[2]
        b = band[k] if per_pair else band[0]
        if l1 >= -b and l2 >= -b and l1 + l2 <= 1.0 + b and abs(g) <= max_gap:
            hit[k] = True
            sol[k, 0], sol[k, 1], sol[k, 2] = l1, l2, g
    return hit, sol
