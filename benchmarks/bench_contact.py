"""Contact benchmarks of issue 11 on ``config/cases/chain2_steel.yaml`` (two Neo-Hookean
half-torus links; link_b's tube is the slave, link_a's tube the master).

    python3 -m benchmarks.bench_contact                       # all three parts
    python3 -m benchmarks.bench_contact --quick               # under a minute
    python3 -m benchmarks.bench_contact --parts search --points 100000 --search-level 1
    python3 -m benchmarks.bench_contact --parts iteration --levels 1 2 3
    python3 -m benchmarks.bench_contact --parts iteration --orders 1 2 --levels 0 1

1. **search**: ``--points`` rays against link_a's tube embedded at ``--search-level``,
   deformed by a smooth random displacement field (amplitude 0.2 h). The rays come from
   points of a surface facing the master: each starts at a known master point ``x2``, moved
   off it by a gap ``g0`` uniform in ``[-h/2, h/2]`` along a slave normal tilted up to 10
   degrees from the master's, so ``x2`` is a hit at ``g0``. ``NurbsFeSurface.search`` (k-d
   tree seeded) against the brute force of ``_search_peer.py`` (every ray against every
   seed), run on the first ``--brute`` rays and scaled linearly to all of them; both must
   find the same hits. Then the per-point cost of ``FacetSurface.search`` (the same rays
   against the master's marching-cubes facets at the same level) against the NURBS+FE one.
2. **iteration**: per element order (``--orders``), level and surface definition the system
   of ``cgfem run`` (``build_bodies`` + ``build_pairs`` + ``System``) at a prescribed state:
   link_b moved by h/2 towards link_a (a penetration of h/2 at the contact point) plus a
   smooth random field of amplitude 0.01 h on both links, ``p_N = 0`` frozen (the first
   outer pass of a step). Timed, best of ``--repeat`` after one warm-up: the bulk residual +
   tangent of the bodies (``BodyModel.assemble`` and the block-diagonal stacking), the
   contact residual + tangent (``ContactSet.add``; of it the search alone,
   ``ContactPair.search``; after the warm-up the previous pairing is known, as from the
   second Newton iterate on), adding the contact block to the matrix, one linear solve
   (factorization + solve, backend ``auto``) and the SPR recovery of every body.
3. **run**: one ``cgfem run`` of chain2_steel (``nurbs_fe``, 1 step, a fifth of the pull)
   at ``--run-level`` in a fresh process, its time split by wrapping library functions
   with timers (exclusive times: a timed function called inside another is not counted
   twice).

Every level / part runs in its own process (clean memory peaks). The machine is shared:
the load average is printed at the start and at the end of every part.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "config" / "cases" / "chain2_steel.yaml"
SEED = 20240611


def source_state() -> str:
    """Which contact search is measured: the commit, and whether the working tree's
    ``contact/`` differs from it (another engineer may be editing it), with a short hash."""
    import hashlib

    def git(*a):
        return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    files = sorted((ROOT / "src" / "cgfem" / "contact").glob("*.py"))
    digest = hashlib.sha1(b"".join(f.read_bytes() for f in files)).hexdigest()[:10]
    dirty = git("status", "--porcelain", "--", "src/cgfem/contact")
    state = "modified in the working tree: " + ", ".join(l.split(maxsplit=1)[1] for l in dirty.splitlines()) if dirty else "clean"
    return f"commit {git('rev-parse', '--short', 'HEAD')}, src/cgfem/contact {state} (sha1 of its *.py {digest})"


def load() -> str:
    return ", ".join(f"{x:.1f}" for x in os.getloadavg())


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def smooth_field(x: np.ndarray, amplitude: float, wavelength: float, seed: int) -> np.ndarray:
    """A smooth random vector field at points ``x`` (n, 3): per component a sum of three
    plane waves of the given wavelength, random directions and phases; returns (n, 3)."""
    rng = np.random.default_rng(seed)
    u = np.zeros_like(x)
    for c in range(3):
        for _ in range(3):
            k = rng.normal(size=3)
            k *= 2.0 * np.pi / (wavelength * np.linalg.norm(k))
            u[:, c] += np.sin(x @ k + rng.uniform(0.0, 2.0 * np.pi)) / 3.0
    return amplitude * u


def best_of(fn, repeat: int):
    """Best wall time (s) of ``repeat`` calls of ``fn`` and the last result."""
    best, res = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = fn()
        best = min(best, time.perf_counter() - t0)
    return best, res


# -- 1. search ---------------------------------------------------------------------------------
def master_surfaces(level: int):
    """link_a's tube at ``level`` as NURBS+FE and as facet master surfaces (as ``build_pair``
    builds them); returns ``(nurbs, nurbs_seeds, facets, solid, tube_id)``."""
    from cgfem.case.load import load_case
    from cgfem.contact.build import patch_ids
    from cgfem.contact.surfaces import FacetSurface, NurbsFeSurface
    from cgfem.fem.space import Space
    from cgfem.geometry.builders import build_solid
    from cgfem.run import embed_body

    body = next(b for b in load_case(CASE).bodies if b.name == "link_a")
    solid = build_solid(body.geometry)
    ids = patch_ids(tuple(p.name for p in solid.patches), ("tube",))
    emb = embed_body(solid, body, level, "nurbs_fe")
    nurbs = NurbsFeSurface(solid, Space.from_embedding(emb), emb.surface, ids)
    keep = np.isin(emb.surface.patch, ids)
    seeds = (emb.surface.patch[keep], emb.surface.uv[keep], emb.surface.x[keep])
    emb_f = embed_body(solid, body, level, "facets")
    fac = emb_f.facets
    facets = FacetSurface(Space.from_embedding(emb_f), fac.triangles, fac.element, np.isin(fac.patch, ids))
    return nurbs, seeds, facets, solid, int(ids[0])


def search_rays(nurbs, u: np.ndarray, tube: int, n: int, seed: int):
    """``n`` rays facing the master (module docstring): ``x1, n1`` (n, 3) and the gap ``g0``
    (n,) at which each meets its master point."""
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0.02, 0.98, (n, 2))
    mp = nurbs.evaluate(u, np.full(n, tube), theta, second=False)
    tilt = rng.normal(size=(n, 3))
    tilt -= np.einsum("pk,pk->p", tilt, mp.normal)[:, None] * mp.normal
    tilt *= (np.tan(np.radians(10.0)) * rng.uniform(0.0, 1.0, n) / np.linalg.norm(tilt, axis=1))[:, None]
    n1 = -(mp.normal + tilt)
    n1 /= np.linalg.norm(n1, axis=1)[:, None]
    g0 = rng.uniform(-0.5, 0.5, n) * nurbs.h
    return mp.x - g0[:, None] * n1, n1, g0


def part_search(level: int, n_points: int, n_brute: int) -> dict:
    from scipy.spatial import cKDTree

    from benchmarks._search_peer import brute_force_search
    from cgfem.contact.pair import MAX_GAP_H

    tic = time.perf_counter()
    nurbs, (seed_piece, seed_theta, seed_x), facets, solid, tube = master_surfaces(level)
    setup = time.perf_counter() - tic
    h = nurbs.h
    u_n = smooth_field(nurbs.space.coordinates, 0.2 * h, 4.0 * h, SEED).ravel()
    u_f = smooth_field(facets.space.coordinates, 0.2 * h, 4.0 * h, SEED).ravel()
    x1, n1, g0 = search_rays(nurbs, u_n, tube, n_points, SEED + 1)
    max_gap = MAX_GAP_H * h
    # warm-up (numba compilation or cache loading) on a few rays
    nurbs.search(u_n, x1[:200], n1[:200], max_gap)
    facets.search(u_f, x1[:200], n1[:200], max_gap)
    t_lib, hits = best_of(lambda: nurbs.search(u_n, x1, n1, max_gap), 1)
    t_warm, _ = best_of(lambda: nurbs.search(u_n, x1, n1, max_gap, hits), 1)
    t_fac, fhits = best_of(lambda: facets.search(u_f, x1, n1, max_gap), 1)
    # brute force on the first n_brute rays; spacing as the library defines it (setup, untimed)
    spacing = float(cKDTree(seed_x).query(seed_x, k=2)[0][:, 1].max())
    domains = np.array([p.surface.domain for p in solid.patches], float)
    sub = slice(0, n_brute)
    t_brute, (b_found, _, _, b_g) = best_of(
        lambda: brute_force_search(nurbs, domains, u_n, seed_piece, seed_theta, spacing, x1[sub], n1[sub],
                                   max_gap), 1)
    lib_found, lib_g = hits.found[sub], hits.g[sub]
    both = lib_found & b_found
    same = both & (np.abs(lib_g - b_g) <= 1e-8 * h)
    exact = hits.found & (np.abs(hits.g - g0) <= 1e-8 * h)
    return {"level": level, "h": h, "points": n_points, "seeds": int(seed_piece.size),
            "triangles": int(facets.candidates.size), "setup_s": setup,
            "lib_s": t_lib, "warm_s": t_warm, "facets_s": t_fac,
            "lib_found": int(hits.found.sum()), "lib_exact": int(exact.sum()),
            "facets_found": int(fhits.found.sum()),
            "facets_gap_err": float(np.max(np.abs(fhits.g - g0)[fhits.found], initial=0.0)),
            "brute_rays": n_brute, "brute_s": t_brute, "brute_scaled_s": t_brute * n_points / n_brute,
            "sub_lib_found": int(lib_found.sum()), "sub_brute_found": int(b_found.sum()),
            "sub_same": int(same.sum()), "sub_only_lib": int((lib_found & ~b_found).sum()),
            "sub_only_brute": int((b_found & ~lib_found).sum()),
            "sub_differ": int((both & ~same).sum()), "peak_mib": peak_mib(), "load": load()}


def print_search(r: dict) -> None:
    n = r["points"]
    print(f"\n1. Search, link_a tube at level {r['level']} (h {r['h']:.4g} m) deformed by a smooth field "
          f"(0.2 h), {n} rays, |g| <= 1 h; {r['seeds']} NURBS seeds, {r['triangles']} facets "
          f"(setup: both embeddings {r['setup_s']:.1f} s)")
    print(f"{'search':<40} {'s':>8} {'us/point':>9} {'found':>7}")
    rows = [("NurbsFeSurface.search (k-d tree)", r["lib_s"], r["lib_found"]),
            ("  same rays, previous hits first", r["warm_s"], r["lib_found"]),
            (f"brute force, {r['brute_rays']} rays scaled to {n}", r["brute_scaled_s"], None),
            ("FacetSurface.search (k-d tree)", r["facets_s"], r["facets_found"])]
    for name, s, found in rows:
        print(f"{name:<40} {s:8.3f} {1e6 * s / n:9.2f} {'' if found is None else found:>7}")
    print(f"speed-up of the library search over brute force: {r['brute_scaled_s'] / r['lib_s']:.0f}x "
          f"(brute force measured {r['brute_s']:.2f} s on {r['brute_rays']} rays)")
    print(f"same hits on the {r['brute_rays']} brute-force rays: library {r['sub_lib_found']}, brute "
          f"{r['sub_brute_found']}, same gap (1e-8 h) {r['sub_same']}, only library {r['sub_only_lib']}, "
          f"only brute {r['sub_only_brute']}, different gap {r['sub_differ']}")
    print(f"library hits at the constructed master point (|g - g0| <= 1e-8 h): {r['lib_exact']} of {n}; "
          f"facets: largest |g - g0| {r['facets_gap_err'] / r['h']:.2e} h (chord error)")
    print(f"per-point cost facets / NURBS+FE: {r['facets_s'] / r['lib_s']:.2f}; peak {r['peak_mib']:.0f} MiB; "
          f"load average {r['load']}")


# -- 2. per Newton iteration -------------------------------------------------------------------
def build_system(level: int, definition: str, order: int = 1):
    """The system ``cgfem run`` builds for chain2_steel with elements of ``order`` (bodies,
    contact pairs, System)."""
    from cgfem.case.load import load_case
    from cgfem.run import build_bodies, build_pairs
    from cgfem.solve.system import System

    case = load_case(CASE)
    models, _, solids = build_bodies(case, level, definition, lambda m: None, order)
    return System(models, build_pairs(case, models, solids, definition, lambda m: None))


def contact_state(system) -> np.ndarray:
    """link_b moved by h/2 towards link_a plus a smooth field of 0.01 h on both (n_dofs,;
    with nurbs_fit the fitted control displacements and multipliers follow)."""
    parts = []
    for i, body in enumerate(system.bodies):
        h = body.space.h
        u = smooth_field(body.space.coordinates, 0.01 * h, 4.0 * h, SEED + i)
        if body.name == "link_b":
            u[:, 1] += 0.5 * h
        parts.append(u.ravel())
    u = np.concatenate(parts)
    # nurbs_fit: the fitted patches' control displacements at the fit of that field
    # (M Z = G u), their multipliers 0
    extra = np.zeros(system.contact.n_extra)
    u = np.concatenate([u, extra])
    for block in system.contact.blocks:
        body = system.split(u)[block.body]
        u[block.z] = block.fit.factor.solve(block.fit.G @ body.reshape(-1, 3)).ravel()
    return u


def part_iteration(level: int, definition: str, repeat: int, order: int = 1) -> dict:
    import scipy.sparse as sp

    from cgfem.solve.backends import choose_backend, factorize

    tic = time.perf_counter()
    system = build_system(level, definition, order)
    setup = time.perf_counter() - tic
    u = contact_state(system)
    us = system.split(u)
    t = 0.2                                               # load factor of the first step
    frozen = system.recover(u)
    system.contact.begin_pass()
    system.contact.freeze(u, [None] * len(system.bodies))   # p_N = 0: the first outer pass
    near_null = system.near_null()
    backend = choose_backend(system.n_dofs, system.symmetric, "auto")

    extra = system.contact.n_extra      # nurbs_fit's fitted controls and multipliers

    def bulk():
        parts = [b.assemble(ub, t, s, True) for b, ub, s in zip(system.bodies, us, frozen)]
        blocks = [p[1] for p in parts] + ([sp.csr_matrix((extra, extra))] if extra else [])
        return np.concatenate([p[0] for p in parts] + [np.zeros(extra)]), sp.block_diag(blocks, format="csr")

    def contact(tangent: bool):
        r = np.zeros(system.n_dofs)
        return r, system.contact.add(u, r, tangent)

    def search():
        for k, p in enumerate(system.contact.pairs):
            p.search(*system.contact._split(u, k))    # the pair's kinematic vectors

    timings = {}
    for name, fn in (("bulk", bulk), ("contact", lambda: contact(True)),
                     ("contact_r", lambda: contact(False)), ("search", search),
                     ("recovery", lambda: system.recover(u))):
        fn()                                              # warm-up
        timings[name], res = best_of(fn, repeat)
        if name == "bulk":
            r_b, K_b = res
        elif name == "contact":
            r_c, K_c = res
    timings["merge"], K = best_of(lambda: (K_b + K_c.tocsr()).tocsr(), repeat)
    rhs = -(r_b + r_c)
    small = sp.random(30, 30, 0.2, random_state=1) + 10.0 * sp.identity(30)
    factorize(small.tocsr(), backend=backend, symmetric=False).solve(np.ones(30))   # solver start-up
    timings["solve"], du = best_of(lambda: factorize(K, backend=backend, symmetric=system.symmetric,
                                                      near_null=near_null).solve(rhs), repeat)
    active = sum(int(a.sum()) for a in system.contact.active())
    return {"level": level, "definition": definition, "order": order, "dofs": system.n_dofs, "setup_s": setup,
            "slave_points": sum(p.n_points for p in system.contact.pairs), "active": active,
            "nnz_bulk": int(K_b.nnz), "nnz_contact": int(K_c.nnz), "backend": backend,
            "solve_residual": float(np.linalg.norm(K @ du - rhs) / np.linalg.norm(rhs)),
            **{f"{k}_s": v for k, v in timings.items()}, "peak_mib": peak_mib(), "load": load()}


def print_iteration(rows: list[dict], repeat: int) -> None:
    print(f"\n2. One Newton iteration of chain2_steel (link_b pushed h/2 into link_a + smooth field "
          f"0.01 h, p_N = 0); seconds, best of {repeat} after a warm-up")
    print(f"{'order':>5} {'level':>5} {'surface':<9} {'DOFs':>7} {'slave':>6} {'active':>6} {'bulk R+K':>9} "
          f"{'contact R+K':>11} {'(search)':>9} {'contact R':>9} {'+Kc':>6} {'solve':>7} {'backend':>8} "
          f"{'SPR':>6} {'contact/bulk':>12} {'peak MiB':>8}")
    for r in rows:
        if "skipped" in r:
            print(f"{r['order']:>5} {r['level']:>5} {r['definition']:<9}  skipped: {r['skipped']}")
            continue
        print(f"{r['order']:>5} {r['level']:>5} {r['definition']:<9} {r['dofs']:>7} {r['slave_points']:>6} {r['active']:>6} "
              f"{r['bulk_s']:9.3f} {r['contact_s']:11.3f} {r['search_s']:9.3f} {r['contact_r_s']:9.3f} "
              f"{r['merge_s']:6.3f} {r['solve_s']:7.2f} {r['backend']:>8} {r['recovery_s']:6.3f} "
              f"{r['contact_s'] / r['bulk_s']:12.2f} {r['peak_mib']:8.0f}")
    print("bulk R+K: BodyModel.assemble of both links (elasticity, ghost, weak Dirichlet) + block_diag; "
          "contact R+K: ContactSet.add with the tangent (search, gap derivatives, COO triplets); "
          "contact R: the same without tangent; +Kc: bulk CSR + contact COO; solve: factorize + solve; "
          "SPR: System.recover. Load averages: " + "; ".join(f"order {r['order']} L{r['level']} {r['definition']}: "
                                                          f"{r['load']}"
                                                          for r in rows if "load" in r))


# -- 3. where the time of a run goes -----------------------------------------------------------
class Timers:
    """Exclusive wall time and calls per category of wrapped functions: time spent in a
    wrapped function called from another wrapped one counts for the inner one only."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self.first: dict[str, float] = {}            # exclusive time of the first call
        self._stack: list[list[float]] = []          # per open call: [start, time of children]

    def wrap(self, category: str, fn):
        def timed(*args, **kwargs):
            self._stack.append([time.perf_counter(), 0.0])
            try:
                return fn(*args, **kwargs)
            finally:
                start, children = self._stack.pop()
                spent = time.perf_counter() - start
                self.seconds[category] = self.seconds.get(category, 0.0) + spent - children
                self.first.setdefault(category, spent - children)
                self.calls[category] = self.calls.get(category, 0) + 1
                if self._stack:
                    self._stack[-1][1] += spent
        return timed

    def patch(self, category: str, owner, name: str) -> None:
        setattr(owner, name, self.wrap(category, getattr(owner, name)))

    def patch_classmethod(self, category: str, cls, name: str) -> None:
        fn = self.wrap(category, getattr(cls, name).__func__)
        setattr(cls, name, classmethod(fn))


