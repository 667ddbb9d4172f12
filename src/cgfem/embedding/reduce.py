"""Reduced boundary rules: at most ``(degree + 1)^3`` points per element and patch, on the
exact surface.

The exact boundary rule of a cut element (:mod:`cgfem.embedding.partition`) has 70 to 300
points: Gauss rules on the cells of the trimmed NURBS pieces. The volume rules need that
(their integrands have degree ``3 degree + 1`` on the surface), but the boundary terms of the
weak form (weak Dirichlet conditions, tractions, contact) integrate products of shape
functions: degree <= 2 in each variable for trilinear (H8) elements, <= 4 for triquadratic
ones. :func:`reduced_surface` keeps, per element and patch, at most ``(degree + 1)^3`` of the
exact points (27 for degree 2, 125 for degree 4) with new positive weights (Caratheodory
recombination, :func:`cgfem.embedding._column_kernels.recombine`) that integrate the
``(degree + 1)^3`` tensor Legendre polynomials of degree <= ``degree`` per variable of the
element exactly as the full rule does. The points keep their ``(xi, eta)`` (barycentrics for
facets), normals, element and piece, so they remain points of the exact surface (of the
polyhedron for facets); integrands with the normal or other non-polynomial factors are
integrated to the accuracy of the reduced rule instead of the full rule's.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from cgfem.embedding import _column_kernels as _k
from cgfem.embedding.columns import DEFAULT_DEGREE, check_degree
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.partition import SurfaceQuadrature


def reduced_surface(grid: CartesianGrid, surface: SurfaceQuadrature,
                    split: Sequence[np.ndarray] = (), degree: int = DEFAULT_DEGREE) -> SurfaceQuadrature:
    """At most ``(degree + 1)^3`` points of ``surface`` per (element, patch), positive
    weights, the same moments of the polynomials of degree <= ``degree`` in each variable
    (module docstring). ``split``: further integer labels (n,) each that also separate the
    groups (e.g. the element of another grid, :mod:`cgfem.contact.rule`); the moments stay
    those of ``grid``'s element. A group whose recombination misses the moments by more
    than ``MOMENT_TOL`` of its area keeps all its points."""
    degree = check_degree(degree)
    rows = np.flatnonzero(surface.w > 0.0)
    key = np.stack([surface.element[rows], surface.patch[rows], *(np.asarray(s)[rows] for s in split)])
    by_key = np.lexsort(key[::-1])                      # stable: a group keeps its points' order
    order, key = rows[by_key], key[:, by_key]
    new = np.r_[True, np.any(key[:, 1:] != key[:, :-1], axis=0)] if order.size else np.zeros(0, bool)
    starts = np.flatnonzero(new)
    offsets = np.r_[starts, order.size].astype(np.int64)
    centre = grid.element_center(grid.element_ijk(key[0, starts])) if order.size else np.zeros((0, 3))
    w = np.zeros(order.size)
    _k.recombine_groups(np.ascontiguousarray(surface.x[order]), np.ascontiguousarray(surface.w[order]),
                        np.ascontiguousarray(centre), 0.5 * grid.h, offsets, degree, w)
    kept = order[w > 0.0]
    return replace(surface.select(kept), w=w[w > 0.0])
