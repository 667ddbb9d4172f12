"""Linear solvers of :mod:`cgfem.solve.linear` on H8 linear elasticity.

    python benchmarks/bench_solvers.py [n ...]      # cube edges in elements, default 14 21 31 38 45

A unit cube of ``n^3`` bricks (E = 1, nu = 0.3), bottom face clamped (dofs eliminated),
load on the top face: about 10k, 30k, 100k, 170k and 300k DOFs for the default edges. Each
(backend, size) runs in its own process, which assembles the matrix, then times
``factorize`` (setup, after a warm-up on a tiny cube), the first ``solve`` and three more
solves with other right-hand sides (re-solve, mean), and reports the memory the solver
added at its peak (Linux VmHWM reset after assembly, minus the RSS before setup; it
includes the solver's own copy of the matrix) and the process's peak RSS. Above 100k DOFs
superlu is skipped where its time, extrapolated from the two largest sizes it ran at,
exceeds two minutes.
"""

from __future__ import annotations

import gc
import json
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np
from benchmarks._memory import reset_peak, status_kib

SUPERLU_BUDGET_S = 120.0  # superlu is skipped above SUPERLU_ALWAYS_DOFS when expected slower
SUPERLU_ALWAYS_DOFS = 100_000


def run_one(backend: str, n: int) -> dict:
    """Time one backend on the n^3 cube (runs in the child process)."""
    from tests.support import elasticity_fixture as fx

    from cgfem.solve.linear import factorize, rigid_body_modes

    Kw, fw, _ = fx.clamped_cube(2)  # warm-up: imports, MKL start-up, first-call costs
    factorize(Kw, backend=backend).solve(fw)
    K, f, free = fx.clamped_cube(n, 1.0 / n)
    coords = fx.grid_coords(n, n, n, 1.0 / n)
    B = rigid_body_modes(coords)[free]
    others = [np.roll(f, 3 * k + 1) for k in range(3)]  # lateral loads on other nodes
    gc.collect()
    base = status_kib("VmRSS")
    hwm_ok = reset_peak()
    t0 = time.perf_counter()
    solver = factorize(K, backend=backend, symmetric=True, near_null=B, rtol=1e-10)
    t1 = time.perf_counter()
    solver.solve(f)
    t2 = time.perf_counter()
    for g in others:
        solver.solve(g)
    t3 = time.perf_counter()
    peak = status_kib("VmHWM") - base if hwm_ok else float("nan")
    return {"backend": solver.backend, "n": n, "dofs": K.shape[0], "nnz": K.nnz,
            "setup_s": t1 - t0, "solve_s": t2 - t1, "resolve_s": (t3 - t2) / len(others),
            "iterations": solver.info["iterations"],
            "residual": max(solver.info["residuals"]), "solver_mib": peak / 1024,
            "maxrss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "factor_nnz": solver.info.get("factor_nnz")}


def machine_info() -> str:
    import pyamg
    import scipy

    from cgfem.solve.linear import available_backends

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return (f"{platform.processor() or platform.machine()}, {cores} usable cores "
            f"(os.cpu_count {os.cpu_count()}), {mem:.0f} GiB RAM, load average {load}\n"
            f"python {platform.python_version()}, numpy {np.__version__}, "
            f"scipy {scipy.__version__}, pyamg {pyamg.__version__}, "
            f"backends {', '.join(available_backends())}")


def main(sizes: list[int]) -> None:
    from cgfem.solve.linear import available_backends

    print(machine_info())
    print(f"{'backend':<8} {'n':>3} {'DOFs':>7} {'setup s':>8} {'solve s':>8} {'re-solve s':>10} "
          f"{'iterations':>14} {'residual':>9} {'solver MiB':>10} {'maxRSS MiB':>10}  factor nnz",
          flush=True)
    superlu_runs: list[tuple[int, float]] = []
    for n in sizes:
        dofs = 3 * (n + 1) ** 2 * n
        for backend in available_backends():
            if backend == "superlu" and dofs > SUPERLU_ALWAYS_DOFS and len(superlu_runs) >= 2:
                (d0, t0), (d1, t1) = superlu_runs[-2:]
                p = np.log(t1 / t0) / np.log(d1 / d0)
                estimate = t1 * (dofs / d1) ** p
                if estimate > SUPERLU_BUDGET_S:
                    print(f"superlu  {n:>3} {dofs:>7}  skipped: {estimate:.0f} s expected (time "
                          f"~ DOFs^{p:.2f} from the two largest runs) > {SUPERLU_BUDGET_S:.0f} s",
                          flush=True)
                    continue
            t = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "benchmarks.bench_solvers", "--one", backend, str(n)],
                                  capture_output=True, text=True, timeout=3600)
            if proc.returncode != 0:
                last = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
                print(f"{backend:<8} {n:>3} {dofs:>7}  FAILED: {last}", flush=True)
                continue
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            if backend == "superlu":
                superlu_runs.append((r["dofs"], r["setup_s"] + r["solve_s"]))
            its = ",".join(str(i) for i in r["iterations"])
            fill = f"{r['factor_nnz'] / 1e6:.0f}M" if r["factor_nnz"] else "-"
            print(f"{backend:<8} {n:>3} {r['dofs']:>7} {r['setup_s']:8.2f} {r['solve_s']:8.3f} "
                  f"{r['resolve_s']:10.3f} {its:>14} {r['residual']:9.1e} {r['solver_mib']:10.0f} "
                  f"{r['maxrss_mib']:10.0f}  {fill:>7}   (wall {time.perf_counter() - t:.0f} s)",
                  flush=True)
    print(f"load average at the end: {', '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--one"]:
        print(json.dumps(run_one(sys.argv[2], int(sys.argv[3]))))
    else:
        main([int(a) for a in sys.argv[1:]] or [14, 21, 31, 38, 45])
