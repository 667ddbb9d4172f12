"""The solver's System with two bodies (no contact): block-diagonal tangent whose blocks are
the one-body tangents, a residual that splits, and a two-body solve equal to the two
one-body solves; in finite strain the tangent is the derivative of the residual."""

from __future__ import annotations

import math

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from cgfem.case.load import parse_case
from cgfem.run import build_models
from cgfem.solve.static import solve_static
from cgfem.solve.floating import FloatingBodies, free_rigid_modes, rotation_stretch, shift_factor
from cgfem.solve.policy import SolverPolicy
from cgfem.solve.system import System


def _pair(model: str, E_box: float, E_sphere: float):
    """A box clamped on xmin and pulled by a traction on xmax, and a sphere whose whole
    surface is held at a prescribed field, loaded by a body force; different materials."""
    data = {
        "name": "pair", "kinematics": "small" if model == "linear_elastic" else "finite", "steps": 1,
        "bodies": {
            "box": {"geometry": {"builder": "box", "min": [0, 0, 0], "max": [1.0, 0.6, 0.5]},
                    "material": {"model": model, "E": E_box, "nu": 0.3},
                    "grid": {"h0": 0.25, "offset": [0.13, 0.29, 0.41]}},
            "ball": {"geometry": {"builder": "sphere", "center": [2.0, 0.1, 0.2], "radius": 0.45},
                     "material": {"model": model, "E": E_sphere, "nu": 0.42},
                     "grid": {"h0": 0.2, "offset": [0.71, 0.37, 0.53]},
                     "body_force": ["0", "0", f"{-0.3 * E_sphere}*(1 + x)"]}},
        "boundary": [
            {"body": "box", "patches": ["xmin"], "type": "displacement", "components": {"x": 0, "y": 0, "z": 0}},
            {"body": "box", "patches": ["xmax"], "type": "traction",
             "value": [f"{0.05 * E_box}", f"{0.01 * E_box}*z", "0"]},
            {"body": "ball", "patches": ["surface"], "type": "displacement",
             "components": {"x": "0.01*y", "y": "-0.02*(z - 0.2)", "z": "0.005"}}],
        "solver": {"linear": "superlu", "outer_passes": 3, "outer_tol": 1e-300}}
    case = parse_case(data, Path("."))
    return case, build_models(case, 0, "nurbs_fe", lambda message: None)[0]


@pytest.fixture(scope="module")
def small_pair():
    return _pair("linear_elastic", 2.0e9, 5.0e8)


def assemble(system: System, u: np.ndarray, t: float, frozen: list, tangent: bool):
    """The system's residual and tangent with every body's recovered stress held at ``frozen``."""
    system.freeze(frozen)
    return system.assemble(u, t, tangent)


def _split_check(system: System, singles: list[System], u: np.ndarray, t: float, frozen: list):
    r, K = assemble(system, u, t, frozen, True)
    parts = [assemble(s, ub, t, [f], True) for s, ub, f in zip(singles, system.split(u), frozen)]
    # the residual splits, body by body, to the last bit
    assert np.array_equal(r, np.concatenate([p[0] for p in parts]))
    # the tangent is block diagonal and each block is the one-body tangent
    K = sp.csr_matrix(K)
    o = system.offsets
    for i, (a, b) in enumerate(zip(o[:-1], o[1:])):
        block = K[a:b][:, a:b]
        assert abs(block - parts[i][1]).max() == 0.0
        assert K[a:b].nnz == block.nnz                               # nothing outside the block
    return r, K


