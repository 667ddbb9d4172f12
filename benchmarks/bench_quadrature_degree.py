"""Build time and size of the quadrature for degree 2 (trilinear elements) against degree 4
(triquadratic) on a chain link (half torus R = 0.02, r = 0.005, h0 = 0.005, the grid of
``link_a`` in config/cases/chain2_steel.yaml) at levels 0-3.

    python3 -m benchmarks.bench_quadrature_degree [max_level] [surface ...]

Per degree and level: cut elements, those that kept the moment-fitted rule (``fitted``), the
exact surface rule's points, the volume points per cut element (mean and most: at most
(degree + 1)^3), the reduced boundary rule's points per (element, patch) (mean and most),
the wall and CPU seconds of ``embed`` and of the reduced boundary rule (``Embedding.boundary``,
built on first use), and the ratio of the degree-4 build to the degree-2 one. A warm-up build
of each degree runs first (JIT). The partition runs on one core; the column rules and the
recombination of the boundary use numba's threads, so CPU seconds may exceed wall seconds.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from cgfem.embedding.quadrature import CUT, embed, grid_for
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import HalfTorusSpec

H0 = 0.005
OFFSET = (0.13, 0.29, 0.41)
DEGREES = (2, 4)


def _timed(fn):
    """``fn()`` with its wall and CPU seconds."""
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def measure(solid, level: int, degree: int, surface: str) -> dict:
    """One build of the link's embedding and of its reduced boundary rule."""
    grid = grid_for(solid, H0, level, OFFSET)
    emb, wall, cpu = _timed(lambda: embed(solid, grid, surface, degree=degree))
    boundary, b_wall, b_cpu = _timed(lambda: emb.boundary)
    cut = np.flatnonzero(emb.status == CUT)
    per_cut = np.bincount(emb.volume.element, minlength=grid.n_elements)[cut]
    groups = np.unique(boundary.element * len(emb.patch_names) + boundary.patch, return_counts=True)[1]
    return dict(cut=cut.size, fitted=emb.fallback.size, surface=emb.surface.w.size,
                mean=per_cut.mean(), most=per_cut.max(), b_mean=groups.mean(), b_most=groups.max(),
                wall=wall, cpu=cpu, b_wall=b_wall, b_cpu=b_cpu)


def main(max_level: int = 3, *surfaces: str) -> None:
    solid = build_solid(HalfTorusSpec((0, 0, 0), (0, 0, 1), 0.02, 0.005, (0, 1, 0)))
    for surface in surfaces or ("nurbs",):
        for degree in DEGREES:  # JIT warm-up
            embed(solid, grid_for(solid, H0, 0, OFFSET), surface, degree=degree).boundary
        print(f"[{surface}] degree level   cut  fitted  surface pts  vol pts/cut (max)  bnd pts/group (max)"
              f"   embed wall/cpu s  boundary wall/cpu s")
        rows = {}
        for level in range(max_level + 1):
            for degree in DEGREES:
                r = rows[degree, level] = measure(solid, level, degree, surface)
                print(f"[{surface}] {degree:>6} {level:>5} {r['cut']:>5} {r['fitted']:>7} {r['surface']:>12} "
                      f"{r['mean']:>11.1f} ({r['most']:>3}) {r['b_mean']:>13.1f} ({r['b_most']:>3}) "
                      f"{r['wall']:>10.2f}/{r['cpu']:<7.2f} {r['b_wall']:>10.2f}/{r['b_cpu']:<7.2f}", flush=True)
            two, four = rows[2, level], rows[4, level]
            print(f"[{surface}]  ratio {level:>5}  degree 4 / degree 2: embed {four['wall'] / two['wall']:.1f}x wall, "
                  f"{four['cpu'] / two['cpu']:.1f}x cpu; boundary {four['b_wall'] / two['b_wall']:.1f}x wall, "
                  f"{four['b_cpu'] / two['b_cpu']:.1f}x cpu", flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    main(int(args[0]) if args else 3, *args[1:])
