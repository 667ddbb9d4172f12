"""Numba kernels of the system's tangent, on CSR arrays with sorted, unique columns per row.

The contact couplings touch a few thousand rows of a tangent with millions of entries; the
rows they do not touch are copied, the others merged (:func:`sum_csr`). A floating body's
shift adds to the diagonal entries of its rows (:func:`diagonal_positions`), the reduced
saddle solver takes the bodies' leading block (:func:`leading_block`), and the AMG set-up
scales its own copy (:func:`scale_values`) and adds its transpose (:func:`sum_csr`): scipy's
general sums, products and slicing of the whole matrix cost a second and several copies of
it each at half a million unknowns.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _position(indptr, indices, row, column):
    """The position of entry ``(row, column)`` (binary search in the row's sorted columns), -1
    if there is none."""
    lo, hi = indptr[row], indptr[row + 1]
    while lo < hi:
        mid = (lo + hi) // 2
        if indices[mid] < column:
            lo = mid + 1
        else:
            hi = mid
    return lo if lo < indptr[row + 1] and indices[lo] == column else -1


@njit(cache=True)
def diagonal_positions(indptr, indices, rows):
    """The position in ``indices`` of the diagonal entry of each row of ``rows`` (k,), -1
    where the row has none."""
    out = np.empty(rows.size, np.int64)
    for r in range(rows.size):
        out[r] = _position(indptr, indices, rows[r], rows[r])
    return out


@njit(cache=True)
def leading_block(indptr, indices, data, n):
    """The CSR arrays of the leading ``n`` x ``n`` block: the first ``n`` rows' entries in
    columns below ``n``, in their order (scipy's ``A[:n][:, :n]`` of a matrix with sorted
    columns)."""
    out_ptr = np.empty(n + 1, indptr.dtype)
    size = 0
    for i in range(n):
        for a in range(indptr[i], indptr[i + 1]):
            if indices[a] < n:
                size += 1
    out_ind = np.empty(size, indices.dtype)
    out_val = np.empty(size, data.dtype)
    out_ptr[0] = 0
    k = 0
    for i in range(n):
        for a in range(indptr[i], indptr[i + 1]):
            if indices[a] < n:
                out_ind[k] = indices[a]
                out_val[k] = data[a]
                k += 1
        out_ptr[i + 1] = k
    return out_ptr, out_ind, out_val


@njit(cache=True)
def scale_values(indptr, indices, data, s, out):
    """The values of ``diag(s) A diag(s)`` on ``A``'s pattern into ``out`` (nnz,; ``data``
    itself allowed): ``data[k] * s[i] * s[j]`` for entry ``k`` in row ``i``, column ``j``
    (numpy's ``data * s_rows * s_cols``, bit for bit)."""
    for i in range(indptr.size - 1):
        for k in range(indptr[i], indptr[i + 1]):
            out[k] = data[k] * s[i] * s[indices[k]]


@njit(cache=True)
def sum_csr(indptr, indices, data, c_indptr, c_indices, c_data, factor):
    """``factor (A + C)`` for CSR ``A`` (``indptr``, ``indices``, ``data``) and ``C`` of the same
    shape, both with sorted, unique column indices per row: the CSR arrays of the sum with
    sorted columns and without zeros (an entry of either, or a sum of both, that is exactly
    zero is left out), each value ``factor * (a + c)``: entry for entry what scipy's
    ``factor * (A + C)`` gives. The rows are merged twice, counting first, so that the arrays
    have the sum's size."""
    n = indptr.size - 1
    out_ptr = np.empty(n + 1, indptr.dtype)
    out_ptr[0] = 0
    out_ind = np.empty(0, indices.dtype)
    out_val = np.empty(0, np.float64)
    size = 0
    for sweep in range(2):
        if sweep == 1:
            out_ind = np.empty(size, indices.dtype)
            out_val = np.empty(size, np.float64)
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
                    if sweep == 1:
                        out_ind[k] = column
                        out_val[k] = factor * value
                    k += 1
            if sweep == 1:
                out_ptr[i + 1] = k
        size = k
    return out_ptr, out_ind, out_val
