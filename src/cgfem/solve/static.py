"""Quasi-static solution: load steps, the outer recovered-stress loop, Newton, cut-back.

For each load step the load factor ``t`` goes up by ``1 / steps``. Inside a step the outer
loop freezes the recovered stress ``P*`` of every body (the *frozen stress*, used by the
weak Dirichlet conditions, later by contact), solves the nonlinear problem by Newton,
recovers ``P*`` from the new displacement and repeats until ``P*`` changes by at most
``outer_tol`` (relative, in the Frobenius norm over all nodes); the next pass freezes the
recovery relaxed by Aitken's factor (:class:`Relaxation`). ``outer_passes`` is only a
cap: a step that reaches it above ``outer_tol`` is kept but marked
``outer_converged = False`` (and the run's status says so, see :class:`StaticResult`).
When Newton fails, the increment is halved (at most ``max_cutbacks`` times per step) and
the step is reached in several sub-steps; if it still fails, the run stops with status
``failed`` and keeps every converged step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from cgfem.case.model import SolverOptions
from cgfem.contact.assembly import ContactSet, active_changes
from cgfem.fem.body import BodyModel
from cgfem.solve.linear import choose_backend, factorize, rigid_body_modes
from cgfem.solve.saddle import FitConstraint
from cgfem.solve.newton import NewtonResult, newton


#: run statuses: every step converged with its outer loop below ``outer_tol``; every step
#: converged but at least one outer loop stopped at the ``outer_passes`` cap; Newton failed
CONVERGED, OUTER_NOT_CONVERGED, FAILED = "converged", "outer_not_converged", "failed"


@dataclass
class StepRecord:
    """One converged (sub)step.

    frozen_stress : per body, the nodal recovered stress (n_nodes, 3, 3) the last Newton
        solve held frozen (None before any recovery); reactions are in equilibrium with it
    recovered : per body, the nodal stress (n_nodes, 3, 3) recovered from the converged ``u``
    outer_converged : the last change of the recovered stress was <= ``outer_tol`` (False:
        the loop stopped at the ``outer_passes`` cap)
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


@dataclass(frozen=True)
class Increment:
    """The outer loop's result at one load factor (see :class:`StepRecord` for the fields)."""

    u: np.ndarray                         # (n_dofs,) converged displacement
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


