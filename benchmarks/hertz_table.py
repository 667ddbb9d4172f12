"""Hertz line contact (half cylinder on a block, plane strain): half-width a and peak
pressure p0 against the closed form, per level and surface definition, with run times.

The case and the measurement are those of ``tests/test_contact_hertz.py`` (imported from
there). Usage: ``python benchmarks/hertz_table.py [--levels 0 1 2 3] [--out DIR]``.
Columns: P (N/m, measured contact load), a and p0 (fitted, see the test's docstring) and
their relative errors, p_max (largest single |lambda_N|) relative to p0, Newton iterations
of the last step, steps (load cut-backs add steps), wall time (s).

``--offsets N`` repeats every run with N further offsets of the cylinder's grid, drawn from
``numpy.random.default_rng(7)`` (column ``offset``): how much of a definition's error is where
the grid happens to lie. A run without contact force (no load: facets' coarse chords may not
reach the block) is printed as such.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_contact_hertz import H0, SURFACES, solve  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--offsets", type=int, default=0, help="further random offsets of the cylinder's grid")
    parser.add_argument("--out", type=Path, default=None, help="keep the runs here (default: a temporary folder)")
    args = parser.parse_args()
    base = args.out or Path(tempfile.mkdtemp(prefix="hertz_"))
    offsets = [None] + [tuple(o) for o in np.random.default_rng(7).uniform(0.0, 1.0, (args.offsets, 3))]
    print(f"h0 = {H0}; runs in {base}")
    print(f"{'L':>2} {'offset':17} {'surface':9} {'status':10} {'P':>10} {'a':>8} {'a_ex':>8} {'err_a':>7} "
          f"{'p0':>10} {'p0_ex':>10} {'err_p0':>7} {'pmax/p0':>7} {'newton':>6} {'steps':>5} {'time':>7}")
    for level in args.levels:
        for k, offset in enumerate(offsets):
            shown = "default" if offset is None else " ".join(f"{o:.2f}" for o in offset)
            for surface in SURFACES:
                start = time.perf_counter()
                try:
                    r = solve(level, surface, base / f"{surface}_{level}_{k}", offset)
                except ZeroDivisionError:
                    print(f"{level:>2} {shown:17} {surface:9} no contact force", flush=True)
                    continue
                wall = time.perf_counter() - start
                steps = r.summary["steps"]
                print(f"{level:>2} {shown:17} {surface:9} {r.status:10} {r.load:10.4g} {r.a:8.4f} {r.a_exact:8.4f} "
                      f"{100 * r.error_a:+6.1f}% {r.p0:10.4g} {r.p0_exact:10.4g} {100 * r.error_p0:+6.1f}% "
                      f"{r.p_max / r.p0_exact:7.2f} {len(steps[-1]['newton_residuals']):6d} {len(steps):5d} "
                      f"{wall:7.1f}", flush=True)


if __name__ == "__main__":
    main()
