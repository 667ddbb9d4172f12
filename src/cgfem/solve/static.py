"""Quasi-static solution: load steps, the outer recovered-stress loop, Newton, cut-back.

For each load step the load factor ``t`` goes up by ``1 / steps``. Inside a step the outer
loop freezes the recovered stress ``P*`` of every body (the *frozen stress*, used by the
weak Dirichlet conditions, later by contact), solves the nonlinear problem by Newton,
recovers ``P*`` from the new displacement and repeats until ``P*`` changes by at most
``outer_tol`` (relative, in the Frobenius norm over all nodes); the next pass freezes the
recovery accelerated (:mod:`cgfem.solve.outer`). ``outer_passes`` is only a
cap: a step that reaches it above ``outer_tol`` (or with contact not settled) is kept but
marked ``outer_converged = False`` (and the run's status says so, see :class:`StaticResult`).
When Newton fails, or two outer passes repeat a state with held contact points against their
rule (:data:`~cgfem.solve.outer.UNSETTLED`), the increment is halved (at most
``max_cutbacks`` times per step, :class:`StepControl`) and the step is reached in several
sub-steps; if it still fails, the step is solved again from where it started with each of
the policy's fallbacks in turn (:func:`~cgfem.solve.policy.fallback_policies`; the failed
attempts' sub-steps are dropped, and the run keeps the fallback that converged; a state
rejected because a floating body turned goes to the next fallback without cut-backs), and when
none is left the run stops with status ``failed`` and keeps every converged step. An increment that fails after its first pass
while loose passes are in play (:func:`~cgfem.solve.outer.pass_tolerance`: the Krylov
path's) is first solved once more from the same state with every pass to ``newton_tol``. The system, its items and
its collaborators are in :mod:`cgfem.solve.system`; the tuning constants in
:class:`~cgfem.solve.policy.SolverPolicy`, which the system carries.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from cgfem.case.model import SolverOptions
from cgfem.solve.outer import IncrementFailure, Log, pass_tolerance, solve_increment
from cgfem.solve.policy import changed, fallback_policies
from cgfem.solve.solves import LinearSolves
from cgfem.solve.system import System


#: run statuses: every step converged with its outer loop below ``outer_tol``; every step
#: converged but at least one outer loop stopped at the ``outer_passes`` cap; Newton failed
CONVERGED, OUTER_NOT_CONVERGED, FAILED = "converged", "outer_not_converged", "failed"


@dataclass
class StepRecord:
    """One converged (sub)step.

    frozen_stress : per body, the nodal recovered stress (n_nodes, 3, 3) the last Newton
        solve held frozen (None before any recovery); reactions are in equilibrium with it
    recovered : per body, the nodal stress (n_nodes, 3, 3) recovered from the converged ``u``
    outer_converged : the last change of the recovered stress was <= ``outer_tol`` and
        contact had settled (False: the loop stopped at the ``outer_passes`` cap)
    """

    load_factor: float
    newton_residuals: list[list[float]]   # residual norms of every Newton solve, one per pass
    outer_passes: int
    outer_changes: list[float]
    outer_converged: bool
    u: list[np.ndarray] = field(repr=False)
    frozen_stress: list[np.ndarray | None] = field(repr=False)
    recovered: list[np.ndarray] = field(repr=False)
    seconds: float = 0.0
    #: the number of the policy's fallback the step converged with (0: the run's own policy)
    fallback: int = 0
    #: the system's whole vector of unknowns: the bodies' ``u`` followed by the contact
    #: set's own unknowns (the fitted surfaces of ``nurbs_fit``, :attr:`System.n_dofs`)
    unknowns: np.ndarray | None = field(default=None, repr=False)
    #: Newton's force scale; the residual over it at the converged state with every master
    #: hit on the continuous surface (not on the extension of the element or triangle its
    #: pairing kept, :data:`~cgfem.contact._ray_kernels.STICKY`, ``HOLD_BAND``); the active
    #: hits that were on one
    reference: float = 0.0
    continuous_residual: float = 0.0
    extended_hits: int = 0


@dataclass
class StaticResult:
    """Outcome of :func:`solve_static`: ``status`` is :data:`CONVERGED`,
    :data:`OUTER_NOT_CONVERGED` (every step reached, some outer loop stopped at its cap;
    ``message`` names the steps) or :data:`FAILED` (``message`` says where)."""

    status: str
    steps: list[StepRecord]
    message: str = ""
    #: the last attempt's failure when ``status`` is :data:`FAILED`
    failure: IncrementFailure | None = None


class StepControl:
    """The load factors of a run: ``steps`` equal steps up to 1, each reached in sub-steps
    when an increment fails. A failure halves the increment (at most ``max_cutbacks``
    times per step); the rest of the step is then taken in sub-steps of the size that
    succeeded, not ever smaller ones (docs/methods/elasticity.md, "Newton")."""

    def __init__(self, steps: int, max_cutbacks: int):
        self.steps, self.max_cutbacks = steps, max_cutbacks
        self.t, self.step = 0.0, 1
        self.size, self.cutbacks = 1.0 / steps, 0

    def next(self) -> float | None:
        """The load factor of the next increment, None when the last step is reached."""
        while self.step <= self.steps:
            target = self.step / self.steps
            if self.t < target - 1e-12 * self.size:
                return target if target - self.t <= self.size * (1.0 + 1e-9) else self.t + self.size
            self.step += 1
            self.size, self.cutbacks = 1.0 / self.steps, 0
        return None

    def accept(self, t: float) -> None:
        """The increment to ``t`` converged."""
        self.t = t

    def step_reached(self) -> bool:
        """Whether the last converged load factor is the current step's end."""
        return not self.t < self.step / self.steps - 1e-12 * self.size

    def restart(self, t: float) -> None:
        """The step again from load factor ``t`` (where it started), at its own size and with
        every cut-back (a fallback's attempt)."""
        self.t, self.size, self.cutbacks = t, 1.0 / self.steps, 0

    def cut_back(self) -> bool:
        """The increment failed: halve it; False when the step has no cut-back left."""
        self.cutbacks += 1
        if self.cutbacks > self.max_cutbacks:
            return False
        self.size *= 0.5
        return True