#: (category, module, owner (None: the module), attribute) of every wrapped function
RUN_TIMERS = (
    ("embedding", "cgfem.run", None, "embed_body"),
    ("model build", "cgfem.fem.body", "BodyModel", "build"),
    ("contact setup", "cgfem.run", None, "build_pairs"),
    ("bulk assembly", "cgfem.fem.body", "BodyModel", "assemble"),
    ("bulk assembly", "cgfem.solve.system", "System", "force_scale"),
    ("stacking + Kc", "cgfem.solve.system", "System", "assemble"),
    ("contact R+K", "cgfem.contact.assembly", "ContactSet", "add"),
    ("contact freeze", "cgfem.contact.assembly", "ContactSet", "freeze"),
    ("linear solve", "cgfem.solve.solves", "LinearSolves", "__call__"),
    ("SPR recovery", "cgfem.fem.body", "BodyModel", "recover"),
    ("step output", "cgfem.run", None, "_write_step"),
)


def part_run(level: int) -> dict:
    import importlib

    import yaml

    from cgfem.case.load import load_case
    from cgfem.report.runs import Run
    from cgfem.run import run_case

    timers = Timers()
    for category, module, owner, name in RUN_TIMERS:
        target = importlib.import_module(module)
        if owner is not None:
            target = getattr(target, owner)
        if name == "build":
            timers.patch_classmethod(category, target, name)
        else:
            timers.patch(category, target, name)
    data = yaml.safe_load(CASE.read_text())
    data["steps"] = 1
    for bc in data["boundary"]:
        if bc["body"] == "link_b":
            bc["components"]["y"] = bc["components"]["y"] / 5.0
    lines: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        case_file = Path(tmp) / "chain2_steel_1step.yaml"
        case_file.write_text(yaml.safe_dump(data))
        t0 = time.perf_counter()
        status = run_case(load_case(case_file), level, "nurbs_fe", Path(tmp) / "out", lines.append)
        total = time.perf_counter() - t0
        summary = json.loads(status.summary.read_text())
    step = summary["steps"][-1] if summary["steps"] else {}
    return {"level": level, "status": status.status, "total_s": total, "seconds": timers.seconds,
            "calls": timers.calls, "first": timers.first, "dofs": sum(b["dofs"] for b in summary["bodies"].values()),
            "newton": Run(status.summary.parent, summary).newton_iterations,
            "passes": sum(s["outer_passes"] for s in summary["steps"]),
            "active": step.get("contact", {}).get("active_points", 0),
            "pull": data["boundary"][-1]["components"]["y"], "peak_mib": peak_mib(), "load": load()}


