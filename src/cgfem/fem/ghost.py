"""Ghost penalty: the remedy of this code for small cut cells.

An element cut so that only a sliver of it is material gives its nodes almost no stiffness:
the matrix becomes arbitrarily ill-conditioned as the sliver shrinks, iterative solvers stall
and direct ones lose digits. Following Burman's ghost penalty, we add on every grid face
shared by two active elements of which at least one is cut

    j(u, v) = gamma * M * sum_{k=1..p} h^(2k - 1) int_F [d^k u/dn^k] . [d^k v/dn^k] dF,

with ``[d^k u/dn^k]`` the jump of the k-th normal derivative of the displacement across the
face, ``p`` the element's order and ``M = lambda + 2 mu`` the P-wave modulus. A polynomial
of degree ``p`` per variable is continuous with its tangential derivatives across a face, so
the normal derivatives up to order ``p`` are all that can jump; the penalty ties a sliver's
nodes to the well-supported element next to it. It is zero for every polynomial of degree
``p`` on the pair of elements (the patch test stays exact) and of order ``h^p`` for a
smooth solution, so the optimal rate in the energy norm is kept. The term is linear in ``u``
and is also used, unchanged, in finite strain (it acts on the displacement field, not on
the stress). Its effect on the conditioning is measured in
``tests/physics/test_ghost.py`` (docs/validation.md).

On a uniform grid the face matrix is one (2 n, 2 n) scalar matrix per axis (``n`` nodes per
element), computed once.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from cgfem.fem._pattern_kernels import add_node_blocks
from cgfem.fem.assembly import Pattern
from cgfem.fem.element import HEX8, Hexahedron
from cgfem.fem.space import Space
from cgfem.quadrature_rules import tensor_gauss


def face_pairs(space: Space) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of active elements sharing a face with at least one of them cut.

    Returns ``(pairs (m, 2), axis (m,))``: compact element numbers, the first one on the
    lower side of the face along ``axis``.
    """
    grid = space.grid
    ijk = grid.element_ijk(space.elements)
    pairs, axes = [], []
    for axis in range(3):
        step = np.zeros(3, np.int64)
        step[axis] = 1
        upper = ijk + step
        inside = upper[:, axis] < grid.shape[axis]
        lower_slot = np.flatnonzero(inside)
        upper_slot = space.slot(grid.element_id(upper[inside]))
        keep = upper_slot >= 0
        lower_slot, upper_slot = lower_slot[keep], upper_slot[keep]
        keep = space.cut[lower_slot] | space.cut[upper_slot]
        pairs.append(np.stack([lower_slot[keep], upper_slot[keep]], axis=1))
        axes.append(np.full(int(keep.sum()), axis))
    return np.concatenate(pairs).astype(np.int64), np.concatenate(axes)


def face_matrix(axis: int, h: float, element: Hexahedron = HEX8) -> np.ndarray:
    """``sum_k h^(2k - 2) int_F [d^k N/dn^k] [d^k N/dn^k] dF`` (2 n, 2 n), ``k = 1..order``,
    for the face between a lower and an upper element along ``axis`` (nodes of the lower
    element first), by tensor Gauss on the face (exact: degree ``2 order`` per variable)."""
    g, gw = tensor_gauss(element.gauss_points, 2)      # points on the face, weights
    others = [a for a in range(3) if a != axis]
    xi = np.zeros((g.shape[0], 3))
    xi[:, others] = g
    xi_lower, xi_upper = xi.copy(), xi.copy()
    xi_lower[:, axis], xi_upper[:, axis] = 1.0, -1.0   # the face is the lower element's + face
    _, d_lower, dd_lower = element.tabulate(xi_lower, h, second=True)
    _, d_upper, dd_upper = element.tabulate(xi_upper, h, second=True)
    derivatives = [(d_lower[:, :, axis], d_upper[:, :, axis]),
                   (dd_lower[:, :, axis, axis], dd_upper[:, :, axis, axis])]
    out = np.zeros((2 * element.n_nodes, 2 * element.n_nodes))
    for k, (lower, upper) in enumerate(derivatives[:element.order], start=1):
        jump = np.concatenate([-lower, upper], axis=1)  # (q, 2 n)
        out += h ** (2 * k - 2) * np.einsum("q,qa,qb->ab", gw * (0.5 * h) ** 2, jump, jump)
    return out


class GhostFaces(NamedTuple):
    """The faces :func:`face_pairs` finds, by their elements' nodes: ``nodes`` (m, 2 n), the
    lower element's ``n`` nodes then the upper one's, and ``axes`` (m,), each face's normal."""

    nodes: np.ndarray
    axes: np.ndarray

    @classmethod
    def of(cls, space: Space) -> "GhostFaces":
        pairs, axes = face_pairs(space)
        nodes = np.concatenate([space.connectivity[pairs[:, 0]], space.connectivity[pairs[:, 1]]], axis=1)
        return cls(np.ascontiguousarray(nodes, dtype=np.int64), axes)

    def node_pairs(self, element: Hexahedron) -> np.ndarray:
        """The node pairs (k, 2) across the faces that no element couples: a node of the lower
        element off the face with one of the upper element off it (a node on the face is in
        both elements); with repeats, one direction (the pattern builder adds both)."""
        m = element.n_nodes
        lower, upper = [], []
        for axis in range(3):
            face = self.nodes[self.axes == axis]
            below = np.flatnonzero(element.node_ijk[:, axis] < element.order)
            above = np.flatnonzero(element.node_ijk[:, axis] > 0)
            a, b = face[:, below], face[:, m + above]
            lower.append(np.repeat(a, above.size, axis=1).ravel())
            upper.append(np.tile(b, (1, below.size)).ravel())
        return np.stack([np.concatenate(lower), np.concatenate(upper)], axis=1).astype(np.int64)


def ghost_penalty(space: Space, faces: GhostFaces, pattern: Pattern, gamma: float,
                  modulus: float) -> tuple[sp.csr_matrix, np.ndarray]:
    """The ghost-penalty matrix (n_dofs, n_dofs) of ``faces`` with ``gamma`` and the P-wave
    ``modulus``, and the positions of its entries in the data of ``pattern`` (which must
    couple the faces' nodes: :meth:`GhostFaces.node_pairs`), in the order of its own data.
    Entries that sum to exactly zero are left out."""
    n = space.n_dofs
    if faces.axes.size == 0 or gamma == 0.0:
        return sp.csr_matrix((n, n)), np.zeros(0, np.int64)
    blocks = np.stack([face_matrix(a, space.h, space.element) for a in range(3)]) * (gamma * modulus * space.h)
    values = pattern.zeros()
    add_node_blocks(faces.nodes, blocks, faces.axes.astype(np.int64), pattern.indptr, pattern.indices, values)
    positions = np.flatnonzero(values)
    indptr = np.searchsorted(positions, pattern.indptr).astype(pattern.indptr.dtype)
    G = sp.csr_matrix((values[positions], pattern.indices[positions], indptr), shape=(n, n))
    return G, positions
