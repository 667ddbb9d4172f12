"""Figures and claims of cgfem.report, on synthetic run folders that follow the contracts
(summary.json, step/surface/contact VTU files written with meshio): every assertion is on
the data the figure draws, not on pixels."""

from __future__ import annotations

import json
from pathlib import Path

import meshio
import numpy as np
import pytest

from cgfem.case.load import load_case
from cgfem.fem.space import Space
from cgfem.geometry.builders import build_solid
from cgfem.report import figure
from cgfem.report.claims import (claim_coarse_facets, claim_lower_reaction, claim_lower_von_mises,
                                 claim_optimal_rate, claims, write_claims)
from cgfem.report.convergence import fitted_rate
from cgfem.report.curves import geometry_errors
from cgfem.report.energy import TOTAL, ErrorRow, energy_errors, read_error_tables, write_error_table
from cgfem.report.runs import Run, load_runs
from cgfem.report.style import new_figure, save_figure, short_log_ticks, short_number
from cgfem.run import embed_body
from tests.support.paths import REPO

PULLED, CLAMPED = "link_b/cap_a+cap_b", "link_a/cap_a+cap_b"
HEX = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)


def _cloud(path: Path, points: np.ndarray, data: dict) -> None:
    cells = [("vertex", np.arange(len(points)).reshape(-1, 1))]
    meshio.write(path, meshio.Mesh(points, cells, point_data=data))


def make_run(root: Path, case: str, level: int, surface: str, *, bodies=("link_a", "link_b"),
             status="converged", reactions=None, von_mises=None, residuals=None,
             volume_error=0.0, seconds=(1.0, 2.0), surface_cloud=None, active=3) -> Path:
    """A run folder: one hexahedron and a small boundary cloud per body per step. ``reactions``:
    (n_steps, 2) F_y on (pulled, clamped); ``von_mises``: peak per step (all bodies)."""
    folder = root / "runs" / case / f"L{level}_{surface}"
    folder.mkdir(parents=True)
    reactions = np.zeros((1, 2)) if reactions is None else np.asarray(reactions, float)
    n = reactions.shape[0]
    h = 0.005 / 2**level
    steps = []
    for k in range(n):
        steps.append({
            "load_factor": (k + 1) / (n + 1) if status == "failed" else (k + 1) / n,
            "newton_residuals": [1.0, 1e-4, 1e-10],
            "pass_residuals": residuals if residuals is not None else [[1.0, 1e-4, 1e-10], [1e-6, 1e-12]],
            "outer_passes": 2,
            "reactions": {PULLED: [0.0, reactions[k, 0], 0.0], CLAMPED: [0.0, reactions[k, 1], 0.0]},
            "outer_converged": status != "outer_not_converged" or k == n - 1,
            "contact": {"force": [0.0, 1.0, 0.0], "active_points": active, "max_pressure": 1.0,
                        "pairs": {f"{bodies[-1]}/{bodies[0]}": {"force": [0.0, 1.0, 0.0],
                                                               "active_points": active, "max_pressure": 1.0}}},
            "max_von_mises": {b: float(von_mises if von_mises is not None else 1e6) for b in bodies},
            "von_mises_max_nodal": {b: 2.0 * float(von_mises if von_mises is not None else 1e6) for b in bodies},
            "error_estimate": {b: 0.1 for b in bodies}, "energy_norm": {b: 1.0 for b in bodies},
            "seconds": 0.5})
        points = np.concatenate([HEX * h + 0.1 * i for i in range(len(bodies))])
        cells = np.arange(8 * len(bodies)).reshape(-1, 8)
        meshio.write(folder / f"step_{k + 1:03d}.vtu", meshio.Mesh(
            points, [("hexahedron", cells)],
            point_data={"displacement": np.full((len(points), 3), 1e-4 * (k + 1)),
                        "stress": np.tile(np.arange(9.0), (len(points), 1)) * (k + 1),
                        "von_mises": np.ones(len(points))},
            cell_data={"status": [np.ones(len(bodies), np.int32)], "element_von_mises": [np.ones(len(bodies))],
                       "body": [np.arange(len(bodies), dtype=np.int32)]}))
        if surface_cloud is None:
            x = np.random.default_rng(k).random((10 * len(bodies), 3)) * 0.01
            body = np.repeat(np.arange(len(bodies)), 10).astype(np.int32)
            u = x * (k + 1) * 1e-2
            stress = np.outer(x[:, 1], np.arange(9.0)) * 1e8
            vm = 1e6 * (1.0 + body + x[:, 0])
            _cloud(folder / f"surface_{k + 1:03d}.vtu", x, {
                "displacement": u, "stress": stress, "von_mises": vm, "body": body,
                "patch": np.zeros(len(x), np.int32)})
        else:
            _cloud(folder / f"surface_{k + 1:03d}.vtu", *surface_cloud(k))
        xc = np.random.default_rng(100 + k).random((6, 3)) * 0.01
        _cloud(folder / f"contact_{k + 1:03d}.vtu", xc, {     # current positions (README)
            "gap": np.zeros(6), "pressure": -np.ones(6), "p_N": -np.ones(6),
            "active": (np.arange(6) < active).astype(np.int32), "normal": np.tile([0, 0, 1.0], (6, 1)),
            "weight": np.ones(6), "force": np.tile([0, 0, 1.0], (6, 1)), "pair": np.zeros(6, np.int32)})
    summary = {
        "case": case, "level": level, "surface": surface, "status": status,
        "message": {"converged": "", "outer_not_converged": "outer loop not converged at load factors 1"
                    }.get(status, "Newton failed after 5 cut-backs"),
        "bodies": {b: {"nodes": 8, "dofs": 24 * 8**level, "volume": 1.0 + volume_error, "area": 2.0,
                       "brep_volume": 1.0, "brep_area": 2.0, "h": h} for b in bodies},
        "steps": steps, "timings": {"build_s": seconds[0], "solve_s": seconds[1]}, "versions": {}}
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder / "summary.json"


