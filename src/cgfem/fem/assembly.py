"""Sparsity pattern of a hexahedral space and the maps that assemble into it.

The pattern couples two nodes when they share an active element (or, with ghost-penalty
faces, a pair of neighbouring elements); every node pair is a dense 3x3 block. The CSR
arrays are built once per space; assembling a matrix is then adding numbers into
``data`` at precomputed positions (no COO, no sorting, no duplicate summation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from cgfem.fem._pattern_kernels import dof_pattern, node_neighbours
from cgfem.fem.space import Space


@dataclass(frozen=True)
class Pattern:
    """CSR structure of a (n_dofs x n_dofs) matrix over one space.

    indptr, indices : CSR arrays, in the index type scipy gives a matrix of this size (int32
        while the size and the nonzeros allow it), so that :meth:`matrix` shares them
    scatter : (n_elements, nd^2) data position of entry ``(m, n)`` of element ``e`` at
        ``[e, nd m + n]``, ``nd`` the element's dofs (24 for the trilinear element, 81 for the
        triquadratic one)
    colours : element lists of one colour each; elements of one colour share no node
    """

    n_dofs: int
    indptr: np.ndarray
    indices: np.ndarray
    scatter: np.ndarray
    colours: tuple[np.ndarray, ...]

    @property
    def nnz(self) -> int:
        return int(self.indices.size)

    def zeros(self) -> np.ndarray:
        return np.zeros(self.nnz)

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """The CSR matrix with these values (shares ``data``)."""
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_dofs, self.n_dofs))


def colours(space: Space) -> tuple[np.ndarray, ...]:
    """Split the active elements in 8 sets by the parity of their grid indices: two
    elements of one set never share a node."""
    ijk = space.grid.element_ijk(space.elements)
    colour = (ijk[:, 0] % 2) * 4 + (ijk[:, 1] % 2) * 2 + ijk[:, 2] % 2
    return tuple(np.flatnonzero(colour == c) for c in range(8) if np.any(colour == c))


def build_pattern(space: Space, extra_pairs: np.ndarray | None = None) -> Pattern:
    """The dof pattern of ``space``; ``extra_pairs`` (m, 2) couples further node pairs (the
    nodes of two elements sharing a face, for the ghost penalty). The scatter map is int32
    when the number of nonzeros allows it (half the memory of int64)."""
    extra = np.zeros((0, 2), np.int64) if extra_pairs is None else np.asarray(extra_pairs, np.int64)
    conn = np.ascontiguousarray(space.connectivity, dtype=np.int64)
    node_ptr, nbr = node_neighbours(conn, space.n_nodes, np.ascontiguousarray(extra[:, 0]),
                                    np.ascontiguousarray(extra[:, 1]))
    nnz = 9 * int(node_ptr[-1])
    nd = space.element.n_dofs
    scatter = np.empty((space.n_elements, nd * nd), np.int32 if nnz < 2**31 - 1 else np.int64)
    indptr, indices = dof_pattern(node_ptr, nbr, conn, scatter)
    # scipy converts the index arrays to the type of index_type on every matrix(): once here
    index = index_type(space.n_dofs, nnz)
    return Pattern(space.n_dofs, indptr.astype(index), indices.astype(index), scatter, colours(space))


def index_type(n: int, nnz: int) -> type:
    """The index type scipy gives a CSR matrix of ``n`` rows (and columns) and ``nnz`` entries:
    int32 while both fit in it, else int64. Index arrays of that type are shared by the
    matrices built on them, not copied."""
    return np.int32 if max(n, nnz) < 2**31 else np.int64
