"""``cgfem run``: a case from its file to its result folder.

case -> geometry -> embedding (per body) -> body models -> static solver -> summary.json and
step_NNN.vtu. Progress goes to ``log`` (stderr on the command line), one line per Newton
iteration and per step. Before any grid is built, the memory the run will need is
estimated from the B-rep volume and area (:mod:`cgfem.memory`) and refused if the machine
does not have it.
"""

from __future__ import annotations

import os
import platform
import signal
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Callable

import numba
import numpy as np

from cgfem import __version__
from cgfem import memory
from cgfem._allocator import keep_freed_memory
from cgfem.case.model import Body, Case
from cgfem.embedding.quadrature import Embedding, embed, grid_for
from cgfem.embedding.store import EmbeddingStore, embedding_key
from cgfem.embedding.tessellate import Tessellation, boundary_tessellation, keep_vertices
from cgfem.contact.assembly import summary as contact_summary
from cgfem.contact.build import build_pair
from cgfem.contact.fit import FIT_NAME_SEPARATOR, fit_mesh, write_fit_json, write_fit_vtu
from cgfem.contact.output import write_contact
from cgfem.definitions import NAMES as SURFACES, NURBS_DEFINITIONS, surface_definition
from cgfem.errors import InputError, RunInterrupted
from cgfem.fem.body import BodyModel, boundary_of
from cgfem.fem.element import ORDERS, hexahedron
from cgfem.fem.materials import von_mises
from cgfem.fem import spr
from cgfem.fem.spr import energy_norm, zz_estimate
from cgfem.geometry.builders import build_solid
from cgfem.geometry.measure import boundary_measures
from cgfem.results import clear_previous, remove_steps, write_collections, write_json_atomic, write_step
from cgfem.solve.linear import available_backends, mkl_threads
from cgfem.solve.static import StepRecord, solve_static
from cgfem.solve.policy import DEFAULT_POLICY, SolverPolicy, changed, fallback_policies
from cgfem.solve.system import System

#: the environment variables that set the thread counts of numba, OpenMP, MKL and OpenBLAS
THREAD_COUNTS = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
#: those and MKL's other thread settings, recorded in a run's summary
THREAD_VARIABLES = THREAD_COUNTS + ("MKL_DYNAMIC", "MKL_CBWR")
#: the status of a run stopped by a signal: its converged steps are written, and its summary
#: says where it stopped
INTERRUPTED = "interrupted"


@dataclass(frozen=True)
class RunStatus:
    """How a run ended: ``status`` (``converged``, ``outer_not_converged``, ``failed`` or
    :data:`INTERRUPTED`), its ``summary.json``, why if not converged, and the signal's
    number if interrupted."""

    status: str
    summary: Path
    message: str = ""
    signum: int = 0


def thread_settings() -> dict:
    """The threads the run's libraries used: numba's count and threading layer, MKL's (PARDISO,
    None without it) and the thread variables of the environment. Results are bitwise
    repeatable for the same settings (PARDISO in its reproducible mode, numba's parallel
    kernels writing disjoint outputs); other thread counts give the same path (Newton
    iterations, active points) to round-off."""
    try:
        layer = numba.threading_layer()
    except ValueError:          # no parallel kernel has run in this process
        layer = None
    return {"numba": numba.get_num_threads(), "numba_layer": layer, "mkl": mkl_threads(),
            "environment": {k: os.environ[k] for k in THREAD_VARIABLES if k in os.environ}}