def _lines(ax):
    return [line for line in ax.get_lines() if not line.get_label().startswith("optimal")]


# ---------------------------------------------------------------- rates and fig09


def test_log_axes_are_labelled_in_short_numbers_at_1_2_5(tmp_path):
    """Tick labels on a log axis: 1, 2 and 5 times the powers of ten, in at most four
    significant digits with k from 10^4 and M from 10^6, and no minor labels."""
    assert [short_number(v) for v in (0.5, 50, 2000, 9999, 1e4, 2.5e5, 1.5e6)] == \
        ["0.5", "50", "2000", "9999", "10k", "250k", "1.5M"]
    fig, axes = new_figure()
    ax = axes[0, 0]
    ax.loglog([1500, 60000], [1, 2])
    short_log_ticks(ax.xaxis)
    fig.canvas.draw()
    lo, hi = ax.get_xlim()
    shown = [t.get_text() for t, x in zip(ax.get_xticklabels(), ax.get_xticks()) if lo <= x <= hi]
    assert shown == ["2000", "5000", "10k", "20k", "50k"]
    assert not any(t.get_text() for t in ax.xaxis.get_minorticklabels())
    save_figure(fig, tmp_path / "ticks.png", tmp_path / "ticks.pdf")     # draws and closes it


def test_fitted_rate_recovers_the_synthetic_rate():
    h = 0.01 / 2.0 ** np.arange(4)
    assert fitted_rate(h, 3.7 * h**0.8731) == pytest.approx(0.8731, abs=1e-10)


def _error_rows(rate_of):
    rows = []
    for surface, p in rate_of.items():
        for level in range(4):
            h = 0.00125 / 2**level
            for body, c in (("lower", 0.3), ("upper", 0.4), (TOTAL, 0.5)):
                rows.append(ErrorRow(surface, level, body, 600 * 8**level, h, c * (h / 0.00125) ** p))
    return rows


def test_fig09_draws_every_definition_with_its_fitted_rate(tmp_path):
    rate_of = {"facets": 0.71, "nurbs_fe": 0.93, "nurbs_fit": 1.02}
    table = tmp_path / "errors.csv"
    write_error_table(_error_rows(rate_of), table)
    assert read_error_tables([table]) == _error_rows(rate_of)
    assert len(figure("fig09", [table]).axes) == 1                 # the whole problem
    fig = figure("fig09", [table], bodies=("lower", TOTAL))
    assert len(fig.axes) == 2
    for ax in fig.axes:
        lines = _lines(ax)
        assert len(lines) == 3
        for line in lines:
            surface, rate = line.get_label().split(": rate ")
            assert float(rate) == pytest.approx(rate_of[surface], abs=0.005)
            assert list(line.get_xdata()) == [600 * 8**k for k in range(4)]
        triangle = [line for line in ax.get_lines() if line.get_label().startswith("optimal")]
        x, y = triangle[0].get_xdata(), triangle[0].get_ydata()
        assert np.log(y[1] / y[0]) / np.log(x[1] / x[0]) == pytest.approx(-1.0 / 3.0, rel=1e-12)
    save_figure(fig, tmp_path / "f.png", tmp_path / "f.pdf")
    assert (tmp_path / "f.png").stat().st_size > 1000 and (tmp_path / "f.pdf").stat().st_size > 1000


