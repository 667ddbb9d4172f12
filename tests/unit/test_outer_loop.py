"""The outer loop: its fixed-point relaxation (Aitken / Irons-Tuck) on affine maps, and the
Newton attempts of a pass (modified Newton first, then full Newton from its best point)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from cgfem.solve.newton import NewtonResult
from cgfem.solve.outer import Relaxation, newton_pass


@pytest.mark.parametrize("a", [0.6, -0.5, 0.2])
def test_relaxation_solves_a_scalar_contraction_after_two_recoveries(a):
    """For G(x) = a x + b the secant factor is 1 / (1 - a): the second relaxed iterate is
    the fixed point b / (1 - a) (plain substitution only approaches it as a^k)."""
    rng = np.random.default_rng(4)
    b = [rng.standard_normal((7, 3, 3)), rng.standard_normal((4, 3, 3))]     # two bodies
    fixed = [bi / (1.0 - a) for bi in b]
    relax = Relaxation()
    x = [np.zeros_like(bi) for bi in b]
    x = relax.next(x, [a * xi + bi for xi, bi in zip(x, b)])       # omega = 1 first
    x = relax.next(x, [a * xi + bi for xi, bi in zip(x, b)])
    assert relax.omega == pytest.approx(1.0 / (1.0 - a), rel=1e-12)
    for xi, fi in zip(x, fixed):
        assert np.abs(xi - fi).max() <= 1e-12 * np.abs(fi).max()
    plain = Relaxation(enabled=False)
    y = [np.zeros_like(bi) for bi in b]
    for _ in range(2):
        y = plain.next(y, [a * yi + bi for yi, bi in zip(y, b)])
    error = max(np.abs(yi - fi).max() / np.abs(fi).max() for yi, fi in zip(y, fixed))
    assert error == pytest.approx(abs(a) ** 2, rel=1e-12)


def test_relaxation_starts_plain_and_bounds_its_factor():
    """No frozen stress yet (None): the recovery itself; a slow contraction (a = 0.95, secant
    factor 20) is clipped to OMEGA_MAX, and the next iterate still moves towards the fixed point."""
    relax = Relaxation()
    r = [np.ones((2, 3, 3))]
    assert relax.next([None], r) is r
    b = np.ones((2, 3, 3))
    x = relax.next([np.zeros_like(b)], [b])
    x = relax.next(x, [0.95 * x[0] + b])
    assert relax.omega == Relaxation.OMEGA_MAX
    assert np.allclose(x[0], 1.0 + 4.0 * 0.95)            # x1 + omega r1, r1 = 0.95 b
    assert abs(x[0] - 20.0).max() < abs(0.95 + 1.0 - 20.0)  # nearer than plain substitution


def _attempts(modified: NewtonResult, *full: NewtonResult):
    """An ``attempt`` returning ``modified`` for modified Newton and the ``full`` results in
    turn for full Newton; and the list of its calls (start, fixed_tangent)."""
    calls, results = [], list(full)

    def attempt(start, fixed_tangent):
        calls.append((start.copy(), fixed_tangent))
        return modified if fixed_tangent else results.pop(0)
    return attempt, calls


def test_full_newton_goes_on_from_where_modified_newton_got_to():
    u0 = np.zeros(3)
    modified = NewtonResult(np.full(3, 0.9), False, [1e-3, 1e-4, 1e-5, 1e-6], 1.0, "max_iterations")
    full = NewtonResult(np.ones(3), True, [1e-6, 1e-12], 1.0, "converged")
    attempt, calls = _attempts(modified, full)
    result, history = newton_pass(attempt, u0, modified_first=True)
    assert result is full
    assert [f for _, f in calls] == [True, False]
    np.testing.assert_array_equal(calls[1][0], modified.u)       # not the pass's start
    assert history == [1e-3, 1e-4, 1e-5, 1e-6, 1e-12]             # the shared iterate once


def test_full_newton_restarts_when_modified_newton_went_up():
    u0 = np.zeros(3)
    for reason, residuals in [("max_iterations", [1e-3, 1e-2]), ("line_search", [1e-3, 1e-4])]:
        modified = NewtonResult(np.full(3, 0.9), False, residuals, 1.0, reason)
        full = NewtonResult(np.ones(3), True, [1e-3, 1e-12], 1.0, "converged")
        attempt, calls = _attempts(modified, full)
        result, history = newton_pass(attempt, u0, modified_first=True)
        np.testing.assert_array_equal(calls[1][0], u0)
        assert history == [1e-3, 1e-12]


def test_first_pass_and_converged_modified_newton_make_one_attempt():
    u0 = np.zeros(3)
    done = NewtonResult(np.ones(3), True, [1e-3, 1e-12], 1.0, "converged")
    for modified_first in (True, False):
        attempt, calls = _attempts(done, done)
        result, history = newton_pass(attempt, u0, modified_first=modified_first)
        assert [f for _, f in calls] == [modified_first]
        assert history == [1e-3, 1e-12]


def test_full_newton_from_the_pass_start_when_it_fails_from_modified_newtons_point():
    u0 = np.zeros(3)
    modified = NewtonResult(np.full(3, 0.9), False, [1e-3, 1e-5, 1e-6], 1.0, "max_iterations")
    stuck = NewtonResult(np.full(3, 0.95), False, [1e-6, 9e-7], 1.0, "line_search")
    full = NewtonResult(np.ones(3), True, [1e-3, 1e-12], 1.0, "converged")
    attempt, calls = _attempts(modified, stuck, full)
    result, history = newton_pass(attempt, u0, modified_first=True)
    assert result is full
    assert [f for _, f in calls] == [True, False, False]
    np.testing.assert_array_equal(calls[1][0], modified.u)
    np.testing.assert_array_equal(calls[2][0], u0)
    assert history == [1e-3, 1e-12]


def test_anderson_solves_an_affine_map_of_low_rank_exactly():
    """Anderson mixing of depth m on G(x) = x0 + A (x - x0) with A of rank 2 (two coupled
    error components, contractions 0.6 and -0.5): after the recovery of the third pass the
    next iterate is the fixed point x0 to round-off, where plain substitution is still
    0.6^3 off and Aitken's single factor cannot remove both components."""
    from cgfem.solve.outer import Anderson
    rng = np.random.default_rng(7)
    shape = (5, 3, 3)
    x0 = rng.standard_normal(shape)
    V = np.linalg.qr(rng.standard_normal((x0.size, 2)))[0]
    A = V @ np.diag([0.6, -0.5]) @ V.T

    def G(x):
        return x0 + (A @ (x - x0).ravel()).reshape(shape)
    anderson = Anderson(depth=3)
    x = x0 + (V @ np.array([1.0, 2.0])).reshape(shape)     # the error in A's range
    for _ in range(3):
        x = anderson.next([x], [G(x)])[0]
    assert np.abs(x - x0).max() <= 1e-12
    recovered = [x0]
    assert Anderson().next([None], recovered) is recovered     # nothing frozen yet: the recovery


