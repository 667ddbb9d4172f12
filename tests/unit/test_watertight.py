"""check_watertight: closed solids pass; open, inconsistently oriented and inward ones fail
with the field of the offending patch."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from cgfem.errors import InputError
from cgfem.geometry.builders import build_solid
from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.solid import Patch, Solid
from cgfem.geometry.specs import BoxSpec, CylinderSpec, HalfTorusSpec, SphereSpec, TorusSpec
from cgfem.geometry.watertight import _closest_on_edge, _patch_edges, check_watertight

BOX = BoxSpec((0.0, 0.0, 0.0), (1.0, 2.0, 3.0))
AXIS = tuple(np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8]))
KEEP = tuple(np.cross(AXIS, (1.0, 0.0, 0.0)) / np.linalg.norm(np.cross(AXIS, (1.0, 0.0, 0.0))))
SPECS = {
    "box": BOX,
    "box-far": BoxSpec((100.0, -50.0, 7.0), (100.5, -49.0, 7.25)),
    "sphere": SphereSpec((1.0, 2.0, 3.0), 0.5),
    "cylinder": CylinderSpec((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0, 2.0),
    "cylinder-tilted": CylinderSpec((0.5, -1.0, 2.0), AXIS, 0.3, 4.0),
    "torus": TorusSpec((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 2.0, 0.5),
    "torus-tilted": TorusSpec((1.0, 1.0, -1.0), AXIS, 1.0, 0.9),
    "half_torus": HalfTorusSpec((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 2.0, 0.5, (1.0, 0.0, 0.0)),
    "half_torus-tilted": HalfTorusSpec((0.0, 3.0, 0.0), AXIS, 1.5, 0.2, KEEP),
}


def replaced(solid: Solid, name: str, surface: NurbsSurface | None) -> Solid:
    """``solid`` with the patch ``name`` replaced by ``surface`` (dropped if None)."""
    patches = []
    for patch in solid.patches:
        if patch.name != name:
            patches.append(patch)
        elif surface is not None:
            patches.append(Patch(name, surface))
    return Solid(tuple(patches))


def expect(solid: Solid, field: str, pattern: str) -> InputError:
    with pytest.raises(InputError) as info:
        check_watertight(solid)
    assert info.value.field == field, str(info.value)
    assert re.search(pattern, info.value.message), info.value.message
    return info.value


# -- closed solids pass -------------------------------------------------------------------
@pytest.mark.parametrize("name", list(SPECS))
def test_closed_solids_pass(name):
    check_watertight(build_solid(SPECS[name]))
    check_watertight(build_solid(SPECS[name]), rel_tol=1e-12)


def test_split_face_passes():
    """A face split in two: its neighbours' edges are covered by two edges each (T-junction)."""
    solid = build_solid(BOX)
    p = solid.named("xmin")[0].surface.points  # (2, 2, 3)
    cut = 0.3 * p[:, 0] + 0.7 * p[:, 1]
    halves = [NurbsSurface.from_points((1, 1), [0, 0, 1, 1], [0, 0, 1, 1], np.stack(pair, axis=1))
              for pair in ((p[:, 0], cut), (cut, p[:, 1]))]
    check_watertight(Solid((Patch("xmin", halves[0]), Patch("xmin", halves[1])) + solid.patches[1:]))


def test_reparametrized_face_passes():
    """A face whose edges are the same segments with a non-uniform (quadratic) parametrization:
    the samples do not coincide with the neighbours' samples, the Newton refinement decides."""
    solid = build_solid(BOX)
    p = solid.named("xmin")[0].surface.points
    q = np.stack([p[:, 0], p[:, 0] + 0.15 * (p[:, 1] - p[:, 0]), p[:, 1]], axis=1)
    face = NurbsSurface.from_points((1, 2), [0, 0, 1, 1], [0, 0, 0, 1, 1, 1], q)
    check_watertight(replaced(solid, "xmin", face), rel_tol=1e-12)


# -- open solids ---------------------------------------------------------------------------
def test_box_with_a_face_removed():
    solid = replaced(build_solid(BOX), "zmax", None)  # xmin (patches[0]) has an edge at z = 3
    err = expect(solid, "patches[0]", r"^edge [uv]=[01] is open: point \(.*\) is 1\.0e\+00 from every other patch edge$")
    assert "3)" in err.message


def test_torus_with_a_gap():
    """Moving the control row u=0 opens the seam by a relative 1e-6."""
    surface = build_solid(SPECS["torus"]).patches[0].surface
    control = surface.control.copy()
    control[0, :, 0] += 4.5e-6 * control[0, :, 3]  # 4.5e-6 along x; bounding-box diagonal 4.5
    moved = NurbsSurface(surface.degree, surface.knots_u, surface.knots_v, control)
    gap = Solid((Patch("surface", moved),))
    err = expect(gap, "patches[0]", r"^edge u=[01] is open: point .* is 4\.5e-06 from every other patch edge$")
    assert "u=0" in err.message  # the first open edge is reported
    check_watertight(gap, rel_tol=1e-5)  # within a looser tolerance it closes


