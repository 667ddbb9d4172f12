"""The system's stacking of the bodies' tangent blocks."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from cgfem.solve.system import stack_diagonal


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

