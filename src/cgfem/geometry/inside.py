"""Point-in-solid classification from the closest point on the exact NURBS boundary.

A point ``x`` is inside when ``(x - foot) . n < 0`` at its closest point ``foot`` with the
outward normal ``n`` (:func:`cgfem.geometry.query.closest_points`). Where the foot lies on
an edge shared by patches or leaves (several candidates at the same distance within
round-off), the candidate whose normal is best aligned with ``x - foot`` decides: this is
right at convex and concave edges (box edges, the rims of the half-torus caps). At
collapsed edges (sphere poles, disc centres) the limit normal is used.

Tolerance: points closer to the surface than ``INSIDE_TOL`` times the diagonal of the
solid's bounding box may be classified either way (they are on the surface within
round-off of the closest-point solve); every other point is classified exactly.
"""

from __future__ import annotations

import numpy as np

from cgfem.geometry.bvh import as_index
from cgfem.geometry.query import closest_points

#: Points within this fraction of the bounding-box diagonal from the surface may go either way.
INSIDE_TOL = 1e-12


def points_inside(index_or_solid, points) -> np.ndarray:
    """Which ``points`` (n, 3) lie inside the solid -> bool (n,).

    ``index_or_solid``: a :class:`~cgfem.geometry.bvh.SurfaceIndex` (reuse it for many calls)
    or a :class:`~cgfem.geometry.solid.Solid` (indexed with the defaults on every call).
    Points outside the index's root box are outside without a closest-point search.
    """
    index = as_index(index_or_solid)
    x = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
    lo, hi = index.bounds
    candidate = np.all((x >= lo) & (x <= hi), axis=1)
    inside = np.zeros(x.shape[0], dtype=bool)
    if np.any(candidate):
        xs = x[candidate]
        cp = closest_points(index, xs)
        side = np.einsum("ij,ij->i", xs - cp.point, cp.normal)
        inside[candidate] = side < 0.0
    return inside
