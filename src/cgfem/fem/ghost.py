"""Ghost penalty: the remedy of this code for small cut cells.

An element cut so that only a sliver of it is material gives its nodes almost no stiffness:
the matrix becomes arbitrarily ill-conditioned as the sliver shrinks, iterative solvers stall
and direct ones lose digits. Following Burman's ghost penalty, we add on every grid face
shared by two active elements of which at least one is cut

    j(u, v) = gamma * M * h * int_F [du/dn] . [dv/dn] dF,

with ``[du/dn]`` the jump of the normal derivative of the displacement across the face and
``M = lambda + 2 mu`` the P-wave modulus. For trilinear elements the normal derivative is
the only discontinuous part of the gradient and the second normal derivative vanishes, so
this one term ties a sliver's nodes to the well-supported element next to it. It is zero
for every linear displacement field (the patch test stays exact) and of order ``h`` for a
smooth solution, so the optimal rate in the energy norm is kept. The term is linear in ``u``
and is also used, unchanged, in finite strain (it acts on the displacement field, not on
the stress). Effect measured in ``tests/physics/test_ghost.py`` and in the issue note.

On a uniform grid the face matrix is one (16, 16) scalar matrix per axis, computed once.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from cgfem.fem.space import Space, shape_functions
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


def face_matrix(axis: int, h: float) -> np.ndarray:
    """``int_F [dN/dn] [dN/dn] dF`` (16, 16) for the face between a lower and an upper
    element along ``axis`` (nodes of the lower element first), by 2x2 Gauss (exact)."""
    g, gw = tensor_gauss(2, 2)                        # (4, 2) points on the face, (4,) weights
    others = [a for a in range(3) if a != axis]
    xi = np.zeros((g.shape[0], 3))
    xi[:, others] = g
    xi_lower, xi_upper = xi.copy(), xi.copy()
    xi_lower[:, axis], xi_upper[:, axis] = 1.0, -1.0   # the face is the lower element's + face
    d_lower = shape_functions(xi_lower, h)[1][:, :, axis]   # (4, 8) normal derivatives
    d_upper = shape_functions(xi_upper, h)[1][:, :, axis]
    jump = np.concatenate([-d_lower, d_upper], axis=1)  # (4, 16)
    return np.einsum("q,qa,qb->ab", gw * (0.5 * h) ** 2, jump, jump)


def ghost_penalty(space: Space, gamma: float, modulus: float) -> tuple[sp.csr_matrix, np.ndarray]:
    """The ghost-penalty matrix (n_dofs, n_dofs) and the node pairs (m, 2) it couples
    beyond the elements (to be added to the sparsity pattern)."""
    pairs, axes = face_pairs(space)
    n = space.n_dofs
    if pairs.size == 0 or gamma == 0.0:
        return sp.csr_matrix((n, n)), np.zeros((0, 2), np.int64)
    scale = gamma * modulus * space.h
    nodes = np.concatenate([space.connectivity[pairs[:, 0]], space.connectivity[pairs[:, 1]]], axis=1)
    mats = np.stack([face_matrix(a, space.h) for a in range(3)])[axes] * scale   # (m, 16, 16)
    rows = np.broadcast_to(nodes[:, :, None], mats.shape)
    cols = np.broadcast_to(nodes[:, None, :], mats.shape)
    blocks = []
    for i in range(3):
        blocks.append(sp.coo_matrix((mats.ravel(), (3 * rows.ravel() + i, 3 * cols.ravel() + i)),
                                    shape=(n, n)))
    G = sum(blocks).tocsr()
    G.sum_duplicates()
    nn = space.n_nodes
    keys = np.unique((nodes[:, :, None] * nn + nodes[:, None, :]).ravel())
    return G, np.stack([keys // nn, keys % nn], axis=1)