@pytest.mark.slow
def test_small_strain_pair_is_two_independent_bodies(small_pair):
    case, (box, ball) = small_pair
    system, singles = System([box, ball]), [System([box]), System([ball])]
    assert system.n_dofs == box.n_dofs + ball.n_dofs and box.n_dofs != ball.n_dofs
    rng = np.random.default_rng(4)
    u = 1e-3 * rng.normal(size=system.n_dofs)
    frozen = system.recover(u)
    for stress in ([None, None], frozen):
        _split_check(system, singles, u, 0.7, stress)

    # the two-body solution of a linear outer pass is the pair of one-body solutions
    def solve(sys_, stress):
        r, K = assemble(sys_, np.zeros(sys_.n_dofs), 1.0, stress, True)
        return spla.spsolve(sp.csc_matrix(K), -r)

    u2 = solve(system, [None, None])
    u_box, u_ball = solve(singles[0], [None]), solve(singles[1], [None])
    scale = np.abs(u2).max()
    assert scale > 1e-4                                              # the loads do something
    assert np.abs(u2 - np.concatenate([u_box, u_ball])).max() <= 1e-12 * scale
    # and the whole static solver (3 outer passes with the recovered stress) agrees
    both = solve_static(system, 1, case.solver).steps[-1].u
    one = [solve_static(s, 1, case.solver).steps[-1].u[0] for s in singles]
    for a, b in zip(both, one):
        assert np.abs(a - b).max() <= 1e-11 * np.abs(b).max()
    # the box's equilibrium: its support carries the traction resultant over the 0.6 x 0.5
    # face, (0.05 E, 0.01 E int z) = (3e7, 1.5e6) N
    step = solve_static(singles[0], 1, case.solver).steps[-1]
    reaction = box.reactions(step.u[0], 1.0, step.frozen_stress[0])["box/xmin"]
    assert np.abs(reaction[:2] + [3.0e7, 1.5e6]).max() <= 1e-8 * 3.0e7


def test_finite_strain_pair_tangent_is_the_derivative_of_the_residual():
    _, (box, ball) = _pair("neo_hookean", 3.0e6, 1.0e6)
    system = System([box, ball])
    rng = np.random.default_rng(8)
    # a finite deformation: a shear and stretch of each body plus noise
    u = []
    for body, G in zip((box, ball), ([[0.1, 0.15, 0.0], [0.0, -0.05, 0.0], [0.05, 0.0, 0.08]],
                                     [[-0.1, 0.0, 0.12], [0.06, 0.1, 0.0], [0.0, 0.0, 0.05]])):
        x = body.space.coordinates
        u.append((x @ np.array(G).T + 0.01 * rng.normal(size=x.shape)).reshape(-1))
    u = np.concatenate(u)
    frozen = system.recover(u)
    r, K = _split_check(system, [System([box]), System([ball])], u, 0.8, frozen)
    v = rng.normal(size=system.n_dofs)
    v /= np.abs(v).max()
    eps = 1e-6
    fd = (assemble(system, u + eps * v, 0.8, frozen, False)[0]
          - assemble(system, u - eps * v, 0.8, frozen, False)[0]) / (2 * eps)
    Kv = K @ v
    assert np.linalg.norm(fd - Kv) <= 1e-8 * np.linalg.norm(Kv)   # measured 1e-10
    # the check can fail: the tangent of the wrong material point is far off
    assert np.linalg.norm(fd - assemble(System([box, ball]), 0 * u, 0.8, frozen, True)[1] @ v) \
        > 1e-2 * np.linalg.norm(Kv)


def test_an_assembly_at_the_same_unknowns_reuses_the_bodies_tangent_bit_for_bit():
    """The bodies' tangent depends on the unknowns alone, not on the load factor or the
    frozen stress: a new outer pass that starts where the last one ended reuses it, and gets
    the residual and tangent a fresh system assembles, to the last bit."""
    _, (box, ball) = _pair("neo_hookean", 3.0e6, 1.0e6)
    rng = np.random.default_rng(3)
    n = box.n_dofs + ball.n_dofs
    u, v = 1e-3 * rng.normal(size=n), 1e-3 * rng.normal(size=n)
    system = System([box, ball])
    frozen_a = system.recover(u)
    frozen_b = [2.0 * f for f in system.recover(v)]
    assemble(system, u, 0.8, frozen_a, True)
    kept = system._bodies_tangent[1]
    cases = [(u, 0.5, frozen_b, True), (v, 0.5, frozen_b, False), (v, 1.0, frozen_a, True)]
    for x, t, frozen, reused in cases:
        r, K = assemble(system, x, t, frozen, True)
        r_fresh, K_fresh = assemble(System([box, ball]), x, t, frozen, True)
        assert (system._bodies_tangent[1] is kept) == reused
        kept = system._bodies_tangent[1]
        assert np.array_equal(r, r_fresh)
        for name in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(K, name), getattr(K_fresh, name)), name


