"""Numba kernels of the Lagrange hexahedra (:mod:`cgfem.fem.element`) on an axis-aligned cube
of size ``h``.

An element is given to every kernel by its node table ``ijk`` (n_nodes, 3) of tensor
indices and its ``order`` (1 or 2); ``n_nodes = ijk.shape[0]``. Points are grouped by element
(``offsets``) and given by local coordinates ``xi`` in ``[-1, 1]^3``; dofs are
``3 * node + component``. Matrices are accumulated straight into the data array of a CSR
matrix through ``scatter`` (n_elements, (3 n_nodes)^2): the position of entry
``(3a + i, 3b + k)`` of element ``e`` is ``scatter[e, 3 n_nodes (3a + i) + 3b + k]``. Kernels
that scatter in parallel take elements of one colour (no shared nodes), so no two threads
add to the same entry.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from cgfem._parallel import parallel_kernel

#: local coordinates (8, 3) of the trilinear element's nodes, in the grid's node order
#: (:meth:`cgfem.embedding.grid.CartesianGrid.element_nodes`)
NODE_XI = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                    [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64)
#: tensor indices of the nodes of the trilinear element (its corners, grid order) and of
#: the triquadratic one (VTK's triquadratic hexahedron: corners, the 12 edge midpoints of the
#: bottom, top and vertical edges, the face centres x-, x+, y-, y+, z-, z+, the centre)
HEX8_IJK = ((NODE_XI + 1.0) / 2.0).astype(np.int64)
HEX27_IJK = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [0, 0, 2], [2, 0, 2], [2, 2, 2], [0, 2, 2],
                      [1, 0, 0], [2, 1, 0], [1, 2, 0], [0, 1, 0], [1, 0, 2], [2, 1, 2], [1, 2, 2], [0, 1, 2],
                      [0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1],
                      [0, 1, 1], [2, 1, 1], [1, 0, 1], [1, 2, 1], [1, 1, 0], [1, 1, 2], [1, 1, 1]], np.int64)


@njit(cache=True)
def element_table(n_nodes):
    """``(ijk, order)`` of the element with ``n_nodes`` nodes per element (8 or 27): for
    kernels that get the element from a connectivity's width."""
    if n_nodes == 8:
        return HEX8_IJK, 1
    return HEX27_IJK, 2


@njit(cache=True)
def lagrange(order, x, k):
    """The 1D Lagrange polynomial ``l_k`` of ``order`` (1 or 2) on the equally spaced points
    of ``[-1, 1]``, and its first and second derivatives, at ``x``:
    order 1 ``l_0 = (1 - x) / 2``, ``l_1 = (1 + x) / 2``; order 2 ``l_0 = x (x - 1) / 2``,
    ``l_1 = 1 - x^2``, ``l_2 = x (x + 1) / 2``."""
    if order == 1:
        if k == 0:
            return 0.5 * (1.0 - x), -0.5, 0.0
        return 0.5 * (1.0 + x), 0.5, 0.0
    if k == 0:
        return 0.5 * x * (x - 1.0), x - 0.5, 1.0
    if k == 1:
        return 1.0 - x * x, -2.0 * x, -2.0
    return 0.5 * x * (x + 1.0), x + 0.5, 1.0


@njit(cache=True)
def basis(ijk, order, xi, h, N, dN):
    """Shape functions ``N`` (n_nodes,) and physical gradients ``dN`` (n_nodes, 3) at ``xi``
    (3,): ``N_a = l_i(xi_0) l_j(xi_1) l_k(xi_2)`` with ``(i, j, k) = ijk[a]``,
    ``dN_a/dX = (2 / h) dN_a/dxi`` on a cube of size ``h``. The one element evaluation of the
    package: every other element quantity is built on it (or on :func:`basis_second`)."""
    s = 2.0 / h
    for a in range(ijk.shape[0]):
        l0, d0, _ = lagrange(order, xi[0], ijk[a, 0])
        l1, d1, _ = lagrange(order, xi[1], ijk[a, 1])
        l2, d2, _ = lagrange(order, xi[2], ijk[a, 2])
        N[a] = l0 * l1 * l2
        dN[a, 0] = s * d0 * l1 * l2
        dN[a, 1] = s * l0 * d1 * l2
        dN[a, 2] = s * l0 * l1 * d2


