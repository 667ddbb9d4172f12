"""The allocator benchmark's input checks and its comparison of two runs' summaries."""

from __future__ import annotations

import pytest

from benchmarks.bench_allocator import comparable, main


@pytest.mark.parametrize("argv, field", [(["--mb", "0"], "--mb"), (["--wait", "-1"], "--wait"),
                                         (["--case", "config/cases/none.yaml"], "--case")])
def test_bad_input_is_one_line_naming_the_field_and_exit_2(capsys, argv, field):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err


def test_summaries_compare_without_what_differs_between_identical_runs():
    a = {"steps": [{"reactions": {"x": [1.0, 2.0]}, "seconds": 3.1}], "timings": {"solve_s": 9.0},
         "versions": {"cgfem": "1"}, "threads": {"numba": 1}}
    b = {"steps": [{"reactions": {"x": [1.0, 2.0]}, "seconds": 4.7}], "timings": {"solve_s": 7.0},
         "versions": {"cgfem": "2"}, "threads": {"numba": 2}}
    assert comparable(a) == comparable(b)
    b["steps"][0]["reactions"]["x"][1] = 2.0000000000000004   # one bit
    assert comparable(a) != comparable(b)
