"""The trilinear (H8) displacement field of one body on its active grid elements.

Active elements (inside and cut) and their nodes get compact numbers; the displacement has
three components per active node, interleaved: dof ``3 * node + component``. Quadrature
points of the embedding are regrouped per active element (:class:`ElementPoints`) and carry
their local coordinates ``xi = (x - x_c) / (h / 2)`` in ``[-1, 1]^3`` (points of a
moment-fitted rule may lie anywhere in the cube), which is all the element kernels need:
on an axis-aligned cube ``dN/dx = (2 / h) dN/dxi``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cgfem.embedding.export import active_hex_mesh
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.quadrature import CUT, Embedding

#: local coordinates of the 8 H8 nodes, in the grid's node order
NODE_XI = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                    [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)


@dataclass(frozen=True)
class ElementPoints:
    """Quadrature points grouped by active element.

    xi : (n, 3) local coordinates in the element's cube
    x : (n, 3) physical coordinates
    w : (n,) weights
    offsets : (n_elements + 1,) points of element ``e`` are ``offsets[e]:offsets[e+1]``
    """

    xi: np.ndarray
    x: np.ndarray
    w: np.ndarray
    offsets: np.ndarray

    @property
    def element(self) -> np.ndarray:
        """(n,) active element of every point."""
        return np.repeat(np.arange(self.offsets.size - 1), np.diff(self.offsets))


@dataclass(frozen=True)
class Space:
    """H8 field over the active elements of a grid.

    elements : (n_elements,) grid ids of the active elements, ascending
    connectivity : (n_elements, 8) compact node numbers, H8 order
    coordinates : (n_nodes, 3) node positions
    cut : (n_elements,) bool, element cut by the boundary
    """

    grid: CartesianGrid
    elements: np.ndarray
    connectivity: np.ndarray
    coordinates: np.ndarray
    cut: np.ndarray

    @classmethod
    def of_elements(cls, grid: CartesianGrid, elements: np.ndarray, cut: np.ndarray) -> "Space":
        """The space on the grid elements ``elements`` (ascending ids); nodes are numbered
        in ascending grid id, as in the VTU meshes of :func:`active_hex_mesh`."""
        coordinates, connectivity = active_hex_mesh(grid, elements)
        return cls(grid, np.asarray(elements, np.int64), connectivity, coordinates, np.asarray(cut, bool))

    @classmethod
    def from_embedding(cls, embedding: Embedding) -> "Space":
        elements = embedding.active_elements
        return cls.of_elements(embedding.grid, elements, embedding.status[elements] == CUT)

    @property
    def n_elements(self) -> int:
        return int(self.elements.size)

    @property
    def n_nodes(self) -> int:
        return int(self.coordinates.shape[0])

    @property
    def n_dofs(self) -> int:
        return 3 * self.n_nodes

    @property
    def h(self) -> float:
        return self.grid.h

    @property
    def element_dofs(self) -> np.ndarray:
        """(n_elements, 24) dofs of every element, node-major: ``3 * node + component``."""
        return (3 * self.connectivity[:, :, None] + np.arange(3)).reshape(-1, 24)

    def slot(self, grid_elements: np.ndarray) -> np.ndarray:
        """Compact numbers of grid elements (-1 for an inactive one)."""
        grid_elements = np.asarray(grid_elements, np.int64)
        pos = np.searchsorted(self.elements, grid_elements)
        pos = np.minimum(pos, max(self.n_elements - 1, 0))
        return np.where(self.elements[pos] == grid_elements, pos, -1)

    def centres(self) -> np.ndarray:
        """(n_elements, 3) element centres."""
        return self.grid.element_center(self.grid.element_ijk(self.elements))

    def local(self, x: np.ndarray, slots: np.ndarray) -> np.ndarray:
        """Local coordinates (n, 3) of points ``x`` in active elements ``slots``."""
        return (np.asarray(x, float) - self.centres()[slots]) / (0.5 * self.h)

    def offsets(self, slots: np.ndarray) -> np.ndarray:
        """Point ranges (n_elements + 1,) of points sorted by active element ``slots``."""
        counts = np.bincount(slots, minlength=self.n_elements)
        return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)

    def group(self, x: np.ndarray, w: np.ndarray, grid_elements: np.ndarray
              ) -> tuple[ElementPoints, np.ndarray, np.ndarray]:
        """Regroup points (x, w, owning grid element) by active element. Returns the grouped
        points, the permutation applied (to carry further per-point data along) and the
        active element of every grouped point. Points of inactive elements are an error (the
        embedding's rules only hold active elements)."""
        slots = self.slot(grid_elements)
        if np.any(slots < 0):
            raise ValueError("quadrature points in inactive elements")
        order = np.argsort(slots, kind="stable")
        slots = slots[order]
        x = np.asarray(x, float)[order]
        points = ElementPoints(self.local(x, slots), x, np.asarray(w, float)[order], self.offsets(slots))
        return points, order, slots

    def points_at(self, slots: np.ndarray, xi: np.ndarray) -> ElementPoints:
        """Points given by active element and local coordinates (sorted by element), with
        zero weights: where to evaluate a field, not a quadrature rule."""
        slots = np.asarray(slots, np.int64)
        if np.any(np.diff(slots) < 0):
            raise ValueError("points must be sorted by element")
        offsets = self.offsets(slots)
        xi = np.ascontiguousarray(xi, dtype=float)
        return ElementPoints(xi, self.centres()[slots] + 0.5 * self.h * xi, np.zeros(slots.size), offsets)

    def volume_points(self, embedding: Embedding) -> ElementPoints:
        rule = embedding.volume
        return self.group(rule.x, rule.w, rule.element)[0]

    def shape_values(self, xi: np.ndarray) -> np.ndarray:
        """H8 shape functions (n, 8) at local coordinates ``xi`` (n, 3)."""
        xi = np.asarray(xi, float)
        return np.prod(1.0 + xi[:, None, :] * NODE_XI[None, :, :], axis=2) / 8.0

    def interpolate(self, nodal: np.ndarray, slots: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """Values at points of a nodal field ``nodal`` (n_nodes, ...)."""
        n = self.shape_values(xi)
        values = nodal[self.connectivity[slots]]
        return np.einsum("pa,pa...->p...", n, values)
