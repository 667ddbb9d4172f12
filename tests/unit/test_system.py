"""The system's stacking of the bodies' tangent blocks."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from cgfem.solve.system import DiagonalStack, add_couplings, stack_diagonal


@pytest.mark.parametrize("extra", [0, 4])
def test_stacked_blocks_are_scipys_block_diagonal_array_for_array(extra):
    """The CSR arrays themselves (not only the matrix) equal scipy's ``block_diag`` of the same
    blocks: a solver fed either gives bitwise the same results."""
    blocks = [sp.random(n, n, density=0.3, format="csr", random_state=n) for n in (5, 7, 3)]
    blocks[1] = sp.csr_matrix(blocks[1].toarray() + np.eye(7))
    found = stack_diagonal(blocks, extra)
    expected = sp.block_diag(blocks + ([sp.csr_matrix((extra, extra))] if extra else []), format="csr")
    assert found.shape == expected.shape == (15 + extra, 15 + extra)
    assert found.has_canonical_format
    for name in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(found, name), getattr(expected, name)), name
    x = np.random.default_rng(1).standard_normal(15 + extra)
    assert np.array_equal(found @ x, expected @ x)



def test_kept_structure_stacks_new_values_and_rebuilds_on_a_new_structure():
    """While the blocks' index arrays are the same memory only the values are new: the stacked
    index arrays are the kept ones, and the result is :func:`stack_diagonal`'s of the new
    blocks; blocks of another structure, and then the first again, rebuild it."""
    rng = np.random.default_rng(4)
    base = [sp.random(n, n, density=0.4, format="csr", random_state=n) + sp.eye(n, format="csr") for n in (6, 4)]
    stack = DiagonalStack(extra=3)

    def revalued(blocks):
        return [sp.csr_matrix((rng.standard_normal(K.nnz), K.indices, K.indptr), shape=K.shape) for K in blocks]

    def check(found, blocks):
        expected = stack_diagonal(blocks, 3)
        for name in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(found, name), getattr(expected, name)), name
    first = stack(base)
    check(first, base)
    kept = revalued(base)
    found = stack(kept)
    check(found, kept)
    assert np.shares_memory(found.indices, first.indices) and np.shares_memory(found.indptr, first.indptr)
    other = [sp.eye(4, format="csr"), sp.eye(6, format="csr")]
    found = stack(other)
    check(found, other)
    assert not np.shares_memory(found.indices, first.indices)
    again = revalued(base)
    check(stack(again), again)


def test_couplings_are_added_entry_for_entry_as_scipy_adds_them():
    """A tangent with explicit zeros (pattern entries nothing was added to) plus couplings
    with duplicates, entries outside the pattern and one that cancels an entry exactly: the
    CSR arrays of scipy's ``K + C``, zeros dropped as scipy drops them."""
    rng = np.random.default_rng(2)
    K = sp.random(60, 60, density=0.3, format="csr", random_state=3) + sp.eye(60, format="csr")
    K.data[::6] = 0.0
    rows, cols = rng.integers(0, 60, 80), rng.integers(0, 60, 80)
    vals = rng.standard_normal(80)
    k = np.flatnonzero(K.data)[4]
    row = np.searchsorted(K.indptr, k, side="right") - 1
    rows, cols = np.append(rows, [row, rows[0]]), np.append(cols, [K.indices[k], cols[0]])
    vals = np.append(vals, [-K.data[k], 0.5])                  # a cancellation and a duplicate
    C = sp.coo_matrix((vals, (rows, cols)), shape=K.shape)
    found, expected = add_couplings(K, C), K + C.tocsr()
    assert expected.nnz < K.nnz + C.nnz
    for name in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(found, name), getattr(expected, name)), name
    # a tangent whose rows are not sorted takes scipy's own sum: the same matrix
    unsorted = sp.csr_matrix((K.data[::-1].copy(), K.indices.copy(), K.indptr.copy()), shape=K.shape)
    unsorted.indices[K.indptr[0]:K.indptr[1]] = unsorted.indices[K.indptr[0]:K.indptr[1]][::-1]
    assert not unsorted.has_sorted_indices
    assert np.array_equal(add_couplings(unsorted, C).toarray(), (unsorted + C.tocsr()).toarray())


