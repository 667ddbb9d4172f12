"""Result files of a run: ``summary.json`` and ``step_NNN.vtu`` (DESIGN.md contracts).

Every file is written to a hidden temporary name next to its target, flushed, then renamed
onto it, so a reader never sees a partial file. ``summary.json`` is written last: a folder
without it holds no finished run (a new run first removes the old summary).
"""

from __future__ import annotations

import json
from pathlib import Path

import meshio
import numpy as np

from cgfem.atomic import write_text_atomic
from cgfem.embedding.export import write_vtu_files


def write_json_atomic(path: Path, data: dict) -> Path:
    """Write ``data`` as indented JSON to ``path`` atomically (NaN and inf refused)."""
    return write_text_atomic(path, json.dumps(data, indent=2, allow_nan=False, default=_jsonable) + "\n")


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


def clear_previous(folder: Path) -> None:
    """Remove the summary and step files an earlier run left in ``folder``."""
    folder = Path(folder)
    for pattern in ("summary.json", "step_*.vtu", "contact_*.vtu"):
        for old in folder.glob(pattern):
            old.unlink()


def step_mesh(bodies: list[dict]) -> meshio.Mesh:
    """One hexahedral mesh holding the active elements of every body.

    ``bodies``: dicts with node ``points`` (n, 3), H8 ``cells`` (m, 8), nodal ``displacement`` (n, 3),
    nodal ``stress`` (n, 3, 3, Cauchy, recovered), nodal ``von_mises`` (n,), per-element
    ``status`` (m,) and ``element_von_mises`` (m,).
    """
    points, cells, point_data, cell_data = [], [], {}, {}
    shift = 0
    for index, b in enumerate(bodies):
        x, c = b["points"], b["cells"]
        points.append(x)
        cells.append(c + shift)
        shift += x.shape[0]
        _append(point_data, "displacement", b["displacement"])
        _append(point_data, "stress", b["stress"].reshape(-1, 9))
        _append(point_data, "von_mises", b["von_mises"])
        _append(cell_data, "status", b["status"].astype(np.int32))
        _append(cell_data, "element_von_mises", b["element_von_mises"])
        _append(cell_data, "body", np.full(c.shape[0], index, np.int32))
    mesh = meshio.Mesh(np.concatenate(points), [("hexahedron", np.concatenate(cells))],
                       point_data={k: np.concatenate(v) for k, v in point_data.items()},
                       cell_data={k: [np.concatenate(v)] for k, v in cell_data.items()})
    return mesh


def _append(store: dict, key: str, value: np.ndarray) -> None:
    store.setdefault(key, []).append(np.asarray(value))


def write_step(folder: Path, number: int, bodies: list[dict]) -> Path:
    target = Path(folder) / f"step_{number:03d}.vtu"
    write_vtu_files({target: step_mesh(bodies)})
    return target
