"""A cached kernel never runs an outdated kernel of another module (cgfem._numba_cache).

The package is copied into a temporary directory together with three probe modules,
``caller -> middle -> callee`` (each calls the next one's kernel) and an ``unrelated`` one;
every run is a fresh interpreter with ``PYTHONPATH`` on the copy and its own
``NUMBA_CACHE_DIR``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import cgfem

PROBES = {
    "_probe_callee.py": """
        from numba import njit

        @njit(cache=True)
        def callee(x):
            return 2.0 * x
    """,
    "_probe_middle.py": """
        from numba import njit

        from cgfem._probe_callee import callee

        @njit(cache=True)
        def middle(x):
            return callee(x) + 1.0
    """,
    "_probe_caller.py": """
        from numba import njit

        from cgfem import _probe_middle

        @njit(cache=True)
        def caller(x):
            return 10.0 * _probe_middle.middle(x)
    """,
    "_probe_unrelated.py": """
        from numba import njit

        @njit(cache=True)
        def unrelated(x):
            return x - 1.0
    """,
}

RUN = """
import json
import cgfem
from cgfem._probe_caller import caller
from cgfem._probe_unrelated import unrelated
values = [caller(3.0), unrelated(3.0)]
stats = [caller.stats, unrelated.stats]
print(json.dumps({"file": cgfem.__file__, "values": values,
                  "hits": [sum(s.cache_hits.values()) for s in stats],
                  "misses": [sum(s.cache_misses.values()) for s in stats]}))
"""


@pytest.fixture()
def package_copy(tmp_path: Path) -> Path:
    root = tmp_path / "src"
    shutil.copytree(Path(cgfem.__file__).parent, root / "cgfem",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    for name, text in PROBES.items():
        (root / "cgfem" / name).write_text(textwrap.dedent(text))
    return root


def _run(root: Path, cache: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(root), NUMBA_CACHE_DIR=str(cache))
    env.pop("NUMBA_DISABLE_JIT", None)
    env.pop("NUMBA_CACHE_LOCATOR_CLASSES", None)
    out = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True, text=True,
                         timeout=120, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_callee_change_recompiles_its_callers_only(package_copy: Path, tmp_path: Path) -> None:
    cache = tmp_path / "numba_cache"
    first = _run(package_copy, cache)
    assert Path(first["file"]).is_relative_to(package_copy)  # the copy, not the installed one
    assert first["values"] == [70.0, 2.0]  # 10 (2 x + 1), x - 1 at x = 3
    assert first["misses"] == [1, 1] and first["hits"] == [0, 0]
    assert list(cache.rglob("_probe_caller.caller-*.nbi")), "nothing was written to NUMBA_CACHE_DIR"

    second = _run(package_copy, cache)  # nothing changed: both load from the cache
    assert second["values"] == first["values"]
    assert second["hits"] == [1, 1] and second["misses"] == [0, 0]

    # change the callee two imports away; keep the length of the file so that neither its
    # size nor (numba's own stamp) the caller's file tells the change
    callee = package_copy / "cgfem" / "_probe_callee.py"
    text = callee.read_text()
    callee.write_text(text.replace("2.0 * x", "3.0 * x"))
    third = _run(package_copy, cache)
    assert third["values"] == [100.0, 2.0]  # 10 (3 x + 1): the new callee runs
    assert third["misses"][0] == 1 and third["hits"][0] == 0  # the caller was recompiled
    assert third["hits"][1] == 1  # the unrelated kernel still loads from the cache

    fourth = _run(package_copy, cache)  # the recompiled caller is cached again
    assert fourth["values"] == third["values"]
    assert fourth["hits"] == [1, 1]


def test_dependency_closure_follows_package_imports() -> None:
    from cgfem import _numba_cache as nc

    closure = nc.dependency_closure("cgfem.embedding._column_kernels")
    assert {"cgfem.embedding._cone_kernels", "cgfem.embedding._face_kernels"} <= set(closure)
    assert "cgfem.geometry.query" not in closure
    assert nc.source_digest("cgfem.embedding._column_kernels") != nc.source_digest(
        "cgfem.embedding._face_kernels")


def test_import_lines_find_what_the_whole_syntax_tree_finds() -> None:
    """Every module of the package: the imports read from its import lines alone are those of
    its whole syntax tree (module level, in functions, relative, parenthesized over lines)."""
    import ast
    import pkgutil

    from cgfem import _numba_cache as nc

    names = ["cgfem"] + [m.name for m in pkgutil.walk_packages(cgfem.__path__, "cgfem.")]
    checked = [n for n in names if nc.module_file(n) is not None]
    assert len(checked) > 100
    for name in checked:
        whole = ast.parse(nc.module_file(name).read_bytes())
        assert nc.imported_modules(name) == nc.modules_imported_by(whole, name), name


def test_import_statements_of_tricky_sources() -> None:
    """Parenthesized names over lines with comments, an import in a function, two imports
    on a line, and prose in a docstring that starts like an import."""
    from cgfem import _numba_cache as nc

    source = textwrap.dedent('''
        """Docs.

        import the case first, then
        from here on import nothing.
        """
        from cgfem.solve import (newton,  # the solver
                                 outer)
        import numpy as np, cgfem.run

        def f():
            from .contact import pair
            return pair
    ''').encode()
    tree = nc.import_statements(source)
    import ast

    got = [ast.unparse(node) for node in tree.body]
    assert got == ["from cgfem.solve import newton, outer", "import numpy as np, cgfem.run",
                   "from .contact import pair"]
