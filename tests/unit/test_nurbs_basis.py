"""NURBS basis functions, rational surface evaluation and NurbsSurface validation.

Checks the kernels of :mod:`cgfem.geometry._nurbs_kernels` against the printed examples of
*The NURBS Book*, against mathematical properties (partition of unity, finite differences)
and against geomdl as an independent implementation.
"""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.errors import InputError
from cgfem.geometry import _nurbs_kernels as K
from cgfem.geometry.nurbs import NurbsSurface
from tests.support.nurbs_helpers import geomdl_surface


# ----------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------
def random_knots(rng, p: int, n_interior: int, unit_spans: bool = False, repeat: bool = True):
    """Clamped knot vector of degree ``p`` with ``n_interior`` interior knots (one of them
    possibly repeated up to ``p`` times when ``repeat``). ``unit_spans``: spans of length
    0.5 to 1.5 (well-conditioned finite differences); else the domain is [0, 1]."""
    if unit_spans:
        breaks = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 1.5, n_interior + 1))])
    else:
        breaks = np.concatenate([[0.0], np.sort(rng.uniform(0.02, 0.98, n_interior)), [1.0]])
    mult = np.ones(n_interior, dtype=int)
    if repeat and n_interior and p > 1 and rng.random() < 0.5:
        mult[rng.integers(n_interior)] = rng.integers(2, p + 1)
    inner = np.repeat(breaks[1:-1], mult)
    return np.concatenate([np.full(p + 1, breaks[0]), inner, np.full(p + 1, breaks[-1])])


def random_surface(rng, p: int, q: int, unit_spans: bool = False, rational: bool = True) -> NurbsSurface:
    ku = random_knots(rng, p, int(rng.integers(0, 4)), unit_spans)
    kv = random_knots(rng, q, int(rng.integers(0, 4)), unit_spans)
    n_u, n_v = ku.size - p - 1, kv.size - q - 1
    points = rng.uniform(-1.0, 1.0, (n_u, n_v, 3))
    weights = rng.uniform(0.5, 1.5, (n_u, n_v)) if rational else None
    return NurbsSurface.from_points((p, q), ku, kv, points, weights)


def global_basis_ders(p: int, U: np.ndarray, u: float, d: int) -> np.ndarray:
    """All basis functions and their derivatives up to ``d`` at ``u``: (d + 1, n + 1)."""
    n = U.size - p - 2
    span = K.find_span(n, p, u, U)
    ders = np.empty((d + 1, p + 1))
    K.ders_basis_funs(span, u, p, d, U, ders)
    out = np.zeros((d + 1, n + 1))
    out[:, span - p: span + 1] = ders
    return out


def cox_de_boor(i: int, p: int, U: np.ndarray, u: float) -> float:
    """Naive recursive N_{i,p}(u) (Eq. 2.5), right-closed on the last non-empty span."""
    if p == 0:
        last = U.size - np.argmax(U[::-1] < U[-1])  # index of the first copy of U[-1]
        if U[i] <= u < U[i + 1] or (u == U[-1] and i + 1 == last):
            return 1.0
        return 0.0
    value = 0.0
    if U[i + p] > U[i]:
        value += (u - U[i]) / (U[i + p] - U[i]) * cox_de_boor(i, p - 1, U, u)
    if U[i + p + 1] > U[i + 1]:
        value += (U[i + p + 1] - u) / (U[i + p + 1] - U[i + 1]) * cox_de_boor(i + 1, p - 1, U, u)
    return value


def away_from_knots(rng, knots: np.ndarray, size: int, gap: float) -> np.ndarray:
    """``size`` random parameters in the domain, each at least ``gap`` from every knot."""
    out = []
    while len(out) < size:
        u = rng.uniform(knots[0], knots[-1])
        if np.min(np.abs(knots - u)) > gap:
            out.append(u)
    return np.array(out)