def test_a_figure_drawn_again_is_the_same_file(tmp_path, monkeypatch):
    """The same figure saved under two clock readings gives the same PNG and PDF bytes: the PDF
    carries no creation date (matplotlib stamps ``SOURCE_DATE_EPOCH``, else the clock)."""
    files = []
    for when in ("1000000000", "2000000000"):
        monkeypatch.setenv("SOURCE_DATE_EPOCH", when)
        fig, axes = new_figure()
        axes[0, 0].plot([1.0, 2.0, 3.0], [3.0, 1.0, 2.0], label="a line")
        axes[0, 0].legend()
        png, pdf = tmp_path / f"{when}.png", tmp_path / f"{when}.pdf"
        save_figure(fig, png, pdf)
        files.append((png.read_bytes(), pdf.read_bytes()))
    assert files[0] == files[1] and b"/CreationDate" not in files[0][1]


# ---------------------------------------------------------------- energy error of a run


def test_energy_error_of_a_linear_field_is_exact(tmp_path):
    """A linear displacement u = G x is reproduced exactly by H8: the strain at every volume
    point is sym(G), so against a constant reference strain per body the error is known:
    ||e||_b = |sym G - eps_b| sqrt(V_b) (Frobenius norm as the energy), here over a fixed
    reference norm R; the whole problem's error is the root of the sum of squares."""
    case_file = REPO / "config" / "cases" / "planar.yaml"
    case = load_case(case_file)
    G = np.array([[1.0, 2.0, 0.0], [0.5, -3.0, 1.0], [0.0, 4.0, 2.0]]) * 1e-4
    folder = tmp_path / "L0_nurbs_fe"
    folder.mkdir()
    points, cells, body_of_cell, shift, bodies = [], [], [], 0, {}
    for index, body in enumerate(case.bodies):
        space = Space.from_embedding(embed_body(build_solid(body.geometry), body, 0, "nurbs_fe"))
        points.append(space.coordinates)
        cells.append(space.connectivity + shift)
        body_of_cell.append(np.full(space.n_elements, index, np.int32))
        shift += space.n_nodes
        bodies[body.name] = {"nodes": space.n_nodes, "dofs": space.n_dofs, "volume": 0, "area": 0,
                             "brep_volume": 0, "brep_area": 0, "h": space.h}
    x = np.concatenate(points)
    meshio.write(folder / "step_001.vtu", meshio.Mesh(
        x, [("hexahedron", np.concatenate(cells))], point_data={"displacement": x @ G.T},
        cell_data={"body": [np.concatenate(body_of_cell)]}))
    (folder / "summary.json").write_text(json.dumps({
        "case": "planar", "level": 0, "surface": "nurbs_fe", "status": "converged",
        "bodies": bodies, "steps": [{"load_factor": 1.0}]}))
    eps_ref = {"lower": np.diag([0.0, 1e-4, -2e-4]), "upper": np.diag([0.0, -1e-4, 3e-4])}
    volumes, R = {}, 3e-8

    def error(xq, w, strain, body):
        volumes[body] = w.sum()
        d = strain - eps_ref[body]
        return np.sqrt(np.einsum("p,pij,pij->", w, d, d)) / R

    rows = energy_errors(case_file, folder, error)
    sym, volume = 0.5 * (G + G.T), 0.0025 * 0.01 * 0.01
    exact = {b: np.linalg.norm(sym - eps_ref[b]) * np.sqrt(volume) / R for b in eps_ref}
    exact[TOTAL] = np.hypot(exact["lower"], exact["upper"])
    assert [r.body for r in rows] == ["lower", "upper", TOTAL]
    for row in rows:
        assert row.error == pytest.approx(exact[row.body], rel=1e-10)
        assert row.dofs == sum(b["dofs"] for b in bodies.values())
        assert row.h == 0.00125
    assert volumes == pytest.approx({"lower": volume, "upper": volume}, rel=1e-10)


