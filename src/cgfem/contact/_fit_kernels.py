"""Numba kernels of the fitted contact surface (:mod:`cgfem.contact.fit`,
:mod:`cgfem.contact.fitted`): the rational basis functions of a NURBS surface and their
parametric derivatives up to second order at many points (:func:`rational_basis_batch`), the
banded Cholesky factorization and solve of a fit's matrix ``M``, and the merge of a point's
equal controls (:func:`merge_controls`).

The B-spline factors come from A2.1 FindSpan and A2.3 DersBasisFuns of
:mod:`cgfem.geometry._nurbs_kernels`; the rational functions
``R_ij = N_i M_j w_ij / W`` with ``W = sum_kl N_k M_l w_kl`` follow by the quotient rule of
A4.4 written for every basis function instead of for the surface point::

    R_s  = (A_s - R W_s) / W
    R_ss = (A_ss - 2 R_s W_s - R W_ss) / W
    R_st = (A_st - R_s W_t - R_t W_s - R W_st) / W

(``A = N_i M_j w_ij`` and its tensor-product derivatives).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cgfem.geometry._nurbs_kernels import ders_basis_funs, find_span

#: rows of the derivative axis: R, R_s, R_t, R_ss, R_st, R_tt as ``(k, l)`` orders
ORDERS = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))


@njit(cache=True)
def rational_basis_batch(p, q, U, V, weights, uv, index, R):
    """Rational basis at the points ``uv`` (n, 2) of a surface of degrees ``(p, q)``, knot
    vectors ``U``, ``V`` and weights ``weights`` (n_u, n_v).

    ``index`` (n, (p+1)(q+1)) int64 receives the flat control index ``i n_v + j`` of every
    non-vanishing function (u-major), ``R`` (n, 6, (p+1)(q+1)) its value and its derivatives
    in the order of :data:`ORDERS` (derivatives above a degree are zero).
    """
    n_u = weights.shape[0]
    n_v = weights.shape[1]
    Nu = np.empty((3, p + 1))
    Nv = np.empty((3, q + 1))
    A = np.empty((6, (p + 1) * (q + 1)))
    Wd = np.empty(6)
    for k in range(uv.shape[0]):
        u = uv[k, 0]
        v = uv[k, 1]
        su = find_span(n_u - 1, p, u, U)
        sv = find_span(n_v - 1, q, v, V)
        ders_basis_funs(su, u, p, 2, U, Nu)
        ders_basis_funs(sv, v, q, 2, V, Nv)
        for r in range(6):
            Wd[r] = 0.0
        m = 0
        for a in range(p + 1):
            for b in range(q + 1):
                i = su - p + a
                j = sv - q + b
                w = weights[i, j]
                A[0, m] = Nu[0, a] * Nv[0, b] * w
                A[1, m] = Nu[1, a] * Nv[0, b] * w
                A[2, m] = Nu[0, a] * Nv[1, b] * w
                A[3, m] = Nu[2, a] * Nv[0, b] * w
                A[4, m] = Nu[1, a] * Nv[1, b] * w
                A[5, m] = Nu[0, a] * Nv[2, b] * w
                for r in range(6):
                    Wd[r] += A[r, m]
                index[k, m] = i * n_v + j
                m += 1
        inv = 1.0 / Wd[0]
        for m in range(A.shape[1]):
            r0 = A[0, m] * inv
            rs = (A[1, m] - r0 * Wd[1]) * inv
            rt = (A[2, m] - r0 * Wd[2]) * inv
            R[k, 0, m] = r0
            R[k, 1, m] = rs
            R[k, 2, m] = rt
            R[k, 3, m] = (A[3, m] - 2.0 * rs * Wd[1] - r0 * Wd[3]) * inv
            R[k, 4, m] = (A[4, m] - rs * Wd[2] - rt * Wd[1] - r0 * Wd[4]) * inv
            R[k, 5, m] = (A[5, m] - 2.0 * rt * Wd[2] - r0 * Wd[5]) * inv


@njit(cache=True)
def banded_cholesky(lb):
    """Cholesky factorization ``A = L L^T`` of a symmetric banded matrix in place, lower
    band stored by columns, ``lb[j, d] = A[j + d, j]`` (n, bandwidth + 1) ->
    ``lb[j, d] = L[j + d, j]``: every loop runs along a column's band, contiguous in memory.
    Returns -1, or the first column whose pivot is not positive (A not positive definite)."""
    n = lb.shape[0]
    bw = lb.shape[1] - 1
    for j in range(n):
        # column j of L from the columns k < j that reach row j
        for k in range(max(0, j - bw), j):
            ljk = lb[k, j - k]
            if ljk == 0.0:
                continue
            for i in range(j, min(n, k + bw + 1)):
                lb[j, i - j] -= lb[k, i - k] * ljk
        pivot = lb[j, 0]
        if not pivot > 0.0:
            return j
        d = np.sqrt(pivot)
        lb[j, 0] = d
        for i in range(1, min(bw + 1, n - j)):
            lb[j, i] /= d
    return -1


@njit(cache=True)
def banded_cholesky_solve(lb, b):
    """Solve ``L L^T x = b`` in place for ``b`` (n, m) with the factor of
    :func:`banded_cholesky`. Each entry of ``x`` takes the same operations in the same order
    for any ``m``; with three columns (a fit's x, y, z) their running values stay in
    registers."""
    n = lb.shape[0]
    bw = lb.shape[1] - 1
    m = b.shape[1]
    if m == 3:
        for j in range(n):                      # L y = b
            d = lb[j, 0]
            x0, x1, x2 = b[j, 0] / d, b[j, 1] / d, b[j, 2] / d
            b[j, 0], b[j, 1], b[j, 2] = x0, x1, x2
            for i in range(j + 1, min(n, j + bw + 1)):
                lij = lb[j, i - j]
                b[i, 0] -= lij * x0
                b[i, 1] -= lij * x1
                b[i, 2] -= lij * x2
        for j in range(n - 1, -1, -1):          # L^T x = y
            s0, s1, s2 = b[j, 0], b[j, 1], b[j, 2]
            for i in range(j + 1, min(n, j + bw + 1)):
                lij = lb[j, i - j]
                s0 -= lij * b[i, 0]
                s1 -= lij * b[i, 1]
                s2 -= lij * b[i, 2]
            d = lb[j, 0]
            b[j, 0], b[j, 1], b[j, 2] = s0 / d, s1 / d, s2 / d
        return
    for j in range(n):                      # L y = b
        for c in range(m):
            b[j, c] /= lb[j, 0]
        for i in range(j + 1, min(n, j + bw + 1)):
            lij = lb[j, i - j]
            for c in range(m):
                b[i, c] -= lij * b[j, c]
    for j in range(n - 1, -1, -1):          # L^T x = y
        for i in range(j + 1, min(n, j + bw + 1)):
            lij = lb[j, i - j]
            for c in range(m):
                b[j, c] -= lij * b[i, c]
        for c in range(m):
            b[j, c] /= lb[j, 0]


#: a row's node where it has no valid entry (:func:`merge_controls`)
NO_CONTROL = np.iinfo(np.int64).max


@njit(cache=True)
def merge_controls(nodes, coef, valid):
    """Per row ``p``, the distinct values among ``nodes[p]`` (n, W) where ``valid[p]``
    (n, W), ascending, with the coefficients ``coef[p]`` (n, r, W) of equal values summed in
    their column order (from 0.0): returns ``(merged nodes (n, W'), merged coef (n, r, W'))``,
    ``W'`` the largest count of distinct values of a row (at least 1). Shorter rows are
    padded with their smallest value (:data:`NO_CONTROL` if they have none) and coefficient 0."""
    n, w = nodes.shape
    r = coef.shape[1]
    order = np.empty((n, w), np.int64)            # each row's valid columns by value, stable
    live = np.zeros(n, np.int64)
    width = 1
    for p in range(n):
        k = 0
        for a in range(w):
            if valid[p, a]:
                i = k
                while i > 0 and nodes[p, order[p, i - 1]] > nodes[p, a]:
                    order[p, i] = order[p, i - 1]
                    i -= 1
                order[p, i] = a
                k += 1
        live[p] = k
        distinct = 0
        for t in range(k):
            if t == 0 or nodes[p, order[p, t]] != nodes[p, order[p, t - 1]]:
                distinct += 1
        width = max(width, distinct)
    merged = np.empty((n, width), np.int64)
    summed = np.zeros((n, r, width))
    for p in range(n):
        merged[p, :] = nodes[p, order[p, 0]] if live[p] > 0 else NO_CONTROL
        g = -1
        for t in range(live[p]):
            a = order[p, t]
            if t == 0 or nodes[p, a] != nodes[p, order[p, t - 1]]:
                g += 1
                merged[p, g] = nodes[p, a]
            for c in range(r):
                summed[p, c, g] += coef[p, c, a]
    return merged, summed
