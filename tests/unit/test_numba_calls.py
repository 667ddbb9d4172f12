"""Calls between the package's kernels compile one version per argument type
(cgfem._numba_calls): constants passed to a kernel, and variables first assigned one, do not
each compile a literal version of it."""

from __future__ import annotations

import numpy as np
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