def embed_body(solid, body: Body, level: int, surface: str, order: int = 1,
               store: EmbeddingStore | None = None) -> Embedding:
    """``body`` embedded in its grid of ``level`` for the surface definition ``surface``
    (:mod:`cgfem.definitions`): the boundary quadrature of the definition's
    :attr:`~cgfem.definitions.SurfaceDefinition.quadrature`, the definition's name kept as
    ``Embedding.definition``, and rules exact to the degree the element of ``order`` needs
    (:attr:`~cgfem.fem.element.Hexahedron.degree`); taken from ``store`` where it holds it
    (else built and kept there: :mod:`cgfem.embedding.store`)."""
    grid = grid_for(solid, body.grid.h0, level, body.grid.offset)
    quadrature, degree = surface_definition(surface).quadrature, hexahedron(order).degree
    build = partial(embed, solid, grid, quadrature, definition=surface, degree=degree)
    return build() if store is None else store.get(embedding_key(solid, grid, quadrature, degree), surface, build)


def build_models(case: Case, level: int, surface: str, log: Callable[[str], None], order: int = 1
                 ) -> tuple[list, dict]:
    """Embed and discretize every body; returns the models and per-body measures."""
    models, measures, _ = build_bodies(case, level, surface, log, order)
    return models, measures


def build_bodies(case: Case, level: int, surface: str, log: Callable[[str], None], order: int = 1,
                 policy: SolverPolicy = DEFAULT_POLICY, memory_check: bool = True,
                 keep_memory: bool = False, store: EmbeddingStore | None = None) -> tuple[list, dict, dict]:
    """Embed (kept in ``store``: :func:`embed_body`) and discretize every body with the element
    of ``order``: the models, per-body measures and the solids. A level whose memory estimate
    exceeds the machine's is refused first (:func:`check_memory`; ``policy`` decides whether
    its systems take the Krylov path) unless ``memory_check`` is False. ``keep_memory``: where the run's estimate
    (:func:`run_memory`) is at most :data:`KEEP_MEMORY_SHARE` of the memory the process may
    hold (:func:`machine_memory`), the process keeps the memory it frees for its later arrays
    (:func:`~cgfem._allocator.keep_freed_memory`: faster where freed pages are slow to get
    back, at a higher peak)."""
    for i, spec in enumerate(case.contact):
        if spec.rule == "segmented" and not surface_definition(surface).exact_surface:
            raise InputError(f"contact[{i}].rule", "'segmented' needs a NURBS surface definition "
                                                   f"(--surface {' or '.join(NURBS_DEFINITIONS)}), not {surface}")
    solids = {b.name: build_solid(b.geometry) for b in case.bodies}
    brep = {name: boundary_measures(solid) for name, solid in solids.items()}
    if memory_check:
        memory.check_memory(case, level, brep, order=order, surface=surface, policy=policy)
    if keep_memory:
        need, have = memory.run_memory(case, level, surface, order, policy, brep), memory.machine_memory()
        if need <= memory.KEEP_MEMORY_SHARE * have and keep_freed_memory():
            log(f"{memory.KEPT_MEMORY_LOG} (estimate {memory.size_text(need)} of {memory.size_text(have)})")
    finite = case.kinematics == "finite"
    models, measures = [], {}
    for body in case.bodies:
        tic, loaded = time.perf_counter(), store.loaded if store is not None else 0
        emb = embed_body(solids[body.name], body, level, surface, order, store)
        model = BodyModel.build(body, emb, boundary_of(case, body.name), case.solver, finite,
                                hexahedron(order))
        models.append(model)
        measures[body.name] = {
            "nodes": model.space.n_nodes, "dofs": model.n_dofs,
            "elements": {k: v for k, v in emb.counts().items() if k in ("inside", "cut")},
            "h": model.space.h, "ghost_penalty": model.gamma,
            "kappa_dirichlet": model.kappa_dirichlet,
            "volume": float(emb.volume.w.sum()), "area": float(emb.surface.w.sum()),
            "brep_volume": brep[body.name].volume, "brep_area": brep[body.name].area}
        log(f"body {body.name}: {model.space.n_nodes} nodes, {model.n_dofs} dofs, "
            f"{int(model.space.cut.sum())} cut elements ({time.perf_counter() - tic:.2f} s"
            f"{', embedding loaded' if store is not None and store.loaded > loaded else ''})")
    return models, measures, solids