@pytest.mark.parametrize("components, free", [({"x": 0, "y": 0, "z": 0}, 0), ({"x": 0, "y": 0}, 1), (None, 6)])
def test_free_rigid_modes_of_a_body(components, free):
    """A box on face xmin: clamped holds every rigid motion; held along x and y only it
    keeps the z translation free (every rotation moves the face along x or y); without
    conditions all six are free: the bodies contact must hold (tangent shift)."""
    data = {"name": "free", "kinematics": "small", "steps": 1,
            "bodies": {"box": {"geometry": {"builder": "box", "min": [0, 0, 0], "max": [1.0, 0.6, 0.5]},
                               "material": {"model": "linear_elastic", "E": 1e9, "nu": 0.3},
                               "grid": {"h0": 0.25, "offset": [0.13, 0.29, 0.41]}}},
            "boundary": [] if components is None else
            [{"body": "box", "patches": ["xmin"], "type": "displacement", "components": components}]}
    case = parse_case(data, Path("."))
    body = build_models(case, 0, "nurbs_fe", lambda message: None)[0][0]
    _, K = body.assemble(np.zeros(body.n_dofs), 1.0, None, True)
    assert free_rigid_modes(body.space.coordinates, sp.csr_matrix(K), SolverPolicy().free_mode) == free


def test_fading_shift_restores_fast_convergence_on_a_soft_mode():
    """A soft mode of stiffness k under a tangent shift s converges at the rate s / (k + s)
    per Newton iteration: with s = 10 k (chain3's middle link at level 2 had k / s ~ 0.09)
    a fixed shift needs over 250 iterations to 1e-12; the shift scaled by shift_factor fades
    with the residual and gets there in 18 (the policy's shift_floor sets the final rate, 1e-3)."""
    from cgfem.solve.newton import newton
    assert shift_factor(5.0, 5.0) == 1.0 and shift_factor(1.0, 0.0) == 1.0
    assert shift_factor(1e-3, 1.0) == pytest.approx(1e-3) and shift_factor(1e-9, 1.0) == SolverPolicy().shift_floor
    k, s, f = 1.0, 10.0, 1.0

    def solve(fading):
        largest = [0.0]

        def assemble(u, tangent):
            r = np.array([k * u[0] - f])
            norm = float(np.abs(r[0]))
            largest[0] = max(largest[0], norm)
            factor = shift_factor(norm, largest[0]) if fading else 1.0
            return r, np.array([[k + factor * s]])
        return newton(assemble, np.zeros(1), lambda K, b: np.linalg.solve(K, b), tol=1e-12, reference=1.0,
                      max_iter=400)
    fixed, fading = solve(False), solve(True)
    assert fixed.converged and len(fixed.residuals) - 1 > 250
    assert fading.converged and len(fading.residuals) - 1 < 25           # 18 measured
    np.testing.assert_allclose(fading.u, [f / k], rtol=1e-12)


def free_box():
    """A box without conditions (six free rigid motions) at level 0, h = 0.25 m."""
    data = {"name": "free", "kinematics": "small", "steps": 1,
            "bodies": {"box": {"geometry": {"builder": "box", "min": [0, 0, 0], "max": [1.0, 0.6, 0.5]},
                               "material": {"model": "linear_elastic", "E": 1e9, "nu": 0.3},
                               "grid": {"h0": 0.25, "offset": [0.13, 0.29, 0.41]}}},
            "boundary": []}
    return build_models(parse_case(data, Path(".")), 0, "nurbs_fe", lambda message: None)[0][0]


