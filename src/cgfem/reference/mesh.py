"""Structured Q9 meshes of axis-aligned rectangles, graded toward the corners.

A mesh is the tensor product of two 1D breakpoint sequences (element edges) in y and z;
every element is a rectangle whose nine nodes are the tensor product of its edges and
midpoints. The nodes form a ``(2 n_y + 1) × (2 n_z + 1)`` grid, node id ``iy·(2 n_z + 1) + iz``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def graded_breakpoints(lo: float, hi: float, n_half: int, beta: float) -> np.ndarray:
    """Element edges (2 n_half + 1,) on [lo, hi], radically graded toward both ends.

    On each half the edges sit at ``(hi − lo)/2 · (k / n_half)^beta`` from its end
    (k = 0 … n_half): element sizes grow like k^(beta−1) away from the end, the first one is
    ``(hi − lo)/2 · n_half^−beta``. ``beta = 1`` is a uniform mesh; doubling ``n_half``
    splits every element's parameter interval in two (uniform refinement of the map).
    """
    if n_half < 1 or beta < 1.0:
        raise ValueError(f"n_half must be >= 1 and beta >= 1 (got {n_half}, {beta})")
    half = 0.5 * (hi - lo) * (np.arange(n_half + 1) / n_half) ** beta
    left = lo + half
    right = hi - half[::-1]
    return np.concatenate([left[:-1], [0.5 * (lo + hi)], right[1:]])


def _with_midpoints(breaks: np.ndarray) -> np.ndarray:
    out = np.empty(2 * len(breaks) - 1)
    out[0::2] = breaks
    out[1::2] = 0.5 * (breaks[:-1] + breaks[1:])
    return out


@dataclass(frozen=True)
class RectMesh:
    """Q9 mesh of ``[y_breaks[0], y_breaks[-1]] × [z_breaks[0], z_breaks[-1]]``.

    ``y_breaks``: (n_y + 1,), ``z_breaks``: (n_z + 1,) strictly increasing element edges.
    """

    y_breaks: np.ndarray
    z_breaks: np.ndarray

    @property
    def n_y(self) -> int:
        return len(self.y_breaks) - 1

    @property
    def n_z(self) -> int:
        return len(self.z_breaks) - 1

    @property
    def grid_shape(self) -> tuple[int, int]:
        """Shape of the node grid ``(2 n_y + 1, 2 n_z + 1)``."""
        return 2 * self.n_y + 1, 2 * self.n_z + 1

    @property
    def n_nodes(self) -> int:
        a, b = self.grid_shape
        return a * b

    @property
    def n_elements(self) -> int:
        return self.n_y * self.n_z

    def node_coords(self) -> np.ndarray:
        """Node positions (n_nodes, 2) as (y, z)."""
        y, z = np.meshgrid(_with_midpoints(self.y_breaks), _with_midpoints(self.z_breaks),
                           indexing="ij")
        return np.stack([y.ravel(), z.ravel()], axis=-1)

    def connectivity(self) -> np.ndarray:
        """Element nodes (n_elements, 9); element ``i·n_z + k``, local node ``3 a + b``."""
        nz_nodes = self.grid_shape[1]
        i, k = np.meshgrid(np.arange(self.n_y), np.arange(self.n_z), indexing="ij")
        a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        iy = 2 * i.ravel()[:, None] + a.ravel()[None, :]
        iz = 2 * k.ravel()[:, None] + b.ravel()[None, :]
        return iy * nz_nodes + iz

    def element_coords(self) -> np.ndarray:
        """Node positions per element (n_elements, 9, 2)."""
        return self.node_coords()[self.connectivity()]

    def side_nodes(self, side: str) -> np.ndarray:
        """Node ids along a side, in increasing coordinate: ``ymin ymax zmin zmax``."""
        ny_nodes, nz_nodes = self.grid_shape
        grid = np.arange(self.n_nodes).reshape(ny_nodes, nz_nodes)
        return {"ymin": grid[0, :], "ymax": grid[-1, :],
                "zmin": grid[:, 0], "zmax": grid[:, -1]}[side].copy()

    def side_edges(self, side: str) -> np.ndarray:
        """Quadratic edges (n_edges, 3) along a side: node ids (end, middle, end)."""
        nodes = self.side_nodes(side)
        k = np.arange((len(nodes) - 1) // 2)
        return np.stack([nodes[2 * k], nodes[2 * k + 1], nodes[2 * k + 2]], axis=-1)

    def locate(self, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Element and reference coordinates of points inside the rectangle.

        ``y``, ``z``: (n,), clipped to the rectangle. Returns ``(element, xi, eta)``, each
        (n,). Points on an inner element edge go to the element with the larger index.
        """
        def axis(breaks: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            t = np.clip(t, breaks[0], breaks[-1])
            i = np.clip(np.searchsorted(breaks, t, side="right") - 1, 0, len(breaks) - 2)
            lo, hi = breaks[i], breaks[i + 1]
            return i, (2.0 * t - lo - hi) / (hi - lo)

        i, xi = axis(self.y_breaks, np.asarray(y, dtype=float))
        k, eta = axis(self.z_breaks, np.asarray(z, dtype=float))
        return i * self.n_z + k, xi, eta
