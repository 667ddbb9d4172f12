"""What of a run's summary two runs of the same input must repeat (``cgfem.results.stable``)."""

from __future__ import annotations

from cgfem.results import stable


def test_a_summary_compares_without_its_wall_times_threads_and_versions():
    a = {"steps": [{"reactions": {"x": [1.0, 2.0]}, "seconds": 3.1}], "timings": {"solve_s": 9.0},
         "versions": {"cgfem": "1"}, "threads": {"numba": 1}}
    b = {"steps": [{"reactions": {"x": [1.0, 2.0]}, "seconds": 4.7}], "timings": {"solve_s": 7.0},
         "versions": {"cgfem": "2"}, "threads": {"numba": 2}}
    assert stable(a) == stable(b)
    b["steps"][0]["reactions"]["x"][1] = 2.0000000000000004   # one bit
    assert stable(a) != stable(b)
