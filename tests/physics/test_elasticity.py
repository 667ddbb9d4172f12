"""Elasticity on cut grids: assembly, patch test, Neo-Hookean tangent and closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from cgfem.embedding.quadrature import embed, grid_for
from cgfem.fem.assembly import build_pattern
from cgfem.fem.elasticity import reference_matrix
from cgfem.fem.materials import uniaxial_stretch_neo_hookean
from cgfem.fem.space import Space
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import SphereSpec
from cgfem.run import build_models
from cgfem.solve.linear import rigid_body_modes
from cgfem.solve.static import solve_static
from cgfem.solve.system import System
from tests.support.elasticity_cases import box_case, uniform_stress_case
from tests.support.newton import record_errors


def _solve(case, level=0, surface="nurbs_fe", order=1):
    models, _ = build_models(case, level, surface, lambda m: None, order)
    system = System(models)
    return system, solve_static(system, case.steps, case.solver)


@pytest.fixture(scope="module")
def sphere_space():
    solid = build_solid(SphereSpec(center=(0.0, 0.0, 0.0), radius=1.0))
    emb = embed(solid, grid_for(solid, 0.5, 0, (0.13, 0.29, 0.41)))
    return emb, Space.from_embedding(emb)


def test_pattern_positions_assemble_like_coo(sphere_space):
    _, space = sphere_space
    pattern = build_pattern(space)
    rng = np.random.default_rng(1)
    ke = rng.standard_normal((space.n_elements, 24, 24))
    data = pattern.zeros()
    np.add.at(data, pattern.scatter.ravel(), ke.ravel())
    dofs = space.element_dofs
    rows = np.broadcast_to(dofs[:, :, None], ke.shape).ravel()
    cols = np.broadcast_to(dofs[:, None, :], ke.shape).ravel()
    reference = sp.coo_matrix((ke.ravel(), (rows, cols)), shape=(space.n_dofs,) * 2).tocsr()
    K = pattern.matrix(data)
    assert abs(K - reference).max() < 1e-13
    # the matrix shares the pattern's index arrays: scipy does not copy them for every matrix
    assert np.shares_memory(K.indices, pattern.indices) and np.shares_memory(K.indptr, pattern.indptr)
    # colours: no two elements of one colour share a node
    for elements in pattern.colours:
        nodes = space.connectivity[elements].ravel()
        assert np.unique(nodes).size == nodes.size


def test_reference_matrix_is_symmetric_with_rigid_modes_as_kernel():
    from cgfem.fem._material_kernels import LINEAR_ELASTIC, tangent_batch

    A = tangent_batch(LINEAR_ELASTIC, np.zeros((1, 3, 3)), 0.7, 1.3)[2][0]
    h = 0.37
    ke = reference_matrix(A, h)
    from cgfem.fem.space import NODE_XI
    modes = rigid_body_modes(0.5 * h * NODE_XI)
    assert np.abs(ke - ke.T).max() < 1e-14 * np.abs(ke).max()
    assert np.abs(ke @ modes).max() < 1e-13 * np.abs(ke).max()
    eig = np.linalg.eigvalsh(ke)
    assert np.sum(eig > 1e-10 * eig.max()) == 18          # 24 dofs - 6 rigid modes


def test_stiffness_energy_of_linear_fields_is_exact_on_cut_sphere():
    """u^T K u = V sigma:eps for u = G x: the cut-cell rule is exact for the integrand and
    the ghost penalty vanishes on linear fields."""
    case, _ = uniform_stress_case(np.diag([1.0, 2.0, 3.0]), 1.0, 0.3, (0.1, 0.2, 0.3))
    models, measures = build_models(case, 1, "nurbs_fe", lambda m: None)
    model = models[0]
    assert model.ghost.nnz > 0
    rng = np.random.default_rng(2)
    G = rng.standard_normal((3, 3))
    u = (model.space.coordinates @ G.T).ravel()
    r = np.zeros(model.n_dofs)
    model.elasticity.add(u, r, None)
    el = model.elasticity
    eps = 0.5 * (G + G.T)
    sig = el.lam * np.trace(eps) * np.eye(3) + 2 * el.mu * eps
    exact = measures["b"]["brep_volume"] * np.sum(sig * eps)
    assert abs(u @ r - exact) < 1e-10 * abs(exact)
    assert np.abs(model.ghost @ u).max() < 1e-12 * np.abs(r).max()


@pytest.mark.slow
@pytest.mark.parametrize("seed, order", [(0, 1), (1, 1), (0, 2)])
def test_patch_test_reproduces_uniform_stress(seed, order):
    rng = np.random.default_rng(seed)
    sigma = rng.standard_normal((3, 3)) * 1e6
    sigma = 0.5 * (sigma + sigma.T)
    # Newton to 1e-11: the patch test checks consistency, not the solver's tolerance (at the
    # default 1e-9 the order-2 recovered stress is off by 1.6e-8, round-off times the
    # condition; at 1e-11 by 1.3e-10)
    case, eps = uniform_stress_case(sigma, 2.0e9, 0.3, rng.uniform(0, 1, 3), solver={"newton_tol": 1e-11})
    system, result = _solve(case, order=order)
    assert result.status == "converged"
    model, step = system.bodies[0], result.steps[-1]
    u = step.u[0].reshape(-1, 3)
    exact = model.space.coordinates @ eps.T
    assert np.abs(u - exact).max() < 1e-8 * np.abs(exact).max()
    assert np.abs(step.recovered[0] - sigma).max() < 1e-8 * np.abs(sigma).max()
    stress_h = model.elasticity.stress(step.u[0])
    assert np.abs(stress_h - sigma).max() < 1e-8 * np.abs(sigma).max()
    # reaction on the three constrained faces: -(sigma n) integrated = -sum of sigma e_a
    reaction = model.reactions(step.u[0], 1.0, step.frozen_stress[0])["b/xmin+ymin+zmin"]
    assert np.allclose(reaction, -sigma.sum(axis=1), rtol=0, atol=1e-8 * np.abs(sigma).max())
    assert step.outer_passes < 20


def _neo_hookean_box(boundary, steps=1, **kw):
    return box_case(boundary, material={"model": "neo_hookean", "E": 1.0e6, "nu": 0.3},
                    kinematics="finite", steps=steps, **kw)


@pytest.mark.parametrize("order", [1, 2])
def test_neo_hookean_tangent_matches_finite_differences(order):
    case = _neo_hookean_box([{"patches": ["xmin"], "type": "displacement",
                              "components": {"x": "0.1*y", "y": "0.05*z*z", "z": "0"}},
                             {"patches": ["zmax"], "type": "traction", "value": ["1e4", "0", "-2e4*x"]}],
                            offset=(0.31, 0.77, 0.52))
    models, _ = build_models(case, 0, "nurbs_fe", lambda m: None, order)
    model = models[0]
    rng = np.random.default_rng(3)
    x = model.space.coordinates
    stress = rng.standard_normal((model.space.n_nodes, 3, 3)) * 1e4
    for _ in range(3):
        G = rng.standard_normal((3, 3)) * 0.15
        # noise of 0.02 (0.01 between the quadratic nodes, half as far apart): no point inverted
        u = (x @ G.T).ravel() + 0.02 / order * rng.standard_normal(model.n_dofs)
        r, K = model.assemble(u, 0.7, stress)
        d = rng.standard_normal(model.n_dofs)
        eps = 1e-6
        fd = (model.assemble(u + eps * d, 0.7, stress, False)[0]
              - model.assemble(u - eps * d, 0.7, stress, False)[0]) / (2 * eps)
        assert np.linalg.norm(K @ d - fd) < 1e-6 * np.linalg.norm(fd)
    assert abs(K - K.T).max() < 1e-10 * abs(K).max()


@pytest.mark.slow
#: tension at order 2 with ``-m long``: order 1's tension and order 2's compression cover both
@pytest.mark.parametrize("stretch, order", [(1.5, 1), pytest.param(1.5, 2, marks=pytest.mark.long), (0.8, 2)])
def test_uniaxial_stretch_matches_closed_form_and_newton_is_quadratic(stretch, order, monkeypatch):
    """Uniaxial tension and compression of an immersed Neo-Hookean box: the displacement and
    the reaction are the closed form's, and Newton's map is quadratic at the solution
    (measured on the error along the solve's last direction, :mod:`tests.support.newton`)."""
    solves = record_errors(monkeypatch)
    E, nu = 1.0e6, 0.3
    case = _neo_hookean_box([
        {"patches": ["xmin"], "type": "displacement", "components": {"x": "0"}},
        {"patches": ["ymin"], "type": "displacement", "components": {"y": "0"}},
        {"patches": ["zmin"], "type": "displacement", "components": {"z": "0"}},
        {"patches": ["xmax"], "type": "displacement", "components": {"x": repr(stretch - 1.0)}}],
        steps=1, solver={"newton_tol": 1e-12, "outer_tol": 1e-11})
    system, result = _solve(case, order=order)
    assert result.status == "converged"
    model, step = system.bodies[0], result.steps[-1]
    lateral, nominal = uniaxial_stretch_neo_hookean(stretch, E, nu)
    reaction = model.reactions(step.u[0], 1.0, step.frozen_stress[0])["b/xmax"]
    assert abs(reaction[0] - nominal * 1.0) < 1e-8 * abs(nominal)      # reference area 1 m^2
    u = step.u[0].reshape(-1, 3)
    x = model.space.coordinates
    expected = x * np.array([stretch - 1.0, lateral - 1.0, lateral - 1.0])
    assert np.abs(u - expected).max() < 1e-10        # measured 4e-14
    # quadratic convergence: the first pass of the step starts far from the solution
    first = result.steps[-1].newton_residuals[0]
    assert len(first) >= 5
    orders = [s["order"] for s in solves if np.isfinite(s["order"])]
    assert orders and min(orders) >= 1.9, orders


@pytest.mark.slow
def test_rigid_rotation_imposed_weakly_is_stress_free():
    E = 1.0e6
    # u = (R - I) x for a 90 degree rotation about z through the origin
    case = _neo_hookean_box([{"patches": ["xmin", "ymin"], "type": "displacement",
                              "components": {"x": "-y - x", "y": "x - y", "z": "0"}}],
                            steps=6, solver={"newton_tol": 1e-12, "outer_tol": 1e-12})
    system, result = _solve(case)
    assert result.status == "converged"
    model, step = system.bodies[0], result.steps[-1]
    P = model.elasticity.stress(step.u[0])
    assert np.abs(P).max() < 1e-8 * E
    assert np.abs(step.recovered[0]).max() < 1e-8 * E


@pytest.mark.slow
def test_reactions_balance_body_force_and_tractions_exactly():
    """Translation invariance of the bulk and ghost terms: the support reaction equals minus
    the resultant of the dead loads, whatever the recovered stress."""
    case = box_case([{"patches": ["zmin"], "type": "displacement", "components": {"x": "0", "y": "0", "z": "0"}},
                     {"patches": ["zmax"], "type": "traction", "value": ["1e4*x", "0", "-2e4*y*y"]}],
                    material={"model": "linear_elastic", "E": 1.0e9, "nu": 0.3}, offset=(0.7, 0.1, 0.45),
                    solver={"outer_passes": 3})
    import dataclasses

    from cgfem.case.expressions import as_vector_expression
    body = dataclasses.replace(case.bodies[0], body_force=as_vector_expression(["0", "3e3", "-7.8e4*(1+z)"], "bf"))
    case = dataclasses.replace(case, bodies=(body,))
    system, result = _solve(case)
    step = result.steps[-1]
    reaction = system.bodies[0].reactions(step.u[0], 1.0, step.frozen_stress[0])["b/zmin"]
    # resultants over the unit box: body force (0, 3e3, -7.8e4 * 1.5), traction (0.5e4, 0, -2e4/3)
    loads = np.array([0.5e4, 3e3, -7.8e4 * 1.5 - 2e4 / 3])
    assert np.allclose(reaction, -loads, rtol=0, atol=1e-9 * np.abs(loads).max())


def test_reference_matrix_equals_the_independent_voigt_brick():
    """Our tensor-form element kernel against the Voigt B^T D B brick of the solver fixture."""
    from tests.support import elasticity_fixture as fx
    from cgfem.fem._material_kernels import LINEAR_ELASTIC, tangent_batch

    E, nu, h = 2.5, 0.27, 0.4
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    A = tangent_batch(LINEAR_ELASTIC, np.zeros((1, 3, 3)), mu, lam)[2][0]
    ke = reference_matrix(A, h)
    assert np.abs(ke - fx.brick_stiffness(h, E, nu)).max() < 1e-14 * np.abs(ke).max()


class _OneDof:
    """A system of one unknown for the load-step control's tests, whose increments are
    scripted (``solve_increment`` replaced): the attributes the linear solves ask for."""

    n_dofs, symmetric, indefinite, bodies, order = 1, True, False, [None], 1

    def __init__(self, policy=None):
        from cgfem.solve.policy import SolverPolicy

        self.policy = policy or SolverPolicy()

    def split(self, u):
        return [u]

    def saddle(self):
        return None

    def near_null(self):
        return np.ones((1, 1))

    def held_by_contact_alone(self):
        return False

    def adopt(self, policy):
        self.policy = policy

    def saved(self):
        return []

    def restore(self, saved):
        pass


def test_cut_back_reaches_the_step_in_equal_sub_steps(monkeypatch):
    """An increment that fails is halved until it succeeds; the rest of the step is then
    taken in sub-steps of that size (not ever smaller ones)."""
    import cgfem.solve.static as static
    from cgfem.case.model import SolverOptions
    from cgfem.solve.outer import Increment, IncrementFailure

    taken = []

    def increment(system, solves, u, stress, t, options, log, guess=None):
        if t - (taken[-1] if taken else 0.0) > 0.3:
            return IncrementFailure("max_iterations", 1, 0.5, 30)   # too large an increment
        taken.append(t)
        return Increment(u, stress, stress, [[1.0, 0.0]], [0.0], True)

    monkeypatch.setattr(static, "solve_increment", increment)
    result = static.solve_static(_OneDof(), 1, SolverOptions(max_cutbacks=2))
    assert result.status == "converged"
    assert taken == pytest.approx([0.25, 0.5, 0.75, 1.0])
    taken.clear()
    result = static.solve_static(_OneDof(), 1, SolverOptions(max_cutbacks=1))
    assert result.status == "failed" and taken == []
    assert result.failure == IncrementFailure("max_iterations", 1, 0.5, 30)
    assert result.message.endswith("after 1 cut-backs (last attempt: Newton stopped on max_iterations in "
                                   "outer pass 1 at |r|/ref = 5.00e-01 after 30 iterations)")


def test_a_step_that_fails_is_tried_again_with_each_fallback(monkeypatch):
    """A step that fails after its cut-backs is solved again from where it started (here
    0.5, the first of two steps) with the policy's fallbacks in turn, each the run's own
    constants with its group changed; the sub-steps the failed attempt converged are dropped
    (``on_drop`` hears how many records stay); the run keeps the fallback that converged and
    each step records it. A fallback of floating constants only is skipped where no body
    floats; when every fallback fails the message says so."""
    import cgfem.solve.static as static
    from dataclasses import replace
    from cgfem.case.model import SolverOptions
    from cgfem.solve.outer import Increment, IncrementFailure
    from cgfem.solve.policy import SolverPolicy

    calls, drops = [], []

    def increment(system, solves, u, stress, t, options, log, guess=None, loose=True):
        calls.append((t, system.policy.floating_search, system.policy.acceleration))
        works = system.policy.acceleration == "anderson" or t <= 0.75
        if not works:
            return IncrementFailure("line_search", 1, 1e-3, 3)
        return Increment(u, stress, stress, [[1.0, 0.0]], [0.0], True)

    monkeypatch.setattr(static, "solve_increment", increment)
    policy = replace(SolverPolicy(), fallbacks="floating_search=energy; acceleration=anderson")
    lines: list[str] = []
    result = static.solve_static(_OneDof(policy), 2, SolverOptions(max_cutbacks=1), log=lines.append,
                                 on_drop=drops.append)
    assert result.status == "converged"
    assert calls == [(0.5, "residual", "aitken"), (1.0, "residual", "aitken"), (0.75, "residual", "aitken"),
                     (1.0, "residual", "aitken"), (1.0, "residual", "anderson")]
    assert [(s.load_factor, s.fallback) for s in result.steps] == [(0.5, 0), (1.0, 2)]
    assert drops == [1]
    assert any(line.endswith("fallback 2: the step again from load factor 0.5 (1 converged sub-step(s) "
                             "dropped) with acceleration=anderson") for line in lines)

    class Floating(_OneDof):
        def held_by_contact_alone(self):
            return True

    calls.clear()
    policy = replace(SolverPolicy(), fallbacks="floating_search=energy; floating_turn=0.02")
    result = static.solve_static(Floating(policy), 2, SolverOptions(max_cutbacks=0))
    assert result.status == "failed" and [s.load_factor for s in result.steps] == [0.5]
    assert [c[:2] for c in calls] == [(0.5, "residual"), (1.0, "residual"), (1.0, "energy"), (1.0, "residual")]
    assert "after 0 cut-backs and 2 fallback(s) (last attempt: Newton stopped on line_search" in result.message
    calls.clear()
    result = static.solve_static(_OneDof(policy), 2, SolverOptions(max_cutbacks=0))
    assert result.status == "failed" and len(calls) == 2 and "fallback" not in result.message


def test_a_state_rejected_for_a_turn_goes_to_the_next_fallback_without_cut_backs(monkeypatch):
    """A state rejected because a floating body turned is not cut back while a fallback is
    left: the step is tried again at once with the next fallback (logged with the rejection);
    with none left it is cut back as any failure."""
    import cgfem.solve.static as static
    from dataclasses import replace
    from cgfem.case.model import SolverOptions
    from cgfem.solve.outer import Increment, IncrementFailure
    from cgfem.solve.policy import SolverPolicy

    calls = []

    def increment(system, solves, u, stress, t, options, log, guess=None, loose=True):
        calls.append((t, system.policy.floating_search))
        if system.policy.floating_search == "energy" or t <= 0.5:
            return Increment(u, stress, stress, [[1.0, 0.0]], [0.0], True)
        return IncrementFailure("rejected", 2, 0.0, 4, rejected="link turned 0.3 rad")

    class Floating(_OneDof):
        def held_by_contact_alone(self):
            return True

    monkeypatch.setattr(static, "solve_increment", increment)
    lines: list[str] = []
    policy = replace(SolverPolicy(), fallbacks="floating_search=energy")
    result = static.solve_static(Floating(policy), 1, SolverOptions(max_cutbacks=5), log=lines.append)
    assert result.status == "converged"
    assert calls == [(1.0, "residual"), (1.0, "energy")]
    assert [(s.load_factor, s.fallback) for s in result.steps] == [(1.0, 1)]
    assert any("was rejected: link turned 0.3 rad; fallback 1: the step again from load factor 0" in line
               and "cut-backs" not in line for line in lines)
    calls.clear()
    result = static.solve_static(Floating(replace(policy, fallbacks="none")), 1, SolverOptions(max_cutbacks=5))
    assert result.status == "failed"
    assert calls[:2] == [(1.0, "residual"), (0.5, "residual")]


def test_a_failure_after_loose_passes_is_tried_again_with_tight_passes(monkeypatch):
    """With loose passes in play (here ``pass_tolerance`` 0.5 on the direct path) an increment
    that fails after its first pass is tried once more with every pass to ``newton_tol``
    (``loose=False``), logged, before any cut-back; one that fails in its first pass, or
    without loose passes, is cut back at once."""
    import cgfem.solve.static as static
    from dataclasses import replace
    from cgfem.case.model import SolverOptions
    from cgfem.solve.outer import Increment, IncrementFailure
    from cgfem.solve.policy import SolverPolicy

    calls, failing = [], {"pass": 3}

    def increment(system, solves, u, stress, t, options, log, guess=None, loose=True):
        calls.append((t, loose))
        if loose:
            return IncrementFailure("line_search", failing["pass"], 1e-3, 3)
        return Increment(u, stress, stress, [[1.0, 0.0]], [0.0], True)

    monkeypatch.setattr(static, "solve_increment", increment)
    lines: list[str] = []
    loose = _OneDof(replace(SolverPolicy(), pass_tolerance=0.5))
    result = static.solve_static(loose, 1, SolverOptions(max_cutbacks=2), log=lines.append)
    assert result.status == "converged" and calls == [(1.0, True), (1.0, False)]
    assert any("outer pass 3" in line and "again with every outer pass solved to newton_tol" in line
               for line in lines)
    # a failure in the first pass is cut back at once
    calls.clear()
    failing["pass"] = 1
    assert static.solve_static(loose, 1, SolverOptions(max_cutbacks=0)).status == "failed"
    assert calls == [(1.0, True)]
    # and so is any failure without loose passes
    calls.clear()
    failing["pass"] = 3
    assert static.solve_static(_OneDof(), 1, SolverOptions(max_cutbacks=0)).status == "failed"
    assert calls == [(1.0, True)]
