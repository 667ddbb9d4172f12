"""Parallel kernels and their serial twins (cgfem._parallel): the twin runs on one thread,
the parallel kernel on more, and both give the same bits."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from cgfem._parallel import parallel_kernel
from cgfem.fem import _element_kernels as kern

PROBE = """
import json, numba, numpy as np
from cgfem.fem import _element_kernels as kern
from cgfem.fem.element import HEX27
rng = np.random.default_rng(7)
xi = rng.uniform(-1.0, 1.0, (40, 3))
offsets = np.array([0, 13, 40], np.int64)
conn = np.arange(54, dtype=np.int64).reshape(2, 27)
u = rng.standard_normal(3 * 54)
H = kern.point_gradients(HEX27.node_ijk, HEX27.order, conn, u, xi, offsets, 0.3)
used = [name for name in ("parallel", "serial") if getattr(kern.point_gradients, name).signatures]
print(json.dumps({"threads": numba.get_num_threads(), "used": used, "H": H.ravel().tolist()}))
"""


def _probe(threads: int) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
    proc = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_one_thread_runs_the_serial_twin_and_two_the_parallel_kernel_with_the_same_bits():
    one, two = _probe(1), _probe(2)
    assert (one["threads"], one["used"]) == (1, ["serial"])
    assert (two["threads"], two["used"]) == (2, ["parallel"])
    assert one["H"] == two["H"]


def test_the_twins_have_names_of_their_own():
    # numba names a kernel's cache files by its qualified name: the twins do not share them
    kernel = kern.integrate_tangent
    assert kernel.serial.py_func.__qualname__ == "integrate_tangent_serial"
    assert kernel.parallel.py_func.__qualname__ == "integrate_tangent"
    assert kernel.serial.py_func.__module__ == kernel.parallel.py_func.__module__ == kern.__name__
    assert kernel.__doc__ == kernel.parallel.py_func.__doc__


def test_a_wrapped_kernel_computes_what_its_python_function_does():
    from numba import prange

    def doubled(a, out):
        for i in prange(a.size):
            out[i] = 2.0 * a[i]
    kernel = parallel_kernel(doubled)
    a = np.arange(5.0)
    out = np.zeros(5)
    kernel(a, out)
    assert np.array_equal(out, 2.0 * a)
