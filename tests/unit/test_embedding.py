"""NURBS-enhanced embedding: exact volumes and areas on cut grids, consistent volume and
surface rules, no missed cut element."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.quadrature import CUT, INSIDE, OUTSIDE, embed, grid_for
from cgfem.geometry.builders import build_solid
from cgfem.geometry.measure import areas_by_name, volume
from cgfem.geometry.specs import BoxSpec, CylinderSpec, HalfTorusSpec, SphereSpec, TorusSpec

R, r = 0.02, 0.005


def _unit(rng) -> tuple[float, float, float]:
    v = rng.normal(size=3)
    return tuple(v / np.linalg.norm(v))


def _shapes(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    axis = np.array(_unit(rng))
    keep = np.cross(axis, _unit(rng))
    keep /= np.linalg.norm(keep)
    centre = tuple(rng.uniform(-1e-3, 1e-3, 3))
    return {
        "sphere": SphereSpec(centre, 0.011),
        "torus": TorusSpec(centre, tuple(axis), R, r),
        "half_torus": HalfTorusSpec(centre, tuple(axis), R, r, tuple(keep)),
        "cylinder": CylinderSpec(centre, tuple(axis), 0.006, 0.021),
        "box": BoxSpec((0.0003, -0.0021, 0.0011), (0.0121, 0.0093, 0.0072)),
    }


def _closed_forms(name: str, spec) -> tuple[float, float]:
    if name == "sphere":
        return 4 / 3 * math.pi * spec.radius**3, 4 * math.pi * spec.radius**2
    if name == "torus":
        return 2 * math.pi**2 * R * r * r, 4 * math.pi**2 * R * r
    if name == "half_torus":
        return math.pi**2 * R * r * r, 2 * math.pi**2 * R * r + 2 * math.pi * r * r
    if name == "cylinder":
        rad, height = spec.radius, spec.height
        return math.pi * rad**2 * height, 2 * math.pi * rad * height + 2 * math.pi * rad**2
    size = np.subtract(spec.max, spec.min)
    return float(np.prod(size)), float(2 * (size[0] * size[1] + size[1] * size[2] + size[0] * size[2]))


#: level 2 with ``-m long`` (40 s): levels 0 and 1 take nine random placements of each shape
@pytest.mark.parametrize("level,seeds", [(0, range(6)), pytest.param(1, range(3), marks=pytest.mark.slow),
                                         pytest.param(2, range(1), marks=(pytest.mark.slow, pytest.mark.long))])
@pytest.mark.parametrize("name", ["sphere", "torus", "half_torus", "cylinder", "box"])
def test_nurbs_volume_and_area_are_exact(name, level, seeds):
    for seed in seeds:
        spec = _shapes(seed)[name]
        solid = build_solid(spec)
        exact_volume, exact_area = _closed_forms(name, spec)
        offset = np.random.default_rng(100 + seed).random(3)
        emb = embed(solid, grid_for(solid, 0.005, level, offset))
        assert emb.volume.w.sum() == pytest.approx(exact_volume, rel=1e-8)
        assert emb.surface.w.sum() == pytest.approx(exact_area, rel=1e-8)
        # each named surface too (caps and tube of the half torus, faces of the box)
        for patch_name, area in areas_by_name(solid).items():
            assert emb.area_by_name()[patch_name] == pytest.approx(area, rel=1e-8)


def test_points_lie_in_their_elements_and_statuses_agree():
    solid = build_solid(_shapes(3)["half_torus"])
    emb = embed(solid, grid_for(solid, 0.005, 1, (0.2, 0.4, 0.9)))
    grid = emb.grid
    for x, element in ((emb.surface.x, emb.surface.element), (emb.volume.x, emb.volume.element)):
        lo = grid.element_corner(grid.element_ijk(element))
        assert np.all(x >= lo - 1e-12 * grid.h) and np.all(x <= lo + grid.h + 1e-12 * grid.h)
    assert np.all(emb.status[emb.surface.element] == CUT)
    assert np.all(emb.status[emb.volume.element] != OUTSIDE)
    # an inside element has no boundary in it and a full 2x2x2 rule of weight h^3
    inside = np.flatnonzero(emb.status == INSIDE)
    weights = np.bincount(emb.volume.element, emb.volume.w, minlength=grid.n_elements)
    assert np.allclose(weights[inside], grid.h**3, rtol=1e-14)


@pytest.mark.slow
def test_divergence_theorem_volume_and_surface_rules_agree():
    """int_V div f dV = oint f.n dA for fields of degree <= 2 in each variable (exact for the
    moment-fitted rules), on a torus and a half torus with rotated axes."""
    rng = np.random.default_rng(11)
    for name in ("torus", "half_torus"):
        solid = build_solid(_shapes(5)[name])
        emb = embed(solid, grid_for(solid, 0.005, 1, rng.random(3)))
        for _ in range(3):
            c = rng.normal(size=(3, 3, 3, 3))  # f_k = sum c[k, a, b, d] x^a y^b z^d / L^(a+b+d)
            L = 0.02

            def field(x, k):
                xs = x / L
                return np.einsum("abd,pa,pb,pd->p", c[k], *(np.power.outer(xs[:, i], np.arange(3))
                                                          for i in range(3)))

            def divergence(x):
                xs = x / L
                total = np.zeros(len(x))
                for k in range(3):
                    powers = [np.power.outer(xs[:, i], np.arange(3)) for i in range(3)]
                    deriv = np.arange(3) * np.power.outer(xs[:, k], np.arange(3) - 1.0) / L
                    powers[k] = deriv
                    total += np.einsum("abd,pa,pb,pd->p", c[k], *powers)
                return total

            lhs = np.sum(emb.volume.w * divergence(emb.volume.x))
            flux = sum(field(emb.surface.x, k) * emb.surface.normal[:, k] for k in range(3))
            rhs = np.sum(emb.surface.w * flux)
            scale = np.sum(np.abs(emb.surface.w * flux))
            assert abs(lhs - rhs) <= 1e-9 * scale


def test_thin_tube_below_grid_size():
    """A torus whose tube radius is below h at level 0: no element has an inside node, yet
    volume and area are exact and every element the surface passes through is cut."""
    spec = TorusSpec((0.0004, -0.0007, 0.0002), (0.0, 0.6, 0.8), 0.02, 0.0015)
    solid = build_solid(spec)
    emb = embed(solid, grid_for(solid, 0.005, 0, (0.42, 0.13, 0.77)))
    assert emb.counts()["inside"] == 0
    assert emb.volume.w.sum() == pytest.approx(2 * math.pi**2 * 0.02 * 0.0015**2, rel=1e-8)
    assert emb.surface.w.sum() == pytest.approx(4 * math.pi**2 * 0.02 * 0.0015, rel=1e-8)
    # dense samples of the surface: their elements must all be cut
    surf = solid.patches[0].surface
    uv = np.random.default_rng(0).random((20000, 2))
    elements = emb.grid.element_id(emb.grid.element_of_points(surf.evaluate(uv)))
    assert np.all(emb.status[elements] == CUT)


def test_uncut_elements_integrate_cubics_exactly():
    solid = build_solid(_shapes(1)["sphere"])
    emb = embed(solid, grid_for(solid, 0.005, 1, (0.5, 0.25, 0.75)))
    grid = emb.grid
    inside = np.flatnonzero(emb.status == INSIDE)
    mask = np.isin(emb.volume.element, inside)
    x, w, e = emb.volume.x[mask], emb.volume.w[mask], emb.volume.element[mask]
    lo = grid.element_corner(grid.element_ijk(e))
    s = (x - lo) / grid.h  # local coordinates in [0, 1]
    for a, b, c in [(3, 0, 0), (1, 2, 3), (3, 3, 3), (2, 1, 0)]:
        got = np.bincount(np.searchsorted(inside, e), w * s[:, 0]**a * s[:, 1]**b * s[:, 2]**c)
        exact = grid.h**3 / ((a + 1) * (b + 1) * (c + 1))
        assert np.allclose(got, exact, rtol=1e-13)


def test_grid_refinement_is_nested():
    grid = CartesianGrid.covering((0.0, 0.0, 0.0), (0.02, 0.01, 0.005), 0.005, 0, (0.3, 0.6, 0.9))
    fine = CartesianGrid.covering((0.0, 0.0, 0.0), (0.02, 0.01, 0.005), 0.005, 1, (0.3, 0.6, 0.9))
    assert grid.refined().h == fine.h
    # every coarse plane is a fine plane
    for axis in range(3):
        coarse_planes = grid.plane(axis, np.arange(grid.node_shape[axis]))
        fine_planes = fine.plane(axis, np.arange(fine.node_shape[axis]))
        coarse_planes = coarse_planes[(coarse_planes >= fine_planes[0]) & (coarse_planes <= fine_planes[-1])]
        assert coarse_planes.size >= 2
        assert np.all(np.min(np.abs(coarse_planes[:, None] - fine_planes[None, :]), axis=1) < 1e-15)
    ids = np.arange(grid.n_elements)
    assert np.array_equal(grid.element_id(grid.element_ijk(ids)), ids)


@pytest.mark.parametrize("name", ["sphere", "torus", "half_torus", "box"])
def test_offset_zero_with_round_coordinates(name):
    """Grid planes through the centre, poles, tangent planes and planar faces (offset 0 and
    round CAD coordinates): the grid is nudged by 1e-3 h0 and everything stays exact."""
    spec = {"sphere": SphereSpec((0, 0, 0), 0.01),
            "torus": TorusSpec((0, 0, 0), (0, 0, 1), R, r),
            "half_torus": HalfTorusSpec((0, 0, 0), (0, 0, 1), R, r, (0, 1, 0)),
            "box": BoxSpec((0.0, 0.0, 0.0), (0.0025, 0.01, 0.01))}[name]
    solid = build_solid(spec)
    for level in (0, 1):
        grid = grid_for(solid, 0.005 if name != "box" else 0.00125, level, (0.0, 0.0, 0.0))
        emb = embed(solid, grid)
        assert emb.volume.w.sum() == pytest.approx(volume(solid), rel=1e-8)
        assert emb.surface.w.sum() == pytest.approx(sum(areas_by_name(solid).values()), rel=1e-8)


def test_facets_definition_through_embed():
    """The facets polyhedron is inscribed in the convex sphere: smaller volume and area,
    second order in h, and its rules agree with the divergence theorem for f = x."""
    solid = build_solid(SphereSpec((0.0003, -0.0002, 0.0001), 0.01))
    errors = []
    for level in range(3):
        grid = grid_for(solid, 0.005, level, (0.37, 0.11, 0.83))
        emb = embed(solid, grid, "facets")
        v = emb.volume.w.sum()
        assert v < volume(solid) and emb.surface.w.sum() < 4 * math.pi * 0.01**2
        assert np.sum(emb.surface.w * emb.surface.normal[:, 0] * emb.surface.x[:, 0]) == pytest.approx(v, rel=1e-12)
        errors.append(1 - v / volume(solid))
    order = np.polyfit(np.log([0.005 / 2**k for k in range(3)]), np.log(errors), 1)[0]
    assert 1.7 < order < 2.4
