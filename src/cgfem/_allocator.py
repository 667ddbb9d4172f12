"""Keep the memory a run frees for the run's later arrays (glibc's allocator).

glibc serves every allocation above its mmap threshold (32 MiB at most) from a fresh mapping
and unmaps it when it is freed. The kernel takes those pages back, and a virtual machine that
reports free pages to its host (virtio-balloon free page reporting) hands them back to the
host within seconds, so the next array of that size is faulted in from the host page by
page, several times slower than memory the process already holds. A Newton iteration at half
a million unknowns allocates and frees several such arrays (the tangent, its merged contact
couplings, the multigrid's work; measurements in docs/performance.md, "Freed memory kept",
and ``benchmarks/bench_allocator.py``).

:func:`keep_freed_memory` makes glibc serve every allocation from the process's heap
(``M_MMAP_MAX = 0``) and give the heap's free top back to the kernel only beyond 2 GiB
(``M_TRIM_THRESHOLD``), so that freed blocks serve the next allocations. Arithmetic is not
touched (the same bits); the peak resident memory grows by the free blocks the heap holds
between larger ones, 3-30 % as measured. ``cgfem warmup`` calls it, ``cgfem run`` where the
run's memory estimate leaves room for that (:func:`cgfem.run.build_bodies`); a library user
may.
"""

from __future__ import annotations

import ctypes
import ctypes.util

#: ``mallopt`` parameters (glibc's ``malloc.h``)
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
#: the largest trim threshold ``mallopt`` takes (an ``int``): free heap top kept, in bytes
TRIM_THRESHOLD = 2**31 - 1


def keep_freed_memory() -> bool:
    """Make the C allocator keep freed memory for reuse (module docstring): True if glibc's
    ``mallopt`` took both settings, False where the C library has no ``mallopt`` or refuses
    them (musl, macOS; nothing changed there)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return mallopt(M_MMAP_MAX, 0) == 1 and mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
