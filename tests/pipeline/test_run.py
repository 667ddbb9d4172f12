"""``cgfem run``: result files, exit codes, progress, memory guard, the outer loop run to
``outer_tol``."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import replace

import meshio
import numpy as np
import pytest

from cgfem.cli import main
from cgfem.fem.element import HEX8, HEX27
from cgfem.geometry.measure import BoundaryMeasures
from cgfem.solve.policy import DEFAULT_POLICY

from tests.support.paths import CASES

#: B-rep measures of a half-torus link (R 20 mm, r 5 mm; its projected area is sqrt(2) A)
#: and of one of planar's boxes (faces normal to the grid axes)
LINK_MEASURES = BoundaryMeasures(4.93e-6, 2.13e-3, 2.0 ** 0.5 * 2.13e-3)
BOX_MEASURES = BoundaryMeasures(2.5e-7, 3e-4, 3e-4)

#: every test here solves a whole problem
pytestmark = pytest.mark.slow


LINK = textwrap.dedent("""\
    name: link_pull
    kinematics: finite
    steps: 2
    bodies:
      link:
        geometry: {builder: half_torus, center: [0, 0, 0], axis: [0, 0, 1], major_radius: 0.02,
                   minor_radius: 0.005, keep: [0, 1, 0]}
        material: {model: neo_hookean, E: 7.0e6, nu: 0.45}
        grid: {h0: 0.005, offset: [0.13, 0.29, 0.41]}
    boundary:
      - {body: link, patches: [cap_a], type: displacement, components: {x: 0, y: 0, z: 0}}
      - {body: link, patches: [cap_b], type: displacement, components: {x: 0, y: -0.002, z: 0}}
    solver: {outer_tol: 1.0e-6}
    """)

CRUSH = textwrap.dedent("""\
    name: crush
    kinematics: finite
    steps: 4
    bodies:
      b:
        geometry: {builder: box, min: [0, 0, 0], max: [1, 1, 1]}
        material: {model: neo_hookean, E: 1.0e6, nu: 0.3}
        grid: {h0: 0.5, offset: [0.13, 0.29, 0.41]}
    boundary:
      - {body: b, patches: [xmin], type: displacement, components: {x: 0, y: 0, z: 0}}
      - {body: b, patches: [xmax], type: displacement, components: {x: -1.2, y: 0.3, z: 0}}
    solver: {max_newton: 8, max_cutbacks: 2}
    """)


#: a policy under which every system takes the direct path
DIRECT_ONLY = replace(DEFAULT_POLICY, krylov_min_dofs=10**9, krylov_nonsymmetric_min_dofs=10**9,
                      krylov_order2_min_dofs=10**9, krylov_saddle_min_dofs=10**9)

def _write(tmp_path, text, name="case.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_run_writes_summary_and_steps(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    # a stale result must not survive (an earlier nurbs_fit run's fits neither); a file of the
    # user's stays
    for stale in ("summary.json", "step_007.vtu", "fit_007.json", "fit_007.vtu", "fit_reference.json"):
        (out / stale).write_text("{}")
    (out / "step_notes.txt").write_text("mine")
    code = main(["run", _write(tmp_path, LINK), "--level", "0", "--surface", "nurbs_fe", "--out", str(out)])
    assert code == 0
    err = capsys.readouterr().err
    assert "newton" in err and "step 2 converged" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "converged"
    assert all(s["outer_converged"] and s["outer_changes"][-1] <= 1e-6 for s in summary["steps"])
    assert (summary["case"], summary["level"], summary["surface"]) == ("link_pull", 0, "nurbs_fe")
    assert summary["policy"] == {}                   # the solver's default constants
    # the default fallbacks change only constants of bodies held by contact alone: none here
    assert summary["fallbacks"] == {} and all(s["fallback"] == 0 for s in summary["steps"])
    body = summary["bodies"]["link"]
    assert body["dofs"] == 3 * body["nodes"]
    assert abs(body["volume"] / body["brep_volume"] - 1) < 1e-8
    assert [s["load_factor"] for s in summary["steps"]] == [0.5, 1.0]
    last = summary["steps"][-1]
    assert list(last["reactions"]) == ["link/cap_a", "link/cap_b"]
    # no other load: the two supports balance, and the pulled cap is pulled towards -y
    ra, rb = (np.array(last["reactions"][k]) for k in ("link/cap_a", "link/cap_b"))
    assert np.linalg.norm(ra + rb) < 1e-9 * np.linalg.norm(ra)
    assert rb[1] < 0 < ra[1]
    assert last["max_von_mises"]["link"] > 0 and last["newton_residuals"][-1] < last["newton_residuals"][0]
    assert sorted(p.name for p in out.iterdir()) == ["boundary.pvd", "boundary_001.vtu", "boundary_002.vtu",
                                                     "step.pvd", "step_001.vtu", "step_002.vtu", "step_notes.txt",
                                                     "summary.json", "surface.pvd", "surface_001.vtu",
                                                     "surface_002.vtu"]
    # ParaView's collections step through the load factors, one file per step
    collection = (out / "step.pvd").read_text()
    assert re.findall(r'timestep="([^"]+)" part="0" file="([^"]+)"', collection) == [
        ("0.5", "step_001.vtu"), ("1.0", "step_002.vtu")]
    mesh = meshio.read(out / "step_002.vtu")
    assert mesh.points.shape[0] == body["nodes"]
    assert {"displacement", "stress", "von_mises_nodal"} <= set(mesh.point_data)
    assert {"status", "von_mises_max_qp"} <= set(mesh.cell_data)
    # the summary's maximum is the VTU's element maximum at material points; the nodal
    # maximum (nodes of cut elements lie outside the body) is reported beside it
    assert last["max_von_mises"]["link"] == pytest.approx(mesh.cell_data["von_mises_max_qp"][0].max(), rel=1e-12)
    assert last["von_mises_max_nodal"]["link"] == pytest.approx(mesh.point_data["von_mises_nodal"].max(),
                                                                 rel=1e-12)
    assert mesh.point_data["displacement"].shape == (body["nodes"], 3)


def test_sub_steps_a_fallback_drops_leave_no_files(tmp_path, monkeypatch):
    """When a fallback solves a step again from its start, the sub-steps of the failed attempt
    leave the summary and take their files with them (here the solver, after both steps of the
    link, reports the second one dropped)."""
    import cgfem.run
    from cgfem.solve.static import StaticResult

    real = cgfem.run.solve_static

    def dropping(system, steps, options, log, on_step, on_drop):
        result = real(system, steps, options, log, on_step, on_drop)
        on_drop(1)
        return StaticResult(result.status, result.steps[:1])

    monkeypatch.setattr(cgfem.run, "solve_static", dropping)
    out = tmp_path / "out"
    assert main(["run", _write(tmp_path, LINK), "--level", "0", "--surface", "facets", "--out", str(out),
                 "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [s["load_factor"] for s in summary["steps"]] == [0.5]
    assert sorted(p.name for p in out.iterdir()) == ["boundary.pvd", "boundary_001.vtu", "step.pvd",
                                                     "step_001.vtu", "summary.json", "surface.pvd",
                                                     "surface_001.vtu"]
    assert "step_002.vtu" not in (out / "step.pvd").read_text()


def test_run_that_fails_keeps_converged_steps_and_exits_1(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["run", _write(tmp_path, CRUSH), "--level", "0", "--surface", "facets", "--out", str(out),
                 "--quiet"])
    assert code == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and "cut-backs" in summary["message"]
    assert "(last attempt: Newton stopped on " in summary["message"]      # says why
    steps = summary["steps"]
    assert 1 <= len(steps) < 4 and all(s["load_factor"] < 1.0 for s in steps)
    assert sorted(p.name for p in out.glob("step_*.vtu")) == [f"step_{i + 1:03d}.vtu" for i in range(len(steps))]
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("args, field", [
    (["--level", "-1"], "--level"),
    (["--level", "40"], "--level"),          # refused by the memory estimate, before any grid
    (["--level", "0", "--policy", "floating_turn=fast"], "--policy"),
    (["--level", "0", "--policy", "no_such_constant=1"], "--policy"),
    (["--level", "0", "--policy", "forcing=-1"], "--policy"),
    (["--level", "0", "--policy", "fallbacks=floating_turn=x"], "--policy: fallbacks: floating_turn"),
])
def test_run_bad_input_exits_2_with_one_line(tmp_path, capsys, args, field):
    out = tmp_path / "out"
    code = main(["run", _write(tmp_path, LINK), "--surface", "facets", "--out", str(out), *args])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0]
    assert not (out / "summary.json").exists()


def test_memory_guard_message_names_the_need(tmp_path, capsys):
    code = main(["run", _write(tmp_path, LINK), "--level", "12", "--surface", "nurbs_fe",
                 "--out", str(tmp_path / "o")])
    assert code == 2
    err = capsys.readouterr().err
    assert "GiB" in err and "this machine has" in err and "DOFs" in err


def test_no_memory_check_runs_a_level_the_estimate_refuses(tmp_path, monkeypatch, capsys):
    """On a machine the estimate finds too small the level is refused (exit 2, one line naming
    the way round, no folder); ``--no-memory-check`` runs it."""
    import cgfem.memory
    monkeypatch.setattr(cgfem.memory, "machine_memory", lambda: 2**20)
    out = tmp_path / "o"
    args = ["run", _write(tmp_path, LINK), "--level", "0", "--surface", "facets", "--out", str(out), "--quiet"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--no-memory-check" in err[0] and not out.exists()
    assert main(args + ["--no-memory-check"]) == 0
    assert json.loads((out / "summary.json").read_text())["status"] == "converged"


def test_memory_guard_compares_with_the_machine_not_the_free_memory():
    """A level is refused only when its estimate exceeds the machine's memory: in the pipeline
    the other runs hold memory while they last (planar at level 3 was refused with 17.6 GiB
    free on a 23 GiB machine, where it peaks at 6 GB)."""
    from cgfem.case import load_case
    from cgfem.errors import InputError
    from cgfem.memory import check_memory, estimate_memory
    case = load_case(CASES / "planar.yaml")
    measures = {b.name: BOX_MEASURES for b in case.bodies}
    need, _, _ = estimate_memory(case, 3, measures)
    check_memory(case, 3, measures, total=need + 1)
    with pytest.raises(InputError, match="level 3 needs about .* this machine has"):
        check_memory(case, 3, measures, total=need - 1)


def test_memory_estimate_follows_the_solve_path():
    """Systems that take the Krylov path (``linear: auto``, at least ``krylov_min_dofs``
    unknowns) are estimated without a factorization's fill: ``KRYLOV_MEMORY`` times the
    direct path's estimate, per element order; chain2_steel at level 4 (1.2M unknowns, 41.7
    GiB direct) then fits 23 GiB. ``nurbs_fit`` takes the Krylov path from
    ``SADDLE_DIRECT_DOFS`` unknowns on, with ``KRYLOV_FIT_MEMORY`` times the direct path's
    estimate."""
    from cgfem.case import load_case
    from cgfem.memory import DIRECT_FIT_MEMORY, KRYLOV_FIT_MEMORY, KRYLOV_MEMORY, estimate_memory
    case = load_case(CASES / "chain2_steel.yaml")
    measures = {b.name: LINK_MEASURES for b in case.bodies}
    for order in (1, 2):
        direct, dofs, krylov = estimate_memory(case, 4, measures, order, "nurbs_fe", DIRECT_ONLY)
        assert not krylov
        iterative, same, krylov = estimate_memory(case, 4, measures, order, "nurbs_fe")
        assert krylov and same == dofs >= 100_000
        assert iterative == pytest.approx(KRYLOV_MEMORY[order] * direct, rel=1e-9)
        # nurbs_fit on the Krylov path keeps its fit rows and patch matrices
        fit = estimate_memory(case, 4, measures, order, "nurbs_fit")
        assert fit[1:] == (dofs, True)
        assert fit[0] == pytest.approx(KRYLOV_FIT_MEMORY[order] * direct, rel=1e-9) and fit[0] > iterative
    # a size below the Krylov threshold is the direct path's; nurbs_fit's has its own threshold
    small = estimate_memory(case, 0, measures, 1, "nurbs_fe")
    assert small[1] < 100_000 and not small[2]
    least = DEFAULT_POLICY.krylov_saddle_min_dofs
    sides = set()
    for level in (0, 1, 2, 3):
        direct, dofs, _ = estimate_memory(case, level, measures, 1, "nurbs_fe", DIRECT_ONLY)
        need, same, krylov = estimate_memory(case, level, measures, 1, "nurbs_fit")
        assert (same, krylov) == (dofs, dofs >= least)
        assert need == pytest.approx((KRYLOV_FIT_MEMORY[1] if krylov else DIRECT_FIT_MEMORY) * direct, rel=1e-9)
        sides.add(dofs >= least)
    assert sides == {False, True}


def test_a_body_held_by_contact_alone_keeps_the_direct_path_longer():
    """The estimate's path follows ``krylov_floating_min_dofs`` where a body has no
    displacement conditions (chain3's middle link) and ``krylov_nonsymmetric_min_dofs``
    (chain2_steel, finite strain) elsewhere: at a size between the two (with the latter at
    20 000) chain2_steel takes the Krylov path and chain3 the direct one."""
    from cgfem.case import load_case
    from cgfem.memory import estimate_memory
    measures = {name: LINK_MEASURES for name in ("link_a", "link_b", "link_c")}
    steel, chain3 = (load_case(CASES / f"{name}.yaml") for name in ("chain2_steel", "chain3"))
    assert chain3.held_by_contact_alone and not steel.held_by_contact_alone
    policy = replace(DEFAULT_POLICY, krylov_nonsymmetric_min_dofs=20_000)
    _, dofs, krylov = estimate_memory(steel, 2, measures, policy=policy)
    assert policy.krylov_nonsymmetric_min_dofs <= dofs < policy.krylov_floating_min_dofs and krylov
    _, dofs, krylov = estimate_memory(chain3, 2, measures, policy=policy)
    assert policy.krylov_min_dofs <= dofs < policy.krylov_floating_min_dofs and not krylov


def test_triquadratic_systems_take_the_krylov_path_from_their_own_threshold():
    """``krylov_order2_min_dofs`` (20k) is below ``krylov_nonsymmetric_min_dofs`` (100k, contact
    in finite strain at order 1): chain2_steel with triquadratic elements at level 1 (about
    37k unknowns) takes the Krylov path, with trilinear ones at level 2 (about 29k) the direct
    one; chain3, whose middle link is held by
    contact alone, keeps the direct path at order 2, level 1 (about 72k)."""
    from cgfem.case import load_case
    from cgfem.memory import estimate_memory
    measures = {name: LINK_MEASURES for name in ("link_a", "link_b", "link_c")}
    steel, chain3 = (load_case(CASES / f"{name}.yaml") for name in ("chain2_steel", "chain3"))
    low, high = DEFAULT_POLICY.krylov_order2_min_dofs, DEFAULT_POLICY.krylov_nonsymmetric_min_dofs
    _, dofs, krylov = estimate_memory(steel, 2, measures, 1)
    assert low <= dofs < high and not krylov
    _, dofs, krylov = estimate_memory(steel, 1, measures, 2)
    assert low <= dofs < high and krylov
    _, dofs, krylov = estimate_memory(chain3, 1, measures, 2)
    assert low <= dofs < DEFAULT_POLICY.krylov_floating_min_dofs and not krylov


def test_memory_estimate_without_contact_lets_the_bent_half_torus_run_order_2_at_level_3():
    """Without contact the Krylov path's factor is ``KRYLOV_MEMORY_NO_CONTACT``: the bent half
    torus at order 2, level 3 (about 750k unknowns; measured peak 14.7 GiB) is estimated
    below 23 GiB; the same two links with and without their contact pair differ by the
    factor alone."""
    from cgfem.case import load_case
    from cgfem.memory import KRYLOV_MEMORY, KRYLOV_MEMORY_NO_CONTACT, estimate_memory
    bent = load_case(CASES / "bent_half_torus.yaml")
    assert not bent.contact
    need, dofs, krylov = estimate_memory(bent, 3, {"link": LINK_MEASURES}, 2)
    assert krylov and dofs > 600_000 and 14.7 * 2**30 < need < 23 * 2**30
    chain = load_case(CASES / "chain2_steel.yaml")
    measures = {b.name: LINK_MEASURES for b in chain.bodies}
    direct = estimate_memory(chain, 3, measures, 2, "nurbs_fe", DIRECT_ONLY)[0]
    assert estimate_memory(chain, 3, measures, 2)[0] == pytest.approx(KRYLOV_MEMORY[2] * direct, rel=1e-9)
    alone = estimate_memory(replace(chain, contact=()), 3, measures, 2)[0]
    assert alone == pytest.approx(KRYLOV_MEMORY_NO_CONTACT[2] * direct, rel=1e-9)
    assert KRYLOV_MEMORY_NO_CONTACT[2] < KRYLOV_MEMORY[2]


#: measured peaks (GB, the largest process's resident set) of runs at one thread: case,
#: level, surface, element order, GB (docs/performance.md, "Memory" and "The extended
#: configuration"). At level 3 on the Krylov path (chain3's two stalled runs factorized some
#: systems directly); the direct path's largest against its estimate (nurbs_fit, the full
#: pipeline run of 0468317); planar at order 2, level 2 and chain2_steel at order 2, level 1
#: with nurbs_fit, on the Krylov path
MEASURED_PEAKS = [("chain3", 3, "facets", 1, 9.5), ("chain3", 3, "nurbs_fit", 1, 12.6),
                  ("chain3", 3, "nurbs_fe", 1, 6.7), ("chain2_steel", 3, "nurbs_fe", 1, 2.8),
                  ("chain2_steel", 3, "nurbs_fit", 1, 5.2), ("planar", 3, "nurbs_fit", 1, 6.8),
                  ("planar", 3, "facets", 1, 4.3), ("chain3", 1, "nurbs_fit", 1, 1.19),
                  ("chain3", 0, "nurbs_fit", 2, 1.97), ("chain2_steel", 0, "nurbs_fit", 2, 1.27),
                  ("planar", 2, "nurbs_fe", 2, 18.5), ("planar", 2, "nurbs_fit", 2, 18.4),
                  ("chain2_steel", 1, "nurbs_fit", 2, 2.51)]
#: the memory (bytes) of the machine they were measured on (MemTotal 24683652 kB)
MEASURED_ON = 24_683_652 * 1024


def test_the_memory_a_run_reserves_bounds_its_measured_peak():
    """``run_memory`` (the estimate plus the interpreter, what the pipeline reserves as
    ``mem_mb``) is above every measured peak, and the two chain3 runs at level 3 that peaked
    at 22 GB together reserve more than the machine they were measured on has (its
    ``MemTotal``, the pipeline's default budget), so that they do not start together there.
    Planar at order 2, level 2 (18.5 GB with nurbs_fe, 18.4 with nurbs_fit) is not refused
    there: the boxes' cut elements are counted from their projected area (about half the
    ``2 A / h^2`` of a curved surface)."""
    from cgfem.case import load_case
    from cgfem.memory import check_memory, run_memory
    reserved = {}
    for name, level, surface, order, peak in MEASURED_PEAKS:
        case = load_case(CASES / f"{name}.yaml")
        reserved[name, level, surface, order] = run_memory(case, level, surface, order)
        assert reserved[name, level, surface, order] > peak * 1e9, (name, level, surface, order)
    assert reserved["chain3", 3, "facets", 1] + reserved["chain3", 3, "nurbs_fit", 1] > MEASURED_ON
    planar = load_case(CASES / "planar.yaml")
    for surface in ("nurbs_fe", "nurbs_fit"):
        check_memory(planar, 2, {b.name: BOX_MEASURES for b in planar.bodies}, total=MEASURED_ON, order=2,
                     surface=surface)


def test_interrupted_run_whose_folder_was_removed_says_so(tmp_path):
    """A workflow manager that stops a run may remove its output folder before the run has
    written its summary (snakemake does): the run still ends as interrupted, with one line
    saying the summary was not written, never a traceback."""
    import shutil

    from cgfem.case import load_case
    from cgfem.run import INTERRUPTED, run_case
    from cgfem.errors import RunInterrupted

    out = tmp_path / "out"

    def log(message: str) -> None:
        if message.startswith("step 1 converged"):
            shutil.rmtree(out)
            raise RunInterrupted(signal.SIGTERM)
    status = run_case(load_case(_write(tmp_path, LINK)), 0, "nurbs_fe", out, log)
    assert status.status == INTERRUPTED and status.signum == signal.SIGTERM
    assert status.message.startswith("interrupted by SIGTERM after 1 converged step(s)")
    assert status.message.endswith("summary.json not written: No such file or directory")
    assert not out.exists()


def test_run_rejects_case_errors_like_check(tmp_path, capsys):
    bad = LINK.replace("outer_tol: 1.0e-6", "outer_tol: 1.0e-6, ghost_penalty: -1")
    code = main(["run", _write(tmp_path, bad), "--level", "0", "--surface", "facets", "--out", str(tmp_path)])
    assert code == 2
    assert "ghost_penalty" in capsys.readouterr().err


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupted_run_keeps_its_steps_and_says_so(tmp_path, signum, code):
    """A signal after the first step: exit 128 + signum, the converged steps' files, and a
    summary whose status says the run was interrupted (never a complete-looking result)."""
    out = tmp_path / "out"
    case = _write(tmp_path, LINK.replace("steps: 2", "steps: 40"))
    proc = subprocess.Popen([sys.executable, "-m", "cgfem", "run", case, "--level", "1", "--surface",
                             "nurbs_fe", "--out", str(out)], stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 300
    while not list(out.glob("step_*.vtu")) and time.time() < deadline:   # wait for a step
        time.sleep(0.2)
    proc.send_signal(signum)
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == code, err[-3000:]
    assert err.strip().splitlines()[-1].startswith("cgfem: interrupted (interrupted by "
                                                   f"{signal.Signals(signum).name} after ")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and 1 <= len(summary["steps"]) < 40
    assert summary["message"].startswith(f"interrupted by {signal.Signals(signum).name} after "
                                         f"{len(summary['steps'])} converged step(s)")
    written = sorted(p.name for p in out.glob("step_*.vtu"))
    assert written == [f"step_{k:03d}.vtu" for k in range(1, len(summary["steps"]) + 1)]
    assert not list(out.glob(".*.tmp"))


def test_uniform_stress_run_reports_its_von_mises_and_reactions(tmp_path):
    from cgfem.run import run_case
    from tests.support.elasticity_cases import uniform_stress_case

    sigma = np.array([[3.0, 1.0, 0.5], [1.0, -2.0, 0.3], [0.5, 0.3, 1.0]]) * 1e6
    case, _ = uniform_stress_case(sigma, 2.0e9, 0.3, (0.37, 0.61, 0.18))
    status = run_case(case, 0, "nurbs_fe", tmp_path)
    assert status.status == "converged"
    step = json.loads(status.summary.read_text())["steps"][-1]
    s = sigma - np.trace(sigma) / 3 * np.eye(3)
    vm = np.sqrt(1.5 * np.sum(s * s))
    assert abs(step["max_von_mises"]["b"] - vm) < 1e-8 * vm
    assert np.allclose(step["reactions"]["b/xmin+ymin+zmin"], -sigma.sum(axis=1), rtol=0, atol=1e-8 * vm)
    mesh = meshio.read(tmp_path / "step_001.vtu")
    assert np.allclose(mesh.point_data["von_mises_nodal"], vm, rtol=1e-8)
    assert abs(step["von_mises_max_nodal"]["b"] - vm) < 1e-8 * vm
    assert np.allclose(mesh.point_data["stress"], sigma.ravel(), rtol=0, atol=1e-8 * vm)


@pytest.mark.slow
def test_order_2_run_writes_triquadratic_cells_with_the_exact_uniform_stress(tmp_path):
    """``--order 2`` on the uniform-stress box: summary records the order, the VTU holds
    27-node hexahedra (in VTK's node order, drawn curved by ParaView) carrying the exact
    displacement at every node (1e-8), the support reactions exact to 1e-8 and the stress
    to 1e-7."""
    from cgfem.run import run_case
    from tests.support.elasticity_cases import uniform_stress_case

    sigma = np.array([[3.0, 1.0, 0.5], [1.0, -2.0, 0.3], [0.5, 0.3, 1.0]]) * 1e6
    case, eps = uniform_stress_case(sigma, 2.0e9, 0.3, (0.37, 0.61, 0.18))
    status = run_case(case, 0, "nurbs_fe", tmp_path / "o", order=2)
    assert status.status == "converged"
    summary = json.loads(status.summary.read_text())
    assert summary["order"] == 2
    step = summary["steps"][-1]
    vm = np.sqrt(1.5 * np.sum((sigma - np.trace(sigma) / 3 * np.eye(3)) ** 2))
    assert np.allclose(step["reactions"]["b/xmin+ymin+zmin"], -sigma.sum(axis=1), rtol=0, atol=1e-8 * vm)
    mesh = meshio.read(tmp_path / "o" / "step_001.vtu")
    assert [c.type for c in mesh.cells] == ["hexahedron27"]
    # the nodal stress is the recovered one: round-off of the outer loop's solves (measured
    # 1.0e-8 of the von Mises stress at the worst node)
    assert np.allclose(mesh.point_data["stress"], sigma.ravel(), rtol=0, atol=1e-7 * vm)
    u = mesh.point_data["displacement"]
    exact = mesh.points @ eps.T
    assert np.abs(u - exact).max() <= 1e-8 * np.abs(exact).max()


def test_unavailable_linear_backend_is_bad_input(tmp_path, capsys, monkeypatch):
    import cgfem.run

    monkeypatch.setattr(cgfem.run, "available_backends", lambda: ("superlu", "pyamg"))
    case = _write(tmp_path, LINK.replace("outer_tol: 1.0e-6", "outer_tol: 1.0e-6, linear: pardiso"))
    code = main(["run", case, "--level", "0", "--surface", "facets", "--out", str(tmp_path / "o")])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "solver.linear" in err[0] and "pardiso" in err[0]


def test_rubber_link_pulled_by_1_75_radii_converges(tmp_path):
    """The cap of the rubber half torus pulled by 0.035 m (1.75 R) in 3 steps at level 1.
    With moment-fitted rules on every cut element (points in the void, signed weights) the
    Newton solves stalled beyond load factor 0.99 and the run failed after 5 cut-backs; with
    the positive in-material rules it converges in 3 steps, and the caps' reactions balance."""
    case = LINK.replace("steps: 2", "steps: 3").replace("y: -0.002", "y: -0.035")
    out = tmp_path / "out"
    assert main(["run", _write(tmp_path, case), "--level", "1", "--surface", "nurbs_fe",
                 "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    last = summary["steps"][-1]
    assert last["load_factor"] == 1.0
    a, b = (np.array(last["reactions"][f"link/{cap}"]) for cap in ("cap_a", "cap_b"))
    assert np.abs(a + b).max() <= 1e-8 * np.abs(a).max()
    assert a[1] > 30.0  # about 34 N, the pull stiffens the rubber (2.8 N for 3 mm)


#: a unit bar of linear material on rollers (xmin, ymin, zmin) stretched by D along x, free
#: lateral faces: sigma_xx = E D / L, the reaction on xmax is E D A / L; default solver options
BAR_E, BAR_D = 1.0e9, 1.0e-3
BAR = textwrap.dedent(f"""\
    name: bar
    kinematics: small
    bodies:
      b:
        geometry: {{builder: box, min: [0, 0, 0], max: [1, 1, 1]}}
        material: {{model: linear_elastic, E: {BAR_E!r}, nu: 0.3}}
        grid: {{h0: 0.3, offset: [0.13, 0.29, 0.41]}}
    boundary:
      - {{body: b, patches: [xmin], type: displacement, components: {{x: 0}}}}
      - {{body: b, patches: [ymin], type: displacement, components: {{y: 0}}}}
      - {{body: b, patches: [zmin], type: displacement, components: {{z: 0}}}}
      - {{body: b, patches: [xmax], type: displacement, components: {{x: {BAR_D!r}}}}}
    """)


def test_outer_loop_runs_to_its_tolerance_with_default_settings(tmp_path):
    """Plain substitution for 4 outer passes (the old default cap) left a change of 1.7e-4
    and the reaction 1.0e-5 off; run to outer_tol = 1e-6 it is off by 3.3e-8 (6 passes), and
    with the Aitken relaxation by 1e-15 (4 passes)."""
    out = tmp_path / "out"
    assert main(["run", _write(tmp_path, BAR), "--level", "0", "--surface", "nurbs_fe", "--out", str(out),
                 "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    step = summary["steps"][-1]
    assert summary["status"] == "converged" and step["outer_converged"] is True
    assert step["outer_changes"][-1] <= 1e-6 < step["outer_changes"][-2]
    reaction = np.array(step["reactions"]["b/xmax"])
    exact = BAR_E * BAR_D          # sigma_xx times the unit area
    assert abs(reaction[0] - exact) <= 1e-7 * exact
    assert np.abs(reaction[1:]).max() <= 1e-7 * exact


@pytest.mark.parametrize("order, solver, kappa", [(1, "", HEX8.kappa_dirichlet), (2, "", HEX27.kappa_dirichlet),
                                                  (2, "solver: {kappa_dirichlet: 25}\n", 25.0)])
def test_weak_dirichlet_factor_is_the_elements_unless_set_and_the_bar_stays_exact(
        tmp_path, order, solver, kappa):
    """``kappa_dirichlet`` defaults to the element's (trilinear and triquadratic differ), a case
    value overrides it, the summary records the one used; the method is consistent, so the
    bar's linear field and reaction are exact whatever the factor."""
    out = tmp_path / "out"
    assert main(["run", _write(tmp_path, BAR + solver), "--level", "0", "--surface", "nurbs_fe",
                 "--out", str(out), "--order", str(order), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["bodies"]["b"]["kappa_dirichlet"] == kappa
    reaction = np.array(summary["steps"][-1]["reactions"]["b/xmax"])
    assert abs(reaction[0] - BAR_E * BAR_D) <= 1e-7 * BAR_E * BAR_D


def test_outer_loop_cap_is_reported_not_hidden(tmp_path, capsys):
    case = BAR + "solver: {outer_passes: 1, outer_tol: 1.0e-12}\n"
    out = tmp_path / "out"
    code = main(["run", _write(tmp_path, case), "--level", "0", "--surface", "nurbs_fe", "--out", str(out)])
    assert code == 1
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if "warning:" in line]
    assert len(warnings) == 1 and "outer_passes = 1" in warnings[0] and "outer_tol" in warnings[0]
    summary = json.loads((out / "summary.json").read_text())
    step = summary["steps"][-1]
    assert step["outer_converged"] is False and step["outer_passes"] == 1
    assert step["outer_changes"] == [1.0]          # the first recovery against none
    assert summary["status"] == "outer_not_converged" and "outer_passes" in summary["message"]
    assert "outer_not_converged" in err.splitlines()[-1]


def test_surface_file_holds_the_boundary_rule_points(tmp_path):
    """surface_001.vtu: one vertex per boundary-rule point of the body, the displacement
    there equals the step's nodal field interpolated (and, in this patch test, the exact
    linear field), the stress is the uniform one, and each point carries its patch."""
    from cgfem.run import build_models
    from tests.support.elasticity_cases import uniform_stress_case

    sigma = np.array([[3.0, 1.0, 0.5], [1.0, -2.0, 0.3], [0.5, 0.3, 1.0]]) * 1e6
    case, eps = uniform_stress_case(sigma, 2.0e9, 0.3, (0.37, 0.61, 0.18))
    from cgfem.run import run_case

    assert run_case(case, 0, "nurbs_fe", tmp_path).status == "converged"
    cloud = meshio.read(tmp_path / "surface_001.vtu")
    step = meshio.read(tmp_path / "step_001.vtu")
    model = build_models(case, 0, "nurbs_fe", lambda m: None)[0][0]
    boundary = model.boundary_points
    assert cloud.points.shape[0] == boundary.points.w.size == model.embedding.boundary.w.size
    assert [c.type for c in cloud.cells] == ["vertex"]
    assert np.array_equal(cloud.cells[0].data.ravel(), np.arange(cloud.points.shape[0]))
    assert np.array_equal(cloud.points, boundary.points.x)
    u = cloud.point_data["displacement"]
    interpolated = boundary.values(model.space, step.point_data["displacement"].ravel())
    assert np.abs(u - interpolated).max() <= 1e-15 * np.abs(interpolated).max()
    assert np.abs(u - cloud.points @ eps.T).max() <= 1e-8 * np.abs(u).max()
    assert np.abs(cloud.point_data["stress"] - sigma.ravel()).max() <= 1e-8 * np.abs(sigma).max()
    s = sigma - np.trace(sigma) / 3 * np.eye(3)
    assert np.allclose(cloud.point_data["von_mises"], np.sqrt(1.5 * np.sum(s * s)), rtol=1e-8)
    assert np.all(cloud.point_data["body"] == 0)
    names = model.embedding.patch_names
    for index, name in enumerate(names):          # box patches: xmin ... zmax
        on = cloud.point_data["patch"] == index
        axis, side = "xyz".index(name[0]), float(name[1:] == "max")
        assert on.any() and np.abs(cloud.points[on, axis] - side).max() < 1e-12


@pytest.mark.parametrize("surface", ["nurbs_fe", "facets"])
def test_boundary_file_holds_the_fields_on_the_triangulated_boundary(tmp_path, surface):
    """boundary_001.vtu: triangles on the body's boundary (the exact faces, or the facets)
    whose vertices carry the step's nodal fields interpolated; with nurbs_fe, in this patch
    test, the exact linear displacement, the uniform stress and its von Mises value, and
    each vertex its patch."""
    from tests.support.elasticity_cases import uniform_stress_case
    from cgfem.run import run_case

    sigma = np.array([[3.0, 1.0, 0.5], [1.0, -2.0, 0.3], [0.5, 0.3, 1.0]]) * 1e6
    case, eps = uniform_stress_case(sigma, 2.0e9, 0.3, (0.37, 0.61, 0.18))
    assert run_case(case, 0, surface, tmp_path).status == "converged"
    mesh = meshio.read(tmp_path / "boundary_001.vtu")
    assert [c.type for c in mesh.cells] == ["triangle"]
    x, tri = mesh.points, mesh.cells[0].data
    assert np.array_equal(np.unique(tri), np.arange(x.shape[0]))
    # closed and outward: the divergence theorem gives the volume the run integrated (the
    # unit box's; with facets the chamfered polyhedron's), every vertex on the box
    a, b, c = (x[tri[:, k]] for k in range(3))
    volume = np.einsum("ij,ij->", (a + b + c) / 3.0, np.cross(b - a, c - a)) / 6.0
    integrated = json.loads((tmp_path / "summary.json").read_text())["bodies"]["b"]["volume"]
    assert volume == pytest.approx(integrated, rel=1e-10)
    if surface == "nurbs_fe":
        assert volume == pytest.approx(1.0, rel=1e-12)
    assert np.all((x > -1e-12) & (x < 1.0 + 1e-12))
    # the vertex fields are the step's nodal fields interpolated where the vertex lies
    from cgfem.run import build_models

    space = build_models(case, 0, surface, lambda m: None)[0][0].space
    slots, xi = space.locate(x)
    assert np.all(slots >= 0)
    step = meshio.read(tmp_path / "step_001.vtu")
    u, stress = mesh.point_data["displacement"], mesh.point_data["stress"]
    for field, nodal in ((u, step.point_data["displacement"]), (stress, step.point_data["stress"])):
        assert np.abs(field - space.interpolate(nodal, slots, xi)).max() <= 1e-14 * np.abs(nodal).max()
    assert np.all(mesh.point_data["body"] == 0)
    if surface == "nurbs_fe":  # facets do not pass the patch test (their chamfered corners)
        assert np.abs(u - x @ eps.T).max() <= 1e-8 * np.abs(u).max()
        assert np.abs(stress - sigma.ravel()).max() <= 1e-8 * np.abs(sigma).max()
        dev = sigma - np.trace(sigma) / 3 * np.eye(3)
        assert np.allclose(mesh.point_data["von_mises"], np.sqrt(1.5 * np.sum(dev * dev)), rtol=1e-8)
        for index, name in enumerate(("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")):
            on = mesh.point_data["patch"] == index
            axis, side = "xyz".index(name[0]), float(name[1:] == "max")
            assert on.any() and np.abs(x[on, axis] - side).max() < 1e-12