def test_step_limit_of_a_floating_body_adapts_its_shift():
    """A Newton step moving a body held by contact alone by 10 h is scaled to 1 h
    (the policy's floating_step), and the body's tangent shift is raised 10-fold for the next iterations
    (a Levenberg-Marquardt damping of its soft rigid motions); steps within the limit are
    kept as they are and lower the damping by damping_decay, down to 1; near convergence
    (residual below damping_above of the increment's largest) a limited step lowers it too.
    The turn limit (floating_turn, off here) is tested by the next test."""
    policy = SolverPolicy(floating_turn=math.inf)
    FLOATING_STEP, DAMPING_DECAY, DAMPING_ABOVE = policy.floating_step, policy.damping_decay, policy.damping_above
    body = free_box()
    floating = FloatingBodies(np.array([0, body.n_dofs]), [body.space.h], [body.space.coordinates], policy)
    floating.bodies = [0]
    h = body.space.h
    du = np.zeros(body.n_dofs)
    du[0::3] = 10.0 * FLOATING_STEP * h                      # a rigid x translation of 10 h
    limited = floating.limit(du)
    np.testing.assert_allclose(limited, 0.1 * du, rtol=1e-14)
    assert floating.damping == pytest.approx(10.0)
    small = 0.5 * FLOATING_STEP * h * np.ones(body.n_dofs)
    assert floating.limit(small) is small
    assert floating.damping == pytest.approx(10.0 * DAMPING_DECAY)
    for _ in range(5):
        floating.limit(small)
    assert floating.damping == 1.0
    floating.damping, floating._fading = 8.0, 0.5 * DAMPING_ABOVE
    np.testing.assert_allclose(floating.limit(du), 0.1 * du, rtol=1e-14)
    assert floating.damping == pytest.approx(8.0 * DAMPING_DECAY)


def test_step_limit_of_a_floating_body_bounds_its_turn():
    """Where ``floating_turn`` times the body's radius (the RMS distance of its nodes to their
    centroid) is below ``floating_step`` element sizes, a floating body's step is limited to
    that: a rigid turn of 1 rad about z is scaled to about floating_turn rad, so that no node
    moves by more than floating_turn times the radius."""
    policy = SolverPolicy()
    body = free_box()
    x = body.space.coordinates
    floating = FloatingBodies(np.array([0, body.n_dofs]), [body.space.h], [x], policy)
    floating.bodies = [0]
    radius = float(np.sqrt(((x - x.mean(axis=0)) ** 2).sum(axis=1).mean()))
    assert floating.radius[0] == pytest.approx(radius)
    assert policy.floating_turn * radius < policy.floating_step * body.space.h
    du = np.cross([0.0, 0.0, 1.0], x - x.mean(axis=0)).ravel()      # a linearized turn of 1 rad
    limited = floating.limit(du)
    assert np.abs(limited).max() == pytest.approx(policy.floating_turn * radius, rel=1e-12)
    np.testing.assert_allclose(limited, np.abs(limited).max() / np.abs(du).max() * du, rtol=1e-14)


