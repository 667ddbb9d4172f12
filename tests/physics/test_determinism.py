"""Same input, same answer: runs in fresh processes repeat bit for bit whatever the load, and
take the same path with another thread count.

For the steel chain (the smoke case: two load steps) and chain3 at level 0, every surface
definition: two runs with two threads each, started together so that each loads the
machine under the other, must write the same summary numbers and the same VTU fields to the
last bit; a third run with one thread must take the same Newton iterations and active
points in every step, with reactions equal to 1e-10.

The two-thread runs call the parallel kernels (cgfem._parallel), which the suite's one-thread
workers and their warm-up shares do not compile: this module compiles them first, once, so
that the two runs started together load them instead of each compiling them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from cgfem.precompile import compile_share, parallel_versions, read_manifest
from cgfem.results import stable
from cgfem.run import THREAD_COUNTS
from tests.support.paths import CASES

#: every test here solves whole problems
pytestmark = pytest.mark.slow

#: chain3 (a body held by contact alone: the most decisions) in the default suite with facets
#: and nurbs_fe; its nurbs_fit (40 s) and the finite strain chain2_steel with ``-m long``
RUNS = [pytest.param("smoke/chain2_steel.yaml", s, marks=pytest.mark.long, id=f"chain2_steel-{s}")
        for s in ("facets", "nurbs_fe", "nurbs_fit")] \
    + [pytest.param("chain3.yaml", s, id=f"chain3-{s}", marks=pytest.mark.long if s == "nurbs_fit" else ())
       for s in ("facets", "nurbs_fe", "nurbs_fit")]


@pytest.fixture(scope="module", autouse=True)
def parallel_kernels_compiled():
    """The parallel kernels' versions the warm-up's runs would call on several threads, in the
    numba cache the runs started here read."""
    report = compile_share(1, 1, parallel_versions(read_manifest()))
    assert report.compiled > 5 and not report.skipped, report.skipped


def start(case: str, surface: str, out: Path, threads: int) -> subprocess.Popen:
    env = dict(os.environ, **dict.fromkeys(THREAD_COUNTS, str(threads)))
    return subprocess.Popen([sys.executable, "-m", "cgfem", "run", str(CASES / case), "--level", "0",
                             "--surface", surface, "--out", str(out), "--quiet"],
                            env=env, stderr=subprocess.PIPE, text=True)


def finish(proc: subprocess.Popen, out: Path) -> dict:
    err = proc.communicate(timeout=900)[1]
    assert proc.returncode == 0, err[-2000:]
    return json.loads((out / "summary.json").read_text())


def path(summary: dict) -> list[tuple]:
    """Per step: the Newton iterations of every outer pass and the active points."""
    return [(tuple(len(r) for r in s["pass_residuals"]), s["contact"]["active_points"])
            for s in summary["steps"]]


@pytest.mark.parametrize("case, surface", RUNS)
def test_runs_repeat_bitwise_under_load_and_follow_one_path_across_thread_counts(tmp_path, case, surface):
    outs = [tmp_path / name for name in ("a", "b", "one_thread")]
    first, second = start(case, surface, outs[0], 2), start(case, surface, outs[1], 2)
    a, b = finish(first, outs[0]), finish(second, outs[1])
    assert stable(a) == stable(b)
    files = sorted(p.name for p in outs[0].glob("*.vtu"))
    assert files == sorted(p.name for p in outs[1].glob("*.vtu")) and files
    for name in files:
        ma, mb = meshio.read(outs[0] / name), meshio.read(outs[1] / name)
        assert np.array_equal(ma.points, mb.points)
        for key, value in ma.point_data.items():
            assert np.array_equal(value, mb.point_data[key], equal_nan=True), (name, key)
    one = finish(start(case, surface, outs[2], 1), outs[2])
    assert one["threads"]["numba"] == 1 and a["threads"]["numba"] == 2
    assert path(one) == path(a)
    for sa, s1 in zip(a["steps"], one["steps"]):
        for key, force in sa["reactions"].items():
            scale = max(np.abs(force).max(), 1.0)
            assert np.allclose(s1["reactions"][key], force, rtol=0, atol=1e-10 * scale), key
