"""numba's on-disk cache, made aware of the kernels' imports.

numba (``@njit(cache=True)``) stamps a cached kernel with its own source file only. A
kernel that calls a kernel of another module is compiled together with it (inlined into
one machine-code library), so after an update of the callee's module the cached caller
would keep running the old callee. This module replaces the stamp of every kernel defined
in a ``cgfem`` module by a digest of that module's source **and** of the sources of every
``cgfem`` module it imports, transitively (imports are read with :mod:`ast`, wherever they
stand in the module, ``from a import b`` counting submodule ``a.b`` too). A change of a
module therefore invalidates exactly the cached kernels of the modules that depend on it;
every other kernel still loads from the cache.

Where the cache lives is unchanged: ``NUMBA_CACHE_DIR`` if the user set it, otherwise the
``__pycache__`` next to the module, otherwise numba's user-wide cache directory (numba's own
locators are asked, in numba's order, and only the stamp is replaced). Kernels outside
``cgfem`` are left to numba. ``NUMBA_CACHE_LOCATOR_CLASSES`` (numba's override of the
locator list) bypasses this module; add ``cgfem._numba_cache.DependencyStampLocator`` in
front of that list to keep it.

:func:`install` runs when :mod:`cgfem` is imported, before any kernel module: a kernel
built with ``cache=True`` picks its locator when it is decorated.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import re
from pathlib import Path

from numba.core import caching

#: Directory of the ``cgfem`` package (its ``__init__.py``).
PACKAGE_DIR = Path(__file__).resolve().parent
PACKAGE = PACKAGE_DIR.name
#: numba's locators that the stamp is grafted onto, in numba's order of preference.
_FILE_LOCATORS = (caching.UserProvidedCacheLocator, caching.InTreeCacheLocator,
                  caching.UserWideCacheLocator)


@functools.lru_cache(maxsize=None)
def module_file(name: str) -> Path | None:
    """Source file of the ``cgfem`` module ``name`` (dotted), or ``None`` if it is none."""
    parts = name.split(".")
    if parts[0] != PACKAGE:
        return None
    base = PACKAGE_DIR.joinpath(*parts[1:])
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def module_name(path: Path) -> str:
    """Dotted name of the module in file ``path`` (inside the package)."""
    rel = path.resolve().relative_to(PACKAGE_DIR).with_suffix("")
    parts = [PACKAGE, *rel.parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


#: a statement that may be an import: ``import ...`` or ``from ... import ...`` at the start of
#: a line, a parenthesized name list to its closing parenthesis, else to the end of the line
_IMPORT_LINE = re.compile(rb"^[ \t]*(?:from[ \t]+[.\w]+[ \t]+import[ \t]*(?:\([^)]*\)|[^\n;]*)|import[ \t]+[^\n;]*)",
                          re.MULTILINE)


def import_statements(source: bytes) -> ast.Module:
    """The import statements of a module's ``source``, as one parsed module: each line that
    starts like an import (:data:`_IMPORT_LINE`, wherever it is indented) parsed alone; a
    line that does not parse is not an import (prose in a docstring). Not followed: a
    backslash continuation of an import, a second statement after ``;`` (the package
    writes neither). A kernel module's stamp is computed in every process that imports it,
    and these lines parse far faster than the whole module; they give what
    :func:`ast.walk` over the whole module gives (checked for every module of the package
    in ``tests/unit/test_numba_cache.py``)."""
    tree = ast.Module(body=[], type_ignores=[])
    for match in _IMPORT_LINE.finditer(source):
        try:
            tree.body.extend(ast.parse(match.group(0).strip()).body)
        except SyntaxError:
            continue
    return tree


@functools.lru_cache(maxsize=None)
def imported_modules(name: str) -> tuple[str, ...]:
    """The ``cgfem`` modules that module ``name`` imports directly (sorted), read from its
    import lines (:func:`import_statements`)."""
    return modules_imported_by(import_statements(module_file(name).read_bytes()), name)


def modules_imported_by(tree: ast.AST, name: str) -> tuple[str, ...]:
    """The ``cgfem`` modules other than ``name`` that the import statements anywhere in
    ``tree`` (a parse of module ``name``) import (sorted): ``from a import b`` counts ``a``
    and submodule ``a.b``; relative imports are resolved against ``name``'s package."""
    is_package = module_file(name).name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                anchor = name.split(".")
                drop = node.level - 1 if is_package else node.level
                anchor = anchor[:len(anchor) - drop] if drop else anchor
                base = ".".join(anchor + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
        else:
            continue
        found.update(t for t in targets if module_file(t) is not None and t != name)
    return tuple(sorted(found))


def dependency_closure(name: str) -> tuple[str, ...]:
    """``name`` and every ``cgfem`` module it imports, transitively (sorted)."""
    seen = {name}
    todo = [name]
    while todo:
        for dep in imported_modules(todo.pop()):
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return tuple(sorted(seen))


@functools.lru_cache(maxsize=None)
def file_digest(name: str) -> bytes:
    """SHA-256 of the source file of module ``name`` (read once per process)."""
    return hashlib.sha256(module_file(name).read_bytes()).digest()


@functools.lru_cache(maxsize=None)
def source_digest(name: str) -> str:
    """SHA-256 (hex) of the sources of module ``name`` and of its dependency closure."""
    h = hashlib.sha256()
    for dep in dependency_closure(name):
        h.update(dep.encode())
        h.update(b"\0")
        h.update(file_digest(dep))
    return h.hexdigest()


class DependencyStampLocator(caching._CacheLocator):
    """Cache locator of the kernels of ``cgfem`` modules: numba's locator for the file (so
    the same cache directory), with :func:`source_digest` of the module as source stamp."""

    def __init__(self, inner: caching._CacheLocator, name: str):
        self._inner = inner
        self._module = name

    def ensure_cache_path(self):
        self._inner.ensure_cache_path()

    def get_cache_path(self):
        return self._inner.get_cache_path()

    def get_source_stamp(self):
        return ("cgfem-deps", source_digest(self._module))

    def get_disambiguator(self):
        return self._inner.get_disambiguator()

    @classmethod
    def from_function(cls, py_func, py_file):
        try:
            name = module_name(Path(py_file))
        except ValueError:  # not a file of this package: numba's own locators decide
            return None
        if module_file(name) is None:
            return None
        for locator_class in _FILE_LOCATORS:
            inner = locator_class.from_function(py_func, py_file)
            if inner is not None:
                return cls(inner, name)
        return None


def install() -> None:
    """Put :class:`DependencyStampLocator` first in numba's list of cache locators (once)."""
    classes = caching.CacheImpl._locator_classes
    if DependencyStampLocator not in classes:
        classes.insert(0, DependencyStampLocator)
