"""Where a finished pipeline run's time went, and what it would take on another machine.

Reads a run's snakemake log (``.snakemake/log/``, the newest unless ``--log``: its elapsed
wall time and each job's start and finish) and the run jobs' benchmark files
(``results/benchmarks/runs/``: each ``cgfem run``'s wall time), and prints: the wall time;
the job time (the runs by group: the order-2 runs, the order-1 runs at levels 2 and above,
the rest; the other jobs); how busy the cores were (job time over cores x wall time); the
longest jobs. With ``--probe`` it also times a fixed run alone on one thread on this machine
(chain2_steel at level 1 with ``nurbs_fe``, warm numba cache, best of two), the machine's
speed for the work the pipeline does, and prints the job time in probe units, the largest
job time a wall time of ``--target`` minutes allows at the same use of the cores, and the
probe time at which this work would take that wall time. Run jobs scale with the probe across
machines of a kind (docs/performance.md, "Full pipeline runs"), so the probe units compare
runs made on different machines.

With ``--record-runs FILE`` it also writes each run's seconds (JSON, by run folder), the
table the workflow orders its runs by (``config/run_seconds.json``: the longest first).

    python3 -m benchmarks.bench_pipeline [--root DIR] [--log FILE] [--cores 2] [--probe]
        [--target 15] [--json out.json] [--record-runs config/run_seconds.json]
"""

from __future__ import annotations

import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from cgfem.results import write_json_atomic
from cgfem.run import THREAD_COUNTS

REPO = Path(__file__).resolve().parents[1]
#: the probe: one run alone on one thread
PROBE = ["config/cases/chain2_steel.yaml", "--level", "1", "--surface", "nurbs_fe"]

_STAMP = re.compile(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]$")
_RULE = re.compile(r"^(?:local)?rule (\w+):$")
_JOBID = re.compile(r"^\s+jobid: (\d+)$")
_WILDCARDS = re.compile(r"^\s+wildcards: (.*)$")
_FINISHED = re.compile(r"^Finished jobid: (\d+)")
_ELAPSED = re.compile(r"^Elapsed time: (?:(\d+) days?, )?(\d+):(\d\d):(\d\d(?:\.\d+)?)$")


@dataclass
class Job:
    """One job of the log: its rule, wildcards (as logged), start and finish (s from the
    first job's start; finish None if the log has no finish for it)."""
    jobid: int
    rule: str
    wildcards: str
    start: float
    finish: float | None = None

    @property
    def seconds(self) -> float | None:
        return None if self.finish is None else self.finish - self.start


def parse_log(text: str) -> tuple[float | None, list[Job]]:
    """The elapsed wall time (s; None if the log does not end with it) and the jobs of a
    snakemake log, in the order they started (times at the log's one-second resolution)."""
    stamp: datetime | None = None
    t0: datetime | None = None
    rule: str | None = None
    jobs: dict[int, Job] = {}
    last: Job | None = None
    elapsed = None
    for line in text.splitlines():
        if m := _STAMP.match(line):
            stamp = datetime.strptime(m.group(1), "%a %b %d %H:%M:%S %Y")
            t0 = t0 or stamp
        elif m := _RULE.match(line):
            rule = m.group(1)
        elif (m := _JOBID.match(line)) and rule is not None and stamp is not None:
            last = jobs[int(m.group(1))] = Job(int(m.group(1)), rule, "", (stamp - t0).total_seconds())
            rule = None
        elif (m := _WILDCARDS.match(line)) and last is not None and not last.wildcards:
            last.wildcards = m.group(1)
        elif (m := _FINISHED.match(line)) and stamp is not None and int(m.group(1)) in jobs:
            jobs[int(m.group(1))].finish = (stamp - t0).total_seconds()
        elif m := _ELAPSED.match(line):
            days, hours, minutes, seconds = m.groups()
            elapsed = ((int(days or 0) * 24 + int(hours)) * 60 + int(minutes)) * 60 + float(seconds)
    return elapsed, sorted(jobs.values(), key=lambda j: (j.start, j.jobid))


def run_times(folder: Path) -> dict[str, float]:
    """Each run job's wall time (s) from its snakemake benchmark file under ``folder``
    (``{case}/L{level}_{surface}[_o{order}].tsv``), by ``{case}/L{level}_{surface}[_o{order}]``."""
    out = {}
    for path in sorted(folder.glob("*/*.tsv")):
        with path.open() as f:
            rows = list(csv.DictReader(f, delimiter="\t"))
        if rows:
            out[f"{path.parent.name}/{path.stem}"] = float(rows[-1]["s"])
    return out


def group(name: str) -> str:
    """The group of a run's name: ``order 2`` (any ``_o{order}``), ``levels 2+`` (order 1 at
    a level of 2 or more) or ``rest``."""
    if re.search(r"_o\d+$", name):
        return "order 2"
    level = int(re.search(r"/L(\d+)_", name).group(1))
    return "levels 2+" if level >= 2 else "rest"


