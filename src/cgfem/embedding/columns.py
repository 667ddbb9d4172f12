"""Positive volume rules of cut elements, every point in the material.

The material part of a cut element is split exactly into columns (a height-function
decomposition, as in Saye's quadrature for implicit domains, here with the exact boundary):
along a *height axis* ``a`` for which the element's piece of boundary is a graph (all its
outward normals have one sign ``sigma`` along ``a``), the material is the union of

- the columns between each boundary point and the element face on the ``-sigma`` side,
  weighted by ``dA |n_a|`` (the projected area), and
- the full columns over the material region ``R`` of the face on the ``sigma`` side.

``R`` is split the same way inside its face: strips from each point of its trimming curves
to the face edge on one side, weighted by ``dl |m_b|``, and full strips over the material
intervals of that edge (a grid line). With the exact boundary rules (NURBS-enhanced:
:mod:`cgfem.embedding.partition`; facets: triangles and straight face segments) and
``degree // 2 + 1`` Gauss points along columns and strips, this *column rule* is exact for
polynomials of degree <= ``degree`` in each variable (2 for trilinear, 4 for triquadratic
elements), has positive weights, and all its points lie in the material.

The column rule has hundreds of points (``degree // 2 + 1`` per boundary point).
Caratheodory recombination (in groups, :func:`cgfem.embedding._column_kernels.recombine`)
keeps at most ``(degree + 1)^3`` of them with new positive weights and the same
``(degree + 1)^3`` tensor Legendre moments, so the final rule is as exact as the column
rule, as small as a ``(degree + 1)^3`` Gauss rule, positive and inside.

An element none of whose three axes makes its boundary a graph (two sheets of a tube
thinner than the element, a saddle, a silhouette inside it) is split into sub-tetrahedra
instead: cones from its centroid over the exact surface and over its faces' material
regions (:mod:`cgfem.embedding._cone_kernels`), positive when the material part is
star-shaped from the centroid, then recombined the same way. An element where neither is
positive keeps the moment-fitted rule of :mod:`cgfem.embedding.moments`;
:attr:`ColumnRules.fallback` lists them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cgfem.embedding import _column_kernels as _k
from cgfem.embedding import _cone_kernels as _cones
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.lines import line_axes
from cgfem.embedding.moments import VolumeRule
from cgfem.embedding.partition import SurfaceQuadrature, TrimQuadrature

OK, NO_DIRECTION, NOT_RECOMBINED, CONES = _k.OK, _k.NO_DIRECTION, _k.NOT_RECOMBINED, _k.CONES
#: polynomial degree per variable the volume rules integrate exactly unless told otherwise
#: (the products of trilinear shape functions and their derivatives)
DEFAULT_DEGREE = 2
#: highest degree accepted (343 moments; the recombination's cost grows as their square)
MAX_DEGREE = 6


def check_degree(degree: int) -> int:
    """``degree`` as an int, or ValueError unless ``1 <= degree <= MAX_DEGREE``."""
    if isinstance(degree, bool) or int(degree) != degree or not 1 <= degree <= MAX_DEGREE:
        raise ValueError(f"quadrature degree must be an integer in 1..{MAX_DEGREE}, got {degree!r}")
    return int(degree)


def n_moments(degree: int) -> int:
    """Number of tensor Legendre polynomials of degree <= ``degree`` in each variable,
    ``(degree + 1)^3``: the most points a recombined rule keeps."""
    return (check_degree(degree) + 1) ** 3


def n_gauss(degree: int) -> int:
    """Gauss points per direction exact for degree ``degree``: ``degree // 2 + 1``
    (``2 n - 1 >= degree``)."""
    return check_degree(degree) // 2 + 1


@dataclass(frozen=True)
class LineHits:
    """Sorted, paired boundary crossings of the grid lines along each axis: for axis ``c``,
    the line through nodes ``(p, q)`` of the other two axes (``b < c'``, numbered
    ``p * node_shape[c'] + q`` as :class:`cgfem.embedding.lines.GridLines`) has the material
    intervals ``coord[c][offsets[c][l]:offsets[c][l + 1]]`` taken in pairs."""

    offsets: tuple[np.ndarray, np.ndarray, np.ndarray]
    coord: tuple[np.ndarray, np.ndarray, np.ndarray]

    @classmethod
    def from_crossings(cls, grid: CartesianGrid, axis: np.ndarray, node: np.ndarray,
                       coord: np.ndarray) -> "LineHits":
        """Hits given one by one: the line ``axis`` (k,) through node ids ``node`` (k,),
        at ``coord`` (k,) along it."""
        offsets, coords = [], []
        ijk = np.column_stack(np.unravel_index(np.asarray(node, np.int64), grid.node_shape))
        for c in range(3):
            b, cc = line_axes(c)
            on = np.asarray(axis) == c
            line = ijk[on, b] * grid.node_shape[cc] + ijk[on, cc]
            order = np.lexsort((coord[on], line))
            n_lines = grid.node_shape[b] * grid.node_shape[cc]
            offsets.append(np.concatenate([[0], np.cumsum(np.bincount(line, minlength=n_lines))]))
            coords.append(np.asarray(coord, float)[on][order])
        return cls(tuple(offsets), tuple(coords))

    def packed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(start (3,), offsets, coord)``: the three CSR arrays concatenated; line ``l`` of
        axis ``c`` is ``coord[offsets[start[c] + l]:offsets[start[c] + l + 1]]``."""
        start = np.cumsum([0] + [o.size for o in self.offsets[:2]]).astype(np.int64)
        base = np.cumsum([0] + [x.size for x in self.coord[:2]])
        offsets = np.concatenate([o + s for o, s in zip(self.offsets, base)]).astype(np.int64)
        return start, offsets, np.concatenate(self.coord).astype(float)


@dataclass(frozen=True)
class ColumnRules:
    """Positive rules of cut elements.

    elements : (m,) the cut element ids, ascending
    volume : the positive rules (at most ``(degree + 1)^3`` points each)
    status : (m,) OK (from the column rule), CONES (from the sub-tetrahedra rule),
        NO_DIRECTION (neither is positive: moment-fitted fallback) or NOT_RECOMBINED (the
        recombination lost accuracy: fallback)
    full_points : (m,) number of points of the exact column (or sub-tetrahedra) rule
    moments : (m, (degree + 1)^3) its moments of the tensor Legendre polynomials
        ``L_a L_b L_c`` (``a`` slowest) in local coordinates ``(x - centre) / (h / 2)``,
        the weights divided by ``(h / 2)^3`` (zero for elements without one)
    degree : the polynomial degree per variable the rules integrate exactly
    """

    elements: np.ndarray
    volume: VolumeRule
    status: np.ndarray
    full_points: np.ndarray
    moments: np.ndarray
    degree: int = DEFAULT_DEGREE

    @property
    def fallback(self) -> np.ndarray:
        """Ids of the cut elements without a positive rule."""
        return self.elements[(self.status != OK) & (self.status != CONES)]


def column_rules(grid: CartesianGrid, elements: np.ndarray, surface: SurfaceQuadrature,
                 trims: TrimQuadrature, lines: LineHits, degree: int = DEFAULT_DEGREE) -> ColumnRules:
    """Positive rules of the cut ``elements`` (ids) from the boundary rule of each, the
    trimming rules of the grid planes and the grid lines' material intervals (module doc),
    exact for polynomials of degree <= ``degree`` in each variable as far as the boundary
    rules are exact for their integrands (degree ``3 degree + 1`` on the surface: the
    column integral, of degree ``degree + 1`` along the height axis, times ``degree`` in
    each of the other two)."""
    n_mom = n_moments(degree)
    elements = np.asarray(elements, np.int64)
    mine = np.flatnonzero(np.isin(surface.element, elements))
    order = mine[np.argsort(surface.element[mine], kind="stable")]
    s_el = surface.element[order]
    s_off = np.concatenate([[0], np.searchsorted(s_el, elements, side="right")]).astype(np.int64)
    keep = trims.element >= 0
    t_key = trims.axis[keep].astype(np.int64) * grid.n_elements + trims.element[keep]
    t_order = np.argsort(t_key, kind="stable")
    start, l_off, l_coord = lines.packed()
    g, gw = np.polynomial.legendre.leggauss(n_gauss(degree))
    m = elements.size
    out_x = np.zeros((m, n_mom, 3))
    out_w = np.zeros((m, n_mom))
    out_count = np.zeros(m, np.int64)
    out_status = np.zeros(m, np.int64)
    out_full = np.zeros(m, np.int64)
    out_moments = np.zeros((m, n_mom))
    if m:
        _k.column_rules(elements, grid.element_ijk(elements), np.asarray(grid.origin, float), float(grid.h),
                        np.asarray(grid.shape, np.int64), np.asarray(grid.node_shape, np.int64),
                        np.ascontiguousarray(surface.x[order]), np.ascontiguousarray(surface.w[order]),
                        np.ascontiguousarray(surface.normal[order]), s_off,
                        t_key[t_order], np.ascontiguousarray(trims.x[keep][t_order]),
                        np.ascontiguousarray(trims.w[keep][t_order]),
                        np.ascontiguousarray(trims.normal[keep][t_order]),
                        start, l_off, l_coord, 0.5 * (g + 1.0), 0.5 * gw, _cones.cone_tables(degree),
                        int(degree), out_x, out_w, out_count, out_status, out_full, out_moments)
    rows = np.arange(n_mom)[None, :] < out_count[:, None]
    volume = VolumeRule(out_x[rows], out_w[rows], np.repeat(elements, out_count))
    return ColumnRules(elements, volume, out_status, out_full, out_moments, int(degree))