def print_run(r: dict) -> None:
    print(f"\n3. One cgfem run of chain2_steel, level {r['level']}, nurbs_fe, 1 step (pull {r['pull']} m): "
          f"status {r['status']}, {r['dofs']} DOFs, {r['newton']} Newton iterations in {r['passes']} "
          f"outer passes, {r['active']} active contact points; run_case {r['total_s']:.1f} s in a fresh "
          f"process (numba cache loads included)")
    print(f"{'category':<16} {'s':>8} {'%':>6} {'calls':>6} {'first call s':>12}")
    seconds = dict(r["seconds"])
    seconds["other"] = r["total_s"] - sum(seconds.values())
    for name, s in sorted(seconds.items(), key=lambda kv: -kv[1]):
        first = r["first"].get(name)
        print(f"{name:<16} {s:8.2f} {100.0 * s / r['total_s']:6.1f} {r['calls'].get(name, ''):>6} "
              f"{'' if first is None else f'{first:.2f}':>12}")
    print("exclusive times of wrapped functions: embedding = run.embed_body; model build = BodyModel.build "
          "(space, ghost, pattern, weak Dirichlet, SPR setup); contact setup = run.build_pairs; bulk assembly = "
          "BodyModel.assemble + System.force_scale; stacking + Kc = the rest of System.assemble (block_diag, "
          "adding the contact COO); contact R+K = ContactSet.add; contact freeze = p_N from sigma*; linear solve "
          "= factorize + solve; SPR recovery = BodyModel.recover; step output = _write_step (stress outputs, "
          "contact points, VTU); other = the rest (geometry, solver bookkeeping, summary)")
    print(f"peak {r['peak_mib']:.0f} MiB; load average {r['load']}")


