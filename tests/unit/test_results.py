"""What of a run's summary two runs of the same input must repeat (``cgfem.results.stable``),
and the result folder's ParaView collections (``cgfem.results.write_collections``)."""

from __future__ import annotations

import meshio
import numpy as np
import pytest

from cgfem.results import clear_previous, remove_steps, stable, write_collections


def test_a_summary_compares_without_its_wall_times_threads_and_versions():
    a = {"steps": [{"reactions": {"x": [1.0, 2.0]}, "seconds": 3.1}], "timings": {"solve_s": 9.0},
         "versions": {"cgfem": "1"}, "threads": {"numba": 1}}
    b = {"steps": [{"reactions": {"x": [1.0, 2.0]}, "seconds": 4.7}], "timings": {"solve_s": 7.0},
         "versions": {"cgfem": "2"}, "threads": {"numba": 2}}
    assert stable(a) == stable(b)
    b["steps"][0]["reactions"]["x"][1] = 2.0000000000000004   # one bit
    assert stable(a) != stable(b)


def _points(folder, name: str, n: int) -> None:
    """A VTU of ``n`` vertices (at x = 0 .. n-1) named ``name`` in ``folder``."""
    x = np.zeros((n, 3))
    x[:, 0] = np.arange(n)
    meshio.write(folder / name, meshio.Mesh(x, [("vertex", np.arange(n).reshape(-1, 1))]))


def test_collections_step_paraview_through_the_load_factors_of_the_steps_kept(tmp_path):
    """Each series of step files gets a ParaView collection whose times are the steps' load
    factors, in step order; ParaView's own reader (through pyvista) finds each step's file at
    its time. Dropped steps leave it; a series with no file left loses its collection."""
    pv = pytest.importorskip("pyvista")
    factors = [0.25, 0.5, 0.875]
    for k in (1, 2, 3):
        _points(tmp_path, f"step_{k:03d}.vtu", 10 * k)
        _points(tmp_path, f"contact_{k:03d}.vtu", k)
    (tmp_path / "boundary.pvd").write_text("left by an earlier run")
    written = write_collections(tmp_path, factors)
    assert sorted(p.name for p in written) == ["contact.pvd", "step.pvd"]
    assert not (tmp_path / "boundary.pvd").exists()
    reader = pv.get_reader(str(tmp_path / "step.pvd"))
    assert reader.time_values == factors
    for k, t in enumerate(factors, start=1):
        reader.set_active_time_value(t)
        assert reader.read()[0].n_points == 10 * k
    remove_steps(tmp_path, [3])
    write_collections(tmp_path, factors[:2])
    assert pv.get_reader(str(tmp_path / "contact.pvd")).time_values == factors[:2]
    remove_steps(tmp_path, [1, 2])
    assert write_collections(tmp_path, []) == []
    assert not list(tmp_path.iterdir())


def test_a_new_run_clears_the_collections_of_the_last(tmp_path):
    for name in ("step.pvd", "fit.pvd", "step_001.vtu", "summary.json"):
        (tmp_path / name).write_text("")
    (tmp_path / "notes.pvd").write_text("")
    clear_previous(tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["notes.pvd"]
