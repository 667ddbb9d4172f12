"""VTU export of an embedding: the files hold exactly the active elements as positively
oriented cubes of volume h^3, the quadrature points with their weights (volume and area are
preserved), unit normals; writing is atomic; pyvista reads the result."""

from __future__ import annotations

import os

import meshio
import numpy as np
import pytest

from cgfem.embedding.export import active_hex_mesh, write_embedding_vtu
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.quadrature import CUT, INSIDE, embed, grid_for
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import BoxSpec, TorusSpec

SUM_TOL = 1e-12      # relative error of summed weights after a write and read
UNIT_TOL = 1e-12     # | |n| - 1 |
GEOMETRY_TOL = 1e-12  # relative error of node coordinates and cell volumes
SUFFIXES = ("_grid.vtu", "_surface.vtu", "_volume_points.vtu")
H8_CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                       [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)

SPECS = {
    "torus": (TorusSpec(center=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), major_radius=1.0,
                        minor_radius=0.4), 0.5),
    "box": (BoxSpec(min=(0.0, 0.0, 0.0), max=(0.3, 0.5, 0.7)), 0.2),
}


@pytest.fixture(scope="module", params=sorted(SPECS))
def written(request, tmp_path_factory):
    """(embedding, {suffix: path}) of a body at level 1 written once per module."""
    spec, h0 = SPECS[request.param]
    solid = build_solid(spec)
    embedding = embed(solid, grid_for(solid, h0, 1, (0.13, 0.29, 0.41)))
    folder = tmp_path_factory.mktemp(request.param)
    paths = write_embedding_vtu(embedding, folder, request.param)
    return embedding, dict(zip(SUFFIXES, paths))