@njit(cache=True)
def basis_second(ijk, order, xi, h, N, dN, d2N):
    """:func:`basis` and the physical second derivatives ``d2N`` (n_nodes, 3, 3), from one
    evaluation of the 1D polynomials (the contact search calls it per master point: calling
    :func:`basis` first would evaluate them twice)."""
    s = 2.0 / h
    for a in range(ijk.shape[0]):
        l0, d0, e0 = lagrange(order, xi[0], ijk[a, 0])
        l1, d1, e1 = lagrange(order, xi[1], ijk[a, 1])
        l2, d2, e2 = lagrange(order, xi[2], ijk[a, 2])
        N[a] = l0 * l1 * l2
        dN[a, 0] = s * d0 * l1 * l2
        dN[a, 1] = s * l0 * d1 * l2
        dN[a, 2] = s * l0 * l1 * d2
        ss = s * s
        d2N[a, 0, 0] = ss * e0 * l1 * l2
        d2N[a, 1, 1] = ss * l0 * e1 * l2
        d2N[a, 2, 2] = ss * l0 * l1 * e2
        d2N[a, 0, 1] = d2N[a, 1, 0] = ss * d0 * d1 * l2
        d2N[a, 0, 2] = d2N[a, 2, 0] = ss * d0 * l1 * d2
        d2N[a, 1, 2] = d2N[a, 2, 1] = ss * l0 * d1 * d2


@parallel_kernel
def basis_at(ijk, order, xi, h, second):
    """Shape functions ``N`` (n, n_nodes), physical gradients ``dN`` (n, n_nodes, 3) and, if
    ``second``, second derivatives ``d2N`` (n, n_nodes, 3, 3) (else (0, n_nodes, 3, 3)) at
    ``xi`` (n, 3)."""
    n, m = xi.shape[0], ijk.shape[0]
    N = np.empty((n, m))
    dN = np.empty((n, m, 3))
    d2N = np.empty((n if second else 0, m, 3, 3))
    for p in prange(n):
        if second:
            basis_second(ijk, order, xi[p], h, N[p], dN[p], d2N[p])
        else:
            basis(ijk, order, xi[p], h, N[p], dN[p])
    return N, dN, d2N


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


@parallel_kernel
def point_gradients(ijk, order, connectivity, u, xi, offsets, h):
    """Displacement gradient ``H[p, i, J] = du_i/dX_J`` (n, 3, 3) at every point."""
    n_el, m = offsets.size - 1, ijk.shape[0]
    H = np.zeros((xi.shape[0], 3, 3))
    for e in prange(n_el):
        N = np.empty(m)
        dN = np.empty((m, 3))
        for p in range(offsets[e], offsets[e + 1]):
            basis(ijk, order, xi[p], h, N, dN)
            for a in range(m):
                base = 3 * connectivity[e, a]
                for i in range(3):
                    ua = u[base + i]
                    for J in range(3):
                        H[p, i, J] += ua * dN[a, J]
    return H


@njit(cache=True)
def _integrate_vector(ijk, order, connectivity, P, values, xi, w, offsets, h, r):
    """``r[3a+i] += sum_p w_p (P[p, i, J] dN_a/dX_J + N_a values[p, i])``; either array may
    be empty (0 rows) and is then left out."""
    use_P = P.shape[0] > 0
    use_values = values.shape[0] > 0
    m = ijk.shape[0]
    N = np.empty(m)
    dN = np.empty((m, 3))
    for e in range(offsets.size - 1):
        for p in range(offsets[e], offsets[e + 1]):
            basis(ijk, order, xi[p], h, N, dN)
            for a in range(m):
                base = 3 * connectivity[e, a]
                for i in range(3):
                    f = 0.0
                    if use_P:
                        f += P[p, i, 0] * dN[a, 0] + P[p, i, 1] * dN[a, 1] + P[p, i, 2] * dN[a, 2]
                    if use_values:
                        f += N[a] * values[p, i]
                    r[base + i] += w[p] * f


@njit(cache=True)
def integrate_force(ijk, order, connectivity, P, xi, w, offsets, h, r):
    """``r[3a+i] += sum_p w_p P[p, i, J] dN_a/dX_J`` (internal force)."""
    _integrate_vector(ijk, order, connectivity, P, np.empty((0, 3)), xi, w, offsets, h, r)


