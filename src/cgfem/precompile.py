"""Compile the package's kernels before their first call, a share per process:
``cgfem warmup --share K/N``.

numba compiles a kernel at its first call and caches it on disk (``cache=True``); from a cold
cache the kernels a run calls take a minute or more to compile (docs/performance.md,
"Compilation"). Processes started together on a cold cache (the pipeline's first jobs, the
test suite's workers) would each compile the same kernels at the same time.

:data:`MANIFEST` lists every kernel of the package with the argument types the warm-up runs
(:mod:`cgfem.warmup`, on one thread) call it with, and the seconds each compilation took
without those of the package's kernels it calls. :func:`share` cuts it into ``n`` shares:
walked by depth in the call graph (a kernel after the kernels it calls), each kernel goes to
the share with the least compile time so far, so that the shares take about the same time
and reach each depth about together, and a kernel mostly finds its callees compiled, by its
own share or another, in the cache (numba looks a callee up there before compiling it).
:func:`compile_share` compiles one share. Started as ``n`` processes at once, the shares
leave in the cache every kernel the warm-up calls, each compiled about once. A run on several
threads calls the parallel kernels (:mod:`cgfem._parallel`) where the one-thread warm-up
called their serial twins: :func:`parallel_versions` names their versions for
:func:`compile_share` (the tests that start two-thread runs compile them so, once).

The manifest is a hint, never a condition of a run: an entry whose kernel no longer exists or
no longer compiles for its types is skipped (reported), and a kernel it misses compiles at its
first call as before. :func:`record` writes it anew (``cgfem warmup --record FILE``: the
warm-up compiled from a cold cache, in a process of its own, a few minutes);
tests/unit/test_precompile.py checks that it lists every kernel of the package.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Callable

from numba.core import types
from numba.core.registry import CPUDispatcher

from cgfem._numba_cache import PACKAGE
from cgfem._numba_calls import in_package
from cgfem._parallel import SERIAL_SUFFIX
from cgfem.atomic import write_text_atomic

#: the manifest shipped with the package
MANIFEST = Path(__file__).with_name("kernels.tsv")
#: the manifest's columns
HEADER = "# kernel\tseconds\targument types"
#: modules not searched for kernels: the command line's entry point, and modules that import
#: optional packages and define none
_SKIP_MODULES = (f"{PACKAGE}.__main__", f"{PACKAGE}.reference")


def _named(cls_name: str, fields: tuple) -> types.Type:
    """The numba type of an instance of the named tuple class ``module:qualified name`` with
    fields of the numba types ``fields``."""
    module, _, qualname = cls_name.partition(":")
    cls = importlib.import_module(module)
    for part in qualname.split("."):
        cls = getattr(cls, part)
    if fields and all(f == fields[0] for f in fields):
        return types.NamedUniTuple(fields[0], len(fields), cls)
    return types.NamedTuple(list(fields), cls)


#: the names :func:`format_types` writes, for :func:`parse_types`
_TYPE_NAMES = {"Array": types.Array, "UniTuple": types.UniTuple, "Tuple": types.Tuple, "named": _named,
               "bool": types.boolean, "none": types.none,
               **{str(t): t for t in (*types.integer_domain, *types.real_domain, *types.complex_domain)}}


def format_type(t: types.Type) -> str:
    """``t`` as an expression :func:`parse_types` reads back: arrays, scalars, tuples and
    named tuples of these. Raises TypeError for another type."""
    if isinstance(t, types.Array):
        return f"Array({format_type(t.dtype)}, {t.ndim}, {t.layout!r}, {t.mutable is False})"
    if isinstance(t, (types.NamedTuple, types.NamedUniTuple)):
        cls = t.instance_class
        return f"named({cls.__module__ + ':' + cls.__qualname__!r}, ({''.join(format_type(f) + ', ' for f in t)}))"
    if isinstance(t, types.UniTuple):
        return f"UniTuple({format_type(t.dtype)}, {t.count})"
    if isinstance(t, types.Tuple):
        return f"Tuple(({''.join(format_type(f) + ', ' for f in t)}))"
    if str(t) in _TYPE_NAMES and _TYPE_NAMES[str(t)] == t:
        return str(t)
    raise TypeError(f"no manifest form for the numba type {t!r}")


def format_types(args: tuple) -> str:
    """Argument types (a tuple of numba types) as :func:`parse_types` reads them."""
    return f"({''.join(format_type(t) + ', ' for t in args)})"


@dataclass(frozen=True)
class Entry:
    """A kernel (``module:qualified name``) and one version of it: ``argtypes``, its argument
    types (:func:`format_types`; "" for a kernel the warm-up does not call), and the
    ``seconds`` its compilation took without the package's kernels it calls (0 where not
    called)."""

    kernel: str
    argtypes: str = ""
    seconds: float = 0.0


@dataclass
class ShareReport:
    """What :func:`compile_share` did: versions compiled (or loaded from the cache), the
    entries ``skipped`` (``kernel: reason``), and the wall time (s)."""

    share: int
    shares: int
    compiled: int = 0
    skipped: list[str] = field(default_factory=list)
    seconds: float = 0.0

    def as_dict(self) -> dict:
        return {"share": self.share, "shares": self.shares, "compiled": self.compiled,
                "skipped": self.skipped, "seconds": round(self.seconds, 3)}


def kernel_name(dispatcher: CPUDispatcher) -> str:
    """``module:qualified name`` of a numba dispatcher's Python function."""
    return f"{dispatcher.py_func.__module__}:{dispatcher.py_func.__qualname__}"