def assert_close_scaled(actual, expected, rtol):
    """``|actual - expected| <= rtol * max(|expected|)`` entrywise (relative to the scale
    of the whole array, so that entries near zero are not held to a relative bound)."""
    expected = np.asarray(expected)
    scale = max(np.abs(expected).max(), 1e-300)
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=rtol * scale)


# ----------------------------------------------------------------------------------------
# The NURBS Book, Examples 2.3 and 2.4
# ----------------------------------------------------------------------------------------
EX_U = np.array([0, 0, 0, 1, 2, 3, 4, 4, 5, 5, 5], dtype=float)
EX_P = 2
EX_N = EX_U.size - EX_P - 2  # n = 7: eight basis functions


@pytest.mark.parametrize("u, span", [(2.5, 4), (0.0, 2), (0.5, 2), (1.0, 3), (4.0, 7), (4.5, 7), (5.0, 7)])
def test_find_span_book_vector(u, span):
    assert K.find_span(EX_N, EX_P, u, EX_U) == span


def test_basis_funs_example_2_3():
    N = np.empty(EX_P + 1)
    K.basis_funs(4, 2.5, EX_P, EX_U, N)
    np.testing.assert_allclose(N, [1 / 8, 6 / 8, 1 / 8], rtol=0, atol=1e-15)


