"""The spring on a body's spin (cgfem.solve.spin): it measures a rigid spin exactly and
nothing else of a rigid motion, its tangent is its residual's derivative, and a case holds it
by name."""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.case import parse_case, parse_yaml
from cgfem.contact.assembly import couplings_matrix
from cgfem.solve.floating import rigid_fit_rows
from cgfem.solve.policy import DEFAULT_POLICY
from cgfem.solve.spin import SPIN_NODES, SpinSpring, spin_nodes, unit_axis
from tests.support.paths import CASES


def torus_nodes(axis: np.ndarray, R: float = 0.02, r: float = 0.005, n: int = 4000,
                seed: int = 3) -> np.ndarray:
    """Points filling a torus about ``axis`` through (0.1, -0.2, 0.3)."""
    rng = np.random.default_rng(seed)
    phi, psi = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 2 * np.pi, n)
    rho = r * np.sqrt(rng.uniform(0, 1, n))
    local = np.column_stack([(R + rho * np.cos(psi)) * np.cos(phi), (R + rho * np.cos(psi)) * np.sin(phi),
                             rho * np.sin(psi)])
    a = unit_axis(axis)
    e1 = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    frame = np.column_stack([e1, np.cross(a, e1), a])
    return local @ frame.T + np.array([0.1, -0.2, 0.3])


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = unit_axis(axis)
    A = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * A + (1 - np.cos(angle)) * A @ A


AXIS = np.array([1.0, 2.0, -0.5])


def test_nodes_are_spread_around_the_axis_and_far_from_it():
    X = torus_nodes(AXIS)
    nodes = spin_nodes(X, AXIS)
    assert len(nodes) == SPIN_NODES                         # a torus fills every sector
    assert np.array_equal(nodes, np.unique(nodes))
    a = unit_axis(AXIS)
    r = X - X.mean(axis=0)
    distance = np.linalg.norm(r - np.outer(r @ a, a), axis=1)
    assert distance[nodes].min() >= np.quantile(distance, 0.7)
    assert np.array_equal(nodes, spin_nodes(X.copy(), 3.0 * AXIS))   # the axis's length is no matter


def test_a_linearized_spin_is_measured_exactly_and_other_rigid_motions_not_at_all():
    X = torus_nodes(AXIS)
    spring = SpinSpring("ring", 6, X, AXIS, E=2e11, h=0.004)
    c = X[spin_nodes(X, AXIS)].mean(axis=0)
    a = unit_axis(AXIS)
    u = np.zeros(6 + X.size + 5)

    def put(U):
        u[6:6 + X.size] = U.ravel()
        return u

    assert spring.angle(put(1e-3 * np.cross(a, X - c))) == pytest.approx(1e-3, rel=1e-12)
    # a turn about a perpendicular axis through any point, and a translation
    b = np.cross(a, [0.3, -0.1, 0.7])
    assert abs(spring.angle(put(np.cross(b, X - [1.0, 2.0, 3.0]) + [0.2, -0.1, 0.4]))) <= 1e-14
    # a finite rotation about the axis: sin(theta), up to what the fit of its inward part
    # (1 - cos theta) a x (a x r) leaves on a cloud not quite symmetric about the axis
    theta = 0.3
    assert spring.angle(put((X - c) @ rotation(a, theta).T - (X - c))) == pytest.approx(np.sin(theta), rel=1e-6)


def test_residual_is_the_energy_gradient_and_the_tangent_its_derivative():
    X = torus_nodes(AXIS, n=600)
    spring = SpinSpring("ring", 3, X, AXIS, E=1e9, h=0.01)
    rng = np.random.default_rng(7)
    n = 3 + X.size + 2
    u, v = rng.normal(size=n) * 1e-3, rng.normal(size=n) * 1e-3
    r = np.zeros(n)
    K = couplings_matrix([spring.add(u, 1.0, r, True)], n).tocsr()
    energy = lambda w: 0.5 * spring.stiffness * spring.angle(w) ** 2
    eps = 1e-6
    slope = (energy(u + eps * v) - energy(u - eps * v)) / (2 * eps)
    assert r @ v == pytest.approx(slope, rel=1e-8)
    r_v = np.zeros(n)
    spring.add(u + v, 1.0, r_v, False)
    assert np.allclose(r_v - r, K @ v, rtol=0, atol=1e-12 * np.abs(r_v - r).max())   # linear: exact
    assert abs((K - K.T)).max() == 0.0
    outside = np.ones(n, bool)
    outside[spring.dofs] = False
    assert not r[outside].any()


def test_stiffness_is_the_nodal_stiffness_on_the_chosen_nodes():
    X = torus_nodes(AXIS)
    spring = SpinSpring("ring", 0, X, AXIS, E=2e11, h=0.004)
    Xs = X[spin_nodes(X, AXIS)]
    r = Xs - Xs.mean(axis=0)
    a = unit_axis(AXIS)
    perp2 = np.sum(r ** 2) - np.sum((r @ a) ** 2)
    assert spring.stiffness == pytest.approx(DEFAULT_POLICY.spin_stiffness * 2e11 * 0.004 * perp2, rel=1e-12)
    assert SpinSpring("ring", 0, X, AXIS, E=2e11, h=0.004, stiffness=0.5).stiffness == pytest.approx(
        0.5 * 2e11 * 0.004 * perp2, rel=1e-12)
    assert np.allclose(spring.g, a @ rigid_fit_rows(Xs)[3:])


def test_the_chain_holds_its_middle_links_spin():
    """chain3's middle link, a full torus about x held by contact alone, has its spin held."""
    case = parse_case(parse_yaml((CASES / "chain3.yaml").read_text()), CASES)
    assert case.body("link_c").hold_spin == (1.0, 0.0, 0.0)
    assert case.body("link_a").hold_spin is None and case.body("link_b").hold_spin is None
