"""Sweep of the NURBS-enhanced embedding: worst relative volume and area errors against the
closed forms for sphere, torus, half torus and cylinder with random rotated axes, at levels
0-3, each for N random grid offsets (default 20), plus offset 0.

    python benchmarks/validate_embedding.py [N] [max_level]

Prints one line per shape and level: worst |volume error|, worst |area error|, the mean
number of cut elements, the total number of cut elements that kept the moment-fitted rule
(no positive rule) over all offsets, the number of negative volume weights outside them
(must be 0) and the mean build time. Exit code 1 if an error exceeds 1e-8 or a positive
rule has a negative weight.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from cgfem.embedding.quadrature import embed, grid_for
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import CylinderSpec, HalfTorusSpec, SphereSpec, TorusSpec

R, r = 0.02, 0.005


def shapes(rng: np.random.Generator):
    def unit():
        v = rng.normal(size=3)
        return v / np.linalg.norm(v)

    axis = unit()
    keep = np.cross(axis, unit())
    keep /= np.linalg.norm(keep)
    c = tuple(rng.uniform(-1e-3, 1e-3, 3))
    return {
        "sphere": (SphereSpec(c, 0.011), 4 / 3 * math.pi * 0.011**3, 4 * math.pi * 0.011**2),
        "torus": (TorusSpec(c, tuple(axis), R, r), 2 * math.pi**2 * R * r * r, 4 * math.pi**2 * R * r),
        "half_torus": (HalfTorusSpec(c, tuple(axis), R, r, tuple(keep)), math.pi**2 * R * r * r,
                       2 * math.pi**2 * R * r + 2 * math.pi * r * r),
        "cylinder": (CylinderSpec(c, tuple(axis), 0.006, 0.021), math.pi * 0.006**2 * 0.021,
                     2 * math.pi * 0.006 * 0.021 + 2 * math.pi * 0.006**2),
    }


def main(n_offsets: int = 20, max_level: int = 3) -> int:
    rng = np.random.default_rng(2018)
    worst = 0.0
    print(f"{'shape':<11} level  max|dV/V|  max|dA/A|  cut elements  fitted  negative  s/build")
    negative_total = 0
    for name in ("sphere", "torus", "half_torus", "cylinder"):
        for level in range(max_level + 1):
            ev = ea = 0.0
            cut = []
            fitted = negative = 0
            t0 = time.perf_counter()
            offsets = [np.zeros(3)] + [rng.random(3) for _ in range(n_offsets)]
            for offset in offsets:
                spec, volume, area = shapes(rng)[name]
                solid = build_solid(spec)
                emb = embed(solid, grid_for(solid, 0.005, level, offset))
                ev = max(ev, abs(emb.volume.w.sum() / volume - 1))
                ea = max(ea, abs(emb.surface.w.sum() / area - 1))
                cut.append(emb.counts()["cut"])
                fitted += emb.fallback.size
                positive = ~np.isin(emb.volume.element, emb.fallback)
                negative += int(np.sum(emb.volume.w[positive] <= 0.0))
            dt = (time.perf_counter() - t0) / len(offsets)
            worst = max(worst, ev, ea)
            negative_total += negative
            print(f"{name:<11} {level:>5}  {ev:9.2e}  {ea:9.2e}  {int(np.mean(cut)):>12}  {fitted:>6}  "
                  f"{negative:>8}  {dt:7.2f}", flush=True)
    print(f"worst relative error {worst:.2e}")
    return 0 if worst <= 1e-8 and negative_total == 0 else 1


if __name__ == "__main__":
    args = [int(a) for a in sys.argv[1:]]
    sys.exit(main(*args))
