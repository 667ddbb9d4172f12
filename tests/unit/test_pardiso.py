"""PARDISO on a kept analysis: patterns within and beyond it, the superseded solver, the bits."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from tests.support import elasticity_fixture as fx
from cgfem.solve import linear
from cgfem.solve.linear import LinearSolverError, available_backends
from cgfem.solve.pardiso import positions_within, union_pattern

pytestmark = pytest.mark.skipif("pardiso" not in available_backends(), reason="pypardiso is not installed")


@pytest.fixture(scope="module")
def cube() -> sp.csr_matrix:
    """Clamped 5^3 cube (540 DOFs), H8 elasticity."""
    return fx.clamped_cube(5, 0.2)[0].tocsr()


def coupled(K: sp.csr_matrix, pairs: list[tuple[int, int]], k: float) -> sp.csr_matrix:
    """``K`` plus a symmetric penalty spring ``k (e_i - e_j)(e_i - e_j)^T`` per pair: entries
    outside K's pattern, as contact couples nodes of two bodies."""
    n = K.shape[0]
    rows, cols, vals = [], [], []
    for i, j in pairs:
        rows += [i, j, i, j]
        cols += [i, j, j, i]
        vals += [k, k, -k, -k]
    return (K + sp.csr_matrix((vals, (rows, cols)), shape=(n, n))).tocsr()


def test_positions_and_union_of_csr_patterns():
    """Against scipy: the positions of a sub-pattern's entries, none for an entry outside,
    and the union of two patterns."""
    rng = np.random.default_rng(0)
    A = sp.random(40, 40, density=0.2, random_state=rng, format="csr") + sp.identity(40, format="csr")
    B = sp.random(40, 40, density=0.1, random_state=rng, format="csr") + sp.identity(40, format="csr")
    for M in (A, B):
        M.sort_indices()
    sub = A.copy()
    sub.data[::3] = 0.0
    sub.eliminate_zeros()
    where = positions_within(sub.indptr, sub.indices, A.indptr, A.indices)
    rows = np.repeat(np.arange(40), np.diff(A.indptr))
    assert np.array_equal(rows[where], np.repeat(np.arange(40), np.diff(sub.indptr)))
    assert np.array_equal(A.indices[where], sub.indices)
    assert positions_within(B.indptr, B.indices, A.indptr, A.indices).size == 0     # B has entries off A
    indptr, indices = union_pattern(A.indptr, A.indices, B.indptr, B.indices)
    U = (abs(A) + abs(B)).tocsr()
    U.sort_indices()
    assert np.array_equal(indptr, U.indptr) and np.array_equal(indices, U.indices)


@pytest.mark.parametrize("symmetric", [True, False])
def test_a_matrix_within_the_pattern_is_factorized_on_the_kept_analysis(cube, symmetric):
    """The second matrix (contact springs on a subset of the first's couplings, other values)
    reuses the analysis; the third couples other dofs and is analysed on the union; each
    solves its own system to round-off, and the solver whose analysis was taken refuses to
    solve."""
    K = cube if symmetric else (cube + sp.triu(cube, 1) * 1e-3).tocsr()
    first = coupled(K, [(0, 500), (3, 400), (7, 300)], 2e3)
    within = coupled(K, [(3, 400)], 5e2)            # a subset of first's extra entries
    beyond = coupled(K, [(11, 200), (3, 400)], 1e3)  # (11, 200) is new
    b = np.random.default_rng(1).standard_normal(K.shape[0])
    s1 = linear.build(first, "pardiso", symmetric=symmetric)
    assert s1.info["analysed"]
    x1 = s1.solve(b)
    s2 = linear.build(within, "pardiso", symmetric=symmetric, reuse=s1)
    assert not s2.info["analysed"]
    with pytest.raises(LinearSolverError, match="superseded"):
        s1.solve(b)
    x2 = s2.solve(b)
    s3 = linear.build(beyond, "pardiso", symmetric=symmetric, reuse=s2)
    assert s3.info["analysed"]
    x3 = s3.solve(b)
    for M, x in ((first, x1), (within, x2), (beyond, x3)):
        assert np.linalg.norm(M @ x - b) <= 1e-9 * np.linalg.norm(b)
        exact = np.linalg.solve(M.toarray(), b)
        assert np.abs(x - exact).max() <= 1e-10 * np.abs(exact).max()
    s4 = linear.build(first, "pardiso", symmetric=symmetric, reuse=s3)   # within the union
    assert not s4.info["analysed"]
    assert np.abs(s4.solve(b) - x1).max() <= 1e-10 * np.abs(x1).max()


def test_the_same_matrices_in_the_same_order_give_the_same_bits(cube):
    """Two chains of factorizations on kept analyses, the same matrices: bitwise equal."""
    b = np.random.default_rng(2).standard_normal(cube.shape[0])
    mats = [coupled(cube, [(0, 500)], 1e3), coupled(cube, [(0, 500)], 3e3), coupled(cube, [(9, 100)], 2e3)]
    runs = []
    for _ in range(2):
        solver, xs = None, []
        for M in mats:
            solver = linear.build(M, "pardiso", symmetric=True, reuse=solver)
            xs.append(solver.solve(b))
        runs.append(xs)
    assert all(np.array_equal(x, y) for x, y in zip(*runs))


