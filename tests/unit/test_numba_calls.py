"""Calls between the package's kernels compile one version per argument type
(cgfem._numba_calls): constants passed to a kernel, and variables first assigned one, do not
each compile a literal version of it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numba import njit

import cgfem  # noqa: F401  (installs the typing of kernel calls)


def _kernels(module: str):
    """A callee and a caller that passes it two constants and a variable first assigned a
    constant, as if defined in ``module``."""
    def callee(a, k):
        return a.size * k

    def caller(a):
        n = 0
        for i in range(a.size):
            n = callee(a, n) + callee(a, 1) + callee(a, 2) + i
        return n
    callee.__module__ = caller.__module__ = module
    callee = njit(callee)
    caller.__globals__["callee"] = callee      # the caller resolves its callee by name
    return callee, njit(caller)


def test_a_package_kernel_is_compiled_once_for_constant_arguments():
    callee, caller = _kernels("cgfem._probe_calls")
    a = np.zeros(3)
    assert caller(a) == caller.py_func(a)
    assert [str(sig[1]) for sig in callee.signatures] == ["int64"]


def test_kernels_of_other_packages_keep_numba_typing():
    callee, caller = _kernels("elsewhere._probe_calls")
    caller(np.zeros(3))
    assert any("Literal" in str(sig[1]) for sig in callee.signatures)



#: kernels that were compiled twice by one run, once per index type or read-only flag of an
#: argument (docs/performance.md, "Compilation"): the reference element's scatter map, the
#: partition's Bezier net, the ray search's packed NURBS nets. The first two are called from
#: Python; the others are compiled (or loaded) only inside their callers
CALLED_FROM_PYTHON = {
    "cgfem.fem._element_kernels": ["integrate_tangent"],
    "cgfem.contact._ray_kernels": ["trace"],
}
INSIDE = {
    "cgfem.embedding._partition_kernels": ["_emit_cell", "_material_element", "_emit_surface"],
    "cgfem.geometry._nurbs_kernels": ["surface_derivs", "surface_derivs_homogeneous", "ders_basis_funs"],
}

RUN = """
import importlib, json, sys, tempfile
from pathlib import Path
from cgfem.case.load import parse_case
from cgfem.run import run_case
from cgfem.warmup import _blocks, _links
with tempfile.TemporaryDirectory() as tmp:
    for data in (_links(), _blocks()):
        case = parse_case(data, Path(tmp))
        for surface in ("nurbs_fe", "nurbs_fit"):
            assert run_case(case, 0, surface, Path(tmp) / f"{case.name}_{surface}").status == "converged"
def versions(kernel):
    # a parallel kernel (cgfem._parallel) is two dispatchers, the one a run calls and its twin
    twins = [getattr(kernel, name) for name in ("parallel", "serial") if hasattr(kernel, name)]
    return sum(len(d.signatures) for d in twins or [kernel])
counts = {f"{m}.{k}": versions(getattr(importlib.import_module(m), k))
          for m, names in json.loads(sys.argv[1]).items() for k in names}
print(json.dumps(counts))
"""


def _versions(kernels: dict, cache: Path | None = None) -> dict[str, int]:
    """The warm-up's two problems (chain links in finite strain, NURBS patches; boxes in small
    strain, whose uncut elements take the reference element's stiffness) with nurbs_fe and
    nurbs_fit in a fresh interpreter (with its own numba cache ``cache``): the versions of
    each of ``kernels`` (module -> names) compiled or loaded there."""
    import json
    import os
    import subprocess
    import sys
    env = dict(os.environ) if cache is None else dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    proc = subprocess.run([sys.executable, "-c", RUN, json.dumps(kernels)], capture_output=True, text=True,
                          timeout=3600, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_contact_run_calls_one_version_of_its_kernels_from_python():
    """The bulk tangent (bodies and the reference element alike) and the ray search (the
    nurbs_fe and the fitted nets alike) run in one compiled version each."""
    counts = _versions(CALLED_FROM_PYTHON)
    assert counts == {name: 1 for name in counts}


@pytest.mark.long
def test_a_contact_run_compiles_one_version_of_its_shared_kernels(tmp_path):
    """From an empty cache (a few minutes): the kernels the embedding, the geometry and the
    contact search share inside their callers are each compiled for one signature."""
    counts = _versions({**CALLED_FROM_PYTHON, **INSIDE}, tmp_path / "numba")
    assert counts == {name: 1 for name in counts}