# ---------------------------------------------------------------- line figures


def test_fig10_profile_takes_the_points_near_the_line(tmp_path):
    y = np.linspace(0.0, 0.01, 11)

    def cloud(k):
        on_line = np.column_stack([np.full(11, 0.00125), y, np.full(11, 0.01)])
        off_x = on_line + [0.001, 0.0, 0.0]                 # outside the band in x
        upper = on_line.copy()                               # same place, other body
        x = np.concatenate([on_line, off_x, upper])
        body = np.repeat([0, 0, 1], 11).astype(np.int32)
        u = np.zeros((33, 3))
        u[:, 2] = -1e-6 * (1 + x[:, 1] * 100) * (1 + body)
        u[11:22, 2] = 5.0
        return x, {"displacement": u, "body": body}

    paths = [make_run(tmp_path, "planar", 2, s, bodies=("lower", "upper"), surface_cloud=cloud)
             for s in ("facets", "nurbs_fit")]
    fig = figure("fig10", paths, body="lower", line={"x": 0.00125, "z": 0.01})
    lines = fig.axes[0].get_lines()
    assert len(lines) == 2
    for line in lines:
        np.testing.assert_allclose(line.get_xdata(), y)
        np.testing.assert_allclose(line.get_ydata(), -1e-6 * (1 + y * 100))


def test_fig13_draws_every_run_and_a_failed_one_as_failed(tmp_path):
    good = np.column_stack([np.arange(1, 6) * 10.0, -np.arange(1, 6) * 10.0])
    paths = [make_run(tmp_path, "chain2_steel", level, s, reactions=good * (1 + level))
             for s in ("nurbs_fe", "nurbs_fit") for level in (0, 1)]
    paths.append(make_run(tmp_path, "chain2_steel", 0, "facets", status="failed", reactions=good[:2]))
    fig = figure("fig13", paths, pulled=PULLED, clamped=CLAMPED)
    pulled, clamped, by_level = fig.axes[:3]
    for ax, column in ((pulled, 0), (clamped, 1)):
        lines = ax.get_lines()
        assert len(lines) == 5
        failed = [line for line in lines if "failed" in line.get_label()]
        assert len(failed) == 1 and failed[0].get_linestyle() == "--" and failed[0].get_marker() == "x"
        np.testing.assert_allclose(failed[0].get_ydata(), np.concatenate([[0.0], good[:2, column]]))
        solid = [line for line in lines if line.get_linestyle() == "-"]
        assert len(solid) == 4 and all(line.get_xdata()[-1] == 1.0 for line in solid)
    finals = {line.get_label(): list(line.get_ydata()) for line in by_level.get_lines()}
    assert finals == {"nurbs_fe": [50.0, 100.0], "nurbs_fit": [50.0, 100.0]}


def test_newton_timings_and_geometry_figures(tmp_path):
    paths = []
    for case in ("planar", "chain3"):
        for level in (0, 1):
            paths.append(make_run(tmp_path, case, level, "nurbs_fe", residuals=[[1.0, 0.1, 1e-3, 1e-9]],
                                  volume_error=10.0 ** (-3 - level), seconds=(level + 1.0, 3.0 * level + 1)))
    fig = figure("newton", paths)
    assert len(fig.axes) == 2
    # summary.json stores norms (N): drawn relative to the first residual of each step
    scaled = make_run(tmp_path / "scaled", "planar", 0, "facets", reactions=np.ones((2, 2)),
                      residuals=[[6329.0, 0.3, 1e-6], [298.0, 3e-8]])
    np.testing.assert_allclose(Run.load(scaled).newton_residuals(),
                               np.tile(np.array([6329.0, 0.3, 1e-6, 298.0, 3e-8]) / 6329.0, 2), rtol=1e-14)
    for ax in fig.axes:
        assert len(ax.get_lines()) == 2
        np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), [1.0, 0.1, 1e-3, 1e-9])
    fig = figure("timings", paths)
    build, solve = fig.axes[:2]
    assert len(build.get_lines()) == 2
    np.testing.assert_allclose(build.get_lines()[0].get_xdata(), [48, 384])
    np.testing.assert_allclose(solve.get_lines()[0].get_ydata(), [1.0, 4.0])
    fig = figure("geometry", paths)
    volume, area = fig.axes[:2]
    np.testing.assert_allclose(volume.get_lines()[0].get_ydata(), [1e-3, 1e-4], rtol=1e-9)
    np.testing.assert_allclose(area.get_lines()[0].get_ydata(), [1e-16, 1e-16])
    assert geometry_errors(Run.load(paths[0]))[0] == pytest.approx(1e-3)