class System:
    """The bodies of a case stacked into one vector of unknowns (block-diagonal tangent),
    followed by the unknowns the contact set owns (``contact.n_extra``: the fitted surfaces
    and their constraint multipliers of ``nurbs_fit``, :mod:`cgfem.contact.fitted`)."""

    def __init__(self, bodies: list[BodyModel], pairs: list | None = None):
        """``pairs``: contact pairs (:class:`~cgfem.contact.pair.ContactPair`) between the
        bodies, by their index in ``bodies``."""
        self.bodies = bodies
        sizes = [b.n_dofs for b in bodies]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.contact = ContactSet(list(pairs or []), self.offsets)
        #: bodies with a rigid motion their own conditions do not hold (held by contact
        #: alone in it), found from the first tangent (:meth:`free_rigid_modes`)
        self.floating: list[int] | None = None if self.contact else []
        #: per body, the rigid motions its own conditions leave free (with :attr:`floating`)
        self.free_modes: dict[int, int] = {}
        self._K: sp.csr_matrix | None = None
        self._shift: sp.csr_matrix | None = None
        #: load factor and largest residual norm of the increment (:meth:`_shift_factor`)
        self._largest: tuple[float, float] | None = None
        #: the floating bodies' shift multiplier, raised when a step had to be limited
        #: (:meth:`limit_step`), lowered again while steps are not
        self.damping = 1.0
        #: the multiplier of the floating bodies' shift in the last tangent, and per floating
        #: body the norm of the force that shift applied in the last Newton step of the
        #: increment (:meth:`limit_step`; N, vanishing with the step)
        self._scale = 0.0
        self.stabilizing: dict[int, float] = {}
        #: the shift factor of the last tangent (:meth:`_shift_factor`)
        self._fading = 1.0

    @property
    def linear(self) -> bool:
        """Small strain without contact: one tangent serves every iteration."""
        return not any(b.finite for b in self.bodies) and not self.contact

    @property
    def symmetric(self) -> bool:
        """Hyperelastic bulk, penalties and the frozen recovered stress give a symmetric
        tangent; contact in finite strain does not (the current-area weight)."""
        return self.contact.symmetric

    @property
    def indefinite(self) -> bool:
        """A saddle-point tangent (the fit constraints of ``nurbs_fit``)."""
        return self.contact.n_extra > 0

    @property
    def n_dofs(self) -> int:
        """All unknowns: the bodies' dofs and the contact set's own."""
        return int(self.offsets[-1]) + self.contact.n_extra

    def split(self, u: np.ndarray) -> list[np.ndarray]:
        return [u[a:b] for a, b in zip(self.offsets[:-1], self.offsets[1:])]

    def assemble(self, u: np.ndarray, t: float, frozen_stress: list[np.ndarray | None],
                 tangent: bool) -> tuple[np.ndarray, sp.csr_matrix | None]:
        """Residual (n_dofs,) at ``u`` and load factor ``t`` with every body's recovered
        stress held at ``frozen_stress`` (one (n_nodes, 3, 3) array or None per body), and
        the tangent if asked (CSR: the bodies' blocks on the diagonal, contact couplings off
        it)."""
        parts = [b.assemble(ub, t, s, tangent and not (self.linear and self._K is not None))
                 for b, ub, s in zip(self.bodies, self.split(u), frozen_stress)]
        r = np.concatenate([p[0] for p in parts] + [np.zeros(self.contact.n_extra)])
        Kc = self.contact.add(u, r, tangent) if self.contact else None
        if not tangent:
            return r, None
        if self.linear and self._K is not None:
            return r, self._K
        extra = self.contact.n_extra
        K = sp.block_diag([p[1] for p in parts] + ([sp.csr_matrix((extra, extra))] if extra else []),
                          format="csr")
        if self.linear:
            self._K = K
        if Kc is not None:
            if self.floating is None:
                self.free_modes = {i: self.free_rigid_modes(i, p[1]) for i, p in enumerate(parts)}
                self.floating = [i for i, n in self.free_modes.items() if n]
            K = K + Kc.tocsr()
            if self.floating:
                self._scale = self.damping * self._shift_factor(t, float(np.linalg.norm(r)))
                K = K + self._scale * self._floating_shift(K)
        return r, K

    def continuous_residual(self, u: np.ndarray, t: float, frozen_stress: list[np.ndarray | None]
                            ) -> tuple[np.ndarray, int]:
        """The residual at ``u`` with every master hit on the continuous surface, in the
        element or triangle holding it (:meth:`~cgfem.contact.assembly.ContactSet.continuous`),
        and how many active hits lie on a kept piece's extension instead."""
        parts = [b.assemble(ub, t, s, False) for b, ub, s in zip(self.bodies, self.split(u), frozen_stress)]
        r = np.concatenate([p[0] for p in parts] + [np.zeros(self.contact.n_extra)])
        return r, self.contact.continuous(u, r)

    def _shift_factor(self, t: float, norm: float) -> float:
        """The fraction of the floating bodies' tangent shift used at a linearization point
        with residual norm ``norm`` at load factor ``t``: ``norm`` over the largest residual
        norm seen at ``t`` (the increment's start), kept in ``[SHIFT_FLOOR, 1]``
        (:func:`shift_factor`)."""
        if self._largest is None or self._largest[0] != t:
            self._largest = (t, norm)
            self.damping = 1.0
            self.stabilizing = {}
        self._largest = (t, max(self._largest[1], norm))
        self._fading = shift_factor(norm, self._largest[1])
        return self._fading

    def limit_onset(self, u: np.ndarray, du: np.ndarray) -> np.ndarray:
        """The first Newton step ``du`` of a solve from ``u``, scaled so that no slave point
        goes deeper into its master than :data:`ONSET_PENETRATION` of its body's element size
        beyond where it already is (gaps at ``u`` and ``u + du``, the gap taken linear along
        the step); ``du`` itself if none does. That step's tangent knows no contact at points
        still open, so where an imposed motion closes a contact it carries the slave through
        the master by all of it: chain2_steel's first step at level 2 pushed 1085 points in
        by up to 1 mm (0.8 h), and Newton then swung hundreds of points in and out of the
        active set for 9 iterations and converged only by holding 721 (pass 1: 17
        iterations, the step 37). Scaled to 0.1 h the pass took 5 iterations and the step 12
        (the run 33 s; at 0.5 h: 14, 30 and 76 s), to the same contact force (3e-10).

        Not applied where a body is held by contact alone (:attr:`floating`): its first step
        is already bounded (:meth:`limit_step`) and governed by the tangent shift, and on
        chain3 the onset limit made things worse: with facets at level 2 two cut-backs and
        4 steps (60 Newton iterations) instead of 1 (25), at level 1 two cut-backs instead
        of none, nurbs_fit at level 2 31 iterations instead of 24."""
        if not self.contact or self.floating or not np.isfinite(ONSET_PENETRATION):
            return du
        pairs = self.contact.pairs
        allowed = [ONSET_PENETRATION * pair.slave_space.h for pair in pairs]
        after = self.contact.gaps(u + du)
        # a point goes no deeper than -g(u + du): the gaps at u are searched only if that is
        # beyond the allowance somewhere (the contact's onset, not a settled contact's steps)
        if all(np.nan_to_num(-g, nan=0.0).max(initial=0.0) <= a for g, a in zip(after, allowed)):
            return du
        factor = 1.0
        for before, end, a in zip(self.contact.gaps(u), after, allowed):
            seen = np.isfinite(end)
            deeper = np.minimum(np.nan_to_num(before[seen], nan=0.0), 0.0) - end[seen]
            depth = float(deeper.max(initial=0.0))
            if depth > a:
                factor = min(factor, a / depth)
        return du if factor == 1.0 else factor * du

    def limit_step(self, du: np.ndarray) -> np.ndarray:
        """The Newton step ``du`` scaled down (all of it: the bodies' equations are coupled)
        so that it moves no node of a body held by contact alone by more than
        ``FLOATING_STEP`` of its element size; ``du`` itself if it does not. Such a body's
        soft rigid motions may take a step far beyond the search's reach (``MAX_GAP_H``),
        where its contact is no longer seen and any rigid position solves its (unloaded)
        equations: chain3's middle link slipped out of both links that way, a converged
        state without contact.

        A step shortened to a fraction ``f`` while the residual is still above
        ``DAMPING_ABOVE`` of the increment's largest (the body is still finding its contacts)
        also multiplies the floating bodies' tangent shift by ``1 / f`` for the next tangents
        (:attr:`damping`, at most ``DAMPING_MAX``); any other step divides it by
        ``1 / DAMPING_DECAY`` again, down to 1. The soft rigid step then shrinks inside the
        solve, where the other bodies follow it, instead of every body's step being scaled
        with it (chain3 at level 2 with nurbs_fit: full load in 17 iterations instead of 30
        with steps cut to 5-8 % and a cut-back). Records :attr:`stabilizing`: the norm of
        ``scale * shift . du`` per floating body, the force the shift put into this step's
        linear system."""
        factor = 1.0
        shift = None if not self.floating or self._shift is None else self._shift.diagonal()
        for i in self.floating or ():
            a, b = self.offsets[i], self.offsets[i + 1]
            if shift is not None:
                self.stabilizing[i] = float(np.linalg.norm(self._scale * shift[a:b] * du[a:b]))
            move = float(np.abs(du[a:b]).max(initial=0.0))
            allowed = FLOATING_STEP * self.bodies[i].space.h
            if move > allowed:
                factor = min(factor, allowed / move)
        raise_ = factor < 1.0 and self._fading >= DAMPING_ABOVE
        self.damping = float(np.clip(self.damping / factor if raise_ else self.damping * DAMPING_DECAY,
                                     1.0, DAMPING_MAX))
        return du if factor == 1.0 else factor * du

    def free_rigid_modes(self, i: int, K: sp.csr_matrix) -> int:
        """How many rigid motions body ``i``'s own tangent ``K`` (its conditions included, no
        contact) leaves free: eigenvalues of ``P^T K P`` on its orthonormalized rigid modes
        ``P`` (3 n, 6) below ``FREE_MODE`` times its mean diagonal. A body without Dirichlet
        conditions has six; one held along x and y on one face only may keep a translation and a
        rotation free."""
        P, _ = np.linalg.qr(rigid_body_modes(self.bodies[i].space.coordinates))
        S = P.T @ (K @ P)
        scale = float(np.mean(np.abs(K.diagonal())))
        return int(np.sum(np.linalg.eigvalsh(0.5 * (S + S.T)) < FREE_MODE * scale))

    def _floating_shift(self, K: sp.csr_matrix) -> sp.csr_matrix:
        """Tangent-only stabilization of bodies held by contact alone in some rigid motion
        (:meth:`free_rigid_modes`): ``FLOATING_SHIFT``
        times the diagonal of their first tangent, scaled by :meth:`_shift_factor` and by
        :attr:`damping` (:meth:`limit_step`), is added
        to the matrix Newton solves, never to the residual. It makes the rigid motions of such
        a body solvable before contact forces hold it (and a frictionless spinning mode
        always), and leaves the converged solution exactly that of the unstabilized equations:
        no stabilizing force remains. The scaling (Levenberg-Marquardt-like) lets the shift
        fade as Newton converges: a soft rigid mode of stiffness ``k`` is corrected at the rate
        ``shift / (k + shift)`` per iteration, 0.92 with the full shift on chain3's middle link
        at level 2 (a torus held at two points), which stalled Newton at 1e-8."""
        if self._shift is None:
            d = np.zeros(self.n_dofs)
            diag = K.diagonal()
            for i in self.floating:
                a, b = self.offsets[i], self.offsets[i + 1]
                d[a:b] = FLOATING_SHIFT * diag[a:b]
            self._shift = sp.diags(d, format="csr")
        return self._shift

    def recover(self, u: np.ndarray) -> list[np.ndarray]:
        return [b.recover(ub) for b, ub in zip(self.bodies, self.split(u))]

    def load_norm(self, t: float) -> float:
        return float(t * np.sqrt(sum(np.dot(b.load, b.load) for b in self.bodies)))

    def force_scale(self, u: np.ndarray) -> float:
        """Norm of the bulk internal force at ``u``: the size of the forces in play, against
        which Newton's residual is measured (it does not shrink with the load increment)."""
        total = 0.0
        for body, ub in zip(self.bodies, self.split(u)):
            f = np.zeros(body.n_dofs)
            body.elasticity.add(ub, f, None)
            total += float(np.dot(f, f))
        return float(np.sqrt(total))

    def saddle(self) -> tuple[int, list[FitConstraint]] | None:
        """nurbs_fit's saddle point for the linear solver (:mod:`cgfem.solve.saddle`): the
        bodies' dof count and one block per fitted patch; None without fitted patches."""
        blocks = self.contact.blocks
        if not blocks:
            return None
        return int(self.offsets[-1]), [
            FitConstraint(b.z, b.mu, self.offsets[b.body] + np.arange(self.bodies[b.body].n_dofs), b.fit.M, b.fit.G,
                          b.fit.factor.solve, b.scale) for b in blocks]

    def near_null(self) -> np.ndarray:
        """Rigid-body modes of every body, block by block (n_dofs, 6 n_bodies); zero on the
        contact set's own unknowns."""
        blocks = [rigid_body_modes(b.space.coordinates) for b in self.bodies]
        modes = sp.block_diag(blocks).toarray()
        return np.vstack([modes, np.zeros((self.contact.n_extra, modes.shape[1]))])


