"""Quasi-static solution: load steps, the outer recovered-stress loop, Newton, cut-back.

For each load step the load factor ``t`` goes up by ``1 / steps``. Inside a step the outer
loop freezes the recovered stress ``P*`` of every body (used by the weak Dirichlet
conditions, later by contact), solves the nonlinear problem by Newton, recovers ``P*``
from the new displacement and repeats until ``P*`` changes by less than ``outer_tol``
(relative, in the Frobenius norm over all nodes) or ``outer_passes`` are used. When Newton
fails, the increment is halved (at most ``max_cutbacks`` times per step) and the step is
reached in several sub-steps; if it still fails, the run stops with status ``failed`` and
keeps every converged step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from cgfem.case.model import SolverOptions
from cgfem.fem.body import BodyModel
from cgfem.solve.linear import choose_backend, factorize, rigid_body_modes
from cgfem.solve.newton import newton


@dataclass
class StepRecord:
    """One converged (sub)step."""

    load_factor: float
    newton_residuals: list[list[float]]   # residual norms of every Newton solve, one per pass
    outer_passes: int
    outer_changes: list[float]
    u: list[np.ndarray] = field(repr=False)
    stress: list[np.ndarray | None] = field(repr=False)     # the recovered stress the last solve used
    recovered: list[np.ndarray] = field(repr=False)         # recovered from the converged u
    seconds: float = 0.0


@dataclass
class StaticResult:
    status: str                     # "converged" | "failed"
    steps: list[StepRecord]
    message: str = ""


class System:
    """The bodies of a case stacked into one vector of unknowns (block-diagonal tangent)."""

    def __init__(self, bodies: list[BodyModel]):
        self.bodies = bodies
        sizes = [b.n_dofs for b in bodies]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.linear = not any(b.finite for b in bodies)
        #: the tangent is symmetric: hyperelastic bulk, penalties, frozen recovered stress
        self.symmetric = True
        self._K: sp.csr_matrix | None = None

    @property
    def n_dofs(self) -> int:
        return int(self.offsets[-1])

    def split(self, u: np.ndarray) -> list[np.ndarray]:
        return [u[a:b] for a, b in zip(self.offsets[:-1], self.offsets[1:])]

    def assemble(self, u: np.ndarray, t: float, stress: list[np.ndarray | None],
                 tangent: bool) -> tuple[np.ndarray, sp.csr_matrix | None]:
        parts = [b.assemble(ub, t, s, tangent and not (self.linear and self._K is not None))
                 for b, ub, s in zip(self.bodies, self.split(u), stress)]
        r = np.concatenate([p[0] for p in parts])
        if not tangent:
            return r, None
        if self.linear and self._K is not None:
            return r, self._K
        K = sp.block_diag([p[1] for p in parts], format="csr")
        if self.linear:
            self._K = K
        return r, K

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

    def near_null(self) -> np.ndarray:
        """Rigid-body modes of every body, block by block (n_dofs, 6 n_bodies)."""
        blocks = [rigid_body_modes(b.space.coordinates) for b in self.bodies]
        return sp.block_diag(blocks).toarray()


class _Solver:
    """Linear solves with the factorization kept while the matrix object is unchanged, or
    while ``frozen`` (modified Newton: the last factorization serves for a new matrix).
    Failures raise :class:`~cgfem.solve.linear.LinearSolverError`, which Newton reports."""

    def __init__(self, backend: str, near_null: np.ndarray, symmetric: bool = True):
        self.backend, self.near_null, self.symmetric = backend, near_null, symmetric
        self._key, self._factor = None, None
        self.frozen = False

    def __call__(self, K: sp.csr_matrix, b: np.ndarray) -> np.ndarray:
        if self._key is not K and not (self.frozen and self._factor is not None):
            self._factor = factorize(K, backend=self.backend, symmetric=self.symmetric,
                                     near_null=self.near_null)
            self._key = K
        return self._factor.solve(b)


def relative_change(new: list[np.ndarray], old: list[np.ndarray | None]) -> float:
    num = sum(float(np.sum((n - (0.0 if o is None else o)) ** 2)) for n, o in zip(new, old))
    den = sum(float(np.sum(n ** 2)) for n in new)
    return float(np.sqrt(num / den)) if den > 0.0 else float(np.sqrt(num))


Log = Callable[[str], None]

#: iterations allowed to modified Newton (frozen tangent) in outer passes after the first
MODIFIED_NEWTON_ITERATIONS = 6


def solve_static(system: System, steps: int, options: SolverOptions, log: Log | None = None,
                 on_step: Callable[[StepRecord], None] | None = None) -> StaticResult:
    """Run the load steps; ``on_step`` is called after every converged (sub)step.

    A step whose increment fails is reached in sub-steps of half the size (a quarter after
    a second failure, ...), at most ``options.max_cutbacks`` halvings per step."""
    log = log or (lambda message: None)
    choose_backend(system.n_dofs, system.symmetric, options.linear)   # ValueError if unusable
    solver = _Solver(options.linear, system.near_null(), system.symmetric)
    u = np.zeros(system.n_dofs)
    stress: list[np.ndarray | None] = [None] * len(system.bodies)
    t, records = 0.0, []
    for step in range(1, steps + 1):
        target = step / steps
        size, cutbacks = 1.0 / steps, 0
        while t < target - 1e-12 * size:
            t_new = target if target - t <= size * (1.0 + 1e-9) else t + size
            start = time.perf_counter()
            outcome = _solve_increment(system, solver, u, stress, t_new, options, log)
            if outcome is None:
                cutbacks += 1
                if cutbacks > options.max_cutbacks:
                    return StaticResult("failed", records, f"no convergence at load factor {t_new:.6g} "
                                        f"after {options.max_cutbacks} cut-backs")
                size *= 0.5
                log(f"cut-back {cutbacks}: load increment {size:.4g}")
                continue
            u, used, stress, residuals, changes = outcome
            t = t_new
            record = StepRecord(t, residuals, len(changes), changes, system.split(u.copy()),
                                used, stress, time.perf_counter() - start)
            records.append(record)
            if on_step:
                on_step(record)
    return StaticResult("converged", records)


def _solve_increment(system: System, solver: _Solver, u0: np.ndarray, stress0: list, t: float,
                     options: SolverOptions, log: Log):
    """Outer loop at load factor ``t``: (u, stress used by the last solve, stress recovered
    from u, Newton residuals per pass, stress changes per pass); None when Newton fails."""
    u, stress = u0, list(stress0)
    changes: list[float] = []
    residuals: list[list[float]] = []
    # the forces in play, which Newton's residual is measured against: the dead loads, the
    # internal forces already carried and (Newton adds it) the first residual of the
    # increment. A cut-back increment has a tiny residual, but round-off scales with the
    # internal forces.
    reference = max(system.load_norm(t), system.force_scale(u))
    for outer in range(1, options.outer_passes + 1):
        def assemble(v, tangent, stress=stress):
            return system.assemble(v, t, stress, tangent)
        # later passes start close to the solution: modified Newton on the last
        # factorization first, a full Newton solve if that does not converge quickly
        attempts = [True, False] if outer > 1 and not system.linear else [False]
        for frozen in attempts:
            solver.frozen = frozen
            tic = time.perf_counter()
            result = newton(assemble, u, solver, tol=options.newton_tol, reference=reference,
                            max_iter=MODIFIED_NEWTON_ITERATIONS if frozen else options.max_newton,
                            fixed_tangent=frozen,
                            log=lambda k, r: log(f"t={t:.4g} pass {outer} newton {k}: "
                                                 f"|r|/ref={r:.3e}  ({time.perf_counter() - tic:.2f} s)"))
            solver.frozen = False
            if result.converged:
                break
        if not result.converged:
            log(f"t={t:.4g}: Newton stopped ({result.reason})")
            return None
        reference = result.reference
        u = result.u
        residuals.append(result.residuals)
        used, stress = stress, system.recover(u)
        changes.append(relative_change(stress, used))
        log(f"t={t:.4g} pass {outer}: recovered stress changed by {changes[-1]:.3e}")
        if changes[-1] <= options.outer_tol:
            break
    # reactions are in equilibrium with the stress the last solve used; the next step starts
    # from the newest recovery
    return u, used, stress, residuals, changes
