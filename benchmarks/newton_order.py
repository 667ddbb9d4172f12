"""Observed Newton convergence of finished runs, step by step, from their ``summary.json``.

For the first Newton solve of every step (the later outer passes start from modified Newton
and are linear by design) it prints the relative residuals of the last iterations, the
observed order ``q = log(r3/r2) / log(r2/r1)`` of the last three above round-off (1e-11 of
the first, as in the tests) and the contraction factors ``r_{k+1} / r_k`` and
``r_{k+1} / r_k^2``: superlinear convergence shows as contraction factors falling towards 0,
quadratic convergence as a bounded ``r_{k+1} / r_k^2`` (the order from three points is
exact only once that ratio has settled).

The residual is only a proxy for the error: the contact penalty next to nearly free sliding
makes ``r_{k+1} / r_k^2`` swing (chain2_steel level 1 facets: 16 then 94 in step 1), so the
order from residuals can read below 2 on a consistent tangent. ``tests/physics/test_newton_order.py``
measures the order on the error ``|u_k - u*|`` instead (each solve continued to round-off).

    python3 -m benchmarks.newton_order results/runs/chain2_steel/L1_facets results/runs/chain2_steel/L1_nurbs_fe
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from cgfem.solve.newton import observed_order

FLOOR = 1e-11


def report(folder: Path) -> list[float]:
    """Print one line per step of the run in ``folder``; return the observed orders."""
    summary = json.loads((folder / "summary.json").read_text())
    print(f"{folder}: {summary['status']}")
    orders = []
    for k, step in enumerate(summary["steps"], 1):
        first = step["pass_residuals"][0]
        rel = [r / first[0] for r in first if r > FLOOR * first[0]]
        q = observed_order(first, floor=FLOOR)
        orders.append(q)
        tail = rel[-4:]
        linear = [b / a for a, b in zip(tail, tail[1:])]
        quadratic = [b / a**2 for a, b in zip(tail, tail[1:])]
        print(f"  step {k} (load {step['load_factor']:.4g}): |r|/r0 " + " ".join(f"{r:.1e}" for r in tail)
              + f"  order {q:.2f}  r+/r " + " ".join(f"{c:.1e}" for c in linear)
              + "  r+/r^2 " + " ".join(f"{c:.1e}" for c in quadratic))
    return orders


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for arg in sys.argv[1:]:
        report(Path(arg))
