"""Positive volume rules of cut elements (column decomposition + Caratheodory recombination):
positive weights, points in the material, at most 27 per element, and the same moments as
the independently derived moment-fitted rules."""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.embedding._column_kernels import legendre_row, recombine
from cgfem.embedding.facets import facet_embedding_parts
from cgfem.embedding.moments import fitted_volume_rule
from cgfem.embedding.quadrature import CUT, embed, grid_for
from cgfem.embedding.columns import CONES, OK, LineHits, column_rules
from cgfem.embedding.lines import cast_lines, cast_z_lines
from cgfem.embedding.partition import partition_surface
from cgfem.geometry.builders import build_solid
from cgfem.geometry.bvh import SurfaceIndex
from cgfem.geometry.inside import points_inside
from cgfem.geometry.specs import HalfTorusSpec, SphereSpec, TorusSpec

AXIS = tuple(np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8]))
SOLIDS = {
    "sphere": (SphereSpec((0.0, 0.0, 0.0), 1.0), 0.7),
    "torus": (TorusSpec((0.0, 0.0, 0.0), AXIS, 1.0, 0.4), 0.6),
    "half_torus": (HalfTorusSpec((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.02, 0.005, (0.0, 1.0, 0.0)), 0.005),
}
OFFSET = (0.13, 0.29, 0.41)


def _local_moments(grid, keys, key, x, w, element, dim: int = 3) -> np.ndarray:
    """Tensor Legendre moments (len(keys), 27) of a rule summed per group ``key`` (sorted
    ``keys``), in the local coordinates of each point's element (weights / (h/2)^dim)."""
    rows = np.searchsorted(keys, key)
    xi = (x - grid.element_center(grid.element_ijk(element))) / (0.5 * grid.h)
    phi = np.empty((len(x), 27))
    for i, p in enumerate(xi):
        legendre_row(p, 2, phi[i])
    out = np.zeros((len(keys), 27))
    np.add.at(out, rows, (w / (0.5 * grid.h) ** dim)[:, None] * phi)
    return out


def _accurate_rules(solid, grid):
    """Positive rules from boundary rules accurate for degree-7 integrands (1e-12, at least
    8 Gauss points per cell direction): (index, partition, cut ids, rules)."""
    index = SurfaceIndex.build(solid)
    part = partition_surface(solid, grid, 1e-12, min_points=8)
    lines = [cast_lines(index, grid, axis).paired() for axis in range(3)]
    hits = LineHits(tuple(a.offsets for a in lines), tuple(a.coord for a in lines))
    cut = np.unique(part.surface.element[part.surface.w > 0.0])
    return index, part, cut, column_rules(grid, cut, part.surface, part.trims, hits)


def _fitted_moments(index, grid, part, cut) -> np.ndarray:
    """Local moments (len(cut), 27) of the moment-fitted rules (x-direction divergence
    theorem) of the ``cut`` elements from the partition ``part``."""
    z = cast_z_lines(index, grid)
    s, t = part.surface, part.trims.select(part.trims.axis == 0)
    ijk = grid.element_ijk(cut)
    edges = [z.inside_intervals(i + 1, j + 1, a, a + grid.h)
             for (i, j, _), a in zip(ijk, grid.plane(2, ijk[:, 2]))]
    fitted = fitted_volume_rule(grid, cut, s.x, s.w, s.normal[:, 0], s.element,
                                t.x, t.w, t.normal[:, 1], t.element, edges)
    return _local_moments(grid, cut, fitted.element, fitted.x, fitted.w, fitted.element)


@pytest.mark.parametrize("name,level", [("sphere", 1), ("torus", 1), ("half_torus", 1),
                                        pytest.param("half_torus", 2, marks=pytest.mark.slow)])
def test_nurbs_rules_are_positive_and_inside(name, level):
    spec, h0 = SOLIDS[name]
    solid = build_solid(spec)
    emb = embed(solid, grid_for(solid, h0, level, OFFSET))
    cut = np.flatnonzero(emb.status == CUT)
    positive = np.setdiff1d(cut, emb.fallback)
    mask = np.isin(emb.volume.element, positive)
    x, w, element = emb.volume.x[mask], emb.volume.w[mask], emb.volume.element[mask]
    assert np.all(w > 0.0)
    assert np.bincount(element).max() <= 27
    assert np.all(points_inside(SurfaceIndex.build(solid), x))
    assert emb.fallback.size == 0


@pytest.mark.parametrize("name", ["sphere", "half_torus"])
def test_nurbs_column_rules_match_moment_fitting(name):
    """Two exact constructions from the same boundary rules, the columns (trimming curves on
    all grid planes, grid lines along all axes) and moment fitting (the x-direction
    divergence theorem, +x faces only), agree on all 27 moments. The boundary rules are
    made accurate enough for the degree-7 integrands of both (Gauss orders follow the
    Bezier piece, not h, so the defaults reach about 1e-5 on the highest moments at this
    coarse level)."""
    spec, h0 = SOLIDS[name]
    solid = build_solid(spec)
    grid = grid_for(solid, h0, 1, OFFSET)
    index, part, cut, rules = _accurate_rules(solid, grid)
    ok = rules.status == OK
    assert ok.all()
    expected = _fitted_moments(index, grid, part, cut)
    assert np.abs(rules.moments[ok] - expected[ok]).max() <= 1e-9
    # and the recombined rules keep the column rules' moments
    mask = np.isin(rules.volume.element, cut[ok])
    got = _local_moments(grid, cut[ok], rules.volume.element[mask], rules.volume.x[mask], rules.volume.w[mask],
                         rules.volume.element[mask])
    assert np.abs(got - rules.moments[ok]).max() <= 1e-12


@pytest.mark.slow
def test_fallback_is_rare_and_exact():
    """Elements where neither the columns nor the sub-tetrahedra are positive keep the
    moment-fitted rule: none on the link at levels 0-3; on a torus whose tube is barely
    thicker than h, 1 of 69 at level 0, and its volume stays exact."""
    spec, h0 = SOLIDS["half_torus"]
    solid = build_solid(spec)
    for level in range(4):
        assert embed(solid, grid_for(solid, h0, level, OFFSET)).fallback.size == 0
    spec, h0 = SOLIDS["torus"]
    solid = build_solid(spec)
    emb = embed(solid, grid_for(solid, h0, 0, OFFSET))
    assert emb.fallback.size <= 1
    assert emb.volume.w.sum() == pytest.approx(2 * np.pi**2 * 1.0 * 0.4**2, rel=1e-8)


def test_sub_tetrahedra_rule_on_a_tube_thinner_than_h():
    """A torus with tube radius 0.3 h: about half of its cut elements hold a whole piece of
    the tube (no axis makes it a graph) and get the sub-tetrahedra rule (cones from the
    centroid over the exact surface and the faces' material regions); every element gets a
    positive rule inside the tube with the moment-fitted rule's moments."""
    solid = build_solid(TorusSpec((0.0004, -0.0007, 0.0002), (0.0, 0.6, 0.8), 0.02, 0.0015))
    grid = grid_for(solid, 0.005, 0, (0.42, 0.13, 0.77))
    index, part, cut, rules = _accurate_rules(solid, grid)
    assert np.all(np.isin(rules.status, [OK, CONES])) and np.sum(rules.status == CONES) >= 30
    v = rules.volume
    assert np.all(v.w > 0.0) and np.bincount(v.element).max() <= 27
    assert np.all(points_inside(index, v.x))
    assert v.w.sum() == pytest.approx(2 * np.pi**2 * 0.02 * 0.0015**2, rel=1e-9)
    expected = _fitted_moments(index, grid, part, cut)
    got = _local_moments(grid, cut, v.element, v.x, v.w, v.element)
    assert np.abs(got - expected).max() <= 1e-9


@pytest.mark.parametrize("name", ["sphere", "torus", "half_torus"])
def test_facet_rules_are_positive_and_exact(name):
    spec, h0 = SOLIDS[name]
    solid = build_solid(spec)
    grid = grid_for(solid, h0, 1, OFFSET)
    emb = embed(solid, grid, "facets")
    parts = facet_embedding_parts(solid, grid)
    cut = parts.cut
    positive = np.setdiff1d(cut, emb.fallback)
    mask = np.isin(emb.volume.element, positive)
    x, w, element = emb.volume.x[mask], emb.volume.w[mask], emb.volume.element[mask]
    assert np.all(w > 0.0) and np.bincount(element).max() <= 27
    lo = grid.element_corner(grid.element_ijk(element))
    assert np.all((x >= lo) & (x <= lo + grid.h))
    rule = fitted_volume_rule(grid, **parts.fitted_volume_args())
    fitted = _local_moments(grid, cut, rule.element, rule.x, rule.w, rule.element)[np.searchsorted(cut, positive)]
    got = _local_moments(grid, positive, element, x, w, element)
    assert np.abs(got - fitted).max() <= 1e-11 * 8
    assert emb.fallback.size == 0


@pytest.mark.parametrize("robust", [False, True])
@pytest.mark.parametrize("n,spread", [(28, 1.0), (300, 1.0), (300, 1e-3), (300, 0.0)])
def test_recombination_keeps_moments_with_at_most_27_positive_weights(n, spread, robust):
    """Random points, a sliver (spread 1e-3), and pairs of points on common vertical lines
    like the Gauss points of columns (spread 0: nearly dependent moment vectors), with the
    fast (complete-pivoting elimination) and the robust (SVD) null vectors."""
    rng = np.random.default_rng(n)
    x = rng.uniform(-1.0, 1.0, (n, 3))
    if spread == 0.0:
        x[1::2, :2] = x[0::2, :2]
    else:
        x[:, 2] = -1.0 + spread * (x[:, 2] + 1.0)  # a sliver when spread is small
    phi = np.empty((n, 27))
    for i, p in enumerate(x):
        legendre_row(p, 2, phi[i])
    w = rng.uniform(0.1, 1.0, n)
    target = w @ phi
    recombine(phi, w, robust)
    assert np.all(w >= 0.0) and np.count_nonzero(w) <= 27
    assert np.abs(w @ phi - target).max() <= 1e-12 * target[0]


@pytest.mark.parametrize("surface", ["nurbs", "facets"])
def test_reduced_boundary_rule_keeps_exact_points_and_polynomial_integrals(surface):
    """At most 27 points per element and patch, a subset of the exact rule's (same position,
    parameters, normal), positive weights, and the same integrals of every tensor Legendre
    polynomial of degree <= 2 per variable on every (element, patch)."""
    spec, h0 = SOLIDS["half_torus"]
    solid = build_solid(spec)
    emb = embed(solid, grid_for(solid, h0, 1, OFFSET), surface)
    full, red = emb.surface, emb.boundary
    assert np.all(red.w > 0.0)
    # NURBS-enhanced rules shrink about 4x; facet rules have few points per element anyway
    assert red.w.size < (full.w.size / 3 if surface == "nurbs" else full.w.size)
    group = lambda q: q.element * len(emb.patch_names) + q.patch  # noqa: E731
    assert np.bincount(group(red)).max() <= 27
    rows = {tuple(r) for r in np.column_stack([full.x, full.normal, full.element, full.patch]).round(15)}
    assert all(tuple(r) in rows for r in np.column_stack([red.x, red.normal, red.element, red.patch]).round(15))
    keys = np.unique(group(full))
    m_full = _local_moments(emb.grid, keys, group(full), full.x, full.w, full.element, dim=2)
    m_red = _local_moments(emb.grid, keys, group(red), red.x, red.w, red.element, dim=2)
    assert np.abs(m_full - m_red).max() <= 1e-12 * np.abs(m_full[:, 0]).max()
    assert np.allclose(np.bincount(red.patch, red.w), np.bincount(full.patch, full.w), rtol=1e-13)