def triple_products(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(p1 - p0) . ((p3 - p0) x (p4 - p0)) per H8 cell (m,)."""
    p = points[cells]
    return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 3] - p[:, 0], p[:, 4] - p[:, 0]))


# -- active_hex_mesh ----------------------------------------------------------------------------
def test_active_hex_mesh_of_two_neighbours():
    grid = CartesianGrid(0.5, (1.0, -2.0, 3.0), (3, 2, 2))
    elements = np.array([grid.element_id([0, 1, 1]), grid.element_id([1, 1, 1])])
    points, cells = active_hex_mesh(grid, elements)
    assert points.shape == (12, 3) and cells.shape == (2, 8)   # two cubes sharing a face
    assert np.unique(cells).size == 12
    np.testing.assert_allclose(triple_products(points, cells), 0.125, rtol=GEOMETRY_TOL)
    np.testing.assert_allclose(points[cells[0, 0]], [1.0, -1.5, 3.5])
    np.testing.assert_allclose(points[cells[1, 6]], [2.0, -1.0, 4.0])
    # points in ascending grid node id
    np.testing.assert_array_equal(grid.node_id(np.rint((points - grid.origin) / grid.h)),
                                  np.unique(grid.element_nodes(elements)))


def test_active_hex_mesh_empty_and_bad_ids():
    grid = CartesianGrid(1.0, (0.0, 0.0, 0.0), (2, 2, 2))
    points, cells = active_hex_mesh(grid, np.array([], np.int64))
    assert points.shape == (0, 3) and cells.shape == (0, 8)
    for bad in (np.array([8]), np.array([-1]), np.array([[0]]), np.array([0.5])):
        with pytest.raises(ValueError):
            active_hex_mesh(grid, bad)


# -- the grid file ------------------------------------------------------------------------------
def test_grid_file_holds_the_active_elements_as_cubes(written):
    embedding, paths = written
    grid, active = embedding.grid, embedding.active_elements
    mesh = meshio.read(paths["_grid.vtu"])
    assert [c.type for c in mesh.cells] == ["hexahedron"]
    cells = mesh.cells[0].data
    assert len(cells) == embedding.counts()["active"] == active.size
    assert len(mesh.points) == embedding.counts()["nodes"]
    assert np.unique(cells).size == len(mesh.points)            # no unused points
    # every cell is the cube of its grid element, in H8 order, volume +h^3
    element_id = mesh.cell_data["element_id"][0]
    np.testing.assert_array_equal(element_id, active)
    corner = grid.element_corner(grid.element_ijk(element_id))
    expected = corner[:, None, :] + grid.h * H8_CORNERS[None, :, :]
    np.testing.assert_allclose(mesh.points[cells], expected, rtol=0, atol=GEOMETRY_TOL * grid.h)
    np.testing.assert_allclose(triple_products(mesh.points, cells), grid.h**3,
                               rtol=GEOMETRY_TOL)
    np.testing.assert_array_equal(mesh.point_data["node_id"], embedding.active_nodes)


def test_grid_file_status_and_material_fraction(written):
    embedding, paths = written
    h, active = embedding.grid.h, embedding.active_elements
    mesh = meshio.read(paths["_grid.vtu"])
    status = mesh.cell_data["status"][0]
    np.testing.assert_array_equal(status, embedding.status[active])
    assert set(np.unique(status)) <= {INSIDE, CUT}
    assert np.sum(status == INSIDE) == embedding.counts()["inside"]
    assert np.sum(status == CUT) == embedding.counts()["cut"]
    fraction = mesh.cell_data["material_fraction"][0]
    assert fraction.sum() * h**3 == pytest.approx(embedding.volume.w.sum(), rel=SUM_TOL)
    np.testing.assert_allclose(fraction[status == INSIDE], 1.0, rtol=1e-13)
    cut = fraction[status == CUT]
    assert np.all(cut > -1e-12) and np.all(cut < 1 + 1e-12)


# -- the point files ----------------------------------------------------------------------------
def test_surface_file_matches_the_surface_rule(written):
    embedding, paths = written
    s = embedding.surface
    mesh = meshio.read(paths["_surface.vtu"])
    assert [c.type for c in mesh.cells] == ["vertex"] and len(mesh.cells[0]) == s.w.size
    assert len(mesh.points) == s.w.size
    np.testing.assert_array_equal(mesh.points, s.x)
    data = mesh.point_data
    assert data["weight"].sum() == pytest.approx(s.w.sum(), rel=SUM_TOL)
    assert data["weight"].sum() == pytest.approx(sum(embedding.area_by_name().values()),
                                                 rel=SUM_TOL)
    assert data["normal"].shape == (s.w.size, 3)
    np.testing.assert_allclose(np.linalg.norm(data["normal"], axis=1), 1.0, atol=UNIT_TOL)
    np.testing.assert_array_equal(data["patch"], s.patch)
    assert data["patch"].min() >= 0 and data["patch"].max() < len(embedding.patch_names)
    np.testing.assert_array_equal(data["element"], s.element)
    assert data["uv"].shape == (s.w.size, 2)
    np.testing.assert_array_equal(data["uv"], s.uv)
    # every point lies in the active element it names
    assert np.all(np.isin(data["element"], embedding.active_elements))


def test_volume_points_file_matches_the_volume_rule(written):
    embedding, paths = written
    v = embedding.volume
    mesh = meshio.read(paths["_volume_points.vtu"])
    assert len(mesh.points) == len(mesh.cells[0]) == v.w.size
    np.testing.assert_array_equal(mesh.points, v.x)
    assert mesh.point_data["weight"].sum() == pytest.approx(v.w.sum(), rel=SUM_TOL)
    np.testing.assert_array_equal(mesh.point_data["element"], v.element)


def test_pyvista_reads_the_grid_file(written):
    pyvista = pytest.importorskip("pyvista")
    embedding, paths = written
    grid = pyvista.read(paths["_grid.vtu"])
    assert grid.n_cells == embedding.counts()["active"]
    assert grid.n_points == embedding.counts()["nodes"]
    assert set(np.unique(grid.celltypes)) == {pyvista.CellType.HEXAHEDRON}
    volume = grid.compute_cell_sizes(length=False, area=False)["Volume"]
    np.testing.assert_allclose(volume, embedding.grid.h**3, rtol=1e-12)
    np.testing.assert_array_equal(grid.cell_data["status"],
                                  embedding.status[embedding.active_elements])


# -- atomic writing -----------------------------------------------------------------------------
def test_written_folder_holds_only_the_three_files(written):
    embedding, paths = written
    folder = paths["_grid.vtu"].parent
    assert sorted(os.listdir(folder)) == sorted(p.name for p in paths.values())


@pytest.fixture(scope="module")
def small_embedding():
    solid = build_solid(BoxSpec(min=(0.0, 0.0, 0.0), max=(0.3, 0.5, 0.7)))
    return embed(solid, grid_for(solid, 0.2, 0, (0.13, 0.29, 0.41)))


def interrupting_write(fail_at: int):
    """A meshio.write that writes call ``fail_at`` (0-based) partially and then raises."""
    real_write, calls = meshio.write, []

    def write(filename, mesh, *args, **kwargs):
        calls.append(filename)
        if len(calls) - 1 == fail_at:
            assert os.path.exists(filename)           # the temporary file exists already
            with open(filename, "w") as f:
                f.write('<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid"')
            raise KeyboardInterrupt("interrupted")
        return real_write(filename, mesh, *args, **kwargs)

    return write, calls


@pytest.mark.parametrize("fail_at", [0, 1, 2])
def test_interrupted_write_leaves_nothing(small_embedding, tmp_path, monkeypatch, fail_at):
    write, calls = interrupting_write(fail_at)
    monkeypatch.setattr(meshio, "write", write)
    with pytest.raises(KeyboardInterrupt):
        write_embedding_vtu(small_embedding, tmp_path, "box")
    assert len(calls) == fail_at + 1
    assert all(os.path.dirname(c) == str(tmp_path) for c in calls)  # temporaries beside targets
    assert os.listdir(tmp_path) == []


def test_interrupted_rewrite_keeps_the_previous_files(small_embedding, tmp_path, monkeypatch):
    paths = write_embedding_vtu(small_embedding, tmp_path, "box")
    before = {p.name: p.read_bytes() for p in paths}
    write, _ = interrupting_write(2)
    monkeypatch.setattr(meshio, "write", write)
    with pytest.raises(KeyboardInterrupt):
        write_embedding_vtu(small_embedding, tmp_path, "box")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_write_creates_the_folder_and_rejects_path_names(small_embedding, tmp_path):
    folder = tmp_path / "a" / "b"
    paths = write_embedding_vtu(small_embedding, folder, "box")
    assert [p.name for p in paths] == ["box" + s for s in SUFFIXES]
    assert all(p.parent == folder and p.is_file() for p in paths)
    for bad in ("", "sub/box", ".."):
        with pytest.raises(ValueError):
            write_embedding_vtu(small_embedding, folder, bad)
