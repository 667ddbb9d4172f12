"""Accuracy per cost of the element orders: time to 1 % of the converged reaction.

Every (order, level) of one case is solved in its own process (the thread settings of this
one: set ``NUMBA_NUM_THREADS`` etc. before). Per run: unknowns (all bodies), Newton
iterations, the y reaction of one support at the last load step, wall time (build, solve)
and peak memory (the child's maximum resident set). Then the error of every reaction against
the best available value: the body-fitted reference ``config/reference/{case}.json`` where
one exists (its pulled support), else the finest order-2 run (labelled as such); and for each
order the cheapest run within 1 % of it. The ratio of their wall times is the speed-up of
order 2 at that accuracy (target: at least 10).

Default case: the clamped half torus of ``config/cases/bent_half_torus.yaml`` (reaction of
``link/cap_b``), which has no body-fitted reference. For the chains:

    python3 -m benchmarks.bench_order --case config/cases/chain2_steel.yaml \\
        --levels 0 1 2 3 --orders 1 2 [--surface nurbs_fe] [--json rows.json]

``--runs 2:0 2:1 1:0 1:1 1:2 1:3`` runs chosen ``order:level`` pairs instead of every order at
every level.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "config" / "cases" / "bent_half_torus.yaml"
#: the support whose y reaction is compared when the case has no reference file
DEFAULT_SUPPORT = "link/cap_b"
#: the accuracy the speed-up is measured at (relative error of the reaction)
ACCURACY = 0.01


def one_run(case: Path, level: int, order: int, surface: str, support: str, folder: Path) -> dict:
    """Solve one level and order in this process (called in a child); its figures."""
    from cgfem.case.load import load_case
    from cgfem.report.runs import Run
    from cgfem.run import run_case

    start = time.perf_counter()
    status = run_case(load_case(case), level, surface, folder / "out", order=order)
    wall = time.perf_counter() - start
    run = Run.load(status.summary)
    timings = run.timings()
    row = {"level": level, "order": order, "status": status.status, "dofs": run.dofs,
           "cut": sum(run.body(b)["elements"]["cut"] for b in run.body_names),
           "newton": run.newton_iterations, "steps": run.n_steps, "build_s": timings["build_s"],
           "solve_s": timings["solve_s"], "wall_s": wall,
           "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    if run.n_steps:
        row["load_factor"] = float(run.load_factors()[-1])
        row["reaction_y"] = float(run.reactions(support)[-1, 1])
    return row


def run_child(case: Path, level: int, order: int, surface: str, support: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([sys.executable, "-m", "benchmarks.bench_order", "--child", str(case), str(level),
                              str(order), surface, support, tmp], capture_output=True, text=True, cwd=ROOT)
        if out.returncode != 0:
            last = (out.stderr.strip().splitlines() or ["no output"])[-1]
            return {"level": level, "order": order, "status": f"error: {last}"}
        return json.loads(out.stdout.strip().splitlines()[-1])


def reference_of(case_name: str) -> tuple[str, float] | None:
    """(pulled support key, final y reaction in N) of the case's body-fitted reference, or None."""
    path = ROOT / "config" / "reference" / f"{case_name}.json"
    if not path.exists():
        return None
    from cgfem.report.validation import Y, Reference

    ref = Reference.load(path)
    return ref.pulled, float(ref.reactions[ref.pulled][-1, Y])


