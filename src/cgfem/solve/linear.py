"""Sparse linear solvers behind one interface: factorize once, solve many right-hand sides.

- ``superlu``: :func:`scipy.sparse.linalg.splu` with MMD on ``A^T + A`` (COLAMD: 5 % more
  fill, 10-20 % slower on H8 elasticity); symmetric matrices in symmetric mode (diagonal
  pivots, threshold 0.01). Never ``spsolve``: with scikit-umfpack it silently uses UMFPACK.
- ``pardiso``: MKL PARDISO (:mod:`cgfem.solve.pardiso`), one instance per solver (freed
  with it), or the instance of the solver it replaces (``reuse``), whose analysis serves a
  matrix within its pattern; symmetric matrices as type -2 (upper triangle), 2-4x faster and
  half the memory of the non-symmetric type 11 at 30k-100k DOFs. Always in its conditional
  numerical reproducibility mode (``iparm(34)``, the number of MKL threads) with MKL's
  dynamic thread adjustment off: a factorization gives the same bits whatever the machine's
  load, where the default mode's parallel factorization does not (:func:`mkl_threads`).
  ``single``: factors in single precision (:mod:`cgfem.solve.pardiso`), refined in double
  precision to the same residual as the double factors; a matrix whose refinement falls
  short of it is factorized again in double precision (``info["precision"]``).
- ``pyamg``: smoothed aggregation on 3x3 nodal blocks with the near-null space (rigid-body
  modes) as preconditioner of CG (symmetric) or GMRES(50), after the symmetric diagonal
  scaling ``D^-1/2 A D^-1/2`` (penalty rows, tiny cut cells); converged when the true
  residual ``||b - Ax|| <= rtol ||b||``, else :class:`LinearSolverError` after
  :data:`MAX_ITERATIONS`.

Each solver keeps its own copy of ``A`` (the caller may overwrite its matrix). Direct solves
must reach ``||b - Ax|| <= 1e-8 ||b||``, after at most two steps of iterative refinement:
this catches (numerically) singular matrices, whose pivots MKL perturbs instead of failing.

Which backend a system gets (``auto``) is decided in :mod:`cgfem.solve.backends`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import glob
import importlib
import os
import site
import sys
import time
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from cgfem.solve._sparse_kernels import scale_values, sum_csr
from cgfem.solve.multigrid import smoothed_aggregation, v_cycle
from cgfem.solve.pardiso import PardisoError, PardisoPattern, union_pattern, values_on

BACKENDS = ("superlu", "pyamg", "pardiso")
DIRECT_CHECK = 1e-8  #: relative residual a direct solve must reach
MAX_ITERATIONS = 1000  #: bound on the Krylov iterations of one pyamg solve
GMRES_RESTART = 50


def scale_symmetric(A: sp.spmatrix, s: np.ndarray, own: bool = False) -> sp.csr_matrix:
    """``diag(s) A diag(s)`` (n, n) for ``s`` (n,) with the pattern of ``A`` (explicit zeros
    dropped, as a product would) and the product's bits, in about half the time of scipy's
    two sparse products: a new CSR matrix, or ``A`` itself scaled in place when the caller
    ``own``s it (a CSR matrix)."""
    if own and sp.issparse(A) and A.format == "csr":
        out = A
    else:
        A = sp.csr_matrix(A)
        out = sp.csr_matrix((np.empty(A.nnz), A.indices.copy(), A.indptr.copy()), shape=A.shape)
    scale_values(A.indptr, A.indices, A.data, np.asarray(s, np.float64), out.data)
    out.eliminate_zeros()
    return out


def symmetric_part(A: sp.csr_matrix) -> sp.csr_matrix:
    """``(A + A^T) / 2`` of a CSR matrix, scipy's ``0.5 * (A + A.T)`` array for array, merged
    with the transpose into arrays of the sum's size (scipy's sum holds about twice as many;
    the examples' patterns are never exactly symmetric, exact zeros being dropped on one
    side, so the union is always formed)."""
    A = sp.csr_matrix(A)
    A.sum_duplicates()
    T = A.T.tocsr()
    T.sum_duplicates()
    indptr, indices, data = sum_csr(A.indptr, A.indices, A.data, T.indptr, T.indices, T.data, 0.5)
    return sp.csr_matrix((data, indices, indptr), shape=A.shape)


class LinearSolverError(RuntimeError):
    """The system could not be solved: singular matrix, no convergence, NaN or inf."""


@functools.cache
def available_backends() -> tuple[str, ...]:
    """The usable backends; pardiso only if pypardiso (and MKL) import."""
    try:
        _point_pypardiso_at_mkl()
        importlib.import_module("pypardiso")  # loads MKL too
    except (ImportError, OSError):
        return ("superlu", "pyamg")
    return BACKENDS


def rigid_body_modes(coords: np.ndarray) -> np.ndarray:
    """(3 n_nodes, 6) rigid-body modes, dofs interleaved (``3 * node + component``): unit
    translations along x, y, z, then rotations ``e_k x (x - c) / L`` about the centroid
    ``c`` (``L`` the RMS distance to it, so the six columns have comparable norms)."""
    coords = np.asarray(coords, dtype=float)
    if coords.ndim != 2 or coords.shape[1] != 3:
        raise ValueError(f"coords must have shape (n_nodes, 3), got {coords.shape}")
    r = coords - coords.mean(axis=0)
    r /= max(float(np.sqrt((r ** 2).sum(axis=1).mean())), np.finfo(float).tiny)
    B = np.zeros((len(r), 3, 6))
    B[:, [0, 1, 2], [0, 1, 2]] = 1.0
    for k in range(3):
        B[:, :, 3 + k] = np.cross(np.eye(3)[k], r)
    return B.reshape(-1, 6)


def mode_bodies(B: np.ndarray) -> np.ndarray | None:
    """The body of every row of ``B`` (n, 6 k), the rigid-body modes of ``k`` bodies block by
    block: the group of six columns the row is nonzero in (-1 where it is zero in all, the
    contact set's own unknowns); None if ``B`` is not so made."""
    n, k = B.shape
    if k % 6:
        return None
    groups = np.abs(B).reshape(n, k // 6, 6).max(axis=2) > 0.0
    if np.any(groups.sum(axis=1) > 1):
        return None
    return np.where(groups.any(axis=1), groups.argmax(axis=1), -1)


class LinearSolver:
    """A factorized (or preconditioned) system, reusable for many right-hand sides.

    ``info``: ``backend``, ``n``, ``symmetric``, ``setup_s``, ``solve_s`` (total),
    ``iterations`` and ``residuals`` (true relative residual), one entry per solve (direct
    backends count refinement steps), and backend details.
    """

    backend: str = ""

    def __init__(self, n: int) -> None:
        self.n = n
        self.info: dict[str, Any] = {"backend": self.backend, "n": n, "setup_s": 0.0,
                                     "solve_s": 0.0, "iterations": [], "residuals": []}

    def solve(self, b: np.ndarray, rtol: float | None = None) -> np.ndarray:
        """The solution of ``A x = b`` for ``b`` of shape (n,). ``rtol``: the relative
        residual this solve may stop at when it is looser than the solver's own (iterative
        backends, for inexact Newton; direct backends always solve to round-off)."""
        b = np.asarray(b, dtype=np.float64)
        if b.shape != (self.n,):
            raise ValueError(f"right-hand side must have shape ({self.n},), got {b.shape}")
        if not np.all(np.isfinite(b)):
            raise LinearSolverError("the right-hand side contains NaN or inf")
        t0 = time.perf_counter()
        norm_b = float(np.linalg.norm(b))
        if norm_b == 0.0:
            x, iterations, residual = np.zeros(self.n), 0, 0.0
        else:
            x, iterations, residual = self._solve(b, norm_b, rtol)
        self.info["solve_s"] += time.perf_counter() - t0
        self.info["iterations"].append(iterations)
        self.info["residuals"].append(residual)
        return x

    def _solve(self, b: np.ndarray, norm_b: float, rtol: float | None) -> tuple[np.ndarray, int, float]:
        """(x, iterations, true relative residual) for ``b != 0``."""
        raise NotImplementedError


class _DirectSolver(LinearSolver):
    """The residual check, with iterative refinement, of the direct backends."""

    _apply: Callable[[np.ndarray], np.ndarray]
    _matvec: Callable[[np.ndarray], np.ndarray]

    def solve_unchecked(self, b: np.ndarray) -> np.ndarray:
        """The factors applied to ``b``, with neither residual check nor refinement (a
        preconditioner's use)."""
        return self._apply(np.asarray(b, dtype=np.float64))

    def _solve(self, b: np.ndarray, norm_b: float, rtol: float | None) -> tuple[np.ndarray, int, float]:
        x = self._apply(b)
        for step in range(3):
            if not np.all(np.isfinite(x)):
                raise LinearSolverError(f"{self.backend}: NaN or inf in the solution "
                                        "(singular matrix?)")
            r = b - self._matvec(x)
            residual = float(np.linalg.norm(r)) / norm_b
            if residual <= DIRECT_CHECK:
                return x, step, residual
            if step < 2:
                x = x + self._apply(r)
        raise LinearSolverError(f"{self.backend}: relative residual {residual:.2e} > "
                                f"{DIRECT_CHECK:g} after 2 refinement steps (singular or "
                                "numerically singular matrix)")


class _SuperLU(_DirectSolver):
    backend = "superlu"

    def __init__(self, A: sp.csr_matrix, symmetric: bool) -> None:
        super().__init__(A.shape[0])
        A = A.tocsc()
        opts = dict(diag_pivot_thresh=0.01, options={"SymmetricMode": True}) if symmetric else {}
        try:
            lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", **opts)
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise LinearSolverError(f"superlu: {exc} (singular matrix)") from exc
        self.info["factor_nnz"] = int(lu.nnz)  # (lu.L and lu.U would copy the factors)
        self._apply, self._matvec = lu.solve, A.dot


@functools.cache
def _point_pypardiso_at_mkl() -> None:
    """Name MKL's runtime library to pypardiso (``PYPARDISO_MKL_RT``) where the environment
    does not. Each :class:`pypardiso.PyPardisoSolver`, the one pypardiso makes on import
    among them, asks the linker for ``mkl_rt`` and, where the linker does not know it (a pip
    install), walks every folder under ``<prefix>/lib*`` for it: 1-1.5 s each time, twice
    per process. The pip wheel puts the library in ``<prefix>/lib`` itself, where the walk,
    which tries the shortest paths first, finds it: the first ``*mkl_rt*`` there (shortest
    first) is named (a test compares it with the walk's choice). Where none is there,
    pypardiso searches as before."""
    if os.environ.get("PYPARDISO_MKL_RT") or ctypes.util.find_library("mkl_rt"):
        return
    for prefix in dict.fromkeys((sys.prefix, site.USER_BASE)):
        found = sorted(glob.glob(f"{glob.escape(prefix)}/[Ll]ib*/*mkl_rt*"), key=len)
        if found:
            os.environ["PYPARDISO_MKL_RT"] = found[0]
            return


@functools.cache
def _mkl_rt() -> str:
    """The MKL runtime pypardiso uses: the one named to it, else the one it finds."""
    _point_pypardiso_at_mkl()
    if named := os.environ.get("PYPARDISO_MKL_RT"):
        return named
    from pypardiso.pardiso_wrapper import PyPardisoSolver

    return str(PyPardisoSolver().libmkl._name)


@functools.cache
def _mkl_library() -> ctypes.CDLL:
    """MKL's runtime library, with its dynamic thread adjustment switched off (done once)."""
    lib = ctypes.CDLL(_mkl_rt())
    lib.MKL_Set_Dynamic(0)
    return lib


def mkl_threads() -> int | None:
    """The number of threads MKL (PARDISO) uses, or None without pypardiso. PARDISO runs in
    its reproducible mode with this many threads (``iparm(34)``), so the same thread count
    gives bitwise the same factorization under any load."""
    if "pardiso" not in available_backends():
        return None
    return int(_mkl_library().MKL_Get_Max_Threads())


class _Pardiso(_DirectSolver):
    backend = "pardiso"

    def __init__(self, A: sp.csr_matrix, symmetric: bool, indefinite: bool = False,
                 reuse: LinearSolver | None = None, single: bool = False) -> None:
        super().__init__(A.shape[0])
        if np.any(np.diff(A.indptr) == 0):
            raise LinearSolverError("pardiso: the matrix has empty rows (singular matrix)")
        mtype, M = 11, A
        # type -2 (symmetric indefinite) reads the upper triangle, which must store every
        # diagonal entry. Not for saddle points (indefinite): on nurbs_fit's constrained
        # system type -2 returned garbage (relative residual 7e7) with and without MKL's
        # matching and scaling, where type 11 solves it to 1e-14
        if symmetric and not indefinite:
            U = sp.triu(A, format="csr")
            U.sort_indices()
            starts = U.indptr[:-1]
            if np.all(np.diff(U.indptr) > 0) and np.all(U.indices[starts] == np.arange(self.n)):
                mtype, M = -2, U
        M.sort_indices()
        self._matvec = A.dot  # the check uses all of A, not just its upper half
        self._threads = mkl_threads() or 1
        pattern = reuse._take(mtype, self.n, single) if isinstance(reuse, _Pardiso) else None
        try:
            data = None if pattern is None else pattern.within(M.indptr, M.indices, M.data)
            analysed = data is None
            if analysed:
                indptr, indices, data = M.indptr, M.indices, M.data
                if pattern is not None:   # entries outside the pattern: analyse the union
                    indptr, indices = union_pattern(pattern.indptr, pattern.indices, M.indptr, M.indices)
                    del pattern           # its memory first
                    data = values_on(indptr, indices, M.indptr, M.indices, M.data)
                pattern = PardisoPattern(_mkl_library(), mtype, indptr, indices, data, self._threads, single)
            pattern.factorize(data)
        except PardisoError as exc:
            raise LinearSolverError(f"pardiso: factorization failed: {exc}") from exc
        self._pattern: PardisoPattern | None = pattern
        #: the double values on the pattern, for a factorization in double precision if the
        #: single one's refinement falls short (None: factorized in double already)
        self._values = np.asarray(data, dtype=np.float64) if single else None
        self.info.update(mtype=mtype, perturbed_pivots=pattern.perturbed_pivots, factor_nnz=pattern.factor_nnz,
                         threads=self._threads, analysed=analysed, precision="single" if single else "double")

    def _solve(self, b: np.ndarray, norm_b: float, rtol: float | None) -> tuple[np.ndarray, int, float]:
        try:
            return super()._solve(b, norm_b, rtol)
        except LinearSolverError:
            if self._values is None or self._pattern is None:
                raise
        self._factorize_double()
        return super()._solve(b, norm_b, rtol)

    def _factorize_double(self) -> None:
        """The matrix factorized again, in double precision, on its pattern (analysed anew:
        the analysis depends on the precision)."""
        old, values = self._pattern, self._values
        self._pattern, self._values = None, None
        indptr, indices = old.indptr, old.indices
        del old                           # its memory first
        try:
            pattern = PardisoPattern(_mkl_library(), self.info["mtype"], indptr, indices, values, self._threads)
            pattern.factorize(values)
        except PardisoError as exc:
            raise LinearSolverError(f"pardiso: factorization failed: {exc}") from exc
        self._pattern = pattern
        self.info.update(precision="double after single", perturbed_pivots=pattern.perturbed_pivots,
                         factor_nnz=pattern.factor_nnz, analysed=True)

    def _take(self, mtype: int, n: int, single: bool = False) -> PardisoPattern | None:
        """This solver's analysed pattern, for a new matrix of type ``mtype`` and size ``n``
        to be factorized in ``single`` precision or not (None if it is of another type, size
        or precision, or was taken): this solver cannot solve afterwards."""
        pattern = self._pattern
        if pattern is None or pattern.mtype != mtype or pattern.n != n or pattern.single != single:
            return None
        self._pattern = None
        return pattern

    def _apply(self, b: np.ndarray) -> np.ndarray:
        if self._pattern is None:
            raise LinearSolverError("pardiso: this factorization was superseded by a later matrix's")
        try:
            return self._pattern.solve(b)
        except PardisoError as exc:
            raise LinearSolverError(f"pardiso: solve failed: {exc}") from exc


class _AMG(LinearSolver):
    backend = "pyamg"

    def __init__(self, A: sp.csr_matrix, symmetric: bool, near_null: np.ndarray | None,
                 rtol: float) -> None:
        super().__init__(A.shape[0])
        d = A.diagonal()
        if np.any(d == 0.0) or (symmetric and np.any(d < 0.0)):
            raise LinearSolverError("pyamg: zero (or, symmetric, negative) diagonal entries")
        self._s, self._rtol, self._symmetric = 1.0 / np.sqrt(np.abs(d)), rtol, symmetric
        As = scale_symmetric(A, self._s)
        B = None
        if near_null is not None:
            near_null = np.asarray(near_null, dtype=float)
            if near_null.ndim != 2 or near_null.shape[0] != self.n:
                raise ValueError(f"near_null must have shape ({self.n}, k), got {near_null.shape}")
            B = near_null / self._s[:, None]  # the null space of S A S is S^-1 null(A)
        if self.n % 3 == 0:  # nodal aggregation (3x3 blocks): 2x fewer iterations without B
            As = As.tobsr(blocksize=(3, 3))
        kwargs: dict[str, Any] = {"improve_candidates": None} if B is not None else {}
        self._ml = smoothed_aggregation(As, B=B, symmetry="hermitian" if symmetric else "nonsymmetric", **kwargs)
        ml = self._ml
        self._As = ml.levels[0].A      # one copy of A
        self._M = spla.LinearOperator((self.n, self.n), matvec=lambda r: v_cycle(ml, r), dtype=np.float64)
        self.info.update(krylov="cg" if symmetric else "gmres", levels=len(self._ml.levels),
                         operator_complexity=float(self._ml.operator_complexity()))

    def _solve(self, b: np.ndarray, norm_b: float, rtol: float | None) -> tuple[np.ndarray, int, float]:
        target = self._rtol if rtol is None else max(self._rtol, rtol)
        bs, y, tol, residual = self._s * b, None, target, np.inf
        calls: list[int] = []
        for _ in range(4):  # tighten the scaled tolerance until the true residual is met
            left = MAX_ITERATIONS - len(calls)
            if left <= 0:
                break
            if self._symmetric:
                y, flag = spla.cg(self._As, bs, x0=y, rtol=tol, maxiter=left, M=self._M,
                                  callback=lambda *_: calls.append(1))
            else:
                y, flag = spla.gmres(self._As, bs, x0=y, rtol=tol, restart=GMRES_RESTART,
                                     maxiter=max(1, left // GMRES_RESTART), M=self._M,
                                     callback=lambda *_: calls.append(1), callback_type="pr_norm")
            if flag < 0 or not np.all(np.isfinite(y)):
                raise LinearSolverError(f"pyamg: Krylov breakdown (flag {flag}) or NaN")
            # the true residual b - A x = S^-1 (S b - S A S y)
            residual = float(np.linalg.norm((bs - self._As @ y) / self._s)) / norm_b
            if residual <= target:
                return self._s * y, len(calls), residual
            tol = max(tol * 0.5 * target / residual, np.finfo(float).eps)
        method = "CG" if self._symmetric else "GMRES"
        raise LinearSolverError(f"pyamg: {method} did not reach relative residual {target:g} "
                                f"in {len(calls)} iterations (reached {residual:.2e})")


def build(A: sp.spmatrix, name: str, *, symmetric: bool = True, near_null: np.ndarray | None = None,
          rtol: float = 1e-10, indefinite: bool = False, reuse: LinearSolver | None = None,
          single: bool = False) -> LinearSolver:
    """The backend ``name`` (one of :data:`BACKENDS`) set up on its own copy of the square
    matrix ``A`` (n, n): factorized (superlu, pardiso) or coarsened (pyamg, which uses
    ``near_null`` (n, k) and the relative residual ``rtol``). ``indefinite``: a saddle point
    (pardiso then factorizes it as non-symmetric). Which backend a system gets is decided in
    :mod:`cgfem.solve.backends`. ``reuse``: a pardiso solver of an earlier matrix of the
    same system, no longer needed: its analysis serves if this matrix's entries lie within its
    pattern (:mod:`cgfem.solve.pardiso`), and it cannot solve afterwards. ``single``: pardiso's
    factors in single precision, refined in double (the module docstring; the other backends
    ignore it). Raises :class:`LinearSolverError` on a singular or non-finite matrix."""
    t0 = time.perf_counter()
    A = sp.csr_matrix(A, dtype=np.float64, copy=True)  # our own copy, sorted and summed
    A.sum_duplicates()
    if not np.all(np.isfinite(A.data)):
        raise LinearSolverError("the matrix contains NaN or inf")
    solver: LinearSolver
    if name == "superlu":
        solver = _SuperLU(A, symmetric)
    elif name == "pardiso":
        solver = _Pardiso(A, symmetric, indefinite, reuse, single)
    elif name == "pyamg":
        solver = _AMG(A, symmetric, near_null, rtol)
    else:
        raise ValueError(f"unknown linear solver backend {name!r}")
    solver.info.update(backend=name, symmetric=symmetric, setup_s=time.perf_counter() - t0)
    return solver