def test_a_floating_bodys_shift_is_scipys_sum_array_for_array():
    """The shift added on the diagonal entries of the floating bodies' rows gives the arrays
    of scipy's ``K + diags(shift)``; a row without its diagonal entry takes scipy's sum."""
    from cgfem.solve.floating import FloatingBodies
    K = sp.random(30, 30, density=0.3, format="csr", random_state=4) + sp.eye(30, format="csr") * 5.0
    K.sum_duplicates()
    floating = FloatingBodies(np.array([0, 12, 30]), [1.0, 1.0], [np.zeros((4, 3)), np.zeros((6, 3))])
    floating.bodies = [1]
    before = K.copy()
    shifted = floating.shifted(K, 1.0, 1.0)
    d = np.zeros(30)
    d[12:] = floating.policy.floating_shift * K.diagonal()[12:]
    expected = K + sp.diags(floating._scale * d, format="csr")
    for name in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(shifted, name), getattr(expected, name)), name
    assert np.array_equal(K.toarray() + np.diag(floating._scale * d), shifted.toarray())
    # the input is left as it was, and a missing diagonal entry falls back to scipy's sum
    assert np.array_equal(K.data, before.data)
    # overwriting: the same arrays, in the input's own memory
    own = K.copy()
    overwritten = floating.shifted(own, 1.0, 1.0, overwrite=True)
    assert overwritten.data is own.data
    for name in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(overwritten, name), getattr(expected, name)), name
    holed = K.tolil()
    holed[20, 20] = 0.0
    holed = holed.tocsr()
    holed.eliminate_zeros()
    assert np.array_equal(floating.shifted(holed, 1.0, 1.0).toarray(),
                          (holed + sp.diags(floating._scale * d, format="csr")).toarray())


def test_the_leading_block_is_scipys_slice_array_for_array():
    """The reduced saddle solver's bodies' block: scipy's ``A[:n][:, :n]``, array for array."""
    from cgfem.solve._sparse_kernels import leading_block
    A = sp.random(50, 50, density=0.2, format="csr", random_state=5)
    for n in (0, 17, 50):
        indptr, indices, data = leading_block(A.indptr, A.indices, A.data, n)
        expected = A[:n][:, :n].tocsr()
        assert np.array_equal(indptr, expected.indptr) and np.array_equal(indices, expected.indices)
        assert np.array_equal(data, expected.data)


def test_scaling_and_symmetric_part_are_scipys_array_for_array():
    """The AMG set-up's ``diag(s) A diag(s)`` and ``(A + A^T) / 2`` give scipy's arrays, on a
    symmetric pattern with a pair that cancels exactly (which scipy drops) and on a pattern
    that is not symmetric; the input is left as it was."""
    from cgfem.solve.linear import scale_symmetric, symmetric_part
    rng = np.random.default_rng(6)
    R = sp.random(40, 40, density=0.2, format="csr", random_state=7)
    A = sp.csr_matrix(R + R.T + sp.eye(40))
    A.data = rng.standard_normal(A.nnz)
    s = rng.uniform(0.5, 2.0, 40)
    expected = sp.csr_matrix(sp.diags(s) @ A @ sp.diags(s))
    expected.eliminate_zeros()
    scaled = scale_symmetric(A, s)
    scaled_before = scaled.toarray()
    assert np.array_equal(scaled.indptr, expected.indptr) and np.array_equal(scaled.indices, expected.indices)
    np.testing.assert_array_equal(scaled.data, A.data * np.repeat(s, np.diff(A.indptr)) * s[A.indices])
    i, j = scaled.nonzero()
    k = np.flatnonzero(i < j)[0]
    scaled[j[k], i[k]] = -scaled[i[k], j[k]]                          # a pair that cancels
    reference = sp.csr_matrix(0.5 * (scaled + scaled.T))
    before = scaled.copy()
    part = symmetric_part(scaled)
    for name in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(part, name), getattr(reference, name)), name
        assert np.array_equal(getattr(scaled, name), getattr(before, name)), name
    assert part.nnz < scaled.nnz
    skew = sp.csr_matrix(sp.triu(A, 1) + sp.eye(40))
    merged, reference = symmetric_part(skew), sp.csr_matrix(0.5 * (skew + skew.T))
    for name in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(merged, name), getattr(reference, name)), name
    # scaled in place when the caller owns the matrix
    mine = A.copy()
    assert scale_symmetric(mine, s, own=True) is mine
    np.testing.assert_array_equal(mine.toarray(), scaled_before)