class _Solver:
    """Linear solves with the factorization kept while the matrix object is unchanged, or
    while ``frozen`` (modified Newton: the last factorization serves for a new matrix).
    Failures raise :class:`~cgfem.solve.linear.LinearSolverError`, which Newton reports."""

    def __init__(self, backend: str, near_null: np.ndarray, symmetric: bool = True, indefinite: bool = False,
                 saddle: tuple | None = None):
        self.backend, self.near_null, self.symmetric = backend, near_null, symmetric
        self.indefinite, self.saddle = indefinite, saddle
        self._key, self._factor = None, None
        self.frozen = False

    def __call__(self, K: sp.csr_matrix, b: np.ndarray, rtol: float | None = None) -> np.ndarray:
        if self._key is not K and not (self.frozen and self._factor is not None):
            self._factor = factorize(K, backend=self.backend, symmetric=self.symmetric,
                                     near_null=self.near_null, indefinite=self.indefinite, saddle=self.saddle)
            self._key = K
        return self._factor.solve(b, rtol)


def relative_change(new: list[np.ndarray], old: list[np.ndarray | None]) -> float:
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


Log = Callable[[str], None]

#: iterations allowed to modified Newton (frozen tangent) in outer passes after the first
MODIFIED_NEWTON_ITERATIONS = 6
#: the floating bodies' tangent shift fades with the residual down to this fraction of it
SHIFT_FLOOR = 1e-4
#: diagonal shift of the tangent of bodies held by contact only (:meth:`System._floating_shift`)
FLOATING_SHIFT = 1e-8
#: adapt the floating bodies' shift to the step limit (Levenberg-Marquardt, see
#: :meth:`System.limit_step`): a step limited to a fraction f at a residual above DAMPING_ABOVE
#: of the increment's largest multiplies the shift of the next tangents by 1 / f, any other
#: step by DAMPING_DECAY, within [1, DAMPING_MAX]. Raised near convergence too, it piled up to
#: ~1e3 on chain3 at level 1 with nurbs_fit (limited steps at |r| ~ 3e-3 of the largest: the
#: middle link's soft spin) and stalled Newton (a cut-back, 225 s instead of 54 s); capped at
#: 100 it no longer helped level 2. DAMPING_MAX = 1 turns it off
DAMPING_DECAY = 0.25
DAMPING_ABOVE = 1e-2
DAMPING_MAX = 1e6
#: a rigid motion whose stiffness is below this fraction of the mean diagonal is free
FREE_MODE = 1e-10
#: largest nodal move, in element sizes, of a body held by contact alone in one Newton step
FLOATING_STEP = 1.0
#: deepest new penetration of a slave point, in its element sizes, that the first Newton step
#: of a solve may cause (:meth:`System.limit_onset`); inf turns the limit off
ONSET_PENETRATION = 0.1
#: relax the outer loop's fixed point (:class:`Relaxation`); False: plain substitution
ACCELERATE = True
#: inexact Newton's forcing factor (:func:`cgfem.solve.newton.newton`): iterative linear
#: solves stop at this fraction of Newton's tolerance over the current residual
FORCING = 0.1


