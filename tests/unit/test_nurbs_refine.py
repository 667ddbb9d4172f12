"""Exact refinement of NURBS surfaces: knot insertion, knot refinement, degree elevation,
Bezier decomposition and splitting leave the geometry unchanged.

Random rational surfaces and a rational-quadratic torus (tensor product of two 9-point
circles) are refined and re-evaluated at random points; control nets are compared with
geomdl where geomdl implements the operation.
"""

from __future__ import annotations

from math import sqrt

import numpy as np
import pytest

from cgfem.errors import InputError
from cgfem.geometry.nurbs import NurbsSurface
from tests.support.nurbs_helpers import geomdl_surface
from cgfem.geometry.refine import (
    bezier_patches,
    curve_elevate_degree,
    curve_insert_knot,
    curve_refine_knots,
    curve_split,
    elevate_degree,
    insert_knot,
    refine_knots,
    split,
)

TOL = 1e-13  # on unit-sized geometry


# ----------------------------------------------------------------------------------------
# surfaces
# ----------------------------------------------------------------------------------------
def random_knots(rng, p: int, n_interior: int) -> np.ndarray:
    """Clamped knot vector on [0, 1] of degree ``p``; one interior knot may be repeated."""
    breaks = np.sort(rng.uniform(0.05, 0.95, n_interior))
    mult = np.ones(n_interior, dtype=int)
    if n_interior and p > 1 and rng.random() < 0.5:
        mult[rng.integers(n_interior)] = rng.integers(2, p + 1)
    return np.concatenate([np.zeros(p + 1), np.repeat(breaks, mult), np.ones(p + 1)])


def random_surface(rng, p: int, q: int) -> NurbsSurface:
    ku = random_knots(rng, p, int(rng.integers(0, 4)))
    kv = random_knots(rng, q, int(rng.integers(0, 4)))
    n_u, n_v = ku.size - p - 1, kv.size - q - 1
    return NurbsSurface.from_points((p, q), ku, kv, rng.uniform(-1.0, 1.0, (n_u, n_v, 3)),
                                    rng.uniform(0.5, 1.5, (n_u, n_v)))


def random_surfaces(seed: int, count: int = 16):
    rng = np.random.default_rng(seed)
    return [random_surface(rng, int(rng.integers(1, 5)), int(rng.integers(1, 5))) for _ in range(count)]


CIRCLE_KNOTS = np.array([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1], dtype=float)


def circle_net() -> np.ndarray:
    """Homogeneous net (9, 3) ``(w cos, w sin, w)`` of the unit circle: 9 points, degree 2,
    weights 1 and sqrt(2)/2 alternating (The NURBS Book, Ex. 7.2)."""
    xy = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1], [1, 0]], float)
    w = np.where(np.arange(9) % 2 == 0, 1.0, sqrt(2.0) / 2.0)
    return np.column_stack([xy * w[:, None], w])


def torus(R: float = 1.0, r: float = 0.4) -> NurbsSurface:
    """x = (R + r cos v) cos u, y = (R + r cos v) sin u, z = r sin v, u, v in [0, 1] (one
    turn each), as the homogeneous product of two rational circles."""
    cu, cv = circle_net(), circle_net()
    Au, Bu, Wu = (cu[:, k][:, None] for k in range(3))  # (9, 1): rows along u
    Av, Bv, Wv = (cv[:, k][None, :] for k in range(3))  # (1, 9): columns along v
    radial = R * Wv + r * Av  # homogeneous R + r cos v
    control = np.stack([radial * Au, radial * Bu, r * Bv * Wu, Wu * Wv], axis=-1)
    return NurbsSurface((2, 2), CIRCLE_KNOTS, CIRCLE_KNOTS, control)


def sample(rng, surface: NurbsSurface, count: int = 200) -> np.ndarray:
    """Random parameters (count, 2) in the domain, including the four corners."""
    (u0, u1), (v0, v1) = surface.domain
    uv = np.column_stack([rng.uniform(u0, u1, count), rng.uniform(v0, v1, count)])
    uv[:4] = [[u0, v0], [u1, v0], [u0, v1], [u1, v1]]
    return uv


