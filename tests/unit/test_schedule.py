"""tests/support/schedule.py: the test files go to pytest-xdist's workers longest first, and a
run can record each file's seconds for the next."""

from __future__ import annotations

import json
from types import SimpleNamespace

from tests.support.schedule import SECONDS, FileSeconds, by_seconds, order_items, read_seconds


def test_files_go_longest_first_and_files_not_recorded_before_all():
    seconds = {"a.py": 1.0, "c.py": 5.0, "d.py": 1.0}
    assert by_seconds(["a.py", "b.py", "c.py", "d.py"], seconds) == ["b.py", "c.py", "a.py", "d.py"]
    assert by_seconds(["x.py", "y.py"], {}) == ["x.py", "y.py"]


def test_items_keep_their_order_within_a_file():
    items = [SimpleNamespace(nodeid=n) for n in ("s.py::t1", "l.py::t1", "s.py::t2", "l.py::t2[0]")]
    order_items(items, {"s.py": 1.0, "l.py": 9.0})
    assert [i.nodeid for i in items] == ["l.py::t1", "l.py::t2[0]", "s.py::t1", "s.py::t2"]


def test_a_run_records_each_files_seconds_longest_first(tmp_path):
    plugin = FileSeconds(tmp_path / "seconds.json")
    for nodeid, duration in [("a.py::t", 0.5), ("b.py::t", 2.0), ("a.py::t", 1.0), ("a.py::u", 0.04)]:
        plugin.pytest_runtest_logreport(SimpleNamespace(nodeid=nodeid, duration=duration))
    plugin.pytest_sessionfinish(None)
    text = (tmp_path / "seconds.json").read_text()
    assert list(json.loads(text).items()) == [("b.py", 2.0), ("a.py", 1.5)]
    assert read_seconds(tmp_path / "seconds.json") == {"b.py": 2.0, "a.py": 1.5}
    assert read_seconds(tmp_path / "none.json") == {}


def test_the_record_names_test_files_of_the_suite():
    seconds = read_seconds(SECONDS)
    root = SECONDS.parent.parent
    assert len(seconds) > 50 and all(s >= 0.0 for s in seconds.values())
    assert sum(f.startswith("tests/") and (root / f).is_file() for f in seconds) >= 0.9 * len(seconds)