def test_anderson_passes_a_broken_recovery_on_and_starts_afresh():
    """A NaN in the recovered stress (a pass that broke) is handed on unmixed, for Newton
    to fail on and the increment to be cut back, and the mixing history restarts: no
    least-squares solve on NaN (numpy's SVD raised LinAlgError there)."""
    from cgfem.solve.outer import Anderson
    anderson = Anderson(depth=3)
    x = [np.ones((2, 3, 3))]
    anderson.next(x, [0.5 * x[0]])
    broken = [np.full((2, 3, 3), np.nan)]
    assert anderson.next(x, broken) is broken
    fine = [0.25 * x[0]]
    # the history restarted: one pass again, nothing to mix (the pass before the break would
    # have been mixed with this one)
    assert anderson.next(x, fine) is fine


class _Contact:
    """A contact set whose passes report the held points ``script[k]`` against their rule
    (empty: none), with no status switch."""

    def __init__(self, script: list[str]):
        self.script, self.passes = script, 0

    def __bool__(self) -> bool:
        return True

    def active(self) -> list[np.ndarray]:
        return [np.array([True, False])]

    def freeze(self, u, frozen) -> None:
        pass

    def begin_pass(self, increment: bool) -> None:
        self.passes += 1

    def changes(self) -> str:
        return ""

    def contradicted(self) -> int:
        return int(bool(self.script[self.passes - 1]))

    def contradicted_state(self) -> str:
        return self.script[self.passes - 1]

    def describe_contradicted(self) -> str:
        return self.script[self.passes - 1]