def _dispatchers_of(value) -> list[CPUDispatcher]:
    """The numba dispatchers a module attribute is: itself, or the two versions of a
    :func:`cgfem._parallel.parallel_kernel`."""
    if isinstance(value, CPUDispatcher):
        return [value]
    return [d for d in (getattr(value, "parallel", None), getattr(value, "serial", None))
            if isinstance(d, CPUDispatcher)]


def package_kernels() -> dict[str, CPUDispatcher]:
    """Every kernel defined at the top level of a module of the package (both versions of a
    parallel kernel), by :func:`kernel_name`; imports every module but :data:`_SKIP_MODULES`."""
    package = importlib.import_module(PACKAGE)
    found = {}
    for info in pkgutil.walk_packages(package.__path__, f"{PACKAGE}."):
        if info.name.startswith(_SKIP_MODULES):
            continue
        module = importlib.import_module(info.name)
        for value in vars(module).values():
            for dispatcher in _dispatchers_of(value):
                if dispatcher.py_func.__module__ == info.name:
                    found[kernel_name(dispatcher)] = dispatcher
    return found


def resolve(kernel: str) -> CPUDispatcher | None:
    """The dispatcher named ``kernel`` (:func:`kernel_name`), or None if there is none."""
    module_name, _, qualname = kernel.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError:
        return None
    # a serial twin (cgfem._parallel) is an attribute of its parallel kernel's module attribute
    for attribute in (qualname, qualname.removesuffix(SERIAL_SUFFIX)):
        for dispatcher in _dispatchers_of(getattr(module, attribute, None)):
            if kernel_name(dispatcher) == kernel:
                return dispatcher
    return None


def parse_types(text: str) -> tuple:
    """The argument types (a tuple of numba types) written by :func:`format_types`."""
    value = eval(text, {"__builtins__": {}}, _TYPE_NAMES)   # noqa: S307 - the names above only
    if not isinstance(value, tuple) or not all(isinstance(t, types.Type) for t in value):
        raise ValueError(f"not a tuple of numba types: {text!r}")
    return value


def read_manifest(path: Path = MANIFEST) -> list[Entry]:
    """The entries of a manifest file (see :func:`write_manifest`)."""
    entries = []
    for line in Path(path).read_text().splitlines():
        if not line or line.startswith("#"):
            continue
        kernel, seconds, signature = (line.split("\t") + ["", ""])[:3]
        entries.append(Entry(kernel, signature, float(seconds or 0.0)))
    return entries


def write_manifest(entries: list[Entry], path: Path) -> None:
    """Write ``entries`` one per line, tab-separated (:data:`HEADER`), atomically."""
    lines = [HEADER] + [f"{e.kernel}\t{e.seconds:.3f}\t{e.argtypes}" for e in entries]
    write_text_atomic(Path(path), "\n".join(lines) + "\n")


def callees(dispatcher: CPUDispatcher) -> set[str]:
    """Names (:func:`kernel_name`) of the package's kernels ``dispatcher``'s function calls by
    a global name or as an attribute of a module it names (read from its code's names)."""
    code, scope = dispatcher.py_func.__code__, dispatcher.py_func.__globals__
    values = [scope[name] for name in code.co_names if name in scope]
    values += [getattr(v, name, None) for v in values if isinstance(v, ModuleType) for name in code.co_names]
    return {kernel_name(d) for v in values for d in _dispatchers_of(v) if in_package(d) and d is not dispatcher}


def depths(kernels: list[str]) -> dict[str, int]:
    """The depth of each kernel in the call graph (:func:`callees`): 0 for a kernel that calls
    no other kernel of the package (or does not resolve), else one more than its deepest
    callee's."""
    depth: dict[str, int] = {}

    def visit(name: str, path: frozenset) -> int:
        if name not in depth:
            dispatcher = resolve(name)
            below = [] if dispatcher is None else [visit(c, path | {name}) for c in callees(dispatcher)
                                                   if c not in path]
            depth[name] = 1 + max(below) if below else 0
        return depth[name]

    for name in kernels:
        visit(name, frozenset())
    return depth


