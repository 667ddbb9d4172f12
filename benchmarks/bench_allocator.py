"""What keeping freed memory (``cgfem._allocator``) is worth on this machine.

1. **Refault**: in a child process, an array of ``--mb`` MiB is filled, freed, and after
   ``--wait`` seconds another of the same size is filled: the second fill's rate (GB/s) with
   glibc's default allocator (the freed block unmapped, its pages back to the kernel and, on a
   virtual machine that reports free pages, to the host) and with
   :func:`~cgfem._allocator.keep_freed_memory` (the block kept in the heap). The first fill is
   printed too: memory the process never had, what every run pays once for its peak.
2. **A run** (default planar at level 3 with ``nurbs_fe``, one thread, the two variants one
   after the other): ``cgfem run``'s wall time and peak resident memory with freed memory
   kept (whatever the run's memory estimate, ``cgfem.memory.KEEP_MEMORY_SHARE``) and with glibc's
   default, their ratio, and whether the two summaries are the same bits
   (:func:`cgfem.results.stable`).

    python3 -m benchmarks.bench_allocator [--mb 600] [--wait 8] [--case config/cases/planar.yaml]
        [--level 3] [--surface nurbs_fe] [--order 1] [--no-run] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from cgfem.results import stable, write_json_atomic
from cgfem.memory import KEPT_MEMORY_LOG
from cgfem.run import THREAD_COUNTS

REPO = Path(__file__).resolve().parents[1]

#: the refault child: argv mode ("default" or "keep"), MiB, wait (s); prints both fills' GB/s
REFAULT = r"""
import json, sys, time
import numpy as np
from cgfem._allocator import keep_freed_memory
mode, mib, wait = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
if mode == "keep":
    keep_freed_memory()
n = mib * 2**20 // 8
rates = []
for k in range(2):
    if k:
        time.sleep(wait)
    tic = time.perf_counter()
    a = np.empty(n)
    a[:] = 1.0
    rates.append(mib * 2**20 / 1e9 / (time.perf_counter() - tic))
    del a
print(json.dumps(rates))
"""

#: the run child: ``cgfem run`` with freed memory kept whatever its estimate (argv[1] "kept") or
#: with glibc's default allocator ("default")
RUN = r"""
import sys
import cgfem.memory
import cgfem.run
if sys.argv[1] == "kept":
    cgfem.memory.KEEP_MEMORY_SHARE = float("inf")
else:
    cgfem.run.keep_freed_memory = lambda: False
from cgfem.cli import main
sys.exit(main(sys.argv[2:]))
"""


def refault(mode: str, mib: int, wait: float) -> tuple[float, float]:
    """The first and second fill rates (GB/s) of the refault child in ``mode``."""
    out = subprocess.run([sys.executable, "-c", REFAULT, mode, str(mib), str(wait)], capture_output=True,
                         text=True, check=True)
    first, second = json.loads(out.stdout)
    return first, second


def timed_child(argv: list[str], log: Path) -> tuple[float, float]:
    """(wall s, peak resident memory GB) of a child process on one thread, its stderr written
    to ``log``; ``RuntimeError`` with its last line if it fails."""
    tic = time.perf_counter()
    with open(log, "w") as err:
        proc = subprocess.Popen(argv, cwd=REPO, env=dict(os.environ, **dict.fromkeys(THREAD_COUNTS, "1")),
                                stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - tic
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        tail = (log.read_text().strip().splitlines() or [""])[-1]
        raise RuntimeError(f"{' '.join(argv[-8:])} failed ({code}): {tail}")
    return wall, usage.ru_maxrss * 1024 / 1e9


def run_pair(case: str, level: int, surface: str, order: int) -> dict:
    """The run with the allocator ``cgfem run`` sets and with glibc's default (module docstring)."""
    args = ["run", case, "--level", str(level), "--surface", surface, "--order", str(order)]
    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        summaries = {}
        for name in ("kept", "default"):
            folder, log = Path(tmp) / name, Path(tmp) / f"{name}.log"
            wall, peak = timed_child([sys.executable, "-c", RUN, name] + args + ["--out", str(folder)], log)
            if (KEPT_MEMORY_LOG in log.read_text()) != (name == "kept"):
                raise RuntimeError(f"the {name} run's log {'lacks' if name == 'kept' else 'has'} "
                                   f"{KEPT_MEMORY_LOG!r}")
            out[name] = {"wall_s": wall, "peak_gb": peak}
            summaries[name] = stable(json.loads((folder / "summary.json").read_text()))
        out["same_bits"] = summaries["kept"] == summaries["default"]
    out["speedup"] = out["default"]["wall_s"] / out["kept"]["wall_s"]
    out["peak_ratio"] = out["kept"]["peak_gb"] / out["default"]["peak_gb"]
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mb", type=int, default=600, help="the refault array (MiB)")
    parser.add_argument("--wait", type=float, default=8.0, help="between free and refill (s)")
    parser.add_argument("--case", default="config/cases/planar.yaml")
    parser.add_argument("--level", type=int, default=3)
    parser.add_argument("--surface", default="nurbs_fe")
    parser.add_argument("--order", type=int, default=1)
    parser.add_argument("--no-run", action="store_true", help="the refault figures only")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    if args.mb <= 0 or args.wait < 0:
        print("bench_allocator: --mb must be > 0 and --wait >= 0", file=sys.stderr)
        return 2
    if not args.no_run and not (REPO / args.case).is_file():
        print(f"bench_allocator: --case: no such file {args.case}", file=sys.stderr)
        return 2
    out: dict = {"mb": args.mb, "wait_s": args.wait}
    try:
        for mode in ("default", "keep"):
            first, second = refault(mode, args.mb, args.wait)
            out[f"refault_{mode}"] = {"first_gb_s": first, "second_gb_s": second}
            print(f"{mode:7s} allocator: {args.mb} MiB filled at {first:.2f} GB/s (new to the process), "
                  f"again {args.wait:g} s after freeing it at {second:.2f} GB/s")
        if not args.no_run:
            run = run_pair(args.case, args.level, args.surface, args.order)
            out["run"] = dict(run, case=args.case, level=args.level, surface=args.surface, order=args.order)
            print(f"{Path(args.case).stem} L{args.level} {args.surface} order {args.order}, one thread: "
                  f"{run['kept']['wall_s']:.1f} s, peak {run['kept']['peak_gb']:.2f} GB with freed memory kept; "
                  f"{run['default']['wall_s']:.1f} s, peak {run['default']['peak_gb']:.2f} GB with glibc's default: "
                  f"{run['speedup']:.2f}x the speed at {run['peak_ratio']:.2f}x the peak; "
                  f"summaries {'the same bits' if run['same_bits'] else 'DIFFERENT'}")
    except (RuntimeError, subprocess.CalledProcessError, OSError) as err:
        print(f"bench_allocator: {err}", file=sys.stderr)
        return 1
    if args.json:
        write_json_atomic(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
