"""Calls between the package's kernels, typed without literal arguments.

numba types a call from one kernel to another on the argument types as its inference first
sees them, literal values included: ``f(x, 1)`` and ``f(x, 2)`` compile ``f`` twice, for
``Literal[int](1)`` and ``Literal[int](2)``, and a variable first assigned a constant
(``n = 0``, later a computed ``int64``) compiles a ``Literal[int](0)`` version of every
kernel it is passed to before inference settles on ``int64``, a version nothing then calls.
Each version is a whole compilation of the callee and of what it inlines, and the on-disk
cache keeps them all. No kernel of this package dispatches on a literal value, so
:func:`install` makes numba type calls to the kernels of ``cgfem`` modules on
:func:`numba.core.types.unliteral` argument types: one version per array layout and scalar
type. Kernels of other packages, and calls from Python (whose arguments never carry
literal types), are left as numba types them.

The machine code does not change (a literal argument is not folded into arithmetic without
``fastmath``), only how many versions are compiled: a cold ``cgfem warmup`` compiles in
about 15 % less time (docs/performance.md, "Compilation").

:func:`install` runs when :mod:`cgfem` is imported, before any kernel is compiled.
"""

from __future__ import annotations

from numba.core import dispatcher, types

from cgfem._numba_cache import PACKAGE

#: numba's own method, which the replacement calls with the arguments made non-literal
_NUMBA_CALL_TEMPLATE = dispatcher.Dispatcher.get_call_template


def in_package(kernel: dispatcher.Dispatcher) -> bool:
    """Whether ``kernel`` is defined in a module of this package."""
    return getattr(kernel.py_func, "__module__", "").split(".")[0] == PACKAGE


def _call_template(self: dispatcher.Dispatcher, args: tuple, kws: dict):
    """numba's ``get_call_template`` of a call to ``self``, on non-literal argument types when
    ``self`` is a kernel of this package."""
    if in_package(self):
        args = tuple(types.unliteral(a) for a in args)
        kws = {k: types.unliteral(v) for k, v in kws.items()}
    return _NUMBA_CALL_TEMPLATE(self, args, kws)


def install() -> None:
    """Type the calls to this package's kernels on non-literal arguments (once)."""
    dispatcher.Dispatcher.get_call_template = _call_template
