"""Reading the result folder of one run (the files :mod:`cgfem.results` and
:mod:`cgfem.contact.output` write): the only module of the report package that knows file
and field names, so a rename is a change here alone.

A run folder ``results/runs/{case}/L{level}_{surface}/`` (``..._o2/`` for order 2) holds ``summary.json``,
``step_NNN.vtu`` (hexahedra of all bodies), ``surface_NNN.vtu`` (boundary points at their
reference positions) and, with contact, ``contact_NNN.vtu`` (slave points at their current
positions); ``NNN`` counts converged steps from 1 (README "Result files").
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import meshio
import numpy as np

SUMMARY = "summary.json"
STEP_VTU = "step_{:03d}.vtu"
SURFACE_VTU = "surface_{:03d}.vtu"
BOUNDARY_VTU = "boundary_{:03d}.vtu"
CONTACT_VTU = "contact_{:03d}.vtu"

#: point / cell data names of the VTU files
DISPLACEMENT = "displacement"       # (n, 3), step and surface files
STRESS = "stress"                   # (n, 9), Cauchy, row-major, step and surface files
VON_MISES = "von_mises"             # (n,), surface file (the step file has von_mises_nodal)
BODY = "body"                       # body index, in the order of summary["bodies"]
PATCH = "patch"                     # patch index within the body
#: point data of contact_NNN.vtu (points at their current positions, never to be warped)
ACTIVE = "active"                   # (n,) contact point active (1) or not (0)
PRESSURE = "pressure"               # (n,) lambda_N (Pa), negative in compression
CONTACT_FORCE = "force"             # (n, 3) force of the master on the slave point (N)
CONTACT_WEIGHT = "weight"           # (n,) area weight (m^2)
NORMAL = "normal"                   # (n, 3) current unit outward normal of the slave
CONTACT_FIELDS = ("gap", PRESSURE, "p_N", ACTIVE, NORMAL, CONTACT_WEIGHT, CONTACT_FORCE, "pair")

#: statuses of summary.json: every step solved with the outer loop below outer_tol; every
#: step solved but the outer loop of at least one stopped at its cap (exit 1); a step failed
#: after every cut-back, only the converged steps listed (exit 1); stopped by a signal, the
#: converged steps listed (exit 130 or 143)
CONVERGED = "converged"
OUTER_NOT_CONVERGED = "outer_not_converged"
FAILED = "failed"
INTERRUPTED = "interrupted"


@dataclass(frozen=True)
class Run:
    """One run folder and its parsed ``summary.json``."""

    folder: Path
    summary: dict

    @classmethod
    def load(cls, path: str | Path) -> "Run":
        """The run whose folder is ``path`` or whose ``summary.json`` is ``path``."""
        path = Path(path)
        folder = path.parent if path.name == SUMMARY else path
        return cls(folder, json.loads((folder / SUMMARY).read_text()))

    @property
    def case(self) -> str:
        return str(self.summary["case"])

    @property
    def level(self) -> int:
        return int(self.summary["level"])

    @property
    def surface(self) -> str:
        return str(self.summary["surface"])

    @property
    def order(self) -> int:
        """The element order of the run (1 for summaries written before orders existed)."""
        return int(self.summary.get("order", 1))

    @property
    def status(self) -> str:
        return str(self.summary["status"])

    @property
    def converged(self) -> bool:
        """Every step solved and every outer loop below its tolerance."""
        return self.status == CONVERGED

    @property
    def outer_not_converged(self) -> bool:
        """Every step solved, but the outer loop of at least one step hit its cap."""
        return self.status == OUTER_NOT_CONVERGED

    @property
    def failed(self) -> bool:
        """The run stopped before the last step (any status but the two above)."""
        return self.status not in (CONVERGED, OUTER_NOT_CONVERGED)

    @property
    def label(self) -> str:
        """``"{surface} L{level}"``, with ``" o{order}"`` after it for an order other than 1."""
        return f"{self.surface} L{self.level}" + (f" o{self.order}" if self.order != 1 else "")

    @property
    def status_note(self) -> str:
        """What a figure says of a run that did not converge ("" if it did)."""
        if self.converged:
            return ""
        if self.outer_not_converged:
            return "outer loop not converged"
        reached = self.load_factors()[-1] if self.n_steps else 0.0
        what = "interrupted" if self.status == INTERRUPTED else "failed"
        return f"{what} beyond load {reached:.3g}"

    @property
    def steps(self) -> list[dict]:
        return list(self.summary["steps"])

    @property
    def n_steps(self) -> int:
        return len(self.summary["steps"])

    @property
    def body_names(self) -> list[str]:
        """Body names in file order (the index stored as ``body`` in the VTU files)."""
        return list(self.summary["bodies"])

    def body_index(self, name: str) -> int:
        return self.body_names.index(name)

    @property
    def dofs(self) -> int:
        """DOFs of all bodies."""
        return int(sum(b["dofs"] for b in self.summary["bodies"].values()))

    @property
    def newton_iterations(self) -> int:
        """Newton iterations of every pass of every converged step (each solve's residuals
        less its first)."""
        return sum(len(r) - 1 for s in self.summary["steps"] for r in s["pass_residuals"])

    def body(self, name: str) -> dict:
        """``summary["bodies"][name]``: nodes, dofs, volume, area, brep_volume, brep_area, h."""
        return dict(self.summary["bodies"][name])

    def timings(self) -> dict[str, float]:
        """Seconds per stage: ``build_s``, ``solve_s`` (and whatever else the run timed)."""
        return {k: float(v) for k, v in self.summary.get("timings", {}).items()}

    def load_factors(self) -> np.ndarray:
        """(n_steps,) load factor of every converged step."""
        return np.array([s["load_factor"] for s in self.steps], float)

    def reactions(self, key: str) -> np.ndarray:
        """(n_steps, 3) reaction force (N) of the displacement entry ``key``
        (``body/patch+patch``) at every converged step."""
        return np.array([s["reactions"][key] for s in self.steps], float).reshape(-1, 3)

    def newton_residuals(self, step: int | None = None) -> np.ndarray:
        """Newton residual norms of every pass of every step (or of step ``step`` alone, an
        index into the converged steps), in order (all iterations), each relative to the
        first residual of its step (summary.json stores norms in N)."""
        values: list[float] = []
        for s in (self.steps if step is None else [self.steps[step]]):
            passes = s.get("pass_residuals") or [s["newton_residuals"]]
            first = float(passes[0][0]) or 1.0
            for residuals in passes:
                values.extend(float(r) / first for r in residuals)
        return np.array(values)

    def max_von_mises(self, body: str, step: int = -1) -> float:
        return float(self.steps[step]["max_von_mises"][body])

    def contact_force(self, step: int = -1, pair: str | None = None) -> np.ndarray:
        """(3,) force (N) the masters exert on the slaves at a step, all pairs or the pair
        ``"slave/master"``."""
        contact = self.steps[step]["contact"]
        return np.asarray((contact if pair is None else contact["pairs"][pair])["force"], float)

    def _vtu(self, pattern: str, step: int) -> meshio.Mesh:
        number = self.n_steps + 1 + step if step < 0 else step
        return meshio.read(self.folder / pattern.format(number))

    def step_mesh(self, step: int = -1) -> meshio.Mesh:
        """The hexahedral mesh of a step (1-based number, or negative from the end)."""
        return self._vtu(STEP_VTU, step)

    def surface_points(self, step: int = -1) -> meshio.Mesh:
        """The boundary points (reference positions) of a step."""
        return self._vtu(SURFACE_VTU, step)

    def boundary(self, step: int = -1) -> meshio.Mesh:
        """The triangulated boundary (reference positions) of a step, or, for runs written
        before ``boundary_NNN.vtu`` existed, the cloud of boundary points."""
        number = self.n_steps + 1 + step if step < 0 else step
        path = self.folder / BOUNDARY_VTU.format(number)
        return meshio.read(path) if path.exists() else self.surface_points(number)

    def contact_points(self, step: int = -1) -> meshio.Mesh:
        """The slave points of every pair of a step, at their current positions."""
        return self._vtu(CONTACT_VTU, step)

    def fitted_surfaces(self, step: int = -1) -> dict[str, tuple]:
        """``nurbs_fit``: per fitted patch ``"body/patch"`` its surface at rest and at a step
        (two :class:`~cgfem.geometry.nurbs.NurbsSurface` with the same knots and weights);
        empty for other definitions or runs without the files."""
        from cgfem.contact.fit import FIT_NAME_SEPARATOR, read_fit_json

        number = self.n_steps + 1 + step if step < 0 else step
        rest, moved = self.folder / "fit_reference.json", self.folder / f"fit_{number:03d}.json"
        if not (rest.is_file() and moved.is_file()):
            return {}
        at_rest = {p.name: p.surface for p in read_fit_json(rest)}
        return {p.name.replace(FIT_NAME_SEPARATOR, "/", 1): (at_rest[p.name], p.surface)
                for p in read_fit_json(moved) if p.name in at_rest}


def load_runs(paths) -> list[Run]:
    """Runs from folders or ``summary.json`` paths, sorted by (case, surface, level)."""
    runs = [Run.load(p) for p in paths]
    return sorted(runs, key=lambda r: (r.case, r.surface, r.level))


def cell_values(mesh: meshio.Mesh, name: str) -> np.ndarray:
    """Cell data ``name`` of the (single block) hexahedral mesh."""
    return np.asarray(mesh.cell_data[name][0])


def stress_component(stress: np.ndarray, i: int, j: int) -> np.ndarray:
    """Component ``sigma_ij`` (n,) of row-major stresses (n, 9)."""
    return np.asarray(stress)[:, 3 * i + j]
