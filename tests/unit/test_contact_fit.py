"""The NURBS surface fitted to the FE displacement (``nurbs_fit``, paper eqs. 18-22).

A box and a torus are embedded at coarse grids. The fitting space keeps the geometry; M is
SPD and sums to the patch's area (partition of unity); a displacement that is linear in x is
both a trilinear FE field and in the NURBS span (``V = A P + b``), so the fit reproduces it
exactly; a smooth non-polynomial field is fitted better and better as the fitting space is
refined, and better than on the paper's original net; the rational basis derivatives equal
the surface's own (A3.6/A4.4) derivatives; the output files round-trip.
"""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.contact.fit import (BandedCholesky, band_order, build_fit, build_fits, fit_mesh, fit_space,
                               read_fit_json, span_lengths, surface_basis, write_fit_json, write_fit_vtu)
from cgfem.embedding.quadrature import embed, grid_for
from cgfem.errors import InputError
from cgfem.fem.space import Space
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import BoxSpec, TorusSpec

TORUS = TorusSpec((0.0003, -0.0002, 0.0001), (0.6, 0.0, 0.8), 0.02, 0.005)
BOX = BoxSpec((0.0, 0.0, 0.0), (0.01, 0.008, 0.006))


def _body(spec, h0: float, offset):
    solid = build_solid(spec)
    emb = embed(solid, grid_for(solid, h0, 0, offset), "nurbs")
    return solid, emb, Space.from_embedding(emb)


@pytest.fixture(scope="module")
def torus():
    return _body(TORUS, 0.004, (0.37, 0.11, 0.64))


@pytest.fixture(scope="module")
def box():
    return _body(BOX, 0.003, (0.13, 0.29, 0.41))


def _fit(body, ip: int, refine="auto"):
    solid, emb, space = body
    return build_fits(solid, emb.surface, space, [ip], refine)[0]


def _size(surface) -> float:
    lo, hi = surface.bounding_box()
    return float(np.max(hi - lo))


# -- the fitting space ------------------------------------------------------------------
@pytest.mark.parametrize("refine", ["auto", None, 0, 1, 3])
def test_fitting_space_keeps_the_geometry(torus, box, refine):
    rng = np.random.default_rng(1)
    for surface in (torus[0].patches[0].surface, box[0].patches[3].surface):
        fitted = fit_space(surface, 0.002, refine)
        (u0, u1), (v0, v1) = surface.domain
        uv = np.column_stack([rng.uniform(u0, u1, 500), rng.uniform(v0, v1, 500)])
        assert np.abs(fitted.evaluate(uv) - surface.evaluate(uv)).max() < 1e-13 * _size(surface)
        if isinstance(refine, int):                     # n knots in every span: n + 1 times the spans
            spans = [b.size - 1 for b in surface.breaks()]
            assert [b.size - 1 for b in fitted.breaks()] == [(refine + 1) * s for s in spans]


def test_auto_spacing_follows_h(torus):
    surface = torus[0].patches[0].surface
    counts = []
    for h in (0.004, 0.002):
        fitted = fit_space(surface, h, "auto")
        for direction in (0, 1):
            length = span_lengths(fitted, direction)[1]
            assert 0.5 * h < length.min() and length.max() < 2.0 * h
            # neighbouring control points (rational circle: corners off the surface) too
            pts = fitted.points
            gaps = np.linalg.norm(np.diff(pts, axis=direction), axis=-1)
            assert 0.5 * h < np.median(gaps) < 2.0 * h
        counts.append(fitted.weights.size)
    assert 3.0 < counts[1] / counts[0] < 5.0              # a finer grid, a finer fit (about 4x)
    # the box's bilinear faces are raised to degree 2 (a C1 fitted surface)
    assert fit_space(build_solid(BOX).patches[0].surface, 0.003, "auto").degree == (2, 2)


