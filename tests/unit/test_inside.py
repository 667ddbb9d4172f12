"""Point-in-solid classification against the analytic solids.

Random points in the (10 % inflated) bounding box, points 1e-9 off the surface along the
normal on both sides, and points 1e-9 away from the sharp and the collapsed features (box
edges and corners, rims of the half-torus caps, sphere poles, disc centres). Only points
closer to the surface than ``INSIDE_TOL`` times the diagonal may disagree with the analytic
test (there are none among these).
"""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.geometry.builders import build_solid, orthonormal_frame
from cgfem.geometry.bvh import SurfaceIndex
from cgfem.geometry.inside import INSIDE_TOL, points_inside
from cgfem.geometry.specs import BoxSpec, CylinderSpec, HalfTorusSpec, SphereSpec, TorusSpec

AXIS = np.array([1.0, 2.0, 3.0]) / np.linalg.norm([1.0, 2.0, 3.0])
KEEP = np.cross(AXIS, [0.0, 0.0, 1.0]) / np.linalg.norm(np.cross(AXIS, [0.0, 0.0, 1.0]))
SPECS = {
    "torus": TorusSpec(center=(0.01, -0.02, 0.005), axis=tuple(AXIS), major_radius=0.02, minor_radius=0.005),
    "half_torus": HalfTorusSpec(center=(0.0, 0.03, 0.0), axis=tuple(AXIS), major_radius=0.02,
                                minor_radius=0.005, keep=tuple(KEEP)),
    "sphere": SphereSpec(center=(0.3, -0.2, 0.1), radius=0.7),
    "box": BoxSpec(min=(-0.5, -0.25, 0.0), max=(0.5, 0.75, 0.4)),
    "cylinder": CylinderSpec(center=(0.1, 0.0, -0.1), axis=tuple(AXIS), radius=0.3, height=0.8),
}
OFFSET = 1e-9


@pytest.fixture(scope="module")
def indexes():
    return {name: SurfaceIndex.build(build_solid(spec)) for name, spec in SPECS.items()}


def signed_level(spec, x) -> np.ndarray:
    """Negative inside, positive outside; its magnitude is at most the distance to the
    surface (exact for the torus, sphere and cylinder side, a lower bound near edges)."""
    x = np.asarray(x, float)
    if isinstance(spec, BoxSpec):
        lo, hi = np.asarray(spec.min), np.asarray(spec.max)
        outside = np.linalg.norm(x - np.clip(x, lo, hi), axis=1)
        inside = np.minimum(x - lo, hi - x).min(axis=1)
        return np.where(outside > 0, outside, -inside)
    if isinstance(spec, SphereSpec):
        return np.linalg.norm(x - np.asarray(spec.center), axis=1) - spec.radius
    a = np.asarray(spec.axis)
    q = x - np.asarray(spec.center)
    z = q @ a
    rho = np.linalg.norm(q - z[:, None] * a, axis=1)
    if isinstance(spec, CylinderSpec):
        side, cap = rho - spec.radius, np.abs(z) - 0.5 * spec.height
        corner = np.hypot(np.maximum(side, 0), np.maximum(cap, 0))
        return np.where((side > 0) & (cap > 0), corner, np.maximum(side, cap))
    tube = np.hypot(rho - spec.major_radius, z) - spec.minor_radius
    if isinstance(spec, HalfTorusSpec):
        return np.maximum(tube, -(q @ np.asarray(spec.keep)))
    return tube


def check(index, spec, x, expect_outside=None):
    """Classify ``x``; everything farther than the tolerance from the surface must agree
    with the analytic test. Returns the number of points checked."""
    level = signed_level(spec, x)
    got = points_inside(index, x)
    decided = np.abs(level) > INSIDE_TOL * index.diagonal
    assert np.array_equal(got[decided], level[decided] < 0), np.flatnonzero(got[decided] != (level[decided] < 0))
    if expect_outside is not None:
        assert np.array_equal(got, ~expect_outside)
    return int(decided.sum())


@pytest.mark.parametrize("name", list(SPECS))
def test_random_points_in_the_bounding_box(indexes, name):
    index, spec = indexes[name], SPECS[name]
    rng = np.random.default_rng(list(SPECS).index(name))
    lo, hi = index.bounds
    pad = 0.1 * (hi - lo)
    x = rng.uniform(lo - pad, hi + pad, (100_000, 3))
    assert check(index, spec, x) == x.shape[0]
    inside = points_inside(index, x)
    assert 0.02 < inside.mean() < 0.9


@pytest.mark.parametrize("name", list(SPECS))
def test_points_a_nanometre_off_the_surface(indexes, name):
    index, spec = indexes[name], SPECS[name]
    solid = build_solid(spec)
    rng = np.random.default_rng(len(name))
    points, normals = [], []
    for patch in solid.patches:
        (u0, u1), (v0, v1) = patch.surface.domain
        uv = np.column_stack([rng.uniform(u0, u1, 3000), rng.uniform(v0, v1, 3000)])
        points.append(patch.surface.evaluate(uv))
        normals.append(patch.surface.normals(uv))
    p, n = np.vstack(points), np.vstack(normals)
    out, inn = p + OFFSET * n, p - OFFSET * n
    # away from edges the offsets land where the normal says
    clear_out = signed_level(spec, out) > 0.5 * OFFSET
    clear_in = signed_level(spec, inn) < -0.5 * OFFSET
    assert clear_out.mean() > 0.99 and clear_in.mean() > 0.99
    assert check(index, spec, out) == out.shape[0]
    assert check(index, spec, inn) == inn.shape[0]
    assert not np.any(points_inside(index, out[clear_out]))
    assert np.all(points_inside(index, inn[clear_in]))