def assert_same_surface(a: NurbsSurface, b: NurbsSurface, rng, count: int = 200, tol: float = TOL):
    """``a`` and ``b`` agree at ``count`` random points of the domain of ``a``."""
    uv = sample(rng, a, count)
    np.testing.assert_allclose(a.evaluate(uv), b.evaluate(uv), rtol=0, atol=tol)


def multiplicities(knots: np.ndarray) -> dict[float, int]:
    values, counts = np.unique(knots, return_counts=True)
    return dict(zip(values.tolist(), counts.tolist()))


# ----------------------------------------------------------------------------------------
# the torus fixture itself
# ----------------------------------------------------------------------------------------
def test_torus_is_a_torus():
    rng = np.random.default_rng(0)
    R, r = 1.0, 0.4
    x = torus(R, r).evaluate(sample(rng, torus(R, r), 500))
    rho = np.hypot(x[:, 0], x[:, 1])
    np.testing.assert_allclose((rho - R) ** 2 + x[:, 2] ** 2, r ** 2, rtol=0, atol=1e-14)


# ----------------------------------------------------------------------------------------
# knot insertion
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("direction", [0, 1])
def test_insert_new_knot_once_and_repeatedly(direction):
    rng = np.random.default_rng(1 + direction)
    for S in random_surfaces(10 + direction) + [torus()]:
        deg = S.degree[direction]
        knots = (S.knots_u, S.knots_v)[direction]
        u = float(rng.uniform(0.1, 0.9))
        assert u not in knots
        for times in range(1, deg + 1):
            T = insert_knot(S, direction, u, times)
            new_knots = (T.knots_u, T.knots_v)[direction]
            assert multiplicities(new_knots)[u] == times
            np.testing.assert_array_equal(np.sort(np.concatenate([knots, np.full(times, u)])), new_knots)
            expected_shape = list(S.control.shape)
            expected_shape[direction] += times
            assert T.control.shape == tuple(expected_shape)
            assert T.degree == S.degree
            # the other direction is untouched
            np.testing.assert_array_equal((T.knots_v, T.knots_u)[direction], (S.knots_v, S.knots_u)[direction])
            assert_same_surface(S, T, rng)


@pytest.mark.parametrize("direction", [0, 1])
def test_insert_existing_knot(direction):
    rng = np.random.default_rng(3)
    done = 0
    for S in random_surfaces(20 + direction, 24) + [torus()]:
        deg = S.degree[direction]
        knots = (S.knots_u, S.knots_v)[direction]
        mult = multiplicities(knots[deg + 1: -deg - 1])
        for u, s in mult.items():
            if s < deg:
                T = insert_knot(S, direction, u, deg - s)
                assert multiplicities((T.knots_u, T.knots_v)[direction])[u] == deg
                assert T.control.shape[direction] == S.control.shape[direction] + deg - s
                assert_same_surface(S, T, rng)
                done += 1
    assert done >= 5


def test_insert_knot_rejects_bad_arguments():
    S = torus()  # degree 2, knots 0.25, 0.5, 0.75 with multiplicity 2
    with pytest.raises(InputError) as info:
        insert_knot(S, 0, 0.5)
    assert info.value.field == "times"
    with pytest.raises(InputError) as info:
        insert_knot(S, 1, 0.3, 3)
    assert info.value.field == "times"
    for bad in (0.0, 1.0, -0.1, 1.5, float("nan")):
        with pytest.raises(InputError) as info:
            insert_knot(S, 0, bad)
        assert info.value.field == "knot"
    with pytest.raises(InputError) as info:
        insert_knot(S, 2, 0.3)
    assert info.value.field == "direction"
    with pytest.raises(InputError) as info:
        insert_knot(S, 0, 0.3, -1)
    assert info.value.field == "times"


def test_insert_knot_returns_new_object_and_leaves_input_alone():
    S = torus()
    before = S.control.copy()
    T = insert_knot(S, 0, 0.3)
    assert T is not S
    np.testing.assert_array_equal(S.control, before)
    assert S.control.shape == (9, 9, 4)
    assert insert_knot(S, 0, 0.3, 0).control.shape == (9, 9, 4)


