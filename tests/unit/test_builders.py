"""The exact builders: sampled points lie on the analytic surfaces, normals point out,
B-rep area and volume equal the closed forms, patch names, watertightness."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cgfem.geometry.builders import (box, build_solid, cylinder, half_cylinder, half_torus, sphere,
                                    torus)
from cgfem.geometry.measure import areas_by_name, boundary_measures, volume
from cgfem.geometry.specs import (PATCH_NAMES, BoxSpec, CylinderSpec, HalfCylinderSpec, HalfTorusSpec,
                                  SphereSpec, TorusSpec)
from cgfem.geometry.watertight import check_watertight

N_SAMPLES = 1000
ON_SURFACE = 1e-13  # relative distance of sampled points to the analytic surface
NORMAL_TOL = 1e-9   # |n - n_exact|
MEASURE = 1e-10     # relative error of B-rep area and volume


def unit(rng) -> np.ndarray:
    a = rng.normal(size=3)
    return a / np.linalg.norm(a)


def perpendicular(rng, axis) -> np.ndarray:
    k = rng.normal(size=3)
    k -= np.dot(k, axis) * axis
    return k / np.linalg.norm(k)


def sample(surface, rng, n=N_SAMPLES):
    """Random parameters, points (n, 3) and unit normals (n, 3) on a patch."""
    (u0, u1), (v0, v1) = surface.domain
    uv = np.column_stack([rng.uniform(u0, u1, n), rng.uniform(v0, v1, n)])
    return surface.evaluate(uv), surface.normals(uv)


def local(p, center, axis):
    """Axial coordinate (n,), radial distance (n,) and radial unit vectors (n, 3)."""
    d = p - np.asarray(center)
    z = d @ axis
    radial = d - z[:, None] * axis
    rho = np.linalg.norm(radial, axis=1)
    return z, rho, radial / rho[:, None]


def sphere_specs():
    rng = np.random.default_rng(1)
    return [SphereSpec((0.0, 0.0, 0.0), 1.0), SphereSpec((1.0, -2.0, 0.5), 0.25),
            SphereSpec(tuple(rng.uniform(-3, 3, 3)), 3.7)]


def cylinder_specs():
    rng = np.random.default_rng(2)
    specs = [CylinderSpec((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0, 2.0)]
    for _ in range(3):
        specs.append(CylinderSpec(tuple(rng.uniform(-2, 2, 3)), tuple(unit(rng)),
                                  rng.uniform(0.1, 2.0), rng.uniform(0.1, 3.0)))
    return specs


def torus_specs():
    rng = np.random.default_rng(3)
    specs = [TorusSpec((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 2.0, 0.5)]
    for _ in range(3):
        R = rng.uniform(0.5, 3.0)
        specs.append(TorusSpec(tuple(rng.uniform(-2, 2, 3)), tuple(unit(rng)), R, R * rng.uniform(0.05, 0.9)))
    return specs


def half_torus_specs():
    rng = np.random.default_rng(4)
    specs = [HalfTorusSpec((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 2.0, 0.5, (1.0, 0.0, 0.0)),
             HalfTorusSpec((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0, 0.3, (0.0, -1.0, 0.0))]
    for _ in range(3):
        axis = unit(rng)
        R = rng.uniform(0.5, 3.0)
        specs.append(HalfTorusSpec(tuple(rng.uniform(-2, 2, 3)), tuple(axis), R, R * rng.uniform(0.05, 0.9),
                                   tuple(perpendicular(rng, axis))))
    return specs


def half_cylinder_specs():
    rng = np.random.default_rng(5)
    specs = [HalfCylinderSpec((0.0, 0.1, 1.0), (0.0, 1.0, 0.0), 1.0, 0.2, (0.0, 0.0, -1.0))]
    for _ in range(3):
        axis = unit(rng)
        specs.append(HalfCylinderSpec(tuple(rng.uniform(-2, 2, 3)), tuple(axis), rng.uniform(0.1, 2.0),
                                      rng.uniform(0.1, 3.0), tuple(perpendicular(rng, axis))))
    return specs


def box_specs():
    return [BoxSpec((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)), BoxSpec((-1.0, 2.0, 0.5), (3.0, 2.5, 4.0)),
            BoxSpec((10.0, -7.0, 3.0), (10.001, -6.0, 300.0))]


def ids(specs):
    return [f"{i}" for i in range(len(specs))]


# -- points on the analytic surfaces, outward normals ----------------------------------
@pytest.mark.parametrize("spec", sphere_specs(), ids=ids(sphere_specs()))
def test_sphere_points_and_normals(spec):
    rng = np.random.default_rng(10)
    c, r = np.array(spec.center), spec.radius
    p, n = sample(sphere(spec).patches[0].surface, rng)
    d = p - c
    dist = np.linalg.norm(d, axis=1)
    assert np.max(np.abs(dist - r)) <= ON_SURFACE * r
    assert np.all(np.einsum("ij,ij->i", n, d) > 0.0)
    assert np.max(np.abs(n - d / dist[:, None])) <= NORMAL_TOL


@pytest.mark.parametrize("spec", torus_specs(), ids=ids(torus_specs()))
def test_torus_points_and_normals(spec):
    rng = np.random.default_rng(11)
    c, a = np.array(spec.center), np.array(spec.axis)
    R, r = spec.major_radius, spec.minor_radius
    p, n = sample(torus(spec).patches[0].surface, rng)
    z, rho, e_rho = local(p, c, a)
    assert np.max(np.abs((rho - R) ** 2 + z**2 - r**2)) <= ON_SURFACE * r**2
    tube_centre = c + R * e_rho
    assert np.all(np.einsum("ij,ij->i", n, p - tube_centre) > 0.0)
    assert np.max(np.abs(n - (p - tube_centre) / r)) <= NORMAL_TOL


@pytest.mark.parametrize("spec", half_torus_specs(), ids=ids(half_torus_specs()))
def test_half_torus_points_and_normals(spec):
    rng = np.random.default_rng(12)
    c, a, keep = np.array(spec.center), np.array(spec.axis), np.array(spec.keep)
    R, r = spec.major_radius, spec.minor_radius
    size = np.linalg.norm(c) + R + r
    solid = half_torus(spec)
    p, n = sample(solid.named("tube")[0].surface, rng)
    z, rho, e_rho = local(p, c, a)
    assert np.max(np.abs((rho - R) ** 2 + z**2 - r**2)) <= ON_SURFACE * r**2
    assert np.all((p - c) @ keep >= -1e-15 * size)
    tube_centre = c + R * e_rho
    assert np.max(np.abs(n - (p - tube_centre) / r)) <= NORMAL_TOL
    s = np.cross(keep, a)
    for name, cap_centre in (("cap_a", c + R * s), ("cap_b", c - R * s)):
        p, n = sample(solid.named(name)[0].surface, rng)
        assert np.max(np.abs((p - c) @ keep)) <= ON_SURFACE * size
        assert np.max(np.linalg.norm(p - cap_centre, axis=1)) <= r * (1 + ON_SURFACE)
        assert np.max(np.abs(n + keep)) <= NORMAL_TOL  # outward: away from the kept half


def check_cylinder_faces(solid, spec, rng, keep=None):
    """``side``, ``bottom`` and ``top`` lie on the cylinder of ``spec`` with outward normals;
    with ``keep`` (3,), every point lies on its side of the axis."""
    c, a, r, h = np.array(spec.center), np.array(spec.axis), spec.radius, spec.height
    size = np.linalg.norm(c) + r + h
    kept = (lambda p: np.all((p - c) @ keep >= -ON_SURFACE * size)) if keep is not None else (lambda p: True)
    p, n = sample(solid.named("side")[0].surface, rng)
    z, rho, e_rho = local(p, c, a)
    assert np.max(np.abs(rho - r)) <= ON_SURFACE * size
    assert np.all(np.abs(z) <= 0.5 * h + ON_SURFACE * size) and kept(p)
    assert np.max(np.abs(n - e_rho)) <= NORMAL_TOL
    for name, sign in (("bottom", -1.0), ("top", 1.0)):
        p, n = sample(solid.named(name)[0].surface, rng)
        z, rho, _ = local(p, c, a)
        assert np.max(np.abs(z - sign * 0.5 * h)) <= ON_SURFACE * size
        assert np.all(rho <= r + ON_SURFACE * size) and kept(p)
        assert np.max(np.abs(n - sign * a)) <= NORMAL_TOL


@pytest.mark.parametrize("spec", cylinder_specs(), ids=ids(cylinder_specs()))
def test_cylinder_points_and_normals(spec):
    check_cylinder_faces(cylinder(spec), spec, np.random.default_rng(13))


@pytest.mark.parametrize("spec", half_cylinder_specs(), ids=ids(half_cylinder_specs()))
def test_half_cylinder_points_and_normals(spec):
    rng = np.random.default_rng(15)
    c, a, keep = np.array(spec.center), np.array(spec.axis), np.array(spec.keep)
    solid = half_cylinder(spec)
    check_cylinder_faces(solid, spec, rng, keep)
    size = np.linalg.norm(c) + spec.radius + spec.height
    p, n = sample(solid.named("flat")[0].surface, rng)
    z, rho, _ = local(p, c, a)
    assert np.max(np.abs((p - c) @ keep)) <= ON_SURFACE * size
    assert np.all((rho <= spec.radius + ON_SURFACE * size) & (np.abs(z) <= 0.5 * spec.height + ON_SURFACE * size))
    assert np.max(np.abs(n + keep)) <= NORMAL_TOL


@pytest.mark.parametrize("spec", box_specs(), ids=ids(box_specs()))
def test_box_points_and_normals(spec):
    rng = np.random.default_rng(14)
    lo, hi = np.array(spec.min), np.array(spec.max)
    size = np.linalg.norm(hi) + np.linalg.norm(lo)
    middle = 0.5 * (lo + hi)
    for patch in box(spec).patches:
        k, side = "xyz".index(patch.name[0]), patch.name[1:]
        plane, sign = (lo[k], -1.0) if side == "min" else (hi[k], 1.0)
        p, n = sample(patch.surface, rng)
        assert np.max(np.abs(p[:, k] - plane)) <= ON_SURFACE * size
        assert np.all((p >= lo - ON_SURFACE * size) & (p <= hi + ON_SURFACE * size))
        assert np.all(n[:, k] * sign == 1.0)
        assert np.all(np.einsum("ij,ij->i", n, p - middle) > 0.0)


# -- area and volume against the closed forms -------------------------------------------
def close(value, exact):
    return abs(value - exact) <= MEASURE * abs(exact)


@pytest.mark.parametrize("spec", sphere_specs(), ids=ids(sphere_specs()))
def test_sphere_measures(spec):
    solid = sphere(spec)
    r = spec.radius
    assert close(volume(solid), 4.0 / 3.0 * math.pi * r**3)
    assert close(areas_by_name(solid)["surface"], 4.0 * math.pi * r**2)


@pytest.mark.parametrize("spec", torus_specs(), ids=ids(torus_specs()))
def test_torus_measures(spec):
    solid = torus(spec)
    R, r = spec.major_radius, spec.minor_radius
    assert close(volume(solid), 2.0 * math.pi**2 * R * r**2)
    assert close(areas_by_name(solid)["surface"], 4.0 * math.pi**2 * R * r)


@pytest.mark.parametrize("spec", half_torus_specs(), ids=ids(half_torus_specs()))
def test_half_torus_measures(spec):
    solid = half_torus(spec)
    R, r = spec.major_radius, spec.minor_radius
    areas = areas_by_name(solid)
    assert close(volume(solid), math.pi**2 * R * r**2)
    assert close(sum(areas.values()), 2.0 * math.pi**2 * R * r + 2.0 * math.pi * r**2)
    assert close(areas["tube"], 2.0 * math.pi**2 * R * r)
    assert close(areas["cap_a"], math.pi * r**2)
    assert close(areas["cap_b"], math.pi * r**2)


@pytest.mark.parametrize("spec", cylinder_specs(), ids=ids(cylinder_specs()))
def test_cylinder_measures(spec):
    solid = cylinder(spec)
    r, h = spec.radius, spec.height
    areas = areas_by_name(solid)
    assert close(volume(solid), math.pi * r**2 * h)
    assert close(areas["side"], 2.0 * math.pi * r * h)
    assert close(areas["bottom"], math.pi * r**2)
    assert close(areas["top"], math.pi * r**2)


@pytest.mark.parametrize("spec", half_cylinder_specs(), ids=ids(half_cylinder_specs()))
def test_half_cylinder_measures(spec):
    solid = half_cylinder(spec)
    r, h = spec.radius, spec.height
    areas = areas_by_name(solid)
    assert close(volume(solid), 0.5 * math.pi * r**2 * h)
    assert close(areas["side"], math.pi * r * h)
    assert close(areas["flat"], 2.0 * r * h)
    assert close(areas["bottom"], 0.5 * math.pi * r**2)
    assert close(areas["top"], 0.5 * math.pi * r**2)


@pytest.mark.parametrize("spec", box_specs(), ids=ids(box_specs()))
def test_box_measures(spec):
    solid = box(spec)
    dx, dy, dz = np.array(spec.max) - np.array(spec.min)
    areas = areas_by_name(solid)
    assert close(volume(solid), dx * dy * dz)
    for name, exact in (("xmin", dy * dz), ("xmax", dy * dz), ("ymin", dx * dz), ("ymax", dx * dz),
                        ("zmin", dx * dy), ("zmax", dx * dy)):
        assert close(areas[name], exact)


@pytest.mark.parametrize("spec", sphere_specs(), ids=ids(sphere_specs()))
def test_sphere_projected_area(spec):
    """``oint |n_x| + |n_y| + |n_z| dA`` of a sphere: twice its shadow on each coordinate
    plane, ``6 pi r^2`` (its patch edges lie where the normal components change sign)."""
    measures = boundary_measures(sphere(spec))
    assert close(measures.projected, 6.0 * math.pi * spec.radius**2)
    assert close(measures.area, 4.0 * math.pi * spec.radius**2)


@pytest.mark.parametrize("spec", box_specs(), ids=ids(box_specs()))
def test_box_projected_area_is_its_area(spec):
    """Every face of an axis-aligned box has one unit normal component."""
    solid = box(spec)
    measures = boundary_measures(solid)
    assert close(measures.projected, measures.area)
    assert measures.area == sum(areas_by_name(solid).values()) and measures.volume == volume(solid)


# -- names, dispatch, watertightness ----------------------------------------------------
ALL = ([("box", s) for s in box_specs()] + [("sphere", s) for s in sphere_specs()]
       + [("cylinder", s) for s in cylinder_specs()] + [("torus", s) for s in torus_specs()]
       + [("half_torus", s) for s in half_torus_specs()]
       + [("half_cylinder", s) for s in half_cylinder_specs()])


@pytest.mark.parametrize("builder, spec", ALL, ids=[f"{b}-{i}" for i, (b, _) in enumerate(ALL)])
def test_patch_names_and_watertight(builder, spec):
    solid = build_solid(spec)
    assert tuple(p.name for p in solid.patches) == PATCH_NAMES[builder]
    assert solid.patch_names == PATCH_NAMES[builder]
    check_watertight(solid)