def newton_pass(attempt: Callable[[np.ndarray, bool], NewtonResult], u: np.ndarray,
                modified_first: bool) -> tuple[NewtonResult, list[float]]:
    """One outer pass's Newton solve from ``u``: ``attempt(start, fixed_tangent)`` runs
    Newton. Later passes start close to the solution (``modified_first``): modified Newton
    on the last factorization first, then, if it does not converge within its few
    iterations, full Newton, from where modified Newton got to when it went down (chain2_steel
    at level 2: 1.2e-9 after 6 modified iterations, then 1 full iteration instead of 3 from
    the pass's start), and from ``u`` if that fails too (modified Newton may stop on a kink
    of the contact surface, line searches cutting its steps: chain2_steel at level 2 with
    nurbs_fe, whose full Newton from there failed at load 0.8 where it converges from ``u``).
    Returns the last result and the residual history of the iterates that lead to it (the
    modified ones first)."""
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


def shift_factor(norm: float, largest: float) -> float:
    """``norm / largest`` kept in ``[SHIFT_FLOOR, 1]`` (1 if ``largest`` is not positive)."""
    if not largest > 0.0:
        return 1.0
    return float(min(1.0, max(norm / largest, SHIFT_FLOOR)))


def solve_static(system: System, steps: int, options: SolverOptions, log: Log | None = None,
                 on_step: Callable[[StepRecord], None] | None = None) -> StaticResult:
    """Run the load steps; ``on_step`` is called after every converged (sub)step.

    A step whose increment fails is reached in sub-steps of half the size (a quarter after
    a second failure, ...), at most ``options.max_cutbacks`` halvings per step. A (sub)step
    whose outer loop stops at ``options.outer_passes`` above ``options.outer_tol`` is kept,
    logged with a ``warning:`` line and makes the status :data:`OUTER_NOT_CONVERGED`."""
    log = log or (lambda message: None)
    # ValueError if unusable
    choose_backend(system.n_dofs, system.symmetric, options.linear, system.indefinite)
    solver = _Solver(options.linear, system.near_null(), system.symmetric, system.indefinite, system.saddle())
    u = np.zeros(system.n_dofs)
    recovered: list[np.ndarray | None] = [None] * len(system.bodies)
    t, records = 0.0, []
    for step in range(1, steps + 1):
        target = step / steps
        size, cutbacks = 1.0 / steps, 0
        while t < target - 1e-12 * size:
            t_new = target if target - t <= size * (1.0 + 1e-9) else t + size
            start = time.perf_counter()
            outcome = _solve_increment(system, solver, u, recovered, t_new, options, log)
            if isinstance(outcome, str):
                cutbacks += 1
                if cutbacks > options.max_cutbacks:
                    return StaticResult(FAILED, records, f"no convergence at load factor {t_new:.6g} "
                                        f"after {options.max_cutbacks} cut-backs (last attempt: {outcome})")
                size *= 0.5
                log(f"cut-back {cutbacks}: load increment {size:.4g}")
                continue
            u, recovered, t = outcome.u, outcome.recovered, t_new
            if not outcome.outer_converged:
                log(f"warning: t={t:.4g}: outer loop stopped at outer_passes = {options.outer_passes} "
                    f"with the recovered stress still changing by {outcome.outer_changes[-1]:.3e} "
                    f"> outer_tol = {options.outer_tol:.3e}")
            record = StepRecord(t, outcome.newton_residuals, len(outcome.outer_changes),
                                outcome.outer_changes, outcome.outer_converged,
                                system.split(u.copy()), outcome.frozen_stress, recovered,
                                time.perf_counter() - start, u.copy(), outcome.reference,
                                outcome.continuous_residual, outcome.extended_hits)
            if outcome.extended_hits and outcome.continuous_residual > options.newton_tol:
                log(f"warning: t={t:.4g}: {outcome.extended_hits} active hits lie on the extension of the "
                    f"master piece (element or triangle) their pairing kept; on the continuous surface "
                    f"|r|/ref = {outcome.continuous_residual:.3e} > newton_tol = {options.newton_tol:.1e}")
            records.append(record)
            if on_step:
                on_step(record)
    capped = [r.load_factor for r in records if not r.outer_converged]
    if capped:
        return StaticResult(OUTER_NOT_CONVERGED, records,
                            f"outer loop stopped at outer_passes = {options.outer_passes} above "
                            f"outer_tol = {options.outer_tol:.3g} at load factor(s) "
                            f"{', '.join(f'{t:.6g}' for t in capped)}")
    return StaticResult(CONVERGED, records)


