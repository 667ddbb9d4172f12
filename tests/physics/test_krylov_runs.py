"""Whole contact problems on the Krylov path of ``linear: auto`` (AMG-preconditioned GMRES,
:mod:`cgfem.solve.solves`) against the direct path: chain2_steel's first load step at level 1
in finite strain (non-symmetric, every contact point of the onset), the same at level 0 with
``nurbs_fit`` (its saddle point reduced to the bodies' dofs), chain3 at level 0 (its
middle link held by contact alone), and runs whose every Krylov solve is made to stall,
which fall back to factorizations and still converge to the same state. And the direct
path's factors in single precision against double ones."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cgfem.case import parse_case, parse_yaml
from cgfem.report.runs import Run
from cgfem.run import run_case
from cgfem.solve.policy import SolverPolicy
from tests.support.paths import CASES

#: every test here solves a whole problem
pytestmark = pytest.mark.slow

KRYLOV = replace(SolverPolicy(), krylov_min_dofs=0, krylov_nonsymmetric_min_dofs=0, krylov_floating_min_dofs=0,
                 krylov_saddle_min_dofs=0)


def first_step(name: str, fraction: float = 1.0, free_spins: bool = False):
    """The case ``name`` in one load step reaching ``fraction`` of its displacements'
    first step; ``free_spins``: without its bodies' ``hold_spin``."""
    path = CASES / f"{name}.yaml"
    data = parse_yaml(path.read_text())
    if free_spins:
        for body in data["bodies"].values():
            body.pop("hold_spin", None)
    for condition in data["boundary"]:
        if condition.get("type") == "displacement":
            condition["components"] = {k: v * fraction / data["steps"] if isinstance(v, float) else v
                                       for k, v in condition["components"].items()}
    data["steps"] = 1
    return parse_case(data, path.parent)


def solve(case, level: int, surface: str, folder, policy: SolverPolicy) -> tuple[dict, list[str]]:
    lines: list[str] = []
    status = run_case(case, level, surface, folder, lines.append, policy=policy)
    assert status.status == "converged", status.message
    return json.loads((folder / "summary.json").read_text()), lines


def reactions(summary: dict) -> np.ndarray:
    step = summary["steps"][-1]
    return np.concatenate([np.ravel(v) for _, v in sorted(step["reactions"].items())]
                          + [np.ravel(step["contact"]["force"])])


def newton_iterations(summary: dict) -> int:
    return Run(Path("."), summary).newton_iterations


def test_krylov_path_solves_the_steel_chain_to_the_direct_solution(tmp_path):
    """chain2_steel's first step at level 1 (finite strain: GMRES; the onset of contact): the
    Krylov path reaches the direct path's reactions and contact force to 1e-8 and the same
    active set, and logs every solve with its iterations. Its passes but the last stop Newton
    once the residual has halved (``krylov_pass_tolerance``), which saves Newton iterations:
    measured 9 against the direct path's 14 (modified ones counted), and 14 with every pass
    solved to ``newton_tol``."""
    case = first_step("chain2_steel")
    direct, _ = solve(case, 1, "nurbs_fe", tmp_path / "direct", SolverPolicy())
    krylov, lines = solve(case, 1, "nurbs_fe", tmp_path / "krylov", KRYLOV)
    a, b = reactions(direct), reactions(krylov)
    assert np.abs(a - b).max() <= 1e-8 * np.abs(a).max()
    assert direct["steps"][-1]["contact"]["active_points"] == krylov["steps"][-1]["contact"]["active_points"] > 10
    assert newton_iterations(krylov) <= newton_iterations(direct) - 3
    solves = [line for line in lines if line.startswith("linear: gmres")]
    assert len(solves) == newton_iterations(krylov)
    assert sum("preconditioner kept" in line for line in solves) > len(solves) // 2
    # and it repeats bit for bit: pyamg's set-up (random starts of its spectral-radius
    # estimates) runs at a fixed seed, whatever state numpy's generator is in
    np.random.rand(11)
    again, _ = solve(case, 1, "nurbs_fe", tmp_path / "again", KRYLOV)
    assert [{k: v for k, v in step.items() if k != "seconds"} for step in again["steps"]] == \
        [{k: v for k, v in step.items() if k != "seconds"} for step in krylov["steps"]]


