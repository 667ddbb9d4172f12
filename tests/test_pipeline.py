"""The Snakemake pipeline: the smoke and the full configuration plan the expected jobs, and
`snakemake --lint` finds nothing. Run in a copy of the workflow files, so results already in
the working tree do not change the plan."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytest.importorskip("snakemake")

REPO = Path(__file__).resolve().parents[1]
FIGURES = ["fig09", "fig10", "fig13", "fig14", "fig15", "fig17", "newton", "timings", "geometry"]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("pipeline")
    shutil.copy(REPO / "Snakefile", root)
    shutil.copytree(REPO / "workflow", root / "workflow")
    shutil.copytree(REPO / "config", root / "config")
    return root


def snakemake(root: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "snakemake", *args], cwd=root,
                          capture_output=True, text=True, timeout=300)


def planned_jobs(root: Path, *args: str) -> dict[str, int]:
    done = snakemake(root, "-n", "--quiet", "rules", *args)
    assert done.returncode == 0, done.stderr + done.stdout
    text = done.stdout + done.stderr
    table = text[text.index("Job stats"):]
    return {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)$", table, re.M) if m[1] != "total"}


def expected_runs(config: dict) -> int:
    return sum(len(e["levels"]) for e in config["examples"].values()) * len(config["surfaces"])


def test_smoke_plan_has_every_rule_once_per_job(workdir):
    config = yaml.safe_load((REPO / "config" / "smoke.yaml").read_text())
    jobs = planned_jobs(workdir, "--configfile", "config/smoke.yaml")
    n_planar = len(config["examples"]["planar"]["levels"]) * len(config["surfaces"])
    assert jobs == {"all": 1, "check_case": 4, "run_case": expected_runs(config), "planar_reference": 1,
                    "planar_errors": n_planar, "claims": 1, **{f: 1 for f in FIGURES}}
    assert expected_runs(config) == 15


def test_full_plan_runs_every_example_level_and_definition(workdir):
    config = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    jobs = planned_jobs(workdir)
    assert jobs["run_case"] == expected_runs(config) == 45
    assert jobs["planar_errors"] == 12


def test_lint_is_clean(workdir):
    done = snakemake(workdir, "--lint")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Congratulations" in done.stdout + done.stderr


def test_a_bad_config_is_refused(workdir, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("surfaces: [facets, hexagons]\n")
    done = snakemake(workdir, "-n", "--configfile", str(bad))
    assert done.returncode != 0 and "hexagons" in done.stdout + done.stderr