# ---------------------------------------------------------------- maps (pyvista off-screen)



def test_map_figures_one_panel_per_run(tmp_path):
    paths = [make_run(tmp_path, "chain2_steel", 0, s, reactions=np.ones((2, 2))) for s in ("facets", "nurbs_fe")]
    paths.append(make_run(tmp_path, "chain2_steel", 1, "nurbs_fit", status="failed", reactions=np.ones((1, 2))))
    fig = figure("fig14", paths)
    panels = [ax for ax in fig.axes if ax.images]
    assert len(panels) == 3
    assert [ax.get_title() for ax in panels] == ["facets L0", "nurbs_fe L0", "nurbs_fit L1 (failed beyond load 0.5)"]
    assert all(ax.images[0].get_array().std() > 0 for ax in panels)       # something was drawn
    sigma_yy = [np.asarray(meshio.read(Path(p).parent / f"surface_{Run.load(p).n_steps:03d}.vtu")
                           .point_data["stress"])[:, 4] for p in paths]
    limits = fig.axes[-1].get_ylim()
    assert limits == pytest.approx((min(s.min() for s in sigma_yy), max(s.max() for s in sigma_yy)))

    fig = figure("fig15", paths[:2])
    titles = [ax.get_title() for ax in fig.axes if ax.images]
    assert titles == ["(a) facets L0: 3 active points", "(b) nurbs_fe L0: 3 active points",
                      "(c) nurbs_fe L0: 3 active points on link_b"]

    chain3 = [make_run(tmp_path, "chain3", 0, s, bodies=("link_a", "link_c", "link_b"), von_mises=v)
              for s, v in (("facets", 2e8), ("nurbs_fe", 3e8))]
    fig = figure("fig17", chain3, body="link_c")
    titles = [ax.get_title() for ax in fig.axes if ax.images]
    assert titles == ["facets L0: peak 200 MPa", "nurbs_fe L0: peak 300 MPa"]
    vm = np.asarray(meshio.read(Path(chain3[0]).parent / "surface_001.vtu").point_data["von_mises"])[10:20]
    assert fig.axes[-1].get_ylim() == pytest.approx((vm.min(), vm.max()))


# ---------------------------------------------------------------- claims


def _chain2(root, facets_status="converged", facets_scale=0.5, nurbs_scale=1.0):
    base = np.column_stack([np.arange(1, 6) * 100.0, -np.arange(1, 6) * 100.0])
    paths = []
    for level in (0, 1, 2):
        converge = 1.0 + 0.5 / 4**level            # stiff on coarse meshes, O(h^2) to the limit
        for s in ("nurbs_fe", "nurbs_fit"):
            paths.append(make_run(root, "chain2_steel", level, s, reactions=base * converge * nurbs_scale))
        status = facets_status if level == 0 else "converged"
        scale = facets_scale[level] if isinstance(facets_scale, dict) else facets_scale
        f = base[:2] if status == "failed" else base * converge * scale
        paths.append(make_run(root, "chain2_steel", level, "facets", status=status, reactions=f))
    return paths


@pytest.mark.parametrize("holds", [True, False])
def test_claims_follow_the_fixture(tmp_path, holds):
    table = tmp_path / "errors.csv"
    write_error_table(_error_rows({"facets": 0.95 if holds else 0.6, "nurbs_fe": 1.0, "nurbs_fit": 1.1}), table)
    chain2 = _chain2(tmp_path, facets_status="failed" if holds else "converged",
                     facets_scale=0.9 if holds else {0: 1.0 / 1.5, 1: 1.1, 2: 1.1})
    chain3 = [make_run(tmp_path, "chain3", 1, s, bodies=("link_a", "link_c", "link_b"), von_mises=v)
              for s, v in (("facets", 2e8 if holds else 4e8), ("nurbs_fe", 3e8))]
    found = claims([table], chain2, chain3, rate_tolerance=0.1, reaction_level=2, pulled=PULLED,
                   component=1, von_mises_levels=[1], von_mises_body="link_c")
    assert [c.reproduced for c in found] == [holds] * 4
    text = write_claims(tmp_path / "claims.md", found).read_text()
    assert text.count("| yes |") == (4 if holds else 0) and text.count("| no |") == (0 if holds else 4)
    assert holds or "facets 0.600, nurbs_fe 1.000, nurbs_fit 1.100" in text