def build_pairs(case: Case, models: list[BodyModel], solids: dict, surface: str,
                log: Callable[[str], None]) -> list:
    """The contact pairs of ``case`` on ``models`` and their ``solids`` (by body name)."""
    index = {m.name: i for i, m in enumerate(models)}
    pairs = []
    for spec in case.contact:
        tic = time.perf_counter()
        pair = build_pair(f"{spec.slave}/{spec.master}", spec, index, models, solids, surface,
                          case.kinematics == "finite", case.body(spec.slave).material.E,
                          case.body(spec.master).material.E)
        pairs.append(pair)
        log(f"contact {pair.name}: {pair.n_points} slave points, penalty {pair.eps:.3g} Pa/m "
            f"({time.perf_counter() - tic:.2f} s)")
    return pairs


@dataclass(frozen=True)
class BoundaryView:
    """A body's triangulated boundary (:func:`boundary_tessellation`) with each vertex
    located in an active element, to draw fields on the surface (``boundary_NNN.vtu``).
    Triangles with a vertex in no active element are left out (none on the examples)."""

    mesh: Tessellation
    slots: np.ndarray
    xi: np.ndarray

    @classmethod
    def of(cls, model: BodyModel, solid) -> "BoundaryView":
        mesh = boundary_tessellation(solid, model.embedding)
        slots, xi = model.space.locate(mesh.x)
        if np.any(slots < 0):
            triangles, used = keep_vertices(mesh.triangles, slots >= 0)
            mesh = Tessellation(mesh.x[used], triangles, mesh.patch[used])
            slots, xi = slots[used], xi[used]
        return cls(mesh, slots, xi)

    def fields(self, model: BodyModel, u: np.ndarray, nodal_cauchy: np.ndarray) -> dict:
        """The mesh with the displacement, the recovered Cauchy stress and its von Mises
        stress interpolated at the vertices."""
        stress = model.space.interpolate(nodal_cauchy, self.slots, self.xi)
        return {"points": self.mesh.x, "triangles": self.mesh.triangles, "patch": self.mesh.patch,
                "displacement": model.space.interpolate(u.reshape(-1, 3), self.slots, self.xi),
                "stress": stress, "von_mises": von_mises(stress)}


def step_outputs(model: BodyModel, u: np.ndarray, recovered: np.ndarray,
                 view: BoundaryView | None = None) -> dict:
    """Fields for the step files and scalars for the summary of one body at one step;
    ``recovered`` is the solver's recovery of ``u`` (the Cauchy stress in small strain).

    The recovered Cauchy stress ``sigma*`` is nodal (SPR; in finite strain SPR of the Cauchy
    stress at the sampling points). ``von_mises_nodal`` is its von Mises stress at the grid
    nodes, some of which lie outside the body (extrapolated values); ``von_mises_max_qp``
    (per element) and ``max_von_mises`` (the body's maximum) are maxima of the von Mises
    stress of ``sigma*`` interpolated at material points only: the volume-rule points of
    inside elements and every boundary-rule point. ``surface`` holds the boundary-rule
    points with ``displacement``, ``stress`` and ``von_mises`` interpolated there, and
    ``boundary`` (if ``view`` is given) the same fields on the triangulated boundary."""
    space, el = model.space, model.elasticity
    nodal_cauchy = (spr.recover(model.recovery, model.cauchy(u, model.sampling_points()))
                    if model.finite else recovered)
    vm_nodes = von_mises(nodal_cauchy)
    vol = el.points
    sigma_h = model.cauchy(u)
    at_points = spr.recovered_at(space, nodal_cauchy, vol.element, vol.xi)
    vm_points = von_mises(at_points)
    # peak stress where the material is: volume points of inside elements (those of cut
    # elements may lie in the void) and every point of the boundary rule
    inner = ~space.cut[vol.element]
    boundary = model.boundary_points
    stress_boundary = boundary.interpolate(space, nodal_cauchy)
    vm_boundary = von_mises(stress_boundary)
    per_element = np.zeros(space.n_elements)
    np.maximum.at(per_element, vol.element[inner], vm_points[inner])
    np.maximum.at(per_element, boundary.slots, vm_boundary)
    eta, _ = zz_estimate(space, vol, sigma_h, at_points, el.mu, el.lam)
    norm = energy_norm(vol, sigma_h, el.mu, el.lam)
    status = np.where(space.cut, 2, 1)
    surface = {"points": boundary.points.x, "displacement": boundary.values(space, u),
               "stress": stress_boundary, "von_mises": vm_boundary, "patch": boundary.patch}
    return {"points": space.coordinates, "cells": space.connectivity, "cell_type": space.element.cell_type,
            "displacement": u.reshape(-1, 3),
            "stress": nodal_cauchy, "von_mises_nodal": vm_nodes, "status": status,
            "von_mises_max_qp": per_element, "max_von_mises": float(per_element.max(initial=0.0)),
            "von_mises_max_nodal": float(vm_nodes.max(initial=0.0)), "surface": surface,
            "error_estimate": float(eta), "energy_norm": float(norm),
            "boundary": view.fields(model, u, nodal_cauchy) if view is not None else None}


