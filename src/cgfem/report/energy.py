"""Energy-norm error of a planar run against the planar reference solution.

The run's displacement is read from its last ``step_NNN.vtu``; the cgFEM volume rule of each
body is rebuilt exactly as the run built it (same case, level and surface definition:
:func:`cgfem.run.embed_body`), and the strain ``sym(grad u_h)`` is evaluated at its points.
The error itself is the reference's business (``cgfem.reference.planar``): this module only
hands it points, weights and strains, one body at a time. Each body's number is its share of
the error relative to the whole reference's energy norm, ``||e||_body / ||u_ref||``, so the
squares add up: the row of body ``TOTAL`` holds ``||e|| / ||u_ref||`` of the whole problem.
"""

from __future__ import annotations

import csv
from dataclasses import astuple, dataclass, fields
from pathlib import Path
from typing import Callable

import numpy as np

from cgfem.case.load import load_case
from cgfem.case.model import Case
from cgfem.embedding.store import EmbeddingStore
from cgfem.fem._element_kernels import point_gradients
from cgfem.fem.element import hexahedron
from cgfem.fem.space import Space
from cgfem.geometry.builders import build_solid
from cgfem.report.runs import BODY, DISPLACEMENT, Run, cell_values
from cgfem.run import embed_body

#: ``error(x (n, 3), w (n,), strain_h (n, 3, 3), body name) -> ||e||_body / ||u_ref||``
BodyError = Callable[[np.ndarray, np.ndarray, np.ndarray, str], float]


#: body name of the row of all bodies together
TOTAL = "all"


@dataclass(frozen=True)
class ErrorRow:
    """Energy-norm error of one body of one run relative to the reference's norm of the whole
    problem (body ``TOTAL``: all bodies); ``dofs`` counts the whole run."""

    surface: str
    level: int
    body: str
    dofs: int
    h: float
    error: float


@dataclass(frozen=True)
class VolumeStrain:
    """Strain of the run at the cgFEM volume rule of one body.

    x : (n, 3) points, w : (n,) weights, strain : (n, 3, 3) small strain sym(grad u_h)
    """

    x: np.ndarray
    w: np.ndarray
    strain: np.ndarray


def nodal_displacements(run: Run, step: int = -1) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Nodal displacement and node positions, both (n_nodes, 3), of every body by name, from a
    step VTU (the nodes of
    body ``b`` are the points its cells use; bodies are stored one after another)."""
    mesh = run.step_mesh(step)
    cells = mesh.cells[0].data
    body = cell_values(mesh, BODY)
    u = np.asarray(mesh.point_data[DISPLACEMENT], float)
    out = {}
    for index, name in enumerate(run.body_names):
        nodes = cells[body == index]
        first, last = int(nodes.min()), int(nodes.max())
        out[name] = (u[first:last + 1], np.asarray(mesh.points[first:last + 1], float))
    return out


def volume_strain(case: Case, run: Run, body_name: str, u: np.ndarray, nodes: np.ndarray,
                  store: EmbeddingStore | None = None) -> VolumeStrain:
    """Strain of nodal displacement ``u`` (n_nodes, 3) at the volume rule of ``body_name``
    rebuilt for the run's level and surface (or loaded from ``store``, where the run may have
    kept it); ``nodes`` (n_nodes, 3) are the VTU's node positions, checked against the
    rebuilt space's (they must be the same nodes)."""
    body = next(b for b in case.bodies if b.name == body_name)
    embedding = embed_body(build_solid(body.geometry), body, run.level, run.surface, run.order, store)
    space = Space.from_embedding(embedding, hexahedron(run.order))
    if space.coordinates.shape != nodes.shape or not np.allclose(space.coordinates, nodes,
                                                                 rtol=0.0, atol=1e-9 * space.h):
        raise ValueError(f"{run.folder}: the nodes of body {body_name} differ from the rebuilt "
                         "embedding's (case file changed since the run?)")
    points = space.volume_points(embedding)
    grad = point_gradients(*space.kernel_element, space.connectivity, np.ascontiguousarray(u, float).ravel(),
                           points.xi, points.offsets, space.h)
    return VolumeStrain(points.x, points.w, 0.5 * (grad + grad.transpose(0, 2, 1)))


def energy_errors(case_file: str | Path, run_folder: str | Path, error: BodyError,
                  store: EmbeddingStore | None = None) -> list[ErrorRow]:
    """Energy-norm error of every body of a run at its last step relative to the reference's
    norm, and of all bodies (body ``TOTAL``); no rows for a failed run (it did not reach the
    final load the reference solves). ``store``: embeddings (:func:`volume_strain`)."""
    case, run = load_case(case_file), Run.load(run_folder)
    rows: list[ErrorRow] = []
    if run.failed or run.n_steps == 0:
        return rows
    for name, (u, nodes) in nodal_displacements(run).items():
        s = volume_strain(case, run, name, u, nodes, store)
        rows.append(ErrorRow(run.surface, run.level, name, run.dofs, float(run.body(name)["h"]),
                             float(error(s.x, s.w, s.strain, name))))
    rows.append(ErrorRow(run.surface, run.level, TOTAL, run.dofs, max(r.h for r in rows),
                         float(np.sqrt(sum(r.error**2 for r in rows)))))
    return rows


def reference_error(reference_file: str | Path) -> BodyError:
    """The error against the cached planar reference (``cgfem.reference.planar``)."""
    from cgfem.reference.planar import PlanarReference, relative_energy_error

    reference = PlanarReference.load(reference_file)

    def error(x: np.ndarray, w: np.ndarray, strain: np.ndarray, body: str) -> float:
        # ||e||_body / ||u_ref|| (the denominator is the reference's norm of both bodies)
        return float(relative_energy_error(reference, x, w, strain, body))

    return error


def write_error_table(rows: list[ErrorRow], path: str | Path) -> None:
    """CSV with a header line: surface, level, body, dofs, h, error."""
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow([fl.name for fl in fields(ErrorRow)])
        for row in rows:
            writer.writerow([repr(v) if isinstance(v, float) else v for v in astuple(row)])


def read_error_tables(paths) -> list[ErrorRow]:
    """Rows of one or more tables written by :func:`write_error_table`."""
    rows = []
    for path in [paths] if isinstance(paths, (str, Path)) else paths:
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                rows.append(ErrorRow(r["surface"], int(r["level"]), r["body"], int(r["dofs"]),
                                     float(r["h"]), float(r["error"])))
    return rows
