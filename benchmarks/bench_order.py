"""Accuracy per cost of the element orders on a bent chain link.

The clamped half torus of ``config/cases/bent_half_torus.yaml`` (R 0.02, r 0.005, E 115 GPa,
nu 0.3, small strain; cap_a clamped, cap_b moved 1e-4 m along y) is solved with trilinear
(order 1) and triquadratic (order 2) hexahedra at each level, every run in its own process.
Per run: unknowns, the moved cap's reaction along y, wall time (build, solve) and peak
memory; then the error of every reaction against the finest order-2 value, and for each
order the cheapest run within 1 % of it: the ratio of their wall times is the speed-up of
order 2 at that accuracy (target: at least 10).

    python3 -m benchmarks.bench_order [--levels 0 1 2 3] [--orders 1 2] [--surface nurbs_fe]
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

CASE = Path(__file__).resolve().parents[1] / "config" / "cases" / "bent_half_torus.yaml"
#: the accuracy the speed-up is measured at (relative error of the reaction)
ACCURACY = 0.01


def one_run(level: int, order: int, surface: str, folder: Path) -> dict:
    """Solve one level and order in this process (called in a child); its figures."""
    from cgfem.case.load import load_case
    from cgfem.run import run_case

    start = time.perf_counter()
    status = run_case(load_case(CASE), level, surface, folder / "out", order=order)
    wall = time.perf_counter() - start
    summary = json.loads(status.summary.read_text())
    body = summary["bodies"]["link"]
    step = summary["steps"][-1]
    return {"level": level, "order": order, "status": status.status, "dofs": body["dofs"],
            "cut": body["elements"]["cut"], "build_s": summary["timings"]["build_s"],
            "solve_s": summary["timings"]["solve_s"], "wall_s": wall,
            "reaction_y": step["reactions"]["link/cap_b"][1],
            "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def run_child(level: int, order: int, surface: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([sys.executable, "-m", "benchmarks.bench_order", "--child", str(level), str(order),
                              surface, tmp], capture_output=True, text=True)
        if out.returncode != 0:
            return {"level": level, "order": order, "status": f"error: {out.stderr.strip().splitlines()[-1:]}"}
        return json.loads(out.stdout.strip().splitlines()[-1])


def report(rows: list[dict]) -> None:
    done = [r for r in rows if r.get("status") == "converged"]
    finest = max((r for r in done if r["order"] == 2), key=lambda r: r["dofs"], default=None)
    reference = finest["reaction_y"] if finest else float("nan")
    print(f"\nreference: order 2 at level {finest['level'] if finest else '-'} ({reference:.8g} N)")
    print(f"{'order':>5} {'level':>5} {'unknowns':>9} {'cut':>6} {'reaction y N':>14} {'error %':>9} "
          f"{'build s':>8} {'solve s':>8} {'wall s':>8} {'peak MiB':>9}")
    for r in rows:
        if r.get("status") != "converged":
            print(f"{r['order']:>5} {r['level']:>5}  {r['status']}")
            continue
        r["error"] = abs(r["reaction_y"] / reference - 1.0)
        print(f"{r['order']:>5} {r['level']:>5} {r['dofs']:>9} {r['cut']:>6} {r['reaction_y']:>14.8g} "
              f"{100 * r['error']:>9.3f} {r['build_s']:>8.2f} {r['solve_s']:>8.2f} {r['wall_s']:>8.2f} "
              f"{r['peak_mib']:>9.0f}")
    cheapest = {}
    for order in (1, 2):
        within = [r for r in done if r["order"] == order and r is not finest and r["error"] <= ACCURACY]
        cheapest[order] = min(within, key=lambda r: r["wall_s"], default=None)
        c = cheapest[order]
        print(f"order {order}: within {100 * ACCURACY:g} % " +
              (f"at level {c['level']} ({c['dofs']} unknowns, {c['wall_s']:.1f} s)" if c else "at no level run"))
    if cheapest[1] and cheapest[2]:
        print(f"speed-up of order 2 at {100 * ACCURACY:g} %: {cheapest[1]['wall_s'] / cheapest[2]['wall_s']:.1f}x "
              "(target >= 10)")


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        level, order, surface, folder = int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], Path(sys.argv[5])
        print(json.dumps(one_run(level, order, surface, folder)))
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--orders", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--surface", default="nurbs_fe")
    args = parser.parse_args()
    print(f"bent half torus ({CASE.name}), surface {args.surface}; cores {os.cpu_count()}; "
          f"load average {os.getloadavg()[0]:.2f}")
    rows = []
    for order in args.orders:
        for level in args.levels:
            r = run_child(level, order, args.surface)
            rows.append(r)
            print(f"order {order} level {level}: {r.get('status')} "
                  + (f"{r['dofs']} unknowns, reaction {r['reaction_y']:.8g} N, {r['wall_s']:.1f} s, "
                     f"{r['peak_mib']:.0f} MiB" if r.get("status") == "converged" else ""), flush=True)
    report(rows)


if __name__ == "__main__":
    main()