def test_bad_refinement_is_input_error(torus):
    with pytest.raises(InputError, match="fit"):
        fit_space(torus[0].patches[0].surface, 0.01, "fine")
    with pytest.raises(InputError, match="fit"):
        fit_space(torus[0].patches[0].surface, 0.01, -1)


def test_basis_derivatives_equal_the_surface_derivatives(torus):
    surface = fit_space(torus[0].patches[0].surface, 0.003, "auto")
    rng = np.random.default_rng(2)
    uv = rng.uniform(0.0, 1.0, (300, 2))
    uv[:4] = [[0.0, 0.0], [1.0, 1.0], [0.25, 0.5], [0.5, 0.75]]        # domain corners, double knots
    B = surface_basis(surface, uv)
    d = surface.derivatives(uv, 2)
    ref = np.stack([d[:, 0, 0], d[:, 1, 0], d[:, 0, 1], d[:, 2, 0], d[:, 1, 1], d[:, 0, 2]], axis=1)
    got = B.apply(surface.points.reshape(-1, 3))
    scale = np.abs(ref).max(axis=(0, 2))                                # per derivative order
    assert np.abs(got - ref).max(axis=(0, 2)).max() / scale.min() < 1e-11
    assert np.all(np.abs(got - ref).max(axis=(0, 2)) < 1e-12 * scale)
    # partition of unity and its derivatives
    sums = B.values.sum(axis=2)
    assert np.abs(sums[:, 0] - 1.0).max() < 1e-14
    assert np.abs(sums[:, 1:]).max() < 1e-10
    # the sparse matrix form gives the same values
    assert np.allclose(B.matrix(4) @ surface.points.reshape(-1, 3), ref[:, 4], rtol=0, atol=1e-12 * scale[4])


def test_banded_cholesky_equals_dense_solve():
    rng = np.random.default_rng(3)
    n_u, n_v = 5, 7
    A = np.zeros((n_u * n_v,) * 2)
    for i in range(n_u * n_v):                        # a 2D stencil of reach 2 (degree 2)
        for j in range(n_u * n_v):
            if abs(i // n_v - j // n_v) <= 2 and abs(i % n_v - j % n_v) <= 2:
                A[i, j] = rng.uniform(-1, 1)
    A = A + A.T + 30.0 * np.eye(n_u * n_v)
    b = rng.standard_normal((n_u * n_v, 3))
    for perm in (np.arange(n_u * n_v), band_order(n_u, n_v, (2, 2))):
        f = BandedCholesky.of(A, perm)
        assert np.abs(f.solve(b) - np.linalg.solve(A, b)).max() < 1e-13
    assert band_order(n_u, n_v, (2, 2))[1] == n_v     # v-major: the smaller band (2 n_u + 2 < 2 n_v + 2)
    with pytest.raises(np.linalg.LinAlgError):
        BandedCholesky.of(A - 100.0 * np.eye(n_u * n_v), np.arange(n_u * n_v))
    # three columns (their own loops) give the bits of each column alone and of the same
    # columns among four (the general loops)
    x3 = f.solve(b)
    for c in range(3):
        assert np.array_equal(f.solve(b[:, c]), x3[:, c])
    assert np.array_equal(f.solve(np.column_stack([b, b[:, 0]]))[:, :3], x3)


# -- M and G ----------------------------------------------------------------------------
@pytest.mark.parametrize("which", ["torus", "box"])
def test_mass_matrix_is_spd_and_sums_to_the_area(torus, box, which):
    body = torus if which == "torus" else box
    ip = 0 if which == "torus" else 5
    fit = _fit(body, ip)
    M = fit.M.toarray()
    assert np.abs(M - M.T).max() <= 1e-14 * np.abs(M).max()          # rounding of T^T R^T W R T
    eig = np.linalg.eigvalsh(M)
    assert eig.min() > 1e-6 * eig.max()
    rule = body[1].surface
    area = rule.w[rule.patch == ip].sum()
    assert abs(M.sum() - area) < 1e-12 * area
    # G sums to the area too (both partitions of unity), and per control function to M's row sums
    assert abs(fit.G.sum() - area) < 1e-12 * area
    assert np.abs(np.asarray(fit.G.sum(axis=1)).ravel() - M.sum(axis=1)).max() < 1e-12 * area


def test_singular_fit_names_the_patch(torus):
    solid, emb, space = torus
    rule = emb.surface.select(emb.surface.patch == 0)
    half = rule.uv[:, 0] < 0.5                        # no rule point on half of the patch
    with pytest.raises(ValueError, match="patch 'surface'.*no surface-rule point"):
        build_fit(solid.patches[0].surface, rule.uv[half], rule.w[half], space, "auto", "surface", 0)


# -- reproduction of linear fields --------------------------------------------------------
def _linear_fields(scale: float):
    rng = np.random.default_rng(4)
    omega = rng.standard_normal(3)
    rotation = np.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]], [-omega[1], omega[0], 0]])
    A = rng.standard_normal((3, 3))
    b = rng.standard_normal(3)
    return {"translation": (np.zeros((3, 3)), b * scale),
            "rotation": (1e-2 * rotation, np.zeros(3)),
            "linear": (1e-2 * A, b * scale)}


