"""Linear-solver layer: every backend against dense solves of small H8 elasticity systems."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import scipy.sparse as sp

from tests.support import elasticity_fixture as fx
from cgfem.solve import backends, linear
from cgfem.solve.backends import choose_backend, factorize
from cgfem.solve.linear import BACKENDS, LinearSolverError, available_backends, rigid_body_modes

AVAILABLE = available_backends()
DIRECT = [b for b in ("superlu", "pardiso") if b in AVAILABLE]


@pytest.fixture(scope="module")
def cube() -> tuple[sp.csr_matrix, np.ndarray, np.ndarray, np.ndarray]:
    """Clamped 5^3 cube (540 DOFs): K, f, rigid-body modes of the free dofs, dense solution."""
    K, f, free = fx.clamped_cube(5, 0.2)
    B = rigid_body_modes(fx.grid_coords(5, 5, 5, 0.2))[free]
    return K, f, B, np.linalg.solve(K.toarray(), f)


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def test_fixture_is_elasticity() -> None:
    """The fixture itself: a uniform strain has the exact strain energy, interior forces vanish."""
    eps = np.array([[1.0, 0.2, 0.1], [0.2, -0.5, 0.3], [0.1, 0.3, 0.7]])
    X = fx.NODE_XI / 2
    u = (X @ eps.T).ravel()
    voigt = np.array([1.0, -0.5, 0.7, 0.6, 0.2, 0.4])
    assert u @ fx.brick_stiffness() @ u == pytest.approx(voigt @ fx.isotropic_d(1, 0.3) @ voigt)
    K, coords = fx.stiffness(3, 4, 5, h=0.5), fx.grid_coords(3, 4, 5, 0.5)
    r = (K @ (coords @ eps.T).ravel()).reshape(-1, 3)
    interior = np.all((coords > 0) & (coords < coords.max(axis=0)), axis=1)
    assert np.abs(r[interior]).max() < 1e-14 * np.abs(r).max()


def test_available_backends() -> None:
    assert AVAILABLE[:2] == ("superlu", "pyamg")
    assert ("pardiso" in AVAILABLE) == (importlib.util.find_spec("pypardiso") is not None)
    assert set(AVAILABLE) <= set(BACKENDS)


@pytest.mark.parametrize("backend", AVAILABLE)
def test_matches_dense_solve(backend: str, cube) -> None:
    K, f, B, x_ref = cube
    solver = factorize(K, backend=backend, near_null=B, rtol=1e-12)
    assert solver.backend == backend == solver.info["backend"]
    x = solver.solve(f)
    assert rel(x, x_ref) < 1e-8
    tol = 1e-12 if backend == "pyamg" else 1e-13
    assert np.linalg.norm(K @ x - f) <= tol * np.linalg.norm(f)
    assert solver.info["setup_s"] > 0 and len(solver.info["iterations"]) == 1


@pytest.mark.parametrize("backend", AVAILABLE)
def test_repeated_solves_reuse_the_factorization(backend: str, cube) -> None:
    K, f, B, _ = cube
    rng = np.random.default_rng(1)
    rhs = rng.standard_normal((K.shape[0], 4))
    refs = np.linalg.solve(K.toarray(), rhs)
    solver = factorize(K, backend=backend, near_null=B, rtol=1e-12)
    K.data *= 2.0  # the caller reuses its matrix: the solver must have its own copy
    try:
        for k in range(4):
            assert rel(solver.solve(rhs[:, k]), refs[:, k]) < 1e-8
        assert rel(solver.solve(rhs[:, 0]), refs[:, 0]) < 1e-8
    finally:
        K.data /= 2.0
    assert len(solver.info["iterations"]) == 5 and len(solver.info["residuals"]) == 5
    if backend == "pyamg":
        assert all(0 < it < 40 for it in solver.info["iterations"])
        assert max(solver.info["residuals"]) <= 1e-12
    else:
        assert solver.info["iterations"] == [0] * 5  # no refinement needed
        assert max(solver.info["residuals"]) < 1e-13


def test_rigid_body_modes_span_the_null_space() -> None:
    coords = fx.grid_coords(3, 4, 5, 0.5) + np.array([1.0, -2.0, 0.5])
    K = fx.stiffness(3, 4, 5, h=0.5)
    B = rigid_body_modes(coords)
    assert B.shape == (3 * len(coords), 6)
    assert np.abs(K @ B).max() < 1e-12 * np.abs(K).max() * np.abs(B).max()
    assert np.linalg.matrix_rank(B) == 6
    # interleaved dofs: translation x is (1, 0, 0) at every node; rotation z is (-y, x, 0)
    assert np.array_equal(B[:, 0], np.tile([1.0, 0.0, 0.0], len(coords)))
    r = coords - coords.mean(axis=0)
    rot_z = B[:, 5].reshape(-1, 3)
    scale = rot_z[:, 1] @ r[:, 0] / (r[:, 0] @ r[:, 0])
    assert np.allclose(rot_z, scale * np.column_stack([-r[:, 1], r[:, 0], 0 * r[:, 0]]), atol=1e-14)
    # and the free dofs of the clamped system: K_free is positive definite
    Kc, *_ = fx.clamped_cube(3)
    assert np.linalg.eigvalsh(Kc.toarray()).min() > 0
    with pytest.raises(ValueError, match="n_nodes, 3"):
        rigid_body_modes(np.zeros((4, 2)))


@pytest.mark.parametrize("backend", DIRECT)
def test_singular_matrix_raises(backend: str, cube) -> None:
    K, f, _, _ = cube
    n = K.shape[0]
    # a dof without stiffness (an empty row and column): exactly singular
    K0 = sp.block_diag([K, sp.csr_matrix((1, 1))], format="csr")
    with pytest.raises(LinearSolverError, match="singular"):
        factorize(K0, backend=backend).solve(np.ones(n + 1))
    # the unconstrained stiffness: numerically singular, caught by the residual check
    Ku = fx.stiffness(3, 3, 3)
    b = np.random.default_rng(2).standard_normal(Ku.shape[0])
    with pytest.raises(LinearSolverError, match="singular"):
        factorize(Ku, backend=backend).solve(b)


def test_pyamg_rejects_a_zero_diagonal(cube) -> None:
    K, *_ = cube
    with pytest.raises(LinearSolverError, match="diagonal"):
        factorize(sp.block_diag([K, sp.csr_matrix((1, 1))], format="csr"), backend="pyamg")


def nonsymmetric(K: sp.csr_matrix) -> sp.csr_matrix:
    """K plus a skew part on its own pattern: positive real, clearly non-symmetric."""
    L = sp.tril(K, -1)
    return (K + 0.3 * (L - L.T)).tocsr()


@pytest.mark.parametrize("backend", AVAILABLE)
def test_nonsymmetric_matrix(backend: str, cube) -> None:
    K, f, B, _ = cube
    A = nonsymmetric(K)
    assert abs(A - A.T).max() > 0.1 * abs(A).max()
    x_ref = np.linalg.solve(A.toarray(), f)
    solver = factorize(A, backend=backend, symmetric=False, near_null=B, rtol=1e-12)
    assert rel(solver.solve(f), x_ref) < 1e-8
    assert rel(solver.solve(-3 * f), -3 * x_ref) < 1e-8
    if backend == "pyamg":
        assert solver.info["krylov"] == "gmres"
        assert all(0 < it < 200 for it in solver.info["iterations"])
    if backend == "pardiso":
        assert solver.info["mtype"] == 11
    # the same matrix declared symmetric is wrong for the symmetric backends: never silent
    if backend != "superlu":
        wrong = factorize(A, backend=backend, symmetric=True, near_null=B, rtol=1e-12)
        try:
            x = wrong.solve(f)
        except LinearSolverError:
            pass
        else:
            assert np.linalg.norm(A @ x - f) <= 1e-8 * np.linalg.norm(f)


def test_pyamg_symmetric_uses_cg(cube) -> None:
    K, f, B, _ = cube
    solver = factorize(K, backend="pyamg", near_null=B)
    solver.solve(f)
    assert solver.info["krylov"] == "cg" and solver.info["operator_complexity"] < 2


def test_badly_scaled_matrix() -> None:
    """Penalty clamp (1e3 x the largest diagonal) and 10 % cut cells scaled by 1e-4."""
    K, f = fx.penalty_cube(8)
    d = K.diagonal()
    assert d.max() / d.min() > 1e5
    B = rigid_body_modes(fx.grid_coords(8, 8, 8))
    x_ref = factorize(K, backend="superlu").solve(f)
    solver = factorize(K, backend="pyamg", near_null=B, rtol=1e-10)
    x = solver.solve(f)
    assert np.linalg.norm(K @ x - f) <= 1e-10 * np.linalg.norm(f)
    assert solver.info["iterations"][0] < 30
    assert rel(x, x_ref) < 1e-6
    for backend in DIRECT:
        assert rel(factorize(K, backend=backend).solve(f), x_ref) < 1e-10


def test_pyamg_scales_the_near_null_space() -> None:
    """After the diagonal scaling S A S, the hierarchy's B must be S^-1 B (white box)."""
    scale = np.where(np.random.default_rng(3).random(27) < 0.3, 1e-4, 1.0)
    K = fx.stiffness(3, 3, 3, element_scale=scale)
    B = rigid_body_modes(fx.grid_coords(3, 3, 3))
    level = factorize(K, backend="pyamg", near_null=B)._ml.levels[0]
    assert np.abs(level.A @ level.B).max() < 1e-12 * abs(level.A).max() * np.abs(level.B).max()


