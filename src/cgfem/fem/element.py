"""The hexahedral elements of the grid: trilinear (8 nodes) and triquadratic (27 nodes).

An element is a tensor-product Lagrange hexahedron of order ``p`` on the cube of size ``h``
of a grid element: its ``(p + 1)^3`` nodes sit at the local coordinates ``xi`` in
``{-1, ..., 1}^3`` spaced ``2 / p`` apart, and the shape function of the node with tensor
indices ``(i, j, k)`` is ``N = l_i(xi_0) l_j(xi_1) l_k(xi_2)`` with the 1D Lagrange
polynomials ``l`` of order ``p`` on equally spaced points (:func:`~cgfem.fem._element_kernels.lagrange`).
Physical derivatives on the axis-aligned cube are ``dN/dX = (2 / h) dN/dxi``.

Node order: :data:`HEX8` takes the grid's corner order (:meth:`cgfem.embedding.grid.CartesianGrid.element_nodes`,
VTK's hexahedron), :data:`HEX27` VTK's triquadratic hexahedron (corners, the 12 edge
midpoints, the 6 face centres, the centre), so that ``step_NNN.vtu`` writes the
connectivity as it is. The number of nodes per element, the quadrature degree an element
needs and its cell type are read from the element everywhere; no other module assumes 8.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from cgfem.fem import _element_kernels as kern

__all__ = ["Hexahedron", "HEX8", "HEX27", "ORDERS", "hexahedron"]


@dataclass(frozen=True)
class Hexahedron:
    """A Lagrange hexahedron of order 1 or 2.

    order : polynomial order per variable
    node_ijk : (n_nodes, 3) int64 tensor indices of the nodes, each in ``0..order``
    cell_type : the meshio cell type of ``step_NNN.vtu`` (``hexahedron``, ``hexahedron27``)
    ghost_penalty : the default ghost-penalty parameter ``gamma`` of this element (the case's
        ``solver.ghost_penalty`` overrides it; :mod:`cgfem.fem.ghost`)
    kappa_dirichlet : the default weak-Dirichlet factor ``kappa_D`` of this element,
        ``beta = kappa_D E / h`` (the case's ``solver.kappa_dirichlet`` overrides it;
        :class:`cgfem.fem.boundary.WeakDirichlet`)
    """

    order: int
    node_ijk: np.ndarray = field(repr=False)
    cell_type: str
    ghost_penalty: float
    kappa_dirichlet: float

    @property
    def n_nodes(self) -> int:
        """Nodes per element, ``(order + 1)^3``."""
        return int(self.node_ijk.shape[0])

    @property
    def n_dofs(self) -> int:
        """Displacement dofs per element, ``3 n_nodes``."""
        return 3 * self.n_nodes

    @property
    def degree(self) -> int:
        """The polynomial degree per variable its stiffness and mass integrands reach,
        ``2 order``: the degree the quadrature of a cut element must integrate exactly."""
        return 2 * self.order

    @property
    def gauss_points(self) -> int:
        """Gauss points per direction that integrate :attr:`degree` exactly on a whole cube."""
        return self.order + 1

    @property
    def node_xi(self) -> np.ndarray:
        """(n_nodes, 3) local coordinates of the nodes in ``[-1, 1]^3``."""
        return -1.0 + (2.0 / self.order) * self.node_ijk

    @functools.cached_property
    def to_bernstein(self) -> np.ndarray:
        """(n_nodes, n_nodes) the map from nodal values to the coefficients of the same
        polynomial in the tensor-product Bernstein basis of the element's order (node
        layout alike). The Bernstein basis is non-negative and sums to one, so a field on the
        element lies in the convex hull of its Bernstein coefficients: the bound the contact
        search takes for an element's displaced box (Lagrange shape functions of order 2 go
        negative, and the nodal values alone do not bound the field). The identity at order 1."""
        return _bernstein_map(self.order, self.node_ijk)

    @property
    def lebesgue(self) -> float:
        """The element's Lebesgue constant ``max_xi sum_a |N_a(xi)|`` over the cube: no point
        of an element moves further than this times its largest nodal move. 1 at order 1
        (non-negative shape functions); ``(5/4)^3`` at order 2 (``|l_0| + |l_1| + |l_2|``
        peaks at 5/4 at ``x = +-1/2``)."""
        return 1.0 if self.order == 1 else 1.25 ** 3

    @property
    def vertices(self) -> np.ndarray:
        """(8,) the element's corner nodes (the first eight), in the grid's corner order."""
        return np.arange(8)

    def tabulate(self, xi: np.ndarray, h: float, second: bool = False
                 ) -> tuple[np.ndarray, np.ndarray] | tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Shape functions at local coordinates ``xi`` (n, 3) of a cube of size ``h``.

        Returns
        -------
        N : (n, n_nodes)
        dN : (n, n_nodes, 3), ``dN[p, a, J] = dN_a/dX_J``
        d2N : (n, n_nodes, 3, 3), ``d2N[p, a, J, K] = d2N_a/dX_J dX_K`` (if ``second``)
        """
        xi = np.ascontiguousarray(np.asarray(xi, float).reshape(-1, 3))
        N, dN, d2N = kern.basis_at(self.node_ijk, self.order, xi, float(h), second)
        return (N, dN, d2N) if second else (N, dN)


def _bernstein_map(order: int, node_ijk: np.ndarray) -> np.ndarray:
    """:attr:`Hexahedron.to_bernstein`: the inverse of the 1D collocation matrix
    ``V[i, j] = B_j(t_i)`` (Bernstein polynomials of ``order`` at the equally spaced nodes
    ``t_i = i / order`` of [0, 1]), taken in tensor product over the node layout."""
    t = np.arange(order + 1) / order
    j = np.arange(order + 1)
    binom = np.array([math.comb(order, k) for k in j], float)
    V = binom[None, :] * t[:, None] ** j[None, :] * (1.0 - t[:, None]) ** (order - j[None, :])
    T = np.linalg.inv(V)
    a, b = node_ijk[:, None, :], node_ijk[None, :, :]
    return T[a[..., 0], b[..., 0]] * T[a[..., 1], b[..., 1]] * T[a[..., 2], b[..., 2]]


#: the trilinear hexahedron (H8), the paper's element
HEX8 = Hexahedron(1, kern.HEX8_IJK, "hexahedron", ghost_penalty=0.05, kappa_dirichlet=10.0)
#: the triquadratic Lagrange hexahedron (27 nodes, VTK's node order)
#: (kappa_D 10 lets the outer loop of nearly incompressible rubber diverge at order 2:
#: docs/methods/elasticity.md, "Weak Dirichlet conditions with a recovered stress")
HEX27 = Hexahedron(2, kern.HEX27_IJK, "hexahedron27", ghost_penalty=0.01, kappa_dirichlet=640.0)
#: the element of each order ``cgfem run --order`` accepts
ORDERS = {1: HEX8, 2: HEX27}


def hexahedron(order: int) -> Hexahedron:
    """The element of ``order`` (1 or 2); ``ValueError`` otherwise."""
    try:
        return ORDERS[int(order)]
    except (KeyError, ValueError, TypeError):
        raise ValueError(f"element order must be one of {sorted(ORDERS)}, got {order!r}") from None
