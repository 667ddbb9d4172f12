"""Where a whole run's Newton iterations go: the linear solves against the bulk assembly.

Runs one case (default chain2_steel, `nurbs_fe`) through ``run_case`` in this process with
timers around the linear solves (:class:`cgfem.solve.solves.LinearSolves`), the bodies'
assembly with tangent (:meth:`cgfem.solve.items.BodyItem.add`, every body summed per system
assembly) and the contact pairs' (:meth:`cgfem.contact.assembly.ContactSet.add`), and prints:

- the run's status, Newton iterations (modified ones counted), outer passes, wall time and
  peak memory (``VmHWM``);
- per linear solve, per system assembly with tangent and per assembly of the bodies'
  tangents (a system assembly at the unknowns of the one before reuses them: a new outer
  pass from where the last one ended): seconds, and the ratio of a linear solve to an
  assembly of the bodies' tangents, the figure issue 33 bounds by 3 ("the linear solve per
  Newton iteration at most 3x the bulk assembly of that iteration");
- on the Krylov path, the preconditioner builds (count, seconds, within the solves) and the
  Krylov iterations of all solves;
- the share of the solve phase in the solves, the bulk and contact assemblies, and the rest
  (recovery, search outside assemblies, line-search residuals without tangent, output).

    python3 -m benchmarks.bench_newton_split --level 3            # issue 33's run
    python3 -m benchmarks.bench_newton_split --level 1 --krylov-min-dofs 0

Run it with one thread (``NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1``) for the
figures of docs/performance.md; the counts do not depend on the load, the seconds do.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._memory import status_kib

ROOT = Path(__file__).resolve().parents[1]


class Timer:
    """Seconds and calls of the wrapped callables, per name."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}

    def wrap(self, owner, attribute: str, name: str, when=lambda *a, **k: True) -> None:
        """Time ``owner.attribute`` under ``name`` on the calls for which ``when(*args)``."""
        original = getattr(owner, attribute)
        timer = self

        @functools.wraps(original)
        def timed(*args, **kwargs):
            if not when(*args, **kwargs):
                return original(*args, **kwargs)
            tic = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                timer.seconds[name] = timer.seconds.get(name, 0.0) + time.perf_counter() - tic
                timer.calls[name] = timer.calls.get(name, 0) + 1
        setattr(owner, attribute, timed)


def measure(case_path: Path, level: int, surface: str, order: int, krylov_min_dofs: int | None,
            refresh_rate: float | None = None) -> dict:
    """One run of ``case_path`` with the timers; the figures printed by :func:`main`."""
    from cgfem.case import parse_case, parse_yaml
    from cgfem.contact.assembly import ContactSet
    from cgfem.report.runs import Run
    from cgfem.run import run_case
    from cgfem.solve.items import BodyItem
    from cgfem.solve.policy import DEFAULT_POLICY
    from cgfem.solve.solves import LinearSolves
    from cgfem.solve.system import System

    timer = Timer()
    timer.wrap(LinearSolves, "__call__", "solve")
    timer.wrap(LinearSolves, "_refresh", "preconditioner")
    krylov_iterations = [0]
    original_krylov = LinearSolves._krylov

    def counted(self, *args, **kwargs):
        x = original_krylov(self, *args, **kwargs)
        krylov_iterations[0] += self.history[-1][1]
        return x
    LinearSolves._krylov = counted
    # one system assembly with tangent: every body's add (summed) and the contact set's
    timer.wrap(System, "assemble", "assembly", lambda self, u, t, tangent: tangent)
    timer.wrap(BodyItem, "add", "bulk", lambda self, u, t, r, tangent: tangent)
    timer.wrap(ContactSet, "add", "contact", lambda self, u, r, tangent, update=True: tangent)
    policy = DEFAULT_POLICY if krylov_min_dofs is None else \
        dataclasses.replace(DEFAULT_POLICY, krylov_min_dofs=krylov_min_dofs,
                            krylov_nonsymmetric_min_dofs=krylov_min_dofs, krylov_order2_min_dofs=krylov_min_dofs,
                            krylov_floating_min_dofs=krylov_min_dofs, krylov_saddle_min_dofs=krylov_min_dofs)
    if refresh_rate is not None:
        policy = dataclasses.replace(policy, krylov_refresh_rate=refresh_rate)
    case = parse_case(parse_yaml(case_path.read_text()), case_path.parent)
    with tempfile.TemporaryDirectory() as folder:
        tic = time.perf_counter()
        status = run_case(case, level, surface, Path(folder), order=order, policy=policy)
        wall = time.perf_counter() - tic
        summary = json.loads((Path(folder) / "summary.json").read_text())
    run = Run(Path("."), summary)
    # the bulk's seconds are summed over the bodies of one system assembly that assembled the
    # bodies' tangents (an assembly at the unknowns of the last one reuses them and is not one)
    bodies = len(run.body_names)
    fresh = timer.calls.get("bulk", 0) // max(1, bodies)
    bulk_per = timer.seconds.get("bulk", 0.0) / max(1, fresh)
    solve_per = timer.seconds.get("solve", 0.0) / max(1, timer.calls.get("solve", 0))
    return {"case": case_path.stem, "level": level, "surface": surface, "order": order,
            "status": status.status, "newton": run.newton_iterations,
            "passes": sum(s["outer_passes"] for s in summary["steps"]), "wall_s": wall,
            "build_s": summary["timings"]["build_s"], "solve_phase_s": summary["timings"]["solve_s"],
            "peak_gib": status_kib("VmHWM") / 2**20, "seconds": timer.seconds, "calls": timer.calls,
            "reactions": summary["steps"][-1]["reactions"] if summary["steps"] else {},
            "krylov_iterations": krylov_iterations[0], "solve_per_s": solve_per, "bulk_per_s": bulk_per,
            "bulk_tangents": fresh,
            "ratio": solve_per / bulk_per if bulk_per > 0.0 else float("nan")}


