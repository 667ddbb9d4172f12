"""MKL PARDISO on one sparsity pattern: analysed once, factorized for every matrix within it.

PARDISO's analysis (phase 11: the fill-reducing ordering and the symbolic factorization)
depends on the matrix's pattern only (for the symmetric type -2; for the non-symmetric type 11
its matching and scaling read the values of the matrix analysed). Newton's matrices keep the
pattern of the bodies' couplings and change only where contact couples other nodes, so
:class:`PardisoPattern` analyses a pattern once and factorizes (phase 22) any later matrix
whose entries lie within it, their missing entries stored as zeros. A matrix with entries
outside is analysed again on the union of both patterns, which then holds the contact
couplings seen so far: on chain3 at order 2, level 0 with ``nurbs_fe`` the 35 Newton
matrices had 16 different patterns but their union grew three times, by 1 % of the entries.
The analysis is about half of a factorization there (0.48 s of 1.03 s at 16 878 unknowns,
one thread; docs/performance.md, "Analysed once").

A pattern may factorize in single precision (``iparm(28)``, its values and right-hand sides
stored as float32, PARDISO's own iterative refinement off: ``iparm(8)``). Its factors take
half the memory and about a third less time on the examples' matrices (docs/performance.md,
"Factors in single precision"); a solve with them has a relative residual of about ``1e-7``,
which the caller refines in double precision (:class:`cgfem.solve.linear.LinearSolver`).

The interface is MKL's documented ``pardiso`` call (LP64, zero-based indices ``iparm(35)``),
in its conditional numerical reproducibility mode with the given threads (``iparm(34)``): the
same matrices in the same order give the same bits.
"""

from __future__ import annotations

import ctypes
import weakref

import numba
import numpy as np

_INT = ctypes.c_int32
_INT_P = ctypes.POINTER(ctypes.c_int32)
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)


class PardisoError(RuntimeError):
    """A PARDISO phase returned an error code (singular matrix, memory, ...)."""


@numba.njit(cache=True)
def positions_within(sub_indptr: np.ndarray, sub_indices: np.ndarray, indptr: np.ndarray,
                     indices: np.ndarray) -> np.ndarray:
    """Where every entry of the CSR pattern ``sub`` (sorted columns) lies in the CSR pattern
    (``indptr``, ``indices``; sorted columns, the same number of rows): (nnz of sub,) indices
    into ``indices``, or an empty array if some entry of ``sub`` is not in it."""
    out = np.empty(sub_indices.size, np.int64)
    for row in range(sub_indptr.size - 1):
        k, end = indptr[row], indptr[row + 1]
        for s in range(sub_indptr[row], sub_indptr[row + 1]):
            col = sub_indices[s]
            while k < end and indices[k] < col:
                k += 1
            if k == end or indices[k] != col:
                return np.empty(0, np.int64)
            out[s] = k
    return out


