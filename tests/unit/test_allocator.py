"""The allocator setting of ``cgfem run``: large arrays come from the heap and freed ones stay.

Each check runs in a child interpreter, whose allocator nothing else has configured: glibc's
``mallinfo2`` (2.33 and later) tells the bytes held in mappings of their own (``hblkhd``) from
the heap's (``arena``) and the heap's free bytes (``fordblks``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import platform
import subprocess
import sys

import pytest

CHILD = r"""
import ctypes, ctypes.util, json, sys
import numpy as np
from cgfem._allocator import keep_freed_memory

class MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
                 "fordblks", "keepcost")]

libc = ctypes.CDLL(ctypes.util.find_library("c"))
libc.mallinfo2.restype = MallInfo2
kept = keep_freed_memory() if sys.argv[1] == "keep" else None
size = 64 * 2**20
a = np.ones(size // 8)
held = libc.mallinfo2()
del a
freed = libc.mallinfo2()
b = np.ones(size // 8)
again = libc.mallinfo2()
print(json.dumps({"kept": kept, "mapped": held.hblkhd, "heap_free_after": freed.fordblks,
                  "heap_after_again": again.arena, "heap_before_again": freed.arena}))
"""


def _glibc_with_mallinfo2() -> bool:
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    return hasattr(ctypes.CDLL(ctypes.util.find_library("c")), "mallinfo2")


def _child(mode: str) -> dict:
    import json

    out = subprocess.run([sys.executable, "-c", CHILD, mode], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


@pytest.mark.skipif(not _glibc_with_mallinfo2(), reason="glibc 2.33 or later only (mallinfo2)")
def test_a_freed_large_array_is_kept_for_the_next():
    size = 64 * 2**20
    default = _child("default")
    assert default["mapped"] >= size            # glibc's own: a mapping of its own, unmapped when freed
    kept = _child("keep")
    assert kept["kept"] is True
    assert kept["mapped"] < size                # from the heap
    assert kept["heap_free_after"] >= size      # freed, still the process's
    # the next array of that size is served from it: the heap does not grow again
    assert kept["heap_after_again"] - kept["heap_before_again"] < size // 2


@pytest.mark.parametrize("fraction, kept", [(0.98, True), (1.02, False)])
def test_a_run_keeps_freed_memory_only_where_its_estimate_leaves_room(monkeypatch, fraction, kept):
    """``cgfem run`` (``build_bodies(..., keep_memory=True)``) keeps freed memory where the
    run's estimate is at most KEEP_MEMORY_SHARE of the machine's memory, and says so."""
    import cgfem.memory as memory
    import cgfem.run as run
    from cgfem.case.load import load_case
    from tests.support.paths import CASES

    case = load_case(CASES / "planar.yaml")
    need = memory.run_memory(case, 0, "facets")
    calls: list[bool] = []
    monkeypatch.setattr(run, "keep_freed_memory", lambda: calls.append(True) or True)
    # a machine on which the estimate is ``fraction`` of KEEP_MEMORY_SHARE of its memory
    monkeypatch.setattr(memory, "machine_memory", lambda: int(need / (memory.KEEP_MEMORY_SHARE * fraction)))
    lines: list[str] = []
    run.build_bodies(case, 0, "facets", lines.append, memory_check=False, keep_memory=True)
    assert bool(calls) == kept
    assert any(line.startswith(memory.KEPT_MEMORY_LOG) for line in lines) == kept


def test_a_control_groups_limit_is_the_memory_the_process_may_hold(monkeypatch):
    """Under a memory limit smaller than the machine (a container, a cluster job limited to the
    estimate it requested) the memory guard, the pipeline's budget and the share of kept memory
    are taken of the limit."""
    import cgfem.memory as memory

    total = memory.machine_memory()
    monkeypatch.setattr(memory, "cgroup_memory_limit", lambda: total // 3)
    assert memory.machine_memory() == total // 3
    monkeypatch.setattr(memory, "cgroup_memory_limit", lambda: 2 * total)
    assert memory.machine_memory() == total


@pytest.mark.parametrize("version", [1, 2])
def test_the_control_groups_limit_is_read_from_the_groups_own_folder(tmp_path, version):
    from cgfem.memory import cgroup_memory_limit

    cgroups = tmp_path / "cgroup"
    if version == 2:
        cgroups.write_text("0::/slurm/job_7/step_0\n")
        folder, name = tmp_path / "slurm/job_7/step_0", "memory.max"
    else:
        cgroups.write_text("9:cpu,cpuacct:/slurm/job_7\n4:memory:/slurm/job_7\n")
        folder, name = tmp_path / "memory/slurm/job_7", "memory.limit_in_bytes"
    folder.mkdir(parents=True)
    (folder / name).write_text("4294967296\n")
    assert cgroup_memory_limit(cgroups, tmp_path) == 4 * 2**30
    (folder / name).write_text("max\n" if version == 2 else "9223372036854771712\n")   # no limit
    assert cgroup_memory_limit(cgroups, tmp_path) is None
    assert cgroup_memory_limit(tmp_path / "none", tmp_path) is None