def share(entries: list[Entry], k: int, n: int) -> list[Entry]:
    """The ``k``-th (1-based) of ``n`` shares of the entries that name argument types, in the
    order they compile: by depth in the call graph (:func:`depths`; a kernel after its
    callees), then in the manifest's order; each entry goes to the share with the least
    compile time so far (the first of equals), so the shares reach each depth about
    together."""
    if not 1 <= k <= n:
        raise ValueError(f"share {k} of {n}: needs 1 <= k <= n")
    typed = [e for e in entries if e.argtypes]
    depth = depths(sorted({e.kernel for e in typed}))
    load = [0.0] * n
    mine = []
    for *_, entry in sorted((depth[e.kernel], i, e) for i, e in enumerate(typed)):
        target = min(range(n), key=load.__getitem__)
        load[target] += entry.seconds
        if target == k - 1:
            mine.append(entry)
    return mine


def parallel_versions(entries: list[Entry]) -> list[Entry]:
    """The entries of the serial twins (:mod:`cgfem._parallel`, names ending in
    :data:`~cgfem._parallel.SERIAL_SUFFIX`) named for their parallel kernels, with the twins'
    argument types and recorded seconds: the versions a run on several threads calls where the
    manifest's one-thread warm-up called the twins."""
    return [Entry(e.kernel.removesuffix(SERIAL_SUFFIX), e.argtypes, e.seconds) for e in entries
            if e.argtypes and e.kernel.endswith(SERIAL_SUFFIX)]


def compile_share(k: int, n: int, entries: list[Entry] | None = None,
                  log: Callable[[str], None] | None = None) -> ShareReport:
    """Compile (or load from the cache) the versions of :func:`share` ``k`` of ``n`` of
    ``entries`` (default: :data:`MANIFEST`'s), in order. An entry that cannot be compiled is
    skipped with its reason."""
    log = log or (lambda message: None)
    entries = read_manifest() if entries is None else entries
    report = ShareReport(k, n)
    start = time.perf_counter()
    for entry in share(entries, k, n):
        dispatcher = resolve(entry.kernel)
        if dispatcher is None:
            report.skipped.append(f"{entry.kernel}: no such kernel")
            continue
        try:
            dispatcher.compile(parse_types(entry.argtypes))
        except Exception as err:                      # a stale entry: the kernel compiles later
            report.skipped.append(f"{entry.kernel}: {type(err).__name__}: {str(err).splitlines()[0][:200]}")
            continue
        report.compiled += 1
    report.seconds = time.perf_counter() - start
    log(f"share {k} of {n}: {report.compiled} kernel versions in {report.seconds:.1f} s"
        + (f", {len(report.skipped)} skipped" if report.skipped else ""))
    return report


def record(path: Path, log: Callable[[str], None] | None = None) -> list[Entry]:
    """Write a manifest of what the warm-up compiles to ``path``: the warm-up runs, on one
    thread, in a new process with an empty temporary cache, which records every compilation
    (:func:`_record_here`). Raises RuntimeError if that process fails."""
    from cgfem.run import THREAD_COUNTS

    log = log or (lambda message: None)
    with tempfile.TemporaryDirectory(prefix="cgfem-record-") as cache:
        env = {**os.environ, **dict.fromkeys(THREAD_COUNTS, "1"), "NUMBA_CACHE_DIR": cache}
        log(f"compiling the warm-up from an empty cache into {path}")
        done = subprocess.run([sys.executable, "-c", f"from {__name__} import _record_here; _record_here({str(path)!r})"],
                              env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"recording failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    return read_manifest(path)


def _record_here(path: str) -> None:
    """Run the warm-up in this process (whose cache must be empty), recording numba's
    compilations of the package's kernels, and write the manifest to ``path``."""
    from numba.core import event

    from cgfem.warmup import warm_up

    with event.install_recorder("numba:compile") as recorder:
        warm_up()
    # a kernel's seconds leave out its package callees' compilations and keep numba's own
    # functions' (compiled once per process, by the first kernel that needs them)
    stack, done = [], {}          # stack: [key, start, package callees' time]; done: key -> seconds
    for stamp, ev in recorder.buffer:
        key = (ev.data["dispatcher"], tuple(ev.data["args"]))
        if ev.is_start:
            stack.append([key, stamp, 0.0])
            continue
        key, begun, inner = stack.pop()
        elapsed = stamp - begun
        ours = in_package(key[0])
        if stack and ours:
            stack[-1][2] += elapsed
        if ours and key not in done:
            done[key] = elapsed - inner
    entries = []
    for (dispatcher, args), seconds in done.items():
        try:
            entries.append(Entry(kernel_name(dispatcher), format_types(args), seconds))
        except TypeError:           # a type without a manifest form: compiled at its first call
            pass
    called = {e.kernel for e in entries}
    entries += [Entry(name) for name in sorted(package_kernels()) if name not in called]
    write_manifest(entries, Path(path))
