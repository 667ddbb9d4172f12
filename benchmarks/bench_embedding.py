"""Quadrature build time and memory of a chain link (half torus R = 0.02, r = 0.005) at
levels 0-4, for both surface definitions.

    python benchmarks/bench_embedding.py [max_level]

h0 = 0.005 makes level 0 resemble the paper's coarsest link mesh (about 250 active nodes
here, 216 in the paper). Times exclude JIT compilation (a warm-up build runs first); memory
is the peak of Python/numpy allocations during a second, traced build (tracemalloc).
``fitted``: cut elements that kept the moment-fitted rule (no positive column rule).
The partition runs on one core; the column rules use numba's threads.
"""

from __future__ import annotations

import sys
import time
import tracemalloc

from cgfem.embedding.quadrature import embed, grid_for
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import HalfTorusSpec


def main(max_level: int = 4) -> None:
    solid = build_solid(HalfTorusSpec((0, 0, 0), (0, 0, 1), 0.02, 0.005, (0, 1, 0)))
    offset = (0.13, 0.29, 0.41)
    for surface in ("nurbs", "facets"):
        embed(solid, grid_for(solid, 0.005, 0, offset), surface)  # JIT warm-up
    print(f"{'surface':<7} level  nodes   cut  fitted  surface pts  volume pts  build s  points/s  peak MiB")
    for surface in ("nurbs", "facets"):
        for level in range(max_level + 1):
            grid = grid_for(solid, 0.005, level, offset)
            t0 = time.perf_counter()
            emb = embed(solid, grid, surface)
            dt = time.perf_counter() - t0
            del emb
            tracemalloc.start()  # a second build, traced (tracing slows it down)
            emb = embed(solid, grid, surface)
            peak = tracemalloc.get_traced_memory()[1] / 2**20
            tracemalloc.stop()
            counts = emb.counts()
            n_points = emb.surface.w.size + emb.volume.w.size
            print(f"{surface:<7} {level:>5} {counts['nodes']:>6} {counts['cut']:>5} {counts['fitted']:>7} "
                  f"{emb.surface.w.size:>12} "
                  f"{emb.volume.w.size:>11} {dt:8.2f} {n_points / dt:9.0f} {peak:9.1f}", flush=True)


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
