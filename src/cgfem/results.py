"""Result files of a run: ``summary.json``, ``step_NNN.vtu``, ``surface_NNN.vtu`` and
``boundary_NNN.vtu`` (README "Result files" lists every field; the keys other tools rely on
are fixed, new ones may be added), and per series of step files a ParaView collection
``{prefix}.pvd`` whose times are the steps' load factors (:func:`write_collections`).

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
from cgfem.embedding.export import _point_cloud as point_cloud, write_vtu_files


def write_json_atomic(path: Path, data: dict) -> Path:
    """Write ``data`` as indented JSON to ``path`` atomically (NaN and inf refused)."""
    return write_text_atomic(path, json.dumps(data, indent=2, allow_nan=False, default=_jsonable) + "\n")


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


#: the keys of ``summary.json`` whose values differ between runs of the same input on the same
#: thread count: wall times (``timings``, each step's ``seconds``), the thread record, versions
VOLATILE = frozenset({"timings", "seconds", "threads", "versions"})


def stable(data):
    """``data`` (a summary, or a part of one) without the :data:`VOLATILE` keys at any depth:
    what two runs of the same input give bit for bit (tests/physics/test_determinism.py)."""
    if isinstance(data, dict):
        return {k: stable(v) for k, v in data.items() if k not in VOLATILE}
    if isinstance(data, list):
        return [stable(v) for v in data]
    return data


#: the files a converged step writes, ``{prefix}_NNN.vtu`` (``fit_NNN.json`` too)
STEP_PREFIXES = ("step", "surface", "boundary", "contact", "fit")
#: the files a run writes once: its summary and, with ``nurbs_fit``, the fits at rest
RUN_FILES = ("summary.json", "fit_reference.json")


def _unlink(folder: Path, patterns) -> None:
    for pattern in patterns:
        for old in Path(folder).glob(pattern):
            old.unlink()


def clear_previous(folder: Path) -> None:
    """Remove the files an earlier run left in ``folder`` (:data:`RUN_FILES`, every step's
    files and their collections), and no other."""
    _unlink(folder, [*RUN_FILES, *(f"{prefix}_[0-9]*.*" for prefix in STEP_PREFIXES),
                     *(f"{prefix}.pvd" for prefix in STEP_PREFIXES)])


def write_collections(folder: Path, load_factors: list[float]) -> list[Path]:
    """Write ``{prefix}.pvd`` into ``folder`` for every prefix of :data:`STEP_PREFIXES` the run
    writes (those with a file of step 1 there; every step writes the same ones): a ParaView
    collection of ``{prefix}_NNN.vtu``, ``NNN = 1 .. len(load_factors)``, each at the time of
    its step's load factor (``load_factors[NNN - 1]``), so that ParaView steps through the
    load. Without steps, a collection left from before is removed. Each file is written
    atomically; returns those written."""
    folder = Path(folder)
    written = []
    for prefix in STEP_PREFIXES:
        target = folder / f"{prefix}.pvd"
        if not load_factors or not (folder / f"{prefix}_001.vtu").exists():
            target.unlink(missing_ok=True)
            continue
        rows = "".join(f'    <DataSet timestep="{float(t)!r}" part="0" file="{prefix}_{k:03d}.vtu"/>\n'
                       for k, t in enumerate(load_factors, start=1))
        written.append(write_text_atomic(target, '<?xml version="1.0"?>\n'
                                         '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
                                         f"  <Collection>\n{rows}  </Collection>\n</VTKFile>\n"))
    return written


def remove_steps(folder: Path, numbers) -> None:
    """Remove the files of steps ``numbers`` (1-based) from ``folder``."""
    _unlink(folder, [f"{prefix}_{number:03d}.*" for number in numbers for prefix in STEP_PREFIXES])


def step_mesh(bodies: list[dict]) -> meshio.Mesh:
    """One hexahedral mesh holding the active elements of every body.

    ``bodies``: dicts with node ``points`` (n, 3), ``cells`` (m, n_nodes) in the element's
    node order and ``cell_type`` (``hexahedron`` or ``hexahedron27``, one for all bodies; a
    dict without it is ``hexahedron``), nodal ``displacement``
    (n, 3), nodal ``stress`` (n, 3, 3, recovered Cauchy), nodal ``von_mises_nodal`` (n,),
    per-element ``status`` (m,) and ``von_mises_max_qp`` (m,).
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
        _append(point_data, "von_mises_nodal", b["von_mises_nodal"])
        _append(cell_data, "status", b["status"].astype(np.int32))
        _append(cell_data, "von_mises_max_qp", b["von_mises_max_qp"])
        _append(cell_data, "body", np.full(c.shape[0], index, np.int32))
    types = {b.get("cell_type", "hexahedron") for b in bodies}
    if len(types) != 1:
        raise ValueError(f"bodies of different element types in one step mesh: {sorted(types)}")
    mesh = meshio.Mesh(np.concatenate(points), [(types.pop(), np.concatenate(cells))],
                       point_data={k: np.concatenate(v) for k, v in point_data.items()},
                       cell_data={k: [np.concatenate(v)] for k, v in cell_data.items()})
    return mesh