def test_pyamg_gives_up_after_bounded_iterations(cube, monkeypatch) -> None:
    K, f, B, _ = cube
    monkeypatch.setattr(linear, "MAX_ITERATIONS", 3)
    solver = factorize(K, backend="pyamg", near_null=B, rtol=1e-14)
    with pytest.raises(LinearSolverError, match="did not reach relative residual"):
        solver.solve(f)


def test_choose_backend(monkeypatch) -> None:
    big = backends.PARDISO_MAX_DOFS + 1
    for name in BACKENDS:
        if name in AVAILABLE:
            assert choose_backend(10, True, name) == name
            assert choose_backend(10**7, False, name) == name
    monkeypatch.setattr(linear, "available_backends", lambda: BACKENDS)
    assert choose_backend(1000, True) == "pardiso"
    assert choose_backend(backends.PARDISO_MAX_DOFS, True) == "pardiso"
    assert choose_backend(big, True) == "pyamg"
    assert choose_backend(big, False) == "pardiso"
    monkeypatch.setattr(linear, "available_backends", lambda: ("superlu", "pyamg"))
    assert choose_backend(1000, True) == "superlu"
    assert choose_backend(backends.SUPERLU_MAX_DOFS + 1, True) == "pyamg"
    assert choose_backend(big, False) == "superlu"
    with pytest.raises(ValueError, match="'pardiso' is not available"):
        choose_backend(1000, True, "pardiso")
    # saddle points never go to pyamg
    assert choose_backend(big, True, indefinite=True) == "superlu"
    with pytest.raises(ValueError, match="saddle-point"):
        choose_backend(1000, True, "pyamg", indefinite=True)
    monkeypatch.setattr(linear, "available_backends", lambda: BACKENDS)
    assert choose_backend(big, True, indefinite=True) == "pardiso"