# ----------------------------------------------------------------------------------------
# knot refinement
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("direction", [0, 1])
def test_refine_knots(direction):
    rng = np.random.default_rng(4 + direction)
    for S in random_surfaces(30 + direction) + [torus()]:
        deg = S.degree[direction]
        knots = (S.knots_u, S.knots_v)[direction]
        new = list(rng.uniform(0.01, 0.99, 5))
        new += [new[0]] * (deg - 1)  # a new knot repeated up to the degree
        interior = multiplicities(knots[deg + 1: -deg - 1])
        new += [u for u, s in interior.items() if s < deg]  # existing knots once more
        rng.shuffle(new)
        T = refine_knots(S, direction, new)
        np.testing.assert_array_equal((T.knots_u, T.knots_v)[direction], np.sort(np.concatenate([knots, new])))
        assert T.control.shape[direction] == S.control.shape[direction] + len(new)
        assert T.control.shape[1 - direction] == S.control.shape[1 - direction]
        assert_same_surface(S, T, rng)
        # same net as inserting one knot after the other
        R = S
        for u in new:
            R = insert_knot(R, direction, u)
        np.testing.assert_allclose(T.control, R.control, rtol=0, atol=TOL)


def test_refine_knots_uniform_subdivision_of_torus():
    rng = np.random.default_rng(6)
    S = torus()
    mids = np.arange(1, 8) / 8
    T = refine_knots(refine_knots(S, 0, mids[mids != 0.25 * np.round(mids * 4)]), 1, [0.125, 0.875])
    assert T.control.shape == (13, 11, 4)
    assert_same_surface(S, T, rng, 400)


def test_refine_knots_rejects_bad_knots():
    S = torus()
    with pytest.raises(InputError) as info:
        refine_knots(S, 0, [0.3, 0.5])  # 0.5 already has multiplicity 2 = degree
    assert info.value.field == "new_knots"
    with pytest.raises(InputError) as info:
        refine_knots(S, 1, [0.3, 0.3, 0.3])
    assert info.value.field == "new_knots"
    with pytest.raises(InputError) as info:
        refine_knots(S, 1, [0.3, 1.0])
    assert info.value.field == "new_knots"
    assert refine_knots(S, 0, []).control.shape == S.control.shape


# ----------------------------------------------------------------------------------------
# degree elevation
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("direction", [0, 1])
@pytest.mark.parametrize("times", [1, 2])
def test_elevate_degree(direction, times):
    rng = np.random.default_rng(7 + 2 * direction + times)
    for S in random_surfaces(40 + 2 * direction + times) + [torus()]:
        T = elevate_degree(S, direction, times)
        deg = S.degree[direction]
        expected_degree = list(S.degree)
        expected_degree[direction] += times
        assert T.degree == tuple(expected_degree)
        before = multiplicities((S.knots_u, S.knots_v)[direction])
        after = multiplicities((T.knots_u, T.knots_v)[direction])
        assert after == {u: s + times for u, s in before.items()}
        n_spans = len(before) - 1
        assert T.control.shape[direction] == S.control.shape[direction] + times * n_spans
        np.testing.assert_array_equal((T.knots_v, T.knots_u)[direction], (S.knots_v, S.knots_u)[direction])
        assert_same_surface(S, T, rng)
        # the end control points are kept (clamped ends interpolate)
        first = (T.control[0], T.control[:, 0])[direction]
        np.testing.assert_allclose(first, (S.control[0], S.control[:, 0])[direction], rtol=0, atol=TOL)
        assert deg + times == T.degree[direction]


def test_elevate_both_directions_of_torus_and_derivatives():
    rng = np.random.default_rng(9)
    S = torus()
    T = elevate_degree(elevate_degree(S, 0, 1), 1, 2)
    assert T.degree == (3, 4)
    assert T.control.shape == (9 + 4, 9 + 8, 4)
    uv = sample(rng, S)
    np.testing.assert_allclose(T.derivatives(uv, 2), S.derivatives(uv, 2), rtol=0, atol=1e-11)


def test_elevate_degree_zero_times_and_rejects_negative():
    S = torus()
    assert elevate_degree(S, 1, 0).degree == (2, 2)
    with pytest.raises(InputError) as info:
        elevate_degree(S, 0, -1)
    assert info.value.field == "times"