def surface_mesh(bodies: list[dict]) -> meshio.Mesh:
    """The boundary-rule points of every body as VTK vertex cells (a point cloud at the
    reference positions: warp by ``displacement`` for the deformed shape).

    ``bodies``: dicts whose ``surface`` holds ``points`` (n, 3), ``displacement`` (n, 3),
    ``stress`` (n, 3, 3, recovered Cauchy), ``von_mises`` (n,) and ``patch`` (n,) (index
    into the body's patch names); the point data adds ``body`` (n,), the body's index.
    """
    x, point_data = [], {}
    for index, b in enumerate(bodies):
        s = b["surface"]
        x.append(np.asarray(s["points"], float).reshape(-1, 3))
        _append(point_data, "displacement", s["displacement"])
        _append(point_data, "stress", np.asarray(s["stress"]).reshape(-1, 9))
        _append(point_data, "von_mises", s["von_mises"])
        _append(point_data, "body", np.full(x[-1].shape[0], index, np.int32))
        _append(point_data, "patch", np.asarray(s["patch"], np.int32))
    return point_cloud(np.concatenate(x), {k: np.concatenate(v) for k, v in point_data.items()})


def boundary_mesh(bodies: list[dict]) -> meshio.Mesh:
    """The triangulated boundary of every body (``boundary`` of each dict: ``points`` (n, 3)
    at reference positions, ``triangles`` (m, 3), and at the vertices ``displacement``
    (n, 3), ``stress`` (n, 3, 3, recovered Cauchy), ``von_mises`` (n,), ``patch`` (n,));
    the point data adds ``body`` (n,), the body's index."""
    x, triangles, point_data, shift = [], [], {}, 0
    for index, b in enumerate(bodies):
        s = b["boundary"]
        x.append(np.asarray(s["points"], float).reshape(-1, 3))
        triangles.append(np.asarray(s["triangles"], np.int64) + shift)
        shift += x[-1].shape[0]
        _append(point_data, "displacement", s["displacement"])
        _append(point_data, "stress", np.asarray(s["stress"]).reshape(-1, 9))
        _append(point_data, "von_mises", s["von_mises"])
        _append(point_data, "body", np.full(x[-1].shape[0], index, np.int32))
        _append(point_data, "patch", np.asarray(s["patch"], np.int32))
    return meshio.Mesh(np.concatenate(x), [("triangle", np.concatenate(triangles))],
                       point_data={k: np.concatenate(v) for k, v in point_data.items()})


def _append(store: dict, key: str, value: np.ndarray) -> None:
    store.setdefault(key, []).append(np.asarray(value))


def write_step(folder: Path, number: int, bodies: list[dict]) -> list[Path]:
    """Write ``step_NNN.vtu`` (:func:`step_mesh`), ``surface_NNN.vtu`` (:func:`surface_mesh`)
    and, when every body has its ``boundary``, ``boundary_NNN.vtu`` (:func:`boundary_mesh`)
    into ``folder``, atomically and together."""
    folder = Path(folder)
    files = {folder / f"step_{number:03d}.vtu": step_mesh(bodies),
             folder / f"surface_{number:03d}.vtu": surface_mesh(bodies)}
    if all(b.get("boundary") is not None for b in bodies):
        files[folder / f"boundary_{number:03d}.vtu"] = boundary_mesh(bodies)
    return write_vtu_files(files)
