"""The Snakemake pipeline: the smoke and the full configuration plan the expected jobs, and
`snakemake --lint` finds nothing. Run in a copy of the workflow files, so results already in
the working tree do not change the plan."""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from tests.support.paths import REPO

pytest.importorskip("snakemake")

FIGURES = ["fig09", "fig10", "fig13", "fig14", "fig15", "fig17", "newton", "timings", "geometry",
           "accuracy"]


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


def dry_run(root: Path, *args: str, cores: int = 2) -> str:
    """The output of a dry run of every job (``-n --forceall -p``) on ``cores`` cores with
    ``args`` (targets first: ``--configfile`` takes every word after it). Each distinct dry
    run is made once: the tests below read several of them."""
    return _dry_run(root, cores, args)


@functools.cache
def _dry_run(root: Path, cores: int, args: tuple[str, ...]) -> str:
    done = snakemake(root, "-n", "--forceall", "-p", "--cores", str(cores), *args)
    assert done.returncode == 0, done.stderr + done.stdout
    return done.stdout + done.stderr


def planned_jobs(text: str) -> dict[str, int]:
    """The jobs per rule of a dry run's output (its "Job stats" table)."""
    table = text[text.index("Job stats"):]
    return {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)$", table, re.M) if m[1] != "total"}


def expected_runs(config: dict) -> int:
    return sum(len(e["levels"]) for e in config["examples"].values()) * len(config["surfaces"])


def expected_order2_runs(config: dict, smoke: dict | None = None) -> set[str]:
    """Run folders of the order-2 runs of ``config`` merged with ``smoke`` (snakemake merges
    --configfile key by key)."""
    runs = set()
    for case, entry in config["examples"].items():
        order2 = {**entry.get("orders", {}).get(2, {}),
                  **((smoke or {}).get("examples", {}).get(case, {}).get("orders", {}).get(2, {}))}
        for level in order2.get("levels", []):
            for surface in order2.get("surfaces", (smoke or config)["surfaces"]):
                runs.add(f"results/runs/{case}/L{level}_{surface}_o2")
    return runs


def test_smoke_plan_has_every_rule_once_per_job(workdir):
    config = yaml.safe_load((REPO / "config" / "smoke.yaml").read_text())
    jobs = planned_jobs(dry_run(workdir, "--configfile", "config/smoke.yaml"))
    jobs.pop("compile_kernels")                         # one per core: checked below
    n_planar = len(config["examples"]["planar"]["levels"]) * len(config["surfaces"])
    assert jobs == {"all": 1, "check_case": 4, "run_case": expected_runs(config), "planar_reference": 1,
                    "run_case_order": 1, "planar_errors": n_planar, "claims": 1, **{f: 1 for f in FIGURES}}
    assert expected_runs(config) == 15                  # 5 example levels x 3 definitions
    # one small order-2 run: the full configuration's order-2 levels do not leak into the smoke
    # one through the merge of --configfile
    full = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    assert expected_order2_runs(full, config) == {"results/runs/chain2_steel/L0_nurbs_fe_o2"}


def test_full_plan_runs_every_example_level_and_definition(workdir):
    config = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    jobs = planned_jobs(dry_run(workdir))
    assert jobs["run_case"] == expected_runs(config) == 36     # 12 example levels x 3
    assert jobs["run_case_order"] == len(expected_order2_runs(config)) == 9   # the chains at level 0
    assert jobs["planar_errors"] == 12
    # the chains' references (copied from their gold files) and the figure drawn from them;
    # the smoke plan above has neither
    assert {rule: n for rule, n in jobs.items() if "reference" in rule} == {
        "planar_reference": 1, "reference_chain2_steel": 1, "reference_chain2_rubber": 1,
        "reference_chain3": 1}
    assert jobs["validation"] == 1


@pytest.mark.parametrize("cores", [1, 2, 64])
def test_the_kernels_compile_in_one_share_per_core_first(workdir, cores):
    """rule compile_kernels: a share of the kernels per core (at most the machine's), ahead of
    every other job."""
    shares = min(cores, os.cpu_count() or 1)
    text = dry_run(workdir, "--configfile", "config/smoke.yaml", cores=cores)
    assert planned_jobs(text)["compile_kernels"] == shares
    planned = set(re.findall(r"results/cache/kernels/share_(\d+)_of_(\d+)\.json", text))
    assert planned == {(str(k), str(shares)) for k in range(1, shares + 1)}
    priorities = {float(p) for p in re.findall(r"priority: ([\d.]+)", text)}
    first = re.search(r"rule compile_kernels:.*?priority: ([\d.]+)", text, re.S)
    assert first and float(first[1]) == max(priorities)


def test_runs_start_longest_first(workdir):
    """A run job's priority is its recorded seconds (config/run_seconds.json); a run not
    recorded (the extended configuration's level 3) comes before every recorded one; the
    cases' checks and the planar reference, which runs wait for, before every run."""
    import json
    recorded = json.loads((REPO / "config" / "run_seconds.json").read_text())
    text = dry_run(workdir, "--configfile", "config/extended.yaml")
    jobs = re.findall(r"rule (\w+):\n(?:    .*\n)*?    wildcards: (.*)\n    priority: ([\d.]+)", text)
    runs = {}
    for rule, wildcards, priority in jobs:
        if rule.startswith("run_case"):
            w = dict(item.split("=") for item in wildcards.split(", "))
            name = f"{w['case']}/L{w['level']}_{w['surface']}" + (f"_o{w['order']}" if "order" in w else "")
            runs[name] = float(priority)
    assert len(runs) == 45 + 9                       # the default runs and the extended ones
    for name, priority in runs.items():
        assert priority == (recorded[name] if name in recorded else 1.0 + max(recorded.values())), name
    assert any(name not in recorded for name in runs)
    checks = [float(p) for p in re.findall(r"rule (?:check_case|planar_reference):\n(?:    .*\n)*?    priority: ([\d.]+)", text)]
    assert len(checks) == 5 and min(checks) > max(runs.values())