def report(rows: list[dict], reference: float | None) -> dict:
    """Print the table and the speed-up; return {order: cheapest row within ACCURACY}."""
    done = [r for r in rows if r.get("status") == "converged"]
    finest = None
    if reference is None:
        finest = max((r for r in done if r["order"] == 2), key=lambda r: r["dofs"], default=None)
        reference = finest["reaction_y"] if finest else float("nan")
        print(f"\nbest value: order 2 at level {finest['level'] if finest else '-'} ({reference:.8g} N; "
              "the finest order-2 run, not a reference)")
    else:
        print(f"\nbest value: the body-fitted reference ({reference:.8g} N)")
    print(f"{'order':>5} {'level':>5} {'unknowns':>9} {'cut':>6} {'Newton':>6} {'reaction y N':>14} "
          f"{'error %':>9} {'build s':>8} {'solve s':>8} {'wall s':>8} {'peak MiB':>9}")
    for r in rows:
        if r.get("status") != "converged":
            print(f"{r['order']:>5} {r['level']:>5}  {r['status']}"
                  + (f" at load factor {r['load_factor']:.4g}" if "load_factor" in r else ""))
            continue
        r["error"] = r["reaction_y"] / reference - 1.0
        print(f"{r['order']:>5} {r['level']:>5} {r['dofs']:>9} {r['cut']:>6} {r['newton']:>6} "
              f"{r['reaction_y']:>14.8g} {100 * r['error']:>+9.3f} {r['build_s']:>8.2f} {r['solve_s']:>8.2f} "
              f"{r['wall_s']:>8.2f} {r['peak_mib']:>9.0f}")
    cheapest = {}
    for order in (1, 2):
        within = [r for r in done if r["order"] == order and r is not finest and abs(r["error"]) <= ACCURACY]
        cheapest[order] = c = min(within, key=lambda r: r["wall_s"], default=None)
        print(f"order {order}: within {100 * ACCURACY:g} % "
              + (f"at level {c['level']} ({c['dofs']} unknowns, {c['wall_s']:.1f} s)" if c else "at no level run"))
    if cheapest[1] and cheapest[2]:
        print(f"speed-up of order 2 at {100 * ACCURACY:g} %: {cheapest[1]['wall_s'] / cheapest[2]['wall_s']:.1f}x "
              "(target >= 10)")
    return cheapest


def _order_level(pair: str) -> tuple[int, int]:
    """``"2:1"`` -> (2, 1); anything else stops with a one-line error (exit 2)."""
    order, colon, level = pair.partition(":")
    if colon and order.isdigit() and level.isdigit():
        return int(order), int(level)
    print(f"bench_order: --runs: expected ORDER:LEVEL pairs such as 2:1, got {pair!r}", file=sys.stderr)
    raise SystemExit(2)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        case, level, order, surface, support, folder = sys.argv[2:8]
        print(json.dumps(one_run(Path(case), int(level), int(order), surface, support, Path(folder))))
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, default=CASE)
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--orders", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--runs", nargs="+", metavar="ORDER:LEVEL",
                        help="run these order:level pairs (instead of --orders x --levels)")
    parser.add_argument("--surface", default="nurbs_fe")
    parser.add_argument("--json", type=Path, help="write the rows here after every run")
    args = parser.parse_args()
    runs = ([_order_level(pair) for pair in args.runs] if args.runs
            else [(order, level) for order in args.orders for level in args.levels])
    from cgfem.case.load import load_case
    from cgfem.errors import InputError

    try:
        name = load_case(args.case).name
    except (InputError, OSError) as error:  # a missing or invalid case file: one line, exit 2
        print(f"bench_order: --case: {error}", file=sys.stderr)
        raise SystemExit(2)
    found = reference_of(name)
    support, reference = found if found else (DEFAULT_SUPPORT, None)
    threads = {k: os.environ.get(k, "-") for k in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    print(f"{name} ({args.case}), surface {args.surface}, y reaction of {support}; cores {os.cpu_count()}; "
          f"threads {threads}; load average {os.getloadavg()[0]:.2f}", flush=True)
    rows = []
    for order, level in runs:
        r = run_child(args.case.resolve(), level, order, args.surface, support)
        rows.append(r)
        print(f"order {order} level {level}: {r.get('status')} "
              + (f"{r['dofs']} unknowns, {r['newton']} Newton, reaction {r['reaction_y']:.8g} N, "
                 f"{r['wall_s']:.1f} s, {r['peak_mib']:.0f} MiB" if r.get("status") == "converged" else ""),
              flush=True)
        if args.json:
            tmp = args.json.with_suffix(".tmp")
            tmp.write_text(json.dumps({"case": name, "surface": args.surface, "support": support,
                                       "reference": reference, "rows": rows}, indent=1))
            tmp.replace(args.json)
    report(rows, reference)


if __name__ == "__main__":
    main()
