"""The accuracy figure (cgfem.report.accuracy) and the claims' order-2 line on synthetic run
summaries of both element orders: every assertion is on the data drawn or decided."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cgfem.report import figure
from cgfem.report.accuracy import accuracy_lines, best_target, final_reaction, wall_seconds
from cgfem.report.claims import claim_order2, claims, claims_markdown
from cgfem.report.runs import Run, load_runs
from cgfem.report.validation import load_references
from tests.unit.test_validation_report import REF_F, reference_json

PULLED, CLAMPED = "link_b/cap_a+cap_b", "link_a/cap_a+cap_b"
LINKS = ("link_a", "link_c", "link_b")


def summary(root: Path, case: str, level: int, surface: str, order: int, force: float, *,
            dofs: int = 1000, seconds: tuple[float, float] = (1.0, 2.0), status: str = "converged",
            von_mises: float = 1e8, contact: float = 1.0) -> Path:
    """A run folder with summary.json alone: 2 steps, the pulled reaction ``force`` (N) at the
    last one (half of it at the first; one step at load 0.5 if ``status`` is failed)."""
    suffix = "" if order == 1 else f"_o{order}"
    folder = root / "runs" / case / f"L{level}_{surface}{suffix}"
    folder.mkdir(parents=True)
    loads = [0.5] if status == "failed" else [0.5, 1.0]
    steps = [{"load_factor": t, "reactions": {PULLED: [0.0, t * force, 0.0], CLAMPED: [0.0, -t * force, 0.0]},
              "max_von_mises": {b: von_mises for b in LINKS},
              "contact": {"force": [0.0, contact, 0.0], "pairs": {}}} for t in loads]
    data = {"case": case, "level": level, "surface": surface, "status": status,
            "bodies": {"link_a": {"dofs": dofs // 2}, "link_b": {"dofs": dofs - dofs // 2}},
            "steps": steps, "timings": {"build_s": seconds[0], "solve_s": seconds[1]}}
    if order != 1:                      # order 1 as in summaries written before orders existed
        data["order"] = order
    (folder / "summary.json").write_text(json.dumps(data))
    return folder / "summary.json"


def _chain2(root: Path) -> list[Path]:
    """chain2_steel: order 1 at levels 0-1 and order 2 at level 0 for facets and nurbs_fe;
    order 2 has 4x the unknowns and 10x the seconds of order 1 at the same level."""
    paths = []
    for surface, scale in (("facets", 0.9), ("nurbs_fe", 1.0)):
        for level, f in ((0, 700.0), (1, 520.0)):
            paths.append(summary(root, "chain2_steel", level, surface, 1, scale * f, dofs=1000 * 8**level,
                                 seconds=(1.0 + level, 2.0 + level)))
        paths.append(summary(root, "chain2_steel", 0, surface, 2, scale * 480.0, dofs=4000, seconds=(10.0, 20.0)))
    return paths


def _lines_of(ax) -> dict:
    return {line.get_label(): line for line in ax.get_lines()}


def test_the_figure_draws_every_run_of_both_orders_against_the_reference(tmp_path):
    ref = reference_json(tmp_path / "chain2_steel.json", case="chain2_steel")
    paths = _chain2(tmp_path)
    fig = figure("accuracy", [str(ref), *map(str, paths)], pulled=PULLED)
    dofs, wall = fig.axes[:2]
    assert len(fig.axes) == 2                              # one example: one row
    for ax, x1, x2 in ((dofs, [1000, 8000], [4000]), (wall, [3.0, 5.0], [30.0])):
        lines = _lines_of(ax)
        np.testing.assert_allclose(lines["nurbs_fe, order 1"].get_xdata(), x1)
        np.testing.assert_allclose(lines["nurbs_fe, order 1"].get_ydata(), [700.0, 520.0])
        np.testing.assert_allclose(lines["facets, order 1"].get_ydata(), [630.0, 468.0])
        np.testing.assert_allclose(lines["nurbs_fe, order 2"].get_xdata(), x2)
        np.testing.assert_allclose(lines["nurbs_fe, order 2"].get_ydata(), [480.0])
        assert lines["nurbs_fe, order 2"].get_linestyle() == "--"
        assert lines["nurbs_fe, order 1"].get_linestyle() == "-"
        # the body-fitted reference: its last step's pulled reaction, 600 N, 123456 DOFs
        target = [line for label, line in lines.items() if label.startswith("body-fitted reference")]
        assert len(target) == 1 and "123456 DOFs" in target[0].get_label()
        np.testing.assert_allclose(target[0].get_ydata(), REF_F[-1])
        assert ax.get_xscale() == "log"
    assert len(_lines_of(dofs)) == 5


def test_without_a_reference_the_finest_order_2_run_is_the_target(tmp_path):
    paths = _chain2(tmp_path)
    runs = load_runs(paths)
    target = best_target("chain2_steel", runs, {}, PULLED, 1)
    assert target.value == 480.0 and "finest order 2 (nurbs_fe L0" in target.label   # nurbs_fe before facets
    # a finer order-2 run wins whatever its definition
    paths.append(summary(tmp_path, "chain2_steel", 1, "facets", 2, 455.0, dofs=32000))
    target = best_target("chain2_steel", load_runs(paths), {}, PULLED, 1)
    assert target.value == 455.0 and "facets L1" in target.label
    fig = figure("accuracy", [str(p) for p in paths], pulled=PULLED)
    lines = _lines_of(fig.axes[0])
    drawn = [line for label, line in lines.items() if label.startswith("finest order 2")]
    assert len(drawn) == 1
    np.testing.assert_allclose(drawn[0].get_ydata(), 455.0)
    np.testing.assert_allclose(lines["facets, order 2"].get_xdata(), [4000, 32000])
    # the reference of another example does not stand in
    other = load_references([reference_json(tmp_path / "chain3.json", case="chain3")])
    assert best_target("chain2_steel", load_runs(paths), other, PULLED, 1).value == 455.0
    # neither a reference nor an order-2 run: no target, the title says so
    only_1 = [p for p in paths if "_o2" not in str(p)]
    assert best_target("chain2_steel", load_runs(only_1), {}, PULLED, 1) is None
    fig = figure("accuracy", [str(p) for p in only_1], pulled=PULLED)
    assert "no reference" in fig.axes[0].get_title()


def test_rows_follow_the_chains_and_stopped_runs_are_named_not_drawn(tmp_path):
    paths = _chain2(tmp_path / "a")
    paths += [summary(tmp_path / "b", "chain3", 0, "nurbs_fe", 2, 12000.0, dofs=16000),
              summary(tmp_path / "b", "chain3", 0, "facets", 2, 1.0, status="failed")]
    runs = load_runs(paths)
    failed = next(r for r in runs if r.failed)
    assert np.isnan(final_reaction(failed, PULLED, 1)) and failed.label == "facets L0 o2"
    assert wall_seconds(failed) == 3.0
    lines = accuracy_lines(runs, PULLED, 1)
    assert [(ln.case, ln.surface, ln.order) for ln in lines] == [
        ("chain2_steel", "facets", 1), ("chain2_steel", "nurbs_fe", 1), ("chain2_steel", "facets", 2),
        ("chain2_steel", "nurbs_fe", 2), ("chain3", "nurbs_fe", 2)]
    fig = figure("accuracy", [str(p) for p in paths], pulled=PULLED)
    assert len(fig.axes) == 4                              # chain2_steel and chain3: two rows
    chain3 = fig.axes[2]
    assert chain3.get_title().startswith("chain3") and "facets L0 o2 (failed)" in chain3.get_title()
    assert set(_lines_of(chain3)) == {"nurbs_fe, order 2",
                                      "finest order 2 (nurbs_fe L0; no body-fitted reference): 12000 N"}


# ---------------------------------------------------------------- claims at order 2


def _order2_runs(root: Path, facets_force: float = 450.0, facets_vm: float = 2e8):
    chain2 = [summary(root, "chain2_steel", 0, s, 2, f, dofs=4000)
              for s, f in (("facets", facets_force), ("nurbs_fe", 480.0), ("nurbs_fit", 481.0))]
    chain3 = [summary(root, "chain3", 0, s, 2, 1e4, von_mises=v, contact=1e4)
              for s, v in (("facets", facets_vm), ("nurbs_fe", 3e8))]
    return chain2, chain3


@pytest.mark.parametrize("facets_force, facets_vm, verdict", [
    (450.0, 2e8, "yes"), (490.0, 2e8, "no"), (450.0, 4e8, "no")])
def test_order_2_line_decides_claims_3_and_4_on_the_order_2_runs(tmp_path, facets_force, facets_vm, verdict):
    chain2, chain3 = _order2_runs(tmp_path, facets_force, facets_vm)
    claim = claim_order2(load_runs(chain2), load_runs(chain3), reaction_level=0, pulled=PULLED,
                         component=1, von_mises_levels=[0], body="link_c")
    assert claim.verdict == verdict and claim.decided
    assert f"claim 3: |F| at load factor 1: facets {facets_force:g} N, nurbs_fe 480 N, nurbs_fit 481 N" in claim.numbers
    assert f"claim 4: L0: facets {facets_vm / 1e6:g} MPa, nurbs_fe 300 MPa" in claim.numbers


def test_order_2_line_is_not_decided_without_its_runs(tmp_path):
    chain2, _ = _order2_runs(tmp_path)
    # no order-2 chain3 run: claim 3 holds, claim 4 cannot be decided
    claim = claim_order2(load_runs(chain2), [], reaction_level=0, pulled=PULLED, component=1,
                         von_mises_levels=[0], body="link_c")
    assert claim.verdict == "not decided" and "claim 4 (not decided): L0: not decided" in claim.numbers
    # a decided failure is a "no" even if the other is not decided
    low = claim_order2(load_runs(_order2_runs(tmp_path / "b", facets_force=500.0)[0]), [],
                       reaction_level=0, pulled=PULLED, component=1, von_mises_levels=[0], body="link_c")
    assert low.verdict == "no"
    # order-1 runs do not count: only the order-2 ones decide
    order1 = [summary(tmp_path / "c", "chain2_steel", 0, s, 1, f) for s, f in (("facets", 1.0), ("nurbs_fe", 2.0),
                                                                              ("nurbs_fit", 2.0))]
    none = claim_order2(load_runs(order1), [], reaction_level=0, pulled=PULLED, component=1,
                        von_mises_levels=[0], body="link_c")
    assert none.verdict == "not decided" and not none.reproduced
    row = next(line for line in claims_markdown([none]).splitlines() if line.startswith("| 3, 4 (order 2) |"))
    assert row.split("|")[3].strip() == "not decided"


def test_claims_table_gains_the_order_2_line_and_keeps_the_four(tmp_path):
    """The four claims see the order-1 runs alone (order-2 ones among their summaries are left
    out); the fifth line sees the order-2 runs, with their distance to the references."""
    from cgfem.report.energy import write_error_table
    from tests.unit.test_report import _error_rows

    table = tmp_path / "errors.csv"
    write_error_table(_error_rows({"facets": 1.0, "nurbs_fe": 1.0, "nurbs_fit": 1.0}), table)
    chain2_o1 = [summary(tmp_path, "chain2_steel", 2, s, 1, f) for s, f in (("facets", 400.0), ("nurbs_fe", 500.0),
                                                                           ("nurbs_fit", 500.0))]
    chain2_o2, chain3_o2 = _order2_runs(tmp_path / "o2", facets_force=600.0)   # not lower at order 2
    ref = reference_json(tmp_path / "chain2_steel.json", case="chain2_steel")
    found = claims([table], chain2_o1 + chain2_o2, [], rate_tolerance=0.1, reaction_level=2, pulled=PULLED,
                   component=1, von_mises_levels=[1], von_mises_body="link_c", references=[ref],
                   order2={"reaction_level": 0, "von_mises_levels": [0]},
                   order2_summaries=chain2_o2 + chain3_o2)
    assert [c.row or c.number for c in found] == [1, 2, 3, 4, "3, 4 (order 2)"]
    assert found[2].reproduced and found[2].numbers.startswith("|F| at load factor 1: facets 400 N")
    assert found[4].verdict == "no" and "facets 600 N" in found[4].numbers
    # distance of the order-2 runs to the chain2_steel reference (600 N): facets L0 o2 at 0 %
    assert "claim 3: pulled reaction vs reference" in found[4].distance
    assert "facets L0 o2 +0.00%" in found[4].distance and "nurbs_fe L0 o2 -20.00%" in found[4].distance
    assert "claim 4: no runs" in found[4].distance or "claim 4: no reference" in found[4].distance
    assert Run.load(chain2_o2[0]).order == 2 and Run.load(chain2_o1[0]).order == 1


def test_bad_input_is_a_one_line_error(tmp_path):
    paths = [str(p) for p in _chain2(tmp_path)]
    with pytest.raises(ValueError, match=r"no reaction entry 'link_b/cap_a' \(it has link_a/cap_a\+cap_b, "):
        figure("accuracy", paths, pulled="link_b/cap_a")
    with pytest.raises(ValueError, match="component: must be one of x, y, z"):
        figure("accuracy", paths, pulled=PULLED, component="w")


def test_figures_are_written_whole(tmp_path):
    from cgfem.report.style import save_figure

    fig = figure("accuracy", [str(p) for p in _chain2(tmp_path)], pulled=PULLED)
    save_figure(fig, tmp_path / "a.png", tmp_path / "a.pdf")
    assert (tmp_path / "a.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "a.pdf").read_bytes()[:5] == b"%PDF-"
    assert not list(tmp_path.glob(".*.tmp"))               # no temporary left behind
