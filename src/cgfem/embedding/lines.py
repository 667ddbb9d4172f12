"""Crossings of a solid's boundary with the grid lines along z.

Every grid line ``(x_i, y_j)`` is cast as a ray through the whole grid; its hits, sorted,
alternate between entering and leaving the solid. This gives the inside status of every
grid node (parity of the hits below it) and, per element, the material part of one of its
z edges (needed by the volume moments, :mod:`cgfem.embedding.moments`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cgfem.embedding.grid import CartesianGrid
from cgfem.geometry.bvh import SurfaceIndex
from cgfem.geometry.query import ray_intersections


@dataclass(frozen=True)
class ZLines:
    """Hits of the z grid lines: line ``(i, j)`` (id ``i * (ny + 1) + j``) has the sorted z
    values ``z[offsets[l]:offsets[l + 1]]``; ``odd`` counts lines with an odd number of hits
    (a grazing ray; their last hit is dropped)."""

    grid: CartesianGrid
    offsets: np.ndarray
    z: np.ndarray
    odd: int

    def line_id(self, i, j) -> np.ndarray:
        return np.asarray(i) * (self.grid.shape[1] + 1) + np.asarray(j)

    def nodes_inside(self) -> np.ndarray:
        """Inside status of every grid node, in :meth:`CartesianGrid.node_id` order."""
        nx, ny, nz = self.grid.node_shape
        zk = self.grid.plane(2, np.arange(nz))
        inside = np.zeros((nx * ny, nz), bool)
        for line in np.flatnonzero(np.diff(self.offsets)):
            hits = self.z[self.offsets[line]:self.offsets[line + 1]]
            inside[line] = np.searchsorted(hits, zk, side="right") % 2 == 1
        return inside.reshape(-1)

    def inside_intervals(self, i: int, j: int, z0: float, z1: float) -> np.ndarray:
        """Material intervals (k, 2) of line ``(i, j)`` within ``[z0, z1]``."""
        line = int(self.line_id(i, j))
        hits = self.z[self.offsets[line]:self.offsets[line + 1]]
        pairs = hits.reshape(-1, 2)
        lo = np.maximum(pairs[:, 0], z0)
        hi = np.minimum(pairs[:, 1], z1)
        keep = hi > lo
        return np.column_stack([lo[keep], hi[keep]])


def cast_z_lines(index: SurfaceIndex, grid: CartesianGrid) -> ZLines:
    """Hits of every z grid line with the boundary indexed by ``index``."""
    nx, ny, nz = grid.node_shape
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    pad = grid.h
    z_start = grid.origin[2] - pad
    origins = np.column_stack([grid.plane(0, ii.ravel()), grid.plane(1, jj.ravel()),
                               np.full(ii.size, z_start)])
    directions = np.tile([0.0, 0.0, 1.0], (ii.size, 1))
    hits = ray_intersections(index, origins, directions, 0.0, nz * grid.h + 2 * pad)
    counts = np.diff(hits.offsets)
    z = z_start + hits.t
    odd = counts % 2 == 1
    if np.any(odd):  # drop the last hit of a grazing line so that hits pair up
        keep = np.ones(z.size, bool)
        keep[hits.offsets[1:][odd] - 1] = False
        z = z[keep]
        counts = counts - odd
    offsets = np.concatenate([[0], np.cumsum(counts)])
    return ZLines(grid, offsets, z, int(odd.sum()))


# ------------------------------------------------------------------------------------------
# grid lines along any axis, with the hits' surface data (used by the facets definition)
# ------------------------------------------------------------------------------------------
def line_axes(axis: int) -> tuple[int, int]:
    """The two axes ``(b, c)``, ``b < c``, that number the grid lines along ``axis``."""
    b, c = (a for a in range(3) if a != axis)
    return b, c


@dataclass(frozen=True)
class GridLines:
    """Hits of the grid lines along ``axis`` with the boundary, CSR-like.

    The line through the nodes whose indices along the other axes ``(b, c)`` (``b < c``) are
    ``(p, q)`` has id ``p * node_shape[c] + q`` (for ``axis = 2`` this is :class:`ZLines`'s
    numbering); its hits are ``offsets[l]:offsets[l + 1]``, sorted along the line.

    offsets : (n_lines + 1,) int
    coord : (m,) coordinate of each hit along ``axis`` (m)
    patch : (m,) patch index in ``solid.patches``
    uv : (m, 2) NURBS parameters of the hit in its patch
    normal : (m, 3) outward unit normal at the hit
    odd : number of lines with an odd number of hits (grazing rays)
    """

    grid: CartesianGrid
    axis: int
    offsets: np.ndarray
    coord: np.ndarray
    patch: np.ndarray
    uv: np.ndarray
    normal: np.ndarray
    odd: int

    @property
    def n_lines(self) -> int:
        return self.offsets.size - 1

    def line_of_hits(self) -> np.ndarray:
        """Line id of every hit, (m,)."""
        return np.repeat(np.arange(self.n_lines), np.diff(self.offsets))

    def paired(self) -> "GridLines":
        """The same hits with the last one of every odd line dropped (as
        :func:`cast_z_lines` does), so that hits pair up into material intervals."""
        counts = np.diff(self.offsets)
        odd = counts % 2 == 1
        if not np.any(odd):
            return self
        keep = np.ones(self.coord.size, bool)
        keep[self.offsets[1:][odd] - 1] = False
        offsets = np.concatenate([[0], np.cumsum(counts - odd)])
        return GridLines(self.grid, self.axis, offsets, self.coord[keep], self.patch[keep],
                         self.uv[keep], self.normal[keep], self.odd)

    def hit_bucket(self) -> np.ndarray:
        """Per hit, ``m + 1`` where ``plane_m < coord <= plane_{m+1}`` is the grid edge ``m``
        holding it (0: at or before the first node plane; ``n + 1``: after the last), (m,)."""
        n = self.grid.node_shape[self.axis]
        planes = self.grid.plane(self.axis, np.arange(n))
        return np.searchsorted(planes, self.coord, side="left")

    def bucket_counts(self) -> np.ndarray:
        """Number of hits of every line in every bucket of :meth:`hit_bucket`,
        (n_lines, n_nodes_along_axis + 1)."""
        n = self.grid.node_shape[self.axis]
        key = self.line_of_hits() * (n + 1) + self.hit_bucket()
        return np.bincount(key, minlength=self.n_lines * (n + 1)).reshape(self.n_lines, n + 1)

    def to_node_order(self, values: np.ndarray) -> np.ndarray:
        """Values (n_lines, n_nodes_along_axis) of the nodes of every line -> the same values
        in :meth:`CartesianGrid.node_id` order, (n_nodes,)."""
        b, c = line_axes(self.axis)
        shape = self.grid.node_shape
        arr = values.reshape(shape[b], shape[c], shape[self.axis])
        return np.moveaxis(arr, 2, self.axis).reshape(-1)

    def nodes_inside(self) -> np.ndarray:
        """Inside status of every grid node by the parity of the hits at or before it along
        its line, (n_nodes,) bool in :meth:`CartesianGrid.node_id` order (use on
        :meth:`paired` hits)."""
        n = self.grid.node_shape[self.axis]
        below = np.cumsum(self.bucket_counts()[:, :n], axis=1)
        return self.to_node_order(below % 2 == 1)


def cast_lines(index: SurfaceIndex, grid: CartesianGrid, axis: int) -> GridLines:
    """Hits of every grid line along ``axis`` with the boundary indexed by ``index`` (all of
    them: call :meth:`GridLines.paired` to drop the last hit of grazing lines). For
    ``axis = 2`` the rays are those of :func:`cast_z_lines`."""
    if axis not in (0, 1, 2):
        raise ValueError(f"axis must be 0, 1 or 2, got {axis!r}")
    b, c = line_axes(axis)
    shape = grid.node_shape
    pp, qq = np.meshgrid(np.arange(shape[b]), np.arange(shape[c]), indexing="ij")
    pad = grid.h
    start = grid.origin[axis] - pad
    origins = np.empty((pp.size, 3))
    origins[:, b] = grid.plane(b, pp.ravel())
    origins[:, c] = grid.plane(c, qq.ravel())
    origins[:, axis] = start
    directions = np.zeros((pp.size, 3))
    directions[:, axis] = 1.0
    hits = ray_intersections(index, origins, directions, 0.0, shape[axis] * grid.h + 2 * pad)
    odd = int(np.sum(np.diff(hits.offsets) % 2 == 1))
    return GridLines(grid, axis, hits.offsets, start + hits.t, hits.patch, hits.uv, hits.normal, odd)
