"""Numba kernels of the patch recovery operators of :mod:`cgfem.fem.spr`.

Samples are sorted by element (``sample_ptr``: element -> sample CSR) and sit at positions
``sample_x``. Patches belong to the grid's vertices (the first eight nodes of every element).
For vertex ``a`` at ``x_a`` and a patch of active elements, the patch's samples give the rows
``p_s = P((x_s - x_a) / h)`` of the complete polynomial basis ``P`` of ``n_terms`` terms
(:func:`_basis`: 4, linear, or 10, quadratic) and the normal matrix ``G = sum_s p_s p_s^T``; the
least-squares polynomial through values ``v_s`` has the coefficients ``c = sum_s C_s v_s``
with ``C_s = G^-1 p_s`` (``c[0]``: its value at ``x_a``). :func:`patch_operators` returns every
vertex's ``C_s`` (CSR over nodes; other nodes have none).

Patch rule. Level 0 is the active elements sharing the vertex; level ``k + 1`` adds every
active element sharing a vertex with level ``k``. A level is *well posed* when it has at
least ``n_terms`` samples and the smallest eigenvalue of ``G / n_samples`` exceeds ``min_eig``
(samples not degenerate for the basis); it is *accepted* when moreover the Lebesgue constant
of the nodal value, ``sum_s |C_s[0]|``, is at most ``max_lebesgue`` (a guard against wild
extrapolation). The first accepted level up to ``max_level`` is used; if none is, the
well-posed level with the smallest Lebesgue constant; if none is well posed, the mean of the
samples of the largest patch (a constant fit, ``linear = False``).
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
            for k in range(8):              # the element's vertices
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
    """The complete polynomial basis of ``p.size`` terms (4: linear, 10: quadratic) at
    ``d = (x - xa) / h``: ``1, d0, d1, d2`` then ``d0^2, d1^2, d2^2, d0 d1, d1 d2, d0 d2``."""
    d0 = (x[0] - xa[0]) / h
    d1 = (x[1] - xa[1]) / h
    d2 = (x[2] - xa[2]) / h
    p[0] = 1.0
    p[1] = d0
    p[2] = d1
    p[3] = d2
    if p.size > 4:
        p[4] = d0 * d0
        p[5] = d1 * d1
        p[6] = d2 * d2
        p[7] = d0 * d1
        p[8] = d1 * d2
        p[9] = d0 * d2


@njit(cache=True)
def _normal_matrix(xa, patch, n, sample_ptr, sample_x, h, n_terms):
    """Normal matrix ``G`` (n_terms, n_terms) and number of samples of a patch."""
    G = np.zeros((n_terms, n_terms))
    p = np.empty(n_terms)
    count = 0
    for i in range(n):
        for s in range(sample_ptr[patch[i]], sample_ptr[patch[i] + 1]):
            _basis(xa, sample_x[s], h, p)
            for r in range(n_terms):
                for c in range(n_terms):
                    G[r, c] += p[r] * p[c]
            count += 1
    return G, count


@njit(cache=True)
def _lebesgue(xa, patch, n, sample_ptr, sample_x, h, Ginv):
    """``sum_s |C_s[0]|`` of a patch."""
    n_terms = Ginv.shape[0]
    p = np.empty(n_terms)
    total = 0.0
    for i in range(n):
        for s in range(sample_ptr[patch[i]], sample_ptr[patch[i] + 1]):
            _basis(xa, sample_x[s], h, p)
            c0 = Ginv[0, 0]
            for r in range(1, n_terms):
                c0 += Ginv[0, r] * p[r]
            total += abs(c0)
    return total


@njit(cache=True)
def _choose(a, coords, patch, marker, stamp, connectivity, node_ptr, node_elements,
            sample_ptr, sample_x, h, max_level, max_lebesgue, min_eig, n_terms):
    """``(level, linear)`` of node ``a``'s fit by the patch rule."""
    best_level = -1
    best = np.inf
    for level in range(max_level + 1):
        n = _patch(a, level, stamp + level, patch, marker, connectivity, node_ptr, node_elements)
        G, count = _normal_matrix(coords[a], patch, n, sample_ptr, sample_x, h, n_terms)
        if count < n_terms or np.linalg.eigvalsh(G / count)[0] <= min_eig:
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
                    max_level, max_lebesgue, min_eig, n_terms, vertex):
    """Every vertex's least-squares operator.

    connectivity (n_elements, n_nodes per element), vertices first; coords (n_nodes, 3);
    node -> element CSR ``node_ptr, node_elements``; element -> sample CSR ``sample_ptr``;
    ``sample_x`` (m, 3); ``n_terms`` 4 (linear fits) or 10 (quadratic); ``vertex`` (n_nodes,)
    bool. Returns ``row_ptr (n_nodes + 1,), cols (nnz,), coef (nnz, n_terms), level
    (n_nodes,), linear (n_nodes,)``: row ``a`` holds ``C_s`` of the samples ``s`` of vertex
    ``a``'s patch (empty for other nodes, whose ``linear`` is False and ``level`` -1).
    """
    n_nodes = coords.shape[0]
    patch = np.empty(connectivity.shape[0], np.int64)
    marker = np.full(connectivity.shape[0], -1, np.int64)
    level = np.full(n_nodes, -1, np.int64)
    linear = np.zeros(n_nodes, np.bool_)
    row_ptr = np.zeros(n_nodes + 1, np.int64)
    stamp = 0
    for a in range(n_nodes):
        row_ptr[a + 1] = row_ptr[a]
        if not vertex[a]:
            continue
        level[a], linear[a] = _choose(a, coords, patch, marker, stamp, connectivity, node_ptr,
                                      node_elements, sample_ptr, sample_x, h, max_level,
                                      max_lebesgue, min_eig, n_terms)
        stamp += max_level + 1
        n = _patch(a, level[a], stamp, patch, marker, connectivity, node_ptr, node_elements)
        stamp += 1
        count = 0
        for i in range(n):
            count += sample_ptr[patch[i] + 1] - sample_ptr[patch[i]]
        row_ptr[a + 1] = row_ptr[a] + count
    cols = np.empty(row_ptr[-1], np.int64)
    coef = np.zeros((row_ptr[-1], n_terms))
    p = np.empty(n_terms)
    for a in range(n_nodes):
        if not vertex[a]:
            continue
        n = _patch(a, level[a], stamp, patch, marker, connectivity, node_ptr, node_elements)
        stamp += 1
        G, count = _normal_matrix(coords[a], patch, n, sample_ptr, sample_x, h, n_terms)
        Ginv = np.zeros((n_terms, n_terms))
        if linear[a]:
            Ginv = np.linalg.inv(G)
        elif count > 0:
            Ginv[0, 0] = 1.0 / count
        pos = row_ptr[a]
        for i in range(n):
            for s in range(sample_ptr[patch[i]], sample_ptr[patch[i] + 1]):
                _basis(coords[a], sample_x[s], h, p)
                cols[pos] = s
                for r in range(n_terms):
                    acc = Ginv[r, 0] * p[0]
                    for c in range(1, n_terms):
                        acc += Ginv[r, c] * p[c]
                    coef[pos, r] = acc
                pos += 1
    return row_ptr, cols, coef, level, linear


