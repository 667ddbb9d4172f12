"""Numba kernels of NURBS evaluation, named after the algorithms of *The NURBS Book*
(Piegl & Tiller, 2nd ed.) and using its variable names.

Conventions (all arrays flat and contiguous, float64 unless said otherwise):

- ``U`` knot vector of length ``n + p + 2`` for ``n + 1`` control points of degree ``p``;
- ``Pw`` homogeneous control net, shape ``(n_u, n_v, 4)``, rows ``(w x, w y, w z, w)``;
- derivative orders are clamped to the degree: derivatives above ``p`` are zero.

The public wrappers are in :mod:`cgfem.geometry.nurbs`; these kernels do no validation.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def find_span(n, p, u, U):
    """A2.1 FindSpan: knot span index ``i`` with ``U[i] <= u < U[i+1]`` (``u = U[n+1]``
    maps to the last non-empty span)."""
    if u >= U[n + 1]:
        return n
    if u <= U[p]:
        return p
    low = p
    high = n + 1
    mid = (low + high) // 2
    while u < U[mid] or u >= U[mid + 1]:
        if u < U[mid]:
            high = mid
        else:
            low = mid
        mid = (low + high) // 2
    return mid


@njit(cache=True)
def basis_funs(i, u, p, U, N):
    """A2.2 BasisFuns: the ``p + 1`` non-vanishing basis functions at ``u`` into ``N``."""
    left = np.empty(p + 1)
    right = np.empty(p + 1)
    N[0] = 1.0
    for j in range(1, p + 1):
        left[j] = u - U[i + 1 - j]
        right[j] = U[i + j] - u
        saved = 0.0
        for r in range(j):
            temp = N[r] / (right[r + 1] + left[j - r])
            N[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        N[j] = saved


@njit(cache=True)
def ders_basis_funs(i, u, p, n, U, ders):
    """A2.3 DersBasisFuns: ``ders[k, j]`` is the k-th derivative of ``N_{i-p+j,p}`` at ``u``,
    for ``k <= n``; rows ``k > p`` are set to zero. ``ders`` has shape ``(n + 1, p + 1)``."""
    ndu = np.empty((p + 1, p + 1))
    left = np.empty(p + 1)
    right = np.empty(p + 1)
    a = np.empty((2, p + 1))
    ndu[0, 0] = 1.0
    for j in range(1, p + 1):
        left[j] = u - U[i + 1 - j]
        right[j] = U[i + j] - u
        saved = 0.0
        for r in range(j):
            ndu[j, r] = right[r + 1] + left[j - r]
            temp = ndu[r, j - 1] / ndu[j, r]
            ndu[r, j] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        ndu[j, j] = saved
    for k in range(n + 1):
        for j in range(p + 1):
            ders[k, j] = 0.0
    for j in range(p + 1):
        ders[0, j] = ndu[j, p]
    nk = min(n, p)
    for r in range(p + 1):
        s1 = 0
        s2 = 1
        a[0, 0] = 1.0
        for k in range(1, nk + 1):
            d = 0.0
            rk = r - k
            pk = p - k
            if r >= k:
                a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                d = a[s2, 0] * ndu[rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                d += a[s2, j] * ndu[rk + j, pk]
            if r <= pk:
                a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                d += a[s2, k] * ndu[r, pk]
            ders[k, r] = d
            s1, s2 = s2, s1
    r = p
    for k in range(1, nk + 1):
        for j in range(p + 1):
            ders[k, j] *= r
        r *= p - k


#: Pascal's triangle ``C(n, k)``, ``n, k < 16`` (a constant table: no division in hot loops).
_PASCAL = np.array([[math.comb(n, k) for k in range(16)] for n in range(16)], dtype=np.float64)


@njit(cache=True)
def binomial(n, k):
    """Binomial coefficient ``C(n, k)`` as a float (``0 <= k <= n``)."""
    if n < _PASCAL.shape[0]:
        return _PASCAL[n, k]
    c = 1.0
    for j in range(1, k + 1):
        c = c * (n - k + j) / j
    return c


@njit(cache=True)
def contract_net(Pw, i0, j0, Nu, Nv, p, q, d, temp, SKLw):
    """Homogeneous derivatives ``SKLw[k, l]`` (4-vectors, ``k + l <= d``) of the tensor
    product of the basis derivatives ``Nu`` (>= d + 1, >= p + 1) and ``Nv`` (>= d + 1, >= q + 1)
    with the window ``Pw[i0 : i0 + p + 1, j0 : j0 + q + 1]`` of a homogeneous net (inner loop
    of A3.6). Scratch ``temp`` (>= q + 1, 4); other entries of ``SKLw`` are left as they are.
    Shared by NURBS surfaces (B-spline basis) and Bezier leaves (Bernstein basis)."""
    for k in range(d + 1):
        for s in range(q + 1):
            a0 = a1 = a2 = a3 = 0.0
            for r in range(p + 1):
                b = Nu[k, r]
                a0 += b * Pw[i0 + r, j0 + s, 0]
                a1 += b * Pw[i0 + r, j0 + s, 1]
                a2 += b * Pw[i0 + r, j0 + s, 2]
                a3 += b * Pw[i0 + r, j0 + s, 3]
            temp[s, 0] = a0
            temp[s, 1] = a1
            temp[s, 2] = a2
            temp[s, 3] = a3
        for l in range(d - k + 1):
            a0 = a1 = a2 = a3 = 0.0
            for s in range(q + 1):
                b = Nv[l, s]
                a0 += b * temp[s, 0]
                a1 += b * temp[s, 1]
                a2 += b * temp[s, 2]
                a3 += b * temp[s, 3]
            SKLw[k, l, 0] = a0
            SKLw[k, l, 1] = a1
            SKLw[k, l, 2] = a2
            SKLw[k, l, 3] = a3


@njit(cache=True)
def surface_derivs_homogeneous(p, q, U, V, Pw, u, v, d, SKLw):
    """A3.6 SurfaceDerivsAlg1 on the homogeneous net: ``SKLw[k, l]`` (4-vector) is
    ``d^{k+l} Sw / du^k dv^l`` for ``k + l <= d``; other entries are zero."""
    n = Pw.shape[0] - 1
    m = Pw.shape[1] - 1
    uspan = find_span(n, p, u, U)
    vspan = find_span(m, q, v, V)
    Nu = np.empty((d + 1, p + 1))
    Nv = np.empty((d + 1, q + 1))
    ders_basis_funs(uspan, u, p, d, U, Nu)
    ders_basis_funs(vspan, v, q, d, V, Nv)
    for k in range(d + 1):
        for l in range(d + 1):
            for c in range(4):
                SKLw[k, l, c] = 0.0
    contract_net(Pw, uspan - p, vspan - q, Nu, Nv, p, q, d, np.empty((q + 1, 4)), SKLw)


@njit(cache=True)
def rat_surface_derivs(SKLw, d, SKL):
    """A4.4 RatSurfaceDerivs: Cartesian derivatives ``SKL[k, l]`` (3-vectors, ``k + l <= d``)
    from the homogeneous ones ``SKLw``. The one quotient rule of the package (NURBS surfaces
    and Bezier leaves); allocation-free, for hot loops."""
    inv_w = 1.0 / SKLw[0, 0, 3]
    if d <= 2:  # the same recursion written out (no loops: the hot case of the queries)
        for c in range(3):
            SKL[0, 0, c] = SKLw[0, 0, c] * inv_w
        if d == 0:
            return
        ws = SKLw[1, 0, 3]
        wt = SKLw[0, 1, 3]
        for c in range(3):
            SKL[1, 0, c] = (SKLw[1, 0, c] - ws * SKL[0, 0, c]) * inv_w
            SKL[0, 1, c] = (SKLw[0, 1, c] - wt * SKL[0, 0, c]) * inv_w
        if d == 1:
            return
        for c in range(3):
            SKL[2, 0, c] = (SKLw[2, 0, c] - 2.0 * ws * SKL[1, 0, c] - SKLw[2, 0, 3] * SKL[0, 0, c]) * inv_w
            SKL[1, 1, c] = (SKLw[1, 1, c] - ws * SKL[0, 1, c] - wt * SKL[1, 0, c]
                            - SKLw[1, 1, 3] * SKL[0, 0, c]) * inv_w
            SKL[0, 2, c] = (SKLw[0, 2, c] - 2.0 * wt * SKL[0, 1, c] - SKLw[0, 2, 3] * SKL[0, 0, c]) * inv_w
        return
    for k in range(d + 1):
        for l in range(d - k + 1):
            v0 = SKLw[k, l, 0]
            v1 = SKLw[k, l, 1]
            v2 = SKLw[k, l, 2]
            for j in range(1, l + 1):
                b = binomial(l, j) * SKLw[0, j, 3]
                v0 -= b * SKL[k, l - j, 0]
                v1 -= b * SKL[k, l - j, 1]
                v2 -= b * SKL[k, l - j, 2]
            for i in range(1, k + 1):
                b = binomial(k, i)
                bw = b * SKLw[i, 0, 3]
                v0 -= bw * SKL[k - i, l, 0]
                v1 -= bw * SKL[k - i, l, 1]
                v2 -= bw * SKL[k - i, l, 2]
                for j in range(1, l + 1):
                    bw = b * binomial(l, j) * SKLw[i, j, 3]
                    v0 -= bw * SKL[k - i, l - j, 0]
                    v1 -= bw * SKL[k - i, l - j, 1]
                    v2 -= bw * SKL[k - i, l - j, 2]
            SKL[k, l, 0] = v0 * inv_w
            SKL[k, l, 1] = v1 * inv_w
            SKL[k, l, 2] = v2 * inv_w


@njit(cache=True)
def surface_derivs(p, q, U, V, Pw, u, v, d, SKL):
    """Rational surface and its derivatives up to total order ``d`` at one ``(u, v)`` into
    ``SKL`` of shape ``(d + 1, d + 1, 3)`` (entries with ``k + l > d`` are zero)."""
    SKLw = np.empty((d + 1, d + 1, 4))
    surface_derivs_homogeneous(p, q, U, V, Pw, u, v, d, SKLw)
    for k in range(d + 1):
        for l in range(d + 1):
            for c in range(3):
                SKL[k, l, c] = 0.0
    rat_surface_derivs(SKLw, d, SKL)


@njit(cache=True)
def surface_point(p, q, U, V, Pw, u, v, out):
    """A4.3 SurfacePoint of the rational surface at one ``(u, v)`` into ``out`` (3,)."""
    n = Pw.shape[0] - 1
    m = Pw.shape[1] - 1
    uspan = find_span(n, p, u, U)
    vspan = find_span(m, q, v, V)
    Nu = np.empty(p + 1)
    Nv = np.empty(q + 1)
    basis_funs(uspan, u, p, U, Nu)
    basis_funs(vspan, v, q, V, Nv)
    Sw = np.zeros(4)
    for s in range(q + 1):
        for r in range(p + 1):
            b = Nu[r] * Nv[s]
            for c in range(4):
                Sw[c] += b * Pw[uspan - p + r, vspan - q + s, c]
    for c in range(3):
        out[c] = Sw[c] / Sw[3]


@njit(cache=True)
def surface_points_batch(p, q, U, V, Pw, uv, out):
    """Points at each row of ``uv`` (n, 2) into ``out`` (n, 3)."""
    for i in range(uv.shape[0]):
        surface_point(p, q, U, V, Pw, uv[i, 0], uv[i, 1], out[i])


@njit(cache=True)
def surface_derivs_batch(p, q, U, V, Pw, uv, d, out):
    """Derivatives up to order ``d`` at each row of ``uv`` (n, 2) into ``out``
    (n, d + 1, d + 1, 3)."""
    for i in range(uv.shape[0]):
        surface_derivs(p, q, U, V, Pw, uv[i, 0], uv[i, 1], d, out[i])


@njit(cache=True)
def unit_normal(p, q, U, V, Pw, u, v, lo_u, hi_u, lo_v, hi_v, out):
    """Unit normal ``S_u x S_v / |S_u x S_v|`` at ``(u, v)`` into ``out`` (3,).

    At a degenerate point (a collapsed edge such as a sphere pole, where the cross product
    vanishes) the normal is the limit taken from inside the domain ``[lo_u, hi_u] x [lo_v,
    hi_v]``: evaluated a relative 1e-7 of the way toward the domain centre.
    """
    SKL = np.empty((2, 2, 3))
    uu = u
    vv = v
    for attempt in range(3):
        surface_derivs(p, q, U, V, Pw, uu, vv, 1, SKL)
        su = SKL[1, 0]
        sv = SKL[0, 1]
        nx = su[1] * sv[2] - su[2] * sv[1]
        ny = su[2] * sv[0] - su[0] * sv[2]
        nz = su[0] * sv[1] - su[1] * sv[0]
        norm = np.sqrt(nx * nx + ny * ny + nz * nz)
        # compare with the larger tangent squared: at a collapsed edge one tangent is
        # round-off, and so is the cross product
        scale = max(su[0] ** 2 + su[1] ** 2 + su[2] ** 2, sv[0] ** 2 + sv[1] ** 2 + sv[2] ** 2)
        if norm > 1e-10 * scale and norm > 0.0:
            out[0] = nx / norm
            out[1] = ny / norm
            out[2] = nz / norm
            return
        step = 1e-7 * 10.0 ** (2 * attempt)
        uu = uu + step * (0.5 * (lo_u + hi_u) - uu)
        vv = vv + step * (0.5 * (lo_v + hi_v) - vv)
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0


@njit(cache=True)
def unit_normals_batch(p, q, U, V, Pw, uv, out):
    """Unit normals at each row of ``uv`` (n, 2) into ``out`` (n, 3)."""
    lo_u = U[p]
    hi_u = U[U.shape[0] - p - 1]
    lo_v = V[q]
    hi_v = V[V.shape[0] - q - 1]
    for i in range(uv.shape[0]):
        unit_normal(p, q, U, V, Pw, uv[i, 0], uv[i, 1], lo_u, hi_u, lo_v, hi_v, out[i])