@pytest.mark.parametrize("backend", DIRECT)
def test_saddle_point(backend: str, cube) -> None:
    """[[K, C^T], [C, 0]]: symmetric indefinite with a zero diagonal block (the fit
    constraints of nurbs_fit); pardiso takes it as non-symmetric (type 11)."""
    K, f, *_ = cube
    rng = np.random.default_rng(3)
    C = sp.random(30, K.shape[0], density=0.05, random_state=rng, format="csr") + sp.eye(30, K.shape[0])
    A = sp.bmat([[K, C.T], [C, None]], format="csr")
    b = np.concatenate([f, rng.standard_normal(30)])
    solver = factorize(A, backend=backend, symmetric=True, indefinite=True)
    x = solver.solve(b)
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)
    assert rel(x, np.linalg.solve(A.toarray(), b)) < 1e-8
    if backend == "pardiso":
        assert solver.info["mtype"] == 11


def test_large_symmetric_saddle_point_is_refused(monkeypatch) -> None:
    """Above SADDLE_MAX_DOFS a symmetric saddle point is refused (the run fails with the
    reason) instead of a factorization that exhausts the memory."""
    monkeypatch.setattr(backends, "SADDLE_MAX_DOFS", 10)
    A = sp.bmat([[sp.identity(20), sp.identity(20)], [sp.identity(20), None]], format="csr")
    with pytest.raises(LinearSolverError, match="saddle-point system of 40 unknowns"):
        factorize(A, symmetric=True, indefinite=True)
    x = factorize(A, symmetric=False, indefinite=True).solve(np.ones(40))
    np.testing.assert_allclose(A @ x, np.ones(40), atol=1e-12)


