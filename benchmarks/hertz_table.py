"""Hertz line contact (half cylinder on a block, plane strain): half-width a and peak
pressure p0 against the closed form and the converged reference, per level and surface
definition, with run times.

The setups and the measurement are those of ``tests/hertz_setup.py`` (``--setup equal``:
``tests/physics/test_contact_hertz.py``; ``--setup indenter``: ``tests/physics/test_contact_hertz_indenter.py``).
Usage: ``python benchmarks/hertz_table.py [--setup equal|indenter] [--levels 0 1 2 3] [--out DIR]``.

Columns: P (N/m, measured contact load) and its error against the reference's load; a and p0
(second-moment half-width, fitted peak) and their errors against Hertz at the run's own load
(``own``: the contact's shape), against Hertz at the reference's load (``Hz``: what the
imposed approach produces) and against the reference (``ref``); p_max (largest single
|lambda_N|) over Hertz's p0 at the run's load; Newton iterations of the last step, steps
(load cut-backs add steps), wall time (s).

``--offsets N`` repeats every run with N further offsets of the cylinder's grid, drawn from
``numpy.random.default_rng(7)`` (column ``offset``): how much of a definition's error is where
the grid happens to lie. A run without contact force (no load: facets' coarse chords may not
reach the block) is printed as such.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from tests.support.hertz_setup import EQUAL, INDENTER, SURFACES, solve

SETUPS = {"equal": EQUAL, "indenter": INDENTER}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--setup", choices=sorted(SETUPS), default="equal")
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--offsets", type=int, default=0, help="further random offsets of the cylinder's grid")
    parser.add_argument("--out", type=Path, default=None, help="keep the runs here (default: a temporary folder)")
    args = parser.parse_args()
    setup = SETUPS[args.setup]
    base = args.out or Path(tempfile.mkdtemp(prefix="hertz_"))
    offsets = [None] + [tuple(o) for o in np.random.default_rng(7).uniform(0.0, 1.0, (args.offsets, 3))]
    print(f"{args.setup}: {setup}\nruns in {base}; errors in %")
    print(f"{'L':>2} {'offset':17} {'surface':9} {'status':10} {'P':>10} {'P ref':>6} {'a':>8} {'own':>6} {'Hz':>6} "
          f"{'ref':>6} {'p0':>10} {'own':>6} {'Hz':>6} {'ref':>6} {'pmax/p0':>7} {'newton':>6} {'steps':>5} {'time':>7}")
    for level in args.levels:
        for k, offset in enumerate(offsets):
            shown = "default" if offset is None else " ".join(f"{o:.2f}" for o in offset)
            for surface in SURFACES:
                start = time.perf_counter()
                try:
                    r = solve(setup, level, surface, base / f"{surface}_{level}_{k}", offset)
                except ZeroDivisionError:
                    print(f"{level:>2} {shown:17} {surface:9} no contact force", flush=True)
                    continue
                wall = time.perf_counter() - start
                steps = r.summary["steps"]
                (ah, ph), (ar, pr) = r.error_vs_hertz(), r.error_vs_reference()
                print(f"{level:>2} {shown:17} {surface:9} {r.status:10} {r.load:10.4g} "
                      f"{100 * (r.load / setup.reference.load - 1):+6.1f} {r.a:8.4f} {100 * r.error_a:+6.1f} "
                      f"{100 * ah:+6.1f} {100 * ar:+6.1f} {r.p0:10.4g} {100 * r.error_p0:+6.1f} {100 * ph:+6.1f} "
                      f"{100 * pr:+6.1f} {r.p_max / r.p0_exact:7.2f} {len(steps[-1]['newton_residuals']):6d} "
                      f"{len(steps):5d} {wall:7.1f}", flush=True)


if __name__ == "__main__":
    main()
