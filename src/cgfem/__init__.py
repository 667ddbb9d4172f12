"""cgfem: contact mechanics in the Cartesian grid finite element method.

Stages, each a subpackage with a small typed interface (data flows one way):

- :mod:`cgfem.case` — case files (YAML) validated and loaded into frozen dataclasses;
- :mod:`cgfem.geometry` — exact NURBS boundary representation of each body;
- :mod:`cgfem.embedding` — Cartesian grids, cut-cell volume and boundary quadrature;
- :mod:`cgfem.fem` — the H8 field of each body and every term acting on it;
- :mod:`cgfem.contact` — contact pairs, surface definitions, gap, residual and tangent;
- :mod:`cgfem.solve` — load steps, the outer loop, Newton and the linear solvers;
- :mod:`cgfem.run` and :mod:`cgfem.results` — from a case file to the result files;
- :mod:`cgfem.report` and :mod:`cgfem.reference` — figures, claims and the planar reference;
- :mod:`cgfem.cli` — the ``cgfem`` command line.

The methods and the reasons behind them are described in docs/methods/ (geometry and
embedding, elasticity, contact); the evidence in docs/validation.md.

Importing the package first installs :mod:`cgfem._numba_cache`, which stamps every cached
numba kernel with the sources of its module and of every ``cgfem`` module it imports (so a
cached kernel never runs an outdated callee of another module), and
:mod:`cgfem._numba_calls`, which types calls between the package's kernels on non-literal
argument types (one compiled version per argument type, not one per constant passed).
"""

from cgfem import _numba_cache, _numba_calls

_numba_cache.install()
_numba_calls.install()

from cgfem.errors import InputError  # noqa: E402  (after the cache locator, on purpose)

__all__ = ["InputError", "__version__"]
__version__ = "0.1.0"
