"""The Krylov path of Newton's linear solves on a two-body contact-like system: a clamped
cube and a cube held by contact alone (penalty springs between facing nodes, stiffness of
order kappa E / h, the floating body's small tangent shift), symmetric and non-symmetric."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from tests.support import elasticity_fixture as fx
from cgfem.solve.krylov import AMGPreconditioner, krylov_solve
from cgfem.solve.linear import available_backends, mode_bodies, rigid_body_modes
from cgfem.solve.multigrid import smoothed_aggregation, v_cycle
from cgfem.solve.policy import SolverPolicy
from cgfem.solve.solves import DIRECT, KRYLOV, LinearSolves

N = 6


def two_bodies(symmetric: bool = True, coupling: float = 1.0, seed: int = 0):
    """(K, b, near_null): cube A (N^3 elements, E = 1, h = 1) clamped by a penalty on z = 0,
    cube B above it with no condition, the top nodes of A tied to the facing bottom nodes of
    B by springs of stiffness ``coupling`` times A's largest diagonal (the contact block), B's
    diagonal shifted by 1e-8 of itself (the floating body's shift). ``symmetric=False`` adds
    a non-symmetric coupling of 10 % (finite strain's current-area weight). Load: B's top
    pulled sideways and down."""
    rng = np.random.default_rng(seed)
    K1 = fx.stiffness(N, N, N)
    x = fx.grid_coords(N, N, N)
    n1 = K1.shape[0]
    bottom = np.flatnonzero(np.repeat(x[:, 2] == 0.0, 3))
    KA = K1 + sp.csr_matrix((np.full(bottom.size, 1e3 * K1.diagonal().max()), (bottom, bottom)), shape=K1.shape)
    KB = K1 + sp.diags(1e-8 * K1.diagonal())
    top_a = np.flatnonzero(x[:, 2] == N)
    bottom_b = np.flatnonzero(x[:, 2] == 0.0)
    k = coupling * K1.diagonal().max()
    rows, cols, vals = [], [], []
    for a, b in zip(top_a, bottom_b):
        for c in range(3):
            i, j = 3 * a + c, n1 + 3 * b + c
            w = k * (1.0 + 0.1 * rng.random())
            skew = 0.0 if symmetric else 0.1 * w * rng.standard_normal()
            rows += [i, j, i, j]
            cols += [i, j, j, i]
            vals += [w, w, -w + skew, -w - skew]
    C = sp.coo_matrix((vals, (rows, cols)), shape=(2 * n1, 2 * n1))
    K = (sp.block_diag([KA, KB]) + C).tocsr()
    b = np.zeros(2 * n1)
    top_b = np.flatnonzero(x[:, 2] == N)
    b[n1 + 3 * top_b] = 0.3 / top_b.size
    b[n1 + 3 * top_b + 2] = -1.0 / top_b.size
    xb = x + [0.0, 0.0, N + 0.1]
    near_null = sp.block_diag([rigid_body_modes(x), rigid_body_modes(xb)]).toarray()
    return K, b, near_null


def policy(**changes) -> SolverPolicy:
    return replace(SolverPolicy(), krylov_min_dofs=0, krylov_nonsymmetric_min_dofs=0, **changes)


@pytest.mark.parametrize("symmetric", [True, False])
def test_amg_krylov_solves_a_body_held_by_contact(symmetric):
    """CG (symmetric) or GMRES reaches 1e-10 on the true residual in few iterations, with the
    floating body's rigid motions (stiffness 1e-8 of the diagonal) carried by the near-null
    space, and its solution is the direct one."""
    K, b, B = two_bodies(symmetric)
    M = AMGPreconditioner(K, B, symmetric)
    x, its, res, ok = krylov_solve(K, b, M, 1e-10, 200, symmetric)
    assert ok and res <= 1e-10 and its <= 60
    exact = sp.linalg.spsolve(K.tocsc(), b)
    assert np.linalg.norm(x - exact) <= 1e-6 * np.linalg.norm(exact)
    # with pyamg's default near-null space (the translations of each node block) the
    # rotations are not caught: more iterations (26 against 40 measured, symmetric; 26 and 43)
    _, its_plain, _, _ = krylov_solve(K, b, AMGPreconditioner(K, None, symmetric), 1e-10, 200, symmetric)
    assert its_plain > 1.25 * its


def test_aggregates_of_every_level_lie_within_one_body():
    """With the bodies' labels (from the blocks of the rigid-body modes) no aggregate of any
    level joins nodes of the two cubes; on pyamg's own strength, where the contact springs
    count as couplings, some of the finest level's do, and with the labels on the finest
    level alone (pyamg's own strength below it) some of the next level's."""
    import pyamg

    from cgfem.solve.multigrid import strength_within_bodies

    K, _, B = two_bodies(True, 1.0)
    As = sp.csr_matrix(K).tobsr(blocksize=(3, 3))
    bodies = mode_bodies(B)[::3]
    assert set(bodies) == {0, 1}

    def mixed(ml) -> list[int]:
        labels, counts = bodies, []
        for level in ml.levels[:-1]:
            agg = level.AggOp.tocsc()
            groups = [np.unique(labels[agg.indices[agg.indptr[j]:agg.indptr[j + 1]]]) for j in range(agg.shape[1])]
            counts.append(sum(g.size > 1 for g in groups))
            labels = np.array([g[0] for g in groups])
        return counts
    within = smoothed_aggregation(As, B=B, keep=True, improve_candidates=None, bodies=bodies)
    assert len(within.levels) >= 3 and mixed(within) == [0] * (len(within.levels) - 1)
    assert np.array_equal(within.levels[0].bodies, bodies)
    assert mixed(smoothed_aggregation(As, B=B, keep=True, improve_candidates=None))[0] > 0
    finest_only = pyamg.smoothed_aggregation_solver(
        As, B=B, keep=True, improve_candidates=None,
        strength=[("predefined", {"C": strength_within_bodies(As, bodies)}), "symmetric"])
    counts = mixed(finest_only)
    assert counts[0] == 0 and counts[1] > 0


@pytest.mark.parametrize("symmetric", [True, False])
def test_preconditioner_is_kept_for_the_next_matrix(symmetric):
    """A preconditioner built on one Newton matrix solves the next one (contact stiffer by
    20 %) in few iterations: it is kept, not rebuilt; the solution is that of the new
    matrix. Inexact Newton's looser tolerance is met, not exceeded by much."""
    K0, b, B = two_bodies(symmetric, 1.0)
    K1, _, _ = two_bodies(symmetric, 1.2, seed=1)
    solves = LinearSolves("auto", B, symmetric, policy=policy())
    assert solves.path(K0.shape[0]) == KRYLOV
    solves(K0, b)
    x = solves(K1, b)
    assert [h[2] for h in solves.history] == ["new", "kept"]
    assert np.linalg.norm(K1 @ x - b) <= 1e-10 * np.linalg.norm(b)
    loose = solves(K1, 2 * b, 1e-4)
    residual = np.linalg.norm(K1 @ loose - 2 * b) / np.linalg.norm(2 * b)
    assert residual <= 1e-4 and solves.history[-1][1] < solves.history[-2][1]


@pytest.mark.parametrize("rate", [0.0, 1.5])
def test_slow_solve_refreshes_the_preconditioner(rate):
    """A kept preconditioner whose solve needs more than :meth:`LinearSolves.kept_limit`
    iterations is rebuilt on the current matrix and the solve goes on from where it got. The
    limit is ``krylov_refresh`` (here 3) or, with ``krylov_refresh_rate``, that factor times
    the fresh solve's iterations per decade of residual times the decades asked for."""
    K0, b, B = two_bodies(True, 1.0)
    K1, _, _ = two_bodies(True, 30.0, seed=1)        # a far stiffer contact block
    solves = LinearSolves("auto", B, True, policy=policy(krylov_refresh=3, krylov_refresh_rate=rate))
    solves(K0, b)
    fresh = solves.history[-1][1]
    res = np.linalg.norm(K0 @ solves(K0, b) - b) / np.linalg.norm(b)   # the same matrix: kept
    assert solves.history[-1][2] == "kept"
    limit = solves.kept_limit(1e-10)
    if rate == 0.0:
        assert limit == 3
    else:   # the fresh solve reached at most 1e-10 (its own residual): at least 10 decades
        assert 3 < limit <= int(np.ceil(rate * fresh))
    x = solves(K1, b)
    assert solves.history[-1][2] == f"refreshed after {limit}"
    assert np.linalg.norm(K1 @ x - b) <= 1e-10 * np.linalg.norm(b) and res <= 1e-10


def test_preconditioner_kept_while_it_converges_at_its_fresh_rate():
    """A kept preconditioner that needs more than ``krylov_refresh`` iterations but no more
    than ``krylov_refresh_rate`` times its fresh rate (contact 20 % stiffer: 35 iterations
    against 31 fresh) is kept; without the rate it is rebuilt."""
    K0, b, B = two_bodies(True, 1.0)
    K1, _, _ = two_bodies(True, 1.2, seed=1)
    for rate, note in [(1.5, "kept"), (0.0, "refreshed after 3")]:
        solves = LinearSolves("auto", B, True, policy=policy(krylov_refresh=3, krylov_refresh_rate=rate))
        solves(K0, b)
        x = solves(K1, b)
        assert solves.history[-1][2] == note and solves.history[-1][1] > 3
        assert np.linalg.norm(K1 @ x - b) <= 1e-10 * np.linalg.norm(b)


def test_stalled_solve_falls_back_to_a_factorization():
    """A Krylov solve that cannot reach its tolerance even with a fresh preconditioner (here
    allowed 2 iterations) falls back to a direct factorization of that matrix, logged, and
    the solution is exact; the same matrix then reuses that factorization."""
    K, b, B = two_bodies(False)
    lines: list[str] = []
    solves = LinearSolves("auto", B, False, policy=policy(krylov_max_iterations=2, krylov_refresh=2),
                          log=lines.append)
    x = solves(K, b)
    assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b)
    assert solves.history[-1][0] == DIRECT and solves.history[-1][2] == "fallback"
    assert any("stalled" in line and "fell back" in line for line in lines)
    solves(K, 2 * b)
    assert solves.history[-1][2] == "fallback kept"


@pytest.mark.parametrize("stay", [0, 2])
def test_after_a_stall_the_next_matrices_are_factorized_directly(stay):
    """After a stalled solve (every Krylov solve here stalls: 2 iterations allowed) the next
    ``krylov_stall_direct`` new matrices are factorized without a Krylov attempt, the
    analysis of each kept for the next; the one after them tries Krylov again."""
    mats = [two_bodies(False, c, seed=k)[0] for k, c in enumerate((1.0, 1.1, 1.2, 1.3))]
    _, b, B = two_bodies(False)
    lines: list[str] = []
    solves = LinearSolves("auto", B, False, log=lines.append,
                          policy=policy(krylov_max_iterations=2, krylov_refresh=2, krylov_stall_direct=stay))
    notes, analysed = [], []
    for K in mats:
        x = solves(K, b)
        assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b)
        notes.append(solves.history[-1][2])
        analysed.append(solves._factor.info.get("analysed"))
    expected = ["fallback", "after a stall", "after a stall", "fallback"] if stay == 2 else ["fallback"] * 4
    assert notes == expected
    if stay and "pardiso" in available_backends():
        assert analysed == [True, False, False, True]       # the same pattern: analysed once
    if stay:
        assert any("after a stall (0 more matrices)" in line for line in lines)


def test_direct_below_the_size_thresholds_and_for_saddle_points_not_given():
    """``auto`` takes the direct path below ``krylov_min_dofs`` (a non-symmetric system below
    ``krylov_nonsymmetric_min_dofs``), with a body held by contact alone below
    ``krylov_floating_min_dofs``, for a saddle point below
    ``krylov_saddle_min_dofs`` or whose fit constraints are not given; an explicit backend
    always."""
    K, b, B = two_bodies(True)
    n = K.shape[0]
    assert LinearSolves("auto", B, policy=replace(SolverPolicy(), krylov_min_dofs=n + 1)).path(n) == DIRECT
    assert LinearSolves("auto", B, policy=policy()).path(n) == KRYLOV
    for floating, least, path in ((True, n + 1, DIRECT), (True, n, KRYLOV), (False, n + 1, KRYLOV)):
        given = policy(krylov_floating_min_dofs=least)
        assert LinearSolves("auto", B, policy=given, floating=floating).path(n) == path
    # a direct-only policy stays direct for a floating body below its own threshold
    given = replace(SolverPolicy(), krylov_min_dofs=n + 1, krylov_floating_min_dofs=0)
    assert LinearSolves("auto", B, policy=given, floating=True).path(n) == DIRECT
    # triquadratic elements have their own threshold; a floating body's adds to it
    given = replace(SolverPolicy(), krylov_min_dofs=n + 1, krylov_order2_min_dofs=n, krylov_floating_min_dofs=0)
    assert LinearSolves("auto", B, policy=given, order=2).path(n) == KRYLOV
    assert LinearSolves("auto", B, policy=given, order=1).path(n) == DIRECT
    given = replace(given, krylov_floating_min_dofs=n + 1)
    assert LinearSolves("auto", B, policy=given, order=2, floating=True).path(n) == DIRECT
    # contact in finite strain (a non-symmetric system) has its own threshold at order 1
    given = replace(SolverPolicy(), krylov_min_dofs=0, krylov_nonsymmetric_min_dofs=n + 1)
    assert LinearSolves("auto", B, symmetric=False, policy=given).path(n) == DIRECT
    assert LinearSolves("auto", B, symmetric=True, policy=given).path(n) == KRYLOV
    assert LinearSolves("auto", B, symmetric=False, policy=replace(given, krylov_nonsymmetric_min_dofs=n)).path(n) \
        == KRYLOV
    assert LinearSolves("auto", B, symmetric=False, policy=replace(given, krylov_order2_min_dofs=n),
                        order=2).path(n) == KRYLOV
    assert LinearSolves("auto", B, indefinite=True, policy=policy()).path(n) == DIRECT
    saddle = (n, [])
    for least, path in ((n, KRYLOV), (n + 1, DIRECT)):
        given = replace(SolverPolicy(), krylov_min_dofs=10**9, krylov_saddle_min_dofs=least)
        assert LinearSolves("auto", B, indefinite=True, saddle=saddle, policy=given).path(n) == path
    assert LinearSolves("superlu", B, policy=policy()).path(n) == DIRECT


def test_per_body_modes_collapse_to_six_columns_with_the_same_span_per_body():
    """Two bodies' modes (n, 12), block by block, become (n, 6) whose rows on each body are
    that body's own modes; columns that mix bodies in a row are left alone."""
    from cgfem.solve.krylov import collapse_modes
    _, _, B = two_bodies(True)
    C = collapse_modes(B, mode_bodies(B))
    n1 = B.shape[0] // 2
    assert C.shape == (B.shape[0], 6)
    np.testing.assert_array_equal(C[:n1], B[:n1, :6])
    np.testing.assert_array_equal(C[n1:], B[n1:, 6:])
    mixed = B.copy()
    mixed[0, 7] = 1.0
    assert mode_bodies(mixed) is None and collapse_modes(mixed, mode_bodies(mixed)) is mixed
    assert collapse_modes(B[:, :6], mode_bodies(B[:, :6])).shape == (B.shape[0], 6)


@pytest.mark.parametrize("symmetric", [True, False])
def test_preconditioners_of_the_same_matrix_are_bitwise_equal(symmetric):
    """pyamg's set-up starts its spectral-radius estimates from numpy's global generator: two
    hierarchies of the same matrix apply bitwise the same V-cycle, and two Krylov solves give
    bitwise the same iterates, only because the set-up runs at a fixed seed; the caller's
    generator continues where it was."""
    K, b, B = two_bodies(symmetric)
    np.random.seed(7)
    expected = np.random.rand(3)
    np.random.seed(7)
    first = AMGPreconditioner(K, B, symmetric)
    np.random.rand(5)               # another state of the global generator at the next set-up
    second = AMGPreconditioner(K, B, symmetric)
    assert np.array_equal(first(b), second(b))
    x1 = krylov_solve(K, b, first, 1e-10, 200, symmetric)[0]
    x2 = krylov_solve(K, b, second, 1e-10, 200, symmetric)[0]
    assert np.array_equal(x1, x2)
    np.random.seed(7)
    AMGPreconditioner(K, B, symmetric)
    assert np.array_equal(np.random.rand(3), expected)


@pytest.mark.parametrize("symmetric", [True, False])
def test_one_v_cycle_is_pyamgs_solve_of_one_cycle(symmetric):
    """:func:`~cgfem.solve.multigrid.v_cycle` (without pyamg's residual norms, the residual
    after the pre-smoothing a product with one triangle) returns what
    ``ml.solve(b, maxiter=1, cycle="V")`` returns to round-off, for the hierarchies the
    project builds (nodal blocks, rigid-body modes, symmetric or not; one sweep or pyamg's
    symmetric sweeps on each side), and bit for bit for a single level."""
    K, b, B = two_bodies(symmetric)
    r = np.random.default_rng(5).standard_normal(K.shape[0])
    scaled = sp.csr_matrix(K).tobsr(blocksize=(3, 3))
    for ml in (AMGPreconditioner(K, B, symmetric)._ml, smoothed_aggregation(scaled)):
        assert len(ml.levels) >= 3
        for rhs in (r, b):
            theirs = ml.solve(rhs, maxiter=1, cycle="V", tol=1e-300)
            ours = v_cycle(ml, rhs)
            assert np.allclose(ours, theirs, rtol=0.0, atol=1e-12 * np.abs(theirs).max())
            assert not np.array_equal(ours, np.zeros_like(ours))
    single = smoothed_aggregation(sp.csr_matrix(fx.stiffness(2, 2, 2) + sp.eye(81)), max_levels=1)
    assert len(single.levels) == 1
    assert np.array_equal(v_cycle(single, r[:81]), single.solve(r[:81], maxiter=1, tol=1e-300))


@pytest.mark.parametrize("pre", ["forward", "backward", "symmetric"])
def test_presmoothing_from_zero_reads_one_triangle_for_the_residual(pre):
    """On every level (3x3 blocks on the finest, 6x6 below with the modes summed over the
    bodies) the pre-smoothing from zero of :class:`~cgfem.solve.multigrid.BlockSmoother`
    gives the bits of the same sweeps of the full rows, and its residual, a product with the
    triangle the last sweep left behind, is ``b - A x`` to round-off; with the two bodies'
    twelve modes apart the 12x12 diagonal blocks of an aggregate of one body are singular,
    and there the residual is computed from ``A``."""
    from cgfem.solve.krylov import collapse_modes

    K, b, B = two_bodies(False)
    rng = np.random.default_rng(8)
    sizes = {}
    for modes in (collapse_modes(B, mode_bodies(B)), B):
        ml = smoothed_aggregation(sp.csr_matrix(K).tobsr(blocksize=(3, 3)), pre=pre, post=pre, B=modes,
                                  symmetry="nonsymmetric", improve_candidates=None)
        for level in ml.levels[:-1]:
            A, smoother = level.A, level.block_smoother
            sizes[A.blocksize[0]] = smoother._A is None
            rhs = rng.standard_normal(A.shape[0])
            full = np.zeros(A.shape[0])
            level.presmoother(A, full, rhs)
            x, residual = smoother.presmooth(rhs)
            assert np.array_equal(x, full)
            expected = rhs - A @ x
            assert np.allclose(residual, expected, rtol=0.0, atol=1e-12 * np.abs(rhs).max())
            assert np.abs(expected).max() > 1e-3 * np.abs(rhs).max()
    assert sizes == {3: True, 6: True, 12: False}


def test_sweeps_written_out_for_3x3_blocks_are_the_loops_bit_for_bit():
    """The 3x3 kernels are the generic loops' arithmetic, operation for operation."""
    from cgfem.solve import _smoother_kernels as kernels
    from cgfem.solve.multigrid import BlockSmoother

    K, b, _ = two_bodies(False)
    smoother = BlockSmoother(sp.csr_matrix(K).tobsr(blocksize=(3, 3)), "forward", "backward")
    x0 = np.random.default_rng(9).standard_normal(K.shape[0])
    for forward in (True, False):
        ours, theirs = x0.copy(), x0.copy()
        kernels.sweep3(*smoother.lower, *smoother.upper, smoother.dinv, ours, b, forward)
        kernels.sweep(*smoother.lower, *smoother.upper, smoother.dinv, theirs, b, forward)
        assert np.array_equal(ours, theirs) and not np.array_equal(ours, x0)
    for part in (smoother.lower, smoother.upper):
        ours, theirs = np.empty_like(x0), np.empty_like(x0)
        kernels.product3(*part, x0, ours)
        kernels.product(*part, x0, theirs)
        assert np.array_equal(ours, theirs)


@pytest.mark.parametrize("symmetric", [True, False])
def test_block_sweeps_do_pyamgs_block_gauss_seidel(symmetric):
    """On every level of a hierarchy the project builds (3x3 blocks on the finest, 6x6 with
    the rigid modes below) a forward sweep of the kernel gives pyamg's block Gauss-Seidel to
    the last bit, and a backward sweep (which reads each row's blocks backwards) to round-off;
    a symmetric sweep is the two in turn."""
    from pyamg.relaxation.relaxation import block_gauss_seidel as pyamg_sweep

    K, b, B = two_bodies(symmetric)
    ml = AMGPreconditioner(K, B, symmetric)._ml
    assert len(ml.levels) >= 3
    rng = np.random.default_rng(6)
    for level in ml.levels[:-1]:
        A, m = level.A, level.A.blocksize[0]
        rhs, x0 = rng.standard_normal(A.shape[0]), rng.standard_normal(A.shape[0])
        for smoother, sweep in ((level.presmoother, "forward"), (level.postsmoother, "backward")):
            ours, theirs = x0.copy(), x0.copy()
            smoother(A, ours, rhs)
            pyamg_sweep(A, theirs, rhs, sweep=sweep, blocksize=m)
            if sweep == "forward":
                assert np.array_equal(ours, theirs)
            else:
                assert np.allclose(ours, theirs, rtol=0.0, atol=1e-13 * np.abs(theirs).max())
                assert not np.allclose(ours, x0)
    default = smoothed_aggregation(sp.csr_matrix(K).tobsr(blocksize=(3, 3)))   # pyamg's symmetric sweeps
    level = default.levels[0]
    ours, theirs = np.zeros(K.shape[0]), np.zeros(K.shape[0])
    level.presmoother(level.A, ours, b)
    pyamg_sweep(level.A, theirs, b, sweep="symmetric", blocksize=level.A.blocksize[0])
    assert np.allclose(ours, theirs, rtol=0.0, atol=1e-13 * np.abs(theirs).max())


@pytest.mark.parametrize("precision", ["double", "single"])
def test_again_solves_another_right_hand_side_with_the_last_factorization(precision):
    """``again`` reuses the direct path's factorization of the last matrix for another
    right-hand side (the floating bodies' cut rotations): the solution of that matrix (to
    round-off with double factors, refined to the solves' check with single ones, whose own
    solution is good to about 1e-7), and no new factorization; off the direct path it
    refuses."""
    from cgfem.solve.linear import DIRECT_CHECK, LinearSolverError
    K, b, B = two_bodies(True)
    n = K.shape[0]
    solves = LinearSolves("auto", B, policy=replace(SolverPolicy(), krylov_min_dofs=n + 1,
                                                    factor_precision=precision))
    solves(K, b)
    factor = solves._factor
    assert factor.info["precision"] == precision
    c = np.random.default_rng(3).standard_normal(n)
    x = solves.again(c)
    assert solves._factor is factor
    assert np.linalg.norm(K @ x - c) <= (1e-10 if precision == "double" else DIRECT_CHECK) * np.linalg.norm(c)
    krylov = LinearSolves("auto", B, policy=policy())
    krylov(K, b)
    with pytest.raises(LinearSolverError):
        krylov.again(c)
