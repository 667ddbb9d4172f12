"""Numba kernels of the H8 element on an axis-aligned cube of size ``h``.

Points are grouped by element (``offsets``) and given by local coordinates ``xi`` in
``[-1, 1]^3``; dofs are ``3 * node + component``. Matrices are accumulated straight into
the data array of a CSR matrix through ``scatter`` (n_elements, 576): the position of entry
``(3a + i, 3b + k)`` of element ``e`` is ``scatter[e, 24 * (3a + i) + 3b + k]``. Kernels
that scatter in parallel take elements of one colour (no shared nodes), so no two threads
add to the same entry.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

#: local coordinates (8, 3) of the H8 nodes, in the grid's node order
#: (:meth:`cgfem.embedding.grid.CartesianGrid.element_nodes`)
NODE_XI = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                    [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64)


@njit(cache=True)
def basis(xi, h, N, dN):
    """H8 shape functions ``N`` (8,) and physical gradients ``dN`` (8, 3) at ``xi`` (3,):
    ``N_a = (1 + s_a0 xi_0)(1 + s_a1 xi_1)(1 + s_a2 xi_2) / 8`` with ``s_a = NODE_XI[a]``,
    ``dN_a/dX = (2 / h) dN_a/dxi`` on a cube of size ``h``. The one H8 evaluation of the
    package: every other H8 quantity is built on it."""
    for a in range(8):
        s0, s1, s2 = NODE_XI[a, 0], NODE_XI[a, 1], NODE_XI[a, 2]
        f0 = 1.0 + s0 * xi[0]
        f1 = 1.0 + s1 * xi[1]
        f2 = 1.0 + s2 * xi[2]
        N[a] = 0.125 * f0 * f1 * f2
        scale = 0.25 / h  # (1/8) * (2/h)
        dN[a, 0] = scale * s0 * f1 * f2
        dN[a, 1] = scale * s1 * f0 * f2
        dN[a, 2] = scale * s2 * f0 * f1


@njit(cache=True, parallel=True)
def basis_at(xi, h):
    """Shape functions ``N`` (n, 8) and physical gradients ``dN`` (n, 8, 3) at ``xi`` (n, 3)."""
    n = xi.shape[0]
    N = np.empty((n, 8))
    dN = np.empty((n, 8, 3))
    for p in prange(n):
        basis(xi[p], h, N[p], dN[p])
    return N, dN


@njit(cache=True)
def locate(x, origin, h, shape, elements, tol, slots, xi):
    """Active element ``slots`` (n,) and local coordinates ``xi`` (n, 3) of points ``x`` (n, 3)
    in a grid (``origin`` (3,), cube size ``h``, ``shape`` (3,) elements per axis) whose
    active elements are the ascending grid ids ``elements``. A point within ``tol`` (in units
    of ``h``) of a grid plane is on that plane, whichever side round-off put it: it belongs
    first to the element above the plane (whose lower face holds it), then to the one
    below; the candidates are tried in that order per axis (axis 0 slowest) and the first
    active one is taken. Points in no active element get slot -1 and NaN local
    coordinates."""
    n_el = elements.size
    cand = np.empty((3, 2), np.int64)
    n_cand = np.empty(3, np.int64)
    t = np.empty(3)
    for p in range(x.shape[0]):
        slots[p] = -1
        xi[p, 0] = xi[p, 1] = xi[p, 2] = np.nan
        ok = True
        for d in range(3):
            t[d] = (x[p, d] - origin[d]) / h
            if not np.isfinite(t[d]):
                ok = False
                continue
            b = np.int64(np.floor(t[d] + tol))   # a point on plane b is in element b first
            cand[d, 0] = b
            cand[d, 1] = b - 1
            n_cand[d] = 2 if t[d] - b <= tol else 1
        if not ok:
            continue
        for q0 in range(n_cand[0]):
            i = cand[0, q0]
            for q1 in range(n_cand[1]):
                j = cand[1, q1]
                for q2 in range(n_cand[2]):
                    k = cand[2, q2]
                    if slots[p] >= 0 or i < 0 or j < 0 or k < 0 \
                            or i >= shape[0] or j >= shape[1] or k >= shape[2]:
                        continue
                    e = (i * shape[1] + j) * shape[2] + k
                    s = np.searchsorted(elements, e)
                    if s < n_el and elements[s] == e:
                        slots[p] = s
                        xi[p, 0] = (x[p, 0] - (origin[0] + (i + 0.5) * h)) / (0.5 * h)
                        xi[p, 1] = (x[p, 1] - (origin[1] + (j + 0.5) * h)) / (0.5 * h)
                        xi[p, 2] = (x[p, 2] - (origin[2] + (k + 0.5) * h)) / (0.5 * h)


@njit(cache=True, parallel=True)
def point_gradients(connectivity, u, xi, offsets, h):
    """Displacement gradient ``H[p, i, J] = du_i/dX_J`` (n, 3, 3) at every point."""
    n_el = offsets.size - 1
    H = np.zeros((xi.shape[0], 3, 3))
    for e in prange(n_el):
        N = np.empty(8)
        dN = np.empty((8, 3))
        for p in range(offsets[e], offsets[e + 1]):
            basis(xi[p], h, N, dN)
            for a in range(8):
                base = 3 * connectivity[e, a]
                for i in range(3):
                    ua = u[base + i]
                    for J in range(3):
                        H[p, i, J] += ua * dN[a, J]
    return H


@njit(cache=True)
def _integrate_vector(connectivity, P, values, xi, w, offsets, h, r):
    """``r[3a+i] += sum_p w_p (P[p, i, J] dN_a/dX_J + N_a values[p, i])``; either array may
    be empty (0 rows) and is then left out."""
    use_P = P.shape[0] > 0
    use_values = values.shape[0] > 0
    N = np.empty(8)
    dN = np.empty((8, 3))
    for e in range(offsets.size - 1):
        for p in range(offsets[e], offsets[e + 1]):
            basis(xi[p], h, N, dN)
            for a in range(8):
                base = 3 * connectivity[e, a]
                for i in range(3):
                    f = 0.0
                    if use_P:
                        f += P[p, i, 0] * dN[a, 0] + P[p, i, 1] * dN[a, 1] + P[p, i, 2] * dN[a, 2]
                    if use_values:
                        f += N[a] * values[p, i]
                    r[base + i] += w[p] * f


@njit(cache=True)
def integrate_force(connectivity, P, xi, w, offsets, h, r):
    """``r[3a+i] += sum_p w_p P[p, i, J] dN_a/dX_J`` (internal force)."""
    _integrate_vector(connectivity, P, np.empty((0, 3)), xi, w, offsets, h, r)


@njit(cache=True, parallel=True)
def integrate_tangent(A, first, xi, w, offsets, h, elements, scatter, data):
    """``K[3a+i, 3b+k] += sum_p w_p dN_a/dX_J A[p, i, J, k, L] dN_b/dX_L`` over the listed
    elements (``A[p - first]`` at point ``p``; ``A[0]`` everywhere if ``first < 0``), accumulated into CSR ``data``. The elements run in parallel, so the listed
    ones must share no node (one colour of :func:`cgfem.fem.assembly.colours`)."""
    for q in prange(elements.size):
        e = elements[q]
        N = np.empty(8)
        dN = np.empty((8, 3))
        ke = np.zeros((24, 24))
        T = np.empty((3, 3, 8, 3))  # T[i, J, b, k] = A[i, J, k, L] dN_b/dX_L
        for p in range(offsets[e], offsets[e + 1]):
            basis(xi[p], h, N, dN)
            ap = p - first if first >= 0 else 0
            for i in range(3):
                for J in range(3):
                    for b in range(8):
                        for k in range(3):
                            T[i, J, b, k] = w[p] * (A[ap, i, J, k, 0] * dN[b, 0]
                                                    + A[ap, i, J, k, 1] * dN[b, 1]
                                                    + A[ap, i, J, k, 2] * dN[b, 2])
            for a in range(8):
                for i in range(3):
                    row = 3 * a + i
                    for b in range(8):
                        for k in range(3):
                            ke[row, 3 * b + k] += (dN[a, 0] * T[i, 0, b, k] + dN[a, 1] * T[i, 1, b, k]
                                                   + dN[a, 2] * T[i, 2, b, k])
        for m in range(24):
            for n in range(24):
                data[scatter[e, 24 * m + n]] += ke[m, n]


@njit(cache=True, parallel=True)
def scatter_reference(ke, elements, scatter, data):
    """Add one element matrix ``ke`` (24, 24) for each listed element (of one colour)."""
    for q in prange(elements.size):
        e = elements[q]
        for m in range(24):
            for n in range(24):
                data[scatter[e, 24 * m + n]] += ke[m, n]


@njit(cache=True)
def integrate_mass(xi, w, offsets, h, components, elements, scatter, data):
    """``K[3a+i, 3b+i] += sum_p w_p N_a N_b`` for the components ``i`` with
    ``components[i]`` true (penalty of weak Dirichlet conditions)."""
    N = np.empty(8)
    dN = np.empty((8, 3))
    for q in range(elements.size):
        e = elements[q]
        me = np.zeros((8, 8))
        for p in range(offsets[e], offsets[e + 1]):
            basis(xi[p], h, N, dN)
            for a in range(8):
                for b in range(8):
                    me[a, b] += w[p] * N[a] * N[b]
        for a in range(8):
            for b in range(8):
                for i in range(3):
                    if components[i]:
                        data[scatter[e, 24 * (3 * a + i) + 3 * b + i]] += me[a, b]


@njit(cache=True)
def integrate_load(connectivity, values, xi, w, offsets, h, r):
    """``r[3a+i] += sum_p w_p N_a values[p, i]`` (tractions, body forces, multipliers)."""
    _integrate_vector(connectivity, np.empty((0, 3, 3)), values, xi, w, offsets, h, r)


@njit(cache=True, parallel=True)
def point_values(connectivity, nodal, xi, offsets, h):
    """Values (n, k) at the points of a nodal field ``nodal`` (n_nodes, k)."""
    k = nodal.shape[1]
    out = np.zeros((xi.shape[0], k))
    for e in prange(offsets.size - 1):
        N = np.empty(8)
        dN = np.empty((8, 3))
        for p in range(offsets[e], offsets[e + 1]):
            basis(xi[p], h, N, dN)
            for a in range(8):
                node = connectivity[e, a]
                for c in range(k):
                    out[p, c] += N[a] * nodal[node, c]
    return out