def check_out(out: Path) -> list[Path]:
    """Refuse an output folder ``out`` that cannot be one (a file, or under a file); returns
    the folders that do not exist yet, outermost first (the run creates them)."""
    missing, folder = [], Path(out)
    while not folder.exists():
        if folder == folder.parent:
            break
        missing.append(folder)
        folder = folder.parent
    if not folder.is_dir():
        where = "is" if folder == Path(out) else f"is under {folder}, which is"
        raise InputError("--out", f"{out} {where} a file, not a folder")
    return missing[::-1]


def _remove_created(created: list[Path]) -> None:
    """Remove the folders this run created (innermost first) while they are empty."""
    for folder in reversed(created):
        try:
            folder.rmdir()
        except OSError:
            return


def run_case(case: Case, level: int, surface: str, out: Path,
             log: Callable[[str], None] = lambda m: None, order: int = 1,
             policy: SolverPolicy = DEFAULT_POLICY, memory_check: bool = True,
             keep_memory: bool = False, store: EmbeddingStore | None = None) -> RunStatus:
    """Solve ``case`` with the hexahedra of ``order`` (1 or 2) and write its results to ``out``;
    ``policy``: the solver's tuning (:class:`~cgfem.solve.policy.SolverPolicy`);
    ``memory_check``: refuse a level whose memory estimate exceeds the machine's
    (:func:`check_memory`); ``keep_memory``: let the process keep the memory it frees where
    the estimate leaves room (:func:`build_bodies`; ``cgfem run`` does); ``store``: where
    the bodies' embeddings are kept for runs on the same geometry and grid (None: built).

    Returns the run status (``converged``, ``outer_not_converged`` or ``failed``, see
    :mod:`cgfem.solve.static`; :data:`INTERRUPTED` when ``log`` raised
    :class:`~cgfem.errors.RunInterrupted` once the output folder was made: the converged
    steps' files and a summary with that status are written). Bad input raises
    :class:`InputError` and leaves no folder this call created.
    """
    if level < 0:
        raise InputError("--level", f"must be >= 0, got {level}")
    if surface not in SURFACES:
        raise InputError("--surface", f"must be one of {', '.join(SURFACES)}, got {surface!r}")
    if order not in ORDERS:
        raise InputError("--order", f"must be one of {', '.join(map(str, ORDERS))}, got {order!r}")
    if case.solver.linear != "auto" and case.solver.linear not in available_backends():
        raise InputError("solver.linear", f"backend {case.solver.linear!r} is not available here "
                         f"(available: {', '.join(available_backends())})")
    out = Path(out)
    created = check_out(out)
    started = time.perf_counter()
    try:
        models, measures, solids = build_bodies(case, level, surface, log, order, policy, memory_check,
                                                keep_memory, store)
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise InputError("--out", f"cannot create {out}: {err.strerror or err}") from None
    except InputError:
        _remove_created(created)
        raise
    clear_previous(out)
    built = time.perf_counter()
    steps: list[dict] = []
    # the fallbacks this run may take, by number; each step's "fallback" is the one it
    # converged with (0: none)
    fallbacks = {str(n): changed(p, replace(policy, fallbacks="none"))
                 for n, p in fallback_policies(policy, case.held_by_contact_alone)}

    def summary(status: str, message: str) -> Path:
        return write_json_atomic(out / "summary.json", {
            "case": case.name, "level": level, "surface": surface, "order": order, "status": status,
            "message": message, "kinematics": case.kinematics, "bodies": measures, "steps": steps,
            "timings": {"build_s": built - started, "solve_s": time.perf_counter() - built},
            "threads": thread_settings(), "policy": changed(policy), "fallbacks": fallbacks,
            "versions": {"cgfem": __version__, "python": platform.python_version(), "numpy": np.__version__}})

    try:
        system = System(models, build_pairs(case, models, solids, surface, log), policy,
                        {b.name: (b.hold_spin, b.material.E) for b in case.bodies if b.hold_spin is not None})
        views = [BoundaryView.of(m, solids[m.name]) for m in models]

        def collect() -> None:
            write_collections(out, [s["load_factor"] for s in steps])

        def on_step(record: StepRecord) -> None:
            steps.append(_write_step(out, system, record, len(steps) + 1, views))
            collect()
            outer = "" if record.outer_converged else ", outer loop NOT converged"
            log(f"step {len(steps)} converged at load factor {record.load_factor:.4g} "
                f"({record.outer_passes} outer passes{outer}, {record.seconds:.2f} s)")

        def on_drop(kept: int) -> None:
            # a fallback solves a step again from its start: the sub-steps after the first
            # ``kept`` are no longer on the run's path; their files go with them
            remove_steps(out, range(kept + 1, len(steps) + 1))
            del steps[kept:]
            collect()

        result = solve_static(system, case.steps, case.solver, log, on_step, on_drop)
    except InputError:
        _remove_created(created)
        raise
    except RunInterrupted as stop:
        name = signal.Signals(stop.signum).name
        message = (f"interrupted by {name} after {len(steps)} converged step(s)"
                   + (f", at load factor {steps[-1]['load_factor']:.6g}" if steps else ""))
        try:
            written = summary(INTERRUPTED, message)
        except OSError as err:  # the folder removed under the run (a workflow manager cleaning up)
            message += f"; summary.json not written: {err.strerror or err}"
            written = out / "summary.json"
        return RunStatus(INTERRUPTED, written, message, stop.signum)
    return RunStatus(result.status, summary(result.status, result.message), result.message)


