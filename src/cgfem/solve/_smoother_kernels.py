"""Numba kernels of the multigrid smoother: block Gauss-Seidel sweeps and products on the
strictly lower and strictly upper block triangles of a BSR matrix, stored apart.

A triangle is ``(indptr, indices, blocks)`` as in BSR (``blocks`` (nnzb, m, m), column blocks
sorted within a row), holding the blocks of one side of the diagonal only; an empty triangle
(``indptr`` all zero) stands for a side whose unknowns are known to be zero. Row block ``i``
of ``A x = b`` is solved for ``x_i`` with the other blocks at their latest values,
``x_i = D_i^-1 (b_i - sum_{j < i} L_ij x_j - sum_{j > i} U_ij x_j)``, in the order of the
sweep. The sums run over the blocks in the order of a whole row of ``A`` (forwards: lower
then upper, by column; backwards: upper then lower, by decreasing column), so a sweep gives
the bits of the same sweep over the unsplit row. ``*3`` kernels are the same arithmetic
written out for 3x3 blocks (the nodal blocks of the finest level), about 2.5 times faster
than the loops over a run-time block size.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def sweep(lower_ptr, lower_idx, lower_blk, upper_ptr, upper_idx, upper_blk, dinv, x, b, forward):
    """One sweep over the block rows of ``L + D + U`` with the inverted diagonal blocks
    ``dinv`` (n / m, m, m): ``x`` (n,) updated in place towards ``A x = b``; ``forward``: rows
    in increasing order, else decreasing (each row's blocks then read backwards, so that the
    matrix streams one way)."""
    m = dinv.shape[1]
    rows = lower_ptr.size - 1
    r = np.empty(m)
    for step in range(rows):
        i = step if forward else rows - 1 - step
        for k in range(m):
            r[k] = 0.0
        for part in range(2):
            first = (part == 0) == forward
            ptr, idx, blk = (lower_ptr, lower_idx, lower_blk) if first else (upper_ptr, upper_idx, upper_blk)
            start, stop = ptr[i], ptr[i + 1]
            for q in range(stop - start):
                jj = start + q if forward else stop - 1 - q
                j = idx[jj]
                for k in range(m):
                    v = 0.0
                    for l in range(m):
                        v += blk[jj, k, l] * x[j * m + l]
                    r[k] += v
        for k in range(m):
            r[k] = b[i * m + k] - r[k]
        for k in range(m):
            v = 0.0
            for l in range(m):
                v += dinv[i, k, l] * r[l]
            x[i * m + k] = v


@njit(cache=True)
def sweep3(lower_ptr, lower_idx, lower_blk, upper_ptr, upper_idx, upper_blk, dinv, x, b, forward):
    """:func:`sweep` for 3x3 blocks, operation for operation."""
    rows = lower_ptr.size - 1
    for step in range(rows):
        i = step if forward else rows - 1 - step
        r0 = 0.0
        r1 = 0.0
        r2 = 0.0
        for part in range(2):
            first = (part == 0) == forward
            ptr, idx, blk = (lower_ptr, lower_idx, lower_blk) if first else (upper_ptr, upper_idx, upper_blk)
            start, stop = ptr[i], ptr[i + 1]
            for q in range(stop - start):
                jj = start + q if forward else stop - 1 - q
                j = 3 * idx[jj]
                a = blk[jj]
                x0, x1, x2 = x[j], x[j + 1], x[j + 2]
                r0 += a[0, 0] * x0 + a[0, 1] * x1 + a[0, 2] * x2
                r1 += a[1, 0] * x0 + a[1, 1] * x1 + a[1, 2] * x2
                r2 += a[2, 0] * x0 + a[2, 1] * x1 + a[2, 2] * x2
        r0 = b[3 * i] - r0
        r1 = b[3 * i + 1] - r1
        r2 = b[3 * i + 2] - r2
        d = dinv[i]
        x[3 * i] = d[0, 0] * r0 + d[0, 1] * r1 + d[0, 2] * r2
        x[3 * i + 1] = d[1, 0] * r0 + d[1, 1] * r1 + d[1, 2] * r2
        x[3 * i + 2] = d[2, 0] * r0 + d[2, 1] * r1 + d[2, 2] * r2


@njit(cache=True)
def product(ptr, idx, blk, y, out):
    """``out = T y`` (n,) for the triangle ``T`` (``ptr``, ``idx``, ``blk``), each row summed
    block by block as in :func:`sweep`."""
    m = blk.shape[1]
    r = np.empty(m)
    for i in range(ptr.size - 1):
        for k in range(m):
            r[k] = 0.0
        for jj in range(ptr[i], ptr[i + 1]):
            j = idx[jj]
            for k in range(m):
                v = 0.0
                for l in range(m):
                    v += blk[jj, k, l] * y[j * m + l]
                r[k] += v
        for k in range(m):
            out[i * m + k] = r[k]


@njit(cache=True)
def product3(ptr, idx, blk, y, out):
    """:func:`product` for 3x3 blocks."""
    for i in range(ptr.size - 1):
        r0 = 0.0
        r1 = 0.0
        r2 = 0.0
        for jj in range(ptr[i], ptr[i + 1]):
            j = 3 * idx[jj]
            a = blk[jj]
            y0, y1, y2 = y[j], y[j + 1], y[j + 2]
            r0 += a[0, 0] * y0 + a[0, 1] * y1 + a[0, 2] * y2
            r1 += a[1, 0] * y0 + a[1, 1] * y1 + a[1, 2] * y2
            r2 += a[2, 0] * y0 + a[2, 1] * y1 + a[2, 2] * y2
        out[3 * i] = r0
        out[3 * i + 1] = r1
        out[3 * i + 2] = r2
