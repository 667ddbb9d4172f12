"""Numba kernels of the constitutive laws at one material point.

Conventions (all arrays float64):

- ``H`` is the displacement gradient ``du/dX``, shape ``(3, 3)``; ``F = I + H``;
- ``P`` is the stress conjugate to ``H``: the first Piola-Kirchhoff stress for the
  Neo-Hookean model, the Cauchy stress ``sigma`` for the small-strain linear model;
- ``A[i, J, k, L] = dP[i, J] / dH[k, L]`` is the tangent, shape ``(3, 3, 3, 3)``.

Models (``mu``, ``lam`` the Lamé parameters):

``LINEAR_ELASTIC``
    ``eps = sym(H)``, ``sigma = lam tr(eps) I + 2 mu eps``, ``W = sigma : eps / 2``,
    ``A[i, j, k, l] = lam d_ij d_kl + mu (d_ik d_jl + d_il d_jk)``.

``NEO_HOOKEAN`` (compressible)
    ``W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2`` with ``I1 = tr(F^T F)``, ``J = det F``;
    ``P = mu (F - F^-T) + lam ln J F^-T``; with ``G = F^-T`` (``G[i, J] = F^-1[J, i]``)
    ``A[i, J, k, L] = mu d_ik d_JL + (mu - lam ln J) G[i, L] G[k, J] + lam G[i, J] G[k, L]``
    (from ``dF^-1[J, i] / dF[k, L] = -F^-1[J, k] F^-1[L, i]`` and
    ``d ln J / dF[k, L] = F^-1[L, k]``). States with ``J <= 0`` are inadmissible:
    ``W = +inf`` and ``P``, ``A`` are filled with NaN.

``J - 1`` and ``I1 - 3`` are evaluated from the invariants of ``H`` (not from ``F``) so that
the energy and ``ln J`` keep their relative accuracy at small strain. The single-point
kernels allocate nothing; the public wrappers are in :mod:`cgfem.fem.materials`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from cgfem._parallel import parallel_kernel

LINEAR_ELASTIC = 0
NEO_HOOKEAN = 1


@njit(cache=True)
def _det_minus_one(H):
    """``det(I + H) - 1 = I1(H) + I2(H) + I3(H)`` without the cancellation of ``det F - 1``."""
    tr = H[0, 0] + H[1, 1] + H[2, 2]
    i2 = (H[0, 0] * H[1, 1] - H[0, 1] * H[1, 0]
          + H[1, 1] * H[2, 2] - H[1, 2] * H[2, 1]
          + H[0, 0] * H[2, 2] - H[0, 2] * H[2, 0])
    i3 = (H[0, 0] * (H[1, 1] * H[2, 2] - H[1, 2] * H[2, 1])
          - H[0, 1] * (H[1, 0] * H[2, 2] - H[1, 2] * H[2, 0])
          + H[0, 2] * (H[1, 0] * H[2, 1] - H[1, 1] * H[2, 0]))
    return tr + i2 + i3


@njit(cache=True)
def _inverse_transpose(H, J, G):
    """``G = F^-T = cof(F) / J`` for ``F = I + H`` (rows of ``cof F`` are cross products
    of the rows of ``F``)."""
    f00 = 1.0 + H[0, 0]
    f01 = H[0, 1]
    f02 = H[0, 2]
    f10 = H[1, 0]
    f11 = 1.0 + H[1, 1]
    f12 = H[1, 2]
    f20 = H[2, 0]
    f21 = H[2, 1]
    f22 = 1.0 + H[2, 2]
    s = 1.0 / J
    G[0, 0] = (f11 * f22 - f12 * f21) * s
    G[0, 1] = (f12 * f20 - f10 * f22) * s
    G[0, 2] = (f10 * f21 - f11 * f20) * s
    G[1, 0] = (f21 * f02 - f22 * f01) * s
    G[1, 1] = (f22 * f00 - f20 * f02) * s
    G[1, 2] = (f20 * f01 - f21 * f00) * s
    G[2, 0] = (f01 * f12 - f02 * f11) * s
    G[2, 1] = (f02 * f10 - f00 * f12) * s
    G[2, 2] = (f00 * f11 - f01 * f10) * s


@njit(cache=True)
def _fill_nan(P, A):
    for i in range(3):
        for j in range(3):
            P[i, j] = np.nan
            for k in range(3):
                for l in range(3):
                    A[i, j, k, l] = np.nan


@njit(cache=True)
def _linear_elastic(H, mu, lam, P, A):
    tr = H[0, 0] + H[1, 1] + H[2, 2]
    W = 0.0
    for i in range(3):
        for j in range(3):
            eps = 0.5 * (H[i, j] + H[j, i])
            s = 2.0 * mu * eps
            if i == j:
                s += lam * tr
            P[i, j] = s
            W += 0.5 * s * eps
            for k in range(3):
                for l in range(3):
                    a = 0.0
                    if i == j and k == l:
                        a += lam
                    if i == k and j == l:
                        a += mu
                    if i == l and j == k:
                        a += mu
                    A[i, j, k, l] = a
    return W


@njit(cache=True)
def _neo_hookean(H, mu, lam, P, A):
    dJ = _det_minus_one(H)
    if not dJ > -1.0:  # J <= 0 (or NaN input)
        _fill_nan(P, A)
        return np.inf
    J = 1.0 + dJ
    lnJ = np.log1p(dJ)
    # I1 - 3 = 2 tr H + H : H
    i1m3 = 0.0
    for i in range(3):
        i1m3 += 2.0 * H[i, i]
        for j in range(3):
            i1m3 += H[i, j] * H[i, j]
    W = 0.5 * mu * i1m3 - mu * lnJ + 0.5 * lam * lnJ * lnJ
    # P holds G = F^-T while the tangent is assembled, then is overwritten in place.
    _inverse_transpose(H, J, P)
    c = mu - lam * lnJ
    for i in range(3):
        for j in range(3):
            gij = P[i, j]
            for k in range(3):
                for l in range(3):
                    a = c * P[i, l] * P[k, j] + lam * gij * P[k, l]
                    if i == k and j == l:
                        a += mu
                    A[i, j, k, l] = a
    for i in range(3):
        for j in range(3):
            g = P[i, j]
            P[i, j] = mu * (H[i, j] - g) + lam * lnJ * g
            if i == j:
                P[i, j] += mu
    return W


@njit(cache=True)
def stress_tangent(model, H, mu, lam, P, A):
    """Stress ``P`` and tangent ``A = dP/dH`` of ``model`` at the displacement gradient ``H``
    (written in place); returns the strain energy density ``W`` (``+inf`` with NaN ``P``
    and ``A`` for an inadmissible Neo-Hookean state ``det F <= 0``)."""
    if model == LINEAR_ELASTIC:
        return _linear_elastic(H, mu, lam, P, A)
    if model == NEO_HOOKEAN:
        return _neo_hookean(H, mu, lam, P, A)
    raise ValueError("unknown material model id")


@njit(cache=True)
def cauchy_from_pk1(model, H, P, sigma_out):
    """Cauchy stress from the stress ``P`` of :func:`stress_tangent` into ``sigma_out``:
    ``sigma = P F^T / J`` for the Neo-Hookean model (NaN if ``J <= 0``), ``sigma = P`` for
    the linear model."""
    if model == LINEAR_ELASTIC:
        for i in range(3):
            for j in range(3):
                sigma_out[i, j] = P[i, j]
        return
    if model != NEO_HOOKEAN:
        raise ValueError("unknown material model id")
    dJ = _det_minus_one(H)
    if not dJ > -1.0:
        for i in range(3):
            for j in range(3):
                sigma_out[i, j] = np.nan
        return
    s = 1.0 / (1.0 + dJ)
    for i in range(3):
        for j in range(3):
            # (P F^T)[i, j] = sum_K P[i, K] F[j, K], F = I + H
            v = P[i, j]
            for K in range(3):
                v += P[i, K] * H[j, K]
            sigma_out[i, j] = v * s


@njit(cache=True)
def von_mises(sigma):
    """Von Mises equivalent stress ``sqrt(3/2 s : s)``, ``s`` the deviator of ``sigma``."""
    p = (sigma[0, 0] + sigma[1, 1] + sigma[2, 2]) / 3.0
    ss = 0.0
    for i in range(3):
        for j in range(3):
            d = sigma[i, j]
            if i == j:
                d -= p
            ss += d * d
    return np.sqrt(1.5 * ss)


@njit(cache=True)
def stress_batch(model, H, mu, lam):
    """Energy density ``W`` (n,) and stress ``P`` (n, 3, 3) at the gradients ``H`` (n, 3, 3)."""
    n = H.shape[0]
    W = np.empty(n)
    P = np.empty((n, 3, 3))
    A = np.empty((3, 3, 3, 3))
    for q in range(n):
        W[q] = stress_tangent(model, H[q], mu, lam, P[q], A)
    return W, P


@parallel_kernel
def tangent_batch(model, H, mu, lam):
    """``W`` (n,), ``P`` (n, 3, 3) and ``A = dP/dH`` (n, 3, 3, 3, 3) at the gradients ``H``."""
    n = H.shape[0]
    W = np.empty(n)
    P = np.empty((n, 3, 3))
    A = np.empty((n, 3, 3, 3, 3))
    for q in prange(n):
        W[q] = stress_tangent(model, H[q], mu, lam, P[q], A[q])
    return W, P, A


@njit(cache=True)
def cauchy_batch(model, H, mu, lam):
    """Cauchy stress (n, 3, 3) at the gradients ``H`` (n, 3, 3)."""
    n = H.shape[0]
    sigma = np.empty((n, 3, 3))
    P = np.empty((3, 3))
    A = np.empty((3, 3, 3, 3))
    for q in range(n):
        stress_tangent(model, H[q], mu, lam, P, A)
        cauchy_from_pk1(model, H[q], P, sigma[q])
    return sigma


@njit(cache=True)
def von_mises_batch(sigma):
    """Von Mises stress (n,) of the stresses ``sigma`` (n, 3, 3)."""
    n = sigma.shape[0]
    out = np.empty(n)
    for q in range(n):
        out[q] = von_mises(sigma[q])
    return out