class _System:
    """A linear system whose recovery is the same after every pass (the stress settles at
    once) and whose contact is :class:`_Contact`."""

    linear = True

    def __init__(self, contact: _Contact):
        from cgfem.solve.policy import SolverPolicy

        self.contact, self.policy = contact, SolverPolicy()

    def load_norm(self, t):
        return 1.0

    def force_scale(self, u):
        return 1.0

    def freeze(self, frozen) -> None:
        pass

    def recover(self, u):
        return [np.ones((2, 3, 3))]

    def turned_floating(self, u) -> str:
        return ""

    def continuous_residual(self, u, t):
        return np.zeros(1), 0


def _increment(monkeypatch, script):
    import cgfem.solve.outer as outer
    from cgfem.case.model import SolverOptions

    monkeypatch.setattr(outer, "newton", lambda assemble, u0, solves, **kw: NewtonResult(
        u0, True, [1.0, 1e-12], 1.0, "converged"))

    class Solves:
        frozen, factorizes, again = False, True, None
    contact = _Contact(script)
    out = outer.solve_increment(_System(contact), Solves(), np.zeros(3), [None], 1.0,
                                SolverOptions(outer_passes=len(script)), lambda m: None)
    return out, contact.passes


def test_passes_that_repeat_the_same_held_points_against_their_rule_fail_the_increment(monkeypatch):
    """Two settled passes in a row with the same contradicted points: the increment fails at
    once (a cut-back follows), naming them, instead of repeating passes to the cap."""
    from cgfem.solve.outer import UNSETTLED, IncrementFailure

    out, passes = _increment(monkeypatch, ["p: points 7 (inactive)"] * 10)
    assert isinstance(out, IncrementFailure) and out.reason == UNSETTLED and passes == 3
    assert "p: points 7 (inactive)" in str(out)


def test_held_points_that_change_or_clear_keep_the_outer_loop_going(monkeypatch):
    """Other points each pass: no repetition, the loop goes on; once none contradicts, the
    increment converges."""
    from cgfem.solve.outer import Increment

    script = ["p: points 7 (inactive)", "p: points 8 (active)", "p: points 7 (inactive)", ""]
    out, passes = _increment(monkeypatch, script + [""] * 6)
    assert isinstance(out, Increment) and out.outer_converged and passes == 4


class _Forces(_System):
    """:class:`_System` whose forces in play (the bulk internal force) are ``forces``."""

    def __init__(self, contact: _Contact, forces: float):
        super().__init__(contact)
        self.forces = forces

    def load_norm(self, t):
        return 0.0

    def force_scale(self, u):
        return self.forces


@pytest.mark.parametrize("forces, passes, last", [(1.0, 3, 1.0), (1.0e4, 2, None), (1.0e-3, 3, 0.1),
                                                  (1.0e-6, 2, None)])
def test_a_pass_is_tight_only_within_newton_tol_of_the_forces_at_its_solution(monkeypatch, forces, passes, last):
    """A displacement-driven increment's first residual (the penalty force ``beta M du_bar``,
    here 1e4) is no force in play: a Newton solve that ends at half of ``newton_tol`` of it
    ends the increment only if the forces at the solution are as large; else, the stress
    having settled, the next pass's Newton is measured against those forces (``last``), at
    least :data:`ROUND_OFF` of the first residual (1e-14 / 1e-9 * 1e4 = 0.1), and ends there.
    Forces below :data:`NO_LOAD` of the first residual (1e-6 < 1e-9 * 1e4) are no load: the
    first residual is the scale."""
    import cgfem.solve.outer as outer
    from cgfem.case.model import SolverOptions

    given = []

    def newton(assemble, u0, solves, *, tol, reference, **kw):
        first = 1.0e4 if not given else 1.0e-5       # the increment's first residual, then the passes'
        given.append(reference)
        ref = max(reference, first)
        return NewtonResult(u0, True, [first, 0.5 * tol * ref], ref, "converged")
    monkeypatch.setattr(outer, "newton", newton)

    class Solves:
        frozen, factorizes, again = False, True, None
    out = outer.solve_increment(_Forces(_Contact([""] * 10), forces), Solves(), np.zeros(3), [None], 1.0,
                                SolverOptions(newton_tol=1e-9, outer_passes=10), lambda m: None)
    assert isinstance(out, outer.Increment) and out.outer_converged
    assert len(given) == passes
    assert given[:2] == [forces, 1.0e4]
    if last is not None:
        assert given[2] == pytest.approx(last)
        assert out.newton_residuals[-1][-1] <= 1e-9 * last


