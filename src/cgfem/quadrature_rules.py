"""Gauss-Legendre rules on the reference interval ``[-1, 1]`` and its tensor products.

The one place the grid's element rules come from: the 2x2x2 rule of inside elements
(:mod:`cgfem.embedding.quadrature`), of the reference stiffness (:mod:`cgfem.fem.elasticity`)
and the 2x2 face rule of the ghost penalty (:mod:`cgfem.fem.ghost`). An ``n``-point rule
integrates polynomials of degree ``2 n - 1`` in each variable exactly.
"""

from __future__ import annotations

import numpy as np


def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``n``-point Gauss-Legendre rule on ``[-1, 1]``: points (n,) ascending, weights (n,)."""
    if n < 1:
        raise ValueError(f"a Gauss rule needs at least one point, got {n}")
    x, w = np.polynomial.legendre.leggauss(n)
    return x, w


def tensor_gauss(n: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``n^dim``-point tensor Gauss rule on ``[-1, 1]^dim``: points (n^dim, dim), the
    first coordinate varying slowest, and weights (n^dim,) summing to ``2^dim``."""
    x, w = gauss_legendre(n)
    points = np.stack(np.meshgrid(*[x] * dim, indexing="ij"), axis=-1).reshape(-1, dim)
    weights = np.prod(np.stack(np.meshgrid(*[w] * dim, indexing="ij"), axis=-1).reshape(-1, dim), axis=1)
    return points, weights
