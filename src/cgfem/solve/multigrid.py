"""Smoothed-aggregation multigrid as a preconditioner: pyamg's hierarchy, our smoothers and
V-cycle.

pyamg builds the hierarchy (the aggregates, the near-null space's coarse functions, the
smoothed prolongators); what applies it at every Krylov iteration is here:

- :func:`smoothed_aggregation`: the hierarchy, set up reproducibly, with the aggregates of
  every level kept within one body where asked (:func:`strength_within_bodies`);
- :class:`BlockSmoother`: block Gauss-Seidel sweeps by numba kernels on each BSR level, whose
  matrix it stores as its strictly lower and strictly upper block triangles apart. A V-cycle
  starts every level from zero, so its first sweep needs one triangle only, and the residual
  after a sweep is a product with the other triangle (:meth:`BlockSmoother.presmooth`): the
  pre-smoothing and the residual handed to the coarse level read the matrix once, where a
  sweep and a product with ``A`` read it twice;
- :func:`v_cycle`: one V-cycle from zero, pyamg's cycle without the residual norms its
  ``solve`` computes around it.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from cgfem.solve import _smoother_kernels as kernels

#: the seed of numpy's global generator while pyamg builds a hierarchy (:func:`smoothed_aggregation`)
AMG_SEED = 2026

#: largest entry of ``D_i D_i^-1 - I`` over the diagonal blocks for which a sweep counts as
#: solving its rows (:meth:`BlockSmoother.presmooth`)
SOLVED = 1e-10

#: the sweeps of a smoothing step, by name (forward: rows in increasing order)
DIRECTIONS = {"forward": (True,), "backward": (False,), "symmetric": (True, False)}


def smoothed_aggregation(A: sp.spmatrix, pre: str = "symmetric", post: str = "symmetric",
                         bodies: np.ndarray | None = None, **kwargs: Any):
    """pyamg's smoothed-aggregation hierarchy of ``A`` (``kwargs`` as
    ``pyamg.smoothed_aggregation_solver``'s) with block Gauss-Seidel smoothers, ``pre`` and
    ``post`` sweeps (:data:`DIRECTIONS`; pyamg's default is symmetric on both sides; every
    BSR level gets a :class:`BlockSmoother`), built with numpy's global generator seeded at
    :data:`AMG_SEED` and restored afterwards. ``bodies`` (one label per node of a BSR ``A``,
    or per row; at least two labels): the aggregates of every level are kept within one label
    (:func:`_within_bodies`). pyamg's spectral-radius estimates (the prolongation smoother's
    weight on every level) start from a random vector of that generator: without the seed two
    set-ups of the same matrix differ at round-off, and so do the Krylov iterates and a run's
    contact decisions after them. (The row-wise Gershgorin weight, pyamg's ``"local"``, needs
    no estimate; on chain2_steel's level-3 Newton matrix it saved a sixth of the set-up and
    cost a sixth more GMRES iterations, so the default stays.)"""
    import pyamg

    smoothers = {"presmoother": ("block_gauss_seidel", {"sweep": pre}),
                 "postsmoother": ("block_gauss_seidel", {"sweep": post})}
    state = np.random.get_state()
    np.random.seed(AMG_SEED)
    try:
        if bodies is not None and np.unique(bodies).size > 1:
            ml = _within_bodies(A, np.asarray(bodies), **smoothers, **kwargs)
        else:
            ml = pyamg.smoothed_aggregation_solver(A, **smoothers, **kwargs)
    finally:
        np.random.set_state(state)
    for level in ml.levels[:-1]:
        M = level.A
        if sp.issparse(M) and M.format == "bsr" and M.blocksize[0] == M.blocksize[1]:
            BlockSmoother(M, pre, post).install(level)
    return ml


def _within_bodies(A: sp.spmatrix, bodies: np.ndarray, max_levels: int = 10, max_coarse: int = 10,
                   B: np.ndarray | None = None, BH: np.ndarray | None = None, keep: bool = False,
                   **kwargs: Any):
    """pyamg's hierarchy built one level at a time, each level aggregated on the strength of
    connection within ``bodies`` (:func:`strength_within_bodies`; the labels of a coarse
    level's nodes are those of their aggregates), ``max_levels`` and ``max_coarse`` (nodes)
    as pyamg's, the other ``kwargs`` applied at every level; ``keep``: every level keeps its
    ``AggOp`` (and pyamg's other set-up operators) and its nodes' ``bodies``. pyamg takes a
    predefined strength only for matrices known before the set-up (the finest); on its own
    strength the coarser levels' aggregates take in nodes across the contact zones again,
    and there the relative rigid motions of the bodies, a floating one's above all, leave
    the coarse space (docs/performance.md, "The Krylov path")."""
    import pyamg

    levels = []
    while True:
        C = strength_within_bodies(A, bodies)
        ml = pyamg.smoothed_aggregation_solver(A, B=B, BH=BH, strength=[("predefined", {"C": C})],
                                               max_levels=2, max_coarse=max_coarse, keep=True, **kwargs)
        if len(ml.levels) == 1:
            break
        fine, coarse = ml.levels
        members = sp.csc_matrix(fine.AggOp)
        labels = np.empty(members.shape[1], bodies.dtype)
        labels[np.repeat(np.arange(members.shape[1]), np.diff(members.indptr))] = bodies[members.indices]
        if keep:
            fine.bodies = bodies
        else:
            for name in ("C", "T", "AggOp", "Cnodes"):
                vars(fine).pop(name, None)
        levels.append(fine)
        A, B, BH, bodies = coarse.A, coarse.B, getattr(coarse, "BH", None), labels
        nodes = A.shape[0] // (A.blocksize[0] if A.format == "bsr" else 1)
        if len(levels) + 1 >= max_levels or nodes <= max_coarse:
            break
    ml.levels = levels + ml.levels[-1:]
    return ml


def strength_within_bodies(A: sp.spmatrix, bodies: np.ndarray) -> sp.csr_matrix:
    """pyamg's default strength of connection of ``A`` (``symmetric``, ``theta = 0``: every
    coupling; nodal for a BSR matrix) without the couplings between nodes of different
    ``bodies`` labels (n_nodes,). Aggregated on it, every finest-level aggregate lies in one
    body, so that each body's rigid-body modes, and nothing that stretches the contact
    between two bodies, span its coarse functions. On pyamg's own strength, whose aggregates
    take in the neighbours across a contact zone (its coupling ``kappa E / h`` is as strong as
    the elements'), the modes of two bodies mixed in one aggregate are neither body's rigid
    motion: a body held by contact alone then loses its soft motions from the coarse space
    (measurements: docs/performance.md, "The Krylov path")."""
    from pyamg.strength import symmetric_strength_of_connection

    C = sp.csr_matrix(symmetric_strength_of_connection(A, 0.0))
    bodies = np.asarray(bodies)
    rows = np.repeat(np.arange(C.shape[0]), np.diff(C.indptr))
    C.data[bodies[rows] != bodies[C.indices]] = 0.0
    C.eliminate_zeros()
    return C


class BlockSmoother:
    """Block Gauss-Seidel on the BSR matrix ``A`` (square blocks m x m, n = m * rows): its
    strictly lower and strictly upper block triangles, each in BSR arrays of its own, and
    its inverted diagonal blocks (pyamg's ``get_block_diag``, as its own smoother inverts
    them). ``pre`` and ``post``: the sweeps before and after the coarse correction
    (:data:`DIRECTIONS`). A forward sweep gives pyamg's ``block_gauss_seidel`` to the last
    bit; a backward one, which reads each row's blocks backwards so that the matrix streams
    one way, to round-off. The triangles are a second copy of the level's matrix."""

    def __init__(self, A: sp.bsr_matrix, pre: str, post: str) -> None:
        from pyamg.util.utils import get_block_diag

        A = A if A.has_sorted_indices else A.sorted_indices()
        m = A.blocksize[0]
        rows = np.repeat(np.arange(A.shape[0] // m), np.diff(A.indptr))
        self.lower = _triangle(A, rows, A.indices < rows)
        self.upper = _triangle(A, rows, A.indices > rows)
        self.empty = (np.zeros_like(self.lower[0]), self.lower[1][:0], self.lower[2][:0])
        self.dinv = np.ascontiguousarray(get_block_diag(A, blocksize=m, inv_flag=True))
        # pyamg pseudo-inverts singular diagonal blocks (the 6k x 6k blocks of k bodies'
        # uncollapsed modes on an aggregate of one body): there a sweep does not solve its row,
        # the triangle's product is not the residual, and ``b - A x`` is computed instead
        D = get_block_diag(A, blocksize=m, inv_flag=False)
        identity = np.einsum("bij,bjk->bik", D, self.dinv) - np.eye(m)
        self._A = None if np.abs(identity).max(initial=0.0) <= SOLVED else A
        self.pre, self.post = DIRECTIONS[pre], DIRECTIONS[post]
        self._sweep = kernels.sweep3 if m == 3 else kernels.sweep
        self._product = kernels.product3 if m == 3 else kernels.product

    def install(self, level) -> None:
        """Make this the smoother of the pyamg ``level``: its ``presmoother`` and
        ``postsmoother`` (pyamg's form ``(A, x, b)``, ``x`` in place) and its
        ``block_smoother``, which :func:`v_cycle` uses."""
        level.presmoother = self._smoother(self.pre)
        level.postsmoother = self._smoother(self.post)
        level.block_smoother = self

    def _smoother(self, directions: tuple[bool, ...]) -> Callable:
        def smooth(_A, x: np.ndarray, b: np.ndarray) -> None:
            for forward in directions:
                self.sweep(x, b, forward)
        return smooth

    def sweep(self, x: np.ndarray, b: np.ndarray, forward: bool, from_zero: bool = False) -> None:
        """One sweep on ``x`` (n,) in place towards ``A x = b``; ``from_zero``: ``x`` is zero,
        and the triangle it would multiply is skipped (the same bits)."""
        upper = self.empty if from_zero and forward else self.upper
        lower = self.empty if from_zero and not forward else self.lower
        self._sweep(*lower, *upper, self.dinv, x, b, forward)

    def presmooth(self, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pre-smoothing sweeps from ``x = 0`` and the residual ``b - A x`` after them:
        ``(x, r)`` (n,). After a forward sweep from ``x_old`` to ``x`` the residual is
        ``U (x_old - x)`` (each row's lower part and diagonal were solved with the new values),
        after a backward one ``L (x_old - x)``; equal to ``b - A x`` to round-off. Where a
        diagonal block is singular (pseudo-inverted) the residual is ``b - A x``."""
        x, before = np.zeros_like(b), None
        for k, forward in enumerate(self.pre):
            before = x.copy() if k else None
            self.sweep(x, b, forward, from_zero=k == 0)
        if self._A is not None:
            return x, b - self._A @ x
        r = np.empty_like(b)
        self._product(*(self.upper if self.pre[-1] else self.lower), -x if before is None else before - x, r)
        return x, r


def _triangle(A: sp.bsr_matrix, rows: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The BSR arrays ``(indptr, indices, blocks)`` of the blocks of ``A`` where ``keep``
    (nnzb,), ``rows`` (nnzb,) their block rows; the order within a row kept, int32 indices."""
    indptr = np.zeros(A.indptr.size, np.int32)
    np.cumsum(np.bincount(rows[keep], minlength=A.indptr.size - 1), out=indptr[1:])
    return indptr, np.ascontiguousarray(A.indices[keep], np.int32), np.ascontiguousarray(A.data[keep])


def v_cycle(ml, b: np.ndarray) -> np.ndarray:
    """One V-cycle of the multigrid hierarchy ``ml`` on ``A x = b`` (n,) from ``x = 0``: the
    ``x`` of ``ml.solve(b, maxiter=1, cycle="V")`` to round-off (operation for operation but
    the residual after the pre-smoothing, :meth:`BlockSmoother.presmooth`), without the two
    residual norms that call computes around its cycle (two products with the finest matrix,
    wasted in a preconditioner)."""
    levels, b = ml.levels, np.ravel(b)
    if len(levels) == 1:
        return np.asarray(ml.coarse_solver(levels[0].A, b))
    return _descend(ml, 0, b)


def _descend(ml, lvl: int, b: np.ndarray) -> np.ndarray:
    """The V-cycle from level ``lvl`` down, from zero: pre-smoothing, the coarse correction
    (solved on the coarsest level), post-smoothing."""
    level = ml.levels[lvl]
    smoother = getattr(level, "block_smoother", None)
    if smoother is not None:
        x, residual = smoother.presmooth(b)
    else:
        x = np.zeros_like(b)
        level.presmoother(level.A, x, b)
        residual = b - level.A @ x
    coarse_b = level.R @ residual
    if lvl == len(ml.levels) - 2:
        coarse_x = np.asarray(ml.coarse_solver(ml.levels[-1].A, coarse_b)).ravel()
    else:
        coarse_x = _descend(ml, lvl + 1, coarse_b)
    x += level.P @ coarse_x
    level.postsmoother(level.A, x, b)
    return x
