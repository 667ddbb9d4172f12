"""Numba kernels of the ray search's seeds (:class:`cgfem.contact.surfaces.RaySurface`).

A seed is a fixed point ``(piece, theta)`` of a master surface; it moves with the unknowns
``u`` (n_nodes, 3) as ``x = X + sum_a coef[a] u[nodes[a]]``, ``X`` (n_seeds, 3) its reference
position, ``coef`` and ``nodes`` (n_seeds, w) the basis it moves with (an element's shape
functions, or a fitted surface's controls). A ray's starts are the seeds nearest to samples
of its segment (:meth:`~cgfem.contact.surfaces.RaySurface._starts`): the samples' nearest
seeds come from a k-d tree, and :func:`nearest_starts` orders and filters them.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def moved_seeds(X, coef, nodes, rows, u, out):
    """Current positions ``out`` (k, 3) of seeds ``rows`` (k,): ``X[r] + sum_a coef[r, a]
    u[nodes[r, a]]``, summed over ``a`` in order (the arithmetic of a CSR product with
    these rows)."""
    for i in range(rows.size):
        r = rows[i]
        a0 = a1 = a2 = 0.0
        for a in range(coef.shape[1]):
            c, j = coef[r, a], nodes[r, a]
            a0 += c * u[j, 0]
            a1 += c * u[j, 1]
            a2 += c * u[j, 2]
        out[i, 0] = X[r, 0] + a0
        out[i, 1] = X[r, 1] + a1
        out[i, 2] = X[r, 2] + a2


@njit(cache=True)
def nearest_starts(seeds_x, found, near, x1, n1, reach, seed_piece, seed_theta, piece, theta):
    """Starts of rays ``x1``, ``n1`` (n, 3) from the nearest seeds ``found`` (n, m) of their
    segment's samples (rows of ``seeds_x`` (n_x, 3), ``n_x``: no seed near the sample),
    ``near`` (n_x,) the seeds' indices in ``seed_piece`` (n_seeds,) and ``seed_theta``
    (n_seeds, 2). Per ray, the ``k = piece.shape[1]`` (``<= m``) samples whose seed lies
    nearest to the ray (distance to the line, ties in sample order; a sample with none at
    infinity), then those within ``reach`` of the ray and not already taken, in that order,
    then the others: ``piece`` (n, k) the seed's patch (-1: not a start) and ``theta``
    (n, k, 2) its parameters. (The numbers of a stable argsort of the distances and a
    stable partition of its first ``k``.)"""
    n, m = found.shape
    k = piece.shape[1]
    n_x = seeds_x.shape[0]
    best = np.empty(k)
    take = np.empty(k, np.int64)
    use = np.empty(k, np.bool_)
    for p in range(n):
        count = 0
        for j in range(m):
            s = found[p, j]
            if s >= n_x:
                d = np.inf
                s = 0
            else:
                v0 = seeds_x[s, 0] - x1[p, 0]
                v1 = seeds_x[s, 1] - x1[p, 1]
                v2 = seeds_x[s, 2] - x1[p, 2]
                along = v0 * n1[p, 0] + v1 * n1[p, 1] + v2 * n1[p, 2]
                w0 = v0 - along * n1[p, 0]
                w1 = v1 - along * n1[p, 1]
                w2 = v2 - along * n1[p, 2]
                d = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            if count < k:
                pos = count
                count += 1
            elif d >= best[k - 1]:
                continue                                  # a later tie sorts after
            else:
                pos = k - 1
            while pos > 0 and best[pos - 1] > d:
                best[pos] = best[pos - 1]
                take[pos] = take[pos - 1]
                pos -= 1
            best[pos] = d
            take[pos] = near[s]
        for c in range(k):
            use[c] = best[c] <= reach
            for b in range(c):
                if take[b] == take[c]:
                    use[c] = False
                    break
        out = 0
        for first in (True, False):
            for c in range(k):
                if use[c] == first:
                    piece[p, out] = seed_piece[take[c]] if first else -1
                    theta[p, out, 0] = seed_theta[take[c], 0]
                    theta[p, out, 1] = seed_theta[take[c], 1]
                    out += 1
