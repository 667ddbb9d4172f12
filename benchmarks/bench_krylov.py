"""The linear solve of one Newton iteration of a contact system: PARDISO against the Krylov
path (AMG-preconditioned GMRES / CG, :mod:`cgfem.solve.krylov`), per level, on
``config/cases/chain2_steel.yaml`` (finite strain: non-symmetric, GMRES).

    python3 -m benchmarks.bench_krylov                    # levels 1 2
    python3 -m benchmarks.bench_krylov --levels 1 2 3 --surface nurbs_fe

The state is the one of ``benchmarks/bench_contact.py`` part 2 (link_b moved h/2 into
link_a plus a smooth field, ``p_N = 0``): every point of the contact zone active. Timed in
one process per level, so that ratios compare like with like on a loaded machine:

- ``bulk``: the bodies' residual and tangent (the bulk assembly of one Newton iteration);
- ``pardiso``: factorization + solve of the Newton matrix (``linear: auto``'s direct path);
- ``amg``: the preconditioner's setup; ``krylov 1e-10`` / ``1e-6`` / ``1e-3``: a solve to that
  relative residual with it (inexact Newton asks for 1e-10 only near the start of an increment
  and for looser ones later);
- ``kept``: a solve to 1e-6 of the Newton matrix of another state (link_b moved 0.2 h
  further) with the same preconditioner, as when it is kept across iterations.

The last columns are the ratios to the bulk assembly of the direct solve and of the Krylov
path's setup + the 1e-6 solve, and of a kept solve: the basis of ``krylov_min_dofs``
(:class:`cgfem.solve.policy.SolverPolicy`). Peak memory (MiB) is the process's.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def one_level(level: int, surface: str) -> dict:
    import numpy as np

    from benchmarks.bench_contact import build_system, contact_state
    from cgfem.solve.backends import factorize
    from cgfem.solve.krylov import AMGPreconditioner, krylov_solve

    system = build_system(level, surface)
    u = contact_state(system)
    system.contact.begin_pass()
    system.contact.freeze(u, [None] * len(system.bodies))
    system.freeze([None] * len(system.bodies))
    t = 0.2
    system.assemble(u, t, True)                           # warm-up (pairing known afterwards)
    tic = time.perf_counter()
    parts = [item.residual_and_tangent(u, t, True) for item in system.body_items]
    bulk = time.perf_counter() - tic
    r, K = system.assemble(u, t, True)
    b = -r
    import scipy.sparse as sp
    small = (sp.random(30, 30, 0.2, random_state=1) + 10.0 * sp.identity(30)).tocsr()
    factorize(small, backend="pardiso", symmetric=False).solve(np.ones(30))      # MKL's start-up
    row = {"level": level, "surface": surface, "n": int(system.n_dofs), "nnz_per_row": K.nnz / system.n_dofs,
           "symmetric": bool(system.symmetric), "bulk_s": bulk}
    del parts
    if system.indefinite:
        return {**row, "skipped": "a saddle point (nurbs_fit): solved by the reduced saddle solver"}
    tic = time.perf_counter()
    direct = factorize(K, backend="pardiso", symmetric=system.symmetric)
    exact = direct.solve(b)
    row["pardiso_s"] = time.perf_counter() - tic
    row["factor_per_row"] = direct.info.get("factor_nnz", 0) / system.n_dofs
    del direct
    tic = time.perf_counter()
    M = AMGPreconditioner(K, system.near_null(), system.symmetric)
    row["amg_s"] = time.perf_counter() - tic
    row["operator_complexity"] = M.info["operator_complexity"]
    for rtol in (1e-10, 1e-6, 1e-3):
        tic = time.perf_counter()
        x, its, res, ok = krylov_solve(K, b, M, rtol, 1000, system.symmetric)
        row[f"krylov_{rtol:g}"] = {"s": time.perf_counter() - tic, "iterations": its, "reached": ok,
                                   "error": float(np.linalg.norm(x - exact) / np.linalg.norm(exact))}
    u2 = u.copy()
    i = [body.name for body in system.bodies].index("link_b")
    u2[system.offsets[i]:system.offsets[i + 1]][1::3] += 0.2 * system.bodies[i].space.h
    r2, K2 = system.assemble(u2, t, True)
    tic = time.perf_counter()
    _, its, res, ok = krylov_solve(K2, -r2, M, 1e-6, 1000, system.symmetric)
    row["kept"] = {"s": time.perf_counter() - tic, "iterations": its, "reached": ok}
    row["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    row["load"] = os.getloadavg()[0]
    return row


def print_table(rows: list[dict]) -> None:
    print("\nOne Newton iteration's linear solve on chain2_steel (link_b h/2 into link_a, p_N = 0); "
          "seconds; ratios to the bulk assembly")
    print(f"{'level':>5} {'surface':<9} {'n':>7} {'nnz/n':>6} {'bulk':>6} {'pardiso':>8} {'fill/n':>7} "
          f"{'amg':>6} {'1e-10 (it)':>12} {'1e-6 (it)':>12} {'1e-3 (it)':>12} {'kept 1e-6':>12} "
          f"{'pardiso/bulk':>12} {'(amg+1e-6)/bulk':>15} {'kept/bulk':>9} {'peak MiB':>8} {'load':>5}")
    for r in rows:
        if "skipped" in r:
            print(f"{r['level']:>5} {r['surface']:<9} {r['n']:>7}  skipped: {r['skipped']}")
            continue
        k = {key: r[f"krylov_{key}"] for key in ("1e-10", "1e-06", "0.001")}
        cell = [f"{v['s']:.2f} ({v['iterations']})" for v in k.values()]
        kept = f"{r['kept']['s']:.2f} ({r['kept']['iterations']})"
        print(f"{r['level']:>5} {r['surface']:<9} {r['n']:>7} {r['nnz_per_row']:6.1f} {r['bulk_s']:6.2f} "
              f"{r['pardiso_s']:8.2f} {r['factor_per_row']:7.0f} {r['amg_s']:6.2f} {cell[0]:>12} {cell[1]:>12} "
              f"{cell[2]:>12} {kept:>12} {r['pardiso_s'] / r['bulk_s']:12.1f} "
              f"{(r['amg_s'] + k['1e-06']['s']) / r['bulk_s']:15.1f} {r['kept']['s'] / r['bulk_s']:9.1f} "
              f"{r['peak_mib']:8.0f} {r['load']:5.1f}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--surface", default="nurbs_fe")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)      # a level in this process
    args = parser.parse_args(argv)
    if args.one is not None:
        print(json.dumps(one_level(args.one, args.surface)))
        return
    rows = []
    for level in args.levels:
        out = subprocess.run([sys.executable, "-m", "benchmarks.bench_krylov", "--one", str(level),
                              "--surface", args.surface], cwd=ROOT, capture_output=True, text=True)
        if out.returncode != 0:
            rows.append({"level": level, "surface": args.surface, "n": 0, "skipped": out.stderr.strip()[-300:]})
        else:
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
        print_table(rows[-1:])
    print_table(rows)


if __name__ == "__main__":
    main()
