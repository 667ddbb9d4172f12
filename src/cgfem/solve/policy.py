"""The static solver's tuning constants in one place.

:class:`SolverPolicy` holds every constant the nonlinear solver and its collaborators use
that a case file does not set (those are :class:`~cgfem.case.model.SolverOptions`). The
defaults are the measured values; why each has its value is in ``docs/methods/elasticity.md``
("The outer loop", "Newton", "Linear solvers") and ``docs/methods/contact.md`` ("Contact
onset", "Bodies held by contact alone"). The system carries its policy
(:class:`~cgfem.solve.system.System`, ``run_case(..., policy=...)``): tests and benchmarks build
one with other values (``dataclasses.replace(DEFAULT_POLICY, onset_penetration=math.inf)``)
instead of patching module globals.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace


@dataclass(frozen=True)
class SolverPolicy:
    """Tuning of the static solver (every value dimensionless unless stated).

    Newton and the outer loop
    -------------------------
    modified_newton_iterations : iterations allowed to modified Newton (the last
        factorization kept) in outer passes after the first, on the direct path only (a Krylov
        solve with an old matrix costs as much as with a new one); 0: full Newton always.
    stagnation_window, stagnation_factor : Newton gives up (reason ``stagnated``, and the
        increment is cut back) when the smallest residual of its last ``stagnation_window``
        iterates is above ``stagnation_factor`` times the smallest one before them (0: never).
        No Newton solve of the examples that converged had such a stretch (1892 solves);
        those that had it all ran into ``max_newton`` or the line search later.
    forcing : inexact Newton's forcing factor ``f``: an iterative linear solve stops at the
        relative residual ``f * newton_tol * reference / |r|`` (at most ``f``).
    forcing_max : on the Krylov path inexact Newton may also stop a linear solve at
        ``min(forcing_max, |r| / reference)`` where that is looser (0: off).
    pass_tolerance : an outer pass that is not the last (the recovered stress still changing by
        more than ``100 outer_tol``) stops Newton at ``pass_tolerance`` times its first residual,
        or at ``newton_tol`` if that is reached first (0: every pass to ``newton_tol``), on the
        direct path.
    krylov_pass_tolerance : the same on the Krylov path, where every Newton iteration costs a
        full Krylov solve: at 0.5 each pass but the last takes about one Newton iteration, and
        the outer loop and Newton converge together.
    predictor : the start of a load increment: ``"none"`` (the last converged state) or
        ``"secant"`` (extrapolated linearly in the load factor from the last two).
    acceleration : the outer loop's fixed-point acceleration of the frozen recovered stress
        (and ``p_N`` with it): ``"aitken"`` (Irons-Tuck dynamic relaxation), ``"anderson"``
        (Anderson mixing of depth :attr:`anderson_depth`) or ``"none"`` (plain substitution).
    anderson_depth : earlier passes Anderson mixing combines.

    Bodies held by contact alone (:class:`~cgfem.solve.floating.FloatingBodies`)
    ---------------------------------------------------------------------------
    free_mode : a rigid motion whose stiffness ``v^T K v`` is below this fraction of the mean
        diagonal of the body's own tangent is free.
    floating_shift : diagonal shift of a floating body's tangent, as a fraction of its first
        tangent's diagonal (tangent only, never the residual).
    shift_floor : the shift fades with ``|r| / max |r|`` of the increment down to this fraction.
    floating_step : largest nodal move of a floating body in one Newton step, in its element
        sizes ``h``.
    floating_turn : largest nodal move of a floating body in one Newton step, in its radius
        (the RMS distance of its nodes to their centroid): about the largest turn (rad) of a
        step. A coarse grid's ``h`` lets a step turn a small body far (1 h turns chain3's middle
        link by 0.21 rad at level 0), and a linearized turn stretches it (``rotation_stretch``).
    floating_rotation, rotation_cut_below, rotation_cut_min_order : largest rotation (rad) of a
        floating body's least-squares rigid motion in one Newton step on the direct path, where
        the residual is below ``rotation_cut_below`` of the increment's largest (near a
        solution, where a larger turn is the soft spin of a body held at two places, not the
        body finding its contacts); a step that turns it further is replaced by the step that minimizes
        Newton's quadratic model with the rotation cut to this size (three more solves with
        the step's factorization): the other unknowns follow the cut turn, where scaling the
        whole step held them back. Only for elements of order ``rotation_cut_min_order``
        and above (triquadratic): the trilinear examples converge without it, and on chain3 at level 1
        it moved ``nurbs_fe`` to another of the middle link's equilibria (0.57 % in the pulled
        reaction). ``floating_rotation = inf`` turns it off.
    floating_search : Newton's line search while a body floats: ``"residual"`` (Armijo on the
        residual norm, as without floating bodies) or ``"energy"`` (the step goes to the least
        energy along it where it descends, :func:`~cgfem.solve.newton.energy_minimum`, so that
        a floating body's soft rigid motion does not rock across a contact point's kink).
        Not the default (the faceted middle link settles at other equilibria, one pipeline
        run needs a cut-back: ``docs/validation.md``, "The chains at random grid offsets"),
        but every fallback's (:attr:`fallbacks`).
    damping_decay, damping_above, damping_max : the Levenberg-Marquardt damping of the shift: a
        step limited to a fraction ``f`` at ``|r|`` above ``damping_above`` of the increment's
        largest multiplies the shift of the next tangents by ``1 / f``; any other step by
        ``damping_decay``; kept in ``[1, damping_max]`` (``damping_max = 1`` turns it off).
    fallbacks : what a run tries when a step fails after its cut-backs: groups of
        ``name=value`` settings separated by ``;`` (settings within a group by ``,``); for each
        group in turn the step is solved again from where it started, with every cut-back,
        the run's constants changed by the group (the failed attempts' sub-steps dropped), and
        the run keeps the group that converged for the rest of its steps (:func:`fallback_policies`; ``"none"``: a
        failed step ends the run). A group that changes only :data:`FLOATING` constants is
        tried only where a body is held by contact alone. The default: the energy line search
        with the floating bodies' shift raised to ``1e-6`` (more damping of their rigid
        motions), the energy line search alone, and the search with the shift at ``1e-5``. A run
        that converges without a fallback is untouched (``docs/methods/contact.md``,
        "Fallbacks").
    rotation_stretch : in small strain a converged state is rejected (the step tried with the
        next fallback, or the increment cut back where none is left)
        where a floating body's linearized rotation stretches a chord between its contacts by
        more than this fraction of the chord's elastic stretch (the rotation is strain-free
        but not length-preserving), more than the gaps at the chord's ends and more than
        ``STRETCH_FLOOR_H`` element sizes (:meth:`~cgfem.solve.system.System.turned_floating`);
        ``inf`` turns the check off.
    spin_stiffness : the spring on a held spin (``bodies.<name>.hold_spin``,
        :class:`~cgfem.solve.spin.SpinSpring`) on each of the nodes that measure the spin, as a
        fraction of the grid's nodal stiffness ``E h``.

    Contact onset (:class:`~cgfem.solve.onset.OnsetLimit`)
    -------------------------------------------------------
    onset_penetration : deepest new penetration of a slave point, in its element sizes, the
        first Newton step of a solve may cause; ``inf`` turns the limit off.

    Linear solves (:class:`~cgfem.solve.solves.LinearSolves`)
    ----------------------------------------------------------
    krylov_min_dofs : ``linear: auto`` solves a symmetric system of trilinear elements (small
        strain, or no contact) of at least this many unknowns by the preconditioned Krylov
        path, smaller ones by the direct path (:mod:`cgfem.solve.backends`).
    krylov_nonsymmetric_min_dofs : the same for the non-symmetric systems of contact in finite
        strain with trilinear elements, where the two paths' answers differ by more than
        their tolerances once a grazing point or a held piece is decided differently
        (chain2_steel at level 2: 2.8e-5 of the reaction vector) and the faceted rubber
        chain's loose passes can fail on the Krylov path.
    krylov_order2_min_dofs : the same for triquadratic elements, whose 27-node couplings give
        about four times the nonzeros per unknown and factorizations that fill far more.
    krylov_floating_min_dofs : the further threshold, besides ``krylov_min_dofs``, of a system
        with a body held by contact alone (no displacement conditions of its own: chain3's
        middle link), whose Newton solves the Krylov path takes several times longer (more
        outer passes with loose passes, more GMRES iterations on its soft modes).
    krylov_saddle_min_dofs : the same for ``nurbs_fit``'s saddle points (on the Krylov path
        solved on the bodies' dofs with the AMG of the reduced matrix kept; on the direct path
        factorized whole up to ``SADDLE_DIRECT_DOFS``, above it reduced with a factorized
        preconditioner rebuilt for every matrix).
    krylov_refresh : a Krylov solve that needs more than this many iterations with a kept
        preconditioner is repeated with a preconditioner of the current matrix, unless
        ``krylov_refresh_rate`` allows more.
    krylov_refresh_rate : the kept preconditioner's limit is also this factor times the
        iterations per decade of residual of the last solve with a fresh one times the decades
        the solve asks for, where that is more than ``krylov_refresh`` (0: that limit alone;
        :meth:`~cgfem.solve.solves.LinearSolves.kept_limit`).
    krylov_max_iterations : iterations after which a Krylov solve with a fresh
        preconditioner is stalled: the system is then factorized directly (logged).
    krylov_stall_direct : after a stalled Krylov solve this many further matrices are
        factorized directly (the analysis of each kept for the next) instead of stalling in
        turn: the matrices after a stall are alike (chain3 at level 3 with ``facets`` stalled
        on four matrices in a row, 440 iterations and a factorization each).
    krylov_rtol : the tightest relative residual a Krylov solve is asked for (inexact Newton
        asks for looser ones).
    factor_precision : ``"single"``: PARDISO factorizes in single precision and the solves are
        refined in double to the double factors' residual check (``1e-8``), where no body is
        held by contact alone; a matrix whose refinement falls short is factorized again in
        double, and so is every later matrix of its system. ``"double"``: always in double.
        Single factors take about a third less time and half the memory; a floating body's
        nearly singular tangent (its stabilizing shift) is what single precision cannot
        resolve (:mod:`cgfem.solve.pardiso`).
    """

    modified_newton_iterations: int = 6
    stagnation_window: int = 10
    stagnation_factor: float = 0.5
    forcing: float = 0.1
    forcing_max: float = 1e-3
    pass_tolerance: float = 0.0
    krylov_pass_tolerance: float = 0.5
    predictor: str = "none"
    acceleration: str = "aitken"
    anderson_depth: int = 3
    free_mode: float = 1e-10
    floating_shift: float = 1e-8
    shift_floor: float = 1e-4
    floating_step: float = 1.0
    floating_turn: float = 0.07
    floating_rotation: float = 0.05
    floating_search: str = "residual"
    rotation_cut_below: float = 1e-3
    rotation_cut_min_order: int = 2
    damping_decay: float = 0.25
    damping_above: float = 1e-2
    damping_max: float = 1e6
    fallbacks: str = ("floating_search=energy, floating_shift=1e-6; floating_search=energy; "
                      "floating_search=energy, floating_shift=1e-5")
    rotation_stretch: float = 1.0
    spin_stiffness: float = 1e-2
    onset_penetration: float = 0.1
    krylov_min_dofs: int = 20_000
    krylov_nonsymmetric_min_dofs: int = 100_000
    krylov_order2_min_dofs: int = 20_000
    krylov_floating_min_dofs: int = 100_000
    krylov_saddle_min_dofs: int = 40_000
    krylov_refresh: int = 40
    krylov_refresh_rate: float = 1.5
    krylov_max_iterations: int = 400
    krylov_stall_direct: int = 4
    krylov_rtol: float = 1e-10
    factor_precision: str = "single"

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "fallbacks":
                if not isinstance(value, str):
                    raise ValueError(f"fallbacks must be text (name=value groups), got {value!r}")
                for group in fallback_groups(value):
                    if any(s.partition("=")[0].strip() == "fallbacks" for s in group):
                        raise ValueError("fallbacks: a fallback cannot set fallbacks")
                    try:
                        policy_with(group, replace(self, fallbacks="none"))
                    except ValueError as err:
                        raise ValueError(f"fallbacks: {err}") from None
            elif f.name in CHOICES:
                if value not in CHOICES[f.name]:
                    raise ValueError(f"{f.name} must be one of {', '.join(CHOICES[f.name])}, got {value!r}")
            elif isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value) \
                    or value < 0:
                raise ValueError(f"{f.name} must be a number >= 0, got {value!r}")
        if self.damping_max < 1.0:
            raise ValueError(f"damping_max must be >= 1, got {self.damping_max!r}")


#: the values of the policy's named choices
CHOICES = {"acceleration": ("aitken", "anderson", "none"), "predictor": ("none", "secant"),
           "floating_search": ("energy", "residual"), "factor_precision": ("single", "double")}

#: the constants only a body held by contact alone uses (:class:`~cgfem.solve.floating.FloatingBodies`,
#: the energy line search, the state check of its turn)
FLOATING = frozenset({"free_mode", "floating_shift", "shift_floor", "floating_step", "floating_turn",
                      "floating_rotation", "floating_search", "rotation_cut_below", "rotation_cut_min_order",
                      "damping_decay", "damping_above", "damping_max", "rotation_stretch",
                      "spin_stiffness"})


def fallback_groups(text: str) -> list[list[str]]:
    """The settings groups of a ``fallbacks`` text (``"a=1, b=2; c=3"``: ``[["a=1", "b=2"],
    ["c=3"]]``; ``"none"`` or blank: none)."""
    if text.strip().lower() == "none":
        return []
    return [[s.strip() for s in group.split(",") if s.strip()] for group in text.split(";") if group.strip()]


def fallback_policies(policy: SolverPolicy, floating: bool = True) -> list[tuple[int, SolverPolicy]]:
    """The policies a run falls back to, in order, each with its number (1 for the first group
    of ``policy.fallbacks``): ``policy`` with the group's constants changed and no fallbacks
    of its own; without the groups that change only :data:`FLOATING` constants when no body
    floats (``floating`` False): they would repeat the attempt that failed."""
    base = replace(policy, fallbacks="none")
    found = []
    for number, group in enumerate(fallback_groups(policy.fallbacks), start=1):
        candidate = policy_with(group, base)
        moved = changed(candidate, base)
        if moved and (floating or not set(moved) <= FLOATING):
            found.append((number, candidate))
    return found


def policy_with(settings: Sequence[str], base: SolverPolicy | None = None) -> SolverPolicy:
    """``base`` with the constants ``settings`` name, each ``"name=value"`` (the value read as
    the constant's type: ``"floating_turn=0.05"``, ``"floating_search=energy"``). Raises
    ValueError naming the setting that is not ``name=value``, not a constant, or out of range."""
    base = DEFAULT_POLICY if base is None else base
    types = {f.name: type(getattr(base, f.name)) for f in fields(base)}
    changes: dict[str, object] = {}
    for setting in settings:
        name, sep, text = setting.partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not text:
            raise ValueError(f"{setting!r} is not name=value")
        if name not in types:
            raise ValueError(f"{name} is not one of the solver's constants ({', '.join(sorted(types))})")
        kind = types[name]
        if kind is str:
            changes[name] = text
            continue
        try:
            number = float(text)
        except ValueError:
            number = math.nan
        if kind is int:
            if not number.is_integer():
                raise ValueError(f"{name} must be an integer, got {text!r}")
            changes[name] = int(number)
        elif text.lower() != "nan" and math.isnan(number):
            raise ValueError(f"{name} must be a number, got {text!r}")
        else:
            changes[name] = number
    return replace(base, **changes)


def changed(policy: SolverPolicy, base: SolverPolicy | None = None) -> dict[str, object]:
    """The constants of ``policy`` that differ from ``base``'s, by name, as JSON can hold
    them: a float that is not finite (``inf`` turns a limit off) as its text, ``"inf"``."""
    def value(v: object) -> object:
        return repr(v) if isinstance(v, float) and not math.isfinite(v) else v
    base = DEFAULT_POLICY if base is None else base
    return {f.name: value(getattr(policy, f.name)) for f in fields(policy)
            if getattr(policy, f.name) != getattr(base, f.name)}


DEFAULT_POLICY = SolverPolicy()