@pytest.mark.parametrize("which", ["torus", "box"])
@pytest.mark.parametrize("refine", ["auto", None])
def test_linear_fields_are_reproduced(torus, box, which, refine):
    body = torus if which == "torus" else box
    ip = 0 if which == "torus" else 4
    fit = _fit(body, ip, refine)
    X = body[2].coordinates
    P = fit.control_points
    for name, (A, b) in _linear_fields(1e-4).items():
        u = (X @ A.T + b).ravel()
        V = fit.displacements(u)
        exact = P @ A.T + b
        size = np.abs(exact).max()
        assert np.abs(V - exact).max() < 1e-11 * size, name
        R, N = fit.rule_matrices()
        fe = N @ u.reshape(-1, 3)
        assert np.abs(R @ V - fe).max() < 1e-12 * size, name
        assert fit.relative_l2_error(u) < 1e-12, name
        # the fitted surface is the moved surface: S(P + V) = x + A x + b at any (s, t)
        uv = np.random.default_rng(5).uniform(0.0, 1.0, (50, 2))
        x0 = fit.surface.evaluate(uv)
        assert np.abs(fit.position(V, uv) - (x0 + x0 @ A.T + b)).max() < 1e-12 * _size(fit.surface), name


# -- a non-polynomial field ---------------------------------------------------------------
def test_fit_error_falls_with_refinement(torus):
    solid, emb, space = torus
    X = space.coordinates
    k = 2.0 * np.pi / 0.02                             # wavelength 0.02: the torus's major radius
    u = 1e-4 * np.column_stack([np.sin(k * X[:, 0]), np.cos(k * X[:, 1]), np.sin(k * X[:, 2] + 1.0)]).ravel()
    errors, sizes = [], []
    for n in (0, 1, 3, 7):
        fit = _fit(torus, 0, n)
        errors.append(fit.relative_l2_error(u))
        sizes.append(fit.n_ctrl)
    errors = np.array(errors)
    assert np.all(np.diff(errors) < 0.0)
    # algebraic convergence while the net is coarser than the grid: error ~ spacing^rate
    # (measured: relative errors 0.77, 0.58, 0.19, 0.049 for 0, 1, 3, 7 knots per span)
    rate = -np.polyfit(np.log(np.sqrt(sizes[1:])), np.log(errors[1:]), 1)[0]
    assert rate > 2.0, (errors, rate)
    auto = _fit(torus, 0, "auto").relative_l2_error(u)
    assert auto < 0.1 * errors[0]                      # better than the original net (0.057)
    paper = build_fits(solid, emb.surface, space, [0], None, smooth=False)[0].relative_l2_error(u)
    assert auto < 0.15 * paper                         # and than the paper's fit (original net, C0: 0.53)


