"""The validation figure and the claims' distances (cgfem.report.validation) on a synthetic
reference JSON and synthetic run summaries: every assertion is on the data drawn."""

from __future__ import annotations

import json
from types import SimpleNamespace
from pathlib import Path

import numpy as np
import pytest

from cgfem.report import figure
from cgfem.report.claims import claims_markdown, reference_distance
from cgfem.report.runs import load_runs
from cgfem.report.validation import Reference, _order_style, _series, final_error, run_errors, von_mises_error

PULLED, CLAMPED = "link_b/cap_a+cap_b", "link_a/cap_a+cap_b"
REF_F = np.array([100.0, 250.0, 400.0, 600.0])          # reference pulled reaction per step (N)


def reference_json(path: Path, case: str = "chain3", mesh: float = 0.001, penalty: float = 0.0005) -> Path:
    steps = [{"load_factor": (k + 1) / 4, "reactions": {PULLED: [0.0, f, 0.0], CLAMPED: [0.0, -f, 0.0]},
              "max_von_mises": {"link_c": 2.0e9}} for k, f in enumerate(REF_F)]
    path.write_text(json.dumps({
        "case": case, "supports": {"pulled": PULLED, "clamped": CLAMPED},
        "reference": {"dofs": 123456, "steps": steps},
        "uncertainty": {"mesh": mesh, "penalty": penalty, "accepted": True,
                        "meshes": [{"von_mises_change_to_finest": {"link_c": 0.04}},
                                   {"von_mises_change_to_finest": {"link_c": 0.0}}]}}))
    return path


def run_summary(root: Path, case: str, level: int, surface: str, scale: float, n_steps: int = 4,
                status: str = "converged", von_mises: float = 1.0e9, dofs: int = 1000) -> Path:
    folder = root / case / f"L{level}_{surface}"
    folder.mkdir(parents=True)
    steps = [{"load_factor": (k + 1) / 4, "reactions": {PULLED: [0.0, scale * REF_F[k], 0.0],
                                                       CLAMPED: [0.0, -scale * REF_F[k], 0.0]},
              "max_von_mises": {"link_c": von_mises}} for k in range(n_steps)]
    (folder / "summary.json").write_text(json.dumps({
        "case": case, "level": level, "surface": surface, "status": status,
        "bodies": {"link_c": {"dofs": dofs}}, "steps": steps}))
    return folder / "summary.json"


def test_errors_against_the_reference(tmp_path):
    ref = Reference.load(reference_json(tmp_path / "chain3.json"))
    assert ref.pulled == PULLED and ref.uncertainty == 0.001 and ref.dofs == 123456
    stiff = load_runs([run_summary(tmp_path, "chain3", 0, "facets", 1.1, von_mises=5.0e8)])[0]
    lf, err = run_errors(stiff, ref, PULLED)
    np.testing.assert_allclose(lf, [0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(err, 0.1)
    assert final_error(stiff, ref, PULLED) == pytest.approx(0.1)
    assert von_mises_error(stiff, ref, "link_c") == pytest.approx(-0.75)
    # a run that stopped at step 2 is compared on its steps only; it has no final error
    short = load_runs([run_summary(tmp_path, "chain3", 1, "facets", 0.9, n_steps=2, status="failed")])[0]
    lf, err = run_errors(short, ref, PULLED)
    np.testing.assert_allclose(lf, [0.25, 0.5])
    np.testing.assert_allclose(err, -0.1)
    assert np.isnan(final_error(short, ref, PULLED)) and np.isnan(von_mises_error(short, ref, "link_c"))


def test_validation_figure_draws_the_errors(tmp_path):
    ref = reference_json(tmp_path / "chain3.json")
    runs = [run_summary(tmp_path, "chain3", level, surface, 1.0 + e, dofs=1000 * 8 ** level)
            for surface, errors in (("facets", (0.4, 0.2, 0.1)), ("nurbs_fe", (0.2, 0.05, 0.0125)))
            for level, e in enumerate(errors)]
    fig = figure("validation", [str(ref), *map(str, runs)])
    steps, dofs, vm = fig.axes[:3]
    lines = {line.get_label(): line for line in steps.get_lines()}
    np.testing.assert_allclose(lines["nurbs_fe L1"].get_ydata(), 5.0)         # percent, every step
    lines = {line.get_label(): line for line in dofs.get_lines()}
    np.testing.assert_allclose(lines["nurbs_fe"].get_xdata(), [1000, 8000, 64000])
    np.testing.assert_allclose(lines["nurbs_fe"].get_ydata(), [0.2, 0.05, 0.0125])
    np.testing.assert_allclose(lines["facets"].get_ydata(), [0.4, 0.2, 0.1])
    np.testing.assert_allclose(lines["reference uncertainty (0.10%)"].get_ydata(), 0.001)
    assert dofs.get_xscale() == "log" and dofs.get_yscale() == "log"
    vm_lines = {line.get_label(): line for line in vm.get_lines()}
    np.testing.assert_allclose(vm_lines["facets"].get_ydata(), 0.5)          # 1 GPa against 2 GPa
    # the peak's own uncertainty: its change between the reference's two finest meshes
    np.testing.assert_allclose(vm_lines["reference uncertainty (4.00%)"].get_ydata(), 0.04)


def test_claims_name_the_distance_of_their_runs(tmp_path):
    refs = {"chain3": Reference.load(reference_json(tmp_path / "chain3.json"))}
    runs = load_runs([run_summary(tmp_path, "chain3", 1, "facets", 1.25),
                      run_summary(tmp_path, "chain3", 1, "nurbs_fe", 0.98, von_mises=3.0e9)])
    text = reference_distance(runs, refs, "link_c")
    assert "facets L1 +25.00% (von Mises -50.00%)" in text
    assert "nurbs_fe L1 -2.00% (von Mises +50.00%)" in text
    assert "0.10% uncertain, its peak von Mises 4.00%" in text
    assert reference_distance(runs, {}) == "no reference of chain3 in this configuration"
    from cgfem.report.claims import Claim
    table = claims_markdown([Claim(4, "x", True, "n", text), Claim(1, "y", False, "m")])
    rows = [line for line in table.splitlines() if line.startswith("| ") and line[2].isdigit()]
    assert [r.split("|")[5].strip() for r in rows] == [text, "no reference"]


def test_each_definition_and_order_is_its_own_series():
    """Runs of one definition at orders 1 and 2 are two series, each by level, labelled
    ``nurbs_fe`` and ``nurbs_fe o2``, drawn solid and dashed: joining them would draw a line
    from order 1 at level 2 back to order 2 at level 0."""
    runs = [SimpleNamespace(surface=s, order=o, level=l)
            for s, o, l in [("nurbs_fe", 1, 2), ("nurbs_fe", 2, 0), ("nurbs_fe", 1, 0), ("facets", 1, 1)]]
    series = _series(runs)
    assert [(label, order, [r.level for r in group]) for label, order, group in series] == [
        ("facets", 1, [1]), ("nurbs_fe", 1, [0, 2]), ("nurbs_fe o2", 2, [0])]
    assert _order_style(1)["linestyle"] == "-" and _order_style(2)["linestyle"] == "--"