def test_half_torus_without_cap_b():
    solid = replaced(build_solid(SPECS["half_torus"]), "cap_b", None)
    expect(solid, "patches[0]", r"^edge u=1 is open: point \(0, 1\.5, 0\) is 1\.0e\+00")


def test_half_torus_without_cap_a_tilted():
    solid = replaced(build_solid(SPECS["half_torus-tilted"]), "cap_a", None)
    expect(solid, "patches[0]", r"^edge u=0 is open")


def test_cylinder_with_a_small_cap():
    spec = SPECS["cylinder-tilted"]
    small = build_solid(CylinderSpec(spec.center, spec.axis, spec.radius * (1 - 1e-6), spec.height))
    solid = replaced(build_solid(spec), "top", small.named("top")[0].surface)
    expect(solid, "patches[0]", r"^edge v=1 is open: point .* is 3\.0e-07 from every other patch edge$")


# -- orientation ------------------------------------------------------------------------------
def test_box_with_a_face_flipped():
    solid = build_solid(BOX)
    flipped = replaced(solid, "zmin", solid.named("zmin")[0].surface.reversed_u())
    # zmin (patches[4]) disagrees with its four neighbours, each neighbour only with zmin
    expect(flipped, "patches[4]", r"^orientation is inconsistent with patches\[0\]$")


def test_half_torus_with_cap_flipped():
    solid = build_solid(SPECS["half_torus-tilted"])
    flipped = replaced(solid, "cap_b", solid.named("cap_b")[0].surface.reversed_u())
    expect(flipped, "patches[2]", r"^orientation is inconsistent with patches\[0\]$")


def test_all_faces_flipped_points_inward():
    solid = build_solid(BOX)
    inward = Solid(tuple(Patch(p.name, p.surface.reversed_u()) for p in solid.patches))
    expect(inward, "patches", r"^normals point inward \(volume < 0")


def test_inward_sphere():
    surface = build_solid(SPECS["sphere"]).patches[0].surface
    expect(Solid((Patch("surface", surface.reversed_u()),)), "patches", r"normals point inward")


# -- pieces -------------------------------------------------------------------------------------
def test_collapsed_edges_are_detected():
    sphere = build_solid(SPECS["sphere"]).patches[0].surface
    edges = _patch_edges(0, sphere, 1e-12)
    assert [e.label for e in edges] == ["u=0", "u=1", "v=0", "v=1"]
    assert [e.collapsed for e in edges] == [False, False, True, True]  # poles


def test_closest_on_edge_matches_dense_sampling():
    """Newton refinement against brute force on a rational edge (torus circle)."""
    rng = np.random.default_rng(5)
    surface = build_solid(SPECS["torus-tilted"]).patches[0].surface
    edge = _patch_edges(0, surface, 1e-12)[2]  # v = 0: the outer equator, a full circle
    x = edge.curve(rng.uniform(0, 1, 50))[0] + rng.normal(scale=1e-3, size=(50, 3))
    j = np.argmin(np.linalg.norm(x[:, None] - edge.x[None], axis=2), axis=1)
    d, t = _closest_on_edge(edge, x, j)
    # reference: dense sampling, then a bounded scalar minimization around the best sample
    grid = np.linspace(0, 1, 200001)
    dense = edge.curve(grid)[0]
    best = grid[np.argmin(np.linalg.norm(x[:, None] - dense[None], axis=2), axis=1)]
    brute = np.array([minimize_scalar(lambda s: np.linalg.norm(edge.curve([s])[0][0] - xi),
                                      bounds=(b - 1e-5, b + 1e-5), method="bounded",
                                      options={"xatol": 1e-13}).fun for xi, b in zip(x, best)])
    assert np.all(d <= brute + 1e-15)  # never worse than the reference
    assert np.all(brute - d <= 1e-11)  # the reference stops at its own tolerance
    c, c1, _ = edge.curve(t)
    assert np.allclose(np.linalg.norm(c - x, axis=1), d, rtol=0, atol=1e-15)
    # the foot is a stationary point: C - x is normal to the curve, up to the round-off of a
    # flat minimum, cos ~ sqrt(2 eps |C| / d) ~ 1e-6 at d ~ 1e-3
    cos = np.einsum("ij,ij->i", c - x, c1) / (d * np.linalg.norm(c1, axis=1))
    assert np.max(np.abs(cos)) < 1e-5


def test_rel_tol_must_be_positive():
    with pytest.raises(ValueError):
        check_watertight(build_solid(BOX), rel_tol=0.0)