# -- driver ------------------------------------------------------------------------------------
def child(argv: list[str]) -> None:
    """``--child PART ARGS...``: one part in this process, its figures as JSON on stdout."""
    part = argv[0]
    if part == "search":
        r = part_search(int(argv[1]), int(argv[2]), int(argv[3]))
    elif part == "iteration":
        r = part_iteration(int(argv[1]), argv[2], int(argv[3]), int(argv[4]))
    else:
        r = part_run(int(argv[1]))
    print(json.dumps(r))


def in_child(*args) -> dict:
    """Run ``--child args`` in a fresh process; its JSON, or ``{"skipped": reason}``."""
    proc = subprocess.run([sys.executable, "-m", "benchmarks.bench_contact", "--child", *map(str, args)], capture_output=True,
                          text=True, cwd=ROOT)
    if proc.returncode != 0:
        lines = proc.stderr.strip().splitlines() or ["(no message)"]
        return {"skipped": lines[-1]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", nargs="+", choices=("search", "iteration", "run"),
                        default=["search", "iteration", "run"])
    parser.add_argument("--points", type=int, default=100_000, help="rays of the search benchmark")
    parser.add_argument("--brute", type=int, default=2000, help="rays the brute force runs on (scaled)")
    parser.add_argument("--search-level", type=int, default=1)
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3], help="levels of part 2")
    parser.add_argument("--surfaces", nargs="+", default=["nurbs_fe", "facets"])
    parser.add_argument("--orders", type=int, nargs="+", default=[1], choices=(1, 2),
                        help="element orders of part 2")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--run-level", type=int, default=1)
    parser.add_argument("--quick", action="store_true",
                        help="10k rays (brute force on 300), part 2 at level 1 once, part 3 at level 0")
    args = parser.parse_args()
    sys.stdout.reconfigure(line_buffering=True)
    if args.quick:
        args.points, args.brute, args.levels, args.repeat, args.run_level = 10_000, 300, [1], 1, 0
    print(f"bench_contact: {os.cpu_count()} cores, load average {load()}\n{source_state()}", flush=True)
    if "search" in args.parts:
        r = in_child("search", args.search_level, args.points, min(args.brute, args.points))
        if "skipped" in r:
            print(f"\n1. Search FAILED: {r['skipped']}")
        else:
            print_search(r)
    if "iteration" in args.parts:
        rows = []
        for order in args.orders:
            for level in args.levels:
                for definition in args.surfaces:
                    r = in_child("iteration", level, definition, args.repeat, order)
                    rows.append({"level": level, "definition": definition, "order": order, **r})
        print_iteration(rows, args.repeat)
    if "run" in args.parts:
        r = in_child("run", args.run_level)
        if "skipped" in r:
            print(f"\n3. Run FAILED: {r['skipped']}")
        else:
            print_run(r)
    print(f"\nload average at the end: {load()}")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        child(sys.argv[2:])
    else:
        main()
