"""The allocator benchmark's input checks."""

from __future__ import annotations

import pytest

from benchmarks.bench_allocator import main


@pytest.mark.parametrize("argv, field", [(["--mb", "0"], "--mb"), (["--wait", "-1"], "--wait"),
                                         (["--case", "config/cases/none.yaml"], "--case")])
def test_bad_input_is_one_line_naming_the_field_and_exit_2(capsys, argv, field):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err