def predict(kind: str, t: float, u: np.ndarray, last: tuple[float, np.ndarray] | None,
            t_new: float) -> np.ndarray | None:
    """The start of the increment from ``(t, u)`` to ``t_new``: None (``u`` itself) for
    ``"none"`` or without an earlier state; for ``"secant"`` the line through the earlier
    converged state ``last = (t_0, u_0)`` and ``(t, u)`` at ``t_new``."""
    if kind != "secant" or last is None or not t > last[0]:
        return None
    t0, u0 = last
    return u + (t_new - t) / (t - t0) * (u - u0)


def solve_static(system: System, steps: int, options: SolverOptions, log: Log | None = None,
                 on_step: Callable[[StepRecord], None] | None = None,
                 on_drop: Callable[[int], None] | None = None) -> StaticResult:
    """Run the load steps; ``on_step`` is called after every converged (sub)step.

    A step whose increment fails is reached in sub-steps of half the size (a quarter after
    a second failure, ...), at most ``options.max_cutbacks`` halvings per step. If it still
    fails it is solved again from where it started with each of the policy's fallbacks in
    turn (:func:`~cgfem.solve.policy.fallback_policies`); an increment whose state is rejected
    because a floating body turned (:meth:`~cgfem.solve.system.System.turned_floating`) goes
    to the next fallback at once, without cut-backs, while one is left. The sub-steps of the failed attempts
    are dropped from the result, and ``on_drop`` is called with the number of records kept
    (every record then lies on the path to the last state; each names the fallback it
    converged with, :attr:`StepRecord.fallback`). A (sub)step
    whose outer loop stops at ``options.outer_passes`` above ``options.outer_tol`` is kept,
    logged with a ``warning:`` line and makes the status :data:`OUTER_NOT_CONVERGED`."""
    log = log or (lambda message: None)
    solves = LinearSolves.of(system, options.linear, log)      # ValueError if unusable
    u = np.zeros(system.n_dofs)
    recovered: list[np.ndarray | None] = [None] * len(system.bodies)
    control, records = StepControl(steps, options.max_cutbacks), []
    t, last = 0.0, None                                     # the converged state before (t, u)
    own, fallback = system.policy, 0                        # the run's policy, the fallback in use
    fallbacks = fallback_policies(own, system.held_by_contact_alone())
    untried = list(fallbacks)
    # where the current step started: the records before it, the converged state and what
    # the system had learnt there (a fallback's attempt starts from it as the first one did);
    # kept only where there is a fallback
    anchor = (0, t, u, recovered, last, system.saved() if fallbacks else None)
    while (t_new := control.next()) is not None:
        start = time.perf_counter()
        guess = predict(system.policy.predictor, t, u, last, t_new)
        outcome = solve_increment(system, solves, u, recovered, t_new, options, log, guess)
        if isinstance(outcome, IncrementFailure) and outcome.outer_pass > 1 \
                and pass_tolerance(system.policy, solves) > 0.0:
            # a pass that starts where a loose one stopped may find no descent on a contact
            # residual that kinks there (faceted surfaces): the increment again, every pass tight
            log(f"t={t_new:.4g}: {outcome}; again with every outer pass solved to newton_tol")
            outcome = solve_increment(system, solves, u, recovered, t_new, options, log, guess, loose=False)
        if isinstance(outcome, IncrementFailure):
            # a state rejected because a floating body turned asks for the floating constants
            # the fallbacks change, not for a smaller increment: the next fallback at once
            turned = bool(outcome.rejected) and bool(untried)
            if not turned and control.cut_back():
                log(f"cut-back {control.cutbacks}: load increment {control.size:.4g}")
                continue
            if not untried:
                also = f" and {len(fallbacks)} fallback(s)" if fallbacks else ""
                return StaticResult(FAILED, records, f"no convergence at load factor {t_new:.6g} "
                                    f"after {options.max_cutbacks} cut-backs{also} (last attempt: {outcome})",
                                    outcome)
            fallback, policy = untried.pop(0)
            kept, t, u, recovered, last, saved = anchor
            system.restore(saved)
            dropped = len(records) - kept
            why = "" if turned else f"no convergence after {options.max_cutbacks} cut-backs; "
            log(f"t={t_new:.4g}: {why}{outcome}; "
                f"fallback {fallback}: the step again from load factor {t:.4g}"
                + (f" ({dropped} converged sub-step(s) dropped)" if dropped else "") + " with "
                + ", ".join(f"{k}={v}" for k, v in changed(policy, own).items() if k != "fallbacks"))
            if dropped:
                del records[kept:]
                if on_drop:
                    on_drop(kept)
            system.adopt(policy)
            solves = LinearSolves.of(system, options.linear, log)     # no analysis kept from the failure
            control.restart(t)
            continue
        last = (t, u)
        u, recovered = outcome.u, outcome.recovered
        control.accept(t_new)
        t = t_new
        if not outcome.outer_converged:
            change = outcome.outer_changes[-1]
            why = (f"the recovered stress still changing by {change:.3e} > outer_tol = {options.outer_tol:.3e}"
                   if change > options.outer_tol else "the contact set not settled")
            log(f"warning: t={t:.4g}: outer loop stopped at outer_passes = {options.outer_passes} with {why}")
        record = StepRecord(t, outcome.newton_residuals, len(outcome.outer_changes),
                            outcome.outer_changes, outcome.outer_converged,
                            system.split(u.copy()), outcome.frozen_stress, recovered,
                            time.perf_counter() - start, fallback, u.copy(), outcome.reference,
                            outcome.continuous_residual, outcome.extended_hits)
        if outcome.extended_hits and outcome.continuous_residual > options.newton_tol:
            log(f"warning: t={t:.4g}: {outcome.extended_hits} active hits lie on the extension of the "
                f"master piece (element or triangle) their pairing kept; on the continuous surface "
                f"|r|/ref = {outcome.continuous_residual:.3e} > newton_tol = {options.newton_tol:.1e}")
        records.append(record)
        if on_step:
            on_step(record)
        if untried and control.step_reached():
            anchor = (len(records), t, u, recovered, last, system.saved())
    capped = [r.load_factor for r in records if not r.outer_converged]
    if capped:
        return StaticResult(OUTER_NOT_CONVERGED, records,
                            f"outer loop stopped at outer_passes = {options.outer_passes} before the "
                            f"recovered stress (outer_tol = {options.outer_tol:.3g}) and the contact set "
                            f"settled at load factor(s) {', '.join(f'{t:.6g}' for t in capped)}")
    return StaticResult(CONVERGED, records)


