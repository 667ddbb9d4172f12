"""Iterative solution of ``nurbs_fit``'s saddle-point systems on the bodies' dofs alone.

The Newton system of :mod:`cgfem.contact.fitted` has three kinds of unknowns: the bodies'
dofs ``u``, and per fitted patch its control displacements ``Z`` and multipliers ``mu``::

    [ K     0     -s G^T ] [u ]   [b_u ]
    [ 0     Kc     s M   ] [Z ] = [b_Z ]
    [ -s G  s M    0     ] [mu]   [b_mu]

(``Kc`` the contact tangent, which only couples ``Z``). Its factorization fills several
times more than the bodies' own matrix, with or without contact, and pyamg cannot take it
at all (docs/performance.md).
``M`` is a small banded SPD matrix factorized once per patch, so ``Z`` and ``mu`` are
eliminated exactly for a given ``u``::

    Z  = M^-1 (b_mu / s + G u),     mu = M^-1 (b_Z - Kc Z) / s,
    S u = K u + C^T Kc C u = b_u + G^T M^-1 b_Z - C^T Kc M^-1 b_mu / s,    C = M^-1 G,

and the reduced operator ``S`` (dense over a contact surface if formed: it never is) is
applied matrix-free in a Krylov solver preconditioned by the sparse ``P = K + C~^T Kc C~``.
``C~`` holds the exact rows of ``C`` for the controls the contact tangent touches (only those
enter ``Kc``), each without its entries below :data:`DROP` of its largest: ``M^-1`` of a
B-spline mass matrix decays fast away from the diagonal, so a row keeps a few knot spans
around its control: ``P`` stays nearly as sparse as nurbs_fe's matrix while ``P^-1 S`` is
close to the identity (docs/methods/contact.md). ``P`` is
factorized by a direct backend (``preconditioner="pardiso"``, ``"superlu"``), which needs
the memory of the bodies' own factorization instead of the whole saddle point's, or
coarsened by the Krylov path's smoothed-aggregation AMG
(:class:`~cgfem.solve.krylov.AMGPreconditioner`), one V-cycle per iteration (``"pyamg"``,
with CG when the system is symmetric).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from cgfem.solve._sparse_kernels import leading_block
from cgfem.solve.krylov import AMGPreconditioner
from cgfem.solve.linear import LinearSolver, LinearSolverError, build, symmetric_part

#: inner iterations of one GMRES cycle
RESTART = 50

#: entries of a row of ``C = M^-1 G`` below this fraction of its largest are left out of the
#: preconditioner (the choice is measured in docs/performance.md)
DROP = 6e-2
#: rows of ``C`` computed at once (``M^-1`` applied to that many unit columns)
ROW_CHUNK = 256


@dataclass(frozen=True)
class FitConstraint:
    """One fitted patch's block of the saddle point: ``z``, ``mu`` (3 m,) global indices of
    its control displacements and multipliers, ``cols`` (3 n_nodes,) those of its body's
    dofs (node-major), ``M`` (m, m), ``G`` (m, n_nodes), ``solve_M`` (``M^-1``, per
    column of an (m, k) array), ``scale`` ``s``. ``M`` and ``G`` are fixed for a run, so
    the rows of ``C = M^-1 G`` the preconditioners ask for are computed once
    (:meth:`truncated_rows`, on the nodes ``G`` reaches: :attr:`_reached`)."""

    z: np.ndarray
    mu: np.ndarray
    cols: np.ndarray
    M: sp.csr_matrix
    G: sp.csr_matrix
    solve_M: object
    scale: float
    _rows: dict = field(default_factory=dict, repr=False, compare=False)

    @cached_property
    def _reached(self) -> tuple[np.ndarray, sp.csr_matrix]:
        """The nodes ``G`` reaches (those near the patch; sorted) and ``G`` on their columns
        (m, reached). The rows of ``C`` are zero on the other nodes, and ``G``'s product on
        these columns alone sums the same entries in the same order as on all of them."""
        reached = np.flatnonzero(np.bincount(self.G.indices, minlength=self.G.shape[1]))
        return reached.astype(self.G.indices.dtype), self.G[:, reached]

    def truncated_rows(self, controls: np.ndarray, drop: float) -> sp.csr_matrix:
        """The rows of ``C = M^-1 G`` of ``controls`` (sorted, unique), without entries
        below ``drop`` of a row's largest: (m, n_nodes), zero in the other rows. ``M`` is
        symmetric, so row ``i`` of ``M^-1`` is ``M^-1 e_i``; rows not asked for before are
        computed :data:`ROW_CHUNK` at a time and kept."""
        m, n_nodes = self.G.shape
        if controls.size == 0:
            return sp.csr_matrix((m, n_nodes))
        kept = self._rows.setdefault(drop, {})
        missing = np.array([i for i in controls.tolist() if i not in kept], np.int64)
        reached, G_reached = self._reached
        for start in range(0, missing.size, ROW_CHUNK):
            chunk = missing[start:start + ROW_CHUNK]
            E = np.zeros((m, chunk.size))
            E[chunk, np.arange(chunk.size)] = 1.0
            rows = np.asarray(G_reached.T @ self.solve_M(E)).T                    # (chunk, reached)
            rows[np.abs(rows) < drop * np.abs(rows).max(axis=1, keepdims=True)] = 0.0
            rows = sp.csr_matrix(rows)
            for k, i in enumerate(chunk.tolist()):
                a, b = rows.indptr[k], rows.indptr[k + 1]
                kept[i] = (reached[rows.indices[a:b]], rows.data[a:b].copy())
        counts = np.zeros(m + 1, np.int64)                 # row i's entries at i + 1
        counts[np.asarray(controls, np.int64) + 1] = [kept[i][0].size for i in controls.tolist()]
        indices = np.concatenate([kept[i][0] for i in controls.tolist()])
        data = np.concatenate([kept[i][1] for i in controls.tolist()])
        return sp.csr_matrix((data, indices, np.cumsum(counts)), shape=(m, n_nodes))


class ReducedSaddleSolver(LinearSolver):
    """The saddle-point system solved on ``u`` (module docstring); ``n_u`` the bodies' dofs
    (the first unknowns), ``constraints`` one :class:`FitConstraint` per fitted patch."""

    backend = "saddle-pyamg"

    def __init__(self, A: sp.csr_matrix, n_u: int, constraints: list[FitConstraint], symmetric: bool,
                 near_null: np.ndarray | None, rtol: float = 1e-10, max_iterations: int = 1000,
                 preconditioner: str = "pyamg", drop: float = DROP, reuse: LinearSolver | None = None) -> None:
        super().__init__(A.shape[0])
        if preconditioner != "pyamg":
            self.backend = f"saddle-{preconditioner}"
        #: the matrix whose system the operator is of (:meth:`krylov`)
        self._bound = A
        A = sp.csr_matrix(A)
        self.n_u, self.constraints, self.symmetric = n_u, constraints, symmetric
        self.rtol, self.max_iterations, self.drop = rtol, max_iterations, drop
        self._z = np.concatenate([c.z for c in constraints])
        self._bind(A)
        self._offsets = np.concatenate([[0], np.cumsum([c.z.size for c in constraints])])
        self._mu = np.concatenate([c.mu for c in constraints])
        self._s = np.concatenate([np.full(c.z.size, c.scale) for c in constraints])
        # the preconditioner's matrix: K + C~^T Kc C~ with C~ the truncated rows of C
        touched = np.flatnonzero(np.diff(self.Kc.indptr) > 0) if self.Kc.nnz else np.zeros(0, np.int64)
        Ct = sp.vstack([self._fit_rows(c, touched[(touched >= a) & (touched < b)] - a)
                        for c, a, b in zip(constraints, self._offsets[:-1], self._offsets[1:])]).tocsr()
        P = (self.K + Ct.T @ self.Kc @ Ct).tocsr()
        if np.any(P.diagonal() == 0.0):
            raise LinearSolverError(f"{self.backend}: zero diagonal entries in the reduced matrix")
        self._factor: LinearSolver | None = None
        # what is factorized (or coarsened): the reduced matrix, n_u x n_u
        self.info.update(factorized_n=int(n_u), factorized_nnz=int(P.nnz))
        if preconditioner != "pyamg":
            if symmetric:
                P = symmetric_part(P)
            # the preconditioner of the system's previous matrix, if given, lends its analysis
            factor = build(P, preconditioner, symmetric=symmetric,
                           reuse=reuse._factor if isinstance(reuse, ReducedSaddleSolver) else None)
            self._factor = factor
            self.info["factor_nnz"] = int(factor.info.get("factor_nnz", 0))
            self._precondition = factor.solve_unchecked
            return
        # the Krylov path's preconditioner of the bodies' matrices (symmetrized if symmetric,
        # one coarse mode set per body, aggregates within bodies), of the reduced matrix
        self._precondition = AMGPreconditioner(P, None if near_null is None else near_null[:n_u], symmetric,
                                               own=True)

    def _fit_rows(self, c: FitConstraint, rows: np.ndarray) -> sp.csr_matrix:
        """:meth:`FitConstraint.truncated_rows` of the patch's controls among its ``Z`` rows
        ``rows`` (local, node-major), per component on the global body columns: (3 m, n_u),
        zero elsewhere."""
        controls = np.unique(np.asarray(rows, np.int64) // 3)
        C3 = sp.kron(c.truncated_rows(controls, self.drop), sp.identity(3), format="coo")
        return sp.csr_matrix((C3.data, (C3.row, c.cols[C3.col])), shape=(c.z.size, self.n_u))

    # -- the fit operators on all blocks ---------------------------------------------------
    def _C(self, u: np.ndarray) -> np.ndarray:
        """``M^-1 G u`` of every block, stacked like ``Z`` (|z|,)."""
        return np.concatenate([c.solve_M(c.G @ u[c.cols].reshape(-1, 3)).ravel() for c in self.constraints])

    def _Ct(self, y: np.ndarray) -> np.ndarray:
        """``G^T M^-1 y`` of every block summed on the bodies' dofs (n_u,)."""
        out = np.zeros(self.n_u)
        for c, a, b in zip(self.constraints, self._offsets[:-1], self._offsets[1:]):
            out[c.cols] += (c.G.T @ c.solve_M(y[a:b].reshape(-1, 3))).ravel()
        return out

    def _Minv(self, y: np.ndarray) -> np.ndarray:
        return np.concatenate([c.solve_M(y[a:b].reshape(-1, 3)).ravel()
                               for c, a, b in zip(self.constraints, self._offsets[:-1], self._offsets[1:])])

    def _bind(self, A: sp.csr_matrix) -> None:
        """The operator of the system of ``A`` (CSR, the whole saddle point): its bodies' block
        ``K``, the contact tangent ``Kc`` on all fitted ``Z``, and its product."""
        n_u, z = self.n_u, self._z
        if A.has_canonical_format:
            indptr, indices, data = leading_block(A.indptr, A.indices, A.data, n_u)
            self.K = sp.csr_matrix((data, indices, indptr), shape=(n_u, n_u))
        else:
            self.K = A[:n_u][:, :n_u].tocsr()
        self.Kc = A[z][:, z].tocsr()
        self._matvec = A.dot

    def iterate(self, b: np.ndarray, rtol: float, max_iterations: int, x0: np.ndarray | None = None,
                rounds: int = 4) -> tuple[np.ndarray, int, float]:
        """Solve ``A x = b`` (n,) on the bodies' dofs (module docstring) from ``x0`` (its
        bodies' part is used; zero if None) until the whole system's relative residual
        ``|b - A x| / |b|`` is at most ``rtol`` or ``max_iterations`` Krylov iterations:
        ``(x, iterations, residual)``. The reduced method runs at most ``rounds`` times, its own
        test tightened each time while the whole residual is above ``rtol``."""
        n_u, z = self.n_u, self._z
        mu, s = self._mu, self._s
        norm_b = float(np.linalg.norm(b))
        if norm_b == 0.0:
            return np.zeros(self.n), 0, 0.0
        b_u, b_Z, b_mu = b[:n_u], b[z], b[mu]
        w = self._Minv(b_mu / s)                                    # M^-1 b_mu / s
        rhs = b_u + self._Ct(b_Z) - self._Ct(self.Kc @ w)
        S = spla.LinearOperator((n_u, n_u), matvec=lambda v: self.K @ v + self._Ct(self.Kc @ self._C(v)))
        Pinv = spla.LinearOperator((n_u, n_u), matvec=self._precondition)
        count = [0]

        def callback(*_):
            count[0] += 1
        norm_rhs = float(np.linalg.norm(rhs))
        if norm_rhs == 0.0:
            x = self._whole(np.zeros(n_u), w, b_Z)
            return x, 0, float(np.linalg.norm(b - self._matvec(x))) / norm_b
        # the residual of the bodies' rows is the whole system's (Z and mu are exact given
        # u), measured against b: a stiff contact tangent makes rhs much larger than b
        reduced = rtol * min(1.0, norm_b / norm_rhs)
        u = None if x0 is None else np.array(x0[:n_u], dtype=np.float64)
        x, residual = np.zeros(self.n), np.inf
        for _ in range(rounds):
            left = max_iterations - count[0]
            if left <= 0:
                break
            if self.symmetric and self.backend == "saddle-pyamg":
                u, _ = spla.cg(S, rhs, x0=u, rtol=reduced, atol=0.0, maxiter=left, M=Pinv, callback=callback)
            else:
                u, _ = spla.gmres(S, rhs, x0=u, rtol=reduced, atol=0.0, restart=min(RESTART, left),
                                  maxiter=max(1, -(-left // RESTART)), M=Pinv, callback=callback,
                                  callback_type="pr_norm")
            x = self._whole(u, w, b_Z)
            residual = float(np.linalg.norm(b - self._matvec(x))) / norm_b
            if not np.isfinite(residual) or residual <= rtol:
                break
            reduced = max(reduced * 0.5 * rtol / residual, np.finfo(float).eps)
        return x, count[0], residual

    def _whole(self, u: np.ndarray, w: np.ndarray, b_Z: np.ndarray) -> np.ndarray:
        """All unknowns (n,) from the bodies' ``u``: ``Z = w + C u`` (``w = M^-1 b_mu / s``) and
        ``mu = M^-1 (b_Z - Kc Z) / s``, exact given ``u``."""
        Z = w + self._C(u)
        x = np.zeros(self.n)
        x[:self.n_u], x[self._z], x[self._mu] = u, Z, self._Minv(b_Z - self.Kc @ Z) / self._s
        return x

    def _solve(self, b: np.ndarray, norm_b: float, rtol: float | None) -> tuple[np.ndarray, int, float]:
        target = self.rtol if rtol is None else max(self.rtol, rtol)
        x, iterations, residual = self.iterate(b, target, self.max_iterations, rounds=1)
        if not np.isfinite(residual) or residual > max(10.0 * target, 1e-8):
            raise LinearSolverError(f"{self.backend}: reached relative residual {residual:.2e} in {iterations} "
                                    f"Krylov iterations")
        return x, iterations, residual

    def krylov(self, A: sp.spmatrix, b: np.ndarray, rtol: float, max_iterations: int,
               x0: np.ndarray | None = None) -> tuple[np.ndarray, int, float, bool]:
        """A solve of the Krylov path (:class:`~cgfem.solve.solves.LinearSolves`): ``A x = b``
        by :meth:`iterate` with this preconditioner, the operator rebound to ``A``'s system
        when ``A`` is a new matrix (with the same unknowns: a later Newton iteration's), and let
        go after the solve, so that no system's blocks outlive it;
        ``(x, iterations, residual, reached)``; NaN raises
        :class:`~cgfem.solve.linear.LinearSolverError`."""
        if self._bound is not A:
            self._bind(sp.csr_matrix(A))
            self._bound = A
        x, iterations, residual = self.iterate(b, rtol, max_iterations, x0)
        # on the Krylov path every Newton matrix is solved once: its blocks are let go (bound
        # again if asked), so that they do not outlive it while the next one is assembled
        self._bound = self.K = self.Kc = self._matvec = None
        if not np.isfinite(residual):
            raise LinearSolverError(f"{self.backend}: NaN in the Krylov iterates")
        return x, iterations, residual, bool(residual <= rtol)


def reduced_saddle(A: sp.csr_matrix, n_u: int, constraints: list[FitConstraint], symmetric: bool,
                   near_null: np.ndarray | None = None, rtol: float = 1e-10,
                   preconditioner: str = "pyamg", reuse: LinearSolver | None = None) -> ReducedSaddleSolver:
    """Set up :class:`ReducedSaddleSolver` for ``A`` (timed like the other backends);
    ``reuse``: the solver of the system's previous matrix, whose factorized preconditioner
    then lends its PARDISO analysis (:func:`cgfem.solve.linear.build`)."""
    t0 = time.perf_counter()
    solver = ReducedSaddleSolver(A, n_u, constraints, symmetric, near_null, rtol,
                                 preconditioner=preconditioner, reuse=reuse)
    solver.info.update(backend=solver.backend, symmetric=symmetric, setup_s=time.perf_counter() - t0)
    return solver
