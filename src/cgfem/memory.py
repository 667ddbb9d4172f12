"""What a run will hold in memory, estimated before any grid is built, and what the machine has.

:func:`estimate_memory` reads a case's B-rep measures (volume, projected area) and the level:
the elements a grid of that level will have inside and cut, the bytes per element measured
for each element order, and the factors of the linear solver's path. ``cgfem run`` refuses a
level whose estimate exceeds :func:`machine_memory` (:func:`check_memory`); the pipeline
reserves :func:`run_memory` per job (``mem_mb``); a run whose estimate leaves room keeps the
memory it frees (:data:`KEEP_MEMORY_SHARE`). The constants' measurements:
docs/performance.md, "Memory".
"""

from __future__ import annotations

from pathlib import Path

from cgfem.case.model import Case
from cgfem.definitions import surface_definition
from cgfem.errors import InputError
from cgfem.geometry.builders import build_solid
from cgfem.geometry.measure import BoundaryMeasures, boundary_measures
from cgfem.solve.policy import DEFAULT_POLICY, SolverPolicy
from cgfem.solve.solves import KRYLOV, solve_path

#: bytes per inside and per cut trilinear element: pattern scatter map, quadrature, tangent
#: data and the factorization's fill (calibrated on the Neo-Hookean half torus at level 3 with
#: PARDISO, an upper bound of its peak; docs/performance.md)
BYTES_PER_ELEMENT = 90_000
BYTES_PER_CUT_ELEMENT = 180_000
#: cut elements per ``P / h^2`` (``P`` the boundary's projected area,
#: :class:`~cgfem.geometry.measure.BoundaryMeasures`): measured 1.00 on planar's boxes and
#: 1.00-1.02 on the chain links at levels 0-3; the estimate takes sqrt(2), which on a link
#: (``P = sqrt(2) A``) is the ``2 A / h^2`` the byte constants were calibrated with
CUT_ELEMENTS_PER_PROJECTED_AREA = 2.0 ** 0.5
#: the memory of an element of each order relative to the trilinear one: 3.4 times the dofs,
#: 11 times the scatter map and the element matrices, more fill
ORDER_MEMORY = {1: 1.0, 2: 12.0}
#: the Krylov path's memory (no factorization: matrix, AMG hierarchy, vectors) relative to the
#: estimate above, per element order, with a margin over chain2_steel with nurbs_fe: order 1
#: at level 3 peaked at 2.62 GiB against 7.0 (0.38), order 2 at level 2 at 9.0 against 16.1
#: (0.56); about 0.4 GiB of each peak is the interpreter and its libraries, which does not
#: grow with the level (docs/performance.md, "Memory")
KRYLOV_MEMORY = {1: 0.45, 2: 0.65}
#: the same for a case without contact (one matrix, CG, no contact surfaces): the bent half
#: torus at order 2 peaked at 3.19 GiB against 8.0 at level 2 (0.40) and at 14.7 GiB against
#: 42.3 at level 3 (0.35); order 1 keeps the contact factor (no measurement at Krylov sizes)
KRYLOV_MEMORY_NO_CONTACT = {1: 0.45, 2: 0.45}
#: the least Krylov-path factor of a case with a body held by contact alone: its stalled
#: Krylov solves are factorized directly (``krylov_stall_direct``), the AMG hierarchy dropped
#: first; chain3 at level 3 with ``facets`` peaked at 8.85 GiB against 13.8 (0.64)
KRYLOV_FALLBACK_MEMORY = 0.7
#: the Krylov path's factor for a fitted surface (``nurbs_fit``: fit rows, patch matrices
#: and their band factors besides the AMG hierarchy), per element order: chain2_steel at
#: level 3 peaked at 4.8 GiB against 7.05 (0.68), planar at 6.3 against 19.2 (0.33); 1 (the
#: factorization's) where a body is held by contact alone (chain3 at level 3: 11.7 against
#: 13.8, with direct fallbacks of the reduced saddle); at order 2 the triquadratic Krylov
#: factor and a little for the fit's own arrays: chain2_steel at level 1 peaked at 2.51 GB
#: against 3.63 and 0.54 for the interpreter (0.54), planar at level 2 at 18.4 GB against 36.5
#: (0.49; before the fitted surface's basis was chunked and the Newton matrices held once,
#: 3.77 and 20.4 GB)
KRYLOV_FIT_MEMORY = {1: 0.75, 2: 0.67}
#: the direct path's factor for a fitted surface (its fit rows, patch matrices and band
#: factors, and the reduced saddle solver's preconditioner factor): chain3 at level 1 peaked
#: at 1.19 GB against 0.59 (and 0.54 for the interpreter), the chains at order 2, level 0 at
#: 0.93 of what a factor of 1 reserves
DIRECT_FIT_MEMORY = 1.25
#: what every run holds besides its grids and systems: the interpreter, numpy, scipy, numba
#: and MKL (about 0.3-0.4 GiB), added by :func:`run_memory`
BASE_MEMORY = 512 * 2**20
#: the largest share of the machine's memory a run may be estimated to need and still keep the
#: memory it frees (:func:`cgfem.run.build_bodies`): kept memory raised the peaks 3-30 %
#: (docs/performance.md, "Freed memory kept"), which neither a run near the machine's memory
#: nor one whose estimate is tight (chain3 at level 3 peaks at 0.87 of it) can take
KEEP_MEMORY_SHARE = 0.4
#: the start of the log line of a run that keeps the memory it frees
KEPT_MEMORY_LOG = "memory: freed blocks kept for reuse"