def test_ders_basis_funs_example_2_4():
    ders = np.empty((3, EX_P + 1))
    K.ders_basis_funs(4, 2.5, EX_P, 2, EX_U, ders)
    np.testing.assert_allclose(ders[0], [1 / 8, 6 / 8, 1 / 8], rtol=0, atol=1e-15)
    np.testing.assert_allclose(ders[1], [-1 / 2, 0.0, 1 / 2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(ders[2], [1.0, -2.0, 1.0], rtol=0, atol=1e-15)


def test_basis_funs_match_naive_cox_de_boor():
    rng = np.random.default_rng(11)
    for p in range(1, 6):
        for _ in range(4):
            U = random_knots(rng, p, int(rng.integers(0, 5)))
            n = U.size - p - 2
            params = np.concatenate([rng.uniform(U[0], U[-1], 6), np.unique(U)])
            for u in params:
                span = K.find_span(n, p, u, U)
                N = np.empty(p + 1)
                K.basis_funs(span, u, p, U, N)
                naive = np.array([cox_de_boor(i, p, U, u) for i in range(n + 1)])
                expected = naive[span - p: span + 1]
                np.testing.assert_allclose(N, expected, rtol=0, atol=1e-14)
                assert np.abs(np.delete(naive, np.arange(span - p, span + 1))).max(initial=0.0) == 0.0


# ----------------------------------------------------------------------------------------
# properties of the basis
# ----------------------------------------------------------------------------------------
def test_partition_of_unity_and_derivative_sums():
    rng = np.random.default_rng(1)
    for p in range(1, 6):
        for _ in range(10):
            U = random_knots(rng, p, int(rng.integers(0, 6)))
            params = np.concatenate([rng.uniform(U[0], U[-1], 20), np.unique(U)])
            for u in params:
                ders = global_basis_ders(p, U, u, p)
                assert np.all(ders[0] >= -1e-15)
                assert abs(ders[0].sum() - 1.0) < 1e-14
                for k in range(1, p + 1):
                    scale = np.abs(ders[k]).max()
                    assert abs(ders[k].sum()) <= 1e-12 * max(scale, 1.0)


def test_basis_derivatives_against_finite_differences():
    rng = np.random.default_rng(2)
    h = 1e-5
    for p in range(1, 6):
        for _ in range(6):
            U = random_knots(rng, p, int(rng.integers(0, 5)), unit_spans=True)
            for u in away_from_knots(rng, U, 10, 10 * h):
                exact = global_basis_ders(p, U, u, 2)
                plus = global_basis_ders(p, U, u + h, 2)
                minus = global_basis_ders(p, U, u - h, 2)
                fd = (plus - minus) / (2 * h)
                assert_close_scaled(fd[0], exact[1], 1e-7)  # N' from N
                if p >= 2:
                    assert_close_scaled(fd[1], exact[2], 1e-7)  # N'' from the analytic N'


def test_derivative_order_above_degree_is_zero_in_basis():
    rng = np.random.default_rng(3)
    for p in range(1, 4):
        U = random_knots(rng, p, 3)
        n = U.size - p - 2
        u = rng.uniform(U[0], U[-1])
        span = K.find_span(n, p, u, U)
        ders = np.full((p + 4, p + 1), np.nan)
        K.ders_basis_funs(span, u, p, p + 3, U, ders)
        assert np.all(ders[p + 1:] == 0.0)
        reference = np.empty((p + 1, p + 1))
        K.ders_basis_funs(span, u, p, p, U, reference)
        np.testing.assert_array_equal(ders[: p + 1], reference)


# ----------------------------------------------------------------------------------------
# rational surfaces
# ----------------------------------------------------------------------------------------
def test_surface_derivatives_against_finite_differences():
    rng = np.random.default_rng(4)
    h = 1e-5
    e_u = np.array([h, 0.0])
    e_v = np.array([0.0, h])
    for p in range(1, 5):
        for q in range(1, 5):
            S = random_surface(rng, p, q, unit_spans=True)
            uv = np.column_stack([away_from_knots(rng, S.knots_u, 8, 10 * h),
                                  away_from_knots(rng, S.knots_v, 8, 10 * h)])
            d = S.derivatives(uv, 2)
            d_up, d_um = S.derivatives(uv + e_u, 1), S.derivatives(uv - e_u, 1)
            d_vp, d_vm = S.derivatives(uv + e_v, 1), S.derivatives(uv - e_v, 1)
            # first derivatives from points
            assert_close_scaled((d_up[:, 0, 0] - d_um[:, 0, 0]) / (2 * h), d[:, 1, 0], 1e-7)
            assert_close_scaled((d_vp[:, 0, 0] - d_vm[:, 0, 0]) / (2 * h), d[:, 0, 1], 1e-7)
            # second and mixed derivatives from the analytic first derivatives
            assert_close_scaled((d_up[:, 1, 0] - d_um[:, 1, 0]) / (2 * h), d[:, 2, 0], 1e-7)
            assert_close_scaled((d_vp[:, 0, 1] - d_vm[:, 0, 1]) / (2 * h), d[:, 0, 2], 1e-7)
            assert_close_scaled((d_vp[:, 1, 0] - d_vm[:, 1, 0]) / (2 * h), d[:, 1, 1], 1e-7)
            assert_close_scaled((d_up[:, 0, 1] - d_um[:, 0, 1]) / (2 * h), d[:, 1, 1], 1e-7)
            # order-0 entry is the point
            np.testing.assert_allclose(d[:, 0, 0], S.evaluate(uv), rtol=0, atol=1e-14)


def test_points_and_derivatives_match_geomdl():
    pytest.importorskip("geomdl")
    rng = np.random.default_rng(5)
    n_surfaces = 0
    for _ in range(7):
        for p in range(1, 5):
            for q in range(1, 5):
                S = random_surface(rng, p, q)
                g = geomdl_surface(S)
                uv = np.vstack([rng.uniform(0.0, 1.0, (4, 2)), [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
                                [[S.knots_u[p + 1], S.knots_v[-q - 2]]]])
                points = S.evaluate(uv)
                ders = S.derivatives(uv, 2)
                for i, (u, v) in enumerate(uv):
                    ref_point = np.array(g.evaluate_single((u, v)))
                    ref = np.array(g.derivatives(u, v, order=2))  # (3, 3, 3): [k][l][xyz]
                    scale = max(1.0, np.abs(ref).max())
                    np.testing.assert_allclose(points[i], ref_point, rtol=0, atol=1e-12)
                    for k in range(3):
                        for l in range(3 - k):
                            np.testing.assert_allclose(ders[i, k, l], ref[k, l], rtol=0, atol=1e-12 * scale)
                n_surfaces += 1
    assert n_surfaces >= 100


@pytest.mark.parametrize("p, q, order", [(1, 1, 3), (2, 1, 4), (1, 3, 5), (2, 2, 3)])
def test_derivative_order_above_degree_is_zero_for_nonrational(p, q, order):
    rng = np.random.default_rng(6)
    S = random_surface(rng, p, q, rational=False)
    uv = rng.uniform(0.0, 1.0, (20, 2))
    d = S.derivatives(uv, order)
    assert d.shape == (20, order + 1, order + 1, 3)
    assert np.all(np.isfinite(d))
    # A4.4 still divides out w = 1 with derivatives sum_i N_i^(k) = 0 up to round-off, so
    # "zero" is relative to the size of the non-zero derivatives
    scale = np.abs(d).max()
    for k in range(order + 1):
        for l in range(order + 1):
            if k + l > order:
                assert np.all(d[:, k, l] == 0.0), (k, l)
            elif k > p or l > q:
                assert np.abs(d[:, k, l]).max() <= 1e-13 * scale, (k, l)
    # the lower orders do not depend on the requested order
    low = S.derivatives(uv, 1)
    for k, l in ((0, 0), (1, 0), (0, 1)):
        np.testing.assert_allclose(d[:, k, l], low[:, k, l], rtol=0, atol=1e-14)


def test_rational_derivative_order_above_degree_is_finite():
    rng = np.random.default_rng(7)
    S = random_surface(rng, 1, 1)
    d = S.derivatives(rng.uniform(0.0, 1.0, (10, 2)), 4)
    assert np.all(np.isfinite(d))


def test_normals_unit_and_orthogonal_to_tangents():
    rng = np.random.default_rng(8)
    for p in range(1, 5):
        for q in range(1, 5):
            S = random_surface(rng, p, q)
            uv = rng.uniform(0.0, 1.0, (30, 2))
            nrm = S.normals(uv)
            d = S.derivatives(uv, 1)
            su, sv = d[:, 1, 0], d[:, 0, 1]
            np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, rtol=0, atol=1e-14)
            for t in (su, sv):
                cos = np.einsum("ij,ij->i", nrm, t) / np.linalg.norm(t, axis=1)
                assert np.abs(cos).max() < 1e-12
            # orientation: along S_u x S_v
            assert np.all(np.einsum("ij,ij->i", nrm, np.cross(su, sv)) > 0.0)


# ----------------------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------------------
def _valid():
    ku = np.array([0, 0, 0, 0.5, 1, 1, 1], dtype=float)  # p = 2, 4 points
    kv = np.array([0, 0, 1, 1], dtype=float)  # q = 1, 2 points
    control = np.ones((4, 2, 4))
    control[..., 0] = np.arange(4)[:, None]
    control[..., 1] = np.arange(2)[None, :]
    return (2, 1), ku, kv, control


def test_valid_input_is_accepted():
    S = NurbsSurface(*_valid())
    assert S.degree == (2, 1) and S.control.shape == (4, 2, 4)
    assert not S.control.flags.writeable


def _with(**changes):
    degree, ku, kv, control = _valid()
    args = dict(degree=degree, knots_u=ku, knots_v=kv, control=control)
    args.update(changes)
    return args


def _bad_control(index, value):
    control = _valid()[3].copy()
    control[index] = value
    return control


@pytest.mark.parametrize("args, field", [
    (_with(knots_u=np.array([0, 0, 0.2, 0.5, 1, 1, 1.0])), "knots_u"),       # not clamped at start
    (_with(knots_v=np.array([0, 0, 1, 2.0])), "knots_v"),                      # not clamped at end
    (_with(knots_u=np.array([0, 0, 0, 0.7, 0.3, 1, 1, 1.0]),
           control=np.ones((5, 2, 4))), "knots_u"),                             # decreasing
    (_with(knots_u=np.array([0, 0, 0, 1, 1, 1.0])), "knots_u"),                # wrong count
    (_with(knots_v=np.array([0, 0, 0.5, 1, 1.0])), "knots_v"),                 # wrong count
    (_with(knots_u=np.array([0, 0, 0, np.nan, 1, 1, 1.0])), "knots_u"),        # NaN knot
    (_with(knots_u=np.array([0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1.0]),
           control=np.ones((6, 2, 4))), "knots_u"),                             # multiplicity > p
    (_with(control=_bad_control((1, 1, 3), 0.0)), "control"),                  # zero weight
    (_with(control=_bad_control((2, 0, 3), -0.5)), "control"),                 # negative weight
    (_with(control=_bad_control((0, 1, 2), np.nan)), "control"),               # NaN coordinate
    (_with(control=_bad_control((0, 1, 3), np.nan)), "control"),               # NaN weight
    (_with(control=np.ones((4, 2, 3))), "control"),                            # not homogeneous
    (_with(degree=(0, 1)), "degree"),
])
def test_bad_input_raises_input_error_naming_the_field(args, field):
    with pytest.raises(InputError) as info:
        NurbsSurface(**args)
    assert info.value.field == field


def test_third_order_rational_derivatives_match_geomdl():
    """The general A4.4 loop (orders above 2, which the written-out quotient rule does not
    cover) against geomdl on rational bicubic surfaces."""
    pytest.importorskip("geomdl")
    rng = np.random.default_rng(11)
    for _ in range(10):
        S = random_surface(rng, 3, 3)
        g = geomdl_surface(S)
        uv = rng.uniform(0.0, 1.0, (5, 2))
        ders = S.derivatives(uv, 3)
        for i, (u, v) in enumerate(uv):
            ref = np.array(g.derivatives(u, v, order=3))  # (4, 4, 3)
            scale = max(1.0, np.abs(ref).max())
            for k in range(4):
                for l in range(4 - k):
                    np.testing.assert_allclose(ders[i, k, l], ref[k, l], rtol=0, atol=1e-11 * scale)


@pytest.mark.parametrize("p, q", [(1, 2), (2, 2), (3, 1), (4, 3)])
def test_bezier_patch_derivatives_match_geomdl(p, q):
    """The Bezier evaluator of the queries and the embedding (Bernstein basis, same
    contraction and quotient rule) against geomdl on a rational Bezier patch, orders 0-2;
    the per-thread scratch is reused between calls of different orders."""
    pytest.importorskip("geomdl")
    from cgfem.geometry._bezier import bezier_derivs, bezier_work

    rng = np.random.default_rng(p * 10 + q)
    knots_u = np.repeat([0.0, 1.0], p + 1)
    knots_v = np.repeat([0.0, 1.0], q + 1)
    S = NurbsSurface.from_points((p, q), knots_u, knots_v, rng.uniform(-1.0, 1.0, (p + 1, q + 1, 3)),
                                 rng.uniform(0.5, 1.5, (p + 1, q + 1)))
    g = geomdl_surface(S)
    work = bezier_work(4)
    SKL = np.full((3, 3, 3), np.nan)
    for s, t in np.vstack([rng.uniform(0.0, 1.0, (6, 2)), [[0.0, 0.0], [1.0, 0.5]]]):
        ref = np.array(g.derivatives(s, t, order=2))
        scale = max(1.0, np.abs(ref).max())
        for d in (2, 0, 1):
            bezier_derivs(S.control, s, t, d, work, SKL)
            for k in range(d + 1):
                for l in range(d + 1 - k):
                    np.testing.assert_allclose(SKL[k, l], ref[k, l], rtol=0, atol=1e-12 * scale)