def test_claim_two_poor_facets_and_failing_nurbs(tmp_path):
    # facets converges on the coarse mesh but further from the reference than both NURBS: poor
    runs = load_runs(_chain2(tmp_path / "a", facets_scale=2.0))
    claim = claim_coarse_facets(runs, PULLED, 1)
    assert claim.reproduced and "facets 190.91%, nurbs_fe 45.45%" in claim.numbers
    # a NURBS definition failing on the coarse mesh breaks the claim even if facets fails too
    paths = _chain2(tmp_path / "b", facets_status="failed")
    bad = Path(paths[1]).parent                      # nurbs_fit L0
    summary = json.loads((bad / "summary.json").read_text())
    summary["status"] = "failed"
    (bad / "summary.json").write_text(json.dumps(summary))
    assert not claim_coarse_facets(load_runs(paths), PULLED, 1).reproduced


def test_claims_with_missing_runs_are_not_reproduced(tmp_path):
    table = tmp_path / "errors.csv"
    # nurbs_fit at one level only: no rate, so not "optimal for every definition"
    write_error_table([r for r in _error_rows({"facets": 1.0, "nurbs_fe": 1.0, "nurbs_fit": 1.0})
                       if r.surface != "nurbs_fit" or r.level == 0], table)
    claim = claim_optimal_rate([table], 0.1)
    assert not claim.reproduced and "nurbs_fit none (fewer than two levels)" in claim.numbers
    write_error_table(_error_rows({"facets": 1.0}), table)            # no NURBS definition run
    assert not claim_optimal_rate([table], 0.1).reproduced
    runs = load_runs([make_run(tmp_path, "chain2_steel", 2, "facets", reactions=np.ones((5, 2)))])
    assert not claim_lower_reaction(runs, 2, PULLED, 1).reproduced
    assert not claim_lower_von_mises(runs, [2], "link_c").reproduced


def test_claims_compare_the_nurbs_definitions_that_were_run(tmp_path):
    """Without nurbs_fit (not implemented yet, not planned) the claims compare facets with
    nurbs_fe alone, say so, and decide as they would with both NURBS definitions."""
    table = tmp_path / "errors.csv"
    write_error_table(_error_rows({"facets": 0.95, "nurbs_fe": 1.0}), table)
    claim = claim_optimal_rate([table], 0.1)
    assert claim.reproduced and "(facets, nurbs_fe)" in claim.text
    assert claim.numbers == "fitted rates in h: facets 0.950, nurbs_fe 1.000"
    write_error_table(_error_rows({"facets": 0.85, "nurbs_fe": 1.0}), table)
    assert not claim_optimal_rate([table], 0.1).reproduced

    paths = [p for p in _chain2(tmp_path / "c", facets_scale=2.0) if "nurbs_fit" not in str(p)]
    runs = load_runs(paths)
    claim = claim_coarse_facets(runs, PULLED, 1)
    assert claim.reproduced and "(nurbs_fe)" in claim.text
    assert "facets 190.91%, nurbs_fe 45.45%" in claim.numbers and "nurbs_fit" not in claim.numbers
    claim = claim_lower_reaction(runs, 2, PULLED, 1)         # facets 2x above nurbs_fe
    assert not claim.reproduced and "(nurbs_fe)" in claim.text
    lower = load_runs([p for p in _chain2(tmp_path / "d", facets_scale=0.9) if "nurbs_fit" not in str(p)])
    claim = claim_lower_reaction(lower, 2, PULLED, 1)
    assert claim.reproduced
    assert claim.numbers == "|F| at load factor 1: facets 464.062 N, nurbs_fe 515.625 N"   # 500 (1 + 0.5 / 16)


