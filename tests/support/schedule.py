"""The order in which pytest-xdist's workers take the test files: the longest first.

With ``--dist loadfile`` each worker takes whole files and, when done, the next file of the
queue. pytest-xdist orders that queue by the number of tests in a file, so the files of a few
whole runs each (the determinism runs, the pipeline's dry runs) came last, and the worker that
took the last of them ran alone for a minute or more. Handing out the longest files first
(longest processing time first) leaves only short files for the end, where they fill the
workers evenly. :data:`SECONDS` records each file's seconds in one worker (setup, call and
teardown of its tests, on a cold numba cache); the workers collect the files in that order
(:func:`by_seconds`) and the queue keeps it (``conftest.py`` turns pytest-xdist's reordering
off). A file the record does not know goes first, as if it were the longest.

``python3 -m pytest -n 2 --dist loadfile --record-file-seconds`` writes the record anew from
the run it ends. The record orders the queue only: a stale one costs balance, never a result.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import pytest

from cgfem.atomic import write_text_atomic

#: each test file's seconds (file path relative to the repository, as in test node ids)
SECONDS = Path(__file__).resolve().parents[1] / "file_seconds.json"


def read_seconds(path: Path = SECONDS) -> dict[str, float]:
    """The record at ``path``; empty if there is none."""
    return json.loads(path.read_text()) if path.is_file() else {}


def by_seconds(files: list[str], seconds: dict[str, float]) -> list[str]:
    """``files`` (distinct) longest first by ``seconds``, those it does not know before all
    others; equal ones in their given order."""
    longest = max(seconds.values(), default=0.0)
    return sorted(files, key=lambda f: -seconds.get(f, longest + 1.0))


def order_items(items: list[pytest.Item], seconds: dict[str, float]) -> None:
    """Reorder ``items`` in place: file by file (:func:`by_seconds`), each file's tests in
    their collected order."""
    groups: dict[str, list[pytest.Item]] = defaultdict(list)
    for item in items:
        groups[item.nodeid.split("::")[0]].append(item)
    items[:] = [item for f in by_seconds(list(groups), seconds) for item in groups[f]]


class FileSeconds:
    """A plugin summing each test file's seconds over the reports of a run (in pytest-xdist's
    controller: every worker's) and writing them to ``path`` at the end, longest first."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.seconds: dict[str, float] = defaultdict(float)

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        self.seconds[report.nodeid.split("::")[0]] += report.duration

    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        ordered = dict(sorted(((f, round(s, 1)) for f, s in self.seconds.items()), key=lambda kv: -kv[1]))
        write_text_atomic(self.path, json.dumps(ordered, indent=1) + "\n")
