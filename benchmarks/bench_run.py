"""End-to-end figures of `cgfem run` on a Neo-Hookean chain link pulled by one cap.

For each level: DOFs, cut elements, time to build (geometry, embedding, models) and to solve,
Newton iterations, outer passes, the linear backend `auto` chose, the pulled cap's reaction
and the peak memory of the run (each level in its own process, so peaks do not mix).

    python3 -m benchmarks.bench_run [max_level] [surface]
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

CASE = textwrap.dedent("""\
    name: link_pull
    kinematics: finite
    steps: 3
    bodies:
      link:
        geometry: {builder: half_torus, center: [0, 0, 0], axis: [0, 0, 1], major_radius: 0.02,
                   minor_radius: 0.005, keep: [0, 1, 0]}
        material: {model: neo_hookean, E: 7.0e6, nu: 0.45}
        grid: {h0: 0.005, offset: [0.13, 0.29, 0.41]}
    boundary:
      - {body: link, patches: [cap_a], type: displacement, components: {x: 0, y: 0, z: 0}}
      - {body: link, patches: [cap_b], type: displacement, components: {x: 0, y: -0.003, z: 0}}
    solver: {outer_passes: 4}
    """)


def one_level(level: int, surface: str, folder: Path) -> dict:
    """Run one level in this process (called in a child) and return its figures."""
    from cgfem.case.load import load_case
    from cgfem.report.runs import Run
    from cgfem.run import run_case

    case_file = folder / "case.yaml"
    case_file.write_text(CASE)
    start = time.perf_counter()
    status = run_case(load_case(case_file), level, surface, folder / "out")
    wall = time.perf_counter() - start
    summary = json.loads(status.summary.read_text())
    body = summary["bodies"]["link"]
    steps = summary["steps"]
    return {"level": level, "status": status.status, "dofs": body["dofs"], "cut": body["elements"]["cut"],
            "build_s": summary["timings"]["build_s"], "solve_s": summary["timings"]["solve_s"], "wall_s": wall,
            "newton": Run(status.summary.parent, summary).newton_iterations,
            "passes": sum(s["outer_passes"] for s in steps),
            "reaction_y": steps[-1]["reactions"]["link/cap_b"][1] if steps else float("nan"),
            "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        level, surface, folder = int(sys.argv[2]), sys.argv[3], Path(sys.argv[4])
        print(json.dumps(one_level(level, surface, folder)))
        return
    max_level = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    surface = sys.argv[2] if len(sys.argv) > 2 else "nurbs_fe"
    print(f"cgfem run, Neo-Hookean half-torus link (R 0.02, r 0.005, h0 0.005), cap pulled 3 mm in 3 "
          f"steps, surface {surface}; cores {os.cpu_count()}; load average {os.getloadavg()[0]:.2f}")
    print(f"{'level':>5} {'DOFs':>8} {'cut':>6} {'build s':>8} {'solve s':>8} {'Newton':>7} {'passes':>7} "
          f"{'reaction y N':>13} {'peak MiB':>9}")
    for level in range(max_level + 1):
        with tempfile.TemporaryDirectory() as tmp:
            out = subprocess.run([sys.executable, "-m", "benchmarks.bench_run", "--child", str(level), surface, tmp],
                                 capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
        print(f"{r['level']:>5} {r['dofs']:>8} {r['cut']:>6} {r['build_s']:>8.2f} {r['solve_s']:>8.2f} "
              f"{r['newton']:>7} {r['passes']:>7} {r['reaction_y']:>13.6g} {r['peak_mib']:>9.0f}"
              + ("" if r["status"] == "converged" else f"  ({r['status']})"))


if __name__ == "__main__":
    main()
