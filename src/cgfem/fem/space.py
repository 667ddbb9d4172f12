"""The displacement field of one body on its active grid elements, for a hexahedral element
of order 1 or 2 (:mod:`cgfem.fem.element`).

Active elements (inside and cut) and their nodes get compact numbers; the displacement has
three components per active node, interleaved: dof ``3 * node + component``. The nodes of
order ``p`` lie on the lattice of spacing ``h / p`` of the grid (its nodes for ``p = 1``), and
are numbered by ascending lattice id. Quadrature points of the embedding are regrouped per
active element (:class:`ElementPoints`) and carry their local coordinates
``xi = (x - x_c) / (h / 2)`` in ``[-1, 1]^3`` (points of a moment-fitted rule may lie anywhere
in the cube), which is all the element kernels need: on an axis-aligned cube
``dN/dx = (2 / h) dN/dxi``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.quadrature import CUT, Embedding
from cgfem.fem import _element_kernels as kern
from cgfem.fem._element_kernels import NODE_XI
from cgfem.fem.element import HEX8, Hexahedron

__all__ = ["NODE_XI", "ElementPoints", "Space", "element_mesh"]

#: distance (in units of h) from a grid plane within which :meth:`Space.locate` also looks
#: for a point in the element across the plane
LOCATE_TOL = 1e-10


def element_mesh(grid: CartesianGrid, elements: np.ndarray, element: Hexahedron = HEX8
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The nodes of ``element`` on the grid elements ``elements`` (m,) (ascending ids).

    Returns ``coordinates`` (n, 3) of the nodes in ascending id on the lattice of spacing
    ``h / order`` (for order 1 the grid's nodes, as :func:`cgfem.embedding.export.active_hex_mesh`)
    and ``connectivity`` (m, n_nodes), each element's nodes in the element's node order.
    """
    p = element.order
    shape = np.asarray(grid.shape, np.int64) * p + 1
    ijk = p * grid.element_ijk(np.asarray(elements, np.int64))[:, None, :] + element.node_ijk[None, :, :]
    ids = (ijk[..., 0] * shape[1] + ijk[..., 1]) * shape[2] + ijk[..., 2]
    nodes = np.unique(ids)
    lattice = np.stack(np.unravel_index(nodes, tuple(shape)), axis=-1)
    coordinates = np.asarray(grid.origin) + lattice.astype(float) * (grid.h / p)
    return coordinates.reshape(-1, 3), np.searchsorted(nodes, ids).astype(np.int64)


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
    """A hexahedral field over the active elements of a grid.

    elements : (n_elements,) grid ids of the active elements, ascending
    connectivity : (n_elements, n_nodes per element) compact node numbers, in the element's
        node order
    coordinates : (n_nodes, 3) node positions
    cut : (n_elements,) bool, element cut by the boundary
    element : the element (:data:`~cgfem.fem.element.HEX8` or :data:`~cgfem.fem.element.HEX27`)
    """

    grid: CartesianGrid
    elements: np.ndarray
    connectivity: np.ndarray
    coordinates: np.ndarray
    cut: np.ndarray
    element: Hexahedron = HEX8

    @classmethod
    def of_elements(cls, grid: CartesianGrid, elements: np.ndarray, cut: np.ndarray,
                    element: Hexahedron = HEX8) -> "Space":
        """The space of ``element`` on the grid elements ``elements`` (ascending ids); nodes
        are numbered by ascending lattice id (:func:`element_mesh`)."""
        coordinates, connectivity = element_mesh(grid, elements, element)
        return cls(grid, np.asarray(elements, np.int64), connectivity, coordinates, np.asarray(cut, bool),
                   element)

    @classmethod
    def from_embedding(cls, embedding: Embedding, element: Hexahedron = HEX8) -> "Space":
        elements = embedding.active_elements
        return cls.of_elements(embedding.grid, elements, embedding.status[elements] == CUT, element)

    @property
    def kernel_element(self) -> tuple[np.ndarray, int]:
        """``(ijk, order)``: the element as the kernels of :mod:`cgfem.fem._element_kernels`
        take it."""
        return self.element.node_ijk, self.element.order

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
        """(n_elements, 3 n_nodes per element) dofs of every element, node-major:
        ``3 * node + component``."""
        return (3 * self.connectivity[:, :, None] + np.arange(3)).reshape(-1, self.element.n_dofs)

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

    def interpolate(self, nodal: np.ndarray, slots: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """Values at points of a nodal field ``nodal`` (n_nodes, ...)."""
        n = self.element.tabulate(xi, self.h)[0]
        values = nodal[self.connectivity[slots]]
        return np.einsum("pa,pa...->p...", n, values)

    # -- point evaluation at arbitrary points ------------------------------------------------
    def locate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The active element holding each point ``x`` (n, 3), in any order: ``slots`` (n,)
        compact element numbers and local coordinates ``xi`` (n, 3), with
        ``x = centre + (h / 2) xi``. A point on a face (within :data:`LOCATE_TOL` h of a grid
        plane) is given to the element whose lower face holds it if that one is active, else
        to the active one across the face: deterministic, and active wherever possible.
        Points in no active element (outside the grid, in outside elements) get slot -1 and
        NaN ``xi``."""
        x = np.ascontiguousarray(np.asarray(x, float).reshape(-1, 3))
        slots = np.empty(x.shape[0], np.int64)
        xi = np.empty((x.shape[0], 3))
        grid = self.grid
        kern.locate(x, np.asarray(grid.origin, float), float(grid.h), np.asarray(grid.shape, np.int64),
                    self.elements, LOCATE_TOL, slots, xi)
        return slots, xi

    def evaluate(self, u: np.ndarray, slots: np.ndarray, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The displacement ``u`` (n_dofs,) at points given by active element ``slots`` (n,)
        and local coordinates ``xi`` (n, 3), in any order (e.g. from :meth:`locate`):
        ``values`` (n, 3) and ``gradients`` (n, 3, 3), ``gradients[p, i, J] = du_i/dX_J``.
        Points with slot -1 get NaN."""
        slots = np.asarray(slots, np.int64).reshape(-1)
        xi = np.asarray(xi, float).reshape(-1, 3)
        u = np.ascontiguousarray(np.asarray(u, float).reshape(-1))
        if u.size != self.n_dofs:
            raise ValueError(f"u has {u.size} entries, the space {self.n_dofs} dofs")
        if slots.size != xi.shape[0]:
            raise ValueError(f"{slots.size} slots for {xi.shape[0]} points")
        if np.any(slots >= self.n_elements):
            raise ValueError("slots beyond the active elements")
        # the element kernels take points grouped by element: sort, evaluate, scatter back
        valid = np.flatnonzero(slots >= 0)
        order = valid[np.argsort(slots[valid], kind="stable")]
        offsets = self.offsets(slots[order])
        xs = np.ascontiguousarray(xi[order])
        values = np.full((slots.size, 3), np.nan)
        gradients = np.full((slots.size, 3, 3), np.nan)
        ijk, p = self.kernel_element
        values[order] = kern.point_values(ijk, p, self.connectivity, u.reshape(-1, 3), xs, offsets, self.h)
        gradients[order] = kern.point_gradients(ijk, p, self.connectivity, u, xs, offsets, self.h)
        return values, gradients
