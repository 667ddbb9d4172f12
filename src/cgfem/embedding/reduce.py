"""Reduced boundary rules: at most 27 points per element and patch, on the exact surface.

The exact boundary rule of a cut element (:mod:`cgfem.embedding.partition`) has 70 to 300
points: Gauss rules on the cells of the trimmed NURBS pieces, adaptive to 1e-9. The volume
rules need that (their integrands have degree 7 on the surface), but the boundary terms of
the weak form (weak Dirichlet conditions, tractions, contact) integrate products of H8 shape
functions, degree <= 2 in each variable. :func:`reduced_surface` keeps, per element and
patch, at most 27 of the exact points with new positive weights (Caratheodory
recombination, :func:`cgfem.embedding._column_kernels.recombine`) that integrate the 27
tensor Legendre polynomials of the element exactly as the full rule does. The points keep
their ``(xi, eta)`` (barycentrics for facets), normals, element and piece, so they remain
points of the exact surface (of the polyhedron for facets); integrands with the normal or
other non-polynomial factors are integrated to the accuracy of a 27-point rule instead of
the full rule's.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from cgfem.embedding import _column_kernels as _k
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.partition import SurfaceQuadrature


def reduced_surface(grid: CartesianGrid, surface: SurfaceQuadrature,
                    split: Sequence[np.ndarray] = ()) -> SurfaceQuadrature:
    """At most 27 points of ``surface`` per (element, patch), positive weights, the same
    moments of polynomials of degree <= 2 in each variable (module docstring). ``split``:
    further integer labels (n,) each that also separate the groups (e.g. the element of
    another grid, :mod:`cgfem.contact.rule`); the moments stay those of ``grid``'s element."""
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
                        np.ascontiguousarray(centre), 0.5 * grid.h, offsets, w)
    kept = order[w > 0.0]
    return replace(surface.select(kept), w=w[w > 0.0])