# ----------------------------------------------------------------------------------------
# Bezier pieces and splitting
# ----------------------------------------------------------------------------------------
def test_bezier_patches_reproduce_the_surface():
    rng = np.random.default_rng(10)
    for S in random_surfaces(50) + [torus()]:
        p, q = S.degree
        breaks_u, breaks_v = S.breaks()
        pieces = bezier_patches(S)
        assert len(pieces) == (breaks_u.size - 1) * (breaks_v.size - 1)
        for piece, (u0, u1), (v0, v1) in pieces:
            assert piece.degree == (p, q)
            assert piece.control.shape == (p + 1, q + 1, 4)
            np.testing.assert_array_equal(piece.knots_u, [u0] * (p + 1) + [u1] * (p + 1))
            np.testing.assert_array_equal(piece.knots_v, [v0] * (q + 1) + [v1] * (q + 1))
            uv = sample(rng, piece, 50)
            np.testing.assert_allclose(piece.evaluate(uv), S.evaluate(uv), rtol=0, atol=TOL)
        spans = {(a, b) for _, (a, b), _ in pieces}
        assert sorted(spans) == list(zip(breaks_u[:-1], breaks_u[1:]))


def test_torus_has_sixteen_bezier_pieces():
    pieces = bezier_patches(torus())
    assert len(pieces) == 16
    assert pieces[0][1:] == ((0.0, 0.25), (0.0, 0.25))
    assert pieces[-1][1:] == ((0.75, 1.0), (0.75, 1.0))


@pytest.mark.parametrize("direction", [0, 1])
def test_split(direction):
    rng = np.random.default_rng(11 + direction)
    for S in random_surfaces(60 + direction) + [torus()]:
        deg = S.degree[direction]
        knots = (S.knots_u, S.knots_v)[direction]
        existing = knots[deg + 1: -deg - 1]
        cuts = [float(rng.uniform(0.1, 0.9))] + ([float(existing[0])] if existing.size else [])
        for cut in cuts:
            left, right = split(S, direction, cut)
            assert left.domain[direction] == (knots[0], cut)
            assert right.domain[direction] == (cut, knots[-1])
            for piece in (left, right):
                assert_same_surface(piece, S, rng, 100)  # sampled on the piece
                assert multiplicities((piece.knots_u, piece.knots_v)[direction])[cut] == deg + 1
            # the seam is shared: last row of the left net equals the first row of the right
            seam_l = (left.control[-1], left.control[:, -1])[direction]
            seam_r = (right.control[0], right.control[:, 0])[direction]
            np.testing.assert_array_equal(seam_l, seam_r)
            total = left.control.shape[direction] + right.control.shape[direction] - 1
            s = multiplicities(knots).get(cut, 0)
            assert total == S.control.shape[direction] + deg - s


def test_split_bezier_piece_gives_bezier_pieces():
    rng = np.random.default_rng(13)
    piece, (u0, u1), (v0, v1) = bezier_patches(torus())[5]
    a, b = split(piece, 0, 0.5 * (u0 + u1))
    c, d = split(a, 1, 0.3 * v0 + 0.7 * v1)
    for part in (a, b, c, d):
        assert part.control.shape == (3, 3, 4)
        assert_same_surface(part, piece, rng, 100)


def test_split_rejects_domain_ends():
    S = torus()
    for bad in (0.0, 1.0):
        with pytest.raises(InputError) as info:
            split(S, 1, bad)
        assert info.value.field == "knot"


# ----------------------------------------------------------------------------------------
# curve functions on arbitrary trailing shapes
# ----------------------------------------------------------------------------------------
def test_curve_functions_on_planar_circle():
    """The 9-point circle as a (9, 3) homogeneous 2-D curve net stays on the unit circle."""
    Pw = circle_net()
    U = CIRCLE_KNOTS

    def on_circle(p, knots, net, params):
        from cgfem.geometry._nurbs_kernels import basis_funs, find_span
        n = net.shape[0] - 1
        for u in params:
            span = find_span(n, p, u, knots)
            N = np.empty(p + 1)
            basis_funs(span, u, p, knots, N)
            cw = N @ net[span - p: span + 1]
            assert abs(np.hypot(cw[0] / cw[2], cw[1] / cw[2]) - 1.0) < 1e-15

    params = np.linspace(0.0, 1.0, 101)
    on_circle(2, *curve_insert_knot(2, U, Pw, 0.1, 2), params)
    on_circle(2, *curve_refine_knots(2, U, Pw, [0.1, 0.6, 0.6, 0.9]), params)
    on_circle(5, *curve_elevate_degree(2, U, Pw, 3), params)
    (UL, QL), (UR, QR) = curve_split(2, U, Pw, 0.4)
    on_circle(2, UL, QL, np.linspace(0.0, 0.4, 21))
    on_circle(2, UR, QR, np.linspace(0.4, 1.0, 21))


