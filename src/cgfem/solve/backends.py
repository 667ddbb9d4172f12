"""Which linear solver a system gets, and the one call that sets it up.

This module chooses between the backends of :mod:`cgfem.solve.linear` and the reduced
saddle-point solver of :mod:`cgfem.solve.saddle` for the direct path (the Krylov path's
preconditioners are :mod:`cgfem.solve.solves`'); those two modules do not import each other.

``auto``, from ``benchmarks/bench_solvers.py`` (clamped H8 cube; 2 cores shared with other
jobs, so times vary up to 2x between runs). Seconds for setup + first solve / a re-solve:

=========  ==========  ==========  ==========  ==========  ==========
DOFs       9.5k        30k         95k         173k        286k
superlu    0.6 / 0.01  7.1 / 0.04  97 / 0.5    skipped     skipped
pardiso    0.1 / 0.01  0.7 / 0.07  8.8 / 0.3   28 / 0.6    52 / 0.8
pyamg      0.2 / 0.11  0.6 / 0.45  4.5 / 2.8   11 / 5.1    11 / 5.9
=========  ==========  ==========  ==========  ==========  ==========

Symmetric systems go to pardiso up to :data:`PARDISO_MAX_DOFS` (at most 2x pyamg's first
solve, ahead from its second solve, insensitive to conditioning; at 173k it needs 5 solves per
factorization to break even, at 286k 9) and to pyamg above; without pypardiso, to superlu
up to :data:`SUPERLU_MAX_DOFS` (under 1 s), then pyamg. Non-symmetric systems go to pardiso,
else superlu (pyamg only on request); so do saddle-point systems (``indefinite``: the fit
constraints of ``nurbs_fit``) up to :data:`SADDLE_DIRECT_DOFS` (triquadratic elements:
:data:`SADDLE_DIRECT_ORDER2_DOFS`), which pyamg cannot solve at all; larger ones, their
constraints given, are solved on the bodies' dofs (:mod:`cgfem.solve.saddle`). Peak memory
at 286k: pardiso 4.1 GB, pyamg 0.9 GB.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from cgfem.solve import linear
from cgfem.solve.linear import BACKENDS, LinearSolver, LinearSolverError
from cgfem.solve.saddle import reduced_saddle

PARDISO_MAX_DOFS = 100_000  #: largest symmetric system ``auto`` sends to pardiso
SUPERLU_MAX_DOFS = 10_000  #: largest symmetric system ``auto`` sends to superlu (no pardiso)
#: largest symmetric saddle point factorized whole when it cannot be reduced (its fit
#: constraints not given, or a backend requested): planar nurbs_fit at 69k unknowns peaked
#: at 3.8 GB, at 470k it passed 23 GB and was killed; chain2_steel at level 3, 171k body
#: dofs, was killed at 14 GB where nurbs_fe peaks at 7 GB
SADDLE_MAX_DOFS = 150_000
#: above this many unknowns a saddle point with its fit constraints known is solved on the
#: bodies' dofs (:mod:`cgfem.solve.saddle`) instead of factorized whole: chain3 at level 1
#: (20.7k unknowns), 2.9 s whole (23M factor entries) against 2.4 s reduced (3.8M, 11 GMRES
#: iterations); the whole run 27.5 s against 19.4 s
SADDLE_DIRECT_DOFS = 20_000
#: the same for triquadratic elements, whose own couplings fill the factor more and the fit's
#: less (its spans are the grid's, its unknowns a smaller share): chain3 at order 2, level 0
#: (20.1k unknowns, 3.3k of them the fit's), 32M factor entries whole against 9.8M reduced,
#: the run's solve 79 s whole against 126 s reduced at the same peak (2.3 GB), three
#: Krylov solves of the reduced system per cut rotation (:meth:`LinearSolves.again`) taking
#: 28 % of it. Order-2 saddle points on the direct path above this size hold a floating
#: body (``krylov_floating_min_dofs``)
SADDLE_DIRECT_ORDER2_DOFS = 40_000


def choose_backend(n_dofs: int, symmetric: bool, requested: str = "auto",
                   indefinite: bool = False) -> str:
    """The backend for a system of ``n_dofs`` unknowns (see the module docstring).
    ``indefinite``: a saddle-point system (zero diagonal block), which pyamg cannot solve:
    pardiso, else superlu."""
    if requested != "auto" and requested not in BACKENDS:
        raise ValueError(f"unknown linear solver backend {requested!r}; "
                         f"choose one of {', '.join(BACKENDS)} or 'auto'")
    have = linear.available_backends()
    if requested != "auto":
        if requested not in have:
            raise ValueError(f"linear solver backend {requested!r} is not available "
                             "(pypardiso does not import)")
        if indefinite and requested == "pyamg":
            raise ValueError("linear solver backend 'pyamg' cannot solve the saddle-point system of "
                             "the nurbs_fit surface definition; choose pardiso, superlu or auto")
        return requested
    if not symmetric or indefinite:
        return "pardiso" if "pardiso" in have else "superlu"
    if "pardiso" in have:
        return "pardiso" if n_dofs <= PARDISO_MAX_DOFS else "pyamg"
    return "superlu" if n_dofs <= SUPERLU_MAX_DOFS else "pyamg"


def factorize(A: sp.spmatrix, *, backend: str = "auto", symmetric: bool = True,
              near_null: np.ndarray | None = None, rtol: float = 1e-10,
              indefinite: bool = False, saddle: tuple | None = None,
              reuse: LinearSolver | None = None, order: int = 1, single: bool = False) -> LinearSolver:
    """Factorize (superlu, pardiso) or build the AMG hierarchy (pyamg) of the square matrix
    ``A``. ``near_null`` (e.g. :func:`rigid_body_modes`) and ``rtol`` (relative residual)
    serve pyamg only; ``indefinite``: a saddle-point matrix (:func:`choose_backend`).
    ``saddle``: ``(n_u, constraints)`` of nurbs_fit's saddle point
    (:mod:`cgfem.solve.saddle`): with ``auto``, one above :data:`SADDLE_DIRECT_DOFS`
    (:data:`SADDLE_DIRECT_ORDER2_DOFS` for elements of ``order`` 2) is solved on the
    bodies' dofs by a Krylov method preconditioned by the reduced matrix, which gets the
    backend the bodies' dofs alone would get (:func:`choose_backend`).
    ``reuse``: the solver of the system's previous matrix, no longer needed (its PARDISO
    analysis may serve this one: :func:`cgfem.solve.linear.build`). ``single``: PARDISO's
    factors in single precision, refined in double (:func:`cgfem.solve.linear.build`); not a
    reduced saddle point's preconditioner, with which the Krylov solve would take more
    iterations (25 against 40 in ``tests/unit/test_saddle.py``), each with the fit's own
    solves. Raises
    :class:`LinearSolverError` on a singular or non-finite matrix, ``ValueError`` on a bad
    backend name or shape."""
    if not sp.issparse(A) or A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"A must be a square sparse matrix, got {type(A).__name__} "
                         f"of shape {getattr(A, 'shape', None)}")
    name = choose_backend(A.shape[0], symmetric, backend, indefinite)
    whole = SADDLE_DIRECT_DOFS if order == 1 else SADDLE_DIRECT_ORDER2_DOFS
    if indefinite and saddle is not None and backend == "auto" and A.shape[0] > whole:
        # the whole factorization's fill is the fit constraints' (chain3 at level 2: 195M
        # factor entries with or without contact, 36M reduced), which no ordering removed
        n_u = int(saddle[0])
        return reduced_saddle(sp.csr_matrix(A, dtype=np.float64), n_u, saddle[1], symmetric, near_null,
                              max(rtol, 1e-10), preconditioner=choose_backend(n_u, symmetric), reuse=reuse)
    if indefinite and symmetric and A.shape[0] > SADDLE_MAX_DOFS:
        raise LinearSolverError(f"{name}: a symmetric saddle-point system of {A.shape[0]} unknowns "
                                f"(above {SADDLE_MAX_DOFS}) would not fit in memory factorized, and "
                                "pyamg cannot solve it")
    return linear.build(A, name, symmetric=symmetric, near_null=near_null, rtol=rtol, indefinite=indefinite,
                        reuse=reuse, single=single)