@numba.njit(cache=True)
def union_pattern(a_indptr: np.ndarray, a_indices: np.ndarray, b_indptr: np.ndarray,
                  b_indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The CSR pattern (indptr, indices; sorted columns, int32) holding the entries of both
    CSR patterns ``a`` and ``b`` (sorted columns, the same number of rows)."""
    n = a_indptr.size - 1
    indptr = np.zeros(n + 1, np.int32)
    indices = np.empty(a_indices.size + b_indices.size, np.int32)
    m = 0
    for row in range(n):
        i, i_end = a_indptr[row], a_indptr[row + 1]
        j, j_end = b_indptr[row], b_indptr[row + 1]
        while i < i_end or j < j_end:
            if j == j_end or (i < i_end and a_indices[i] < b_indices[j]):
                indices[m] = a_indices[i]
                i += 1
            elif i == i_end or b_indices[j] < a_indices[i]:
                indices[m] = b_indices[j]
                j += 1
            else:
                indices[m] = a_indices[i]
                i += 1
                j += 1
            m += 1
        indptr[row + 1] = m
    return indptr, indices[:m].copy()


def values_on(indptr: np.ndarray, indices: np.ndarray, sub_indptr: np.ndarray, sub_indices: np.ndarray,
              sub_data: np.ndarray) -> np.ndarray | None:
    """The values (nnz,) on the CSR pattern (``indptr``, ``indices``) of the CSR matrix
    (``sub_indptr``, ``sub_indices``, ``sub_data``; sorted columns), zero where it has no
    entry; None if it has another number of rows or an entry outside the pattern."""
    if sub_indptr.size != indptr.size:
        return None
    where = positions_within(sub_indptr, sub_indices, indptr, indices)
    if where.size != sub_indices.size:
        return None
    values = np.zeros(indices.size)
    values[where] = sub_data
    return values


class PardisoPattern:
    """One PARDISO instance (its internal memory ``pt``) of matrix type ``mtype`` analysed
    on a CSR pattern (``indptr``, ``indices``: sorted columns, every row nonempty, for type
    -2 the upper triangle with its diagonal) of ``n`` rows. :meth:`factorize` takes values on
    that pattern; :meth:`within` maps a matrix onto it. Freed with the object (phase -1).

    ``data`` (nnz,): the values on the pattern the analysis sees (type 11's matching and
    scaling read them); ``library``: MKL's runtime (``ctypes.CDLL``); ``threads``: the
    reproducibility mode's; ``single``: factors in single precision (module docstring).
    Raises :class:`PardisoError` if the analysis fails."""

    def __init__(self, library: ctypes.CDLL, mtype: int, indptr: np.ndarray, indices: np.ndarray,
                 data: np.ndarray, threads: int, single: bool = False) -> None:
        self.mtype, self.n = int(mtype), int(indptr.size - 1)
        self.single = bool(single)
        #: the floating-point type of the values, right-hand sides and solutions PARDISO sees
        self._dtype = np.float32 if self.single else np.float64
        self.indptr = np.ascontiguousarray(indptr, dtype=np.int32)
        self.indices = np.ascontiguousarray(indices, dtype=np.int32)
        self._call = library.pardiso
        self._call.restype = None
        self.pt = np.zeros(64, dtype=np.int64)
        self.iparm = np.zeros(64, dtype=np.int32)
        library.pardisoinit(self.pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
                            ctypes.byref(_INT(self.mtype)), self.iparm.ctypes.data_as(_INT_P))
        self.iparm[33] = threads      # iparm(34): reproducible with this many threads
        self.iparm[34] = 1            # iparm(35): zero-based indices
        if self.single:
            self.iparm[27] = 1        # iparm(28): single precision
            self.iparm[7] = 0         # iparm(8): no refinement in single precision
        self._data: np.ndarray | None = None     # the values last factorized
        weakref.finalize(self, _release, self._call, self.pt, self.iparm, self.mtype, self.n)
        #: whether :meth:`factorize` has run (:meth:`solve` needs it)
        self.factorized = False
        self._phase(11, np.ascontiguousarray(data, dtype=self._dtype))

    @property
    def nnz(self) -> int:
        """Entries of the pattern."""
        return int(self.indices.size)

    def within(self, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray) -> np.ndarray | None:
        """:func:`values_on` this pattern of the CSR matrix (``indptr``, ``indices``, ``data``)."""
        return values_on(self.indptr, self.indices, indptr, indices, data)

    def factorize(self, data: np.ndarray) -> None:
        """Numerical factorization (phase 22) of the values ``data`` (nnz,) on the pattern."""
        self._data = np.ascontiguousarray(data, dtype=self._dtype)
        self._phase(22, self._data)
        self.factorized = True

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``x`` (n,) float64 with ``A x = b`` for the last factorized values (phase 33). In
        single precision ``b`` is scaled to a largest entry of 1 before it is rounded, so that
        no entry leaves float32's range."""
        if not self.factorized:
            raise PardisoError("solve before a factorization")
        scale = 1.0
        if self.single:
            scale = float(np.abs(b).max(initial=0.0)) or 1.0
            b = b / scale
        b = np.ascontiguousarray(b, dtype=self._dtype)
        x = np.zeros_like(b)
        self._phase(33, self._data, b, x)
        return x.astype(np.float64) * scale if self.single else x

    @property
    def perturbed_pivots(self) -> int:
        """Pivots the last factorization perturbed (``iparm(14)``)."""
        return int(self.iparm[13])

    @property
    def factor_nnz(self) -> int:
        """Entries of the factors (``iparm(18)``)."""
        return int(self.iparm[17])

    def _phase(self, phase: int, data: np.ndarray, b: np.ndarray | None = None,
               x: np.ndarray | None = None) -> None:
        error = _pardiso(self._call, self.pt, self.iparm, self.mtype, phase, self.n, data, self.indptr,
                         self.indices, b, x)
        if error != 0:
            raise PardisoError(f"phase {phase} returned error {error}")


def _pardiso(call, pt: np.ndarray, iparm: np.ndarray, mtype: int, phase: int, n: int, data: np.ndarray,
             indptr: np.ndarray, indices: np.ndarray, b: np.ndarray | None = None,
             x: np.ndarray | None = None) -> int:
    """One ``pardiso`` call (one matrix, one right-hand side, no user permutation, silent):
    PARDISO's error code."""
    b = np.zeros(1) if b is None else b
    x = np.zeros(1) if x is None else x
    error = _INT(0)
    one = ctypes.byref(_INT(1))
    call(pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), one, one, ctypes.byref(_INT(mtype)),
         ctypes.byref(_INT(phase)), ctypes.byref(_INT(n)), data.ctypes.data_as(_DOUBLE_P),
         indptr.ctypes.data_as(_INT_P), indices.ctypes.data_as(_INT_P), None, one,
         iparm.ctypes.data_as(_INT_P), ctypes.byref(_INT(0)), b.ctypes.data_as(_DOUBLE_P),
         x.ctypes.data_as(_DOUBLE_P), ctypes.byref(error))
    return int(error.value)


def _release(call, pt: np.ndarray, iparm: np.ndarray, mtype: int, n: int) -> None:
    """Phase -1: PARDISO frees the memory of ``pt``."""
    index = np.zeros(1, np.int32)
    _pardiso(call, pt, iparm, mtype, -1, n, np.zeros(1), index, index)