def test_elevate_bezier_curve_by_formula():
    """Degree elevation of a single Bezier segment is Eq. (5.36); checked on a line, whose
    elevated control points are equally spaced."""
    Pw = np.array([[0.0, 1.0], [3.0, 1.0]])  # x(u) = 3u, weight 1
    Uh, Qw = curve_elevate_degree(1, [0, 0, 1, 1], Pw, 2)
    np.testing.assert_array_equal(Uh, [0, 0, 0, 0, 1, 1, 1, 1])
    np.testing.assert_allclose(Qw[:, 0], [0, 1, 2, 3], rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------------------
# geomdl cross-checks
# ----------------------------------------------------------------------------------------
def test_insert_knot_matches_geomdl():
    pytest.importorskip("geomdl")
    from geomdl import operations

    rng = np.random.default_rng(14)
    for S in random_surfaces(70, 20) + [torus()]:
        p, q = S.degree
        u, v = (float(x) for x in rng.uniform(0.1, 0.9, 2))
        ru, rv = int(rng.integers(1, p + 1)), int(rng.integers(1, q + 1))
        g = geomdl_surface(S)
        operations.insert_knot(g, [u, v], [ru, rv])
        T = insert_knot(insert_knot(S, 0, u, ru), 1, v, rv)
        np.testing.assert_allclose(np.array(g.knotvector_u), T.knots_u, rtol=0, atol=0)
        np.testing.assert_allclose(np.array(g.knotvector_v), T.knots_v, rtol=0, atol=0)
        np.testing.assert_allclose(np.array(g.ctrlptsw), T.control.reshape(-1, 4), rtol=0, atol=TOL)


def test_bezier_patches_match_geomdl_decomposition():
    pytest.importorskip("geomdl")
    from geomdl import operations

    for S in random_surfaces(80, 12) + [torus()]:
        ours = bezier_patches(S)
        theirs = operations.decompose_surface(geomdl_surface(S))  # u outer, v inner
        assert len(ours) == len(theirs)
        for (piece, _, _), g in zip(ours, theirs):
            np.testing.assert_allclose(np.array(g.ctrlptsw), piece.control.reshape(-1, 4), rtol=0, atol=TOL)


def test_split_matches_geomdl():
    pytest.importorskip("geomdl")
    from geomdl import operations

    rng = np.random.default_rng(15)
    for S in random_surfaces(90, 12):
        for direction, geomdl_split in ((0, operations.split_surface_u), (1, operations.split_surface_v)):
            cut = float(rng.uniform(0.1, 0.9))
            ours = split(S, direction, cut)
            theirs = geomdl_split(geomdl_surface(S), cut)
            for a, g in zip(ours, theirs):
                np.testing.assert_allclose(np.array(g.ctrlptsw), a.control.reshape(-1, 4), rtol=0, atol=TOL)


def test_elevate_degree_matches_geomdl_bezier_elevation():
    """geomdl elevates only Bezier nets (helpers.degree_elevation, Eq. 5.36; its surface
    degree elevation is a no-op in 5.4). By uniqueness of the Bezier form, the Bezier pieces
    of our elevated surface must equal geomdl's elevation of the original Bezier pieces."""
    pytest.importorskip("geomdl")
    from geomdl import helpers

    for S in random_surfaces(100, 12) + [torus()]:
        p, q = S.degree
        for direction, times in ((0, 1), (1, 2)):
            ours = bezier_patches(elevate_degree(S, direction, times))
            original = bezier_patches(S)
            assert len(ours) == len(original)
            for (mine, _, _), (piece, _, _) in zip(ours, original):
                net = piece.control if direction == 0 else piece.control.transpose(1, 0, 2)
                deg = (p, q)[direction]
                rows = [helpers.degree_elevation(deg, net[:, j].tolist(), num=times) for j in range(net.shape[1])]
                expected = np.array(rows).transpose(1, 0, 2)  # (deg + times + 1, m, 4)
                if direction == 1:
                    expected = expected.transpose(1, 0, 2)
                np.testing.assert_allclose(mine.control, expected, rtol=0, atol=TOL)
