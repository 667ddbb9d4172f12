"""Numba kernels that build the CSR pattern of a hexahedral space in O(n) (no global sort).

Nodes are coupled when they share an element or are listed as an extra pair; each node
pair is a dense 3x3 block of dofs. See :mod:`cgfem.fem.assembly` for the layout.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _csr_of_lists(keys, values, n):
    """CSR (ptr, data) grouping ``values`` by ``keys`` in [0, n)."""
    ptr = np.zeros(n + 1, np.int64)
    for k in keys:
        ptr[k + 1] += 1
    for i in range(n):
        ptr[i + 1] += ptr[i]
    fill = ptr[:-1].copy()
    data = np.empty(keys.size, np.int64)
    for j in range(keys.size):
        data[fill[keys[j]]] = values[j]
        fill[keys[j]] += 1
    return ptr, data


@njit(cache=True)
def node_neighbours(connectivity, n_nodes, extra_a, extra_b):
    """Sorted neighbour lists (ptr, nbr) of every node, itself included."""
    ne = connectivity.shape[0]
    el_nodes = connectivity.ravel()
    el_ids = np.repeat(np.arange(ne), connectivity.shape[1])
    el_ptr, el_of = _csr_of_lists(el_nodes, el_ids, n_nodes)
    keys = np.concatenate((extra_a, extra_b))
    vals = np.concatenate((extra_b, extra_a))
    ex_ptr, ex_of = _csr_of_lists(keys, vals, n_nodes)
    mark = np.full(n_nodes, -1, np.int64)
    count = np.zeros(n_nodes + 1, np.int64)
    buf = np.empty(n_nodes, np.int64)
    for pass_ in range(2):
        if pass_ == 1:
            for a in range(n_nodes):
                count[a + 1] += count[a]
            nbr = np.empty(count[n_nodes], np.int64)
            mark[:] = -1
        for a in range(n_nodes):
            m = 0
            for j in range(el_ptr[a], el_ptr[a + 1]):
                e = el_of[j]
                for lb in range(connectivity.shape[1]):
                    b = connectivity[e, lb]
                    if mark[b] != a:
                        mark[b] = a
                        buf[m] = b
                        m += 1
            for j in range(ex_ptr[a], ex_ptr[a + 1]):
                b = ex_of[j]
                if mark[b] != a:
                    mark[b] = a
                    buf[m] = b
                    m += 1
            if pass_ == 0:
                count[a + 1] = m
            else:
                nbr[count[a]:count[a] + m] = np.sort(buf[:m])
    return count, nbr


@njit(cache=True)
def dof_pattern(node_ptr, nbr, connectivity, scatter):
    """CSR ``(indptr, indices)`` of the dofs and the element scatter map (filled in place,
    ``scatter[e, nd (3a + i) + 3b + k]`` = data position of element entry ``(3a+i, 3b+k)``,
    ``nd = 3 connectivity.shape[1]``)."""
    n_nodes = node_ptr.size - 1
    indptr = np.zeros(3 * n_nodes + 1, np.int64)
    for a in range(n_nodes):
        deg = node_ptr[a + 1] - node_ptr[a]
        for i in range(3):
            indptr[3 * a + i + 1] = indptr[3 * a + i] + 3 * deg
    indices = np.empty(indptr[-1], np.int64)
    for a in range(n_nodes):
        deg = node_ptr[a + 1] - node_ptr[a]
        for i in range(3):
            start = indptr[3 * a + i]
            for r in range(deg):
                b = nbr[node_ptr[a] + r]
                for k in range(3):
                    indices[start + 3 * r + k] = 3 * b + k
    m = connectivity.shape[1]
    nd = 3 * m
    for e in range(connectivity.shape[0]):
        for la in range(m):
            a = connectivity[e, la]
            lo, deg = node_ptr[a], node_ptr[a + 1] - node_ptr[a]
            for lb in range(m):
                b = connectivity[e, lb]
                rank = np.searchsorted(nbr[lo:lo + deg], b)
                base = indptr[3 * a] + 3 * rank
                for i in range(3):
                    for k in range(3):
                        scatter[e, nd * (3 * la + i) + 3 * lb + k] = base + i * 3 * deg + k
    return indptr, indices


@njit(cache=True)
def add_node_blocks(nodes, blocks, which, indptr, indices, out):
    """``out`` (the data of a dof pattern) plus, for every row ``f`` of ``nodes`` (m, q) and
    every pair ``(i, j)`` of its entries, ``blocks[which[f], i, j]`` at the pattern's entries
    ``(3 nodes[f, i] + c, 3 nodes[f, j] + c)``, ``c = 0, 1, 2`` (the same scalar coupling on
    each displacement component). Every such node pair must be in the pattern, whose rows of
    one node list the same columns, each node's three in a row (:func:`dof_pattern`)."""
    q = nodes.shape[1]
    for f in range(nodes.shape[0]):
        block = blocks[which[f]]
        for i in range(q):
            row = 3 * nodes[f, i]
            first, last = indptr[row], indptr[row + 1]
            for j in range(q):
                column = 3 * nodes[f, j]
                lo, hi = first, last
                while lo < hi:                   # the column in the node's sorted row
                    mid = (lo + hi) // 2
                    if indices[mid] < column:
                        lo = mid + 1
                    else:
                        hi = mid
                offset = lo - first
                value = block[i, j]
                for c in range(3):
                    out[indptr[row + c] + offset + c] += value