@pytest.mark.parametrize("level, surface", [(1, "nurbs_fe"), (0, "nurbs_fit")])
def test_single_precision_factors_keep_the_double_factors_newton_iterates(tmp_path, level, surface):
    """chain2_steel's first step (finite strain: non-symmetric tangents; with ``nurbs_fit``
    the whole saddle point factorized): PARDISO's factors in single precision, refined in
    double, give the Newton iterates of double factors: the same number of iterations with
    residuals within 1e-8 of the force scale Newton measures them against, the same active
    points, reactions and contact force to 1e-8 (measured: 5e-15 and 1e-14)."""
    case = first_step("chain2_steel")
    double, _ = solve(case, level, surface, tmp_path / "double", replace(SolverPolicy(), factor_precision="double"))
    single, lines = solve(case, level, surface, tmp_path / "single", SolverPolicy())
    assert any(line.startswith("linear: direct, pardiso (single precision factors)") for line in lines)
    assert not any("double precision" in line for line in lines)     # no fallback to double
    a, b = reactions(double), reactions(single)
    assert np.abs(a - b).max() <= 1e-8 * np.abs(a).max()
    for x, y in zip(double["steps"], single["steps"], strict=True):
        assert x["contact"]["active_points"] == y["contact"]["active_points"] > 5
        apart = np.abs(np.subtract(x["newton_residuals"], y["newton_residuals"]))
        assert apart.max() <= 1e-8 * x["newton_reference"]
    assert newton_iterations(double) == newton_iterations(single) > 0


@pytest.mark.long   # passed alone; in one full-suite run its reactions were 9 % off the direct path's
def test_krylov_path_holds_a_body_held_by_contact_alone(tmp_path):
    """chain3 at level 0 (small strain: CG): the middle link is held by contact alone (six
    free rigid motions, the tangent shift); the Krylov path converges to the direct path's
    reactions (1e-8) without falling back."""
    case = first_step("chain3")
    direct, _ = solve(case, 0, "nurbs_fe", tmp_path / "direct", SolverPolicy())
    krylov, lines = solve(case, 0, "nurbs_fe", tmp_path / "krylov", KRYLOV)
    assert krylov["steps"][-1]["contact"]["floating"]["link_c"]["free_modes"] == 6
    a, b = reactions(direct), reactions(krylov)
    assert np.abs(a - b).max() <= 1e-8 * np.abs(a).max()
    # small strain: a symmetric tangent, CG; no solve stalls
    assert any(line.startswith("linear: cg") for line in lines)
    assert not any("stalled" in line for line in lines)


def test_a_stalled_krylov_solve_falls_back_and_the_run_converges(tmp_path):
    """With two Krylov iterations allowed no solve reaches its tolerance: every one falls
    back to a factorization (logged), and the run converges to the direct path's state. With
    the matrices after a stall factorized directly (``krylov_stall_direct``, 4) it stalls
    less often, at most once per five matrices, and converges there too."""
    case = first_step("chain2_steel", 0.5)
    stall = replace(KRYLOV, krylov_max_iterations=2, krylov_refresh=2, krylov_stall_direct=0)
    direct, _ = solve(case, 0, "nurbs_fe", tmp_path / "direct", SolverPolicy())
    fallen, lines = solve(case, 0, "nurbs_fe", tmp_path / "stalled", stall)
    assert sum("stalled" in line and "fell back" in line for line in lines) >= newton_iterations(fallen) // 2
    a, b = reactions(direct), reactions(fallen)
    assert np.abs(a - b).max() <= 1e-8 * np.abs(a).max()
    stay, lines = solve(case, 0, "nurbs_fe", tmp_path / "stay", replace(stall, krylov_stall_direct=4))
    stalls = sum("stalled" in line and "fell back" in line for line in lines)
    after = sum("after a stall" in line for line in lines)
    assert stalls >= 1 and after >= 1 and stalls <= after
    assert np.abs(reactions(stay) - a).max() <= 1e-8 * np.abs(a).max()