def test_bad_backend_name(cube) -> None:
    K, *_ = cube
    with pytest.raises(ValueError, match="'mumps'"):
        choose_backend(100, True, "mumps")
    with pytest.raises(ValueError, match="'SuperLU'"):
        factorize(K, backend="SuperLU")


def test_bad_input(cube) -> None:
    K, f, _, _ = cube
    solver = factorize(K, backend="superlu")
    with pytest.raises(ValueError, match="shape"):
        solver.solve(f[:-1])
    with pytest.raises(ValueError, match="shape"):
        solver.solve(np.column_stack([f, f]))
    assert np.array_equal(solver.solve(np.zeros_like(f)), np.zeros_like(f))
    bad = f.copy()
    bad[3] = np.nan
    with pytest.raises(LinearSolverError, match="NaN"):
        solver.solve(bad)
    Kn = K.copy()
    Kn.data[7] = np.inf
    with pytest.raises(LinearSolverError, match="NaN or inf"):
        factorize(Kn)
    with pytest.raises(ValueError, match="square"):
        factorize(K[:-1])
    with pytest.raises(ValueError, match="square"):
        factorize(K.toarray())


@pytest.mark.parametrize("symmetric", [True, False])
def test_pyamg_stops_at_a_looser_per_solve_tolerance(symmetric: bool, cube) -> None:
    """solve(b, rtol): the true residual reaches the looser rtol in fewer Krylov iterations;
    a tighter one than the solver's own is not taken (its own still holds), and direct
    backends solve to round-off whatever rtol asks."""
    K, f, B, _ = cube
    solver = factorize(K, backend="pyamg", symmetric=symmetric, near_null=B, rtol=1e-12)
    solver.solve(f)
    solver.solve(f, 1e-4)
    solver.solve(f, 1e-16)
    tight, loose, tighter = solver.info["iterations"]
    r_tight, r_loose, r_tighter = solver.info["residuals"]
    assert r_tight <= 1e-12 and r_loose <= 1e-4 and r_tighter <= 1e-12
    assert loose < 0.6 * tight and tighter == tight
    for backend in DIRECT:
        direct = factorize(K, backend=backend)
        direct.solve(f, 1e-2)
        assert direct.info["residuals"][0] < 1e-13


@pytest.mark.slow
@pytest.mark.skipif("pardiso" not in available_backends(), reason="pypardiso is not installed")
def test_pardiso_repeats_bitwise_under_a_concurrent_load() -> None:
    """PARDISO's parallel factorization (26k unknowns, two threads) gives the same bits every
    time while two other processes load the machine: in its default mode it gave two or
    three different solutions out of six, in its reproducible mode (``iparm(34)``) one."""
    import hashlib
    import subprocess
    import sys

    K, f, _ = fx.clamped_cube(20)
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        digests = {hashlib.sha1(factorize(K, backend="pardiso").solve(f).tobytes()).hexdigest()
                   for _ in range(6)}
    finally:
        for proc in burners:
            proc.kill()
    assert len(digests) == 1


MKL_PROBE = """
import json, os
os.environ.pop("PYPARDISO_MKL_RT", None)
from pypardiso.pardiso_wrapper import PyPardisoSolver
own = str(PyPardisoSolver().libmkl._name)       # pypardiso's own search (walks site-packages)
from cgfem.solve import linear
print(json.dumps([own, linear._mkl_rt(), os.environ.get("PYPARDISO_MKL_RT")]))
"""


@pytest.mark.skipif("pardiso" not in AVAILABLE, reason="pypardiso is not installed")
def test_pypardiso_is_pointed_at_the_library_its_own_search_finds() -> None:
    """Naming MKL's runtime to pypardiso (which spares its walk of site-packages) names the
    library pypardiso's own search finds; where the linker knows it, nothing is named."""
    import ctypes.util
    import json
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "PYPARDISO_MKL_RT"}
    proc = subprocess.run([sys.executable, "-c", MKL_PROBE], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    own, used, named = json.loads(proc.stdout.strip().splitlines()[-1])
    if ctypes.util.find_library("mkl_rt"):
        assert named is None
    else:
        assert named is not None and os.path.realpath(named) == os.path.realpath(own)
    assert os.path.realpath(used) == os.path.realpath(own)