def report(row: dict) -> str:
    """The figures of one run as lines of text."""
    s, c = row["seconds"], row["calls"]
    phase = row["solve_phase_s"]
    rest = phase - s.get("solve", 0.0) - s.get("assembly", 0.0)
    lines = [
        f"{row['case']} level {row['level']} {row['surface']} order {row['order']}: {row['status']}, "
        f"{row['newton']} Newton iterations, {row['passes']} outer passes, wall {row['wall_s']:.1f} s "
        f"(build {row['build_s']:.1f} s, solve {phase:.1f} s), peak {row['peak_gib']:.2f} GiB",
        f"  linear solves:        {c.get('solve', 0):5d} x {row['solve_per_s']:.3f} s = {s.get('solve', 0.0):8.1f} s",
        f"  of which preconditioner builds: {c.get('preconditioner', 0)} taking {s.get('preconditioner', 0.0):.1f} s; "
        f"Krylov iterations {row['krylov_iterations']}",
        f"  tangent assemblies:   {c.get('assembly', 0):5d} x "
        f"{s.get('assembly', 0.0) / max(1, c.get('assembly', 0)):.3f} s = {s.get('assembly', 0.0):8.1f} s "
        f"(contact {s.get('contact', 0.0):.1f} s)",
        f"  bodies' tangents:     {row['bulk_tangents']:5d} x {row['bulk_per_s']:.3f} s = {s.get('bulk', 0.0):8.1f} s "
        f"(the other {c.get('assembly', 0) - row['bulk_tangents']} assemblies reused them at the same unknowns)",
        f"  the rest of the solve phase: {rest:.1f} s",
        *(f"  final reaction of {name}: {np.array2string(np.asarray(value), precision=10)} N"
          for name, value in row["reactions"].items()),
        f"  linear solve / bodies' tangent assembly: {row['ratio']:.2f} (issue 33: at most 3)",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", type=Path, default=ROOT / "config" / "cases" / "chain2_steel.yaml")
    parser.add_argument("--level", type=int, default=3)
    parser.add_argument("--surface", default="nurbs_fe")
    parser.add_argument("--order", type=int, default=1)
    parser.add_argument("--krylov-min-dofs", type=int, default=None,
                        help="the Krylov path's thresholds, every order's, floating bodies' and saddle points' "
                             "too (default the policy's); 0 forces it")
    parser.add_argument("--krylov-refresh-rate", type=float, default=None,
                        help="the policy's krylov_refresh_rate (default the policy's); 0: rebuild the "
                             "preconditioner past krylov_refresh iterations alone")
    parser.add_argument("--json", type=Path, help="write the figures to this file")
    args = parser.parse_args(argv)
    row = measure(args.case, args.level, args.surface, args.order, args.krylov_min_dofs, args.krylov_refresh_rate)
    print(report(row))
    if args.json:
        args.json.write_text(json.dumps(row, indent=1))
    return 0 if row["status"] == "converged" else 1


if __name__ == "__main__":
    sys.exit(main())