def test_cut_rotation_minimizes_the_quadratic_model_at_the_cut_turn():
    """A step that turns a floating body by more than ``floating_rotation`` is replaced by the
    minimizer of Newton's quadratic model ``du^T K du / 2 + r^T du`` among the steps with the
    rotation scaled to ``floating_rotation``: its rotation is that, and ``K du + r`` lies in
    the span of the rotation rows (the constraint's multipliers). A step within it is kept;
    so is every step far from a solution (residual above ``rotation_cut_below`` of the
    increment's largest), of elements below ``rotation_cut_min_order`` and of a body whose spin
    is held (``held``). The body's own
    stiffness with a weak spring on every dof stands in for the shifted tangent of a body
    held by contact alone (its rigid motions nearly free)."""
    from cgfem.solve.floating import rigid_fit_rows
    policy = SolverPolicy(floating_turn=math.inf, floating_step=math.inf)
    body = free_box()
    x = body.space.coordinates
    stiffness = body.assemble(np.zeros(body.n_dofs), 1.0, None)[1]
    K = (stiffness + 1e-6 * abs(stiffness.diagonal()).mean() * sp.identity(body.n_dofs)).tocsc()
    factor = spla.splu(K)
    rng = np.random.default_rng(7)
    spin = np.cross([0.3, 0.2, 1.0], x - x.mean(axis=0)).ravel()
    r = -(K @ spin) - 1e-3 * np.abs(K @ spin).max() * rng.standard_normal(body.n_dofs)
    du0 = factor.solve(-r)
    rows = rigid_fit_rows(x)[3:]
    assert np.linalg.norm(rows @ spin) == pytest.approx(np.linalg.norm([0.3, 0.2, 1.0]), rel=1e-12)
    assert np.linalg.norm(rows @ du0) > policy.floating_rotation

    def floating_at(residual: float, order: int, held: frozenset[int] = frozenset()) -> FloatingBodies:
        """A floating body whose increment's largest residual is 1, at ``residual``."""
        floating = FloatingBodies(np.array([0, body.n_dofs]), [body.space.h], [x], policy, order, held)
        floating.bodies = [0]
        floating.shifted(K, 1.0, 1.0)
        floating.shifted(K, 1.0, residual)
        return floating
    near = 0.5 * policy.rotation_cut_below
    cut = floating_at(near, 2).limit(du0, factor.solve)
    omega0, omega = rows @ du0, rows @ cut
    np.testing.assert_allclose(omega, omega0 * policy.floating_rotation / np.linalg.norm(omega0), rtol=1e-8)
    gradient = K @ cut + r
    multipliers = np.linalg.lstsq(rows.T, gradient, rcond=None)[0]
    assert np.linalg.norm(gradient - rows.T @ multipliers) <= 1e-8 * np.linalg.norm(r)
    small = 0.5 * policy.floating_rotation / np.linalg.norm(omega0) * du0
    assert floating_at(near, 2).limit(small, factor.solve) is small
    assert floating_at(2.0 * policy.rotation_cut_below, 2).limit(du0, factor.solve) is du0
    assert floating_at(near, 1).limit(du0, factor.solve) is du0
    # a body whose spin a spring holds (bodies.<name>.hold_spin) keeps its turns
    assert floating_at(near, 2, frozenset({0})).limit(du0, factor.solve) is du0


def test_rotation_stretch_of_a_turned_and_strained_body():
    """A body turned (linearized) by omega = 0.05 rad about z and strained by 1e-3 along y,
    held at two points 0.4 m apart along y: the turn stretches their chord by
    |omega x d|^2 / (2 |d|) = 5e-4 m, which an exact turn would not, the strain by 4e-4 m;
    both read to 1 % (the points' reference positions are recovered to first order), with the
    sum of the gaps at the chord's ends."""
    body = free_box()
    x = body.space.coordinates
    c = x.mean(axis=0)
    omega, strain = np.array([0.0, 0.0, 0.05]), 1e-3

    def displacement(X):
        r = X - c
        return np.cross(omega, r) + strain * r[:, 1:2] * np.array([0.0, 1.0, 0.0])
    u = displacement(x).ravel()
    X = np.array([[0.5, 0.1, 0.25], [0.5, 0.5, 0.25]])
    turn, spurious, elastic, room = rotation_stretch(body.space, u, X + displacement(X), [1e-4, 2e-4])
    assert turn == pytest.approx(0.05, rel=1e-10)
    assert spurious == pytest.approx((0.05 * 0.4) ** 2 / 0.8, rel=1e-2)
    assert elastic == pytest.approx(strain * 0.4, rel=1e-2)
    assert room == pytest.approx(3e-4)


def test_the_policy_sets_the_held_spins_spring(small_pair):
    """``spin_stiffness`` is the spring per node over ``E h``: a system given ten times the
    default holds the ball's spin ten times as stiffly, with the same measure of the spin."""
    case, (box, ball) = small_pair
    holds = {"ball": ((1.0, 0.0, 0.0), 5.0e8)}
    default = System([box, ball], holds=holds).springs
    stiffer = System([box, ball], policy=SolverPolicy(spin_stiffness=10.0 * SolverPolicy().spin_stiffness),
                     holds=holds).springs
    assert len(default) == len(stiffer) == 1 and default[0].stiffness > 0.0
    assert stiffer[0].stiffness == pytest.approx(10.0 * default[0].stiffness, rel=1e-12)
    np.testing.assert_array_equal(stiffer[0].g, default[0].g)