def around(points, directions):
    """Every point offset by ``OFFSET`` along every (normalised) direction, both ways."""
    d = np.asarray(directions, float)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return (np.asarray(points)[:, None, :] + OFFSET * np.concatenate([d, -d])[None]).reshape(-1, 3)


def test_box_edges_and_corners(indexes):
    spec = SPECS["box"]
    lo, hi = np.asarray(spec.min), np.asarray(spec.max)
    rng = np.random.default_rng(1)
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    edges = []
    for axis in range(3):
        for corner in corners:
            if corner[axis] == lo[axis]:
                t = rng.uniform(0, 1, 5)
                e = np.repeat(corner[None], 5, axis=0)
                e[:, axis] = lo[axis] + t * (hi[axis] - lo[axis])
                edges.append(e)
    features = np.vstack([corners] + edges)
    directions = np.vstack([np.eye(3), [[1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 1, 1], [1, -1, 0], [1, 1, -1]],
                            rng.normal(size=(20, 3))])
    x = around(features, directions)
    assert check(indexes["box"], spec, x) >= 0.85 * x.shape[0]


def test_half_torus_cap_rims_and_centres(indexes):
    spec = SPECS["half_torus"]
    keep, a = np.asarray(spec.keep), np.asarray(spec.axis)
    s = np.cross(keep, a)
    c, R, r = np.asarray(spec.center), spec.major_radius, spec.minor_radius
    theta = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    rng = np.random.default_rng(2)
    x = []
    for side in (1.0, -1.0):
        centre = c + side * R * s
        radial = np.cos(theta)[:, None] * s + np.sin(theta)[:, None] * a
        rim = centre + r * radial
        for point, tube_normal in zip(rim, radial):
            directions = np.vstack([-keep, tube_normal, tube_normal - keep, tube_normal - 0.2 * keep,
                                    0.2 * tube_normal - keep, rng.normal(size=(6, 3))])
            x.append(around(point[None], directions))
        x.append(around(centre[None], np.vstack([keep, rng.normal(size=(6, 3))])))
        x.append(around(centre[None] + 1e-7 * s, np.vstack([keep])))
    x = np.vstack(x)
    assert check(indexes["half_torus"], spec, x) >= 0.9 * x.shape[0]


def test_cylinder_rims(indexes):
    spec = SPECS["cylinder"]
    a = np.asarray(spec.axis)
    e1, e2, _ = orthonormal_frame(a)
    theta = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    radial = np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2
    rng = np.random.default_rng(3)
    x = []
    for side in (1.0, -1.0):
        rim = np.asarray(spec.center) + side * 0.5 * spec.height * a + spec.radius * radial
        for point, n_side in zip(rim, radial):
            n_cap = side * a
            x.append(around(point[None], np.vstack([n_cap, n_side, n_cap + n_side, n_cap + 0.1 * n_side,
                                                    0.1 * n_cap + n_side, rng.normal(size=(4, 3))])))
    x = np.vstack(x)
    assert check(indexes["cylinder"], spec, x) >= 0.85 * x.shape[0]


def test_sphere_poles_and_disc_centres(indexes):
    sphere = SPECS["sphere"]
    c, r = np.asarray(sphere.center), sphere.radius
    poles = c + r * np.array([[0, 0, 1.0], [0, 0, -1.0]])
    x = around(poles, [[0, 0, 1.0], [0.3, 0, 1.0], [0, -0.2, 1.0]])
    expect_outside = signed_level(sphere, x) > 0
    assert check(indexes["sphere"], sphere, x, expect_outside) == x.shape[0]
    cyl = SPECS["cylinder"]
    a = np.asarray(cyl.axis)
    centres = np.asarray(cyl.center) + 0.5 * cyl.height * np.array([a, -a])
    e1, e2, _ = orthonormal_frame(a)
    x = around(centres, [a, a + 0.1 * e1, a - 0.3 * e2])
    x = np.vstack([x, around(centres + 1e-8 * e1, [a])])
    assert check(indexes["cylinder"], cyl, x) == x.shape[0]


def test_torus_inner_equator_and_far_points(indexes):
    spec = SPECS["torus"]
    a = np.asarray(spec.axis)
    e1, e2, _ = orthonormal_frame(a)
    phi = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    inner = np.asarray(spec.center) + (spec.major_radius - spec.minor_radius) * radial
    x = (inner[:, None, :] + OFFSET * np.stack([radial, -radial], axis=1)).reshape(-1, 3)
    expect_outside = np.tile([False, True], phi.size)
    assert check(indexes["torus"], spec, x, expect_outside) == x.shape[0]
    far = np.asarray(spec.center) + np.array([[1.0, 0, 0], [0, -3.0, 0], [0, 0, 100.0]])
    assert not np.any(points_inside(indexes["torus"], far))
    assert np.all(points_inside(indexes["torus"], np.asarray(spec.center) + spec.major_radius * radial))


def test_accepts_a_solid():
    spec = SPECS["sphere"]
    x = np.array([spec.center, np.asarray(spec.center) + [0, 0, 0.71]])
    assert list(points_inside(build_solid(spec), x)) == [True, False]
