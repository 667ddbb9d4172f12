"""Robustness and accuracy at any grid offset: every example, level and definition at random
offsets of every body's grid.

For each example x level x definition, ``--count`` seeded random offsets per body (printed,
so any run can be repeated with ``cgfem run``) are solved, each in its own process; per run:
status, steps and cut-backs (sub-steps beyond the case's steps), the fallback a converged
step needed (the policy's ``fallbacks``; printed when one did), Newton iterations, the
final pulled reaction (the first displacement entry whose component ``--component`` is
nonzero, the contact force for planar) and, for planar, the energy-norm error against the
body-fitted reference. Per example and definition: the fraction converged, the spread
(max - min over the mean) of the final reaction across offsets at each level beside its
change from the lowest level to the next, and the planar error per level.

    python3 -m benchmarks.bench_offsets [--examples planar chain2_steel ...] [--levels 0 1]
        [--surfaces facets nurbs_fe nurbs_fit] [--count 10] [--sets K ...] [--seed 2026] [--jobs 2]
        [--reference results/reference/planar.npz] [--policy NAME=VALUE ...] [--json out.json]
    python3 -m benchmarks.bench_offsets --from-json L0.json L1.json   # summarize saved runs
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import yaml

from cgfem.report.runs import Run
from cgfem.run import THREAD_COUNTS

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = {"planar": "planar.yaml", "chain2_steel": "chain2_steel.yaml",
            "chain2_rubber": "chain2_rubber.yaml", "chain3": "chain3.yaml"}


def offset_cases(example: str, count: int, seed: int) -> list[tuple[dict, dict]]:
    """``count`` copies of the example's case data with seeded random grid offsets per body;
    each with the offsets it got (body -> [3 floats])."""
    data = yaml.safe_load((REPO / "config" / "cases" / EXAMPLES[example]).read_text())
    rng = np.random.default_rng([seed, sorted(EXAMPLES).index(example)])
    out = []
    for _ in range(count):
        case = json.loads(json.dumps(data))
        offsets = {}
        for name, body in case["bodies"].items():
            body["grid"]["offset"] = offsets[name] = [round(float(v), 4) for v in rng.uniform(0.0, 1.0, 3)]
        out.append((case, offsets))
    return out


def run_one(case: dict, level: int, surface: str, folder: Path, threads: int, policy: list[str] = ()) -> dict:
    """One ``cgfem run`` in its own process (``policy``: its ``--policy`` settings); the figures
    of its summary."""
    case_file = folder / "case.yaml"
    case_file.write_text(yaml.safe_dump(case, sort_keys=False))
    env = dict(os.environ, **dict.fromkeys(THREAD_COUNTS, str(threads)))
    proc = subprocess.run([sys.executable, "-m", "cgfem", "run", str(case_file), "--level", str(level),
                           "--surface", surface, "--out", str(folder / "out"), "--quiet",
                           *(f"--policy={item}" for item in policy)],
                          capture_output=True, text=True, env=env)
    summary_file = folder / "out" / "summary.json"
    if proc.returncode == 2 or not summary_file.exists():
        return {"status": f"error ({proc.returncode}): {proc.stderr.strip().splitlines()[-1:] }"}
    summary = json.loads(summary_file.read_text())
    steps = summary["steps"]
    return {"status": summary["status"], "message": summary.get("message", ""), "steps": len(steps),
            "cutbacks": max(0, len(steps) - int(case.get("steps", 1))) if summary["status"] == "converged"
            else None, "newton": Run(folder / "out", summary).newton_iterations,
            "final": final_value(case, steps), "folder": str(folder / "out"),
            "fallback": max((s.get("fallback", 0) for s in steps), default=0)}


def final_value(case: dict, steps: list[dict]) -> float:
    """The pulled reaction along y (chains) or the contact force along z (planar) of the
    last step; NaN without steps."""
    if not steps:
        return float("nan")
    if case["name"] == "planar":
        return float(-steps[-1]["contact"]["force"][2])
    pulled = next(b for b in case["boundary"] if b.get("type") == "displacement"
                  and any(float(v) != 0.0 for v in b["components"].values()))
    key = f"{pulled['body']}/{'+'.join(pulled['patches'])}"
    return float(steps[-1]["reactions"][key][1])


def planar_error(case: dict, folder: str, reference: str) -> float:
    from cgfem.report.energy import TOTAL, energy_errors, reference_error

    with tempfile.TemporaryDirectory() as tmp:
        case_file = Path(tmp) / "case.yaml"
        case_file.write_text(yaml.safe_dump(case, sort_keys=False))
        rows = energy_errors(case_file, folder, reference_error(reference))
    return next((r.error for r in rows if r.body == TOTAL), float("nan"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", nargs="+", default=list(EXAMPLES), choices=list(EXAMPLES))
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--surfaces", nargs="+", default=["facets", "nurbs_fe", "nurbs_fit"])
    parser.add_argument("--count", type=int, default=10)
    parser.add_argument("--sets", type=int, nargs="+", metavar="K",
                        help="run only these offset sets (0 to count - 1; the same offsets as in a full sweep)")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--jobs", type=int, default=2, help="runs at once (one thread each)")
    parser.add_argument("--reference", default=str(REPO / "results" / "reference" / "planar.npz"),
                        help="the planar reference (python3 -m cgfem.reference.planar --out FILE)")
    parser.add_argument("--policy", action="append", default=[], metavar="NAME=VALUE",
                        help="passed to every cgfem run (a solver constant changed; repeatable)")
    parser.add_argument("--json", help="write every run's figures to this file")
    parser.add_argument("--from-json", nargs="+", metavar="FILE",
                        help="run nothing: summarize the runs saved by earlier --json files together")
    args = parser.parse_args()
    if args.sets is not None and not all(0 <= k < args.count for k in args.sets):
        parser.error(f"--sets: offset sets run from 0 to {args.count - 1} (--count {args.count})")
    if args.from_json:
        rows = [row for name in args.from_json for row in json.loads(Path(name).read_text())]
        summarize(rows, sorted({r["level"] for r in rows}))
        return
    print(f"seed {args.seed}, {args.count} offsets per body; cores {os.cpu_count()}, load "
          f"{os.getloadavg()[0]:.2f}" + (f"; policy {' '.join(args.policy)}" if args.policy else ""), flush=True)
    jobs = []
    for example in args.examples:
        for k, (case, offsets) in enumerate(offset_cases(example, args.count, args.seed)):
            if args.sets is not None and k not in args.sets:
                continue
            print(f"{example} offset set {k}: " + ", ".join(f"{b} {o}" for b, o in offsets.items()), flush=True)
            for level in args.levels:
                for surface in args.surfaces:
                    jobs.append((example, k, level, surface, case))
    rows = []
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
        def work(job):
            example, k, level, surface, case = job
            folder = Path(tmp) / f"{example}_{k}_L{level}_{surface}"
            folder.mkdir()
            row = {"example": example, "offset_set": k, "level": level, "surface": surface,
                   **run_one(case, level, surface, folder, 1, args.policy)}
            if example == "planar" and row["status"] == "converged" and Path(args.reference).exists():
                row["energy_error"] = planar_error(case, row["folder"], args.reference)
            print(f"{example:>13} set {k:>2} L{level} {surface:>9}: {row['status']:>19} "
                  f"steps {row.get('steps', '-')} cut-backs {row.get('cutbacks', '-')} "
                  f"Newton {row.get('newton', '-')} final {row.get('final', float('nan')):.6g}"
                  + (f" fallback {row['fallback']}" if row.get("fallback") else "")
                  + (f" error {row['energy_error']:.4f}" if "energy_error" in row else "")
                  + (f"  [{row['message']}]" if row.get("message") else ""), flush=True)
            return row
        rows = list(pool.map(work, jobs))
    summarize(rows, args.levels)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


def summarize(rows: list[dict], levels: list[int]) -> None:
    print(f"\n{'example':>13} {'surface':>9} {'converged':>10} " + " ".join(
        f"{'L' + str(l) + ' mean':>12} {'spread %':>9}" for l in levels) + f" {'change L0-L1 %':>15}"
        + "  planar error per level")
    for example in dict.fromkeys(r["example"] for r in rows):
        for surface in dict.fromkeys(r["surface"] for r in rows):
            mine = [r for r in rows if r["example"] == example and r["surface"] == surface]
            if not mine:
                continue
            ok = [r for r in mine if r["status"] == "converged"]
            means, cells = [], []
            for level in levels:
                values = np.array([r["final"] for r in ok if r["level"] == level])
                mean = float(values.mean()) if values.size else float("nan")
                spread = 100 * float(np.ptp(values) / abs(mean)) if values.size > 1 else float("nan")
                means.append(mean)
                cells.append(f"{mean:>12.6g} {spread:>9.3f}")
            change = 100 * abs(means[1] / means[0] - 1) if len(means) > 1 else float("nan")
            errors = [np.mean([r["energy_error"] for r in ok if r["level"] == l and "energy_error" in r] or [np.nan])
                      for l in levels]
            print(f"{example:>13} {surface:>9} {len(ok):>4}/{len(mine):<5} " + " ".join(cells)
                  + f" {change:>15.3f}" + ("  " + ", ".join(f"{e:.4f}" for e in errors) if example == "planar" else ""))


if __name__ == "__main__":
    main()
