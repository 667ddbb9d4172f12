"""The gold files of the chains' body-fitted references (``config/reference/*.json``): each
was made by the current reference code for the current case file, holds what the issue asks
of a reference (three meshes or more, order, penalties, times, per-step values), and the
pipeline's ``--from-gold`` copy refuses a stale one with the command that regenerates it.

Nothing here solves a problem: the gold files are read, not recomputed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cgfem.reference.tori import ACCEPT, code_of, main, script_version
from tests.support.paths import CASES, REPO

GOLD = REPO / "config" / "reference"
CHAINS = ("chain2_steel", "chain2_rubber", "chain3")


def gold_files() -> list[Path]:
    return [GOLD / f"{name}.json" for name in CHAINS if (GOLD / f"{name}.json").is_file()]


def test_every_chain_has_a_gold_file():
    assert [p.stem for p in gold_files()] == list(CHAINS)


@pytest.mark.parametrize("gold", gold_files(), ids=lambda p: p.stem)
def test_gold_file_is_current_and_complete(gold, tmp_path):
    data = json.loads(gold.read_text())
    case = CASES / f"{gold.stem}.yaml"
    # the copy the pipeline makes succeeds: current script version and case file
    out = tmp_path / "copy.json"
    assert main(["--case", str(case), "--from-gold", str(gold), "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == data
    assert data["command"].startswith("python3 -m cgfem.reference.tori ")
    assert f"--out config/reference/{gold.stem}.json" in data["command"]
    # three meshes or more, each run converged through every load step of the case
    steps = data["reference"]["steps"]
    levels = [run["level"] for run in data["runs"]]
    assert len(levels) >= 3 and levels == sorted(levels)
    for run in data["runs"] + [data["penalty_run"]]:
        assert run["converged"] and len(run["steps"]) == len(steps)
        assert run["mesh"]["dofs"] > 0 and sum(run["seconds"].values()) > 0.0
    assert data["penalty_run"]["mesh"] == data["runs"][-1]["mesh"]
    assert data["reference"]["order"] >= 2
    assert data["penalty_run"]["penalty_factor"] == 10.0 * data["reference"]["penalty_factor"]
    # per step: the pulled and clamped reactions balance, and each equals its contact force
    pulled, clamped = data["supports"]["pulled"], data["supports"]["clamped"]
    for step in steps:
        f_pulled, f_clamped = step["reactions"][pulled][1], step["reactions"][clamped][1]
        assert f_pulled > 0.0 > f_clamped
        assert abs(f_pulled + f_clamped) <= 1e-6 * f_pulled
        for pair in step["contact"].values():
            assert abs(abs(pair["force"][1]) - f_pulled) <= 1e-6 * f_pulled
    # the verdict its own numbers give, accepted: mesh and penalty changes below 0.3 %
    u = data["uncertainty"]
    assert u["accepted"] == (u["mesh"] < ACCEPT and u["penalty"] < ACCEPT)
    assert u["accepted"] and u["mesh"] < ACCEPT and u["penalty"] < ACCEPT
    rows = u["meshes"]
    assert u["mesh"] >= rows[-2]["change_to_finest"] == u["mesh_change"]
    # the mesh is refined to h_contact over the whole contact zone of every step of the finest
    # run: the zone's extent, from the tube vertices carrying contact (one element beyond the
    # zone), is within r_contact plus one contact element
    finest = data["runs"][-1]
    extents = [v for step in finest["steps"] for v in step["contact_extent"].values()]
    assert 0.0 < max(extents) == u["contact_extent"]
    assert u["contact_extent"] <= u["r_contact"] + finest["mesh"]["h_contact"]
    assert u["r_contact"] == finest["mesh"]["r_contact"]
    assert [row["r_contact"] for row in rows] == [u["r_contact"]] * len(rows)


def test_a_stale_gold_file_is_refused_with_its_command(tmp_path, capsys):
    gold = json.loads((GOLD / "chain3.json").read_text())
    stale = tmp_path / "stale.json"
    stale.write_text(json.dumps({**gold, "script_version": "0" * 16}))
    out = tmp_path / "out.json"
    assert main(["--case", str(CASES / "chain3.yaml"), "--from-gold", str(stale), "--out", str(out)]) == 1
    message = capsys.readouterr().err
    assert "script version 0000000000000000" in message and gold["command"] in message
    assert not out.exists()
    # the same gold file against another case's content
    assert main(["--case", str(CASES / "chain2_steel.yaml"), "--from-gold", str(GOLD / "chain3.json"),
                 "--out", str(out)]) == 1
    assert "made for another content" in capsys.readouterr().err


def test_script_version_ignores_documentation_only():
    code = 'def f(x):\n    """Doc."""\n    # note\n    return x + 1  # trailing\n'
    assert code_of(code) == "def f(x):\n    return x + 1\n"
    assert code_of(code.replace("Doc.", "Other doc.").replace("# note", "# other")) == code_of(code)
    assert code_of(code.replace("x + 1", "x + 2")) != code_of(code)
    assert len(script_version()) == 16
