"""Newton-Raphson with a backtracking line search, every stage passed in as a function.

``assemble(u, tangent) -> (r, K)`` gives the residual and (if asked) the tangent;
``solve(K, r) -> du`` solves ``K du = -r`` (or raises); ``log(iteration, relative residual)``
reports progress. The line search halves the step while the residual norm does not
decrease enough or the trial state is inadmissible (a NaN residual: an inverted element);
close to the solution it takes the full Newton step, so the quadratic convergence is kept.

"Enough" is Armijo on ``|r|^2 / 2``; when no step fraction down to :data:`MIN_STEP` meets it,
the search is repeated against the largest of the last :data:`NONMONOTONE` accepted
residuals instead of the current one (non-monotone, Grippo-Lampariello-Lucidi): contact makes
the residual only piecewise smooth (a point crossing onto another master element or triangle
kinks it), and a full step across a few kinks may raise the residual a little on its way to a
solution the monotone search would give up on. Non-monotone from the start loses chain3 at
level 1 (its middle link, held by contact alone, wanders off); monotone alone loses
chain2_rubber at level 1 with facets.

``energy_line_search``: where the residual is the gradient of an energy (small strain: the
elastic energy plus the contact penalty's, the fit's multipliers aside) and the step ``du``
descends it (``s(0) = du . r(u) < 0``), the step goes to the energy's least value along it,
the zero of ``s(a) = du . r(u + a du)`` on ``(0, 1]`` (:func:`energy_minimum`), instead of
the residual's Armijo search. A body held by contact alone has a rigid motion that only a
few contact points resist, each through the kink of its penalty law: Newton's step from one
side of a kink overshoots to the other, the residual's search accepts it since the residual
fell, and the next step comes back (chain3's middle link rocking about the chain's axis as
one point engages and lets go). Where the energy is convex along the step, ``s`` is
continuous and increasing, kinks included, and its zero is where the rocking step should
stop. Where ``s(0) >= 0`` the residual's search is used: for an exact solve ``s(0) = -du . K du``, so the
(shifted) tangent curves the wrong way along the step (the contact's curvature terms on the
floating body's rigid turn; on chain3 at level 0, offset set 4, about 40 % of the steps with
``nurbs_fit``). The policy's ``floating_search`` chooses it: not the default, every
fallback's (:attr:`~cgfem.solve.policy.SolverPolicy.fallbacks`; measured in
``docs/validation.md``).

``stagnation=(window, factor)``: Newton stops (reason ``stagnated``) once the smallest
residual of its last ``window`` iterates is above ``factor`` times the smallest one before
them: a solve that has not halved its residual in ten iterations (contact points switching,
a floating body's steps cut short by its limit) has not converged within the iteration cap
in any run of the examples, and its increment is cut back as after the cap, only sooner.

Inexact Newton (``forcing``): an iterative linear solve need only reach the relative residual
``eta = forcing * tol * reference / |r|``: its error then adds at most ``forcing`` times the
tolerance to the next residual, so the convergence test is met as with an exact solve, and
the last iterations (and modified Newton's, far from ``|r| = reference``) stop the Krylov
solver many digits early. ``solve`` is then called as ``solve(K, -r, eta)``. With
``forcing_max`` the solve may also stop at ``min(forcing_max, |r| / reference)``, whichever is
looser (the forcing ``eta_k ~ |r_k|`` of Dembo-Eisenstat-Steihaug, which keeps Newton's
quadratic convergence): the first iterations, far from the solution, need few digits.

``loose``: the solve may stop once ``|r| <= loose * |r(u0)|`` (an outer pass that is not the
last needs no more: the frozen stress it is solved with changes next pass). Whether a pass
is accurate enough to end its increment is the outer loop's call
(:func:`cgfem.solve.outer.solve_increment`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

#: Armijo constant and the smallest step fraction tried by the line search
ARMIJO = 1e-4
MIN_STEP = 1.0 / 64.0
#: accepted residuals the non-monotone line search compares against
NONMONOTONE = 5
#: the energy line search stops where the slope along the step is below this fraction of its
#: first, or after this many residuals ...
SLOPE_RTOL = 0.1
SLOPE_EVALUATIONS = 12
#: ... or when its bracket is narrower than this fraction of the step
SLOPE_WIDTH = 1e-3


@dataclass
class NewtonResult:
    """Outcome of one Newton solve.

    residuals : residual norms, the first at the initial guess
    reference : the force scale convergence was measured against
    reason : why it stopped ("converged", "max_iterations", "line_search", "stagnated", "nan",
        "linear_solver")
    """

    u: np.ndarray
    converged: bool
    residuals: list[float] = field(default_factory=list)
    reference: float = 0.0
    reason: str = ""


def newton(assemble: Callable[[np.ndarray, bool], tuple[np.ndarray, object]], u0: np.ndarray,
           solve: Callable[[object, np.ndarray], np.ndarray], *, tol: float, reference: float,
           max_iter: int, log: Callable[[int, float, str], None] | None = None,
           fixed_tangent: bool = False, limit: Callable[[np.ndarray], np.ndarray] | None = None,
           forcing: float | None = None, forcing_max: float = 0.0, loose: float = 0.0,
           stagnation: tuple[int, float] = (0, 0.0),
           energy_line_search: Callable[[], bool] | None = None) -> NewtonResult:
    """Solve ``r(u) = 0`` from ``u0`` until ``|r| <= tol * max(reference, |r(u0)|)``. With
    ``fixed_tangent`` no tangent is assembled (``solve`` gets None and must use a
    factorization it kept: modified Newton). ``limit(du)``: the Newton step shortened
    before the line search (a trust region on some unknowns), ``du`` itself if it is not.
    ``log(iteration, |r| / reference, note)``: ``note`` says how the step was shortened
    (line-search fraction, the limit's ratio of step norms), empty for a full step. ``forcing``:
    inexact Newton (module docstring), None for exact solves; ``forcing_max``, ``loose`` and
    ``stagnation``: module docstring (0 turns them off). ``energy_line_search()``: whether
    this step searches for the energy's minimum along it (module docstring); None: never."""
    u = u0.copy()
    need = not fixed_tangent
    r, K = assemble(u, need)
    norm = float(np.linalg.norm(r))
    reference = max(reference, norm)
    result = NewtonResult(u, False, [norm], reference)
    target = max(tol * reference, loose * norm)
    if log:
        log(0, norm / reference if reference > 0.0 else norm, "")
    if not np.isfinite(norm):
        result.reason = "nan"
        return result
    for it in range(1, max_iter + 1):
        if norm <= target:
            result.converged, result.reason = True, "converged"
            break
        try:
            du = solve(K, -r) if forcing is None else \
                solve(K, -r, forcing_rtol(forcing, tol, reference, norm, forcing_max))
        except RuntimeError as err:   # LinearSolverError: singular, no convergence, NaN
            result.reason = f"linear_solver: {err}"
            return result
        if need:
            K = None        # the next tangent replaces it: not two matrices held while it is assembled
        limited = du
        if limit is not None:
            limited = limit(du)
        shortened = float(np.linalg.norm(limited)) / float(np.linalg.norm(du)) if limited is not du else 1.0
        du = limited
        # monotone first; if no step decreases the residual, the largest step below the
        # largest of the last NONMONOTONE residuals (from the same trials, not assembled again)
        bound = max(result.residuals[-NONMONOTONE:])
        trial = fallback = None
        if energy_line_search is not None and energy_line_search():
            trial = energy_minimum(assemble, u, du, r, need)
        step = 1.0
        while trial is None and step >= MIN_STEP:
            candidate = u + step * du
            # the full step usually succeeds: assemble its tangent at once
            r_new, K_new = assemble(candidate, need and step == 1.0)
            n_new = float(np.linalg.norm(r_new))
            armijo = 1.0 - 2.0 * ARMIJO * step
            if np.isfinite(n_new) and n_new ** 2 <= armijo * norm ** 2:
                trial = (candidate, r_new, n_new, K_new, step)
                break
            if fallback is None and np.isfinite(n_new) and n_new ** 2 <= armijo * bound ** 2:
                fallback = (candidate, r_new, n_new, K_new, -step)
            step *= 0.5
        trial = trial or fallback
        if trial is None:
            result.reason = "line_search"
            return result
        u, r, norm, K_new, taken = trial
        if need:
            K = K_new if K_new is not None else assemble(u, True)[1]
        result.u = u
        result.residuals.append(norm)
        if log:
            log(it, norm / reference, _step_note(taken, shortened))
        if norm > target and stagnated(result.residuals, *stagnation):
            result.reason = "stagnated"
            break
    else:
        if norm <= target:
            result.converged, result.reason = True, "converged"
        else:
            result.reason = "max_iterations"
    result.u = u
    return result


def energy_minimum(assemble: Callable[[np.ndarray, bool], tuple[np.ndarray, object]], u: np.ndarray,
                   du: np.ndarray, r: np.ndarray, tangent: bool) -> tuple | None:
    """The point of least energy along Newton's step ``du`` from ``u`` (residual ``r``, the
    energy's gradient): the full step where the slope ``s(1) = du . r(u + du)`` is at most
    ``SLOPE_RTOL |s(0)|``, otherwise the zero of ``s`` on ``(0, 1)`` (:func:`slope_zero`).
    Returns ``(u + a du, r, |r|, K, a)`` (``K`` the tangent at the full step if ``tangent``,
    else None) or None where ``du`` does not descend (``s(0) >= 0``) or a residual is not
    finite."""
    s0 = float(np.dot(du, r))
    if not s0 < 0.0:
        return None
    r1, K1 = assemble(u + du, tangent)
    n1 = float(np.linalg.norm(r1))
    if not np.isfinite(n1):
        return None
    s1 = float(np.dot(du, r1))
    if s1 <= SLOPE_RTOL * abs(s0):
        return u + du, r1, n1, K1, 1.0
    trials: dict[float, tuple] = {1.0: (u + du, r1, n1, K1, 1.0)}

    def slope(a: float) -> float:
        ra, _ = assemble(u + a * du, False)
        trials[a] = (u + a * du, ra, float(np.linalg.norm(ra)), None, a)
        return float(np.dot(du, ra)) if np.isfinite(trials[a][2]) else math.nan

    a = slope_zero(slope, s0, s1)
    return trials.get(a) if a is not None else None


def slope_zero(slope: Callable[[float], float], s0: float, s1: float, rtol: float = SLOPE_RTOL,
               evaluations: int = SLOPE_EVALUATIONS, width: float = SLOPE_WIDTH) -> float | None:
    """Where the increasing function ``slope`` (``slope(0) = s0 < 0 < s1 = slope(1)``) is
    zero, within ``rtol |s0|``: regula falsi with the Anderson-Bjoerck scaling of the end it
    keeps, and a bisection after a guess that did not halve the bracket (a slope that is
    flat and then steep, the soft rigid motion meeting a contact spring, would otherwise
    creep along the flat side). Stops after ``evaluations`` calls or when the bracket is
    narrower than ``width`` times its right end; then the last point where the slope was
    still negative (the energy, convex, is below its start there and not past its minimum),
    or the bracket's right end if there was none. None if ``slope`` returns NaN."""
    a, sa, b, sb = 0.0, s0, 1.0, s1
    bisect = False
    for _ in range(evaluations):
        c = 0.5 * (a + b) if bisect else b - sb * (b - a) / (sb - sa)
        sc = slope(c)
        if math.isnan(sc):
            return None
        if abs(sc) <= rtol * abs(s0):
            return c
        before = b - a
        if sc < 0.0:
            m = 1.0 - sc / sa
            sb *= m if m > 0.0 else 0.5
            a, sa = c, sc
        else:
            m = 1.0 - sc / sb
            sa *= m if m > 0.0 else 0.5
            b, sb = c, sc
        bisect = b - a > 0.5 * before
        if b - a <= width * b:
            break
    return a if a > 0.0 else b


def stagnated(residuals: list[float], window: int, factor: float) -> bool:
    """Whether the smallest of the last ``window`` residuals is above ``factor`` times the
    smallest one before them (False for ``window`` 0 or fewer than ``window + 1`` residuals)."""
    if window <= 0 or len(residuals) <= window:
        return False
    return min(residuals[-window:]) > factor * min(residuals[:-window])


def _step_note(step: float, shortened: float) -> str:
    """How a Newton step was taken: the line-search fraction (negative: accepted by the
    non-monotone test) and the limit's shortening, empty for a full step."""
    notes = []
    if step != 1.0:
        notes.append(f"step {abs(step):.3g}" + (" non-monotone" if step < 0 else ""))
    if shortened < 1.0:
        notes.append(f"limited to {shortened:.3g}")
    return ", ".join(notes)


def forcing_rtol(forcing: float, tol: float, reference: float, norm: float, forcing_max: float = 0.0) -> float:
    """The relative residual an inexact Newton step's linear solve must reach at residual
    ``norm``: ``forcing * tol * reference / norm`` (at most ``forcing``), or
    ``min(forcing_max, norm / reference)`` if that is looser."""
    if not norm > 0.0:
        return forcing
    eta = min(forcing, forcing * tol * reference / norm)
    if forcing_max > 0.0 and reference > 0.0:
        eta = max(eta, min(forcing_max, norm / reference))
    return float(eta)


def observed_order(residuals: list[float], floor: float = 1e-13) -> float:
    """Convergence order ``q`` of ``r_{k+1} ~ C r_k^q`` from the last three residuals above
    round-off (``floor`` times the first one): ``log(r3/r2) / log(r2/r1)``."""
    r = np.asarray(residuals, float)
    r = r[r > floor * r[0]] if r.size else r
    if r.size < 3:
        return float("nan")
    r1, r2, r3 = r[-3:]
    return float(np.log(r3 / r2) / np.log(r2 / r1))


def window_orders(residuals: list[float], floor: float = 1e-11, count: int = 2) -> list[float]:
    """The three-point orders ``log(r3/r2) / log(r2/r1)`` of the last ``count`` windows whose
    first two residuals are above ``floor`` times the first residual. Unlike
    :func:`observed_order` the third may be round-off: a residual at round-off is no smaller
    than the true one, so its window can only read low. The better of the last two tells a
    quadratic end whose constant ``r+/r^2`` changes between iterations (it depends on the
    direction of the remaining error) from a linear one, which reads about 1 in both."""
    r = [float(x) for x in residuals]
    above = [k for k in range(1, len(r) - 1) if min(r[k - 1], r[k]) > floor * r[0]]
    return [float(np.log(r[k + 1] / r[k]) / np.log(r[k] / r[k - 1])) for k in above[-count:]]
