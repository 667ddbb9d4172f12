"""Krylov solves preconditioned by algebraic multigrid with the elastic near-null space.

:class:`AMGPreconditioner` is pyamg's smoothed aggregation on 3x3 nodal blocks with the
bodies' rigid-body modes as near-null space, built on the symmetric diagonal scaling
``D^-1/2 A D^-1/2`` of a matrix ``A`` (penalty rows and tiny cut cells make the diagonal vary
over orders of magnitude); one V-cycle is one application. It may be applied to the systems of
later matrices (other Newton iterations, other outer passes): :func:`krylov_solve` solves
``K x = b`` for any ``K`` with a preconditioner built on another, by CG where ``K`` is
symmetric and by restarted GMRES where it is not (finite strain with contact), and reports
whether it reached the relative residual asked for within its iterations, so that the caller
can refresh the preconditioner or fall back to a factorization.

Why pyamg: it is the well-kept smoothed-aggregation library that installs from PyPI with
wheels, takes a user near-null space (the rigid-body modes, which carry the contact
block's and the floating bodies' soft motions to the coarse grid) and nodal blocks, and the
project already used it for its symmetric systems (:mod:`cgfem.solve.linear`).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from cgfem.solve.linear import LinearSolverError, mode_bodies, scale_symmetric, symmetric_part
from cgfem.solve.multigrid import smoothed_aggregation, v_cycle

#: inner iterations of one GMRES cycle
RESTART = 50


def collapse_modes(B: np.ndarray, bodies: np.ndarray | None) -> np.ndarray:
    """The rigid-body modes of several bodies, ``B`` (n, 6 k) block by block (each row
    nonzero in one group of six columns at most: ``bodies``, from
    :func:`~cgfem.solve.linear.mode_bodies`, is not None), summed into six columns (n, 6): on
    an aggregate that lies in one body (every one of the finest level,
    :class:`AMGPreconditioner`) both span the same motions, and the coarse blocks are 6x6
    instead of 6k x 6k. Other shapes are returned as they are."""
    n, k = B.shape
    if k == 6 or bodies is None:
        return B
    return B.reshape(n, k // 6, 6).sum(axis=1)


class AMGPreconditioner:
    """One V-cycle of smoothed aggregation on ``A`` (n, n), scaled: ``z = s * V(s * r)``
    with ``s = |diag A|^-1/2``. ``near_null`` (n, 6 k): the rigid-body modes of the bodies
    (zero rows allowed; :func:`collapse_modes`), whose blocks also keep every aggregate of the
    finest level within one body (:func:`~cgfem.solve.multigrid.strength_within_bodies`);
    ``symmetric``: the hierarchy's restriction is ``P^T`` (CG) or built for a non-symmetric
    ``A`` (GMRES); ``own``: ``A`` is the caller's to spend (scaled in place, no copy).
    ``info``: ``setup_s``, ``levels``, ``operator_complexity``."""

    def __init__(self, A: sp.csr_matrix, near_null: np.ndarray | None, symmetric: bool, own: bool = False):
        tic = time.perf_counter()
        A = sp.csr_matrix(A, dtype=np.float64)
        d = A.diagonal()
        if np.any(d == 0.0) or not np.all(np.isfinite(A.data)):
            raise LinearSolverError("amg: zero diagonal entries, NaN or inf in the matrix")
        self.n, self.symmetric = A.shape[0], symmetric
        self._s = 1.0 / np.sqrt(np.abs(d))
        As = scale_symmetric(A, self._s, own)
        if symmetric:
            As = symmetric_part(As)
        B, bodies = None, None
        if near_null is not None:
            near_null = np.asarray(near_null, float)
            bodies = mode_bodies(near_null)
            B = collapse_modes(near_null, bodies) / self._s[:, None]
        if self.n % 3 == 0:
            As = As.tobsr(blocksize=(3, 3))
            bodies = None if bodies is None else bodies[::3]
        kwargs = {"improve_candidates": None} if B is not None else {}
        if bodies is not None:      # every aggregate of the finest level in one body
            kwargs["bodies"] = bodies
        # one forward block Gauss-Seidel sweep before the coarse correction and one backward
        # after it (a symmetric V-cycle for CG): pyamg's default symmetric sweeps on both
        # sides cost a third more per GMRES solve for the same iterations within 20 %
        self._ml = smoothed_aggregation(As, pre="forward", post="backward", B=B,
                                        symmetry="hermitian" if symmetric else "nonsymmetric", **kwargs)
        self.info = {"setup_s": time.perf_counter() - tic, "levels": len(self._ml.levels),
                     "operator_complexity": float(self._ml.operator_complexity())}

    def __call__(self, r: np.ndarray) -> np.ndarray:
        s = self._s
        return s * v_cycle(self._ml, s * r)

    def operator(self) -> spla.LinearOperator:
        return spla.LinearOperator((self.n, self.n), matvec=self)

    def krylov(self, K: sp.spmatrix, b: np.ndarray, rtol: float, max_iterations: int,
               x0: np.ndarray | None = None) -> tuple[np.ndarray, int, float, bool]:
        """A solve of the Krylov path: :func:`krylov_solve` of ``K x = b`` with this
        preconditioner."""
        return krylov_solve(K, b, self, rtol, max_iterations, self.symmetric, x0)


def krylov_solve(K: sp.spmatrix, b: np.ndarray, M: AMGPreconditioner, rtol: float, max_iterations: int,
                 symmetric: bool, x0: np.ndarray | None = None) -> tuple[np.ndarray, int, float, bool]:
    """Solve ``K x = b`` (n,) by CG (``symmetric``) or GMRES(:data:`RESTART`) preconditioned by
    ``M`` until the true relative residual ``|b - K x| / |b| <= rtol`` or ``max_iterations``
    iterations. Returns ``(x, iterations, residual, reached)``; raises
    :class:`~cgfem.solve.linear.LinearSolverError` on a breakdown or NaN."""
    norm_b = float(np.linalg.norm(b))
    if norm_b == 0.0:
        return np.zeros_like(b), 0, 0.0, True
    count = [0]

    def callback(*_):
        count[0] += 1
    x, tol, residual = x0, rtol, np.inf
    P = M.operator()
    for _ in range(4):        # tighten the Krylov method's own test until the true residual is met
        left = max_iterations - count[0]
        if left <= 0:
            break
        if symmetric:
            x, flag = spla.cg(K, b, x0=x, rtol=tol, atol=0.0, maxiter=left, M=P, callback=callback)
        else:
            x, flag = spla.gmres(K, b, x0=x, rtol=tol, atol=0.0, restart=min(RESTART, left),
                                 maxiter=max(1, -(-left // RESTART)), M=P, callback=callback,
                                 callback_type="pr_norm")
        if flag < 0 or not np.all(np.isfinite(x)):
            raise LinearSolverError(f"krylov: breakdown (flag {flag}) or NaN")
        residual = float(np.linalg.norm(b - K @ x)) / norm_b
        if residual <= rtol:
            return x, count[0], residual, True
        tol = max(tol * 0.5 * rtol / residual, np.finfo(float).eps)
    return x, count[0], residual, False
