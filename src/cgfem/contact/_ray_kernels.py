"""Numba kernels of the NURBS+FE ray tracing (:class:`cgfem.contact.surfaces.NurbsFeSurface`).

The current master surface is ``x2(theta) = Q(theta) + N(zeta(Q)) . U2`` (eq. 16): ``Q`` a
NURBS patch, ``N`` the shape functions (8 or 27 nodes) of the grid element holding ``Q`` and ``U2`` its
nodal displacements. Per slave point ``(x1, n1)`` a Newton solve of
``F = x2(theta) - x1 - g n1 = 0`` on ``(xi, eta, g)`` runs from each start in turn; the first
admissible hit (converged, ``|g| <= max_gap``, master normal against ``n1``) is kept.

Flat data (all contiguous):

- ``layout`` (n_patches, 8) int64 rows ``(p, q, n_u, n_v, knot offset, control offset,
  closed along u, closed along v)``: patch ``k``'s ``knots_u`` are
  ``knots[o : o + n_u + p + 1]``, its ``knots_v`` follow them, and its homogeneous control
  net (n_u, n_v, 4) is ``control[c : c + 4 n_u n_v]``;
- the grid of the master space: ``origin`` (3,), ``h``, ``shape`` (3,) elements per axis,
  ``elements`` ascending grid ids of the active elements, ``connectivity`` (n_el, n_nodes) and the
  nodal displacements ``u`` (n_nodes, 3);
- starts: ``start_piece`` (n, k) patch, ``start_theta`` (n, k, 2), tried in column order up
  to the first ``start_piece < 0``.

NURBS evaluation is :func:`cgfem.geometry._nurbs_kernels.surface_derivs`, the grid element
:func:`cgfem.fem._element_kernels.locate`, the element's basis :func:`~cgfem.fem._element_kernels.basis`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from cgfem._parallel import parallel_kernel
from cgfem.fem._element_kernels import basis, element_table, locate
from cgfem.geometry._nurbs_kernels import surface_derivs

#: ``trace`` status of a point: a Newton iterate's ``Q`` lay in no active element
OUTSIDE = 1
#: the ray Newton keeps the previous pairing's master element while ``Q`` stays within
#: 1 + STICKY of it in local coordinates (the NURBS+FE master surface is only C0 across element
#: faces: without this an iterate of 1e-8 h can carry the hit across the kink and back); the
#: continuity check after a step polishes such hits onto the element holding them
#: (:func:`trace` with ``polish``) to measure what the band changed
STICKY = 2e-3
#: the wider band of a hit whose master piece is held (it kept returning to the piece it had
#: just left within one increment: :data:`cgfem.contact.pair.MAX_RETURNS`), in the same units
#: (local coordinates of the element, barycentric coordinates of the triangle)
HOLD_BAND = 0.25


@njit(cache=True)
def patch_derivs(k, uu, vv, layout, knots, control, SKL):
    """First derivatives of patch ``k`` at ``(uu, vv)`` into ``SKL`` (2, 2, 3)."""
    p, q, nu, nv, ko, co = layout[k, 0], layout[k, 1], layout[k, 2], layout[k, 3], layout[k, 4], layout[k, 5]
    U = knots[ko:ko + nu + p + 1]
    V = knots[ko + nu + p + 1:ko + nu + p + 1 + nv + q + 1]
    Pw = control[co:co + 4 * nu * nv].reshape((nu, nv, 4))
    surface_derivs(p, q, U, V, Pw, uu, vv, 1, SKL)


@njit(cache=True)
def master_point(k, uu, vv, layout, knots, control, origin, h, shape, elements, tol, connectivity, u,
                 x, t):
    """:func:`master_point_in` with no preferred element."""
    return master_point_in(k, uu, vv, layout, knots, control, origin, h, shape, elements, tol,
                           connectivity, u, x, t, -1, STICKY)


@njit(cache=True)
def sticky_xi(Q, prefer, band, origin, h, shape, elements, xi):
    """Local coordinates ``xi`` (3,) of ``Q`` (3,) in active element ``prefer``; True if they lie
    within ``1 + band`` (the element is kept), False otherwise or if ``prefer < 0``."""
    if prefer < 0:
        return False
    gid = elements[prefer]
    ijk0 = gid // (shape[1] * shape[2])
    ijk1 = (gid // shape[2]) % shape[1]
    ijk2 = gid % shape[2]
    ok = True
    for d, c in ((0, ijk0), (1, ijk1), (2, ijk2)):
        xi[d] = (Q[d] - (origin[d] + (c + 0.5) * h)) / (0.5 * h)
        if abs(xi[d]) > 1.0 + band:
            ok = False
    return ok


@njit(cache=True)
def master_point_in(k, uu, vv, layout, knots, control, origin, h, shape, elements, tol, connectivity, u,
                    x, t, prefer, band):
    """Current master point ``x`` (3,) and tangents ``t`` (2, 3) at ``(uu, vv)`` of patch ``k``
    (eq. 16): ``x = Q + N . U2``, ``t_alpha = Q_alpha + (grad N . Q_alpha) . U2``, in element
    ``prefer`` if ``Q`` lies within its cube widened by ``band`` (:func:`sticky_xi`), else in
    the element holding ``Q``. Returns the element's slot (-1: ``Q`` in no active element;
    ``x``, ``t`` then unset)."""
    SKL = np.empty((2, 2, 3))
    patch_derivs(k, uu, vv, layout, knots, control, SKL)
    Q = np.empty((1, 3))
    for c in range(3):
        Q[0, c] = SKL[0, 0, c]
    slot = np.empty(1, np.int64)
    xi = np.empty((1, 3))
    if sticky_xi(Q[0], prefer, band, origin, h, shape, elements, xi[0]):
        slot[0] = prefer
    else:
        locate(Q, origin, h, shape, elements, tol, slot, xi)
    e = slot[0]
    if e < 0:
        return e
    ijk, order = element_table(connectivity.shape[1])
    m = ijk.shape[0]
    N = np.empty(m)
    dN = np.empty((m, 3))
    basis(ijk, order, xi[0], h, N, dN)
    for c in range(3):
        x[c] = SKL[0, 0, c]
        t[0, c] = SKL[1, 0, c]
        t[1, c] = SKL[0, 1, c]
    for a in range(m):
        node = connectivity[e, a]
        psi0 = dN[a, 0] * SKL[1, 0, 0] + dN[a, 1] * SKL[1, 0, 1] + dN[a, 2] * SKL[1, 0, 2]
        psi1 = dN[a, 0] * SKL[0, 1, 0] + dN[a, 1] * SKL[0, 1, 1] + dN[a, 2] * SKL[0, 1, 2]
        for c in range(3):
            x[c] += N[a] * u[node, c]
            t[0, c] += psi0 * u[node, c]
            t[1, c] += psi1 * u[node, c]
    return e


@njit(cache=True)
def solve3(J, F, step):
    """``step = -J^{-1} F`` for ``J`` (3, 3) by Gaussian elimination with partial pivoting
    (``J`` is overwritten). Returns False, leaving ``step`` unset, if ``|det J| <= 1e-300``."""
    b = np.empty(3)
    for i in range(3):
        b[i] = -F[i]
    det = 1.0
    for c in range(3):
        piv = c
        for r in range(c + 1, 3):
            if abs(J[r, c]) > abs(J[piv, c]):
                piv = r
        if piv != c:
            det = -det
            for j in range(3):
                J[c, j], J[piv, j] = J[piv, j], J[c, j]
            b[c], b[piv] = b[piv], b[c]
        det *= J[c, c]
        if J[c, c] == 0.0:
            return False
        for r in range(c + 1, 3):
            f = J[r, c] / J[c, c]
            for j in range(c, 3):
                J[r, j] -= f * J[c, j]
            b[r] -= f * b[c]
    if not abs(det) > 1e-300:
        return False
    for i in range(2, -1, -1):
        s = b[i]
        for j in range(i + 1, 3):
            s -= J[i, j] * step[j]
        step[i] = s / J[i, i]
    return True


@njit(cache=True)
def wrap(a, lo, hi):
    """``a`` brought into ``[lo, hi)`` modulo the period ``hi - lo`` (a closed direction)."""
    if lo <= a < hi:
        return a
    return lo + (a - lo) % (hi - lo)


@parallel_kernel
def trace(x1, n1, start_piece, start_theta, start_slot, band, max_gap, ray_tol, max_iter, layout, knots,
          control, origin, h, shape, elements, tol, connectivity, u, found, piece, theta, g, slot, status,
          polish):
    """Per point ``p`` of ``x1``, ``n1`` (n, 3): :func:`ray_newton` from each start in turn;
    the first admissible hit (``|g| <= max_gap`` too) is written to ``found`` (n,) bool,
    ``piece`` (n,), ``theta`` (n, 2), ``g`` (n,), ``slot`` (n,) master element (others left as
    they are); ``start_slot`` (n, c) the preferred element of each start (-1: none), kept while
    the iterate lies within ``band`` (n,) of it (:func:`sticky_xi`). ``status`` (n,)
    gets :data:`OUTSIDE` where an iterate left the active elements, else 0. A hit converged
    in a preferred element is polished without it (:data:`STICKY`): the hit is on the
    continuous surface, in the element holding it, unless that polishing fails to converge
    (the two elements' Newton steps point across the face at each other), when the
    preferred element's hit is kept."""
    for p in prange(x1.shape[0]):
        out = np.empty(4)
        status[p] = 0
        for c in range(start_piece.shape[1]):
            k = start_piece[p, c]
            if k < 0:
                break
            r = ray_newton(x1[p], n1[p], k, start_theta[p, c, 0], start_theta[p, c, 1], 0.0, max_gap, ray_tol,
                           max_iter, layout, knots, control, origin, h, shape, elements, tol, connectivity,
                           u, start_slot[p, c], band[p], out)
            if polish and r == 1 and start_slot[p, c] >= 0:
                # converged in the kept element, perhaps on its extension past a face: the
                # same Newton in the elements holding the iterates (one evaluation if the hit
                # is inside the kept element; a few iterations if it is across the face)
                polished = np.empty(4)
                r2 = ray_newton(x1[p], n1[p], k, out[0], out[1], out[2], max_gap, ray_tol, max_iter, layout,
                                knots, control, origin, h, shape, elements, tol, connectivity, u, -1,
                                0.0, polished)
                if r2 == 1:
                    for i in range(4):
                        out[i] = polished[i]
            if r < 0:
                status[p] = -1 - r
                break
            if r == 1 and abs(out[2]) <= max_gap:
                found[p] = True
                piece[p] = k
                theta[p, 0], theta[p, 1], g[p] = out[0], out[1], out[2]
                slot[p] = np.int64(out[3])
                break


@njit(cache=True)
def ray_newton(x1, n1, k, u0, v0, g0, max_gap, ray_tol, max_iter, layout, knots, control, origin, h, shape,
               elements, tol, connectivity, u, prefer, band, out):
    """Newton on ``x2(theta) - x1 - g n1 = 0`` from ``(u0, v0)`` on patch ``k``, ``g = g0``;
    a step leaving the patch's domain wraps around along a closed direction (``layout[k, 6:8]``)
    and is clipped onto the domain along an open one, and a clipped step that does not
    move is a stuck one. Stops converged (``|F| <= ray_tol h``), on a singular ``J``, a
    stuck step, ``|g| > 4 max_gap`` or after ``max_iter`` iterations. ``out`` (4,) receives
    ``(xi, eta, g, slot)`` (the master element of the hit: ``prefer``, the element of the
    previous pairing, while ``Q`` lies within ``band`` of it, else the element holding
    ``Q``). Returns 1 converged with ``m2 . n1 < 0`` (``m2 = t_xi x t_eta``, the
    master normal against the ray), 0 not, ``-1 - OUTSIDE`` if an iterate left the active
    elements."""
    kl = layout[k]
    U = knots[kl[4]:kl[4] + kl[2] + kl[0] + 1]
    V = knots[kl[4] + kl[2] + kl[0] + 1:kl[4] + kl[2] + kl[0] + 1 + kl[3] + kl[1] + 1]
    lo0, hi0, lo1, hi1 = U[0], U[U.size - 1], V[0], V[V.size - 1]
    x = np.empty(3)
    t = np.empty((2, 3))
    F = np.empty(3)
    J = np.empty((3, 3))
    step = np.empty(3)
    th0, th1, g = u0, v0, g0
    for _ in range(max_iter):
        # evaluated at theta clipped to the domain, as evaluate() does (iterates are inside
        # it; a start is taken as given)
        e = master_point_in(k, min(max(th0, lo0), hi0), min(max(th1, lo1), hi1), layout, knots, control,
                            origin, h, shape, elements, tol, connectivity, u, x, t, prefer, band)
        if e < 0:
            return -1 - OUTSIDE
        for c in range(3):
            F[c] = x[c] - x1[c] - g * n1[c]
            J[c, 0] = t[0, c]
            J[c, 1] = t[1, c]
            J[c, 2] = -n1[c]
        if np.sqrt(F[0] * F[0] + F[1] * F[1] + F[2] * F[2]) <= ray_tol * h:
            out[0], out[1], out[2], out[3] = th0, th1, g, e
            m0 = t[0, 1] * t[1, 2] - t[0, 2] * t[1, 1]
            m1 = t[0, 2] * t[1, 0] - t[0, 0] * t[1, 2]
            m2 = t[0, 0] * t[1, 1] - t[0, 1] * t[1, 0]
            return 1 if m0 * n1[0] + m1 * n1[1] + m2 * n1[2] < 0.0 else 0
        if not solve3(J, F, step) or not abs(g) <= 4.0 * max_gap:
            return 0
        a0 = th0 + step[0]
        a1 = th1 + step[1]
        g += step[2]
        c0 = wrap(a0, lo0, hi0) if kl[6] else min(max(a0, lo0), hi0)
        c1 = wrap(a1, lo1, hi1) if kl[7] else min(max(a1, lo1), hi1)
        if c0 == a0 - step[0] and c1 == a1 - step[1] and (c0 != a0 or c1 != a1):
            return 0
        th0, th1 = c0, c1
    return 0
