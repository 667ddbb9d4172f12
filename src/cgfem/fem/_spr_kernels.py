"""Numba kernels of the patch recovery operators of :mod:`cgfem.fem.spr`.

Samples are sorted by element (``sample_ptr``: element -> sample CSR) and sit at positions
``sample_x``. For node ``a`` at ``x_a`` and a patch of active elements, the patch's samples
give the rows ``p_s = (1, (x_s - x_a) / h)`` and the normal matrix ``G = sum_s p_s p_s^T``;
the least-squares linear polynomial through values ``v_s`` has the coefficients
``c = sum_s C_s v_s`` with ``C_s = G^-1 p_s`` (``c[0]``: its value at ``x_a``; ``c[1:] / h``:
its gradient). :func:`patch_operators` returns every node's ``C_s`` (CSR over nodes).

Patch rule. Level 0 is the active elements sharing the node; level ``k + 1`` adds every
active element sharing a node with level ``k``. A level is *well posed* when it has at least
4 samples and the smallest eigenvalue of ``G / n_samples`` exceeds ``min_eig`` (samples not
all in one plane); it is *accepted* when moreover the Lebesgue constant of the nodal value,
``sum_s |C_s[0]|``, is at most ``max_lebesgue`` (a guard against wild extrapolation). The
first accepted level up to ``max_level`` is used; if none is, the well-posed level with the
smallest Lebesgue constant; if none is well posed, the mean of the samples of the largest
patch (a constant fit, ``linear = False``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _patch(a, level, stamp, patch, marker, connectivity, node_ptr, node_elements):
    """Elements of node ``a``'s patch of ``level`` into ``patch``, marked ``stamp`` in
    ``marker``; returns the patch size."""
    n = 0
    for j in range(node_ptr[a], node_ptr[a + 1]):
        e = node_elements[j]
        marker[e] = stamp
        patch[n] = e
        n += 1
    for _ in range(level):
        m = n
        for i in range(n):
            for k in range(8):
                b = connectivity[patch[i], k]
                for j in range(node_ptr[b], node_ptr[b + 1]):
                    f = node_elements[j]
                    if marker[f] != stamp:
                        marker[f] = stamp
                        patch[m] = f
                        m += 1
        n = m
    return n


@njit(cache=True)
def _basis(xa, x, h, p):
    p[0] = 1.0
    for d in range(3):
        p[d + 1] = (x[d] - xa[d]) / h


@njit(cache=True)
def _normal_matrix(xa, patch, n, sample_ptr, sample_x, h):
    """Normal matrix ``G`` (4, 4) and number of samples of a patch."""
    G = np.zeros((4, 4))
    p = np.empty(4)
    count = 0
    for i in range(n):
        for s in range(sample_ptr[patch[i]], sample_ptr[patch[i] + 1]):
            _basis(xa, sample_x[s], h, p)
            for r in range(4):
                for c in range(4):
                    G[r, c] += p[r] * p[c]
            count += 1
    return G, count


@njit(cache=True)
def _lebesgue(xa, patch, n, sample_ptr, sample_x, h, Ginv):
    """``sum_s |C_s[0]|`` of a patch."""
    p = np.empty(4)
    total = 0.0
    for i in range(n):
        for s in range(sample_ptr[patch[i]], sample_ptr[patch[i] + 1]):
            _basis(xa, sample_x[s], h, p)
            total += abs(Ginv[0, 0] + Ginv[0, 1] * p[1] + Ginv[0, 2] * p[2] + Ginv[0, 3] * p[3])
    return total


@njit(cache=True)
def _choose(a, coords, patch, marker, stamp, connectivity, node_ptr, node_elements,
            sample_ptr, sample_x, h, max_level, max_lebesgue, min_eig):
    """``(level, linear)`` of node ``a``'s fit by the patch rule."""
    best_level = -1
    best = np.inf
    for level in range(max_level + 1):
        n = _patch(a, level, stamp + level, patch, marker, connectivity, node_ptr, node_elements)
        G, count = _normal_matrix(coords[a], patch, n, sample_ptr, sample_x, h)
        if count < 4 or np.linalg.eigvalsh(G / count)[0] <= min_eig:
            continue
        leb = _lebesgue(coords[a], patch, n, sample_ptr, sample_x, h, np.linalg.inv(G))
        if leb <= max_lebesgue:
            return level, True
        if leb < best:
            best, best_level = leb, level
    if best_level >= 0:
        return best_level, True
    return max_level, False