def _write_fits(out: Path, system: System, record: StepRecord, number: int) -> dict:
    """``nurbs_fit``: the fitted surfaces of step ``number`` as ``fit_NNN.json`` (NURBS, the
    moved control nets, patches named ``body::patch``; ``fit_reference.json`` the same at
    rest, written once) and ``fit_NNN.vtu`` (sampled, with the FE displacement beside the
    fitted one); per fitted patch its relative L2 distance to the FE displacement."""
    fits = system.contact.fits(record.unknowns)
    patches = [b.fit for b, _ in fits]
    moves = [V for _, V in fits]
    bodies = [m.name for m in system.bodies]
    names = [f"{bodies[b.body]}/{b.fit.name}" for b, _ in fits]
    in_file = [n.replace("/", FIT_NAME_SEPARATOR, 1) for n in names]     # '/' is not allowed there
    if number == 1:
        write_fit_json(out / "fit_reference.json", patches, [np.zeros_like(V) for V in moves], in_file)
    write_fit_json(out / f"fit_{number:03d}.json", patches, moves, in_file)
    write_fit_vtu(out / f"fit_{number:03d}.vtu", fit_mesh(patches, moves, [record.u[b.body] for b, _ in fits]))
    return {name: {"control_points": b.fit.n_ctrl, "relative_l2_error": b.fit.relative_l2_error(record.u[b.body], V)}
            for name, (b, V) in zip(names, fits)}