def probe(repeats: int = 2) -> float:
    """The probe's wall time (s), best of ``repeats`` runs, each ``cgfem run`` in a process of
    its own on one thread (numba, OpenMP, MKL, as the pipeline's jobs). ``RuntimeError`` with
    the run's last line of stderr if it fails."""
    env = dict(os.environ, **dict.fromkeys(THREAD_COUNTS, "1"))
    best = float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeats):
            tic = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "cgfem", "run", *PROBE, "--out", str(Path(tmp) / "probe"),
                                   "--quiet"], cwd=REPO, env=env, capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(f"the probe run failed ({proc.returncode}): "
                                   f"{(proc.stderr.strip().splitlines() or [''])[-1]}")
            best = min(best, time.perf_counter() - tic)
    return best


def report(root: Path, log: Path, cores: int) -> dict:
    """The figures of the run in ``root`` whose snakemake log is ``log`` (module docstring);
    ``ValueError`` if the log has no elapsed time or there are no run benchmark files."""
    elapsed, jobs = parse_log(log.read_text())
    runs = run_times(root / "results" / "benchmarks" / "runs")
    if elapsed is None:
        raise ValueError(f"{log}: no elapsed time (the run did not finish)")
    if not runs:
        raise ValueError(f"{root / 'results/benchmarks/runs'}: no run benchmark files")
    groups: dict[str, float] = {}
    for name, seconds in runs.items():
        key = group(name)
        groups[key] = groups.get(key, 0.0) + seconds
    others = sum(j.seconds or 0.0 for j in jobs if not j.rule.startswith("run_case"))
    total = sum(runs.values()) + others
    return {"log": str(log), "wall_s": elapsed, "jobs": len(jobs), "runs": len(runs),
            "run_s": sum(runs.values()), "groups_s": groups, "other_jobs_s": others, "job_s": total,
            "cores": cores, "busy": total / (cores * elapsed),
            "longest": sorted(runs.items(), key=lambda kv: -kv[1])[:6]}


def projection(out: dict, probe_s: float, target_min: float) -> dict:
    """The figures of :func:`report` ``out`` against a probe of ``probe_s`` (s): the job time
    in probes, the job time a wall time of ``target_min`` allows at the same use of the cores
    (s and probes), and the probe time at which this work takes that wall time."""
    allowed = target_min * 60.0 * out["cores"] * out["busy"]
    return {"probe_s": probe_s, "job_probes": out["job_s"] / probe_s, "target_min": target_min,
            "allowed_job_s": allowed, "allowed_job_probes": allowed / probe_s,
            "probe_at_target_s": probe_s * allowed / out["job_s"]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", type=Path, default=REPO, help="the pipeline's folder (results/, .snakemake/)")
    parser.add_argument("--log", type=Path, help="the snakemake log (default: the newest under .snakemake/log)")
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--probe", action="store_true", help="time the probe run on this machine")
    parser.add_argument("--target", type=float, default=15.0, help="the wall time to project to (min)")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--record-runs", type=Path, metavar="FILE",
                        help="write each run's seconds (JSON), the workflow's run order")
    args = parser.parse_args(argv)
    log = args.log or max((args.root / ".snakemake" / "log").glob("*.snakemake.log"), default=None)
    try:
        if log is None:
            raise ValueError(f"{args.root}: no snakemake log under .snakemake/log")
        out = report(args.root, log, args.cores)       # checked before the probe's minute
        if args.probe:
            out.update(projection(out, probe(), args.target))
    except (ValueError, RuntimeError, OSError) as err:
        print(f"bench_pipeline: {err}", file=sys.stderr)
        return 2
    print(f"{out['log']}: wall {out['wall_s'] / 60:.2f} min, {out['jobs']} jobs ({out['runs']} runs)")
    groups = ", ".join(f"{k} {v:.0f} s" for k, v in sorted(out["groups_s"].items()))
    print(f"job time {out['job_s']:.0f} s = {out['job_s'] / 60:.1f} job-min: runs {out['run_s']:.0f} s ({groups}), "
          f"other jobs {out['other_jobs_s']:.0f} s; cores busy {100 * out['busy']:.0f} % of {out['cores']}")
    print("longest: " + ", ".join(f"{name} {s:.0f} s" for name, s in out["longest"]))
    if "probe_s" in out:
        print(f"probe (chain2_steel L1 nurbs_fe alone, one thread): {out['probe_s']:.2f} s; "
              f"job time {out['job_probes']:.0f} probes")
        print(f"{out['target_min']:g} min of wall time at {100 * out['busy']:.0f} % busy allows "
              f"{out['allowed_job_s']:.0f} s of jobs = {out['allowed_job_probes']:.0f} probes here: "
              f"this work fits where the probe takes at most {out['probe_at_target_s']:.2f} s")
    if args.json:
        write_json_atomic(args.json, out)
    if args.record_runs:
        times = run_times(args.root / "results" / "benchmarks" / "runs")
        write_json_atomic(args.record_runs, {name: round(s, 1) for name, s in sorted(times.items())})
    return 0


if __name__ == "__main__":
    sys.exit(main())
