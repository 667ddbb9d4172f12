"""Newton with its line search on scalar and small vector problems with known roots."""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.solve.newton import (NONMONOTONE, SLOPE_RTOL, energy_minimum, newton, observed_order, slope_zero,
                                window_orders)


def _scalar(r, dr):
    def assemble(u, tangent):
        return np.array([r(u[0])]), (np.array([[dr(u[0])]]) if tangent else None)
    return assemble


def _solve(K, b):
    return np.linalg.solve(K, b)


def test_full_steps_converge_quadratically():
    """x^3 + x - 3 = 0 from 1: the full steps are taken, the order is 2."""
    res = newton(_scalar(lambda x: x ** 3 + x - 3.0, lambda x: 3 * x ** 2 + 1.0), np.array([1.0]), _solve,
                 tol=1e-14, reference=1.0, max_iter=20)
    assert res.converged and abs(res.u[0] ** 3 + res.u[0] - 3.0) <= 1e-14
    assert observed_order(res.residuals, floor=1e-15) > 1.8


def test_window_orders_tell_a_quadratic_end_from_a_linear_one():
    """chain2_steel level 0, nurbs_fe, step 1 (relative residuals; the last is round-off):
    the last two windows read 1.16 and 2.81, quadratic with a constant that changed; a
    tangent off by 1e-3 (r+ = 1e-3 r from some point on) reads 1 in both."""
    quadratic = [1.0, 2.8e-3, 2.1e-5, 7.1e-8, 8.1e-15]
    assert window_orders(quadratic) == pytest.approx([1.163, 2.81], abs=5e-3)
    # the one window above round-off reads low
    assert observed_order(quadratic, floor=1e-11) == pytest.approx(1.163, abs=5e-3)
    linear = [1.0, 1e-2] + [1e-2 * 1e-3 ** k for k in range(1, 4)]
    assert window_orders(linear, floor=1e-13) == pytest.approx([1.0, 1.0], abs=1e-9)
    assert window_orders([1.0, 1e-13, 1e-16]) == []     # the second residual at round-off


def test_line_search_tames_arctan():
    """arctan(x) from x = 3: plain Newton diverges (|x| grows from any |x0| > 1.39); the
    line search halves the steps that raise the residual above the last NONMONOTONE ones and
    reaches the root."""
    x = np.array([3.0])
    for _ in range(3):                               # plain Newton: diverges
        x = x - np.arctan(x) * (1.0 + x ** 2)
    assert abs(x[0]) > 1e3
    res = newton(_scalar(np.arctan, lambda x: 1.0 / (1.0 + x ** 2)), np.array([3.0]), _solve,
                 tol=1e-12, reference=1.0, max_iter=40)
    assert res.converged and abs(res.u[0]) < 1e-12
    # every accepted residual is below the largest of the NONMONOTONE before it
    r = res.residuals
    assert all(r[k] < max(r[max(0, k - NONMONOTONE):k]) for k in range(1, len(r)))


def test_inadmissible_trials_are_halved():
    """x^2 - 3.61 (root 1.9) with a NaN residual beyond x = 2 (an inverted element): the first
    full step from 0.5 lands at 3.86 and its half at 2.18, both NaN; the quarter step is
    taken and Newton converges."""
    calls = []

    def r(x):
        calls.append(x)
        return np.nan if x > 2.0 else x * x - 3.61
    res = newton(_scalar(r, lambda x: 2.0 * x), np.array([0.5]), _solve, tol=1e-13, reference=1.0, max_iter=20)
    assert np.allclose(calls[1:4], [3.86, 2.18, 1.34])
    assert np.isfinite(res.residuals).all()
    assert res.converged and abs(res.u[0] - 1.9) < 1e-12


def test_nonmonotone_fallback_reuses_the_monotone_trials():
    """r = x with a tangent of the wrong sign on [-6, 0] (an ascent direction there): from
    10 a short tangent lands at -5 (|r| 5); from -5 every step fraction raises |r|, so the
    monotone search fails, and the largest fraction below the largest recent residual (10) is
    taken, the half step to -7.5; the tangent is right again there and the root follows. The
    fallback takes that step from the monotone pass's own trials: the start, the first full
    step, 7 trials, the tangent at the accepted half step and the last full step (evaluating
    the fallback's steps again would add 2)."""
    calls = []

    def assemble(u, tangent):
        x = u[0]
        calls.append(x)
        slope = 2.0 / 3.0 if x > 0.0 else (-1.0 if x >= -6.0 else 1.0)
        return np.array([x]), (np.array([[slope]]) if tangent else None)
    res = newton(assemble, np.array([10.0]), _solve, tol=1e-14, reference=1.0, max_iter=10)
    assert res.converged and res.u[0] == 0.0
    np.testing.assert_allclose(res.residuals, [10.0, 5.0, 7.5, 0.0])
    assert len(calls) == 11