@njit(cache=True)
def patch_operators(connectivity, coords, node_ptr, node_elements, sample_ptr, sample_x, h,
                    max_level, max_lebesgue, min_eig):
    """Every node's least-squares operator.

    connectivity (n_elements, 8); coords (n_nodes, 3); node -> element CSR
    ``node_ptr, node_elements``; element -> sample CSR ``sample_ptr``; ``sample_x`` (m, 3).
    Returns ``row_ptr (n_nodes + 1,), cols (nnz,), coef (nnz, 4), level (n_nodes,),
    linear (n_nodes,)``: row ``a`` holds ``C_s`` of the samples ``s`` of node ``a``'s patch.
    """
    n_nodes = coords.shape[0]
    patch = np.empty(connectivity.shape[0], np.int64)
    marker = np.full(connectivity.shape[0], -1, np.int64)
    level = np.empty(n_nodes, np.int64)
    linear = np.empty(n_nodes, np.bool_)
    row_ptr = np.zeros(n_nodes + 1, np.int64)
    stamp = 0
    for a in range(n_nodes):
        level[a], linear[a] = _choose(a, coords, patch, marker, stamp, connectivity, node_ptr,
                                      node_elements, sample_ptr, sample_x, h, max_level,
                                      max_lebesgue, min_eig)
        stamp += max_level + 1
        n = _patch(a, level[a], stamp, patch, marker, connectivity, node_ptr, node_elements)
        stamp += 1
        count = 0
        for i in range(n):
            count += sample_ptr[patch[i] + 1] - sample_ptr[patch[i]]
        row_ptr[a + 1] = row_ptr[a] + count
    cols = np.empty(row_ptr[-1], np.int64)
    coef = np.zeros((row_ptr[-1], 4))
    p = np.empty(4)
    for a in range(n_nodes):
        n = _patch(a, level[a], stamp, patch, marker, connectivity, node_ptr, node_elements)
        stamp += 1
        G, count = _normal_matrix(coords[a], patch, n, sample_ptr, sample_x, h)
        Ginv = np.zeros((4, 4))
        if linear[a]:
            Ginv = np.linalg.inv(G)
        elif count > 0:
            Ginv[0, 0] = 1.0 / count
        pos = row_ptr[a]
        for i in range(n):
            for s in range(sample_ptr[patch[i]], sample_ptr[patch[i] + 1]):
                _basis(coords[a], sample_x[s], h, p)
                cols[pos] = s
                for r in range(4):
                    coef[pos, r] = (Ginv[r, 0] * p[0] + Ginv[r, 1] * p[1]
                                    + Ginv[r, 2] * p[2] + Ginv[r, 3] * p[3])
                pos += 1
    return row_ptr, cols, coef, level, linear


@njit(cache=True)
def _averaged_row(a, write, out_cols, out_vals, start, row_ptr, cols, coef, linear, coords, h,
                  connectivity, node_ptr, node_elements, nb, nb_mark, acc, seen, touched):
    """Row ``a`` of the averaged operator (only counted unless ``write``); returns its size."""
    n_nb = 0
    for j in range(node_ptr[a], node_ptr[a + 1]):
        for k in range(8):
            b = connectivity[node_elements[j], k]
            if nb_mark[b] != a and (linear[b] or b == a):
                nb_mark[b] = a
                nb[n_nb] = b
                n_nb += 1
    if not linear[a] and n_nb > 1:  # a constant fit is not exact at the other nodes: drop it
        for i in range(n_nb):
            if nb[i] == a:
                nb[i] = nb[n_nb - 1]
        n_nb -= 1
    n_out = 0
    for i in range(n_nb):
        b = nb[i]
        d0 = (coords[a, 0] - coords[b, 0]) / h
        d1 = (coords[a, 1] - coords[b, 1]) / h
        d2 = (coords[a, 2] - coords[b, 2]) / h
        for j in range(row_ptr[b], row_ptr[b + 1]):
            s = cols[j]
            if seen[s] != a:
                seen[s] = a
                touched[n_out] = s
                acc[s] = 0.0
                n_out += 1
            if write:
                acc[s] += (coef[j, 0] + d0 * coef[j, 1] + d1 * coef[j, 2] + d2 * coef[j, 3]) / n_nb
    if write:
        for i in range(n_out):
            out_cols[start + i] = touched[i]
            out_vals[start + i] = acc[touched[i]]
    return n_out


@njit(cache=True)
def average_rows(row_ptr, cols, coef, linear, coords, h, connectivity, node_ptr, node_elements,
                 n_samples):
    """ZZ averaging: row ``a`` is the mean, over the nodes ``b`` sharing an element with ``a``
    (``a`` included) whose fit is linear, of ``b``'s polynomial evaluated at ``x_a``
    (a node whose neighbours all have constant fits keeps its own row).
    Returns the CSR arrays ``(indptr, indices, data)`` of the (n_nodes, n_samples) operator."""
    n_nodes = coords.shape[0]
    nb = np.empty(64, np.int64)
    nb_mark = np.full(n_nodes, -1, np.int64)
    acc = np.zeros(n_samples)
    seen = np.full(n_samples, -1, np.int64)
    touched = np.empty(n_samples, np.int64)
    indptr = np.zeros(n_nodes + 1, np.int64)
    empty_c = np.empty(0, np.int64)
    empty_v = np.empty(0)
    for a in range(n_nodes):
        size = _averaged_row(a, False, empty_c, empty_v, 0, row_ptr, cols, coef, linear, coords,
                             h, connectivity, node_ptr, node_elements, nb, nb_mark, acc, seen,
                             touched)
        indptr[a + 1] = indptr[a] + size
    indices = np.empty(indptr[-1], np.int64)
    data = np.empty(indptr[-1])
    nb_mark[:] = -1
    seen[:] = -1
    for a in range(n_nodes):
        _averaged_row(a, True, indices, data, indptr[a], row_ptr, cols, coef, linear, coords, h,
                      connectivity, node_ptr, node_elements, nb, nb_mark, acc, seen, touched)
    return indptr, indices, data
