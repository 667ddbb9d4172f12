"""Brute-force ray search on a NURBS+FE master, the peer of ``NurbsFeSurface.search`` in
``bench_contact.py``: every ray is measured against **every** seed of the master (the same
dense exact surface-rule points the library seeds its k-d tree with, at their current
positions), no spatial structure at all. The seeds near the ray segment start a plain ray
Newton written here on the surface's public ``evaluate``; the nearest admissible hit wins
(master normal against the slave normal, ``|g| <= max_gap``), as in the library.

Seed-to-ray distances are computed chunk by chunk with matrix products (BLAS), so the peer
is a fast brute force, not a Python double loop.
"""

from __future__ import annotations

import numpy as np

#: Newton starts per ray (the seeds nearest to the ray) and Newton iterations
STARTS = 4
ITERATIONS = 16
#: rays per chunk of the all-pairs distance matrix (chunk x seeds doubles)
CHUNK = 128


def seed_positions(surface, u: np.ndarray, piece: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Current positions (m, 3) of the seeds ``(piece, theta)`` (m,), (m, 2)."""
    return surface.evaluate(u, piece, theta, second=False).x


def nearest_seeds(seeds: np.ndarray, x1: np.ndarray, n1: np.ndarray, max_gap: float, spacing: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """For every ray ``x1 + g n1`` (n, 3), the :data:`STARTS` seeds (m, 3) closest to the ray
    among those within ``|g| <= max_gap + spacing`` and ``2 spacing`` of it: indices (n, STARTS)
    and a mask (n, STARTS) of the ones that qualify."""
    n = x1.shape[0]
    idx = np.zeros((n, STARTS), np.int64)
    good = np.zeros((n, STARTS), bool)
    s2 = np.einsum("mk,mk->m", seeds, seeds)
    for a in range(0, n, CHUNK):
        xc, nc = x1[a:a + CHUNK], n1[a:a + CHUNK]
        along = nc @ seeds.T - np.einsum("ck,ck->c", xc, nc)[:, None]          # (c, m)
        off2 = s2[None, :] - 2.0 * (xc @ seeds.T) + np.einsum("ck,ck->c", xc, xc)[:, None] - along ** 2
        off2[(np.abs(along) > max_gap + spacing) | (off2 > (2.0 * spacing) ** 2)] = np.inf
        part = np.argpartition(off2, STARTS, axis=1)[:, :STARTS]                # (c, STARTS)
        vals = np.take_along_axis(off2, part, axis=1)
        order = np.argsort(vals, axis=1)
        idx[a:a + CHUNK] = np.take_along_axis(part, order, axis=1)
        good[a:a + CHUNK] = np.isfinite(np.take_along_axis(vals, order, axis=1))
    return idx, good


def ray_newton(surface, u: np.ndarray, x1: np.ndarray, n1: np.ndarray, piece: np.ndarray,
               theta: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Newton on ``x2(theta) - x1 - g n1 = 0`` from ``theta`` (k, 2), clipped to the patch
    domains ``lo, hi`` (n_patches, 2); converged (k,), theta, g and the master normal (k, 3)."""
    theta = theta.copy()
    g = np.zeros(x1.shape[0])
    for _ in range(ITERATIONS):
        mp = surface.evaluate(u, piece, theta, second=False)
        F = mp.x - x1 - g[:, None] * n1
        J = np.stack([mp.t[:, 0], mp.t[:, 1], -n1], axis=2)
        ok = np.abs(np.linalg.det(J)) > 1e-300
        step = np.zeros_like(F)
        step[ok] = -np.linalg.solve(J[ok], F[ok][..., None])[..., 0]
        theta = np.clip(theta + step[:, :2], lo[piece], hi[piece])
        g = g + step[:, 2]
    mp = surface.evaluate(u, piece, theta, second=False)
    converged = np.linalg.norm(mp.x - x1 - g[:, None] * n1, axis=1) <= tol
    return converged, theta, g, mp.normal


def brute_force_search(surface, domains: np.ndarray, u: np.ndarray, seed_piece: np.ndarray,
                       seed_theta: np.ndarray, spacing: float, x1: np.ndarray, n1: np.ndarray,
                       max_gap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Brute-force hits of the rays ``x1 + g n1`` (n, 3): found (n,), piece (n,), theta (n, 2),
    g (n,) (``inf`` where nothing was found). ``domains`` (n_patches, 2, 2): per patch
    ``((u0, u1), (v0, v1))``."""
    n = x1.shape[0]
    seeds = seed_positions(surface, u, seed_piece, seed_theta)
    idx, good = nearest_seeds(seeds, x1, n1, max_gap, spacing)
    rows = np.repeat(np.arange(n), STARTS)[good.ravel()]
    start = idx.ravel()[good.ravel()]
    piece = seed_piece[start]
    lo, hi = domains[:, :, 0], domains[:, :, 1]
    ok, theta, g, normal = ray_newton(surface, u, x1[rows], n1[rows], piece, seed_theta[start], lo, hi,
                                      1e-12 * surface.h)
    admissible = ok & (np.abs(g) <= max_gap) & (np.einsum("pk,pk->p", normal, n1[rows]) < 0.0)
    found = np.zeros(n, bool)
    best_piece, best_theta, best_g = np.zeros(n, np.int64), np.zeros((n, 2)), np.full(n, np.inf)
    for k in np.flatnonzero(admissible):          # nearest admissible hit per ray
        r = rows[k]
        if abs(g[k]) < abs(best_g[r]):
            found[r], best_piece[r], best_theta[r], best_g[r] = True, piece[k], theta[k], g[k]
    return found, best_piece, best_theta, best_g
