"""Gauss-Legendre rules on the reference interval ``[-1, 1]`` and its tensor products, and
rules on triangles.

The one place the grid's element rules come from: the 2x2x2 rule of inside elements
(:mod:`cgfem.embedding.quadrature`), of the reference stiffness (:mod:`cgfem.fem.elasticity`)
and the 2x2 face rule of the ghost penalty (:mod:`cgfem.fem.ghost`). An ``n``-point rule
integrates polynomials of degree ``2 n - 1`` in each variable exactly. The triangle rules
integrate over the facets of :mod:`cgfem.embedding.facets`.
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


# symmetric triangle rules: barycentric orbits, weights normalised to sum 1 (polished by
# Newton on the moment equations of all monomials up to the degree)
#: degree 4, 6 points (Strang & Fix; Dunavant's rule 4): two orbits (a, a, 1 - 2a)
_RULE4_S21 = ((0.44594849091596483, 0.22338158967801136), (0.09157621350977077, 0.10995174365532195))
#: degree 8, 16 points (Dunavant's rule 8): centroid, three (a, a, 1 - 2a), one (a, b, 1 - a - b)
_RULE8_S3 = 0.14431560767775461
_RULE8_S21 = ((0.4592925882927025, 0.09509163426730695), (0.17056930775173426, 0.10321737053472947),
              (0.050547228317032185, 0.03245849762320132))
_RULE8_S111 = ((0.26311282963471405, 0.008394777409917169, 0.027230314174422027),)


def _symmetric_rule(s3, s21, s111) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric points (q, 3) and weights (q,) of the orbits: the centroid of weight ``s3``
    (None: no centroid), ``(a, a, 1 - 2a)`` of weight ``w`` for each ``(a, w)`` of ``s21``
    and the six permutations of ``(a, b, 1 - a - b)`` for each ``(a, b, w)`` of ``s111``."""
    bary, w = [], []
    if s3 is not None:
        bary.append([1 / 3, 1 / 3, 1 / 3])
        w.append(s3)
    for a, wa in s21:
        bary += [[a, a, 1 - 2 * a], [a, 1 - 2 * a, a], [1 - 2 * a, a, a]]
        w += [wa] * 3
    for a, b, wab in s111:
        c = 1 - a - b
        bary += [[a, b, c], [a, c, b], [b, a, c], [b, c, a], [c, a, b], [c, b, a]]
        w += [wab] * 6
    return np.array(bary), np.array(w)


def triangle_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """A rule on triangles exact for polynomials of total ``degree``: barycentric points
    (q, 3) and weights (q,) summing to 1 (multiply by the area). Degree <= 4: 6 points,
    <= 8: 16 points (symmetric); higher: the collapsed (Duffy) product of Gauss-Legendre
    rules."""
    if degree <= 4:
        return _symmetric_rule(None, _RULE4_S21, ())
    if degree <= 8:
        return _symmetric_rule(_RULE8_S3, _RULE8_S21, _RULE8_S111)
    k = (degree + 3) // 2  # (1 - s) p(s, .) has degree degree + 1 in s: 2k - 1 >= degree + 1
    g, gw = np.polynomial.legendre.leggauss(k)
    g, gw = 0.5 * (g + 1.0), 0.5 * gw
    s, t = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    w = np.outer(gw, gw).ravel() * (1.0 - s) * 2.0
    u, v = s, t * (1.0 - s)
    return np.column_stack([1.0 - u - v, u, v]), w