@parallel_kernel
def integrate_tangent(ijk, order, A, first, xi, w, offsets, h, elements, scatter, data):
    """``K[3a+i, 3b+k] += sum_p w_p dN_a/dX_J A[p, i, J, k, L] dN_b/dX_L`` over the listed
    elements (``A[p - first]`` at point ``p``; ``A[0]`` everywhere if ``first < 0``),
    accumulated into CSR ``data``. ``A`` must have the major symmetry
    ``A[i, J, k, L] = A[k, L, i, J]`` of a hyperelastic tangent: the upper triangle of each
    element matrix is integrated and mirrored (the element matrices are symmetric bit for
    bit). The elements run in parallel, so the listed ones must share no node (one colour of
    :func:`cgfem.fem.assembly.colours`)."""
    m = ijk.shape[0]
    nd = 3 * m
    for q in prange(elements.size):
        e = elements[q]
        N = np.empty(m)
        dN = np.empty((m, 3))
        ke = np.zeros((nd, nd))
        T = np.empty((3, 3, nd))  # T[i, J, 3b + k] = w_p A[i, J, k, L] dN_b/dX_L
        for p in range(offsets[e], offsets[e + 1]):
            basis(ijk, order, xi[p], h, N, dN)
            ap = p - first if first >= 0 else 0
            for i in range(3):
                for J in range(3):
                    for b in range(m):
                        for k in range(3):
                            T[i, J, 3 * b + k] = w[p] * (A[ap, i, J, k, 0] * dN[b, 0]
                                                         + A[ap, i, J, k, 1] * dN[b, 1]
                                                         + A[ap, i, J, k, 2] * dN[b, 2])
            # row 3a + i of the upper triangle: one contiguous run of columns (vectorized)
            for a in range(m):
                d0, d1, d2 = dN[a, 0], dN[a, 1], dN[a, 2]
                for i in range(3):
                    row = 3 * a + i
                    for c in range(row, nd):
                        ke[row, c] += d0 * T[i, 0, c] + d1 * T[i, 1, c] + d2 * T[i, 2, c]
        for r in range(nd):
            for c in range(r + 1, nd):
                ke[c, r] = ke[r, c]
        for r in range(nd):
            for c in range(nd):
                data[scatter[e, nd * r + c]] += ke[r, c]


@parallel_kernel
def scatter_reference(ke, elements, scatter, data):
    """Add one element matrix ``ke`` (nd, nd) for each listed element (of one colour)."""
    nd = ke.shape[0]
    for q in prange(elements.size):
        e = elements[q]
        for r in range(nd):
            for c in range(nd):
                data[scatter[e, nd * r + c]] += ke[r, c]


@njit(cache=True)
def integrate_mass(ijk, order, xi, w, offsets, h, components, elements, scatter, data):
    """``K[3a+i, 3b+i] += sum_p w_p N_a N_b`` for the components ``i`` with
    ``components[i]`` true (penalty of weak Dirichlet conditions)."""
    m = ijk.shape[0]
    nd = 3 * m
    N = np.empty(m)
    dN = np.empty((m, 3))
    for q in range(elements.size):
        e = elements[q]
        me = np.zeros((m, m))
        for p in range(offsets[e], offsets[e + 1]):
            basis(ijk, order, xi[p], h, N, dN)
            for a in range(m):
                for b in range(m):
                    me[a, b] += w[p] * N[a] * N[b]
        for a in range(m):
            for b in range(m):
                for i in range(3):
                    if components[i]:
                        data[scatter[e, nd * (3 * a + i) + 3 * b + i]] += me[a, b]


@njit(cache=True)
def integrate_load(ijk, order, connectivity, values, xi, w, offsets, h, r):
    """``r[3a+i] += sum_p w_p N_a values[p, i]`` (tractions, body forces, multipliers)."""
    _integrate_vector(ijk, order, connectivity, np.empty((0, 3, 3)), values, xi, w, offsets, h, r)


@parallel_kernel
def point_values(ijk, order, connectivity, nodal, xi, offsets, h):
    """Values (n, k) at the points of a nodal field ``nodal`` (n_nodes, k)."""
    k = nodal.shape[1]
    m = ijk.shape[0]
    out = np.zeros((xi.shape[0], k))
    for e in prange(offsets.size - 1):
        N = np.empty(m)
        dN = np.empty((m, 3))
        for p in range(offsets[e], offsets[e + 1]):
            basis(ijk, order, xi[p], h, N, dN)
            for a in range(m):
                node = connectivity[e, a]
                for c in range(k):
                    out[p, c] += N[a] * nodal[node, c]
    return out
