"""``nurbs_fit`` against ``nurbs_fe`` on chain2_steel (issue "nurbs_fit ... kept sparse").

For each level, each definition runs ``cgfem run`` in its own process (so peak memories do
not mix) and reports: unknowns (the bodies' dofs, plus the fitted patches' control
displacements and multipliers for nurbs_fit), nonzeros per unknown of every matrix the
linear solver factorized (largest over the run) and of its factor, Newton iterations, solve
time, time per Newton iteration and the peak resident memory. The last lines give the ratios
nurbs_fit / nurbs_fe measured in the same run (targets: time <= 3x, memory <= 2x, nonzeros
per unknown within 20 %).

    python3 -m benchmarks.bench_fit [--parallel] [--first-step] [levels ...]   # default: 1 2

``--parallel``: the two definitions of a level run at once, one thread each (2 cores: at
level 3 nurbs_fe takes 48 min and nurbs_fit 68 min); both then share the machine alike, so
their ratios still compare like with like, while their absolute times are those of a loaded
machine. ``--first-step``: only the case's first load step (the caps pulled by a fifth of
the 5 mm, as one step): the contact forms there (nurbs_fe at level 3: 19 of 81 Newton
iterations, 14 of its 48 minutes). ``--verbose``: every run's progress log on stderr, each
line prefixed with its level and definition.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CASE = REPO / "config" / "cases" / "chain2_steel.yaml"
SURFACES = ("nurbs_fe", "nurbs_fit")


def first_step_case():
    """chain2_steel's first load step alone: one step, the pull divided by the step count."""
    from cgfem.case import parse_case, parse_yaml

    data = parse_yaml(CASE.read_text())
    pulled = next(b for b in data["boundary"] if b["body"] == "link_b")
    pulled["components"]["y"] /= data["steps"]
    data["steps"] = 1
    return parse_case(data, CASE.parent)


def one_run(level: int, surface: str, folder: Path, first_step: bool = False, verbose: bool = False) -> dict:
    """Run one analysis in this process (a child) and return its figures; ``verbose``: its
    progress log on stderr."""
    import resource

    import cgfem.solve.solves as static
    from cgfem.case.load import load_case
    from cgfem.report.runs import Run
    from cgfem.run import run_case

    matrices: list[dict] = []
    factorize = static.factorize

    def counting(A, **kwargs):
        solver = factorize(A, **kwargs)
        # the reduced saddle solver factorizes its reduced matrix, not A
        n, nnz = solver.info.get("factorized_n", A.shape[0]), solver.info.get("factorized_nnz", A.nnz)
        matrices.append({"n": int(n), "nnz": int(nnz), "factor_nnz": int(solver.info.get("factor_nnz", 0)),
                         "backend": solver.backend})
        return solver

    static.factorize = counting
    case = first_step_case() if first_step else load_case(CASE)
    def log(message: str) -> None:
        if verbose:
            print(f"[L{level} {surface}] {message}", file=sys.stderr, flush=True)
    status = run_case(case, level, surface, folder / "out", log=log)
    summary = json.loads(status.summary.read_text())
    iterations = Run(status.summary.parent, summary).newton_iterations
    solve = summary["timings"]["solve_s"]
    widest = max(matrices, key=lambda m: m["nnz"] / m["n"])
    return {"level": level, "surface": surface, "status": summary["status"], "unknowns": widest["n"],
            "dofs": sum(b["dofs"] for b in summary["bodies"].values()),
            "nnz_per_unknown": widest["nnz"] / widest["n"], "factor_nnz_per_unknown": widest["factor_nnz"] / widest["n"],
            "backend": widest["backend"], "factorizations": len(matrices), "newton": iterations,
            "build_s": summary["timings"]["build_s"], "solve_s": solve, "s_per_newton": solve / max(iterations, 1),
            "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def _child(level: int, surface: str, tmp: str, env: dict | None, first_step: bool,
           verbose: bool) -> subprocess.Popen:
    code = (f"import json; from benchmarks import bench_fit; "
            f"from pathlib import Path; "
            f"print(json.dumps(bench_fit.one_run({level}, {surface!r}, Path({tmp!r}), {first_step!r}, {verbose!r})))")
    # verbose: the child's log goes straight to this process's stderr (its errors too)
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                            stderr=None if verbose else subprocess.PIPE, text=True, env=env)


def main(levels: list[int], parallel: bool = False, first_step: bool = False, verbose: bool = False) -> None:
    rows = []
    env = None
    if parallel:
        from cgfem.run import THREAD_COUNTS

        env = dict(os.environ, **dict.fromkeys(THREAD_COUNTS, "1"))
    print(f"{'L':>2} {'surface':9} {'status':10} {'unknowns':>9} {'dofs':>8} {'nnz/unk':>8} {'LU/unk':>8} "
          f"{'newton':>6} {'solve s':>8} {'s/newton':>9} {'peak MiB':>9}", flush=True)
    for level in levels:
        groups = [SURFACES] if parallel else [(s,) for s in SURFACES]
        for group in groups:
            tmps = [tempfile.TemporaryDirectory() for _ in group]
            children = [_child(level, surface, t.name, env, first_step, verbose) for surface, t in zip(group, tmps)]
            for surface, child, tmp in zip(group, children, tmps):
                stdout, stderr = child.communicate()
                tmp.cleanup()
                if child.returncode != 0:
                    last = (stderr or "").strip().splitlines() or ["see the log above"]
                    print(f"{level:>2} {surface:9} error: {last[-1]}", flush=True)
                    continue
                r = json.loads(stdout.strip().splitlines()[-1])
                rows.append(r)
                print(f"{level:>2} {surface:9} {r['status']:10} {r['unknowns']:>9} {r['dofs']:>8} "
                      f"{r['nnz_per_unknown']:>8.1f} {r['factor_nnz_per_unknown']:>8.1f} {r['newton']:>6} "
                      f"{r['solve_s']:>8.1f} {r['s_per_newton']:>9.2f} {r['peak_mib']:>9.0f}", flush=True)
    print("\nratios nurbs_fit / nurbs_fe (targets: time <= 3, memory <= 2, nnz per unknown <= 1.2):")
    for level in levels:
        pair = {r["surface"]: r for r in rows if r["level"] == level}
        if len(pair) == 2:
            fe, fit = pair["nurbs_fe"], pair["nurbs_fit"]
            print(f"  L{level}: time per Newton iteration {fit['s_per_newton'] / fe['s_per_newton']:.2f}, "
                  f"solve time {fit['solve_s'] / fe['solve_s']:.2f}, peak memory {fit['peak_mib'] / fe['peak_mib']:.2f}, "
                  f"nnz per unknown {fit['nnz_per_unknown'] / fe['nnz_per_unknown']:.2f}, "
                  f"factor nnz per unknown {fit['factor_nnz_per_unknown'] / max(fe['factor_nnz_per_unknown'], 1e-300):.2f}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("levels", nargs="*", type=int, default=[1, 2])
    parser.add_argument("--parallel", action="store_true", help="both definitions of a level at once, one thread each")
    parser.add_argument("--first-step", action="store_true", help="only the first load step")
    parser.add_argument("--verbose", action="store_true", help="every run's progress log on stderr")
    args = parser.parse_args()
    main(args.levels, parallel=args.parallel, first_step=args.first_step, verbose=args.verbose)