def _solve_increment(system: System, solver: _Solver, u0: np.ndarray,
                     recovered0: list[np.ndarray | None], t: float, options: SolverOptions,
                     log: Log) -> Increment | str:
    """Outer loop at load factor ``t`` from ``u0`` and the recovery ``recovered0`` of the
    previous step, until the recovered stress changes by <= ``options.outer_tol`` or
    ``options.outer_passes`` solves are done; why it stopped (a string) when Newton fails."""
    u, frozen, recovered = u0, list(recovered0), list(recovered0)
    changes: list[float] = []
    residuals: list[list[float]] = []
    # the forces in play, which Newton's residual is measured against: the dead loads, the
    # internal forces already carried and (Newton adds it) the first residual of the
    # increment. A cut-back increment has a tiny residual, but round-off scales with the
    # internal forces.
    reference = max(system.load_norm(t), system.force_scale(u))
    relaxation = Relaxation(ACCELERATE)
    following = recovered
    contact = system.contact
    active = contact.active()
    settled = True
    for outer in range(1, options.outer_passes + 1):
        frozen = following
        if contact:
            contact.freeze(u, frozen)      # p_N = n . sigma* . n, with the same frozen sigma*
            contact.begin_pass(increment=outer == 1)

        def assemble(v, tangent, frozen=frozen):
            return system.assemble(v, t, frozen, tangent)
        def attempt(start: np.ndarray, fixed_tangent: bool) -> NewtonResult:
            solver.frozen = fixed_tangent
            tic = time.perf_counter()
            first = True

            def limit(du: np.ndarray) -> np.ndarray:
                # newton's first step starts from ``start``
                nonlocal first
                du = system.limit_step(du)
                if first:
                    first = False
                    du = system.limit_onset(start, du)
                return du
            try:
                return newton(assemble, start, solver, tol=options.newton_tol, reference=reference,
                              max_iter=MODIFIED_NEWTON_ITERATIONS if fixed_tangent else options.max_newton,
                              fixed_tangent=fixed_tangent, limit=limit, forcing=FORCING,
                              log=lambda k, r, note: log(f"t={t:.4g} pass {outer} newton {k}: |r|/ref={r:.3e}  "
                                                         f"({time.perf_counter() - tic:.2f} s"
                                                         f"{'; ' + note if note else ''})"))
            finally:
                solver.frozen = False
        result, history = newton_pass(attempt, u, modified_first=outer > 1 and not system.linear)
        if not result.converged:
            log(f"t={t:.4g}: Newton stopped ({result.reason})")
            last = result.residuals[-1] / result.reference if result.reference > 0.0 else float("nan")
            why = f"; {contact.changes()}" if contact else ""
            return (f"Newton stopped on {result.reason} in outer pass {outer} at |r|/ref = {last:.2e} "
                    f"after {len(result.residuals) - 1} iterations{why}")
        reference = result.reference
        u = result.u
        residuals.append(history)
        recovered = system.recover(u)
        changes.append(relative_change(recovered, frozen))
        if contact:
            previous, active = active, contact.active()
            switched = active_changes(active, previous)
            contradicted = contact.contradicted()
            settled = outer > 1 and switched == 0 and contradicted == 0
            held = f", {contradicted} held against their rule" if contradicted else ""
            log(f"t={t:.4g} pass {outer}: recovered stress changed by {changes[-1]:.3e}, "
                f"{int(sum(a.sum() for a in active))} active contact points ({switched} switched{held})")
        else:
            log(f"t={t:.4g} pass {outer}: recovered stress changed by {changes[-1]:.3e}")
        if changes[-1] <= options.outer_tol and settled:
            break
        following = relaxation.next(frozen, recovered)
    extended, continuous = 0, 0.0
    if contact:
        r, extended = system.continuous_residual(u, t, frozen)
        continuous = float(np.linalg.norm(r)) / reference if reference > 0.0 else float(np.linalg.norm(r))
    # reactions are in equilibrium with the stress the last solve held frozen; the next step
    # starts from the newest recovery
    return Increment(u, frozen, recovered, residuals, changes, changes[-1] <= options.outer_tol and settled,
                     reference, continuous, extended)
