"""Newton's linear solves: the path a system's matrices take, and what is kept between them.

:class:`LinearSolves` is what Newton calls as ``solve(K, b, rtol)``. Two paths:

- **direct**: the backend :mod:`cgfem.solve.backends` chooses (pardiso, superlu, pyamg for
  large symmetric systems without contact, the reduced saddle solver of ``nurbs_fit``), set up
  once per matrix and kept while Newton passes the same matrix object (or, in modified
  Newton, while ``frozen``);
- **krylov** (``linear: auto`` on a symmetric system of at least ``policy.krylov_min_dofs``
  unknowns, a non-symmetric one (contact in finite strain) of at least
  ``policy.krylov_nonsymmetric_min_dofs``, ``policy.krylov_order2_min_dofs`` with
  triquadratic elements,
  ``policy.krylov_floating_min_dofs`` with a body held by contact alone, a saddle point of at
  least ``policy.krylov_saddle_min_dofs``): CG or GMRES preconditioned by
  smoothed-aggregation AMG with the rigid-body modes (:mod:`cgfem.solve.krylov`); a saddle
  point (``nurbs_fit``) is solved on the bodies' dofs with the AMG of its reduced matrix
  (:mod:`cgfem.solve.saddle`). The preconditioner is kept across Newton
  iterations, outer passes and load steps while a solve with it converges in at most
  :meth:`LinearSolves.kept_limit` iterations (``policy.krylov_refresh``, or more when a fresh
  preconditioner needed more per decade of residual: the elements of order 2); past that
  the solve is repeated with a preconditioner
  of the current matrix, and a solve that stalls even then (``policy.krylov_max_iterations``)
  falls back to a factorization of that matrix (a saddle point's reduced one), and of the
  next ``policy.krylov_stall_direct`` matrices too. The tolerance is inexact Newton's
  (:func:`cgfem.solve.newton.forcing_rtol`), never tighter than ``policy.krylov_rtol``.

PARDISO's factors are in single precision, refined in double, where ``policy.factor_precision``
asks for it and no body is held by contact alone; once a matrix of the system needs its
factorization again in double precision, every later one gets double factors at once.

Every choice is logged: the path and backend once, and per Krylov solve its iterations and
whether the preconditioner was kept, refreshed, or the solve fell back; factors in double
precision after single ones fell short.
"""

from __future__ import annotations

import time
import weakref
from typing import Callable

import numpy as np
import scipy.sparse as sp

from cgfem.solve.backends import choose_backend, factorize
from cgfem.solve.krylov import AMGPreconditioner
from cgfem.solve.saddle import ReducedSaddleSolver, reduced_saddle
from cgfem.solve import linear
from cgfem.solve.linear import LinearSolverError
from cgfem.solve.policy import DEFAULT_POLICY, SolverPolicy

DIRECT, KRYLOV = "direct", "krylov"
#: the relative residual of a reduced saddle point's solve in :meth:`LinearSolves.again`
AGAIN_RTOL = 1e-6


def solve_path(backend: str, n: int, policy: SolverPolicy = DEFAULT_POLICY, saddle: bool = False,
               floating: bool = False, order: int = 1, symmetric: bool = True) -> str:
    """:data:`KRYLOV` for ``auto`` on a ``saddle`` point (``nurbs_fit``'s, reduced to the
    bodies' dofs) of at least ``policy.krylov_saddle_min_dofs`` unknowns, on any other of at
    least ``policy.krylov_min_dofs`` (elements of ``order`` 1, ``symmetric``),
    ``policy.krylov_nonsymmetric_min_dofs`` (``order`` 1, not ``symmetric``: contact in
    finite strain) or ``policy.krylov_order2_min_dofs`` (``order`` 2) and, with a body held
    by contact alone (``floating``), of at least ``policy.krylov_floating_min_dofs`` too;
    else :data:`DIRECT`."""
    if saddle:
        least = policy.krylov_saddle_min_dofs
    elif order != 1:
        least = policy.krylov_order2_min_dofs
    elif symmetric:
        least = policy.krylov_min_dofs
    else:
        least = policy.krylov_nonsymmetric_min_dofs
    if floating and not saddle:
        least = max(least, policy.krylov_floating_min_dofs)
    return KRYLOV if backend == "auto" and n >= least else DIRECT


