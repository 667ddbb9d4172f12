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