class _Settling(_System):
    """:class:`_System` whose recovered stress settles over the passes: relative changes of
    about 1 (from nothing), 1e-2, 1e-5 and 1e-8, without acceleration."""

    def __init__(self, contact: _Contact):
        from dataclasses import replace

        super().__init__(contact)
        self.policy = replace(self.policy, acceleration="none")
        self.scales = iter([1.0, 1.01, 1.01001, 1.0100100001])

    def recover(self, u):
        return [np.full((2, 3, 3), next(self.scales))]


@pytest.mark.parametrize("factorizes, expected", [(False, [0.5, 0.5, 0.5, 0.0]), (True, [0.0] * 4)])
def test_passes_but_the_last_stop_newton_early_only_on_the_krylov_path(monkeypatch, factorizes, expected):
    """On the Krylov path (no factorization to keep) Newton stops at ``krylov_pass_tolerance``
    of a pass's first residual while the stress still changes by more than ``100 outer_tol``
    (passes 1-3 here), and the pass after that is solved to ``newton_tol``; on the direct path
    every pass is (``pass_tolerance`` 0)."""
    import cgfem.solve.outer as outer
    from cgfem.case.model import SolverOptions

    loose = []

    def newton(assemble, u0, solves, **kw):
        loose.append(kw["loose"])
        return NewtonResult(u0, True, [1.0, 1e-12], 1.0, "converged")
    monkeypatch.setattr(outer, "newton", newton)

    solves = SimpleNamespace(frozen=False, factorizes=factorizes, again=None)
    out = outer.solve_increment(_Settling(_Contact([""] * 10)), solves, np.zeros(3), [None], 1.0,
                                SolverOptions(outer_tol=1e-6, outer_passes=10), lambda m: None)
    assert isinstance(out, outer.Increment) and out.outer_converged
    assert loose == expected


@pytest.mark.parametrize("factorizes, expected", [(False, [1.0, 1.0e4, 1.0e4, 1.0]),
                                                  (True, [1.0, 1.0e4, 1.0e4, 1.0e4, 1.0])])
def test_the_last_passes_are_measured_against_the_forces_from_their_start_on_the_krylov_path(
        monkeypatch, factorizes, expected):
    """The increment's first residual (1e4, a penalty force) is no force in play (1.0). On the
    Krylov path the forces become Newton's reference as soon as the stress changed by at most
    ``100 outer_tol`` (after pass 3), so the pass whose stress settles (pass 4) is tight and
    ends the increment; on the direct path they are measured only once the stress settled,
    and a fifth pass is tight."""
    import cgfem.solve.outer as outer
    from cgfem.case.model import SolverOptions

    given = []

    def newton(assemble, u0, solves, *, tol, reference, **kw):
        first = 1.0e4 if not given else 1.0e-5
        given.append(reference)
        ref = max(reference, first)
        return NewtonResult(u0, True, [first, 0.5 * tol * ref], ref, "converged")
    monkeypatch.setattr(outer, "newton", newton)

    system = _Forces(_Contact([""] * 10), 1.0)
    system.policy = replace(system.policy, acceleration="none")
    # relative changes of 1, 1e-2, 1e-5, 1e-8, then none
    scales = iter([1.0, 1.01, 1.01001, 1.0100100001, 1.0100100001])
    system.recover = lambda u: [np.full((2, 3, 3), next(scales))]
    solves = SimpleNamespace(frozen=False, factorizes=factorizes, again=None)
    out = outer.solve_increment(system, solves, np.zeros(3), [None], 1.0,
                                SolverOptions(newton_tol=1e-9, outer_tol=1e-6, outer_passes=10), lambda m: None)
    assert isinstance(out, outer.Increment) and out.outer_converged
    assert given == expected