def test_inexact_newton_asks_for_the_forcing_tolerance_and_still_converges():
    """forcing: each linear solve is asked for eta = forcing tol ref / |r| (at most forcing);
    a solver that returns exactly that relative error still converges to tol, with the
    residual after the last step below tol."""
    from cgfem.solve.newton import forcing_rtol

    A = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]])
    target = np.array([0.3, -0.2, 0.5])

    def assemble(u, tangent):
        r = A @ u + 0.1 * u ** 3 - (A @ target + 0.1 * target ** 3)
        return r, (A + np.diag(0.3 * u ** 2)) if tangent else None
    asked, norms = [], []

    def inexact(K, b, rtol):
        asked.append(rtol)
        norms.append(np.linalg.norm(b))
        x = np.linalg.solve(K, b)
        e = np.linalg.solve(K, np.array([1.0, -1.0, 1.0]))   # perturb: residual exactly rtol |b|
        return x + e * rtol * np.linalg.norm(b) / np.linalg.norm(K @ e)
    tol, reference = 1e-10, 10.0
    res = newton(assemble, np.zeros(3), inexact, tol=tol, reference=reference, max_iter=30, forcing=0.1)
    assert res.converged and res.residuals[-1] <= tol * res.reference
    assert np.allclose(asked, [forcing_rtol(0.1, tol, res.reference, n) for n in norms])
    assert asked[0] == pytest.approx(0.1 * tol * res.reference / norms[0]) and max(asked) <= 0.1
    assert asked[-1] > 1e3 * asked[0]   # the last solves stop many digits earlier
    assert np.abs(res.u - target).max() < 1e-9


def test_log_notes_say_how_each_step_was_taken():
    """The log's note names the line-search fraction and the limit's shortening, and is
    empty for a full step: x^2 - 3.61 from 0.5 with NaN beyond x = 2 takes a quarter step
    to 1.34, whose full step lands at 2.02 (NaN) so half of it is taken, then full steps; a limit halving every step is reported as 'limited to 0.5'."""
    def r(x):
        return np.nan if x > 2.0 else x * x - 3.61
    notes: list[str] = []
    res = newton(_scalar(r, lambda x: 2.0 * x), np.array([0.5]), _solve, tol=1e-13, reference=1.0, max_iter=20,
                 log=lambda k, rel, note: notes.append(note))
    assert res.converged
    assert notes[:3] == ["", "step 0.25", "step 0.5"] and all(n == "" for n in notes[3:])
    notes.clear()
    res = newton(_scalar(lambda x: x - 1.0, lambda x: 1.0), np.array([0.0]), _solve, tol=1e-3, reference=1.0,
                 max_iter=20, limit=lambda du: 0.5 * du, log=lambda k, rel, note: notes.append(note))
    # x halves its distance to the root each step: 10 steps to 1e-3
    assert res.converged and len(res.residuals) - 1 == 10
    assert all(n == "limited to 0.5" for n in notes[1:])


def _contracting(rate):
    """r(u) = u with a solver whose step removes only ``1 - rate`` of it: |r| falls by
    ``rate`` per iteration, every full step passes Armijo."""
    def assemble(u, tangent):
        return u.copy(), (np.eye(1) if tangent else None)

    def solve(K, b):
        return (1.0 - rate) * np.linalg.solve(K, b)
    return assemble, solve


@pytest.mark.parametrize("rate, stops_at", [(0.95, 10), (0.9, None)])
def test_newton_stops_where_ten_iterations_have_not_halved_the_residual(rate, stops_at):
    """|r| falling by 0.95 per iteration: after ten (0.95^10 = 0.60 > 0.5) Newton stops as
    ``stagnated``; by 0.9 (0.9^10 = 0.35) it goes on to the cap. Without the window (0) it
    never stops early."""
    assemble, solve = _contracting(rate)
    res = newton(assemble, np.array([1.0]), solve, tol=1e-12, reference=1.0, max_iter=30,
                 stagnation=(10, 0.5))
    assert not res.converged
    if stops_at is None:
        assert res.reason == "max_iterations" and len(res.residuals) == 31
    else:
        assert res.reason == "stagnated" and len(res.residuals) == stops_at + 1
        assert res.u[0] == pytest.approx(rate ** stops_at, rel=1e-12)
    off = newton(assemble, np.array([1.0]), solve, tol=1e-12, reference=1.0, max_iter=30)
    assert off.reason == "max_iterations" and len(off.residuals) == 31


def test_a_solve_that_converges_after_a_slow_stretch_is_not_stopped():
    """Nine slow iterations (0.95 each) then full Newton steps: the window never sees ten
    iterations without halving, and Newton converges."""
    count = [0]

    def assemble(u, tangent):
        return u.copy(), (np.eye(1) if tangent else None)

    def solve(K, b):
        count[0] += 1
        return (0.05 if count[0] <= 9 else 1.0 - 1e-3) * np.linalg.solve(K, b)
    res = newton(assemble, np.array([1.0]), solve, tol=1e-9, reference=1.0, max_iter=30,
                 stagnation=(10, 0.5))
    assert res.converged and res.reason == "converged"