def test_a_solver_of_another_size_or_type_lends_nothing(cube):
    """Reuse needs the same size and matrix type: otherwise a fresh analysis, and the lender
    keeps its factorization."""
    b = np.ones(cube.shape[0])
    s1 = linear.build(cube, "pardiso", symmetric=True)
    s2 = linear.build((cube + sp.triu(cube, 1) * 1e-3).tocsr(), "pardiso", symmetric=False, reuse=s1)
    assert s2.info["analysed"] and s2.info["mtype"] == 11
    small = cube[:90, :90].tocsr()
    s3 = linear.build(small, "pardiso", symmetric=True, reuse=s1)
    assert s3.info["analysed"]
    assert np.linalg.norm(cube @ s1.solve(b) - b) <= 1e-8 * np.linalg.norm(b)


def floating_pair(cube: sp.csr_matrix, shift: float) -> sp.csr_matrix:
    """Two copies of the clamped cube, the second's clamp released to a diagonal ``shift``
    (a fraction of its diagonal: a body held only weakly, as a floating body's stabilized
    tangent) and tied to the first by one stiff spring: nearly singular for a small shift."""
    free = fx.stiffness(4, 4, 4)
    free = (free + sp.diags(shift * free.diagonal())).tocsr()
    M = sp.block_diag([cube, free], format="csr")
    return coupled(M, [(cube.shape[0] - 1, cube.shape[0] + 1)], 1e-3 * cube.diagonal().max())


@pytest.mark.parametrize("symmetric", [True, False])
def test_single_precision_factors_are_refined_to_the_check_in_double(cube, symmetric):
    """Factors in single precision: their own solution has the residual of float32 (far above
    the double factors' round-off), one or two steps of refinement in double bring it below
    the check, and the solution is the double factors' to that accuracy; the same matrices in
    the same order give the same bits again."""
    K = cube if symmetric else (cube + sp.triu(cube, 1) * 1e-3).tocsr()
    M = coupled(K, [(0, 500), (3, 400)], 10.0)   # springs of 27 times the largest diagonal
    b = np.random.default_rng(4).standard_normal(M.shape[0])
    double = linear.build(M, "pardiso", symmetric=symmetric)
    single = linear.build(M, "pardiso", symmetric=symmetric, single=True)
    assert (double.info["precision"], single.info["precision"]) == ("double", "single")
    raw = single.solve_unchecked(b)
    assert 1e-10 < np.linalg.norm(M @ raw - b) / np.linalg.norm(b) < 1e-5
    x, reference = single.solve(b), double.solve(b)
    assert double.info["iterations"][-1] == 0 < single.info["iterations"][-1] <= 2
    assert single.info["residuals"][-1] <= linear.DIRECT_CHECK
    assert np.linalg.norm(M @ x - b) <= linear.DIRECT_CHECK * np.linalg.norm(b)
    assert np.abs(x - reference).max() <= 1e-6 * np.abs(reference).max()
    again = linear.build(M, "pardiso", symmetric=symmetric, single=True)
    assert np.array_equal(again.solve(b), x)


def test_single_factors_that_fall_short_are_factorized_again_in_double(cube):
    """A nearly singular matrix (a weakly held body, shift 1e-7 of its diagonal): refinement
    with single-precision factors cannot reach the check, so the matrix is factorized again in
    double precision, which solves it; a solver of the other precision lends no analysis."""
    M = floating_pair(cube, 1e-7)
    b = np.random.default_rng(5).standard_normal(M.shape[0])
    solver = linear.build(M, "pardiso", symmetric=True, single=True)
    raw = solver.solve_unchecked(b)
    assert np.linalg.norm(M @ raw - b) > 1e3 * linear.DIRECT_CHECK * np.linalg.norm(b)
    x = solver.solve(b)
    assert solver.info["precision"] == "double after single"
    assert np.linalg.norm(M @ x - b) <= linear.DIRECT_CHECK * np.linalg.norm(b)
    nxt = linear.build(M, "pardiso", symmetric=True, reuse=solver)    # double: takes the analysis
    assert not nxt.info["analysed"]
    other = linear.build(M, "pardiso", symmetric=True, single=True, reuse=nxt)
    assert other.info["analysed"]
    assert np.linalg.norm(M @ nxt.solve(b) - b) <= 1e-8 * np.linalg.norm(b)


def test_newtons_solves_take_single_factors_until_one_falls_short(cube):
    """:class:`LinearSolves` (the direct path) factorizes in single precision where no body
    floats and the policy asks for it; after a matrix that needed double factors, every later
    matrix gets them at once (logged); a system with a floating body, or the policy
    ``factor_precision="double"``, always gets double factors."""
    from dataclasses import replace

    from cgfem.solve.policy import SolverPolicy
    from cgfem.solve.solves import LinearSolves

    good, bad = coupled(cube, [(0, 500)], 10.0), floating_pair(cube, 1e-7)
    lines: list[str] = []
    solves = LinearSolves("auto", None, log=lines.append)
    precisions = []
    for M in (good, bad, good):
        b = np.random.default_rng(6).standard_normal(M.shape[0])
        x = solves(M, b)
        assert np.linalg.norm(M @ x - b) <= linear.DIRECT_CHECK * np.linalg.norm(b)
        precisions.append(solves._factor.info["precision"])
    assert precisions == ["single", "double after single", "double"]
    assert sum("double precision" in line for line in lines) == 1
    for kwargs in ({"floating": True}, {"policy": replace(SolverPolicy(), factor_precision="double")}):
        solves = LinearSolves("auto", None, **kwargs)
        solves(good, np.ones(good.shape[0]))
        assert solves._factor.info["precision"] == "double"
