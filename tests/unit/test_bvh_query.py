"""Bezier leaves, the BVH, closest points and ray intersections on the exact builders.

References are analytic: the roots of the torus quartic (``numpy.roots``, polished by
Newton), the slab and sphere formulas for rays; the analytic foot points of a torus, a
sphere and a box for closest points.
"""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.geometry.builders import build_solid
from cgfem.geometry.bvh import SurfaceIndex
from cgfem.geometry.query import closest_points, ray_intersections, bernstein_ders
from cgfem.geometry.specs import BoxSpec, CylinderSpec, HalfTorusSpec, SphereSpec, TorusSpec

AXIS = tuple(np.array([1.0, 2.0, 3.0]) / np.linalg.norm([1.0, 2.0, 3.0]))
TORUS = TorusSpec(center=(0.01, -0.02, 0.005), axis=AXIS, major_radius=0.02, minor_radius=0.005)
SPHERE = SphereSpec(center=(0.3, -0.2, 0.1), radius=0.7)
BOX = BoxSpec(min=(-0.5, -0.25, 0.0), max=(0.5, 0.75, 0.4))
CYLINDER = CylinderSpec(center=(0.1, 0.0, -0.1), axis=AXIS, radius=0.3, height=0.8)
HALF_TORUS = HalfTorusSpec(center=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), major_radius=0.02,
                           minor_radius=0.005, keep=(0.0, 1.0, 0.0))
SPECS = {"torus": TORUS, "sphere": SPHERE, "box": BOX, "cylinder": CYLINDER, "half_torus": HALF_TORUS}


@pytest.fixture(scope="module")
def indexes():
    return {name: SurfaceIndex.build(build_solid(spec)) for name, spec in SPECS.items()}


# ----------------------------------------------------------------------------------------
# analytic references
# ----------------------------------------------------------------------------------------
def torus_local(spec: TorusSpec, x):
    """``(rho, z, radial unit vector)`` of points ``x`` (n, 3) about the torus axis."""
    a = np.asarray(spec.axis)
    q = x - np.asarray(spec.center)
    z = q @ a
    radial = q - z[:, None] * a
    rho = np.linalg.norm(radial, axis=1)
    return rho, z, radial / rho[:, None]


def torus_foot(spec: TorusSpec, x):
    """Analytic closest point and distance on the torus (``x`` off the tube's centre circle
    and off the axis)."""
    rho, z, e = torus_local(spec, x)
    R, r = spec.major_radius, spec.minor_radius
    centre = np.asarray(spec.center) + R * e
    to_x = x - centre
    foot = centre + r * to_x / np.linalg.norm(to_x, axis=1)[:, None]
    return foot, np.abs(np.hypot(rho - R, z) - r)


def torus_quartic_roots(spec: TorusSpec, o, d):
    """Real roots of ``(|q|^2 + R^2 - r^2)^2 - 4 R^2 (|q|^2 - (q . a)^2) = 0``,
    ``q = o + t d - c``: ``numpy.roots`` then two Newton steps. Also the smallest distance
    between any two (complex) roots, relative to their size, to spot near-tangent rays."""
    P = np.polynomial.polynomial
    a = np.asarray(spec.axis)
    R, r = spec.major_radius, spec.minor_radius
    q0 = o - np.asarray(spec.center)
    qq = np.array([q0 @ q0, 2.0 * q0 @ d, d @ d])
    A = qq + np.array([R * R - r * r, 0.0, 0.0])
    za = np.array([q0 @ a, d @ a])
    coeffs = P.polysub(P.polymul(A, A), 4.0 * R * R * P.polysub(qq, P.polymul(za, za)))
    roots = np.roots(coeffs[::-1])
    gaps = np.where(np.eye(roots.size, dtype=bool), np.inf, np.abs(roots[:, None] - roots[None, :]))
    real = np.sort(roots[np.abs(roots.imag) <= 1e-7 * np.abs(roots)].real)
    deriv = P.polyder(coeffs)
    for _ in range(2):
        real = real - P.polyval(real, coeffs) / P.polyval(real, deriv)
    return real, gaps.min() / np.abs(roots).max()


def random_rays(rng, lo, hi, n):
    """Origins in the box ``[lo, hi]`` inflated by 20 %, random directions of random length."""
    pad = 0.2 * (hi - lo)
    o = rng.uniform(lo - pad, hi + pad, (n, 3))
    d = rng.normal(size=(n, 3)) * rng.uniform(0.5, 2.0, (n, 1))
    return o, d


