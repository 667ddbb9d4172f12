"""The ``cgfem`` command line.

``cgfem check CASE.yaml [--level L [--surface S]] [--json] [--vtu DIR]`` validates a case
file, builds every body's exact geometry and prints, per body, the B-rep volume and the area
of each named patch (computed from the NURBS surfaces alone). With ``--level`` it also embeds
every body in its grid of that level and prints the element counts and the volume and areas
of the quadrature of the surface definition ``S``. Exit codes: 0 success, 2 bad input (one
line on stderr naming the offending field, no traceback).

``cgfem run CASE.yaml --level L --surface S --out DIR [--order P] [--policy NAME=VALUE ...]``
solves the case with hexahedra of order ``P`` (1, default, or 2), the solver's tuning constants
changed as ``--policy`` says (:func:`cgfem.solve.policy.policy_with`), and writes
``DIR/summary.json``, ``DIR/step_NNN.vtu`` and ``DIR/surface_NNN.vtu`` (:mod:`cgfem.run`),
with a progress line per Newton iteration and per step on stderr. Exit codes: 0 converged
(status ``converged``), 1 not converged (status ``failed``: Newton failed, the converged
steps are written; or ``outer_not_converged``: every step solved but the outer loop of at
least one stopped at ``solver.outer_passes`` above ``solver.outer_tol``), 2 bad input, 130
or 143 interrupted by SIGINT or SIGTERM (status ``interrupted``: the converged steps are
written, and ``summary.json`` says where the run stopped).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NoReturn

from cgfem import __version__
from cgfem._allocator import keep_freed_memory
from cgfem.definitions import NAMES as SURFACES
from cgfem.errors import InputError, RunInterrupted

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2

#: what ``--surface`` selects today (contact, which it is named for, is not in yet)
SURFACE_HELP = ("contact surface definition: facets (marching-cubes triangles), nurbs_fe (exact "
                "NURBS + FE displacement) or nurbs_fit (fitted NURBS); without contact it picks "
                "the boundary quadrature: on the facets for facets, on the exact NURBS surface "
                "for nurbs_fe and nurbs_fit")

@dataclass(frozen=True)
class GridReport:
    """The embedding of a body at one level (SI units)."""

    level: int
    surface: str
    h: float
    counts: dict[str, int]
    volume: float
    patch_areas: dict[str, float]

    def as_dict(self) -> dict:
        return {"level": self.level, "surface": self.surface, "h": self.h, "volume": self.volume,
                "area": sum(self.patch_areas.values()),
                "elements": {"inside": self.counts["inside"], "cut": self.counts["cut"],
                             "active": self.counts["active"], "moment_fitted": self.counts["fitted"]},
                "nodes": self.counts["nodes"]}


@dataclass(frozen=True)
class BodyReport:
    """What ``cgfem check`` reports of one body (SI units)."""

    name: str
    patch_areas: dict[str, float]
    brep_volume: float
    grid: GridReport | None = None

    @property
    def brep_area(self) -> float:
        return sum(self.patch_areas.values())

    def as_dict(self) -> dict:
        out = {"brep_volume": self.brep_volume, "brep_area": self.brep_area,
               "patches": {name: {"area": area} for name, area in self.patch_areas.items()}}
        if self.grid is not None:
            out.update(self.grid.as_dict())
            for name, area in self.grid.patch_areas.items():
                out["patches"][name]["quadrature_area"] = area
        return out


def check_case(path: str, level: int | None = None, surface: str = "nurbs_fe",
               vtu: str | None = None) -> list[BodyReport]:
    """Validate the case at ``path``, measure its bodies and, if ``level`` is given, embed
    them in their grids (writing VTU files to ``vtu`` if given); raises :class:`InputError`."""
    from cgfem.case import check_patch_names, load_case
    from cgfem.geometry.builders import build_solid
    from cgfem.geometry.measure import areas_by_name, volume

    case = load_case(path)
    solids = {}
    for body in case.bodies:
        try:
            solids[body.name] = build_solid(body.geometry)
        except InputError as err:
            raise err.within(f"bodies.{body.name}.geometry") from None
    check_patch_names(case, {name: solid.patch_names for name, solid in solids.items()})
    reports = []
    for body in case.bodies:
        solid = solids[body.name]
        grid_report = None
        if level is not None:
            grid_report = _embed_report(solid, body, level, surface, vtu)
        reports.append(BodyReport(body.name, areas_by_name(solid), volume(solid), grid_report))
    return reports


def _embed_report(solid, body, level: int, surface: str, vtu: str | None) -> GridReport:
    from cgfem.run import embed_body

    emb = embed_body(solid, body, level, surface)
    if vtu is not None:
        from cgfem.embedding.export import write_embedding_vtu

        write_embedding_vtu(emb, vtu, f"{body.name}_L{level}_{surface}")
    return GridReport(level, surface, emb.grid.h, emb.counts(), float(emb.volume.w.sum()),
                      emb.area_by_name())


def _format_table(reports: Sequence[BodyReport]) -> str:
    lines = []
    for rep in reports:
        lines.append(f"body {rep.name}: B-rep volume {rep.brep_volume:.12g} m^3, "
                     f"area {rep.brep_area:.12g} m^2")
        g = rep.grid
        if g is not None:
            c = g.counts
            lines.append(f"  level {g.level} ({g.surface}), h = {g.h:.6g} m: {c['inside']} inside + "
                         f"{c['cut']} cut elements ({c['fitted']} with moment-fitted rules), "
                         f"{c['nodes']} nodes; quadrature volume "
                         f"{g.volume:.12g} m^3 (relative error {g.volume / rep.brep_volume - 1:+.2e})")
        width = max(len(n) for n in rep.patch_areas)
        for name, area in rep.patch_areas.items():
            line = f"  patch {name:<{width}}  area {area:.12g} m^2"
            if g is not None:
                line += f"  quadrature {g.patch_areas[name]:.12g} m^2"
            lines.append(line)
    return "\n".join(lines)


def _cmd_check(args: argparse.Namespace) -> int:
    if args.level is not None and args.level < 0:
        raise InputError("--level", f"must be >= 0, got {args.level}")
    if args.vtu is not None and args.level is None:
        raise InputError("--vtu", "needs --level")
    if args.surface is not None and args.level is None:
        raise InputError("--surface", "needs --level (the surface definition only matters to the embedding)")
    reports = check_case(args.case, args.level, args.surface or "nurbs_fe", args.vtu)
    if args.json:
        print(json.dumps({"bodies": {r.name: r.as_dict() for r in reports}}, indent=2))
    else:
        print(_format_table(reports))
    return EXIT_OK


def _cmd_run(args: argparse.Namespace) -> int:
    import signal
    import time

    from cgfem.case.load import load_case
    from cgfem.errors import RunInterrupted
    from cgfem.run import INTERRUPTED, run_case
    from cgfem.solve.static import CONVERGED

    from cgfem.solve.policy import policy_with

    case = load_case(args.case)
    try:
        policy = policy_with(args.policy)
    except ValueError as err:
        raise InputError("--policy", str(err)) from None
    if args.embedding_cache is not None and os.path.exists(args.embedding_cache) \
            and not os.path.isdir(args.embedding_cache):
        raise InputError("--embedding-cache", f"{args.embedding_cache} is not a folder")
    start = time.perf_counter()
    received: list[int] = []

    def on_signal(signum, frame) -> None:
        # stop at the next progress point, outside compiled code; a second signal at once
        if received:
            raise RunInterrupted(signum)
        received.append(signum)

    def log(message: str) -> None:
        if received:
            raise RunInterrupted(received[0])
        if not args.quiet:
            print(f"[{time.perf_counter() - start:8.2f} s] {message}", file=sys.stderr, flush=True)

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        store = None
        if args.embedding_cache is not None:
            from cgfem.embedding.store import EmbeddingStore

            store = EmbeddingStore(args.embedding_cache, log)
        status = run_case(case, args.level, args.surface, args.out, log, args.order, policy=policy,
                          memory_check=args.memory_check, keep_memory=True, store=store)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if status.status == INTERRUPTED:
        print(f"cgfem: interrupted ({status.message}); {status.summary}", file=sys.stderr)
        return 128 + status.signum
    log(f"{status.status}: {status.summary}" + (f" ({status.message})" if status.message else ""))
    return EXIT_OK if status.status == CONVERGED else EXIT_FAILED


def _parse_share(text: str) -> tuple[int, int]:
    """``K/N`` of ``--share``: (k, n) with 1 <= k <= n."""
    k, slash, n = text.partition("/")
    if not (slash and k.isdigit() and n.isdigit() and 1 <= int(k) <= int(n)):
        raise InputError("--share", f"must be K/N with 1 <= K <= N, got {text!r}")
    return int(k), int(n)


def _cmd_warmup(args: argparse.Namespace) -> int:
    import time

    start = time.perf_counter()

    def log(message: str) -> None:
        print(f"[{time.perf_counter() - start:8.2f} s] {message}", file=sys.stderr, flush=True)

    if args.share is not None and args.record is not None:
        raise InputError("--record", "cannot be combined with --share")
    if args.share is not None:
        from cgfem.precompile import compile_share

        k, n = _parse_share(args.share)
        print(json.dumps(compile_share(k, n, log=log).as_dict(), indent=2))
        return EXIT_OK
    if args.record is not None:
        from cgfem.precompile import record

        if os.path.isdir(args.record):
            raise InputError("--record", f"{args.record} is a folder, not a file")
        try:
            entries = record(args.record, log)
        except RuntimeError as err:
            print(f"cgfem: error: {err}", file=sys.stderr)
            return EXIT_FAILED
        log(f"{sum(1 for e in entries if e.argtypes)} kernel versions, {len(entries)} entries: {args.record}")
        return EXIT_OK
    from cgfem.warmup import warm_up

    keep_freed_memory()
    try:
        warm_up(log)
    except RuntimeError as err:
        print(f"cgfem: error: {err}", file=sys.stderr)
        return EXIT_FAILED
    log("numba kernels compiled and cached")
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cgfem", description="Contact mechanics in the Cartesian "
                                     "grid finite element method with exact NURBS geometry.")
    parser.add_argument("--version", action="version", version=f"cgfem {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    check = sub.add_parser("check", help="validate a case file and print geometry statistics")
    check.add_argument("case", help="case file (YAML)")
    check.add_argument("--json", action="store_true", help="print JSON instead of a table")
    check.add_argument("--level", type=int, default=None,
                       help="embed the bodies in their grids of this level (h = h0 / 2^level)")
    check.add_argument("--surface", choices=sorted(SURFACES), default=None,
                       help=f"with --level: {SURFACE_HELP} (default nurbs_fe)")
    check.add_argument("--vtu", default=None, metavar="DIR",
                       help="write the grid and the quadrature points as VTU files to DIR")
    check.set_defaults(func=_cmd_check)
    run = sub.add_parser("run", help="solve a case and write summary.json, step_NNN.vtu and "
                         "surface_NNN.vtu")
    run.add_argument("case", help="case file (YAML)")
    run.add_argument("--level", type=int, required=True, help="mesh level (h = h0 / 2^level)")
    run.add_argument("--surface", choices=sorted(SURFACES), required=True, help=SURFACE_HELP)
    run.add_argument("--out", required=True, metavar="DIR",
                     help="result folder (created when the run starts; must not be a file)")
    run.add_argument("--order", type=int, default=1,
                     help="element order: 1, the trilinear hexahedron (default, the paper's), or 2, "
                          "the triquadratic one (27 nodes)")
    run.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    run.add_argument("--no-memory-check", dest="memory_check", action="store_false",
                     help="run a level whose memory estimate (an upper bound, up to about twice the "
                          "peak) exceeds this machine's memory")
    run.add_argument("--policy", action="append", default=[], metavar="NAME=VALUE",
                     help="set one of the solver's tuning constants (cgfem.solve.policy.SolverPolicy; "
                          "repeat for more), for experiments; summary.json records the ones changed")
    run.add_argument("--embedding-cache", default=None, metavar="DIR",
                     help="keep the bodies' embeddings in DIR and load them from there in later runs on "
                          "the same geometry and grid (any surface definition with the same boundary "
                          "quadrature, any loads and solver settings): the same results, bit for bit")
    run.set_defaults(func=_cmd_run)
    warmup = sub.add_parser("warmup", help="compile and cache the numba kernels (two small contact "
                            "problems, every surface definition) before a batch of runs")
    warmup.add_argument("--share", default=None, metavar="K/N",
                        help="compile only the K-th of N shares of the kernels the warm-up calls, as "
                             "listed in the package's manifest (start the N shares side by side)")
    warmup.add_argument("--record", default=None, metavar="FILE",
                        help="write that manifest to FILE: the warm-up compiled from an empty cache in "
                             "a process of its own (minutes)")
    warmup.set_defaults(func=_cmd_warmup)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cgfem`` console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except InputError as err:
        print(f"cgfem: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (KeyboardInterrupt, RunInterrupted) as stop:  # before any step: nothing written
        print("cgfem: interrupted", file=sys.stderr)
        return 128 + getattr(stop, "signum", 2)
    except BrokenPipeError:  # output piped into a pager or `head` that stopped reading
        sys.stdout = None
        return EXIT_OK


def console() -> NoReturn:
    """The ``cgfem`` console script: :func:`main`, whose exit code the process ends with at
    once, its output flushed. Every file a command writes is complete and closed when
    :func:`main` returns (results are written atomically), so the interpreter's teardown
    (freeing every module and array, a fixed cost of every pipeline job:
    ``docs/performance.md``, "Per-process cost") is skipped."""
    code = main()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, ValueError, OSError):   # closed, None or a broken pipe
            pass
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    console()