@njit(cache=True)
def _averaged_row(a, write, out_cols, out_vals, start, row_ptr, cols, coef, linear, vertex, coords, h,
                  connectivity, node_ptr, node_elements, nb, nb_mark, acc, seen, touched, p):
    """Row ``a`` of the averaged operator (only counted unless ``write``); returns its size."""
    n_nb = 0
    for j in range(node_ptr[a], node_ptr[a + 1]):
        for k in range(8):                  # the vertices of the elements holding a
            b = connectivity[node_elements[j], k]
            if nb_mark[b] != a and linear[b]:
                nb_mark[b] = a
                nb[n_nb] = b
                n_nb += 1
    if n_nb == 0:           # no linear fit around: a vertex keeps its own constant fit,
        if vertex[a]:       # another node the mean of its vertices' constant fits
            nb[0] = a
            n_nb = 1
        else:
            for j in range(node_ptr[a], node_ptr[a + 1]):
                for k in range(8):
                    b = connectivity[node_elements[j], k]
                    if nb_mark[b] != a:
                        nb_mark[b] = a
                        nb[n_nb] = b
                        n_nb += 1
    n_out = 0
    for i in range(n_nb):
        b = nb[i]
        _basis(coords[b], coords[a], h, p)
        for j in range(row_ptr[b], row_ptr[b + 1]):
            s = cols[j]
            if seen[s] != a:
                seen[s] = a
                touched[n_out] = s
                acc[s] = 0.0
                n_out += 1
            if write:
                value = coef[j, 0]
                for r in range(1, p.size):
                    value += p[r] * coef[j, r]
                acc[s] += value / n_nb
    if write:
        for i in range(n_out):
            out_cols[start + i] = touched[i]
            out_vals[start + i] = acc[touched[i]]
    return n_out


@njit(cache=True)
def average_rows(row_ptr, cols, coef, linear, vertex, coords, h, connectivity, node_ptr, node_elements,
                 n_samples):
    """ZZ averaging: row ``a`` is the mean, over the vertices ``b`` of the elements holding
    node ``a`` whose fit is not constant, of ``b``'s polynomial evaluated at ``x_a`` (a vertex
    without such neighbours keeps its own constant fit; another node takes the mean of its
    vertices' constant fits). Returns the CSR arrays ``(indptr, indices, data)`` of the
    (n_nodes, n_samples) operator."""
    n_nodes = coords.shape[0]
    nb = np.empty(64, np.int64)
    nb_mark = np.full(n_nodes, -1, np.int64)
    acc = np.zeros(n_samples)
    seen = np.full(n_samples, -1, np.int64)
    touched = np.empty(n_samples, np.int64)
    indptr = np.zeros(n_nodes + 1, np.int64)
    empty_c = np.empty(0, np.int64)
    empty_v = np.empty(0)
    p = np.empty(coef.shape[1])
    for a in range(n_nodes):
        size = _averaged_row(a, False, empty_c, empty_v, 0, row_ptr, cols, coef, linear, vertex, coords,
                             h, connectivity, node_ptr, node_elements, nb, nb_mark, acc, seen,
                             touched, p)
        indptr[a + 1] = indptr[a] + size
    indices = np.empty(indptr[-1], np.int64)
    data = np.empty(indptr[-1])
    nb_mark[:] = -1
    seen[:] = -1
    for a in range(n_nodes):
        _averaged_row(a, True, indices, data, indptr[a], row_ptr, cols, coef, linear, vertex, coords, h,
                      connectivity, node_ptr, node_elements, nb, nb_mark, acc, seen, touched, p)
    return indptr, indices, data