# -- output ---------------------------------------------------------------------------------
def test_json_and_vtu_output(torus, tmp_path):
    import meshio

    solid, emb, space = torus
    fit = _fit(torus, 0)
    X = space.coordinates
    A = 1e-2 * np.array([[0.1, 0.2, 0.0], [0.0, -0.3, 0.1], [0.2, 0.0, 0.1]])
    u = (X @ A.T).ravel()
    V = fit.displacements(u)
    path = write_fit_json(tmp_path / "fit.json", [fit], [V])
    (patch,) = read_fit_json(path)
    assert patch.name == "surface"
    assert np.array_equal(patch.surface.points, fit.moved(V).points)
    assert np.array_equal(patch.surface.weights, fit.surface.weights)
    assert np.array_equal(patch.surface.knots_u, fit.surface.knots_u) and patch.surface.degree == (2, 2)
    samples = 12
    mesh = fit_mesh([fit, fit], [V, V], [u, u], samples)
    assert mesh.points.shape == (2 * (samples + 1) ** 2, 3)
    assert mesh.cells_dict["quad"].shape == (2 * samples**2, 4)
    # a linear field: the fitted and the FE displacement agree at the sampled points
    d, fe = mesh.point_data["displacement"], mesh.point_data["fe_displacement"]
    assert np.abs(d - fe).max() < 1e-12 * np.abs(fe).max()
    assert np.abs(mesh.points - mesh.point_data["reference"] - d).max() < 1e-15 * _size(fit.surface)
    out = write_fit_vtu(tmp_path / "fit.vtu", mesh)
    back = meshio.read(out)
    assert back.points.shape == mesh.points.shape and back.cells_dict["quad"].shape == (2 * samples**2, 4)
    assert np.allclose(back.point_data["fe_displacement"], fe, rtol=0, atol=0)


def test_fitted_surface_is_c1_across_the_circles_double_knots(torus):
    solid, emb, space = torus
    X = space.coordinates
    u = 1e-4 * np.column_stack([np.sin(200 * X[:, 0]), np.cos(150 * X[:, 1]), np.sin(300 * X[:, 2])]).ravel()
    t = np.linspace(0.01, 0.99, 100)
    jumps = {}
    for smooth in (True, False):
        fit = build_fits(solid, emb.surface, space, [0], "auto", smooth)[0]
        V = fit.displacements(u)
        normals = []
        for side in (-1e-9, 1e-9):                    # either side of the joint v = 0.25
            d = fit.derivatives(V, np.column_stack([t, np.full_like(t, 0.25 + side)]))
            m = np.cross(d[:, 1], d[:, 2])
            normals.append(m / np.linalg.norm(m, axis=1)[:, None])
        jumps[smooth] = np.arccos(np.clip((normals[0] * normals[1]).sum(axis=1), -1.0, 1.0)).max()
        if smooth:
            assert fit.n_free < fit.n_ctrl
    assert jumps[True] < 1e-6 < 1e-3 < jumps[False], jumps


def test_band_order_folds_the_seams_of_a_closed_patch(torus):
    """The torus patch closes on itself in both directions: in the natural numbering its
    seams couple the first and last rows (bandwidth about n); the order chosen with M's
    pattern is reverse Cuthill-McKee's, at most a fifth of n, and the fit solves the same."""
    from cgfem.contact.fit import bandwidth
    fit = _fit(torus, 0)
    M = fit.M
    n = M.shape[0]
    chosen = fit.factor.perm
    assert bandwidth(M, np.arange(n)) >= n // 2
    assert bandwidth(M, chosen) <= n // 5
    assert fit.factor.bandwidth == bandwidth(M, chosen)
    b = np.random.default_rng(3).standard_normal((n, 3))
    assert np.abs(fit.factor.solve(b) - np.linalg.solve(M.toarray(), b)).max() <= 1e-10 * np.abs(
        np.linalg.solve(M.toarray(), b)).max()