def planned_runs(root: Path, *args: str, target: str | None = None) -> set[str]:
    """Run folders (results/runs/{case}/L{level}_{surface}) of the jobs a dry run of
    ``target`` (default: all; several separated by spaces) plans; ``args`` last
    (``--configfile`` takes every word after it)."""
    text = dry_run(root, *(target.split() if target else []), *args)
    return set(re.findall(r"results/runs/\w+/L\d+_\w+(?=/summary\.json)", text))


@pytest.mark.parametrize("configfile", [None, "config/smoke.yaml"])
def test_order_2_runs_land_in_their_own_folders(workdir, configfile):
    """The accuracy figure asks for the order-2 runs (``_o2`` folders, run with --order 2)
    beside the order-1 ones; the paper's figures ask for order 1 alone."""
    args = ("--configfile", configfile) if configfile else ()
    config = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    smoke = yaml.safe_load((REPO / configfile).read_text()) if configfile else None
    text = dry_run(workdir, "paper_figures/accuracy.png", *args)
    runs = set(re.findall(r"results/runs/\w+/L\d+_\w+(?=/summary\.json)", text))
    order2 = {r for r in runs if r.endswith("_o2")}
    assert order2 == expected_order2_runs(config, smoke) and order2
    assert all(not r.startswith("results/runs/planar") for r in runs)
    commands = re.findall(r"cgfem run .*", text)
    assert sorted(c.split("--out ")[1].split()[0] for c in commands if "--order 2 --out " in c) == sorted(order2)
    paper = planned_runs(workdir, *args, target="paper_figures/fig13.png paper_figures/fig14.png "
                                                "paper_figures/fig15.png paper_figures/fig17.png")
    assert paper and not any(r.endswith("_o2") for r in paper)


@pytest.mark.parametrize("configfile", [None, "config/smoke.yaml"])
def test_every_definition_is_planned(workdir, configfile):
    """The three surface definitions at every level of every example; fig10 compares facets
    with nurbs_fit as the paper does."""
    args = ("--configfile", configfile) if configfile else ()
    runs = {r for r in planned_runs(workdir, *args) if not r.endswith("_o2")}     # order 1
    assert {re.search(r"/L\d+_(\w+)$", path)[1] for path in runs} == {"facets", "nurbs_fe", "nurbs_fit"}
    config = yaml.safe_load((REPO / (configfile or "config/config.yaml")).read_text())
    assert len(runs) == expected_runs(config)
    level = config["figures"]["fig10"]["level"]
    fig10 = planned_runs(workdir, *args, target="paper_figures/fig10.png")
    assert fig10 == {f"results/runs/planar/L{level}_facets", f"results/runs/planar/L{level}_nurbs_fit"}


def test_fig10_falls_back_to_nurbs_fe(workdir, tmp_path):
    """Without nurbs_fit among the surfaces, fig10 compares facets with nurbs_fe."""
    extra = tmp_path / "two.yaml"
    extra.write_text("surfaces: [facets, nurbs_fe]\n")
    level = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["figures"]["fig10"]["level"]
    fig10 = planned_runs(workdir, "--configfile", str(extra), target="paper_figures/fig10.png")
    assert fig10 == {f"results/runs/planar/L{level}_facets", f"results/runs/planar/L{level}_nurbs_fe"}


def test_lint_is_clean(workdir):
    done = snakemake(workdir, "--lint")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Congratulations" in done.stdout + done.stderr


def test_a_bad_orders_entry_is_refused(workdir, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("examples:\n  chain3: {case: config/cases/chain3.yaml, levels: [0], orders: {3: {levels: [0]}}}\n")
    done = snakemake(workdir, "-n", "--configfile", str(bad))
    assert done.returncode != 0 and "orders" in done.stdout + done.stderr


def test_a_bad_config_is_refused(workdir, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("surfaces: [facets, hexagons]\n")
    done = snakemake(workdir, "-n", "--configfile", str(bad))
    assert done.returncode != 0 and "hexagons" in done.stdout + done.stderr


def test_runs_reserve_their_estimated_memory(workdir):
    """Every run job of the extended configuration reserves ``mem_mb``, the run's own estimate
    (``cgfem.memory.run_memory``) in MB, at most the budget ``--resources mem_mb`` (a job above
    it would never start)."""
    from cgfem.case import load_case
    from cgfem.memory import run_memory
    budget = 12_000
    done = snakemake(workdir, "-n", "--forceall", "--configfile", "config/extended.yaml",
                     "--resources", f"mem_mb={budget}")
    assert done.returncode == 0, done.stderr + done.stdout
    jobs = re.findall(r"rule (run_case\w*):\n(?:    .*\n)*?    wildcards: (.*)\n(?:    priority: .*\n)?    resources: (.*)",
                      done.stdout + done.stderr)
    config = yaml.safe_load((REPO / "config" / "extended.yaml").read_text())
    assert len([j for j in jobs if j[0] == "run_case"]) == expected_runs(config)
    capped = 0
    for _, wildcards, resources in jobs:
        w = dict(item.split("=") for item in wildcards.split(", "))
        case = load_case(REPO / config["examples"][w["case"]]["case"])
        need = run_memory(case, int(w["level"]), w["surface"], int(w.get("order", 1))) // 10**6
        reserved = int(re.search(r"mem_mb=(\d+)", resources)[1])
        assert reserved == min(need, budget), wildcards
        capped += need > budget
    assert capped == 2          # chain3 at level 3, nurbs_fit (15 GB) and planar's
