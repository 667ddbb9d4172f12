"""The ``cgfem check`` and ``cgfem run`` commands: exact numbers on good cases, exit code 2
with a one-line message naming the field on bad ones, and a refused run leaves no folder."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cgfem.cli import main
from cgfem.errors import InputError
from cgfem.geometry.builders import build_solid
from cgfem.geometry.io import solid_to_dict, write_solid
from cgfem.geometry.specs import BoxSpec
from tests.support.paths import CASES


GOOD = """\
name: t
kinematics: small
bodies:
  ring:
    geometry: {builder: torus, center: [0, 0, 0], axis: [0, 0, 1], major_radius: 0.02, minor_radius: 0.005}
    material: {model: linear_elastic, E: 1.0e9, nu: 0.3}
    grid: {h0: 0.005}
  block:
    geometry: {builder: box, min: [0, 0, 0.1], max: [1, 2, 3.1]}
    material: {model: linear_elastic, E: 1.0e9, nu: 0.3}
    grid: {h0: 0.5}
boundary:
  - {body: block, patches: [zmin], type: displacement, components: {z: 0.0}}
  - {body: block, patches: [zmax], type: traction, value: ["0", "0", "-1e6*x"]}
"""


def _write(tmp_path: Path, text: str) -> str:
    path = tmp_path / "case.yaml"
    path.write_text(text)
    return str(path)


def test_check_json_reports_exact_brep_measures(tmp_path, capsys):
    assert main(["check", _write(tmp_path, GOOD), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)["bodies"]
    R, r = 0.02, 0.005
    assert out["ring"]["brep_volume"] == pytest.approx(2 * math.pi**2 * R * r * r, rel=1e-12)
    assert out["ring"]["brep_area"] == pytest.approx(4 * math.pi**2 * R * r, rel=1e-12)
    assert out["block"]["brep_volume"] == pytest.approx(6.0, rel=1e-14)
    assert out["block"]["patches"]["zmin"]["area"] == pytest.approx(2.0, rel=1e-14)
    assert out["block"]["patches"]["xmax"]["area"] == pytest.approx(6.0, rel=1e-14)


def test_check_table_lists_every_patch(tmp_path, capsys):
    assert main(["check", _write(tmp_path, GOOD)]) == 0
    out = capsys.readouterr().out
    for name in ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax", "surface"):
        assert f"patch {name}" in out


@pytest.mark.parametrize("case", sorted(p.name for p in CASES.glob("*.yaml")))
def test_paper_cases_check(case, capsys):
    assert main(["check", str(CASES / case), "--json"]) == 0
    bodies = json.loads(capsys.readouterr().out)["bodies"]
    for body in bodies.values():
        assert body["brep_volume"] > 0.0


def test_nurbs_file_body(tmp_path, capsys):
    write_solid(build_solid(BoxSpec((0, 0, 0), (1, 1, 2))), tmp_path / "box.json")
    text = GOOD.replace("{builder: torus, center: [0, 0, 0], axis: [0, 0, 1], major_radius: 0.02, "
                        "minor_radius: 0.005}", "{builder: nurbs, file: box.json}")
    assert main(["check", _write(tmp_path, text), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["bodies"]["ring"]["brep_volume"] == pytest.approx(2.0)


def _open_box(tmp_path: Path) -> None:
    data = solid_to_dict(build_solid(BoxSpec((0, 0, 0), (1, 1, 1))))
    data["patches"].pop()
    (tmp_path / "open.json").write_text(json.dumps(data))


TORUS = ("{builder: torus, center: [0, 0, 0], axis: [0, 0, 1], major_radius: 0.02, "
         "minor_radius: 0.005}")
BAD = {
    "yaml_syntax": (lambda s: s.replace("kinematics: small", "kinematics: [small"), "case.yaml"),
    "unknown_top_key": (lambda s: s + "colour: red\n", "colour"),
    "unknown_nested_key": (lambda s: s.replace("grid: {h0: 0.5}", "grid: {h0: 0.5, size: 3}"),
                           "bodies.block.grid.size"),
    "wrong_type": (lambda s: s.replace("E: 1.0e9, nu: 0.3}\n    grid: {h0: 0.5}",
                                       "E: stiff, nu: 0.3}\n    grid: {h0: 0.5}"),
                   "bodies.block.material.E"),
    "r_ge_R": (lambda s: s.replace("minor_radius: 0.005", "minor_radius: 0.02"),
               "bodies.ring.geometry.minor_radius"),
    "zero_box": (lambda s: s.replace("max: [1, 2, 3.1]", "max: [1, 0, 3.1]"), "bodies.block.geometry.max"),
    "zero_axis": (lambda s: s.replace("axis: [0, 0, 1]", "axis: [0, 0, 0]"), "bodies.ring.geometry.axis"),
    "non_unit_axis": (lambda s: s.replace("axis: [0, 0, 1]", "axis: [0, 0, 2]"), "bodies.ring.geometry.axis"),
    "unknown_patch": (lambda s: s.replace("patches: [zmin]", "patches: [bottom]"), "boundary[0].patches[0]"),
    "unknown_body": (lambda s: s.replace("{body: block, patches: [zmin]", "{body: brick, patches: [zmin]"),
                     "boundary[0].body"),
    "import": (lambda s: s.replace('"-1e6*x"', '"__import__(\'os\')"'), "boundary[1].value[2]"),
    "attribute": (lambda s: s.replace('"-1e6*x"', '"x.real"'), "boundary[1].value[2]"),
    "unlisted_call": (lambda s: s.replace('"-1e6*x"', '"log(x)"'), "boundary[1].value[2]"),
    "huge_exponent": (lambda s: s.replace('"-1e6*x"', '"10**10**10"'), "boundary[1].value[2]"),
    "nu_half": (lambda s: s.replace("E: 1.0e9, nu: 0.3}\n    grid: {h0: 0.5}",
                                    "E: 1.0e9, nu: 0.5}\n    grid: {h0: 0.5}"), "bodies.block.material.nu"),
    "negative_h0": (lambda s: s.replace("grid: {h0: 0.5}", "grid: {h0: -0.5}"), "bodies.block.grid.h0"),
    "missing_nurbs_file": (lambda s: s.replace(TORUS, "{builder: nurbs, file: nowhere.json}"),
                           "bodies.ring.geometry.file"),
    "open_nurbs": (lambda s: s.replace(TORUS, "{builder: nurbs, file: open.json}"),
                   "bodies.ring.geometry.patches[0]"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_input_exits_2_with_one_line(name, tmp_path, capsys):
    edit, field = BAD[name]
    _open_box(tmp_path)
    path = _write(tmp_path, edit(GOOD))
    assert main(["check", path]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("cgfem: error: ")
    assert field in lines[0], lines[0]


def test_missing_case_file(tmp_path, capsys):
    assert main(["check", str(tmp_path / "nope.yaml")]) == 2
    assert "nope.yaml" in capsys.readouterr().err


def test_console_script_exit_code_and_no_traceback(tmp_path):
    path = _write(tmp_path, GOOD.replace("minor_radius: 0.005", "minor_radius: 0.03"))
    proc = subprocess.run([sys.executable, "-m", "cgfem", "check", path], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip() == ("cgfem: error: bodies.ring.geometry.minor_radius: must be smaller "
                                   "than major_radius (0.03 >= 0.02)")


def test_console_script_output_through_a_pipe_is_complete(tmp_path, capsys):
    """The console script ends the process without the interpreter's teardown: what a
    command printed into a pipe (block-buffered, so still in the buffer at the end) arrives
    whole, with the exit code, as from :func:`main` in this process."""
    path = _write(tmp_path, GOOD)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    proc = subprocess.run([sys.executable, "-m", "cgfem", "check", path, "--json"], capture_output=True,
                          text=True, env=env)
    assert proc.returncode == 0, proc.stderr
    assert main(["check", path, "--json"]) == 0
    assert json.loads(proc.stdout) == json.loads(capsys.readouterr().out)


def test_check_level_reports_grid_quadrature(tmp_path, capsys):
    """The JSON contract of ``cgfem check --json``: volume, area, brep_*, elements, nodes per
    body."""
    assert main(["check", _write(tmp_path, GOOD), "--level", "0", "--json",
                 "--vtu", str(tmp_path / "vtu")]) == 0
    bodies = json.loads(capsys.readouterr().out)["bodies"]
    for body in bodies.values():
        assert set(body) >= {"volume", "area", "brep_volume", "brep_area", "elements", "nodes"}
        assert body["volume"] == pytest.approx(body["brep_volume"], rel=1e-8)
        assert body["area"] == pytest.approx(body["brep_area"], rel=1e-8)
        assert body["elements"]["cut"] > 0
    assert len(list((tmp_path / "vtu").glob("*.vtu"))) == 6


def test_check_level_needs_nonnegative(tmp_path, capsys):
    assert main(["check", _write(tmp_path, GOOD), "--level", "-1"]) == 2
    assert "--level" in capsys.readouterr().err


def test_check_surface_needs_level(tmp_path, capsys):
    assert main(["check", _write(tmp_path, GOOD), "--surface", "facets"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--surface" in err[0] and "--level" in err[0]


def _one_error_line(capsys, field: str) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cgfem: error: ") and field in lines[0], captured.err
    return lines[0]


@pytest.mark.parametrize("under", [False, True])
def test_run_out_on_a_file_is_bad_input(tmp_path, capsys, under):
    existing = tmp_path / "results"
    existing.write_text("not a folder")
    out = existing / "run1" if under else existing
    code = main(["run", _write(tmp_path, GOOD), "--level", "0", "--surface", "nurbs_fe", "--out", str(out)])
    assert code == 2
    assert "a file, not a folder" in _one_error_line(capsys, "--out")
    assert existing.read_text() == "not a folder"


@pytest.mark.parametrize("order, message", [(3, "must be one of 1, 2, got 3"), (0, "must be one of 1, 2, got 0")])
def test_unknown_element_order_is_bad_input(tmp_path, capsys, order, message):
    out = tmp_path / "o"
    code = main(["run", _write(tmp_path, GOOD), "--level", "0", "--surface", "nurbs_fe", "--out", str(out),
                 "--order", str(order)])
    assert code == 2
    assert message in _one_error_line(capsys, "--order")
    assert not out.exists()


def test_refused_run_leaves_no_folder(tmp_path, capsys):
    """Refused by the memory estimate: neither the folder nor its missing parents appear."""
    out = tmp_path / "a" / "b"
    code = main(["run", _write(tmp_path, GOOD), "--level", "40", "--surface", "nurbs_fe", "--out", str(out)])
    assert code == 2
    _one_error_line(capsys, "--level")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.yaml"]


@pytest.mark.slow
def test_bad_input_after_the_folder_was_made_removes_it(tmp_path, capsys, monkeypatch):
    """Bad input found once the run started (here raised by the solver) removes the folders
    the run created, and only those: a folder that held a file before is kept."""
    import cgfem.run

    def refuse(*args, **kwargs):
        assert (tmp_path / "a" / "b").is_dir()      # the run had created its folder
        raise InputError("solver.linear", "refused for the test")

    monkeypatch.setattr(cgfem.run, "solve_static", refuse)
    block_only = GOOD.replace("  ring:\n    geometry: " + TORUS + "\n", "").replace(
        "    material: {model: linear_elastic, E: 1.0e9, nu: 0.3}\n    grid: {h0: 0.005}\n", "", 1)
    case = _write(tmp_path, block_only)
    code = main(["run", case, "--level", "0", "--surface", "nurbs_fe", "--out", str(tmp_path / "a" / "b"),
                 "--quiet"])
    assert code == 2
    _one_error_line(capsys, "solver.linear")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.yaml"]
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / "notes.txt").write_text("mine")
    monkeypatch.setattr(cgfem.run, "solve_static", lambda *a, **k: refuse_kept(kept))
    assert main(["run", case, "--level", "0", "--surface", "nurbs_fe", "--out", str(kept / "run"),
                 "--quiet"]) == 2
    assert sorted(p.name for p in kept.iterdir()) == ["notes.txt"]


def refuse_kept(folder):
    assert (folder / "run").is_dir()
    raise InputError("solver.linear", "refused for the test")