# ----------------------------------------------------------------------------------------
# Bernstein kernel and leaves
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("p", [1, 2, 3, 5])
def test_bernstein_derivatives_match_finite_differences(p):
    from math import comb

    x = 0.37
    B = np.empty((3, p + 1))
    bernstein_ders(p, x, 2, B)
    i = np.arange(p + 1)
    exact = lambda y: np.array([comb(p, k) for k in i]) * y ** i * (1 - y) ** (p - i)
    assert np.allclose(B[0], exact(x), atol=1e-15)
    assert B[0].sum() == pytest.approx(1.0, abs=1e-15)
    h = 1e-5
    assert np.allclose(B[1], (exact(x + h) - exact(x - h)) / (2 * h), atol=1e-8)
    assert np.allclose(B[2], (exact(x + h) - 2 * exact(x) + exact(x - h)) / h**2, atol=2e-5)


@pytest.mark.parametrize("name", list(SPECS))
def test_leaves_reproduce_patches_and_boxes_contain_them(indexes, name):
    index = indexes[name]
    solid = build_solid(SPECS[name])
    g = np.linspace(0.0, 1.0, 9)
    s, t = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    for k in range(index.n_leaves):
        u0, u1, v0, v1 = index.leaf_param[k]
        uv = np.column_stack([u0 + s * (u1 - u0), v0 + t * (v1 - v0)])
        exact = solid.patches[index.leaf_patch[k]].surface.evaluate(uv)
        leaf = index.leaf_surface(k).evaluate(uv)
        assert np.abs(leaf - exact).max() <= 1e-14 * index.diagonal
        assert np.all(exact >= index.leaf_lo[k]) and np.all(exact <= index.leaf_hi[k])
    # the leaves tile every patch's domain
    for ip, patch in enumerate(solid.patches):
        (a0, a1), (b0, b1) = patch.surface.domain
        box = index.leaf_param[index.leaf_patch == ip]
        area = np.sum((box[:, 1] - box[:, 0]) * (box[:, 3] - box[:, 2]))
        assert area == pytest.approx((a1 - a0) * (b1 - b0), rel=1e-14)


@pytest.mark.parametrize("name", list(SPECS))
def test_bvh_nodes_nest_and_own_every_leaf_once(indexes, name):
    index = indexes[name]
    owned = []
    for node in range(index.node_lo.shape[0]):
        left, right = index.node_child[node]
        if left < 0:
            start, count = index.node_start[node], index.node_count[node]
            assert 1 <= count
            owned.extend(range(start, start + count))
            assert np.all(index.leaf_lo[start:start + count] >= index.node_lo[node])
            assert np.all(index.leaf_hi[start:start + count] <= index.node_hi[node])
        else:
            for child in (left, right):
                assert np.all(index.node_lo[child] >= index.node_lo[node])
                assert np.all(index.node_hi[child] <= index.node_hi[node])
            assert index.node_count[node] == index.node_count[left] + index.node_count[right]
    assert sorted(owned) == list(range(index.n_leaves))


def test_leaves_are_nearly_flat(indexes):
    index = indexes["torus"]
    solid = build_solid(TORUS)
    worst = 0.0
    g = np.linspace(0.0, 1.0, 5)
    s, t = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    for k in range(index.n_leaves):
        n = index.leaf_surface(k).normals(np.column_stack([
            index.leaf_param[k, 0] + s * (index.leaf_param[k, 1] - index.leaf_param[k, 0]),
            index.leaf_param[k, 2] + t * (index.leaf_param[k, 3] - index.leaf_param[k, 2])]))
        mean = n.sum(axis=0) / np.linalg.norm(n.sum(axis=0))
        worst = max(worst, np.degrees(np.arccos(np.clip(n @ mean, -1, 1))).max())
    assert worst <= 30.0
    # the quarter-circle Bezier pieces are cut at least 2 x 2 times
    assert index.n_leaves >= 4 * 16
    assert solid.patches[0].surface.control.shape == (9, 9, 4)


