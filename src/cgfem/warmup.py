"""Compile (and cache) the numba kernels before a batch of runs: ``cgfem warmup``.

Every kernel is compiled with ``cache=True``, so a process that finds the cache loads it in
well under a second; a process that does not compiles every kernel it calls, minutes in all.
Jobs started together on a fresh install (many jobs of a cluster) each compile the kernels
they call at the same time. Running :func:`warm_up` once first leaves the cache complete for
all of them. On a few cores, :mod:`cgfem.precompile` does better: the kernels these runs
compile, listed once, compiled in shares by as many processes at once (the pipeline's first
jobs, the test suite's workers).

It solves two small contact problems, on the coarsest grids, with each surface definition:
two half-torus links pulled apart by 0.5 mm (Neo-Hookean, finite strain; rational NURBS
patches, trimmed caps; the facets' chord gap at this grid is wider than 0.1 mm) and two
boxes pressed together (linear elastic, small strain; planar patches, a body held by
contact alone along z). Together they call every kernel the examples call: embedding,
assembly in both kinematics, SPR recovery, contact search, residual and tangent with each
surface definition, the fit of ``nurbs_fit`` and the boundary tessellation. Triquadratic
runs call no kernel beyond these (docs/performance.md, "Compilation"). Each run must
converge; the results are thrown away.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path
from typing import Callable, NamedTuple

from cgfem.case.load import parse_case
from cgfem.definitions import NAMES
from cgfem.run import run_case
from cgfem.solve.static import CONVERGED

#: every surface definition a case can name (:data:`cgfem.definitions.NAMES`)
SURFACE_DEFINITIONS = tuple(sorted(NAMES))

_LINK = {"builder": "half_torus", "major_radius": 0.02, "minor_radius": 0.005}
_STEEL = {"model": "neo_hookean", "E": 116.0e9, "nu": 0.3}


def _links() -> dict:
    """chain2's links at its coarsest grid, one step of 0.5 mm."""
    return {
        "name": "warmup_links", "kinematics": "finite", "steps": 1,
        "bodies": {
            "link_a": {"geometry": {**_LINK, "center": [0, 0, 0], "axis": [0, 0, 1], "keep": [0, 1, 0]},
                       "material": _STEEL, "grid": {"h0": 0.005, "offset": [0.13, 0.29, 0.41]}},
            "link_b": {"geometry": {**_LINK, "center": [0, 0.03, 0], "axis": [1, 0, 0], "keep": [0, -1, 0]},
                       "material": _STEEL, "grid": {"h0": 0.005, "offset": [0.37, 0.71, 0.23]}}},
        "boundary": [
            {"body": "link_a", "patches": ["cap_a", "cap_b"], "type": "displacement",
             "components": {"x": 0.0, "y": 0.0, "z": 0.0}},
            {"body": "link_b", "patches": ["cap_a", "cap_b"], "type": "displacement",
             "components": {"x": 0.0, "y": 0.0005, "z": 0.0}}],
        "contact": [{"slave": "link_b", "master": "link_a", "kappa": 10.0,
                     "slave_patches": ["tube"], "master_patches": ["tube"]}]}


def _blocks() -> dict:
    """Two boxes pressed together by a pressure on top; the lower one rests on the upper one's
    contact alone along z (held in x and y), as in the planar example."""
    material = {"model": "linear_elastic", "E": 1.0e9, "nu": 0.3}
    return {
        "name": "warmup_blocks", "kinematics": "small", "steps": 1,
        "bodies": {
            "lower": {"geometry": {"builder": "box", "min": [0, 0, 0], "max": [1, 1, 1]},
                      "material": material, "grid": {"h0": 0.3, "offset": [0.13, 0.29, 0.41]}},
            "upper": {"geometry": {"builder": "box", "min": [0, 0, 1], "max": [1, 1, 2]},
                      "material": material, "grid": {"h0": 0.3, "offset": [0.13, 0.29, 0.57]}}},
        "boundary": [
            {"body": "upper", "patches": ["zmax"], "type": "displacement", "components": {"z": 0.0}},
            {"body": "lower", "patches": ["xmin"], "type": "displacement", "components": {"x": 0.0}},
            {"body": "lower", "patches": ["ymin"], "type": "displacement", "components": {"y": 0.0}},
            {"body": "upper", "patches": ["xmin"], "type": "displacement", "components": {"x": 0.0}},
            {"body": "upper", "patches": ["ymin"], "type": "displacement", "components": {"y": 0.0}},
            {"body": "lower", "patches": ["zmin"], "type": "traction", "value": [0.0, 0.0, 1.0e6]}],
        "contact": [{"slave": "lower", "master": "upper", "kappa": 10.0,
                     "slave_patches": ["zmax"], "master_patches": ["zmin"]}]}


class WarmupRun(NamedTuple):
    """One warm-up run: the problem's name, the surface definition, the run's status, its
    wall time (s), the contact force (3,) of the masters on the slaves and the support
    reactions (support name -> (3,)) at its last step (N)."""

    problem: str
    surface: str
    status: str
    seconds: float
    contact_force: tuple[float, float, float]
    reactions: dict[str, list[float]]


def warm_up(log: Callable[[str], None] | None = None) -> list[WarmupRun]:
    """Solve the two problems with every surface definition in a temporary folder.

    Returns
    -------
    list of WarmupRun
        One per run, links first, definitions in :data:`SURFACE_DEFINITIONS` order.

    Raises
    ------
    RuntimeError
        If a run does not converge (a broken install: the kernels were compiled, the
        solver is not right).
    """
    log = log or (lambda message: None)
    done = []
    with tempfile.TemporaryDirectory(prefix="cgfem-warmup-") as tmp:
        for data in (_links(), _blocks()):
            case = parse_case(data, Path(tmp))
            for surface in SURFACE_DEFINITIONS:
                tic = time.perf_counter()
                status = run_case(case, 0, surface, Path(tmp) / f"{case.name}_{surface}")
                seconds = time.perf_counter() - tic
                log(f"{case.name} with {surface}: {status.status} ({seconds:.1f} s)")
                steps = json.loads(status.summary.read_text())["steps"]
                force = tuple(steps[-1]["contact"]["force"]) if steps else (0.0, 0.0, 0.0)
                reactions = steps[-1]["reactions"] if steps else {}
                done.append(WarmupRun(case.name, surface, status.status, seconds, force, reactions))
                if status.status != CONVERGED:
                    raise RuntimeError(f"warm-up run {case.name} with {surface} ended {status.status}: "
                                       f"{status.message}")
    return done
