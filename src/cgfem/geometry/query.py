"""Closest points and ray intersections on a solid's exact NURBS boundary.

Both queries traverse the bounding-volume hierarchy of a :class:`SurfaceIndex` with an
explicit stack and then solve a small Newton problem on each candidate Bezier leaf, in the
leaf's local parameters ``(s, t)`` in ``[0, 1]^2`` (see :mod:`cgfem.geometry.bvh`):

- **closest point** (branch and bound): phase 1 walks the tree (nearer child first) and
  collects the leaves whose lower bound (distance to the leaf's box and to its normal slab)
  does not exceed an upper bound (distance to the leaves' corner control points, which lie
  on the surface); phase 2 projects onto them in order of lower bound until that bound
  exceeds the best distance found. Projection: from the best sample of a
  ``SEED_GRID^2`` grid, projected Newton for ``min f = |S(s, t) - x|^2`` with the full
  Hessian ``[S_a . S_b + S_ab . (S - x)]``, the active-set rule at the box ``[0, 1]^2`` (a
  bound variable whose gradient points outward stays fixed; the other one minimises along
  the edge), a Gauss-Newton/Levenberg step where the Hessian is not positive definite, and a
  backtracking line search for steps that are not yet small. Converged when a step moves
  less than ``STEP_TOL`` (local parameters): the feet are accurate to about 1e-14 of the
  solid's size.
- **ray intersection** (box and slab tests): the leaf's homogeneous net is projected on two
  planes through the ray, which gives a planar polynomial Bezier map ``G(s, t)`` whose zeros
  are the hits. It is halved (de Casteljau; parameter aspect ratio kept below ``ASPECT``)
  until each piece is either excluded (the convex hull of its net misses the origin) or
  provably one-to-one (every s-difference and t-difference of its net have a cross product
  of one sign, so ``G_s`` and ``G_t`` never align), at most ``MAX_DEPTH`` times. A
  one-to-one piece holds at most one root: Newton on ``S(s, t) - (o + tau d) = 0`` in
  ``(s, t, tau)`` from its centre; if that ends outside the piece, the piece is halved again
  (at the depth limit, Newton also starts from its corners). Roots inside the leaf's box (up
  to ``BOX_TOL``) are kept, and roots whose points coincide (within ``MERGE_TOL`` times the
  solid's diagonal, e.g. a hit on an edge shared by two leaves) are merged. So every
  transversal hit is found, except two hits closer together than a piece at the depth limit
  (a nearly tangent ray); tangent (double) roots are found when Newton reaches them.

Among candidate feet whose distances tie (within ``TIE_TOL`` times the diagonal: the foot
lies on an edge shared by patches or leaves), the one whose normal is best aligned with
``x - foot`` is kept: at an edge this is the face that ``x`` actually faces, which makes the
inside test of :mod:`cgfem.geometry.inside` exact there. At collapsed edges (sphere poles,
disc centres) the normal is the limit from inside the leaf (L'Hopital on ``S_s x S_t``).

The kernels are split by concern: :mod:`cgfem.geometry._closest_kernels` (closest points),
:mod:`cgfem.geometry._ray_kernels` (rays), :mod:`cgfem.geometry._bezier` (evaluation of the
leaves, shared); each takes the BVH as one :class:`~cgfem.geometry.bvh.BvhArrays`. (numba's
cache follows these imports: :mod:`cgfem._numba_cache`.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cgfem.geometry._bezier import bernstein_ders, bezier_derivs, leaf_normal, leaf_points_normals
from cgfem.geometry._closest_kernels import closest_points_kernel
from cgfem.geometry._ray_kernels import ray_kernel
from cgfem.geometry.bvh import SurfaceIndex, as_index

__all__ = ["ClosestPoints", "RayHits", "closest_points", "ray_intersections", "TIE_TOL", "MERGE_TOL",
           "bernstein_ders", "bezier_derivs", "leaf_normal"]

#: Distances within this fraction of the solid's diagonal tie (see module docstring).
TIE_TOL = 1e-11
#: Ray hits whose points are closer than this fraction of the diagonal are one hit.
MERGE_TOL = 1e-10

@dataclass(frozen=True)
class ClosestPoints:
    """Closest points ("feet") on the surface of ``n`` query points.

    Attributes
    ----------
    patch : (n,) int, index of the foot's patch in ``solid.patches``
    uv : (n, 2) the foot's parameters in its patch
    point : (n, 3) the foot ``S(u, v)``
    distance : (n,) ``|x - foot|``
    normal : (n, 3) outward unit normal at the foot (limit normal at collapsed edges); where
        the foot lies on an edge, that of the face best aligned with ``x - foot``
    leaf : (n,) int, the leaf of the index holding the foot
    on_edge : (n,) bool, the foot lies on the boundary of its leaf's parameter box
    """

    patch: np.ndarray
    uv: np.ndarray
    point: np.ndarray
    distance: np.ndarray
    normal: np.ndarray
    leaf: np.ndarray
    on_edge: np.ndarray


@dataclass(frozen=True)
class RayHits:
    """Intersections of ``n`` rays with the surface, CSR-like: the hits of ray ``i`` are
    ``offsets[i]:offsets[i + 1]``, sorted by ``t``.

    Attributes
    ----------
    offsets : (n + 1,) int
    ray : (m,) int, the ray of each hit
    t : (m,) ray parameter, ``point = origin + t direction``
    patch : (m,) int, index in ``solid.patches``
    uv : (m, 2) parameters of the hit in its patch
    point : (m, 3) the hit ``S(u, v)`` (exactly on the surface)
    normal : (m, 3) outward unit normal there
    """

    offsets: np.ndarray
    ray: np.ndarray
    t: np.ndarray
    patch: np.ndarray
    uv: np.ndarray
    point: np.ndarray
    normal: np.ndarray

    def count(self) -> np.ndarray:
        """Number of hits per ray, (n,)."""
        return np.diff(self.offsets)


# ------------------------------------------------------------------------------------------
# public functions
# ------------------------------------------------------------------------------------------
def closest_points(index, points) -> ClosestPoints:
    """Closest points on the boundary of the indexed solid.

    Parameters
    ----------
    index : :class:`SurfaceIndex` (or a :class:`~cgfem.geometry.solid.Solid`, indexed here)
    points : (n, 3) query points
    """
    index = as_index(index)
    x = _as_points(points, "points")
    n = x.shape[0]
    leaf = np.empty(n, dtype=np.int64)
    st = np.empty((n, 2))
    foot = np.empty((n, 3))
    dist = np.empty(n)
    normal = np.empty((n, 3))
    closest_points_kernel(index.arrays(), x, TIE_TOL * index.diagonal, leaf, st, foot, dist, normal)
    on_edge = np.any((st == 0.0) | (st == 1.0), axis=1)
    return ClosestPoints(patch=index.leaf_patch[leaf], uv=_patch_uv(index, leaf, st), point=foot,
                         distance=dist, normal=normal, leaf=leaf, on_edge=on_edge)


def ray_intersections(index, origins, directions, t_min: float = 0.0, t_max: float = np.inf) -> RayHits:
    """Every transversal intersection of the rays ``origin + t direction``,
    ``t_min <= t <= t_max``, with the boundary of the indexed solid.

    Parameters
    ----------
    index : :class:`SurfaceIndex` (or a :class:`~cgfem.geometry.solid.Solid`, indexed here)
    origins : (n, 3)
    directions : (n, 3), non-zero (not necessarily unit: ``t`` is in units of ``|direction|``)
    """
    index = as_index(index)
    o = _as_points(origins, "origins")
    d = _as_points(directions, "directions")
    if o.shape != d.shape:
        raise ValueError(f"origins {o.shape} and directions {d.shape} differ in shape")
    if np.any(np.all(d == 0.0, axis=1)):
        raise ValueError("a ray direction is zero")
    n = o.shape[0]
    capacity = 8
    while True:
        t = np.empty((n, capacity))
        leaf = np.empty((n, capacity), dtype=np.int64)
        st = np.empty((n, capacity, 2))
        count = np.empty(n, dtype=np.int64)
        ray_kernel(index.arrays(), o, d, float(t_min), float(t_max), MERGE_TOL * index.diagonal,
                   t, leaf, st, count)
        if n == 0 or count.max() <= capacity:
            break
        capacity = 4 * int(count.max())
    keep = np.arange(capacity)[None, :] < count[:, None]
    t, leaf, st = t[keep], leaf[keep], st[keep]
    point = np.empty((t.size, 3))
    normal = np.empty((t.size, 3))
    leaf_points_normals(index.leaf_degree, index.leaf_offset, index.control, leaf, st, point, normal)
    offsets = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
    return RayHits(offsets=offsets, ray=np.repeat(np.arange(n), count), t=t, patch=index.leaf_patch[leaf],
                   uv=_patch_uv(index, leaf, st), point=point, normal=normal)


def _as_points(points, name: str) -> np.ndarray:
    x = np.ascontiguousarray(points, dtype=float)
    if x.ndim == 1 and x.size == 3:
        x = x.reshape(1, 3)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} must be finite")
    return x


def _patch_uv(index: SurfaceIndex, leaf: np.ndarray, st: np.ndarray) -> np.ndarray:
    box = index.leaf_param[leaf]
    return np.column_stack([box[:, 0] + st[:, 0] * (box[:, 1] - box[:, 0]),
                            box[:, 2] + st[:, 1] * (box[:, 3] - box[:, 2])])
