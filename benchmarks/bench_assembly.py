"""Assembly speed of H8 linear elasticity: cgfem against scikit-fem and NGSolve.

    python benchmarks/bench_assembly.py

Meshes: a unit cube of 32^3 elements (33^3 nodes, 107,811 dofs, no cut element) for all
three codes, and a cut torus (R = 0.02, r = 0.005, h0 = 0.005, level 3) for cgfem only.
Every variant runs in its own subprocess (clean memory peaks, clean thread settings) and
reports the best of 3 runs after one warm-up run (numba compiles or loads its cache on the
first call). "RSS+" is the peak resident memory growth of one run: VmHWM is reset through
/proc/self/clear_refs before the run and compared with VmRSS before it.

cgfem variants (numba threads 1 and 2):

- pattern: ``build_pattern`` (CSR structure, element scatter map, colours), once per mesh;
- linear: ``Elasticity.linear_stiffness_data`` + ``pattern.matrix`` (inside elements get
  one reference matrix, cut ones are integrated point by point);
- per-point: ``integrate_tangent`` over every colour with the constant elasticity tensor
  (the path of finite strain and of cut elements);
- Neo-Hookean: ``Elasticity.add`` with the Neo-Hookean model at a small random
  displacement (gradients, constitutive tangent, tangent matrix and internal force);
- first assembly: pattern + linear, what a new mesh costs (sum of the two best times).

Peers: scikit-fem ``asm(linear_elasticity)`` (2x2x2 Gauss; builds its COO/CSR matrix every
call, single thread) and NGSolve ``BilinearForm.Assemble`` (a fresh form: matrix graph +
values; and a second ``Assemble`` of the same form, which reuses the graph) with 1 and 2
threads. Ratios are elements/s of the row over elements/s of the peer (> 1: row faster);
torus rows are compared per element with the cube peers.

The machine is shared: the load average is printed at the start and the end, and
2-thread figures in particular move with the load.
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import resource
import subprocess
import sys
import time

import numpy as np
from benchmarks._memory import reset_peak, status_kib

N_CUBE = 32                      # elements per edge of the unit cube
E_MOD, NU = 1.0, 0.3             # material (the matrices scale linearly with E)
LAM = E_MOD * NU / ((1 + NU) * (1 - 2 * NU))
MU = E_MOD / (2 * (1 + NU))
#: gradient of the linear displacement field of the quadratic-form check
G_CHECK = np.array([[1.0e-3, 2.0e-4, -3.0e-4],
                    [5.0e-4, -2.0e-3, 1.0e-4],
                    [-4.0e-4, 3.0e-4, 1.5e-3]])
TORUS = dict(center=(0, 0, 0), axis=(0, 0, 1), major_radius=0.02, minor_radius=0.005)
TORUS_GRID = dict(h0=0.005, level=3, offset=(0.13, 0.29, 0.41))
REPEAT = 3


# -- measurement ------------------------------------------------------------------------------
PEAK_METHOD = {"exact": "VmHWM reset per run"}


def measure(fn, repeat: int = REPEAT, warmup: bool = True):
    """Best time (s) of ``repeat`` runs of ``fn`` after a warm-up, the process CPU time (s, all
    threads) of that run, the largest peak RSS growth (MiB) of a run, and the result of the
    last run."""
    if warmup:
        res = fn()
        del res
    best, cpu, growth, res = math.inf, 0.0, 0.0, None
    for _ in range(repeat):
        res = None
        gc.collect()
        rss0 = status_kib("VmRSS")
        exact = reset_peak()
        t0, c0 = time.perf_counter(), time.process_time()
        res = fn()
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        peak = status_kib("VmHWM") if exact else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        if not exact:
            PEAK_METHOD["exact"] = "ru_maxrss (not reset: upper bound)"
        if dt < best:
            best, cpu = dt, dc
        growth = max(growth, (peak - rss0) / 1024.0)
    return best, cpu, growth, res


def expected_quadratic_form(volume: float) -> float:
    """``u^T K u`` of ``u = G x``: ``volume * sigma : eps``."""
    eps = 0.5 * (G_CHECK + G_CHECK.T)
    sigma = LAM * np.trace(eps) * np.eye(3) + 2.0 * MU * eps
    return volume * float(np.sum(sigma * eps))


def rel(a: float, b: float) -> float:
    return abs(a - b) / abs(b)


# -- cgfem ----------------------------------------------------------------------------------------
def cube_space(n: int):
    """The full cube of n^3 elements on [0, 1]^3 and its 2x2x2 Gauss points."""
    from cgfem.embedding.grid import CartesianGrid
    from cgfem.fem.space import ElementPoints, Space

    grid = CartesianGrid(1.0 / n, (0.0, 0.0, 0.0), (n, n, n))
    elements = np.arange(grid.n_elements, dtype=np.int64)
    space = Space.of_elements(grid, elements, np.zeros(elements.size, bool))
    g = 1.0 / np.sqrt(3.0)
    gauss = np.array([[a, b, c] for a in (-g, g) for b in (-g, g) for c in (-g, g)])
    xi = np.tile(gauss, (elements.size, 1))
    x = np.repeat(space.centres(), 8, axis=0) + 0.5 * grid.h * xi
    w = np.full(xi.shape[0], (0.5 * grid.h) ** 3)
    offsets = np.arange(0, 8 * elements.size + 1, 8, dtype=np.int64)
    return space, ElementPoints(xi, x, w, offsets)


def our_cube_matrix(n: int):
    """Our linear stiffness (CSR) of the n^3 cube and its node coordinates."""
    from cgfem.fem._material_kernels import LINEAR_ELASTIC
    from cgfem.fem.assembly import build_pattern
    from cgfem.fem.elasticity import Elasticity

    space, points = cube_space(n)
    pattern = build_pattern(space)
    el = Elasticity(space, pattern, points, LINEAR_ELASTIC, MU, LAM)
    return pattern.matrix(el.linear_stiffness_data()), space.coordinates


def _profile(fn, lines: int) -> str:
    import cProfile
    import io
    import pstats

    prof = cProfile.Profile()
    prof.enable()
    fn()
    prof.disable()
    out = io.StringIO()
    pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(lines)
    text = out.getvalue()
    start = text.find("ncalls")
    return text[start:].rstrip() if start >= 0 else text


def ours(mesh: str) -> dict:
    import numba

    from cgfem.fem import _element_kernels as kern
    from cgfem.fem._material_kernels import LINEAR_ELASTIC, NEO_HOOKEAN, tangent_batch
    from cgfem.fem.assembly import build_pattern
    from cgfem.fem.elasticity import Elasticity

    out: dict = {"mesh": mesh}
    if mesh == "cube":
        t0 = time.perf_counter()
        space, points = cube_space(N_CUBE)
        out["setup_s"] = time.perf_counter() - t0
        volume = 1.0
    else:
        from cgfem.embedding.quadrature import embed, grid_for
        from cgfem.fem.space import Space
        from cgfem.geometry.builders import build_solid
        from cgfem.geometry.specs import TorusSpec

        solid = build_solid(TorusSpec(**TORUS))
        off = TORUS_GRID["offset"]
        embed(solid, grid_for(solid, TORUS_GRID["h0"], 1, off))  # JIT / cache warm-up
        t0 = time.perf_counter()
        emb = embed(solid, grid_for(solid, TORUS_GRID["h0"], TORUS_GRID["level"], off))
        out["embed_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        space = Space.from_embedding(emb)
        points = space.volume_points(emb)
        out["setup_s"] = time.perf_counter() - t0
        out["counts"] = emb.counts()
        volume = float(points.w.sum())
        out["volume_rule"] = volume
        out["volume_exact"] = 2.0 * math.pi**2 * TORUS["major_radius"] * TORUS["minor_radius"]**2
        del emb
    h = space.h
    out.update(dofs=space.n_dofs, elements=space.n_elements, cut=int(space.cut.sum()),
               points=int(points.w.size))

    numba.set_num_threads(1)
    out["pattern_s"], out["pattern_cpu"], out["pattern_mib"], pattern = measure(
        lambda: build_pattern(space))
    out["nnz"] = pattern.nnz
    out["scatter_mib"] = pattern.scatter.nbytes / 2**20
    out["colours"] = len(pattern.colours)

    A = tangent_batch(LINEAR_ELASTIC, np.zeros((1, 3, 3)), MU, LAM)[2]
    lin = Elasticity(space, pattern, points, LINEAR_ELASTIC, MU, LAM)
    neo = Elasticity(space, pattern, points, NEO_HOOKEAN, MU, LAM)
    u = 0.01 * h * np.random.default_rng(1).standard_normal(space.n_dofs)

    def linear():
        return pattern.matrix(lin.linear_stiffness_data())

    def per_point():
        data = pattern.zeros()
        for elements in pattern.colours:
            kern.integrate_tangent(*space.kernel_element, A, -1, points.xi, points.w, points.offsets, h, elements,
                                   pattern.scatter, data)
        return pattern.matrix(data)

    def neo_hookean(disp=u):
        r = np.zeros(space.n_dofs)
        data = pattern.zeros()
        neo.add(disp, r, data)
        return pattern.matrix(data)

    K_lin = K_pp = None
    out["runs"] = {}
    for threads in (1, 2):
        numba.set_num_threads(threads)
        runs = {"numba_threads": numba.get_num_threads()}
        runs["linear_s"], runs["linear_cpu"], runs["linear_mib"], K_lin = measure(linear)
        runs["per_point_s"], runs["per_point_cpu"], runs["per_point_mib"], K_pp = measure(per_point)
        runs["neo_s"], runs["neo_cpu"], runs["neo_mib"], _ = measure(neo_hookean)
        out["runs"][threads] = runs

    out["threading_layer"] = numba.threading_layer()
    # checks: both linear paths agree, u^T K u of a linear field, NH tangent at u = 0
    scale = np.abs(K_lin.data).max()
    out["linear_vs_per_point"] = float(np.abs(K_lin.data - K_pp.data).max() / scale)
    ulin = (space.coordinates @ G_CHECK.T).ravel()
    out["quad_form"] = float(ulin @ (K_lin @ ulin))
    out["quad_form_expected"] = expected_quadratic_form(volume)
    K_nh0 = neo_hookean(np.zeros(space.n_dofs))
    out["neo_at_zero_vs_linear"] = float(np.abs(K_nh0.data - K_lin.data).max() / scale)
    del K_pp, K_nh0

    if mesh == "cube":  # where the time goes
        numba.set_num_threads(1)
        out["profile_pattern"] = _profile(lambda: build_pattern(space), 6)
        out["profile_neo"] = _profile(neo_hookean, 6)
    return out


# -- peers ------------------------------------------------------------------------------------------
def _dense_perm_skfem(basis, mesh_p, n):
    """Our dof (3 * node + c) for every scikit-fem dof."""
    ijk = np.rint(mesh_p.T * n).astype(np.int64)          # (n_vertices, 3)
    node = (ijk[:, 0] * (n + 1) + ijk[:, 1]) * (n + 1) + ijk[:, 2]
    ours_of = np.empty(basis.N, np.int64)
    for c in range(3):
        ours_of[basis.nodal_dofs[c]] = 3 * node + c
    return ours_of


def skfem_worker() -> dict:
    try:
        import skfem
        from skfem import Basis, ElementHex1, ElementVector, MeshHex, asm
        from skfem.models.elasticity import linear_elasticity
    except ImportError as exc:
        return {"skipped": f"scikit-fem not importable ({exc}); pip install scikit-fem"}
    out = {"version": skfem.__version__}
    form = linear_elasticity(LAM, MU)

    def setup():
        mesh = MeshHex.init_tensor(*[np.linspace(0.0, 1.0, N_CUBE + 1)] * 3)
        return mesh, Basis(mesh, ElementVector(ElementHex1()), intorder=3)  # 2x2x2 Gauss

    out["setup_s"], _, _, (mesh, basis) = measure(setup, repeat=1, warmup=False)
    out["points_per_element"] = int(basis.X.shape[1])
    out["dofs"], out["elements"] = int(basis.N), int(mesh.nelements)
    out["asm_s"], out["asm_cpu"], out["asm_mib"], K = measure(lambda: asm(form, basis))
    out["nnz"] = int(K.nnz)
    ulin = np.empty(basis.N)
    for c in range(3):
        ulin[basis.nodal_dofs[c]] = (mesh.p.T @ G_CHECK.T)[:, c]
    out["quad_form"] = float(ulin @ (K @ ulin))
    out["quad_form_expected"] = expected_quadratic_form(1.0)
    del K
    # same matrix as ours on a 4^3 cube, entry by entry after renumbering, and its spectrum
    n = 4
    small = MeshHex.init_tensor(*[np.linspace(0.0, 1.0, n + 1)] * 3)
    sb = Basis(small, ElementVector(ElementHex1()), intorder=3)
    Ks = asm(form, sb).toarray()
    Ko, _ = our_cube_matrix(n)
    Ko = Ko.toarray()
    perm = _dense_perm_skfem(sb, small.p, n)
    Kp = np.empty_like(Ko)
    Kp[np.ix_(perm, perm)] = Ks
    out["small_entry_diff"] = float(np.abs(Kp - Ko).max() / np.abs(Ko).max())
    ev_s, ev_o = np.linalg.eigvalsh(Ks), np.linalg.eigvalsh(Ko)
    out["small_eig_diff"] = float(np.abs(ev_s - ev_o).max() / ev_o.max())
    return out


def ngsolve_worker(threads: int) -> dict:
    try:
        import ngsolve
        from ngsolve.meshes import MakeStructured3DMesh
    except Exception as exc:  # noqa: BLE001 - any import failure means: skip
        return {"skipped": f"ngsolve not importable ({type(exc).__name__}: {exc}); "
                           "pip install ngsolve"}
    out = {"version": ngsolve.__version__}
    os_threads_outside = len(os.listdir("/proc/self/task"))

    def form(V):
        u, v = V.TnT()
        eps_u, eps_v = ngsolve.Sym(ngsolve.Grad(u)), ngsolve.Sym(ngsolve.Grad(v))
        a = ngsolve.BilinearForm(V)
        a += (2.0 * MU * ngsolve.InnerProduct(eps_u, eps_v)
              + LAM * ngsolve.Trace(eps_u) * ngsolve.Trace(eps_v)) * ngsolve.dx
        return a

    mesh = MakeStructured3DMesh(hexes=True, nx=N_CUBE, ny=N_CUBE, nz=N_CUBE)
    V = ngsolve.VectorH1(mesh, order=1)
    out["dofs"], out["elements"] = int(V.ndof), int(mesh.ne)
    ngsolve.SetNumThreads(threads)
    with ngsolve.TaskManager():
        out["ngsolve_threads"] = int(ngsolve.GetNumThreads())
        out["os_threads_added"] = len(os.listdir("/proc/self/task")) - os_threads_outside

        def fresh():
            a = form(V)
            a.Assemble()
            return a

        out["fresh_s"], out["fresh_cpu"], out["fresh_mib"], a = measure(fresh)
        out["reassemble_s"], out["reassemble_cpu"], out["reassemble_mib"], _ = measure(
            lambda: a.Assemble())
        out["nze"] = int(a.mat.nze)
        gf = ngsolve.GridFunction(V)
        gf.Set(ngsolve.CoefficientFunction(tuple(
            sum(G_CHECK[i, j] * (ngsolve.x, ngsolve.y, ngsolve.z)[j] for j in range(3))
            for i in range(3))))
        Ku = gf.vec.CreateVector()
        Ku.data = a.mat * gf.vec
        out["quad_form"] = float(ngsolve.InnerProduct(Ku, gf.vec))
        out["quad_form_expected"] = expected_quadratic_form(1.0)
        # spectrum of the 4^3 cube against ours
        small = MakeStructured3DMesh(hexes=True, nx=4, ny=4, nz=4)
        Vs = ngsolve.VectorH1(small, order=1)
        s = form(Vs)
        s.Assemble()
        rows, cols, vals = s.mat.COO()
        Ks = np.zeros((Vs.ndof, Vs.ndof))
        np.add.at(Ks, (np.asarray(rows), np.asarray(cols)), np.asarray(vals))
    Ko = our_cube_matrix(4)[0].toarray()
    ev_s, ev_o = np.linalg.eigvalsh(Ks), np.linalg.eigvalsh(Ko)
    out["small_eig_diff"] = float(np.abs(ev_s - ev_o).max() / ev_o.max())
    return out


WORKERS = {
    "ours-cube": lambda: ours("cube"),
    "ours-torus": lambda: ours("torus"),
    "skfem": skfem_worker,
    "ngsolve-1": lambda: ngsolve_worker(1),
    "ngsolve-2": lambda: ngsolve_worker(2),
}


# -- driver ------------------------------------------------------------------------------------------
def run_worker(name: str, timeout: float = 400.0) -> dict:
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "benchmarks.bench_assembly", "--worker", name],
                              capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"skipped": f"timed out after {timeout:.0f} s"}
    wall = time.perf_counter() - t0
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            res = json.loads(line[7:])
            res["wall_s"] = wall
            return res
    tail = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-6:])
    return {"skipped": f"worker failed (exit {proc.returncode}):\n{tail}"}


def _load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def main() -> None:
    import numba
    import scipy

    t_start = time.perf_counter()
    print(f"assembly benchmark: H8 linear elasticity, E = {E_MOD}, nu = {NU}; best of {REPEAT} "
          f"after 1 warm-up; cores {os.cpu_count()}; load average {_load()}")
    print(f"numpy {np.__version__}, scipy {scipy.__version__}, numba {numba.__version__} "
          f"(threading layer config '{numba.config.THREADING_LAYER}', "
          f"NUMBA_NUM_THREADS {numba.config.NUMBA_NUM_THREADS})")
    res = {}
    for name in WORKERS:
        print(f"  running {name} ...", flush=True)
        res[name] = run_worker(name)
    print()

    # ---- details
    cube, torus, skf = res["ours-cube"], res["ours-torus"], res["skfem"]
    ng = {1: res["ngsolve-1"], 2: res["ngsolve-2"]}
    for key, r in res.items():
        if "skipped" in r:
            print(f"{key}: SKIPPED - {r['skipped']}")
    if "skipped" not in cube:
        print(f"cube (cgfem): {cube['elements']} elements, {cube['dofs']} dofs, nnz {cube['nnz']}, "
              f"{cube['colours']} colours, scatter map {cube['scatter_mib']:.0f} MiB, numba threading "
              f"layer {cube['threading_layer']}; "
              f"space + Gauss points {cube['setup_s']:.2f} s")
    if "skipped" not in torus:
        c = torus["counts"]
        print(f"torus (cgfem, level {TORUS_GRID['level']}): embedding build {torus['embed_s']:.2f} s "
              f"(single run, not part of assembly), Space + volume points {torus['setup_s']:.2f} s; "
              f"{torus['elements']} active elements ({c['inside']} inside, {c['cut']} cut), "
              f"{torus['dofs']} dofs, {torus['points']} volume points, nnz {torus['nnz']}, "
              f"scatter map {torus['scatter_mib']:.0f} MiB")
    if "skipped" not in skf:
        print(f"scikit-fem {skf['version']}: {skf['elements']} elements, {skf['dofs']} dofs, "
              f"nnz {skf['nnz']}, {skf['points_per_element']} points/element; mesh + Basis "
              f"{skf['setup_s']:.2f} s (not in the asm time)")
    for t, r in ng.items():
        if "skipped" not in r:
            print(f"NGSolve {r['version']} requested {t} thread(s): GetNumThreads() = "
                  f"{r['ngsolve_threads']}, OS threads added by TaskManager = {r['os_threads_added']}; "
                  f"{r['elements']} elements, {r['dofs']} dofs, nze {r['nze']}")
    print()

    # ---- table
    rows = []  # (variant, threads, dofs, elements, wall s, cpu s, MiB)
    for label, r in (("cube", cube), ("torus", torus)):
        if "skipped" in r:
            continue
        d, e = r["dofs"], r["elements"]
        rows.append((f"cgfem {label}: pattern (once per mesh)", "numpy", d, e,
                     r["pattern_s"], r["pattern_cpu"], r["pattern_mib"]))
        for t in ("1", "2"):
            run = r["runs"][t]
            rows.append((f"cgfem {label}: linear values", t, d, e, run["linear_s"], run["linear_cpu"],
                         run["linear_mib"]))
            rows.append((f"cgfem {label}: first assembly = pattern + linear", t, d, e,
                         r["pattern_s"] + run["linear_s"], r["pattern_cpu"] + run["linear_cpu"],
                         max(r["pattern_mib"], run["linear_mib"])))
            rows.append((f"cgfem {label}: per-point tangent kernel", t, d, e, run["per_point_s"],
                         run["per_point_cpu"], run["per_point_mib"]))
            rows.append((f"cgfem {label}: Neo-Hookean add (force + tangent)", t, d, e, run["neo_s"],
                         run["neo_cpu"], run["neo_mib"]))
    if "skipped" not in skf:
        rows.append(("scikit-fem cube: asm", "1", skf["dofs"], skf["elements"], skf["asm_s"],
                     skf["asm_cpu"], skf["asm_mib"]))
    for t, r in ng.items():
        if "skipped" not in r:
            thr = str(r["ngsolve_threads"])
            rows.append(("NGSolve cube: fresh form + Assemble", thr, r["dofs"], r["elements"],
                         r["fresh_s"], r["fresh_cpu"], r["fresh_mib"]))
            rows.append(("NGSolve cube: re-Assemble (graph reused)", thr, r["dofs"], r["elements"],
                         r["reassemble_s"], r["reassemble_cpu"], r["reassemble_mib"]))
    rate_skf = skf["elements"] / skf["asm_s"] if "skipped" not in skf else None
    ng_ref = ng[2] if "skipped" not in ng[2] else None
    rate_ng = ng_ref["elements"] / ng_ref["fresh_s"] if ng_ref else None
    print("x skfem = elements/s over scikit-fem asm; x NGSolve = elements/s over NGSolve fresh form "
          "+ Assemble, 2 threads (> 1: faster)")
    head = (f"{'variant':<50} {'thr':>5} {'DOFs':>7} {'elements':>8} {'time s':>7} {'CPU s':>6} "
            f"{'elements/s':>10} {'x skfem':>8} {'x NGSolve':>9} {'RSS+ MiB':>8}")
    print(head)
    print("-" * len(head))
    for variant, thr, d, e, s, cpu, mib in rows:
        rate = e / s
        xs = f"{rate / rate_skf:8.2f}" if rate_skf else f"{'n/a':>8}"
        xn = f"{rate / rate_ng:9.2f}" if rate_ng else f"{'n/a':>9}"
        print(f"{variant:<50} {thr:>5} {d:>7} {e:>8} {s:7.3f} {cpu:6.2f} {rate:10.3e} {xs} {xn} "
              f"{mib:8.1f}")
    print("(thr: numba / NGSolve threads; CPU s: process CPU time of the best run, all threads - "
          "CPU s < thr x time s means the threads did not get their cores; RSS+: "
          f"{', '.join(sorted({r.get('peak_method', '?') for r in res.values() if 'skipped' not in r}))}"
          ")")
    two = [cpu / s for _, thr, _, _, s, cpu, _ in rows if thr == "2" and s > 0.1]
    if two and max(two) < 1.3:
        print(f"WARNING: no 2-thread row used much more than one core (CPU s / time s <= "
              f"{max(two):.2f}): the machine is busy, 2-thread figures here are single-core ones")
    print()

    # ---- targets
    if "skipped" not in cube:
        print("targets (same run, cube 32^3):")
        runs = cube["runs"]
        if rate_skf:
            for t in ("1", "2"):
                v, p = runs[t]["linear_s"], cube["pattern_s"]
                print(f"  vs scikit-fem asm (target >= 15x), {t} numba thread(s): linear values "
                      f"{skf['asm_s'] / v:6.1f}x {'PASS' if skf['asm_s'] / v >= 15 else 'FAIL'}; "
                      f"first assembly (pattern + values) {skf['asm_s'] / (p + v):6.1f}x "
                      f"{'PASS' if skf['asm_s'] / (p + v) >= 15 else 'FAIL'}; per-point "
                      f"{skf['asm_s'] / runs[t]['per_point_s']:6.1f}x; Neo-Hookean "
                      f"{skf['asm_s'] / runs[t]['neo_s']:6.1f}x")
        for t in (1, 2):
            r = ng[t]
            if "skipped" in r:
                print(f"  vs NGSolve {t} thread(s): skipped")
                continue
            run = runs[str(t)]
            first = cube["pattern_s"] + run["linear_s"]
            print(f"  vs NGSolve, {t} thread(s) each (target >= 1x): linear values vs re-Assemble "
                  f"{r['reassemble_s'] / run['linear_s']:5.2f}x "
                  f"{'PASS' if r['reassemble_s'] >= run['linear_s'] else 'FAIL'}; first assembly vs "
                  f"fresh form {r['fresh_s'] / first:5.2f}x "
                  f"{'PASS' if r['fresh_s'] >= first else 'FAIL'}"
                  f"; per-point vs fresh {r['fresh_s'] / run['per_point_s']:5.2f}x; Neo-Hookean vs "
                  f"fresh {r['fresh_s'] / run['neo_s']:5.2f}x")
        print()
        print("where the time goes (cube, 1 numba thread):")
        print(f"  pattern {cube['pattern_s']:.3f} s vs linear values {runs['1']['linear_s']:.3f} s: "
              f"the pattern is {cube['pattern_s'] / (cube['pattern_s'] + runs['1']['linear_s']):.0%} "
              f"of a first assembly")
        print("  cProfile of build_pattern (tottime):")
        print("\n".join("    " + ln for ln in cube["profile_pattern"].splitlines()))
        print("  cProfile of one Neo-Hookean add (tottime):")
        print("\n".join("    " + ln for ln in cube["profile_neo"].splitlines()))
        print()

    # ---- checks
    print("checks:")
    for label, r in (("cube", cube), ("torus", torus)):
        if "skipped" in r:
            continue
        print(f"  cgfem {label}: u^T K u of u = G x {r['quad_form']:.9e}, volume * sigma:eps "
              f"{r['quad_form_expected']:.9e}, rel. diff "
              f"{rel(r['quad_form'], r['quad_form_expected']):.1e}; "
              f"reference vs per-point data {r['linear_vs_per_point']:.1e}; Neo-Hookean tangent at "
              f"u = 0 vs linear {r['neo_at_zero_vs_linear']:.1e}")
    if "skipped" not in torus:
        print(f"  torus volume: rule {torus['volume_rule']:.9e}, exact {torus['volume_exact']:.9e}, "
              f"rel. diff {rel(torus['volume_rule'], torus['volume_exact']):.1e}")
    if "skipped" not in skf:
        print(f"  scikit-fem cube: u^T K u {skf['quad_form']:.9e} (rel. diff "
              f"{rel(skf['quad_form'], skf['quad_form_expected']):.1e}); 4^3 cube vs cgfem after "
              f"renumbering: max entry diff {skf['small_entry_diff']:.1e}, sorted eigenvalues "
              f"{skf['small_eig_diff']:.1e} (relative to the max)")
    for t, r in ng.items():
        if "skipped" not in r:
            print(f"  NGSolve cube ({t} thr): u^T K u {r['quad_form']:.9e} (rel. diff "
                  f"{rel(r['quad_form'], r['quad_form_expected']):.1e}); 4^3 cube sorted eigenvalues "
                  f"vs cgfem {r['small_eig_diff']:.1e}")
    if "skipped" not in cube and "skipped" not in skf:
        print(f"  nnz: cgfem {cube['nnz']}, scikit-fem {skf['nnz']}"
              + (f", NGSolve {ng[2]['nze']}" if "skipped" not in ng[2] else ""))
    print()
    print(f"total {time.perf_counter() - t_start:.0f} s; load average at the end {_load()}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worker", choices=sorted(WORKERS), help="run one variant, print JSON")
    args = parser.parse_args()
    if args.worker:
        result = WORKERS[args.worker]()
        result["peak_method"] = PEAK_METHOD["exact"]
        print("RESULT " + json.dumps(result))
    else:
        main()