# ----------------------------------------------------------------------------------------
# rays
# ----------------------------------------------------------------------------------------
@pytest.mark.slow
def test_rays_through_a_rotated_torus_match_the_quartic(indexes):
    index = indexes["torus"]
    rng = np.random.default_rng(11)
    lo, hi = index.bounds
    # half the rays aimed at random points of the tube so that 2 and 4 hits are common
    o, d = random_rays(rng, lo, hi, 1500)
    rho_target = rng.uniform(-1, 1, (750, 3)) * TORUS.minor_radius
    target = np.asarray(TORUS.center) + TORUS.major_radius * np.array([1.0, 0.0, 0.0]) + rho_target
    d[:750] = target - o[:750]
    hits = ray_intersections(index, o, d, t_min=-np.inf)
    counts = hits.count()
    scale = index.diagonal
    checked = skipped = 0
    histogram = np.zeros(5, dtype=int)
    for i in range(o.shape[0]):
        expected, gap = torus_quartic_roots(TORUS, o[i], d[i])
        if gap < 1e-6:  # a near-tangent ray: two roots closer than the reference resolves
            skipped += 1
            continue
        got = hits.t[hits.offsets[i]:hits.offsets[i + 1]]
        assert counts[i] == expected.size, (i, expected, got)
        assert np.all(np.abs(got - expected) <= 1e-9 * (np.abs(expected) + scale / np.linalg.norm(d[i])))
        histogram[counts[i]] += 1
        checked += 1
    assert checked >= 1000 and skipped <= 5
    assert histogram[2] >= 100 and histogram[4] >= 30 and histogram[0] >= 100
    assert histogram[1] == histogram[3] == 0
    # hits lie on the torus, their points are origin + t direction, their uv map to them
    rho, z, _ = torus_local(TORUS, hits.point)
    assert np.abs(np.hypot(rho - TORUS.major_radius, z) - TORUS.minor_radius).max() <= 1e-12 * scale
    along = o[hits.ray] + hits.t[:, None] * d[hits.ray]
    assert np.abs(along - hits.point).max() <= 1e-12 * scale
    surface = build_solid(TORUS).patches[0].surface
    assert np.abs(surface.evaluate(hits.uv) - hits.point).max() <= 1e-14 * scale
    assert np.all(np.diff(hits.t)[np.diff(hits.ray) == 0] > 0)
    # entering hits have the normal against the direction, leaving ones along it
    cos = np.einsum("ij,ij->i", hits.normal, d[hits.ray]) / np.linalg.norm(d[hits.ray], axis=1)
    rank = np.arange(hits.t.size) - hits.offsets[hits.ray]
    assert np.all(cos[rank % 2 == 0] < 0) and np.all(cos[rank % 2 == 1] > 0)


def test_ray_parameter_window(indexes):
    index = indexes["torus"]
    rng = np.random.default_rng(5)
    o, d = random_rays(rng, *index.bounds, 300)
    every = ray_intersections(index, o, d, t_min=-np.inf)
    window = ray_intersections(index, o, d, t_min=-0.3, t_max=0.4)
    keep = (every.t >= -0.3) & (every.t <= 0.4)
    assert np.array_equal(window.ray, every.ray[keep])
    assert np.allclose(window.t, every.t[keep], rtol=0, atol=1e-15)
    forward = ray_intersections(index, o, d)
    assert np.array_equal(forward.ray, every.ray[every.t >= 0.0])


def test_rays_against_a_sphere(indexes):
    index = indexes["sphere"]
    rng = np.random.default_rng(3)
    o, d = random_rays(rng, *index.bounds, 2000)
    hits = ray_intersections(index, o, d, t_min=-np.inf)
    c, r = np.asarray(SPHERE.center), SPHERE.radius
    q = o - c
    A, B, C = np.sum(d * d, 1), 2 * np.sum(q * d, 1), np.sum(q * q, 1) - r * r
    disc = B * B - 4 * A * C
    clear = np.abs(disc) > 1e-8 * B * B + 1e-12  # not grazing
    expected = np.where(disc > 0, 2, 0)
    assert np.array_equal(hits.count()[clear], expected[clear])
    assert np.sum(expected[clear] == 2) > 500 and np.sum(expected[clear] == 0) > 200
    two = clear & (disc > 0)
    root = np.sqrt(np.where(disc > 0, disc, 0.0))
    t_ref = np.column_stack([(-B - root) / (2 * A), (-B + root) / (2 * A)])[two]
    got = np.array([hits.t[hits.offsets[i]:hits.offsets[i + 1]] for i in np.flatnonzero(two)])
    assert np.abs(got - t_ref).max() <= 1e-12 * np.abs(t_ref).max()
    assert np.abs(np.linalg.norm(hits.point - c, axis=1) - r).max() <= 1e-14


