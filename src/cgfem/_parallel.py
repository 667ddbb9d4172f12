"""Kernels parallel over numba's threads, with a serial twin for runs on one thread.

Compiling a kernel with ``parallel=True`` costs numba its parfor passes and the gufunc it
builds around the parallel loop, about half again the compile time of the same kernel
compiled serially (docs/performance.md, "Compilation"), and a run on one thread (every
pipeline job runs with ``NUMBA_NUM_THREADS=1``) gains nothing from the parallel version.
:func:`parallel_kernel` therefore compiles a kernel two ways, each on its first call and
cached on disk under its own name (the twin's qualified name ends in ``_serial``): a call
runs the serial twin while numba runs one thread (:func:`numba.get_num_threads`), the
parallel kernel otherwise. Both compute the same numbers: no parallel loop of the package
reduces across its iterations (each iteration writes outputs of its own).

The kernels so built are called from Python only (a kernel calling another calls a numba
dispatcher, not this wrapper).
"""

from __future__ import annotations

import functools
import types
from typing import Callable

import numba

#: the end of a serial twin's qualified name
SERIAL_SUFFIX = "_serial"


def parallel_kernel(fn: Callable) -> Callable:
    """``fn`` compiled with ``numba.njit(cache=True, parallel=True)`` and, as its serial twin,
    with ``numba.njit(cache=True)`` (``prange`` runs as ``range``); the returned function
    calls the twin on one thread. Its attributes ``parallel`` and ``serial`` are the two
    numba dispatchers."""
    parallel = numba.njit(cache=True, parallel=True)(fn)
    twin = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__, fn.__defaults__, fn.__closure__)
    twin.__qualname__ = f"{fn.__qualname__}{SERIAL_SUFFIX}"
    twin.__module__ = fn.__module__
    twin.__doc__ = fn.__doc__
    serial = numba.njit(cache=True)(twin)

    @functools.wraps(fn)
    def kernel(*args, **kwargs):
        return (serial if numba.get_num_threads() == 1 else parallel)(*args, **kwargs)
    kernel.parallel, kernel.serial = parallel, serial
    return kernel
