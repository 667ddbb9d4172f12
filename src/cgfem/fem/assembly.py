"""Sparsity pattern of an H8 space and the maps that assemble into it.

The pattern couples two nodes when they share an active element (or, with ghost-penalty
faces, a pair of neighbouring elements); every node pair is a dense 3x3 block. The CSR
arrays are built once per space; assembling a matrix is then adding numbers into
``data`` at precomputed positions (no COO, no sorting, no duplicate summation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from cgfem.fem.space import Space


@dataclass(frozen=True)
class Pattern:
    """CSR structure of a (n_dofs x n_dofs) matrix over one space.

    indptr, indices : CSR arrays (int64)
    scatter : (n_elements, 576) data position of entry ``(m, n)`` of element ``e`` at
        ``[e, 24 m + n]``
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

    def positions(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Data positions of dof pairs that are in the pattern."""
        rows = np.asarray(rows, np.int64)
        cols = np.asarray(cols, np.int64)
        start, stop = self.indptr[rows], self.indptr[rows + 1]
        # columns of a row are sorted: binary search inside each row's slice
        keys = rows * self.n_dofs + cols
        flat = np.repeat(np.arange(self.n_dofs, dtype=np.int64), np.diff(self.indptr)) * self.n_dofs \
            + self.indices
        pos = np.searchsorted(flat, keys)
        if np.any(pos >= stop) or np.any(pos < start) or np.any(flat[np.minimum(pos, flat.size - 1)] != keys):
            raise ValueError("dof pair outside the sparsity pattern")
        return pos


def colours(space: Space) -> tuple[np.ndarray, ...]:
    """Split the active elements in 8 sets by the parity of their grid indices: two
    elements of one set never share a node."""
    ijk = space.grid.element_ijk(space.elements)
    colour = (ijk[:, 0] % 2) * 4 + (ijk[:, 1] % 2) * 2 + ijk[:, 2] % 2
    return tuple(np.flatnonzero(colour == c) for c in range(8) if np.any(colour == c))


def node_pairs(space: Space, extra_pairs: np.ndarray | None = None) -> np.ndarray:
    """Sorted unique node pairs ``a * n_nodes + b`` coupled by an element (and ``extra``)."""
    c = space.connectivity
    keys = (c[:, :, None] * space.n_nodes + c[:, None, :]).ravel()
    if extra_pairs is not None and extra_pairs.size:
        a, b = extra_pairs[:, 0], extra_pairs[:, 1]
        keys = np.concatenate([keys, a * space.n_nodes + b, b * space.n_nodes + a])
    return np.unique(keys)


def build_pattern(space: Space, extra_pairs: np.ndarray | None = None) -> Pattern:
    """The dof pattern of ``space``; ``extra_pairs`` (m, 2) couples further node pairs (the
    nodes of two elements sharing a face, for the ghost penalty)."""
    nn = space.n_nodes
    pairs = node_pairs(space, extra_pairs)
    a, b = pairs // nn, pairs % nn
    per_node = np.bincount(a, minlength=nn)
    node_ptr = np.concatenate([[0], np.cumsum(per_node)]).astype(np.int64)
    # dof row 3a+i holds the 3 dofs of every neighbour b of a, in order
    row_len = 3 * np.repeat(per_node, 3)
    indptr = np.concatenate([[0], np.cumsum(row_len)]).astype(np.int64)
    start = indptr[3 * a]                      # row 3a's start, per pair
    rank = np.arange(pairs.size) - node_ptr[a]  # position of b among a's neighbours
    indices = np.empty(indptr[-1], np.int64)
    for i in range(3):
        for k in range(3):
            indices[start + i * 3 * per_node[a] + 3 * rank + k] = 3 * b + k
    # scatter positions of every element entry
    c = space.connectivity
    keys = c[:, :, None] * nn + c[:, None, :]            # (ne, 8, 8)
    pair_index = np.searchsorted(pairs, keys)            # index into pairs
    a_e = c[:, :, None]
    base = indptr[3 * a_e] + 3 * (pair_index - node_ptr[a_e])  # (ne, 8, 8): row 3a, col 3b
    rowlen = 3 * per_node[a_e]                           # length of each of a's dof rows
    i = np.arange(3).reshape(1, 1, 3, 1, 1)
    k = np.arange(3).reshape(1, 1, 1, 1, 3)
    scatter = base[:, :, None, :, None] + i * rowlen[:, :, None, :, None] + k
    # axes (e, a, i, b, k) -> entry (3a+i, 3b+k) of the 24x24 element matrix
    scatter = np.ascontiguousarray(scatter.reshape(space.n_elements, 576))
    return Pattern(3 * nn, indptr, indices, scatter, colours(space))