def test_rays_against_a_box(indexes):
    index = indexes["box"]
    rng = np.random.default_rng(4)
    o, d = random_rays(rng, *index.bounds, 2000)
    hits = ray_intersections(index, o, d, t_min=-np.inf)
    lo, hi = np.asarray(BOX.min), np.asarray(BOX.max)
    with np.errstate(divide="ignore"):
        a, b = (lo - o) / d, (hi - o) / d
    t0 = np.minimum(a, b).max(axis=1)
    t1 = np.maximum(a, b).min(axis=1)
    expected = np.where(t0 < t1, 2, 0)
    assert np.array_equal(hits.count(), expected)
    assert np.sum(expected == 2) > 500 and np.sum(expected == 0) > 200
    got = hits.t.reshape(-1, 2)
    assert np.allclose(got, np.column_stack([t0, t1])[expected == 2], rtol=1e-13, atol=1e-15)
    names = [p.name for p in build_solid(BOX).patches]
    # the patch of each hit is the face it lies on
    axis = {"x": 0, "y": 1, "z": 2}
    for name, point in zip((names[k] for k in hits.patch), hits.point):
        bound = lo if name.endswith("min") else hi
        assert point[axis[name[0]]] == pytest.approx(bound[axis[name[0]]], abs=1e-15)


def test_rays_through_shared_edges_and_corners_count_once(indexes):
    index = indexes["box"]
    # enters through the edge x = 0.5, y = -0.25 and leaves through the edge x = -0.5, y = 0.75;
    # enters through the corner (0.5, 0.75, 0.4) and leaves through the face z = 0
    o = np.array([[1.5, -1.25, 0.2], [1.5, 1.75, 1.4]])
    d = np.array([[-1.0, 1.0, 0.0], [-1.0, -1.0, -1.0]])
    hits = ray_intersections(index, o, d)
    assert list(hits.count()) == [2, 2]
    assert np.allclose(hits.t, [1.0, 2.0, 1.0, 1.4], rtol=0, atol=1e-14)
    expected = [[0.5, -0.25, 0.2], [-0.5, 0.75, 0.2], [0.5, 0.75, 0.4], [0.1, 0.35, 0.0]]
    assert np.allclose(hits.point, expected, rtol=0, atol=1e-14)


