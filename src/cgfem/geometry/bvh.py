"""A bounding-volume hierarchy over nearly flat Bezier leaves of a solid's NURBS patches.

:meth:`SurfaceIndex.build` cuts every patch into Bezier pieces (exact knot insertion,
:mod:`cgfem.geometry.refine`), subdivides each piece ``subdivisions x subdivisions`` times
and then halves pieces whose normals still turn by more than ``max_leaf_angle``. Each
resulting *leaf* is a self-contained rational Bezier patch, stored in flat arrays:

- ``leaf_degree`` (n_leaf, 2) ``(p, q)``;
- ``leaf_param`` (n_leaf, 4) its parameter box ``(u0, u1, v0, v1)`` in its patch;
- ``leaf_offset`` (n_leaf + 1,) rows of ``control`` (n_ctrl, 4) holding its homogeneous
  control net ``(w x, w y, w z, w)``, row-major ``(p + 1) x (q + 1)`` (index ``i (q + 1) + j``);
- ``leaf_patch`` (n_leaf,) index of the patch in ``solid.patches``;
- ``leaf_lo``, ``leaf_hi`` (n_leaf, 3) its axis-aligned box: the box of the Cartesian control
  points (the convex hull property, weights being positive), inflated by ``BOX_INFLATION``
  times the solid's bounding-box diagonal;
- ``leaf_axis`` (n_leaf, 3) its mean unit normal ``m`` and ``leaf_slab`` (n_leaf, 2) the
  interval of ``m . P`` over its control points (inflated alike): the leaf lies in this slab,
  a tighter bound than the box for a nearly flat leaf.

Inside a leaf, the kernels of :mod:`cgfem.geometry.query` (they take the arrays as one
:class:`BvhArrays`) work with the local parameters
``(s, t)`` in ``[0, 1]^2``: ``u = u0 + s (u1 - u0)``, ``v = v0 + t (v1 - v0)``.

The hierarchy is a binary tree in flat arrays, nodes in depth-first order (node 0 is the
root): ``node_lo``, ``node_hi`` (n_node, 3) boxes, ``node_child`` (n_node, 2) children
(``-1`` for a leaf node), ``node_start``, ``node_count`` (n_node,) the range of leaves a leaf
node holds (leaves are stored in tree order, so every leaf node owns a contiguous range).
Built by median split of the leaf centroids along the longest axis of their bounds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from cgfem.errors import InputError
from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.refine import bezier_patches, refine_knots, split
from cgfem.geometry.solid import Solid

#: Leaf boxes are inflated by this fraction of the solid's bounding-box diagonal.
BOX_INFLATION = 1e-10
#: Most leaves a leaf node of the hierarchy holds.
LEAVES_PER_NODE = 4
#: Normals sampled per direction to estimate a leaf's normal cone.
_ANGLE_SAMPLES = 5


class BvhArrays(NamedTuple):
    """The arrays of a :class:`SurfaceIndex` that the query kernels read, as one argument
    (numba takes a named tuple of arrays); layout in the module docstring."""

    node_lo: np.ndarray
    node_hi: np.ndarray
    node_child: np.ndarray
    node_start: np.ndarray
    node_count: np.ndarray
    leaf_lo: np.ndarray
    leaf_hi: np.ndarray
    leaf_axis: np.ndarray
    leaf_slab: np.ndarray
    leaf_degree: np.ndarray
    leaf_offset: np.ndarray
    control: np.ndarray


@dataclass(frozen=True, eq=False)
class SurfaceIndex:
    """Bezier leaves of a solid's patches and a BVH over their boxes (see module docstring
    for the layout of every array)."""

    leaf_degree: np.ndarray
    leaf_param: np.ndarray
    leaf_offset: np.ndarray
    control: np.ndarray
    leaf_patch: np.ndarray
    leaf_lo: np.ndarray
    leaf_hi: np.ndarray
    leaf_axis: np.ndarray
    leaf_slab: np.ndarray
    node_lo: np.ndarray
    node_hi: np.ndarray
    node_child: np.ndarray
    node_start: np.ndarray
    node_count: np.ndarray
    #: bounding-box diagonal of the solid (m); the scale of every tolerance
    diagonal: float
    #: number of patches of the solid
    n_patches: int

    def __post_init__(self) -> None:
        for name in ("leaf_degree", "leaf_param", "leaf_offset", "control", "leaf_patch", "leaf_lo",
                     "leaf_hi", "leaf_axis", "leaf_slab", "node_lo", "node_hi", "node_child",
                     "node_start", "node_count"):
            arr = np.ascontiguousarray(getattr(self, name))
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    # -- construction ------------------------------------------------------------------------
    @classmethod
    def build(cls, solid: Solid, max_leaf_angle: float = math.radians(30.0), subdivisions: int = 2,
              max_splits: int = 6) -> "SurfaceIndex":
        """Index ``solid``.

        Parameters
        ----------
        solid : the closed set of patches
        max_leaf_angle : radians; a leaf is halved (in the direction in which its normal turns
            most) while some sampled normal deviates from the mean normal by more than this
        subdivisions : every Bezier piece is first cut into ``subdivisions`` equal parameter
            intervals per direction (2 gives 45-degree leaves for the builders' quarter circles)
        max_splits : most halvings of one piece by the angle criterion
        """
        if isinstance(subdivisions, bool) or not isinstance(subdivisions, (int, np.integer)) or subdivisions < 1:
            raise InputError("subdivisions", f"expected a positive integer, got {subdivisions!r}")
        if not 0.0 < max_leaf_angle < math.pi:
            raise InputError("max_leaf_angle", f"expected an angle in (0, pi) radians, got {max_leaf_angle!r}")
        pieces: list[tuple[int, NurbsSurface, np.ndarray]] = []
        for index, patch in enumerate(solid.patches):
            surface = _subdivided(patch.surface, int(subdivisions))
            for piece, _, _ in bezier_patches(surface):
                for leaf, axis in _split_by_angle(piece, max_leaf_angle, max_splits):
                    pieces.append((index, leaf, axis))
        return cls._from_pieces(pieces, len(solid.patches))

    @classmethod
    def _from_pieces(cls, pieces, n_patches: int) -> "SurfaceIndex":
        n_leaf = len(pieces)
        degree = np.array([leaf.degree for _, leaf, _ in pieces], dtype=np.int64).reshape(n_leaf, 2)
        param = np.array([(leaf.knots_u[0], leaf.knots_u[-1], leaf.knots_v[0], leaf.knots_v[-1])
                          for _, leaf, _ in pieces], dtype=float).reshape(n_leaf, 4)
        patch = np.array([index for index, _, _ in pieces], dtype=np.int64)
        nets = [leaf.control.reshape(-1, 4) for _, leaf, _ in pieces]
        pts = [net[:, :3] / net[:, 3:] for net in nets]
        lo = np.array([p.min(axis=0) for p in pts])
        hi = np.array([p.max(axis=0) for p in pts])
        axis = np.array([a for _, _, a in pieces], dtype=float).reshape(n_leaf, 3)
        along = [p @ a for p, a in zip(pts, axis)]
        slab = np.array([(v.min(), v.max()) for v in along]).reshape(n_leaf, 2)
        diagonal = float(np.linalg.norm(hi.max(axis=0) - lo.min(axis=0)))
        pad = BOX_INFLATION * diagonal
        lo -= pad
        hi += pad
        slab += [-pad, pad]
        tree = _median_split_tree(lo, hi, LEAVES_PER_NODE)
        order = tree["order"]
        nets = [nets[k] for k in order]
        offset = np.concatenate([[0], np.cumsum([net.shape[0] for net in nets])]).astype(np.int64)
        return cls(leaf_degree=degree[order], leaf_param=param[order], leaf_offset=offset,
                   control=np.concatenate(nets, axis=0), leaf_patch=patch[order],
                   leaf_lo=lo[order], leaf_hi=hi[order], leaf_axis=axis[order], leaf_slab=slab[order],
                   node_lo=tree["lo"], node_hi=tree["hi"],
                   node_child=tree["child"], node_start=tree["start"], node_count=tree["count"],
                   diagonal=diagonal, n_patches=n_patches)

    # -- views -----------------------------------------------------------------------------------
    @property
    def n_leaves(self) -> int:
        return int(self.leaf_patch.size)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The root box ``(lo, hi)``, each (3,)."""
        return self.node_lo[0], self.node_hi[0]

    def leaf_surface(self, k: int) -> NurbsSurface:
        """Leaf ``k`` as a Bezier :class:`NurbsSurface` on its parameter box (it evaluates at
        ``(u, v)`` to its patch at ``(u, v)``)."""
        p, q = (int(d) for d in self.leaf_degree[k])
        u0, u1, v0, v1 = self.leaf_param[k]
        net = self.control[self.leaf_offset[k]: self.leaf_offset[k + 1]].reshape(p + 1, q + 1, 4)
        return NurbsSurface((p, q), np.repeat([u0, u1], p + 1), np.repeat([v0, v1], q + 1), net)

    def arrays(self) -> BvhArrays:
        """The arrays the query kernels take, as one :class:`BvhArrays`."""
        return BvhArrays(**{name: getattr(self, name) for name in BvhArrays._fields})


def as_index(index_or_solid) -> SurfaceIndex:
    """``index_or_solid`` itself if it is a :class:`SurfaceIndex`, else the default index of
    the :class:`Solid`."""
    if isinstance(index_or_solid, SurfaceIndex):
        return index_or_solid
    if isinstance(index_or_solid, Solid):
        return SurfaceIndex.build(index_or_solid)
    raise TypeError(f"expected a SurfaceIndex or a Solid, got {type(index_or_solid).__name__}")


# -- leaves ----------------------------------------------------------------------------------------
def _subdivided(surface: NurbsSurface, k: int) -> NurbsSurface:
    """``surface`` with ``k - 1`` equally spaced knots inserted in every non-empty span, both
    directions (exact)."""
    if k == 1:
        return surface
    frac = np.arange(1, k) / k
    for direction, breaks in enumerate(surface.breaks()):
        new = (breaks[:-1, None] + frac[None, :] * np.diff(breaks)[:, None]).ravel()
        surface = refine_knots(surface, direction, new)
    return surface


def _normal_turning(piece: NurbsSurface) -> tuple[float, float, float, np.ndarray]:
    """Largest angle between a sampled normal and the mean normal, the largest turning of
    the normal along u and along v (radians), from an ``_ANGLE_SAMPLES^2`` grid (kept a
    relative 1e-3 off the piece's edges, which may be collapsed), and the mean unit normal
    (3,) (zero if the normals cancel)."""
    (u0, u1), (v0, v1) = piece.domain
    m = _ANGLE_SAMPLES
    frac = np.clip(np.linspace(0.0, 1.0, m), 1e-3, 1.0 - 1e-3)  # not on a collapsed edge
    uu, vv = np.meshgrid(u0 + frac * (u1 - u0), v0 + frac * (v1 - v0), indexing="ij")
    n = piece.normals(np.column_stack([uu.ravel(), vv.ravel()])).reshape(m, m, 3)
    mean = n.sum(axis=(0, 1))
    norm = np.linalg.norm(mean)
    if norm == 0.0:
        return math.pi, math.pi, math.pi, np.zeros(3)
    spread = np.arccos(np.clip(n @ (mean / norm), -1.0, 1.0)).max()
    along_u = np.arccos(np.clip(np.sum(n[0] * n[-1], axis=-1), -1.0, 1.0)).max()
    along_v = np.arccos(np.clip(np.sum(n[:, 0] * n[:, -1], axis=-1), -1.0, 1.0)).max()
    return float(spread), float(along_u), float(along_v), mean / norm


def _split_by_angle(piece: NurbsSurface, max_angle: float,
                    max_splits: int) -> list[tuple[NurbsSurface, np.ndarray]]:
    """Halve the Bezier ``piece`` until its normal cone is narrower than ``max_angle``;
    the leaves with their mean unit normals."""
    spread, along_u, along_v, mean = _normal_turning(piece)
    if spread <= max_angle or max_splits == 0:
        return [(piece, mean)]
    direction = 0 if along_u >= along_v else 1
    lo, hi = piece.domain[direction]
    left, right = split(piece, direction, 0.5 * (lo + hi))
    return _split_by_angle(left, max_angle, max_splits - 1) + _split_by_angle(right, max_angle, max_splits - 1)


# -- hierarchy ------------------------------------------------------------------------------------
def _median_split_tree(lo: np.ndarray, hi: np.ndarray, per_node: int) -> dict[str, np.ndarray]:
    """Binary tree over boxes ``lo``, ``hi`` (n, 3), nodes in depth-first order.

    Returns ``order`` (n,) the leaf permutation (tree order), ``lo``, ``hi`` (n_node, 3),
    ``child`` (n_node, 2), ``start``, ``count`` (n_node,).
    """
    centre = 0.5 * (lo + hi)
    order: list[int] = []
    node_lo, node_hi, child, start, count = [], [], [], [], []

    def visit(ids: np.ndarray) -> int:
        node = len(node_lo)
        node_lo.append(lo[ids].min(axis=0))
        node_hi.append(hi[ids].max(axis=0))
        child.append([-1, -1])
        start.append(len(order))
        count.append(0)
        if ids.size <= per_node:
            order.extend(ids.tolist())
            count[node] = ids.size
            return node
        c = centre[ids]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        ids = ids[np.argsort(c[:, axis], kind="stable")]
        half = ids.size // 2
        left = visit(ids[:half])
        right = visit(ids[half:])
        child[node] = [left, right]
        count[node] = ids.size
        return node

    visit(np.arange(lo.shape[0]))
    return {"order": np.array(order, dtype=np.int64), "lo": np.array(node_lo), "hi": np.array(node_hi),
            "child": np.array(child, dtype=np.int64), "start": np.array(start, dtype=np.int64),
            "count": np.array(count, dtype=np.int64)}
