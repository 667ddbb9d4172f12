"""The outer loop of one load increment: freeze, solve by Newton, recover, accelerate.

Inside an increment each pass freezes the recovered stress ``P*`` of every body (and, with
contact, ``p_N`` from it), solves the nonlinear problem by Newton with ``P*`` held, recovers
``P*`` from the new displacement and measures its relative change (Frobenius norm over all
nodes of all bodies). The loop stops when the change is at most ``outer_tol`` and contact has
settled (no status switch since the previous pass, no held point against its rule, at least
two passes); ``outer_passes`` is only a cap. The next pass freezes the recovery accelerated
by the policy's scheme (:class:`Relaxation`, :class:`Anderson`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from cgfem.case.model import SolverOptions
from cgfem.contact.assembly import active_changes
from cgfem.solve.newton import NewtonResult, newton

Log = Callable[[str], None]
#: the failure reason of an increment whose passes repeat a state with held points against
#: their rule (:class:`IncrementFailure`)
UNSETTLED = "contact_unsettled"
#: a pass is accepted when Newton's residual is within ``newton_tol`` of the forces in play at
#: its solution, or within this fraction of the increment's first residual (the penalty force
#: ``beta M du_bar`` of a displacement-driven step), whichever is larger: the round-off of the
#: penalty forces summed into the residual, about 50 eps of them
ROUND_OFF = 1e-14
#: a state whose forces in play are below this fraction of the increment's first residual
#: carries no load (its bodies moved rigidly, or one hangs free); the first residual is then
#: the only force scale, and the pass is accepted within ``newton_tol`` of it. Its tangent may
#: be numerically singular (chain3 with ``facets`` at level 0, link C on one contact point or
#: none), so that no solve could go further
NO_LOAD = 1e-9
#: the passes after one whose recovered stress changed by at most this many ``outer_tol`` are
#: the last ones: Newton solves them to ``newton_tol`` (no loose passes), and on the Krylov
#: path against the forces in play at their start rather than the increment's first residual,
#: so that the first of them whose stress settles ends the increment. On the direct path the
#: forces are measured from a pass that settled (a pass more, but of cheap modified-Newton
#: solves; measured: the same time, 2 more Newton iterations on chain2_steel at level 1)
LAST_PASSES = 100.0


@dataclass(frozen=True)
class Increment:
    """The outer loop's result at one load factor (see
    :class:`~cgfem.solve.static.StepRecord` for the fields)."""

    u: np.ndarray                         # (n_dofs,) converged unknowns
    frozen_stress: list[np.ndarray | None]
    recovered: list[np.ndarray]
    newton_residuals: list[list[float]]
    outer_changes: list[float]
    outer_converged: bool
    #: Newton's force scale, and the residual over it with every master hit on the continuous
    #: surface, with the number of active hits that lie on a kept piece's extension
    reference: float = 0.0
    continuous_residual: float = 0.0
    extended_hits: int = 0


@dataclass(frozen=True)
class IncrementFailure:
    """Why an increment failed: Newton's ``reason`` (``max_iterations``, ``line_search``,
    ``stagnated``, ``nan`` or ``linear_solver: ...``) in outer pass ``outer_pass``, its last residual over
    its reference ``residual``, after ``iterations`` Newton iterations; ``contact``: what the
    contact set did at the last linearization point (empty without contact). ``rejected``:
    the outer loop ended but its state is no solution of the model (reason ``rejected``,
    :meth:`~cgfem.solve.system.System.turned_floating`), and why. Reason :data:`UNSETTLED`:
    two passes in a row converged (stress within ``outer_tol``, no switch) with the same
    held points against their rule, which further passes would only repeat; ``contact``
    names those points."""

    reason: str
    outer_pass: int
    residual: float
    iterations: int
    contact: str = ""
    rejected: str = ""

    def __str__(self) -> str:
        if self.rejected:
            return f"the state reached in outer pass {self.outer_pass} was rejected: {self.rejected}"
        if self.reason == UNSETTLED:
            return (f"contact did not settle: outer passes {self.outer_pass - 1} and {self.outer_pass} "
                    f"converged to the same state with held points against their rule ({self.contact})")
        why = f"; {self.contact}" if self.contact else ""
        return (f"Newton stopped on {self.reason} in outer pass {self.outer_pass} at |r|/ref = "
                f"{self.residual:.2e} after {self.iterations} iterations{why}")


def relative_change(new: list[np.ndarray], old: list[np.ndarray | None]) -> float:
    """``|new - old| / |new|`` over all arrays (Frobenius; ``old`` None counts as zero)."""
    num = sum(float(np.sum((n - (0.0 if o is None else o)) ** 2)) for n, o in zip(new, old))
    den = sum(float(np.sum(n ** 2)) for n in new)
    return float(np.sqrt(num / den)) if den > 0.0 else float(np.sqrt(num))


class Relaxation:
    """Aitken's dynamic relaxation (Irons-Tuck) of the fixed point ``P* -> recover(u(P*))``.

    With the residual ``r_k = recover(u(P*_k)) - P*_k`` of pass ``k`` the next frozen
    stress is ``P*_{k+1} = P*_k + omega_k r_k``, ``omega_k = -omega_{k-1} r_{k-1}.(r_k - r_{k-1})
    / |r_k - r_{k-1}|^2`` (kept in ``[OMEGA_MIN, OMEGA_MAX]``), ``omega_0 = 1``: for a linear
    contraction it removes the dominant eigencomponent of the error each pass. Disabled
    (``enabled=False``) it is plain substitution, ``P*_{k+1} = recover(u(P*_k))``."""

    OMEGA_MIN, OMEGA_MAX = 0.1, 4.0

    def __init__(self, enabled: bool = True):
        self.enabled = enabled
        self.omega = 1.0
        self._previous: np.ndarray | None = None

    def next(self, frozen: list[np.ndarray | None], recovered: list[np.ndarray]) -> list[np.ndarray]:
        """The frozen stress of the next pass."""
        if not self.enabled or any(f is None for f in frozen):
            return recovered
        residual = np.concatenate([(r - f).ravel() for r, f in zip(recovered, frozen)])
        if self._previous is not None:
            d = residual - self._previous
            dd = float(np.dot(d, d))
            if dd > 0.0:
                omega = -self.omega * float(np.dot(self._previous, d)) / dd
                self.omega = float(np.clip(omega, self.OMEGA_MIN, self.OMEGA_MAX))
        self._previous = residual
        return [f + self.omega * (r - f) for r, f in zip(recovered, frozen)]


class Anderson:
    """Anderson acceleration (type II, mixing 1) of the fixed point ``P* -> recover(u(P*))``
    over the last ``depth`` passes: with ``x_k`` the frozen stress of pass ``k``,
    ``g_k = recover(u(x_k))`` and ``f_k = g_k - x_k``, the next frozen stress is
    ``x_{k+1} = g_k - dG gamma`` with ``gamma`` the least-squares solution of
    ``dF gamma = f_k`` (``dF``, ``dG``: the differences of the last ``depth + 1`` ``f`` and
    ``g``). For an affine map of dimension ``d <= depth`` it is exact after ``d + 1`` passes;
    with ``depth = 1`` it is the secant method (Aitken's factor on the whole residual)."""

    def __init__(self, depth: int = 3):
        self.depth = max(1, int(depth))
        self._f: list[np.ndarray] = []
        self._g: list[np.ndarray] = []

    def next(self, frozen: list[np.ndarray | None], recovered: list[np.ndarray]) -> list[np.ndarray]:
        """The frozen stress of the next pass (the recovery itself while nothing was frozen)."""
        if any(f is None for f in frozen):
            return recovered
        g = np.concatenate([r.ravel() for r in recovered])
        f = g - np.concatenate([x.ravel() for x in frozen])
        if not np.all(np.isfinite(f)):      # a broken pass: no mixing; Newton meets the NaN
            self._f.clear()
            self._g.clear()
            return recovered
        self._f.append(f)
        self._g.append(g)
        del self._f[:-self.depth - 1], self._g[:-self.depth - 1]
        if len(self._f) < 2:
            return recovered
        dF = np.column_stack([b - a for a, b in zip(self._f[:-1], self._f[1:])])
        dG = np.column_stack([b - a for a, b in zip(self._g[:-1], self._g[1:])])
        gamma = np.linalg.lstsq(dF, f, rcond=1e-12)[0]
        x = g - dG @ gamma
        out, start = [], 0
        for r in recovered:
            out.append(x[start:start + r.size].reshape(r.shape))
            start += r.size
        return out


def forces_in_play(system, u: np.ndarray, t: float, first: float, newton_tol: float) -> float:
    """The force scale a pass's residual is accepted against (N): the larger of the dead loads
    at ``t`` and the bulk internal force at ``u``, at least :data:`ROUND_OFF` / ``newton_tol``
    times the increment's first residual ``first``; ``first`` itself when the forces are below
    :data:`NO_LOAD` of it (a state that carries no load)."""
    forces = max(system.load_norm(t), system.force_scale(u))
    if forces < NO_LOAD * first:
        return first
    return max(forces, ROUND_OFF / newton_tol * first)


def newton_pass(attempt: Callable[[np.ndarray, bool], NewtonResult], u: np.ndarray,
                modified_first: bool) -> tuple[NewtonResult, list[float]]:
    """One outer pass's Newton solve from ``u``: ``attempt(start, fixed_tangent)`` runs
    Newton. Later passes start close to the solution (``modified_first``): modified Newton
    on the last factorization first, then, if it does not converge within its few
    iterations, full Newton, from where modified Newton got to when it went down (chain2_steel
    at level 2: 1.2e-9 after 6 modified iterations, then 1 full iteration instead of 3 from
    the pass's start), and from ``u`` if that fails too (modified Newton may stop on a kink
    of the contact surface, line searches cutting its steps). Returns the last result and
    the residual history of the iterates that lead to it (the modified ones first)."""
    if not modified_first:
        result = attempt(u, False)
        return result, list(result.residuals)
    modified = attempt(u, True)
    if modified.converged:
        return modified, list(modified.residuals)
    if modified.reason == "max_iterations" and modified.residuals[-1] < modified.residuals[0]:
        result = attempt(modified.u, False)
        if result.converged:
            return result, modified.residuals[:-1] + result.residuals
    result = attempt(u, False)
    return result, list(result.residuals)


def accelerator(policy) -> Relaxation | Anderson:
    """The outer loop's fixed-point acceleration the policy names."""
    if policy.acceleration == "anderson":
        return Anderson(policy.anderson_depth)
    return Relaxation(policy.acceleration == "aitken")


def pass_tolerance(policy, solves, loose: bool = True) -> float:
    """The fraction of its first residual at which Newton may stop in an outer pass that is
    not the last: ``policy.pass_tolerance`` on the direct path, ``krylov_pass_tolerance`` on
    the Krylov path, where a later pass cannot use modified Newton's cheap solves and loose
    passes save whole Newton iterations (docs/methods/elasticity.md, "Loose passes"); 0 (every
    pass to ``newton_tol``) unless ``loose``."""
    if not loose:
        return 0.0
    return policy.pass_tolerance if solves.factorizes else policy.krylov_pass_tolerance


def solve_increment(system, solves, u0: np.ndarray, recovered0: list[np.ndarray | None], t: float,
                    options: SolverOptions, log: Log, start: np.ndarray | None = None, loose: bool = True
                    ) -> Increment | IncrementFailure:
    """The outer loop at load factor ``t`` from the unknowns ``u0`` and the recovery
    ``recovered0`` of the previous step (module docstring): an :class:`Increment`, or an
    :class:`IncrementFailure` when Newton fails. ``solves``: the linear solves
    (:class:`~cgfem.solve.solves.LinearSolves`); ``start``: the unknowns the first pass
    starts from (a predictor), ``u0`` if None; ``loose``: passes that are not the last may
    stop early (:func:`pass_tolerance`)."""
    policy = system.policy
    u, frozen, recovered = u0, list(recovered0), list(recovered0)
    changes: list[float] = []
    residuals: list[list[float]] = []
    # the forces in play, which Newton's residual is measured against: the dead loads, the
    # internal forces already carried and (Newton adds it) the first residual of the
    # increment. A cut-back increment has a tiny residual, but round-off scales with the
    # internal forces.
    reference = max(system.load_norm(t), system.force_scale(u))
    acceleration = accelerator(policy)
    following = recovered
    contact = system.contact
    active = contact.active()
    settled = True
    # the held points against their rule after a pass that otherwise settled
    unsettled_before = None
    first = 0.0           # Newton's reference in the first pass
    if start is not None:
        u = start
    # a pass that is not the last needs Newton only to a fraction of its first residual
    loose_fraction = pass_tolerance(policy, solves, loose)
    again = solves.again if solves.factorizes else None
    forces_from = options.outer_tol * (1.0 if solves.factorizes else LAST_PASSES)
    for outer in range(1, options.outer_passes + 1):
        stop_at = loose_fraction if (outer == 1 or changes[-1] > LAST_PASSES * options.outer_tol) else 0.0
        frozen = following
        system.freeze(frozen)
        if contact:
            contact.freeze(u, frozen)      # p_N = n . sigma* . n, with the same frozen sigma*
            contact.begin_pass(increment=outer == 1)

        def assemble(v, tangent):
            return system.assemble(v, t, tangent)

        def floating() -> bool:
            return bool(system.floating.bodies)

        def attempt(start: np.ndarray, fixed_tangent: bool, outer=outer) -> NewtonResult:
            solves.frozen = fixed_tangent
            tic = time.perf_counter()
            first = [True]

            def limit(du: np.ndarray) -> np.ndarray:
                # Newton's first step starts from ``start``; on the direct path the floating
                # bodies' rotations may be cut with the step's factorization (``again``)
                du = system.limit(start, du, first[0], again)
                first[0] = False
                return du
            try:
                return newton(assemble, start, solves, tol=options.newton_tol, reference=reference,
                              max_iter=policy.modified_newton_iterations if fixed_tangent else options.max_newton,
                              fixed_tangent=fixed_tangent, limit=limit, forcing=policy.forcing,
                              forcing_max=0.0 if solves.factorizes else policy.forcing_max, loose=stop_at,
                              stagnation=(policy.stagnation_window, policy.stagnation_factor),
                              energy_line_search=floating if policy.floating_search == "energy" else None,
                              log=lambda k, r, note: log(f"t={t:.4g} pass {outer} newton {k}: |r|/ref={r:.3e}  "
                                                         f"({time.perf_counter() - tic:.2f} s"
                                                         f"{'; ' + note if note else ''})"))
            finally:
                solves.frozen = False
        modified = outer > 1 and not system.linear and policy.modified_newton_iterations > 0 and solves.factorizes
        result, history = newton_pass(attempt, u, modified_first=modified)
        if not result.converged:
            log(f"t={t:.4g}: Newton stopped ({result.reason})")
            last = result.residuals[-1] / result.reference if result.reference > 0.0 else float("nan")
            return IncrementFailure(result.reason, outer, last, len(result.residuals) - 1,
                                    contact.changes() if contact else "")
        reference = result.reference
        if outer == 1:
            first = reference
        u = result.u
        residuals.append(history)
        recovered = system.recover(u)
        changes.append(relative_change(recovered, frozen))
        # Newton's reference includes the increment's first residual, which in a displacement-
        # driven increment is the weak-Dirichlet penalty's force beta M du_bar (it grows with
        # kappa_D, to 1e4 times the forces in play): a pass is tight only within newton_tol
        # of the forces at its solution, and the next pass's Newton is measured against them.
        # Tightness decides nothing before the last passes (the bulk internal force costs an
        # assembly), so it is measured only from then on (LAST_PASSES)
        tight = False
        if changes[-1] <= forces_from:
            forces = forces_in_play(system, u, t, first, options.newton_tol)
            tight = history[-1] <= options.newton_tol * forces
            if not tight:
                reference = forces
        if contact:
            previous, active = active, contact.active()
            switched = active_changes(active, previous)
            contradicted = contact.contradicted()
            settled = outer > 1 and switched == 0 and contradicted == 0 and tight
            held = f", {contradicted} held against their rule" if contradicted else ""
            log(f"t={t:.4g} pass {outer}: recovered stress changed by {changes[-1]:.3e}, "
                f"{int(sum(a.sum() for a in active))} active contact points ({switched} switched{held})")
            # a pass that settled but for the same held points as the pass before: the next
            # pass starts from the same state with the same frozen stress and repeats it
            unsettled = contact.contradicted_state() if (
                outer > 1 and switched == 0 and contradicted and tight) else None
            if unsettled is not None and unsettled == unsettled_before:
                which = contact.describe_contradicted()
                log(f"t={t:.4g}: contact does not settle ({which})")
                return IncrementFailure(UNSETTLED, outer, 0.0, sum(len(h) - 1 for h in residuals), which)
            unsettled_before = unsettled
        else:
            settled = tight
            log(f"t={t:.4g} pass {outer}: recovered stress changed by {changes[-1]:.3e}")
        if changes[-1] <= options.outer_tol and settled:
            break
        following = acceleration.next(frozen, recovered)
    rejected = system.turned_floating(u) if contact else ""
    if rejected:
        log(f"t={t:.4g}: state rejected: {rejected}")
        return IncrementFailure("rejected", len(changes), 0.0, sum(len(h) - 1 for h in residuals),
                                contact.changes(), rejected)
    extended, continuous = 0, 0.0
    if contact:
        r, extended = system.continuous_residual(u, t)
        continuous = float(np.linalg.norm(r)) / reference if reference > 0.0 else float(np.linalg.norm(r))
    # reactions are in equilibrium with the stress the last solve held frozen; the next step
    # starts from the newest recovery
    return Increment(u, frozen, recovered, residuals, changes, changes[-1] <= options.outer_tol and settled,
                     reference, continuous, extended)