class LinearSolves:
    """Linear solves of one system's Newton matrices (n, n).

    ``backend``: the case's ``solver.linear`` (``auto`` or a backend name); ``near_null``
    (n, k): the rigid-body modes of every body (AMG); ``symmetric``, ``indefinite`` (a saddle
    point), ``saddle``, ``floating`` (a body held by contact alone), ``order`` (the elements'):
    the system's structure (:class:`~cgfem.solve.system.System`).
    Failures raise :class:`~cgfem.solve.linear.LinearSolverError`, which Newton reports."""

    def __init__(self, backend: str, near_null: np.ndarray, symmetric: bool = True, indefinite: bool = False,
                 saddle: tuple | None = None, policy: SolverPolicy = DEFAULT_POLICY,
                 log: Callable[[str], None] | None = None, floating: bool = False, order: int = 1):
        self.backend, self.near_null, self.symmetric = backend, near_null, symmetric
        self.indefinite, self.saddle, self.policy = indefinite, saddle, policy
        self.floating, self.order = floating, order
        self.log = log or (lambda message: None)
        #: the last matrix set up (a weak reference: Newton lets it go once solved, and a
        #: solver that needs it again holds it itself) and its solver
        self._key: weakref.ref | None = None
        self._factor = None
        #: modified Newton: the last setup serves for a new matrix (or for None)
        self.frozen = False
        #: the Krylov path's kept preconditioner, and whether it was built on the current matrix
        self._amg: AMGPreconditioner | ReducedSaddleSolver | None = None
        self._fresh = False
        #: iterations per decade of residual of the last solve with a fresh preconditioner
        self._per_decade: float | None = None
        self._logged = False
        #: matrices still to factorize directly after a stall (``policy.krylov_stall_direct``)
        self._direct_left = 0
        self._n = None
        #: PARDISO's factors in single precision (refined in double) until one falls short
        self.single = policy.factor_precision == "single" and not floating
        #: per solve: (path, iterations, what happened) for the benchmarks and the tests
        self.history: list[tuple[str, int, str]] = []

    @classmethod
    def of(cls, system, backend: str, log: Callable[[str], None] | None = None) -> "LinearSolves":
        """The solves of ``system``'s matrices with the case's ``backend``; ``ValueError`` if
        that backend cannot solve them."""
        choose_backend(system.n_dofs, system.symmetric, backend, system.indefinite)
        solves = cls(backend, system.near_null(), system.symmetric, system.indefinite, system.saddle(),
                     system.policy, log, system.held_by_contact_alone(), system.order)
        solves._n = system.n_dofs
        return solves

    @property
    def factorizes(self) -> bool:
        """Whether the matrices are factorized (the direct path), so that modified Newton's
        solves with a kept factorization are cheap; on the Krylov path a solve with the last
        matrix costs as much as one with a new matrix, and full Newton converges faster."""
        return self._n is None or self.path(self._n) == DIRECT

    def path(self, n: int) -> str:
        """The path of a system of ``n`` unknowns (:func:`solve_path`); a saddle point whose fit
        constraints are not given is factorized whole (:data:`DIRECT`)."""
        if self.indefinite and self.saddle is None:
            return DIRECT
        return solve_path(self.backend, n, self.policy, self.indefinite, self.floating, self.order,
                          self.symmetric)

    def __call__(self, K: sp.csr_matrix | None, b: np.ndarray, rtol: float | None = None) -> np.ndarray:
        """The solution of ``K x = b``; ``rtol``: the relative residual an iterative solve may
        stop at (inexact Newton). ``K`` None (modified Newton): the last matrix."""
        n = self._n = b.shape[0]
        if self.path(n) == KRYLOV:
            return self._krylov(K, b, rtol)
        if not self._is_last(K) and not (self.frozen and self._factor is not None):
            # the last matrix's solver lends its analysis where the pattern allows (and cannot
            # solve afterwards)
            previous, self._factor = self._factor, None
            self._factor = factorize(K, backend=self.backend, symmetric=self.symmetric,
                                     near_null=self.near_null, indefinite=self.indefinite, saddle=self.saddle,
                                     reuse=previous, order=self.order, single=self.single)
            self._key = weakref.ref(K)
            if not self._logged:
                self._logged = True
                precision = self._factor.info.get("precision")
                factors = f" ({precision} precision factors)" if precision else ""
                self.log(f"linear: direct, {self._factor.backend}{factors}, {n} unknowns")
        x = self._factor.solve(b, rtol)
        self._check_precision()
        self.history.append((DIRECT, int(self._factor.info["iterations"][-1]), self._factor.backend))
        return x

    def _check_precision(self) -> None:
        """Double factors from now on if the last factorization had to be repeated in double
        precision (logged once)."""
        if self.single and self._factor.info.get("precision") == "double after single":
            self.single = False
            self.log("linear: single-precision factors fell short of the residual check; "
                     "factorized again in double precision, and so from now on")

    def _is_last(self, K: sp.csr_matrix | None) -> bool:
        """Whether ``K`` is the matrix last set up (None: the one a frozen solve keeps)."""
        last = self._key() if self._key is not None else None
        return last is K

    def again(self, b: np.ndarray) -> np.ndarray:
        """``b`` (n,) solved with the last matrix's factorization on the direct path, without a
        new set-up or the residual check (a reduced saddle point to :data:`AGAIN_RTOL`): the
        floating bodies' cut rotations (:meth:`~cgfem.solve.floating.FloatingBodies.limit`),
        whose right-hand sides are rigid rotations of a body the matrix barely holds. Factors
        in single precision are refined and checked as by a solve (their own solution is good
        to about ``1e-7`` only)."""
        factor = self._factor
        if factor is None or not self.factorizes:
            raise LinearSolverError("no factorization to solve with again")
        if isinstance(factor, ReducedSaddleSolver):
            return factor.iterate(b, AGAIN_RTOL, self.policy.krylov_max_iterations)[0]
        unchecked = getattr(factor, "solve_unchecked", None)
        if unchecked is None or factor.info.get("precision") == "single":
            return factor.solve(b)
        return unchecked(b)

    def _krylov(self, K: sp.csr_matrix | None, b: np.ndarray, rtol: float | None) -> np.ndarray:
        """The Krylov path (module docstring)."""
        p = self.policy
        if K is None or (self.frozen and self._key is not None):
            K = self._key() if self._key is not None else None
            if K is None:
                raise LinearSolverError("the last matrix is gone: nothing to solve with")
        if not self._is_last(K):
            previous = self._factor
            self._key, self._factor, self._fresh = weakref.ref(K), None, False
            if self._direct_left > 0:       # a stall not long ago: factorized as well
                self._direct_left -= 1
                self._factor = self._factorize(K, previous)
                self.history.append((DIRECT, 0, "after a stall"))
                self.log(f"linear: {self._factor.backend} after a stall ({self._direct_left} more matrices)")
                return self._factor.solve(b)
        if self._factor is not None:        # this matrix was factorized after a stall
            self.history.append((DIRECT, 0, "fallback kept"))
            return self._factor.solve(b)
        target = max(p.krylov_rtol, rtol if rtol is not None else 0.0)
        kind = "cg" if self.symmetric else "gmres"
        tic = time.perf_counter()
        note = "kept"
        total, res, ok = 0, float("nan"), False
        try:
            if self._amg is None:
                self._refresh(K)
                note = "new"
            fresh = self._fresh
            x, its, res, ok = self._amg.krylov(K, b, target,
                                               p.krylov_max_iterations if fresh else self.kept_limit(target))
            total = its
            if not ok and not fresh:
                self._refresh(K)
                note = f"refreshed after {its}"
                x, its, res, ok = self._amg.krylov(K, b, target, p.krylov_max_iterations, x0=x)
                total += its
                fresh = True
            # the fresh iterations over the decades of the whole solve (from |b|, also where a
            # kept attempt went first): the rate measured with the kept one's share counted in
            # keeps the limit lower (docs/performance.md, "The Krylov path")
            if ok and fresh and 0.0 < res < 1.0 and its > 0:
                self._per_decade = its / np.log10(1.0 / res)
        except LinearSolverError as err:      # a breakdown (an indefinite matrix for CG), NaN
            self._amg, ok = None, False
            note = str(err)
        if ok:
            self.history.append((KRYLOV, total, note))
            self.log(f"linear: {kind} {total} iterations to {res:.1e} (target {target:.1e}; preconditioner "
                     f"{note}; {time.perf_counter() - tic:.2f} s)")
            return x
        # the hierarchy that stalled goes first: the factorization needs its memory (chain3
        # at level 3 with nurbs_fit peaked at 14.3 GB holding both)
        self._amg = None
        self._factor = self._factorize(K, None)
        self._direct_left = p.krylov_stall_direct
        self.history.append((DIRECT, total, "fallback"))
        self.log(f"linear: {kind} stalled at {res:.1e} after {total} iterations (target {target:.1e}; {note}); "
                 f"fell back to {self._factor.backend} for this matrix and the next {self._direct_left}")
        return self._factor.solve(b)

    def _factorize(self, K: sp.csr_matrix, previous: linear.LinearSolver | None) -> linear.LinearSolver:
        """The Krylov path's direct solver of ``K`` (after a stall): PARDISO (else SuperLU),
        for a saddle point on its reduced matrix; ``previous``: the last such solver, whose
        analysis it may take (:func:`cgfem.solve.backends.factorize`)."""
        direct = "pardiso" if "pardiso" in linear.available_backends() else "superlu"
        if self.saddle is not None:
            # the saddle point's reduced matrix factorized as its preconditioner
            return reduced_saddle(K, self.saddle[0], self.saddle[1], self.symmetric, self.near_null,
                                  preconditioner=direct, reuse=previous)
        return factorize(K, backend=direct, symmetric=self.symmetric, reuse=previous, single=self.single)

    def kept_limit(self, target: float) -> int:
        """The iterations a solve to the relative residual ``target`` may take with a kept
        preconditioner before it is rebuilt: ``policy.krylov_refresh``, or
        ``policy.krylov_refresh_rate`` times the iterations per decade of residual of the last
        solve that ended with a fresh preconditioner (its fresh iterations over the decades
        from ``|b|``) times the decades ``target`` asks for, whichever is more."""
        p = self.policy
        if self._per_decade is None or not 0.0 < target < 1.0:
            return p.krylov_refresh
        rated = int(np.ceil(p.krylov_refresh_rate * self._per_decade * np.log10(1.0 / target)))
        return max(p.krylov_refresh, rated)

    def _refresh(self, K: sp.csr_matrix) -> None:
        """A preconditioner of ``K``, kept for the matrices that follow: AMG of ``K``, or of a
        saddle point's reduced matrix (:mod:`cgfem.solve.saddle`)."""
        self._amg = None                    # free the old hierarchy first
        if self.saddle is not None:
            self._amg = reduced_saddle(K, self.saddle[0], self.saddle[1], self.symmetric, self.near_null,
                                       self.policy.krylov_rtol, preconditioner="pyamg")
        else:
            self._amg = AMGPreconditioner(K, self.near_null, self.symmetric)
        self._fresh = True