def machine_memory() -> int:
    """Bytes of memory this process may hold: the machine's physical memory (``MemTotal``, 16
    GiB if unknown), or its control group's limit where that is smaller (a container's, a
    cluster job's: :func:`cgroup_memory_limit`)."""
    total = 16 * 2**30
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    total = int(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    limit = cgroup_memory_limit()
    return total if limit is None else min(total, limit)


def cgroup_memory_limit(cgroups: Path = Path("/proc/self/cgroup"),
                        root: Path = Path("/sys/fs/cgroup")) -> int | None:
    """Bytes this process's memory control group allows (cgroup v2 ``memory.max``, v1
    ``memory.limit_in_bytes`` of the group ``cgroups`` names, under ``root``), None if there
    is no limit or none can be read (a cluster job's limit is what it requested)."""
    try:
        lines = cgroups.read_text().splitlines()
    except OSError:
        return None
    for line in lines:
        _, controllers, path = line.split(":", 2)
        if controllers == "":
            limit = root / path.lstrip("/") / "memory.max"
        elif "memory" in controllers.split(","):
            limit = root / "memory" / path.lstrip("/") / "memory.limit_in_bytes"
        else:
            continue
        try:
            text = limit.read_text().strip()
        except OSError:
            continue
        if text.isdigit() and int(text) < 2**60:
            return int(text)
    return None


def estimate_memory(case: Case, level: int, measures: dict[str, BoundaryMeasures], order: int = 1,
                    surface: str = "nurbs_fe", policy: SolverPolicy = DEFAULT_POLICY) -> tuple[int, int, bool]:
    """Estimated bytes and DOFs of ``case`` at ``level`` with elements of ``order`` from the
    B-rep measures of every body (``measures``): inside elements ~ V / h^3, cut elements
    ~ :data:`CUT_ELEMENTS_PER_PROJECTED_AREA` P / h^2, ``order^3`` nodes per element; and
    whether the Newton systems take the Krylov path (:func:`~cgfem.solve.solves.solve_path`),
    whose estimate is :data:`KRYLOV_MEMORY` (:data:`KRYLOV_MEMORY_NO_CONTACT` without
    contact) times the factorization's, at least :data:`KRYLOV_FALLBACK_MEMORY` times it where a body is held by
    contact alone (stalled solves factorized); for a fitted ``surface`` (``nurbs_fit``),
    whose fit rows and patch matrices the Krylov path keeps too, :data:`KRYLOV_FIT_MEMORY`
    times it, or all of it where a body is held by contact alone; on the direct path
    :data:`DIRECT_FIT_MEMORY` times it."""
    total, dofs = 0.0, 0
    for body in case.bodies:
        h = body.grid.h(level)
        m = measures[body.name]
        inside, cut = m.volume / h**3, CUT_ELEMENTS_PER_PROJECTED_AREA * m.projected / h**2
        total += ORDER_MEMORY[order] * (BYTES_PER_ELEMENT * inside + BYTES_PER_CUT_ELEMENT * cut)
        dofs += int(3 * order**3 * (inside + cut))
    fitted = surface_definition(surface).fitted
    krylov = solve_path(case.solver.linear, dofs, policy, fitted, case.held_by_contact_alone, order,
                        case.symmetric) == KRYLOV
    if krylov:
        floating = case.held_by_contact_alone
        if fitted:
            factor = 1.0 if floating else KRYLOV_FIT_MEMORY[order]
        else:
            factor = (KRYLOV_MEMORY if case.contact else KRYLOV_MEMORY_NO_CONTACT)[order]
            factor = max(factor, KRYLOV_FALLBACK_MEMORY) if floating else factor
        total *= factor
    elif fitted:
        total *= DIRECT_FIT_MEMORY
    return int(total), dofs, krylov


def case_measures(case: Case) -> dict[str, BoundaryMeasures]:
    """The boundary measures of each body of ``case``, by name, from its B-rep (built, about
    3 ms per body; no grid)."""
    return {b.name: boundary_measures(build_solid(b.geometry)) for b in case.bodies}


def run_memory(case: Case, level: int, surface: str, order: int = 1,
               policy: SolverPolicy = DEFAULT_POLICY,
               measures: dict[str, BoundaryMeasures] | None = None) -> int:
    """Bytes a run of ``case`` will hold at most, by :func:`estimate_memory` plus
    :data:`BASE_MEMORY`: what a scheduler reserves for it (the pipeline's ``mem_mb``).
    ``measures``: the bodies' :func:`case_measures`, computed here if not given (a caller
    estimating many runs of one case computes them once)."""
    measures = case_measures(case) if measures is None else measures
    return estimate_memory(case, level, measures, order, surface, policy)[0] + BASE_MEMORY


def check_memory(case: Case, level: int, measures: dict[str, BoundaryMeasures],
                 total: int | None = None, order: int = 1, surface: str = "nurbs_fe",
                 policy: SolverPolicy = DEFAULT_POLICY) -> None:
    """Refuse a level whose estimated memory (:func:`estimate_memory`, an upper bound;
    docs/performance.md) exceeds the machine's physical memory ``total`` (default :func:`machine_memory`). Not the
    memory free at the moment: in the pipeline other runs hold some of it while they last."""
    need, dofs, krylov = estimate_memory(case, level, measures, order, surface, policy)
    have = machine_memory() if total is None else total
    if need > have:
        path = "Krylov path" if krylov else "direct solver"
        raise InputError("--level", f"level {level} needs about {size_text(need)} "
                         f"(~{dofs:.2g} DOFs, {path}), but this machine has {size_text(have)} "
                         f"(an upper bound: --no-memory-check runs it anyway)")


def size_text(n_bytes: float) -> str:
    """``n_bytes`` in GiB, TiB, PiB or EiB, whichever reads best."""
    for unit in ("GiB", "TiB", "PiB"):
        n_bytes /= 1024.0 ** (3 if unit == "GiB" else 1)
        if n_bytes < 1024.0:
            return f"{n_bytes:.1f} {unit}"
    return f"{n_bytes / 1024.0:.1f} EiB"
