"""Constitutive kernels at a material point.

The tangent is checked against central finite differences of the stress, and the stress
against central finite differences of the energy, at random states with ``|H| ~ 0.3``.
Further: stress-free reference and small-strain limit of the Neo-Hookean law, objectivity,
major symmetry, symmetric Cauchy stress, rejection of ``det F <= 0``, the closed-form
uniaxial Neo-Hookean reference and the von Mises stress.
"""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.case.model import Lame, Material
from cgfem.errors import InputError
from cgfem.fem import _material_kernels as _k
from cgfem.fem.materials import (
    LINEAR_ELASTIC,
    NEO_HOOKEAN,
    cauchy,
    lame,
    model_id,
    stress,
    stress_tangent_at,
    uniaxial_stretch_neo_hookean,
    von_mises,
)

E, NU = 210.0e3, 0.3
LAM, MU = lame(E, NU)
MODELS = {"linear_elastic": LINEAR_ELASTIC, "neo_hookean": NEO_HOOKEAN}
FD_STEP = 1e-6


def random_gradients(n: int, seed: int, size: float = 0.3, min_det: float = 0.3) -> np.ndarray:
    """``n`` displacement gradients with entries of size ~``size`` and ``det F > min_det``."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        H = size * rng.uniform(-1.0, 1.0, (3, 3))
        if np.linalg.det(np.eye(3) + H) > min_det:
            out.append(H)
    return np.array(out)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0.0:
        Q[:, 0] = -Q[:, 0]
    return Q


def energy(model: int, H: np.ndarray, mu: float = MU, lam: float = LAM) -> float:
    return stress_tangent_at(model, H, mu, lam)[0]


def pk(model: int, H: np.ndarray, mu: float = MU, lam: float = LAM) -> np.ndarray:
    return stress_tangent_at(model, H, mu, lam)[1]


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("nu", [0.3, 0.45])
def test_tangent_is_derivative_of_stress(name: str, nu: float) -> None:
    model = MODELS[name]
    lam, mu = lame(E, nu)
    for H in random_gradients(20, seed=1):
        _, _, A = stress_tangent_at(model, H, mu, lam)
        A_fd = np.empty((3, 3, 3, 3))
        for k in range(3):
            for L in range(3):
                dH = np.zeros((3, 3))
                dH[k, L] = FD_STEP
                A_fd[:, :, k, L] = (pk(model, H + dH, mu, lam) - pk(model, H - dH, mu, lam)) / (2 * FD_STEP)
        assert rel(A, A_fd) < 1e-6


@pytest.mark.parametrize("name", MODELS)
def test_stress_is_derivative_of_energy(name: str) -> None:
    model = MODELS[name]
    for H in random_gradients(20, seed=2):
        P = pk(model, H)
        P_fd = np.empty((3, 3))
        for k in range(3):
            for L in range(3):
                dH = np.zeros((3, 3))
                dH[k, L] = FD_STEP
                P_fd[k, L] = (energy(model, H + dH) - energy(model, H - dH)) / (2 * FD_STEP)
        assert rel(P, P_fd) < 1e-6


def linear_elastic_C(mu: float, lam: float) -> np.ndarray:
    d = np.eye(3)
    return (lam * np.einsum("ij,kl->ijkl", d, d)
            + mu * (np.einsum("ik,jl->ijkl", d, d) + np.einsum("il,jk->ijkl", d, d)))


def test_linear_elastic_matches_hooke() -> None:
    H = random_gradients(1, seed=3)[0]
    W, P, A = stress_tangent_at(LINEAR_ELASTIC, H, MU, LAM)
    eps = 0.5 * (H + H.T)
    sigma = LAM * np.trace(eps) * np.eye(3) + 2 * MU * eps
    np.testing.assert_allclose(P, sigma, rtol=0, atol=1e-12 * MU)
    np.testing.assert_allclose(A, linear_elastic_C(MU, LAM), rtol=0, atol=1e-12 * MU)
    assert W == pytest.approx(0.5 * np.sum(sigma * eps), rel=1e-13)


@pytest.mark.parametrize("name", MODELS)
def test_stress_free_reference_and_small_strain_limit(name: str) -> None:
    W, P, A = stress_tangent_at(MODELS[name], np.zeros((3, 3)), MU, LAM)
    assert W == 0.0
    assert np.all(P == 0.0)
    np.testing.assert_allclose(A, linear_elastic_C(MU, LAM), rtol=0, atol=1e-12 * MU)


def test_neo_hookean_small_strain_matches_linear() -> None:
    """At ``|H| ~ 1e-6`` the stresses agree to relative ~1e-6 (next order is quadratic)."""
    for H in random_gradients(5, seed=4, size=1e-6, min_det=0.0):
        assert rel(pk(NEO_HOOKEAN, H), pk(LINEAR_ELASTIC, H)) < 1e-5
        assert energy(NEO_HOOKEAN, H) == pytest.approx(energy(LINEAR_ELASTIC, H), rel=1e-5)


def test_neo_hookean_objectivity() -> None:
    rng = np.random.default_rng(5)
    for H in random_gradients(20, seed=6):
        R = random_rotation(rng)
        F = np.eye(3) + H
        W, P, _ = stress_tangent_at(NEO_HOOKEAN, H, MU, LAM)
        W_r, P_r, _ = stress_tangent_at(NEO_HOOKEAN, R @ F - np.eye(3), MU, LAM)
        assert W_r == pytest.approx(W, rel=1e-12)
        assert rel(P_r, R @ P) < 1e-12


def test_neo_hookean_pure_rotation_is_stress_free() -> None:
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    for F in (R, R.T, R @ np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])):
        W, P, _ = stress_tangent_at(NEO_HOOKEAN, F - np.eye(3), MU, LAM)
        assert abs(W) <= 1e-12 * MU
        assert np.max(np.abs(P)) <= 1e-12 * MU


@pytest.mark.parametrize("name", MODELS)
def test_major_symmetry(name: str) -> None:
    for H in random_gradients(20, seed=7):
        _, _, A = stress_tangent_at(MODELS[name], H, MU, LAM)
        np.testing.assert_allclose(A, A.transpose(2, 3, 0, 1), rtol=0, atol=1e-13 * np.max(np.abs(A)))


def test_neo_hookean_cauchy_symmetric_and_consistent() -> None:
    Hs = random_gradients(20, seed=8)
    sigma = cauchy(NEO_HOOKEAN, Hs, MU, LAM)
    _, P = stress(NEO_HOOKEAN, Hs, MU, LAM)
    for H, s, Pq in zip(Hs, sigma, P):
        F = np.eye(3) + H
        J = np.linalg.det(F)
        assert rel(s.T, s) < 1e-12
        # sigma = (mu (F F^T - I) + lam ln J I) / J
        expected = (MU * (F @ F.T - np.eye(3)) + LAM * np.log(J) * np.eye(3)) / J
        assert rel(s, expected) < 1e-12
        assert rel(s, Pq @ F.T / J) < 1e-12


def test_linear_cauchy_is_stress() -> None:
    Hs = random_gradients(4, seed=9)
    np.testing.assert_array_equal(cauchy(LINEAR_ELASTIC, Hs, MU, LAM), stress(LINEAR_ELASTIC, Hs, MU, LAM)[1])


@pytest.mark.parametrize("H", [
    np.diag([-1.0, 0.0, 0.0]),            # J = 0
    np.diag([-2.0, 0.0, 0.0]),            # J = -1 (reflection)
    -1.5 * np.eye(3),                     # F = -I/2, J = -1/8
])
def test_inadmissible_state_rejected(H: np.ndarray) -> None:
    W, P, A = stress_tangent_at(NEO_HOOKEAN, H, MU, LAM)
    assert W == np.inf
    assert np.all(np.isnan(P)) and np.all(np.isnan(A))
    assert np.all(np.isnan(cauchy(NEO_HOOKEAN, H[None], MU, LAM)))
    W_b, P_b = stress(NEO_HOOKEAN, H[None], MU, LAM)
    assert W_b[0] == np.inf and np.all(np.isnan(P_b))


@pytest.mark.parametrize("stretch", [0.6, 0.95, 1.05, 1.7, 3.0])
@pytest.mark.parametrize("nu", [0.0, 0.3, 0.49, -0.2])
def test_uniaxial_closed_form(stretch: float, nu: float) -> None:
    lam, mu = lame(E, nu)
    t, P11 = uniaxial_stretch_neo_hookean(stretch, E, nu)
    # lateral stress vanishes at the returned lateral stretch (to rounding of mu (t^2 - 1))
    assert abs(mu * (t - 1.0 / t) + lam * np.log(stretch * t * t) / t) <= 1e-14 * (mu + abs(lam))
    W, P, _ = stress_tangent_at(NEO_HOOKEAN, np.diag([stretch - 1.0, t - 1.0, t - 1.0]), mu, lam)
    assert P[0, 0] == pytest.approx(P11, rel=1e-12)
    assert np.max(np.abs(P[1:, 1:])) <= 1e-12 * abs(P11)
    assert np.all(P[0, 1:] == 0.0) and np.all(P[1:, 0] == 0.0)
    assert np.sign(P11) == np.sign(stretch - 1.0)
    if nu == 0.0:
        assert t == 1.0


def test_uniaxial_without_lateral_equilibrium_raises() -> None:
    """For nu = -0.5 (lam = -mu/2), mu (t^2 - 1) + lam ln(s t^2) has its minimum over t at
    t^2 = 1/2, where it is mu (-1/2 - ln(s/2)/2) > 0 for s = 0.6: no stress-free lateral state."""
    with pytest.raises(InputError, match="no laterally stress-free state"):
        uniaxial_stretch_neo_hookean(0.6, E, -0.5)


@pytest.mark.parametrize("nu", [0.0, 0.3, 0.49, -0.2])
@pytest.mark.parametrize("delta", [1e-7, -1e-7])
def test_uniaxial_small_stretch_gives_young_modulus(nu: float, delta: float) -> None:
    t, P11 = uniaxial_stretch_neo_hookean(1.0 + delta, E, nu)
    assert P11 / delta == pytest.approx(E, rel=1e-5)
    assert (t - 1.0) / -delta == pytest.approx(nu, abs=1e-5)


def test_von_mises() -> None:
    rng = np.random.default_rng(10)
    s = rng.normal(size=5) * 1e3
    uniaxial = np.zeros((5, 3, 3))
    uniaxial[:, 0, 0] = s
    np.testing.assert_allclose(von_mises(uniaxial), np.abs(s), rtol=1e-14)
    hydrostatic = s[:, None, None] * np.eye(3)
    assert np.all(np.abs(von_mises(hydrostatic)) <= 1e-12 * np.abs(s))
    shear = np.zeros((3, 3))
    shear[0, 1] = shear[1, 0] = 2.0
    assert von_mises(shear) == pytest.approx(np.sqrt(3.0) * 2.0, rel=1e-14)
    assert _k.von_mises(uniaxial[0]) == pytest.approx(abs(s[0]), rel=1e-14)


def test_lame_and_model_id() -> None:
    lam, mu = lame(E, NU)
    # one order everywhere: the case file's material gives the same named pair
    assert lame(E, NU) == Material("neo_hookean", E, NU).lame()
    assert (lame(E, NU).lam, lame(E, NU).mu) == (lam, mu)
    assert lam != mu and Lame(lam=1.0, mu=2.0) == (1.0, 2.0)
    assert mu == pytest.approx(E / (2 * (1 + NU)), rel=1e-15)
    assert lam == pytest.approx(E * NU / ((1 + NU) * (1 - 2 * NU)), rel=1e-15)
    # E = mu (3 lam + 2 mu) / (lam + mu)
    assert mu * (3 * lam + 2 * mu) / (lam + mu) == pytest.approx(E, rel=1e-14)
    assert model_id("linear_elastic") == LINEAR_ELASTIC
    assert model_id("neo_hookean") == NEO_HOOKEAN
    with pytest.raises(ValueError, match="mooney_rivlin"):
        model_id("mooney_rivlin")
    with pytest.raises(InputError):
        lame(E, 0.5)


def test_batch_matches_single_point() -> None:
    Hs = random_gradients(6, seed=11).reshape(2, 3, 3, 3)
    for model in MODELS.values():
        W, P = stress(model, Hs, MU, LAM)
        assert W.shape == (2, 3) and P.shape == (2, 3, 3, 3)
        for idx in np.ndindex(2, 3):
            W1, P1, _ = stress_tangent_at(model, Hs[idx], MU, LAM)
            assert W[idx] == W1
            np.testing.assert_array_equal(P[idx], P1)
