"""Throughput of the geometry kernels on the paper's torus (R = 0.02 m, r = 0.005 m).

Run ``python benchmarks/bench_geometry.py`` (with ``src`` on the path or the package
installed). Prints

- point-in-solid queries/s (``points_inside``, 10^5 points in the 10 %-inflated box);
- ray intersections/s (``ray_intersections``, 10^4 random rays);
- surface evaluations/s of ``NurbsSurface.evaluate`` against geomdl's ``evaluate_list``
  (a batch of 10^5 parameters) and ``evaluate_single`` (a loop of 10^4 single points; ours
  both through ``NurbsSurface.evaluate`` and through the numba kernel ``surface_point``), on
  the same torus surface in the same run, and the speed-ups.

Every timing is the best of a few repetitions after a warm-up call (JIT compilation
excluded). Timings use all numba threads (``NUMBA_NUM_THREADS`` to change that).
"""

from __future__ import annotations

import time

import numba
import numpy as np

from cgfem.geometry._nurbs_kernels import surface_point
from cgfem.geometry.builders import build_solid
from cgfem.geometry.bvh import SurfaceIndex
from cgfem.geometry.inside import points_inside
from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.query import ray_intersections
from cgfem.geometry.specs import TorusSpec

TORUS = TorusSpec(center=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), major_radius=0.02, minor_radius=0.005)
N_POINTS = 100_000
N_RAYS = 10_000
N_EVAL = 100_000
N_SINGLE = 10_000
REPEAT = 3


def best_time(fn, repeat: int = REPEAT) -> float:
    """Smallest wall time of ``repeat`` calls of ``fn`` (s)."""
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def geomdl_surface(surface: NurbsSurface):
    """The same surface as a geomdl ``NURBS.Surface`` (weighted control points)."""
    from geomdl import NURBS

    g = NURBS.Surface(normalize_kv=False)
    g.degree_u, g.degree_v = surface.degree
    g.set_ctrlpts(surface.control.reshape(-1, 4).tolist(), *surface.control.shape[:2])
    g.knotvector_u = surface.knots_u.tolist()
    g.knotvector_v = surface.knots_v.tolist()
    return g


def bench_queries(rng) -> None:
    solid = build_solid(TORUS)
    start = time.perf_counter()
    index = SurfaceIndex.build(solid)
    build = time.perf_counter() - start
    lo, hi = index.bounds
    pad = 0.1 * (hi - lo)
    points = rng.uniform(lo - pad, hi + pad, (N_POINTS, 3))
    origins = rng.uniform(lo - pad, hi + pad, (N_RAYS, 3))
    directions = rng.normal(size=(N_RAYS, 3))
    points_inside(index, points[:10])  # warm-up (JIT)
    ray_intersections(index, origins[:10], directions[:10])
    t_inside = best_time(lambda: points_inside(index, points))
    t_rays = best_time(lambda: ray_intersections(index, origins, directions))
    hits = ray_intersections(index, origins, directions)
    print(f"torus R={TORUS.major_radius} r={TORUS.minor_radius}: {index.n_leaves} Bezier leaves, "
          f"index built in {build * 1e3:.0f} ms, {numba.get_num_threads()} numba threads")
    print(f"  point-in-solid : {N_POINTS / t_inside:12,.0f} queries/s   ({N_POINTS} points, "
          f"{points_inside(index, points).mean():.1%} inside)")
    print(f"  ray hits       : {N_RAYS / t_rays:12,.0f} rays/s      ({N_RAYS} rays, "
          f"{hits.t.size / N_RAYS:.2f} hits per ray)")


def bench_evaluation(rng) -> None:
    surface = build_solid(TORUS).patches[0].surface
    g = geomdl_surface(surface)
    uv = rng.uniform(0.0, 1.0, (N_EVAL, 2))
    params = uv.tolist()
    surface.evaluate(uv[:10])  # warm-up (JIT)
    ours = surface.evaluate(uv)
    ref = np.array(g.evaluate_list(params[:1000]))
    assert np.abs(ours[:1000] - ref).max() < 1e-15, "cgfem and geomdl disagree"
    t_batch = best_time(lambda: surface.evaluate(uv))
    t_geomdl_batch = best_time(lambda: g.evaluate_list(params), repeat=1)
    single = uv[:N_SINGLE]
    single_params = [tuple(p) for p in single.tolist()]

    def ours_single():
        for row in single:
            surface.evaluate(row)

    def geomdl_single():
        for p in single_params:
            g.evaluate_single(p)

    p, q = surface.degree
    args = (p, q, surface.knots_u, surface.knots_v, surface.control)
    out = np.empty(3)

    def kernel_single():
        for u, v in single_params:
            surface_point(*args, u, v, out)

    kernel_single()  # warm-up (JIT)
    t_single = best_time(ours_single)
    t_kernel = best_time(kernel_single)
    t_geomdl_single = best_time(geomdl_single, repeat=1)
    print("surface evaluation (torus patch, degree (2, 2), 9 x 9 control points)")
    print(f"  batch  cgfem  evaluate       : {N_EVAL / t_batch:14,.0f} points/s")
    print(f"  batch  geomdl evaluate_list  : {N_EVAL / t_geomdl_batch:14,.0f} points/s"
          f"   -> cgfem {t_geomdl_batch / t_batch:8.0f} x faster")
    print(f"  single cgfem  evaluate(row)  : {N_SINGLE / t_single:14,.0f} points/s"
          f"   (Python wrapper: validation and allocation per call)")
    print(f"  single cgfem  surface_point  : {N_SINGLE / t_kernel:14,.0f} points/s"
          f"   (the numba kernel called from Python)")
    print(f"  single geomdl evaluate_single: {N_SINGLE / t_geomdl_single:14,.0f} points/s"
          f"   -> cgfem {t_geomdl_single / t_single:8.1f} x (wrapper), "
          f"{t_geomdl_single / t_kernel:.1f} x (kernel) faster")


def main() -> None:
    rng = np.random.default_rng(2024)
    bench_queries(rng)
    bench_evaluation(rng)


if __name__ == "__main__":
    main()