def test_krylov_path_solves_the_fitted_steel_chain_and_falls_back_when_stalled(tmp_path):
    """``nurbs_fit`` on the Krylov path: GMRES on the bodies' dofs with the fit unknowns
    eliminated (:mod:`cgfem.solve.saddle`), preconditioned by AMG of the reduced matrix, kept
    across Newton iterations. chain2_steel's first step at level 0 reaches the direct path's
    (the whole saddle point factorized) reactions and contact force to 1e-8 with the same
    active set, in fewer Newton iterations (loose passes; measured 9 against 13); with every
    solve made to stall each falls back to the reduced matrix factorized, and the run still
    converges there."""
    case = first_step("chain2_steel")
    direct, _ = solve(case, 0, "nurbs_fit", tmp_path / "direct", SolverPolicy())
    krylov, lines = solve(case, 0, "nurbs_fit", tmp_path / "krylov", KRYLOV)
    a, b = reactions(direct), reactions(krylov)
    assert np.abs(a - b).max() <= 1e-8 * np.abs(a).max()
    assert direct["steps"][-1]["contact"]["active_points"] == krylov["steps"][-1]["contact"]["active_points"] > 0
    assert newton_iterations(krylov) < newton_iterations(direct)
    solves = [line for line in lines if line.startswith("linear: gmres")]
    assert len(solves) == newton_iterations(krylov)
    assert sum("preconditioner kept" in line for line in solves) > len(solves) // 2
    stall = replace(KRYLOV, krylov_max_iterations=2, krylov_refresh=2, krylov_stall_direct=0)
    fallen, lines = solve(case, 0, "nurbs_fit", tmp_path / "stalled", stall)
    assert sum("fell back to saddle-" in line for line in lines) >= newton_iterations(fallen) // 2
    c = reactions(fallen)
    assert np.abs(a - c).max() <= 1e-8 * np.abs(a).max()


def test_a_body_held_by_contact_alone_keeps_the_direct_path_longer():
    """chain3's middle link has no displacement conditions: with ``krylov_min_dofs = 0`` (and
    ``krylov_nonsymmetric_min_dofs``) its Newton systems still take the direct path (below
    ``krylov_floating_min_dofs``), while chain2_steel's take the Krylov path; the built
    system and the case file agree on which is which, and on whether its matrices are
    symmetric (chain3 small strain, chain2_steel contact in finite strain)."""
    from cgfem.run import build_bodies, build_pairs
    from cgfem.solve.solves import DIRECT, KRYLOV, LinearSolves
    from cgfem.solve.system import System

    policy = replace(SolverPolicy(), krylov_min_dofs=0, krylov_nonsymmetric_min_dofs=0)
    for name, floating in (("chain3", True), ("chain2_steel", False)):
        case = first_step(name)
        models, _, solids = build_bodies(case, 0, "nurbs_fe", lambda message: None)
        system = System(models, build_pairs(case, models, solids, "nurbs_fe", lambda message: None), policy)
        assert system.held_by_contact_alone() == case.held_by_contact_alone == floating
        assert system.symmetric == case.symmetric == (case.kinematics == "small")
        assert LinearSolves.of(system, "auto").path(system.n_dofs) == (DIRECT if floating else KRYLOV)


def test_aggregates_within_bodies_keep_the_floating_link_in_the_coarse_space(tmp_path, monkeypatch):
    """chain3's Newton matrix at level 1 once both contacts carry (the fourth of the direct
    path's first pass), solved by CG with a fresh preconditioner: with every finest-level
    aggregate within one body (:func:`cgfem.solve.multigrid.strength_within_bodies`) 15-20
    iterations reach 1e-3 (measured 15); with pyamg's own strength, whose aggregates take in
    the neighbours across the contact zones, the middle link's rigid motions are no longer
    in the coarse space and the same solve takes 76-115 (measured 76)."""
    from cgfem.solve import krylov
    from cgfem.solve.krylov import AMGPreconditioner, krylov_solve
    from cgfem.solve.solves import LinearSolves

    class Captured(Exception):
        pass

    seen = []
    direct = LinearSolves.__call__

    def spy(self, K, b, rtol=None):
        if K is not None:
            seen.append(K)
            if len(seen) == 4:
                raise Captured((K.copy(), b.copy(), self.near_null, self.symmetric))
        return direct(self, K, b, rtol)

    monkeypatch.setattr(LinearSolves, "__call__", spy)
    with pytest.raises(Captured) as captured:
        # the link's spin free: held (chain3.yaml's hold_spin), it is no soft motion, and the
        # two strengths both take 16 iterations
        run_case(first_step("chain3", free_spins=True), 1, "nurbs_fe", tmp_path, policy=SolverPolicy())
    K, b, near_null, symmetric = captured.value.args[0]
    assert symmetric and near_null.shape[1] == 18
    its = {}
    for name in ("within", "across"):
        if name == "across":
            own = krylov.smoothed_aggregation
            monkeypatch.setattr(krylov, "smoothed_aggregation", lambda A, bodies=None, **kw: own(A, **kw))
        x, its[name], res, ok = krylov_solve(K, b, AMGPreconditioner(K, near_null, True), 1e-3, 400, True)
        assert ok and res <= 1e-3
    assert its["within"] <= 25 and its["across"] >= 3 * its["within"], its