def _floating_summary(system: System, record: StepRecord, unknowns: np.ndarray) -> dict:
    """Per body held by contact alone in some rigid motion: how many rigid motions its own
    conditions leave free, the stabilizing force (the norm of the force the tangent shift put
    into the increment's last Newton step, :attr:`~cgfem.solve.floating.FloatingBodies.stabilizing`; the
    residual never carries it), the norm of the force its equations leave unbalanced at the
    converged state (N), to compare with the contact force, and where its spin is held
    (``hold_spin``, :class:`~cgfem.solve.spin.SpinSpring`) ``spin``: the axis, the spin
    (rad), the spring's moment about the axis (N m) and its stiffness (N m/rad)."""
    system.freeze(record.frozen_stress)
    r = system.split(system.assemble(unknowns, record.load_factor, False)[0])
    floating = system.floating
    held = {spring.name: spring for spring in system.springs}
    entries = {}
    for i in floating.bodies:
        name = system.bodies[i].name
        entries[name] = {"free_modes": floating.free_modes.get(i, 0),
                         "stabilizing_force": floating.stabilizing.get(i, 0.0),
                         "residual": float(np.linalg.norm(r[i]))}
        if name in held:
            spring = held[name]
            entries[name]["spin"] = {"axis": spring.axis.tolist(), "angle": spring.angle(unknowns),
                                     "moment": spring.moment(unknowns), "stiffness": spring.stiffness}
    return entries


def _write_step(out: Path, system: System, record: StepRecord, number: int,
                views: list[BoundaryView]) -> dict:
    """Write the files of step ``number`` and return its entry of ``summary.json``."""
    models = system.bodies
    contact = {"force": [0.0, 0.0, 0.0], "active_points": 0, "max_pressure": 0.0, "pairs": {}}
    if system.contact:
        unknowns = record.unknowns if record.unknowns is not None else np.concatenate(record.u)
        points = system.contact.points(unknowns)
        write_contact(out, number, points)
        contact = contact_summary(points, [p.name for p in system.contact.pairs])
        if system.contact.blocks:
            contact["fits"] = _write_fits(out, system, record, number)
        # the residual over Newton's reference with every master hit on the
        # continuous surface (Newton's own last residual where no active hit lies on the
        # extension of a kept master element or triangle, extended_hits = 0)
        contact["extended_hits"] = record.extended_hits
        contact["continuous_residual"] = record.continuous_residual
        if system.floating.bodies:
            contact["floating"] = _floating_summary(system, record, unknowns)
    outputs = [step_outputs(m, u, s, v) for m, u, s, v in zip(models, record.u, record.recovered, views)]
    write_step(out, number, outputs)
    reactions = {}
    for m, u, s in zip(models, record.u, record.frozen_stress):
        reactions.update({k: v.tolist() for k, v in m.reactions(u, record.load_factor, s).items()})
    names = [m.name for m in models]
    entry = {"load_factor": record.load_factor, "newton_residuals": record.newton_residuals[0],
             "newton_reference": record.reference,
             "pass_residuals": record.newton_residuals,
             "outer_passes": record.outer_passes, "outer_changes": record.outer_changes,
             "outer_converged": record.outer_converged, "fallback": record.fallback,
             "reactions": reactions,
             "contact": contact,
             "max_von_mises": {n: o["max_von_mises"] for n, o in zip(names, outputs)},
             "von_mises_max_nodal": {n: o["von_mises_max_nodal"] for n, o in zip(names, outputs)},
             "error_estimate": {n: o["error_estimate"] for n, o in zip(names, outputs)},
             "energy_norm": {n: o["energy_norm"] for n, o in zip(names, outputs)},
             "seconds": record.seconds}
    return entry