def _kinked(soft: float, stiff: float, force: float):
    """A body held by contact alone, in one unknown: a rigid motion of stiffness ``soft``
    pushed by ``force`` onto a penalty spring ``stiff`` that engages at x = 1 (the residual is
    the gradient of the convex energy ``soft x^2 / 2 + stiff <x - 1>^2 / 2 - force x``).
    Returns the assemble function and the root."""
    def assemble(u, tangent):
        x = u[0]
        r = np.array([soft * x + stiff * max(x - 1.0, 0.0) - force])
        return r, (np.array([[soft + (stiff if x > 1.0 else 0.0)]]) if tangent else None)
    return assemble, (force + stiff) / (soft + stiff)


def test_energy_line_search_stops_a_soft_motion_at_its_contact():
    """From x = 0, where the spring is off, Newton's step on the soft stiffness goes to
    x = force / soft = 5e5, far past the spring's kink: every fraction of it down to 1/64
    raises the residual, and the residual's line search gives up. The energy's slope along
    the step is continuous and increasing through the kink; the step stops at its zero, on
    the spring, and Newton converges there."""
    assemble, root = _kinked(soft=1e-6, stiff=1.0, force=0.5)
    residual = newton(assemble, np.array([0.0]), _solve, tol=1e-12, reference=1.0, max_iter=20)
    assert not residual.converged and residual.reason == "line_search"
    energy = newton(assemble, np.array([0.0]), _solve, tol=1e-12, reference=1.0, max_iter=20,
                    energy_line_search=lambda: True)
    assert energy.converged and energy.u[0] == pytest.approx(root, rel=1e-12)
    assert len(energy.residuals) <= 4


def test_energy_minimum_is_the_zero_of_the_slope_along_the_step():
    """Along a step across two kinks of a convex energy in two unknowns the point returned has
    a slope within SLOPE_RTOL of the first, and lies within that of the exact minimum along
    the line (the slope is piecewise linear there: the minimum is found by bisection on a
    fine sampling); a step that does not descend gets None, and one whose end still
    descends is taken whole."""
    A = np.array([[2.0, 0.5], [0.5, 1e-3]])
    f = np.array([1.0, 0.2])

    def assemble(u, tangent):
        r = A @ u + 50.0 * np.maximum(u - 0.3, 0.0) - f
        return r, (A if tangent else None)
    u = np.zeros(2)
    r, K = assemble(u, True)
    du = np.linalg.solve(K, -r)
    slope = lambda a: float(du @ assemble(u + a * du, False)[0])    # noqa: E731
    assert slope(1.0) > 0.0                   # the step overshoots the kinks
    x, r_x, n_x, K_x, a = energy_minimum(assemble, u, du, r, True)
    assert 0.0 < a < 1.0 and K_x is None
    assert abs(float(du @ r_x)) <= SLOPE_RTOL * abs(float(du @ r))
    assert np.allclose(x, u + a * du) and n_x == pytest.approx(np.linalg.norm(r_x))
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if slope(mid) < 0.0 else (lo, mid)
    # the slope rises by at least |slope(0)| over [0, a*] (it is increasing and linear in
    # pieces): within SLOPE_RTOL |slope(0)| of zero is within SLOPE_RTOL of a* in the fraction
    assert abs(a - lo) <= SLOPE_RTOL * lo
    assert energy_minimum(assemble, u, -du, r, True) is None
    short = energy_minimum(assemble, u, 1e-3 * du, r, True)
    assert short is not None and short[4] == 1.0 and short[3] is not None


def test_slope_zero_does_not_creep_or_overshoot_on_a_flat_then_steep_slope():
    """A soft motion (slope 1e-6 per unit step) meeting a spring 1e15 times stiffer at 0.6 of
    the step: regula falsi from the steep end creeps (each guess a hair past the flat side's
    last); with the bisections the bracket closes on the kink, and what is returned, the
    tolerance being out of reach, is the last point before it, where the energy still falls."""
    calls = []

    def slope(a):
        calls.append(a)
        return -1.0 + 1e-6 * a + 1e9 * max(a - 0.6, 0.0)
    a = slope_zero(slope, slope(0.0), slope(1.0))
    assert slope(a) < 0.0 and 0.6 * 0.99 <= a <= 0.6          # within 1 % of the kink
    assert len(calls) <= 2 + 12 + 1
    # a slope with its zero in reach is met within the tolerance, in a few evaluations
    calls.clear()
    a = slope_zero(lambda x: slope(x) if x < 0.6 else -1.0 + 5.0 * (x - 0.6), -1.0, 1.0)
    assert abs(-1.0 + 5.0 * (a - 0.6)) <= SLOPE_RTOL and len(calls) <= 8
