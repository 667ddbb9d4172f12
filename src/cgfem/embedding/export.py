"""VTU files of an embedding, for ParaView and for checking the quadrature by eye.

:func:`write_embedding_vtu` writes three files into ``folder``:

``{name}_grid.vtu``
    The active (inside and cut) elements as VTK hexahedra (cell type 12) on the active nodes
    only. Point ``i`` is grid node ``embedding.active_nodes[i]`` (ascending grid node id).
    Cell data: ``status`` int8 (1 inside, 2 cut), ``element_id`` int64 (linear grid element
    id), ``material_fraction`` float64 (sum of the element's volume weights / h^3, in [0, 1]),
    ``moment_fitted`` int8 (1 for a cut element with the moment-fitted fallback rule).
    Point data: ``node_id`` int64 (linear grid node id).
``{name}_surface.vtu``
    One vertex cell per surface quadrature point, at the point ``x`` on the exact surface.
    Point data: ``normal`` (n, 3) outward unit normal, ``weight`` area weight [m^2],
    ``patch`` int32 index into ``embedding.patch_names`` (the order of ``solid.patches``;
    the names themselves are not stored: meshio 5.3 does not write VTU field data),
    ``element`` int64 owning grid element id, ``uv`` (n, 2) NURBS parameters ``(xi, eta)``
    stored with 2 components as in :class:`SurfaceQuadrature` (ParaView shows them as a
    2-component array; they are parameters, not a vector in space).
``{name}_volume_points.vtu``
    One vertex cell per volume quadrature point. Point data: ``weight`` volume weight [m^3],
    ``element`` int64 owning grid element id.

The files are written atomically: each goes to a hidden temporary file in ``folder`` (name
``.{file}.XXXX.tmp``), and only when all three are complete and flushed to disk are they
moved into place with :func:`os.replace`. An interrupted write leaves the previous files (if
any) untouched and removes its temporary files.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import meshio
import numpy as np

from cgfem.atomic import fsync, new_temporary
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.quadrature import Embedding

VTK_FORMAT = "vtu"


def active_hex_mesh(grid: CartesianGrid, elements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hexahedral mesh of the grid elements ``elements`` (m,) on their nodes only.

    Returns ``points`` (n, 3), the coordinates of the nodes of ``elements`` in ascending
    grid node id (``np.unique(grid.element_nodes(elements))``), and ``cells`` (m, 8), the
    indices of each element's nodes in ``points`` in VTK_HEXAHEDRON order (bottom face
    counter-clockwise seen from +z, then the top face), so every cell has volume +h^3.
    """
    elements = np.asarray(elements)
    if elements.ndim != 1 or not (elements.size == 0 or np.issubdtype(elements.dtype, np.integer)):
        raise ValueError(f"elements must be a 1-d array of integer ids, got shape {elements.shape} "
                         f"and dtype {elements.dtype}")
    elements = elements.astype(np.int64)
    if elements.size and (elements.min() < 0 or elements.max() >= grid.n_elements):
        raise ValueError(f"element ids must lie in [0, {grid.n_elements}), got "
                         f"[{elements.min()}, {elements.max()}]")
    connectivity = grid.element_nodes(elements).reshape(-1, 8)    # (m, 8) grid node ids
    nodes = np.unique(connectivity)                               # (n,)
    ijk = np.stack(np.unravel_index(nodes, grid.node_shape), axis=-1)
    points = grid.node_coordinates(ijk).reshape(-1, 3)
    cells = np.searchsorted(nodes, connectivity).astype(np.int64)
    return points, cells


def grid_mesh(embedding: Embedding) -> meshio.Mesh:
    """The active elements of ``embedding`` as a meshio hexahedral mesh (see module doc)."""
    grid = embedding.grid
    elements = embedding.active_elements
    points, cells = active_hex_mesh(grid, elements)
    weight = np.bincount(embedding.volume.element, embedding.volume.w, minlength=grid.n_elements)
    cell_data = {"status": [embedding.status[elements].astype(np.int8)],
                 "element_id": [elements.astype(np.int64)],
                 "material_fraction": [weight[elements] / grid.h**3],
                 "moment_fitted": [np.isin(elements, embedding.fallback).astype(np.int8)]}
    return meshio.Mesh(points, [("hexahedron", cells)],
                       point_data={"node_id": embedding.active_nodes.astype(np.int64)},
                       cell_data=cell_data)


def surface_mesh(embedding: Embedding) -> meshio.Mesh:
    """The surface quadrature points of ``embedding`` as vertex cells (see module doc)."""
    s = embedding.surface
    return _point_cloud(s.x, {"normal": s.normal, "weight": s.w,
                              "patch": s.patch.astype(np.int32),
                              "element": s.element.astype(np.int64), "uv": s.uv})


def volume_points_mesh(embedding: Embedding) -> meshio.Mesh:
    """The volume quadrature points of ``embedding`` as vertex cells (see module doc)."""
    v = embedding.volume
    return _point_cloud(v.x, {"weight": v.w, "element": v.element.astype(np.int64)})


def _point_cloud(x: np.ndarray, point_data: dict[str, np.ndarray]) -> meshio.Mesh:
    """Points ``x`` (n, 3), one vertex cell each, with ``point_data`` arrays (n, ...)."""
    x = np.asarray(x, float).reshape(-1, 3)
    vertices = np.arange(len(x), dtype=np.int64)[:, None]
    data = {k: np.ascontiguousarray(v) for k, v in point_data.items()}
    return meshio.Mesh(x, [("vertex", vertices)], point_data=data)


def write_embedding_vtu(embedding: Embedding, folder, name: str) -> list[Path]:
    """Write ``{name}_grid.vtu``, ``{name}_surface.vtu`` and ``{name}_volume_points.vtu``
    into ``folder`` (created if missing), atomically; return their paths in that order."""
    if not name or os.sep in name or (os.altsep and os.altsep in name) or name in (".", ".."):
        raise ValueError(f"name must be a plain file-name stem, got {name!r}")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return write_vtu_files({folder / f"{name}_grid.vtu": grid_mesh(embedding),
                            folder / f"{name}_surface.vtu": surface_mesh(embedding),
                            folder / f"{name}_volume_points.vtu": volume_points_mesh(embedding)})


def write_vtu_files(files: Mapping[Path, meshio.Mesh]) -> list[Path]:
    """Write every mesh of ``files`` (target path -> mesh) as VTU, all or none.

    Each mesh goes to a temporary file next to its target, which is flushed to disk; only
    when all are written are they renamed onto their targets (:func:`os.replace`, atomic per
    file). If writing fails, the temporary files are removed and every target keeps its
    previous content; only a failure between two renames (the disk vanishing) can leave a
    mix of new and old files, each of them complete.
    """
    staged: list[tuple[Path, Path]] = []
    try:
        for target, mesh in files.items():
            target = Path(target)
            tmp = new_temporary(target)
            staged.append((tmp, target))
            meshio.write(tmp, mesh, file_format=VTK_FORMAT)
            fsync(tmp)
        for tmp, target in staged:
            os.replace(tmp, target)
    except BaseException:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)
        raise
    return [target for _, target in staged]
