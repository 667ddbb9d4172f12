"""cgfem: contact mechanics in the Cartesian grid finite element method.

Stages, each a subpackage with a small typed interface (data flows one way):

- :mod:`cgfem.geometry` — exact NURBS boundary representation of each body;
- :mod:`cgfem.case` — case files (YAML) validated and loaded into frozen dataclasses;
- :mod:`cgfem.cli` — the ``cgfem`` command line.

Importing the package first installs :mod:`cgfem._numba_cache`, which stamps every cached
numba kernel with the sources of its module and of every ``cgfem`` module it imports (so a
cached kernel never runs an outdated callee of another module).
"""

from cgfem import _numba_cache

_numba_cache.install()

from cgfem.errors import InputError  # noqa: E402  (after the cache locator, on purpose)

__all__ = ["InputError", "__version__"]
__version__ = "0.1.0"
