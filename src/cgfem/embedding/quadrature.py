"""Embedding of one body in its Cartesian grid: element status and quadrature rules.

:func:`embed` classifies every grid element as outside, inside or cut and builds, for the
polynomial ``degree`` per variable its rules must integrate exactly (2 for trilinear
elements, the default; 4 for triquadratic ones):

- the volume rule: ``n^3`` Gauss points on inside elements, ``n = degree // 2 + 1`` (2x2x2
  for degree 2, 3x3x3 for degree 4; exact for degree ``2 n - 1`` in each variable); on cut
  elements, positive rules of at most ``(degree + 1)^3`` points in the material, exact for
  degree <= ``degree`` in each variable (:mod:`cgfem.embedding.columns`), or, where neither
  the columns nor the sub-tetrahedra give a positive rule, the moment-fitted
  ``(degree + 1)^3`` rule (:mod:`cgfem.embedding.moments`, exact too, but with points
  possibly outside the material and signed weights);
- the surface rule on the exact NURBS boundary, per patch, with ``(xi, eta)``, outward
  normals and owning elements (:mod:`cgfem.embedding.partition`), and its reduction to at
  most ``(degree + 1)^3`` points per element and patch for the weak form
  (:mod:`cgfem.embedding.reduce`).

An element is cut when a piece of the boundary of positive area lies in it, whatever the
signs of its nodes (a surface that enters and leaves through one face, a tube thinner than
the element); otherwise it is inside or outside as its centre is (for ``facets``: cut,
inside or outside by its node signs). Why each rule is as it is:
docs/methods/geometry-and-embedding.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from cgfem.definitions import DEFINITIONS, surface_definition
from cgfem.embedding.facets import FacetSurface, facet_embedding_parts, facet_surface_degree, volume_surface_degree
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.columns import DEFAULT_DEGREE, ColumnRules, LineHits, check_degree, column_rules, n_gauss
from cgfem.embedding.lines import cast_lines, cast_z_lines
from cgfem.embedding.moments import VolumeRule, fitted_volume_rule
from cgfem.embedding.partition import (DEFAULT_TOL, MAX_POINTS, SurfaceQuadrature, partition_min_points,
                                      partition_surface)
from cgfem.embedding.reduce import reduced_surface
from cgfem.geometry.bvh import SurfaceIndex
from cgfem.geometry.inside import points_inside
from cgfem.geometry.solid import Solid
from cgfem.quadrature_rules import tensor_gauss

OUTSIDE, INSIDE, CUT = 0, 1, 2
#: the boundary quadratures :func:`embed` builds (the one of each contact surface
#: definition is its :attr:`~cgfem.definitions.SurfaceDefinition.quadrature`)
SURFACE_DEFINITIONS = ("nurbs", "facets")


@dataclass(frozen=True)
class Embedding:
    """A body in its grid.

    status : (n_elements,) int8, OUTSIDE / INSIDE / CUT per grid element
    volume : volume rule over the active (inside and cut) elements
    surface : boundary rule; ``surface.patch`` indexes ``patch_names``
    fallback : ids of the cut elements with a moment-fitted rule instead of a positive one
    facets : the triangles of the ``facets`` definition (``surface.piece`` indexes them);
        None for the NURBS boundary
    definition : the surface definition the embedding was built for: ``facets``,
        ``nurbs_fe`` or ``nurbs_fit`` (the last two share the NURBS quadrature)
    degree : the polynomial degree per variable the volume rule and :attr:`boundary`
        integrate exactly (2: trilinear elements; 4: triquadratic ones)
    """

    grid: CartesianGrid
    status: np.ndarray
    volume: VolumeRule
    surface: SurfaceQuadrature
    patch_names: tuple[str, ...]
    fallback: np.ndarray
    facets: FacetSurface | None
    definition: str
    degree: int = DEFAULT_DEGREE

    @cached_property
    def boundary(self) -> SurfaceQuadrature:
        """The reduced boundary rule for the weak form's boundary terms: at most
        ``(degree + 1)^3`` points of ``surface`` per element and patch with its moments of
        the polynomials of degree <= ``degree`` per variable (:mod:`cgfem.embedding.reduce`),
        built on first use."""
        return reduced_surface(self.grid, self.surface, degree=self.degree)

    @property
    def active_elements(self) -> np.ndarray:
        """Ids of the inside and cut elements, ascending."""
        return np.flatnonzero(self.status != OUTSIDE)

    @property
    def active_nodes(self) -> np.ndarray:
        """Ids of the nodes of active elements, ascending."""
        return np.unique(self.grid.element_nodes(self.active_elements))

    def counts(self) -> dict[str, int]:
        return {"inside": int(np.sum(self.status == INSIDE)), "cut": int(np.sum(self.status == CUT)),
                "active": int(np.sum(self.status != OUTSIDE)), "nodes": int(self.active_nodes.size),
                "fitted": int(self.fallback.size)}

    def area_by_name(self) -> dict[str, float]:
        """Surface-rule area of every named surface."""
        areas = np.bincount(self.surface.patch, self.surface.w, minlength=len(self.patch_names))
        out = dict.fromkeys(dict.fromkeys(self.patch_names), 0.0)
        for name, area in zip(self.patch_names, areas):
            out[name] += float(area)
        return out


#: relative shift (of h0) applied to an axis whose grid planes would contain control points
NUDGE = 1e-3


def grid_for(solid: Solid, h0: float, level: int, offset=(0.0, 0.0, 0.0)) -> CartesianGrid:
    """The grid of ``level`` covering the control points of ``solid`` (which contain it).

    A grid plane through a control point of the geometry (a planar face in a grid plane, a
    plane tangent to a torus along a knot line, a pole on a grid line: round CAD coordinates
    with offset 0) makes the cut-cell problem degenerate. Such an axis is shifted by
    ``NUDGE * h0`` (times 1.6, 2.2, ... until no plane is within 1e-9 h of a control point).
    The geometry and its integrals stay exact; only the grid moves, by a thousandth of h0.
    """
    pts = np.concatenate([p.surface.points.reshape(-1, 3) for p in solid.patches])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    offset = np.asarray(offset, float).copy()
    h = h0 / 2.0**level
    for axis in range(3):
        coords = np.unique(pts[:, axis])
        for attempt in range(1, 20):
            base = offset[axis] * h0
            distance = np.abs((coords - base) / h - np.round((coords - base) / h))
            if np.all(distance > 1e-9):
                break
            offset[axis] = (offset[axis] + NUDGE * (1.0 + 0.618 * attempt)) % 1.0
    return CartesianGrid.covering(lo, hi, h0, level, offset)


def _interior_rule(grid: CartesianGrid, elements: np.ndarray, degree: int = DEFAULT_DEGREE) -> VolumeRule:
    """``n^3`` Gauss rule, ``n = degree // 2 + 1`` (exact for degree ``2 n - 1 >= degree``
    per variable: 2x2x2 for degree 2, 3x3x3 for degree 4), on each of ``elements``."""
    local, wq = tensor_gauss(n_gauss(degree), 3)
    centre = grid.element_center(grid.element_ijk(elements))
    x = centre[:, None, :] + 0.5 * grid.h * local[None, :, :]
    w = np.broadcast_to(wq * (0.5 * grid.h) ** 3, x.shape[:2])
    return VolumeRule(x.reshape(-1, 3), w.reshape(-1), np.repeat(elements, local.shape[0]))


def embed(solid: Solid, grid: CartesianGrid, surface: str = "nurbs", tol: float = DEFAULT_TOL,
          points: int | None = None, index: SurfaceIndex | None = None,
          definition: str | None = None, degree: int = DEFAULT_DEGREE,
          min_points: int | None = None) -> Embedding:
    """Classify the elements of ``grid`` and build the quadrature of ``solid`` for the
    boundary ``surface`` (``nurbs``: exact NURBS boundary; ``facets``: the marching-cubes
    polyhedron of :mod:`cgfem.embedding.facets`).

    Parameters
    ----------
    solid, grid : the body and its grid
    surface : ``nurbs`` or ``facets``
    tol : target relative accuracy of the NURBS partition's Gauss intervals
    points : Gauss points per direction of the moment-fitted fallback rule; at least and by
        default ``degree + 1`` (exact for degree < points per variable)
    index : the solid's surface index (built if None)
    definition : the contact surface definition the embedding serves (a name of
        :data:`cgfem.definitions.DEFINITIONS`, whose quadrature must be ``surface``), by
        default the first one on ``surface`` (``facets`` or ``nurbs_fe``)
    degree : polynomial degree in each variable that the volume rule and the reduced
        boundary rule integrate exactly: 2 (trilinear elements, the default) or 4
        (triquadratic); any integer in ``1..MAX_DEGREE`` is accepted. Cut elements get at
        most ``(degree + 1)^3`` points, inside elements ``(degree // 2 + 1)^3``.
    min_points : fewest Gauss points per direction and interval of the NURBS partition,
        by default :func:`cgfem.embedding.partition.partition_min_points` of ``degree``
        (the most are ``max(MAX_POINTS, min_points + 2)``); with ``tol`` it sets how
        exactly the boundary rule, hence the cut-cell rules, integrate their integrands
    """
    if surface not in SURFACE_DEFINITIONS:
        raise ValueError(f"unknown surface definition {surface!r} (known: {', '.join(SURFACE_DEFINITIONS)})")
    degree = check_degree(degree)
    points = degree + 1 if points is None else int(points)
    if points < degree + 1:
        raise ValueError(f"the fitted rule needs at least degree + 1 = {degree + 1} points per direction "
                         f"to be exact for degree {degree}, got {points}")
    if definition is None:
        definition = next(d.name for d in DEFINITIONS.values() if d.quadrature == surface)
    if surface_definition(definition).quadrature != surface:
        raise ValueError(f"surface definition {definition!r} does not use the {surface!r} quadrature")
    index = SurfaceIndex.build(solid) if index is None else index
    names = tuple(p.name for p in solid.patches)
    if surface == "facets":
        parts = facet_embedding_parts(solid, grid, index, facet_surface_degree(degree), points)
        # the column integrands have total degree 3 degree + 1 on the triangles
        need = volume_surface_degree(degree)
        exact = parts.surface if parts.degree >= need else parts.surface_rule(need)
        rules = column_rules(grid, parts.cut, exact, parts.trims, parts.line_hits(), degree)
        fitted = _fallback_rule(grid, rules, parts.fitted_volume_args(points) if rules.fallback.size else None,
                                points)
        return _assemble(grid, parts.status, rules, fitted, parts.surface, names,
                         parts.facet_surface(), definition, degree)
    z_lines = cast_z_lines(index, grid)
    min_points = partition_min_points(degree) if min_points is None else int(min_points)
    part = partition_surface(solid, grid, tol, min_points=min_points, max_points=max(MAX_POINTS, min_points + 2))
    status = np.zeros(grid.n_elements, np.int8)
    cut = np.unique(part.surface.element[part.surface.w > 0.0])
    status[cut] = CUT
    # an uncut element is wholly inside or outside: ask at its centre, which is h/2 away
    # from any boundary on its faces (a node may lie on the boundary)
    uncut = np.flatnonzero(status != CUT)
    centres = grid.element_center(grid.element_ijk(uncut))
    status[uncut[points_inside(index, centres)]] = INSIDE
    xy = [cast_lines(index, grid, axis).paired() for axis in (0, 1)]
    hits = LineHits((xy[0].offsets, xy[1].offsets, z_lines.offsets), (xy[0].coord, xy[1].coord, z_lines.z))
    rules = column_rules(grid, cut, part.surface, part.trims, hits, degree)
    s, t = part.surface, part.trims.select(part.trims.axis == 0)
    fitted_elements = rules.fallback
    cut_ijk = grid.element_ijk(fitted_elements)
    z0 = grid.plane(2, cut_ijk[:, 2])
    edges = [z_lines.inside_intervals(i + 1, j + 1, a, a + grid.h) for (i, j, _), a in zip(cut_ijk, z0)]
    args = dict(elements=fitted_elements, surf_x=s.x, surf_w=s.w, surf_nx=s.normal[:, 0], surf_element=s.element,
                trim_x=t.x, trim_w=t.w, trim_my=t.normal[:, 1], trim_element=t.element, edge_intervals=edges)
    fitted = fitted_volume_rule(grid, **args, n=points)
    return _assemble(grid, status, rules, fitted, part.surface, names, None, definition, degree)


def _fallback_rule(grid: CartesianGrid, rules: ColumnRules, args: dict | None, points: int) -> VolumeRule:
    """Moment-fitted rules of the elements of ``rules.fallback`` (``args``: the boundary
    data of all cut elements, :func:`fitted_volume_rule`'s keywords; None if there are no
    fallback elements)."""
    if args is None:
        return VolumeRule.empty()
    pick = np.isin(args["elements"], rules.fallback)
    args = dict(args, elements=args["elements"][pick],
                edge_intervals=[iv for iv, p in zip(args["edge_intervals"], pick) if p])
    args.pop("n", None)
    return fitted_volume_rule(grid, **args, n=points)


def _assemble(grid: CartesianGrid, status: np.ndarray, rules: ColumnRules, fitted: VolumeRule,
              surface: SurfaceQuadrature, names: tuple[str, ...], facets: FacetSurface | None,
              definition: str, degree: int) -> Embedding:
    inner = _interior_rule(grid, np.flatnonzero(status == INSIDE), degree)
    volume = VolumeRule(*(np.concatenate([getattr(inner, f), getattr(rules.volume, f), getattr(fitted, f)])
                          for f in ("x", "w", "element")))
    return Embedding(grid, status, volume, surface, names, rules.fallback, facets, definition, degree)