def test_outer_not_converged_is_neither_converged_nor_failed(tmp_path):
    """A run whose outer loop hit its cap reached every step: drawn to the last step, dotted
    with hollow markers (not dashed crosses), on the level panel, and not 'converged' for the
    claims."""
    good = np.column_stack([np.arange(1, 6) * 10.0, -np.arange(1, 6) * 10.0])
    paths = [make_run(tmp_path, "chain2_steel", 0, "nurbs_fe", reactions=good),
             make_run(tmp_path, "chain2_steel", 1, "nurbs_fe", status="outer_not_converged", reactions=good * 0.9),
             make_run(tmp_path, "chain2_steel", 0, "facets", status="failed", reactions=good[:2])]
    runs = {r.label: r for r in load_runs(paths)}
    outer, failed = runs["nurbs_fe L1"], runs["facets L0"]
    assert (outer.converged, outer.outer_not_converged, outer.failed) == (False, True, False)
    assert (failed.converged, failed.outer_not_converged, failed.failed) == (False, False, True)
    assert outer.status_note == "outer loop not converged" and failed.status_note == "failed beyond load 0.667"
    assert runs["nurbs_fe L0"].status_note == ""
    fig = figure("fig13", paths, pulled=PULLED, clamped=CLAMPED)
    by_label = {line.get_label(): line for line in fig.axes[0].get_lines()}
    line = by_label["nurbs_fe L1 (outer loop not converged)"]
    assert line.get_linestyle() == ":" and line.get_markerfacecolor() == "white"
    np.testing.assert_allclose(line.get_xdata(), [0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    assert by_label["facets L0 (failed beyond load 0.667)"].get_linestyle() == "--"
    assert by_label["nurbs_fe L0"].get_linestyle() == "-"
    level_panel = fig.axes[2]
    np.testing.assert_allclose(level_panel.get_lines()[0].get_ydata(), [50.0, 45.0])
    hollow = level_panel.collections[0]
    np.testing.assert_allclose(hollow.get_offsets(), [[1.0, 45.0]])
    assert hollow.get_label() == "nurbs_fe: outer loop not converged"
    # the claims count it as not converged (claim 4 needs converged runs)
    chain3 = [make_run(tmp_path, "chain3", 0, "facets", bodies=("link_a", "link_c", "link_b"), von_mises=1e8),
              make_run(tmp_path, "chain3", 0, "nurbs_fe", bodies=("link_a", "link_c", "link_b"), von_mises=3e8,
                       status="outer_not_converged")]
    claim = claim_lower_von_mises(load_runs(chain3), [0], "link_c")
    assert not claim.reproduced and "nurbs_fe outer_not_converged" in claim.numbers


def test_claim_4_needs_facets_to_carry_the_load(tmp_path):
    """A facets run whose links never touch has a tiny von Mises stress: not a comparison."""
    chain3 = [make_run(tmp_path, "chain3", 0, s, bodies=("link_a", "link_c", "link_b"), von_mises=v)
              for s, v in (("facets", 1e-2), ("nurbs_fe", 3e8))]
    summary = Path(chain3[0])
    data = json.loads(summary.read_text())
    for step in data["steps"]:
        step["contact"]["force"] = [0.0, 1e-9, 0.0]
    summary.write_text(json.dumps(data))
    claim = claim_lower_von_mises(load_runs(chain3), [0], "link_c")
    assert not claim.reproduced and "facets carries no load" in claim.numbers and "never touch" in claim.numbers


def test_contact_points_are_drawn_where_the_file_puts_them(tmp_path):
    """contact_NNN.vtu holds the slave points at their current positions: fig15 draws the
    active ones as stored, not warped again by the boundary cloud's displacement."""
    from cgfem.report.maps import active_contact_points

    path = make_run(tmp_path, "chain2_rubber", 0, "nurbs_fe", reactions=np.ones((2, 2)), active=4)
    run = Run.load(path)
    cloud = run.contact_points()
    assert set(cloud.point_data) == {"gap", "pressure", "p_N", "active", "normal", "weight", "force", "pair"}
    np.testing.assert_array_equal(active_contact_points(run), np.asarray(cloud.points)[:4])
    np.testing.assert_allclose(run.contact_force(), [0.0, 1.0, 0.0])
    np.testing.assert_allclose(run.contact_force(pair="link_b/link_a"), [0.0, 1.0, 0.0])


def test_fig15_panel_c_draws_the_active_points_on_the_deformed_slave(tmp_path):
    """Panel (c): the slave body of the first pair (link_b), warped by its displacement, its
    active contact points as stored, the camera on the side of their mean normal."""
    from cgfem.report.maps import contact_panel

    path = make_run(tmp_path, "chain2_rubber", 0, "nurbs_fe", reactions=np.ones((2, 2)), active=4)
    run = Run.load(path)
    panel = contact_panel(run)
    assert panel["body"] == "link_b"
    cloud = meshio.read(Path(path).parent / "surface_002.vtu")
    mine = np.asarray(cloud.point_data["body"]).ravel() == 1
    x, u = np.asarray(cloud.points)[mine], np.asarray(cloud.point_data["displacement"])[mine]
    np.testing.assert_allclose(panel["points"], x + u)
    np.testing.assert_allclose(panel["displacement"], u)
    contact = meshio.read(Path(path).parent / "contact_002.vtu")
    np.testing.assert_array_equal(panel["active"], np.asarray(contact.points)[:4])
    np.testing.assert_allclose(panel["view"], [0.0, 0.0, 1.0])
    # the colour scale of the figure covers panel (c) too
    fig = figure("fig15", [path])
    assert len([ax for ax in fig.axes if ax.images]) == 2
    assert fig.axes[-1].get_ylim()[1] >= np.linalg.norm(u, axis=1).max() * (1 - 1e-12)
    # a last step without contact pairs: no panel (c)
    data = json.loads(Path(path).read_text())
    data["steps"][-1]["contact"]["pairs"] = {}
    Path(path).write_text(json.dumps(data))
    fig = figure("fig15", [path])
    assert [ax.get_title() for ax in fig.axes if ax.images] == ["(a) nurbs_fe L0: 4 active points"]


def test_centred_colour_values_keep_zero_in_the_middle():
    """fig14's diverging map: each sign scaled to its own extreme, zero at the centre."""
    from cgfem.report.maps import centred

    v = np.array([-20.0, -10.0, 0.0, 4.5, 9.0])
    assert np.allclose(centred(v, (-20.0, 9.0)), [-1.0, -0.5, 0.0, 0.5, 1.0])


def test_claim_4_over_levels_decides_where_it_can(tmp_path):
    """Claim 4 on levels 1 and 2: decided where both runs converged, undecided levels named
    with the reason; reproduced only if facets is lower on every decided level."""
    links = ("link_a", "link_c", "link_b")
    chain3 = [make_run(tmp_path, "chain3", 1, "facets", bodies=links, von_mises=2.9e8),
              make_run(tmp_path, "chain3", 1, "nurbs_fe", bodies=links, von_mises=5.0e8),
              make_run(tmp_path, "chain3", 2, "facets", bodies=links, von_mises=1e8, status="failed",
                       reactions=np.zeros((2, 2))),
              make_run(tmp_path, "chain3", 2, "nurbs_fe", bodies=links, von_mises=6.0e8)]
    claim = claim_lower_von_mises(load_runs(chain3), [1, 2], "link_c")
    assert claim.reproduced and "(meshes 1, 2)" in claim.text
    assert claim.numbers == ("L1: facets 290 MPa, nurbs_fe 500 MPa; L2: not decided, missing or unconverged "
                             "runs: facets failed, nurbs_fe converged")
    # higher with facets on the one decided level: not reproduced
    higher = [make_run(tmp_path / "b", "chain3", 1, s, bodies=links, von_mises=v)
              for s, v in (("facets", 6e8), ("nurbs_fe", 5e8))]
    assert not claim_lower_von_mises(load_runs(higher), [1, 2], "link_c").reproduced
    # nothing decided: not reproduced
    assert not claim_lower_von_mises(load_runs(chain3[2:]), [1, 2], "link_c").reproduced


def test_newton_iterations_count_every_pass_of_every_step_less_its_first_residual():
    """Residual lists hold the initial residual, then one entry per iteration: 3 residuals
    are 2 iterations, a pass that starts converged (1 residual) none."""
    steps = [{"pass_residuals": [[1.0, 1e-3, 1e-9], [1e-10]]}, {"pass_residuals": [[1.0, 1e-12]]}]
    assert Run(Path("."), {"steps": steps}).newton_iterations == 3