# ----------------------------------------------------------------------------------------
# closest points
# ----------------------------------------------------------------------------------------
@pytest.mark.slow
def test_closest_points_on_a_rotated_torus(indexes):
    index = indexes["torus"]
    rng = np.random.default_rng(7)
    R, r = TORUS.major_radius, TORUS.minor_radius
    a = np.asarray(TORUS.axis)
    e1 = np.cross(a, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    n = 4000
    phi, theta = rng.uniform(0, 2 * np.pi, (2, n))
    # distance from the tube centre circle: 0 < dist < 2 r (within one minor radius of the
    # surface, inside and outside), then farther, up to 20 diagonals
    dist = np.concatenate([rng.uniform(1e-3 * r, 2 * r, n // 2), r + rng.uniform(0, 1, n // 4) * R,
                           r + np.exp(rng.uniform(np.log(R), np.log(20 * index.diagonal), n - n // 2 - n // 4))])
    radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    centre = np.asarray(TORUS.center) + R * radial
    x = centre + dist[:, None] * (np.cos(theta)[:, None] * radial + np.sin(theta)[:, None] * a)
    rho, _, _ = torus_local(TORUS, x)
    x = x[rho > 1e-3 * R]  # the foot is not unique on the axis
    cp = closest_points(index, x)
    foot, exact = torus_foot(TORUS, x)
    scale = R + r
    assert np.abs(cp.distance - exact).max() <= 1e-12 * scale
    assert np.abs(cp.point - foot).max() <= 1e-11 * scale
    # outward normals: along x - foot outside, against it inside
    rho, z, _ = torus_local(TORUS, x)
    outside = np.hypot(rho - R, z) > r
    unit = (x - cp.point) / cp.distance[:, None]
    cos = np.einsum("ij,ij->i", unit, cp.normal)
    assert np.all(cos[outside] > 1 - 1e-9) and np.all(cos[~outside] < -1 + 1e-9)
    surface = build_solid(TORUS).patches[0].surface
    assert np.abs(surface.evaluate(cp.uv) - cp.point).max() <= 1e-14 * scale


def test_closest_points_on_the_tube_centre_circle_and_axis(indexes):
    index = indexes["torus"]
    R, r = TORUS.major_radius, TORUS.minor_radius
    a = np.asarray(TORUS.axis)
    e1 = np.cross(a, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    phi = np.linspace(0, 2 * np.pi, 37)
    on_circle = np.asarray(TORUS.center) + R * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    on_axis = np.asarray(TORUS.center) + np.linspace(-0.1, 0.1, 11)[:, None] * a
    cp = closest_points(index, np.vstack([on_circle, on_axis]))
    expected = np.concatenate([np.full(phi.size, r), np.hypot(R, np.linspace(-0.1, 0.1, 11)) - r])
    assert np.abs(cp.distance - expected).max() <= 1e-12 * (R + r)


def test_closest_points_on_a_sphere(indexes):
    index = indexes["sphere"]
    rng = np.random.default_rng(8)
    c, r = np.asarray(SPHERE.center), SPHERE.radius
    u = rng.normal(size=(3000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    dist = np.concatenate([rng.uniform(0.01, 0.999, 1500), rng.uniform(1.001, 30.0, 1500)]) * r
    poles = np.array([[0, 0, 1.0], [0, 0, -1.0]])
    u = np.vstack([u, poles, poles, poles])
    dist = np.concatenate([dist, [0.5 * r] * 2, [1.5 * r] * 2, [(1 + 1e-9) * r] * 2])
    x = c + dist[:, None] * u
    cp = closest_points(index, x)
    assert np.abs(cp.distance - np.abs(dist - r)).max() <= 1e-12 * r
    assert np.abs(cp.point - (c + r * u)).max() <= 1e-11 * r
    sign = np.where(dist > r, 1.0, -1.0)
    assert np.abs(cp.normal - u).max() <= 1e-9  # including the limit normal at the poles
    assert np.all(np.einsum("ij,ij->i", x - cp.point, cp.normal) * sign > 0)


def test_closest_points_at_box_corners_and_edges(indexes):
    index = indexes["box"]
    lo, hi = np.asarray(BOX.min), np.asarray(BOX.max)
    rng = np.random.default_rng(9)
    # outside: the foot is the clamped point (a corner, an edge or a face point)
    x = rng.uniform(lo - 0.5, hi + 0.5, (4000, 3))
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    x = np.vstack([x, corners, corners + 1e-9 * np.sign(corners - 0.5 * (lo + hi)),
                   corners - 1e-3 * np.sign(corners - 0.5 * (lo + hi))])
    cp = closest_points(index, x)
    clamped = np.clip(x, lo, hi)
    outside = np.any((x < lo) | (x > hi), axis=1)
    inside_dist = np.minimum(x - lo, hi - x).min(axis=1)
    expected = np.where(outside, np.linalg.norm(x - clamped, axis=1), inside_dist)
    assert np.abs(cp.distance - expected).max() <= 1e-15
    assert np.abs(cp.point[outside] - clamped[outside]).max() <= 1e-15
    # the normal is the face's normal x actually faces: positive side outside, negative inside
    side = np.einsum("ij,ij->i", x - cp.point, cp.normal)
    assert np.all(side[outside] > 0) and np.all(side[~outside & (expected > 0)] < 0)
    assert np.any(cp.on_edge)


def test_higher_degree_patches_give_the_same_answers():
    """The torus degree-elevated to (3, 4) with extra knots: same geometry, other leaves."""
    from cgfem.geometry.refine import elevate_degree, refine_knots
    from cgfem.geometry.solid import Patch, Solid

    surface = build_solid(TORUS).patches[0].surface
    surface = refine_knots(elevate_degree(elevate_degree(surface, 0, 1), 1, 2), 0, [0.1, 0.6, 0.6])
    assert surface.degree == (3, 4)
    index = SurfaceIndex.build(Solid((Patch("surface", surface),)))
    assert set(map(tuple, index.leaf_degree)) == {(3, 4)}
    rng = np.random.default_rng(12)
    R, r = TORUS.major_radius, TORUS.minor_radius
    x = np.asarray(TORUS.center) + rng.uniform(-1, 1, (3000, 3)) * (R + 2 * r)
    rho, z, _ = torus_local(TORUS, x)
    x = x[(rho > 1e-2 * R) & (np.abs(np.hypot(rho - R, z)) > 1e-2 * r)]
    cp = closest_points(index, x)
    foot, exact = torus_foot(TORUS, x)
    assert np.abs(cp.distance - exact).max() <= 1e-12 * (R + r)
    assert np.abs(cp.point - foot).max() <= 1e-11 * (R + r)
    o, d = random_rays(rng, *index.bounds, 300)
    hits = ray_intersections(index, o, d, t_min=-np.inf)
    for i in range(o.shape[0]):
        expected, gap = torus_quartic_roots(TORUS, o[i], d[i])
        if gap > 1e-6:
            got = hits.t[hits.offsets[i]:hits.offsets[i + 1]]
            assert got.size == expected.size
            scale = np.abs(expected) + index.diagonal / np.linalg.norm(d[i])
            assert np.all(np.abs(got - expected) <= 1e-9 * scale)
