"""Numba kernel of the system's tangent: a CSR matrix plus a few sparse rows, merged row by row.

The contact couplings touch a few thousand rows of a tangent with millions of entries; the
rows they do not touch are copied, the others merged (both sorted by column).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def add_csr(indptr, indices, data, c_indptr, c_indices, c_data):
    """``A + C`` for CSR ``A`` (``indptr``, ``indices``, ``data``) and ``C`` of the same shape,
    both with sorted, unique column indices per row: the CSR arrays of the sum with sorted
    columns and without zeros (an entry of either, or a sum of both, that is exactly zero is
    left out), entry for entry what scipy's ``A + C`` gives. The index and value arrays are
    views of arrays of ``nnz(A) + nnz(C)`` entries."""
    n = indptr.size - 1
    out_ptr = np.empty(n + 1, indptr.dtype)
    out_ind = np.empty(indices.size + c_indices.size, indices.dtype)
    out_val = np.empty(indices.size + c_indices.size, data.dtype)
    out_ptr[0] = 0
    k = 0
    for i in range(n):
        a, a1, c, c1 = indptr[i], indptr[i + 1], c_indptr[i], c_indptr[i + 1]
        while a < a1 or c < c1:
            if c == c1 or (a < a1 and indices[a] < c_indices[c]):
                column, value = indices[a], data[a]
                a += 1
            elif a == a1 or c_indices[c] < indices[a]:
                column, value = c_indices[c], c_data[c]
                c += 1
            else:
                column, value = indices[a], data[a] + c_data[c]
                a += 1
                c += 1
            if value != 0.0:
                out_ind[k] = column
                out_val[k] = value
                k += 1
        out_ptr[i + 1] = k
    return out_ptr, out_ind[:k], out_val[:k]
