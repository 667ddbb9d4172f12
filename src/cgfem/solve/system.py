"""A case's bodies and contact pairs as one system of equations, summed over its items.

The unknowns are the bodies' dofs stacked in order (body ``i`` owns ``offsets[i]:offsets[i+1]``)
followed by the unknowns the contact set owns (``contact.n_extra``: the fitted surfaces and
their constraint multipliers of ``nurbs_fit``, :mod:`cgfem.contact.fitted`). The residual and
the tangent are sums over items (:mod:`cgfem.solve.items`): every body, every contact pair,
the fit constraints, the springs that hold bodies' spins (:mod:`cgfem.solve.spin`). Two collaborators act on what Newton solves: the floating bodies'
tangent shift and step limit (:class:`~cgfem.solve.floating.FloatingBodies`) and the
contact-onset limit (:class:`~cgfem.solve.onset.OnsetLimit`).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.sparse as sp

from cgfem.contact.assembly import ContactSet, couplings_matrix
from cgfem.fem.assembly import index_type
from cgfem.solve.floating import STRETCH_FLOOR_H, FloatingBodies, rotation_stretch
from cgfem.solve.items import Block, BodyItem
from cgfem.solve.linear import rigid_body_modes
from cgfem.solve.onset import OnsetLimit
from cgfem.solve.spin import SpinSpring
from cgfem.solve._sparse_kernels import sum_csr
from cgfem.solve.policy import DEFAULT_POLICY, SolverPolicy
from cgfem.solve.saddle import FitConstraint


def stack_diagonal(blocks: list[sp.spmatrix], extra: int = 0) -> sp.csr_matrix:
    """The square ``blocks`` (at least one) on the diagonal of one CSR matrix, in order,
    followed by ``extra`` empty rows and columns: their CSR arrays concatenated, each block's
    column indices shifted by the sizes before it. For blocks in canonical form the arrays are
    those of ``scipy.sparse.block_diag(..., format="csr")``, without its round trip through COO."""
    mats = [sp.csr_matrix(K) for K in blocks]
    starts = np.cumsum([0] + [K.shape[0] for K in mats])
    nnz = np.cumsum([0] + [K.nnz for K in mats])
    n = int(starts[-1]) + extra
    index = index_type(n, int(nnz[-1]))
    data = np.concatenate([K.data for K in mats])
    indices = np.concatenate([K.indices.astype(index) + index(s) for K, s in zip(mats, starts)])
    indptr = np.concatenate([np.zeros(1, index)] + [K.indptr[1:].astype(index) + index(z) for K, z in zip(mats, nnz)]
                            + [np.full(extra, nnz[-1], index)])
    return sp.csr_matrix((data, indices, indptr), shape=(n, n))


def add_couplings(K: sp.csr_matrix, C: sp.spmatrix) -> sp.csr_matrix:
    """``K + C`` (n, n), entry for entry scipy's sum (sorted columns, exact zeros left out),
    merged row by row by a kernel that copies the rows ``C`` does not touch: the contact
    couplings' thousands of entries against the bodies' millions."""
    C = sp.csr_matrix(C)
    C.sum_duplicates()
    if not K.has_canonical_format:
        return sp.csr_matrix(K + C)
    index = K.indices.dtype
    indptr, indices, data = sum_csr(K.indptr, K.indices, K.data, C.indptr.astype(index),
                                    C.indices.astype(index), C.data.astype(np.float64), 1.0)
    return sp.csr_matrix((data, indices, indptr), shape=K.shape)


class DiagonalStack:
    """:func:`stack_diagonal` for blocks whose structure does not change (the bodies' fixed
    sparsity patterns): the stacked index arrays are built on the first call and kept while
    the blocks' index arrays are the same memory; later calls only concatenate the values.
    The blocks' index arrays are never written to (scipy's arithmetic returns new matrices)."""

    def __init__(self, extra: int = 0):
        self.extra = int(extra)
        self._sources: list[np.ndarray] = []     # the blocks' index arrays, held alive
        self._structure: tuple[np.ndarray, np.ndarray, int] | None = None

    def __call__(self, blocks: list[sp.spmatrix]) -> sp.csr_matrix:
        mats = [sp.csr_matrix(K) for K in blocks]
        sources = [a for K in mats for a in (K.indices, K.indptr)]
        if self._structure is None or len(sources) != len(self._sources) or any(
                a.ctypes.data != b.ctypes.data or a.shape != b.shape or a.dtype != b.dtype
                for a, b in zip(sources, self._sources)):
            K = stack_diagonal(mats, self.extra)
            self._sources, self._structure = sources, (K.indices, K.indptr, K.shape[0])
            return K
        indices, indptr, n = self._structure
        return sp.csr_matrix((np.concatenate([K.data for K in mats]), indices, indptr), shape=(n, n))


class System:
    """The items of a case on one vector of unknowns (module docstring).

    ``bodies``: the body models (:class:`~cgfem.fem.body.BodyModel`); ``pairs``: contact
    pairs (:class:`~cgfem.contact.pair.ContactPair`) between them, by their index in
    ``bodies``; ``policy``: the solver's tuning (:class:`~cgfem.solve.policy.SolverPolicy`)."""

    def __init__(self, bodies: list, pairs: list | None = None, policy: SolverPolicy = DEFAULT_POLICY,
                 holds: dict[str, tuple[tuple[float, float, float], float]] | None = None):
        self.bodies = bodies
        self.policy = policy
        sizes = [b.n_dofs for b in bodies]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.body_items = [BodyItem(b, a) for b, a in zip(bodies, self.offsets[:-1])]
        self.contact = ContactSet(list(pairs or []), self.offsets)
        #: the springs holding bodies' spins: ``holds`` maps a body's name to its spin axis and
        #: Young's modulus (Pa) (``bodies.<name>.hold_spin``, :mod:`cgfem.solve.spin`)
        holds = holds or {}
        self.springs = [SpinSpring(b.name, int(a), b.space.coordinates, *holds[b.name], b.space.h,
                                   policy.spin_stiffness)
                        for b, a in zip(bodies, self.offsets[:-1]) if b.name in holds]
        #: the bodies held by contact alone, their tangent shift and step limit
        self.floating = FloatingBodies(self.offsets, [b.space.h for b in bodies],
                                       [b.space.coordinates for b in bodies], policy, self.order,
                                       held=frozenset(i for i, b in enumerate(bodies) if b.name in holds))
        if not self.contact:
            self.floating.bodies = []
        #: the contact-onset limit of a solve's first Newton step
        self.onset = OnsetLimit(self.contact, lambda: bool(self.floating.bodies), policy)
        self._stack = DiagonalStack(self.contact.n_extra)
        #: the bodies' stacked tangent and the body unknowns it was assembled at: it depends
        #: on nothing else (not the load factor, not the frozen stress), so an assembly at the
        #: same unknowns (a new outer pass from where the last one ended), or at any unknowns
        #: in small strain (bulk, ghost penalty and the weak conditions' penalty constant,
        #: with or without contact), reuses it
        self._bodies_tangent: tuple[np.ndarray, sp.csr_matrix] | None = None
        self._small_strain = not any(b.finite for b in bodies)

    def adopt(self, policy: SolverPolicy) -> None:
        """Use ``policy`` from now on, in the system and its collaborators (a run's fallback,
        :func:`~cgfem.solve.policy.fallback_policies`)."""
        self.policy = self.onset.policy = policy
        self.floating.adopt(policy)

    def saved(self) -> list:
        """What the solve has learnt beyond the unknowns (the contact pairs' states), for
        :meth:`restore`: a fallback starts a step again as the first attempt did."""
        return self.contact.saved()

    def restore(self, saved: list) -> None:
        """The state :meth:`saved` returned."""
        self.contact.restore(saved)

    @property
    def items(self) -> list:
        """Every item, in the order their residuals are summed: bodies, then contact."""
        return self.body_items + self.springs + (self.contact.items if self.contact else [])

    @property
    def linear(self) -> bool:
        """Small strain without contact: one tangent serves every iteration."""
        return self._small_strain and not self.contact

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
        """The bodies' displacements (views of ``u``)."""
        return [item.dofs(u) for item in self.body_items]

    def freeze(self, frozen_stress: list[np.ndarray | None]) -> None:
        """Hold every body's recovered stress at ``frozen_stress`` (one (n_nodes, 3, 3) array
        (Pa) or None per body) in the residuals and tangents that follow."""
        for item, s in zip(self.body_items, frozen_stress):
            item.frozen = s

    def assemble(self, u: np.ndarray, t: float, tangent: bool) -> tuple[np.ndarray, sp.csr_matrix | None]:
        """The residual (n_dofs,) (N) at ``u`` and load factor ``t``, the sum of every item's,
        and if asked the tangent (CSR, N/m): the bodies' blocks on the diagonal, the contact
        couplings off it, plus the floating bodies' shift (tangent only)."""
        at = u[:self.offsets[-1]]
        kept = self._bodies_tangent
        reuse = tangent and kept is not None and (self._small_strain or np.array_equal(kept[0], at))
        r = np.zeros(self.n_dofs)
        parts = [item.add(u, t, r, tangent and not reuse) for item in self.body_items]
        coupled = self.contact.parts(u, r, tangent) if self.contact else []
        coupled += [spring.add(u, t, r, tangent) for spring in self.springs]
        if not tangent:
            return r, None
        if reuse:
            K = kept[1]
        else:
            K = self._stack([p.K for p in parts if isinstance(p, Block)])
            self._bodies_tangent = (at.copy(), K)
            self.floating.detect([p.K for p in parts])
        if coupled:     # the contact's and the springs' entries, merged into K at once
            K = add_couplings(K, couplings_matrix(coupled, self.n_dofs))   # a new matrix: the shift may go into it
            K = self.floating.shifted(K, t, float(np.linalg.norm(r)), overwrite=True)
        return r, K

    def continuous_residual(self, u: np.ndarray, t: float) -> tuple[np.ndarray, int]:
        """The residual at ``u`` with every master hit on the continuous surface, in the
        element or triangle holding it (:meth:`~cgfem.contact.assembly.ContactSet.continuous`),
        and how many active hits lie on a kept piece's extension instead."""
        r = np.zeros(self.n_dofs)
        for item in self.body_items + self.springs:
            item.add(u, t, r, False)
        return r, self.contact.continuous(u, r)

    def limit(self, start: np.ndarray, du: np.ndarray, first: bool,
              solve: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
        """Newton's step ``du`` from ``start`` after the floating bodies' step limit (their
        rotations cut with ``solve``, a solve with the step's matrix, if given) and, on a
        solve's ``first`` step, the contact-onset limit."""
        du = self.floating.limit(du, solve)
        return self.onset.limit(start, du) if first else du

    def turned_floating(self, u: np.ndarray) -> str:
        """Why the state ``u`` is not a small-strain solution, empty if it is: a floating
        body (small strain, held at two or more places: where each pair holds it, or its
        point nearest the master where none is active) whose linearized rotation stretches a
        chord between those places (:func:`~cgfem.solve.floating.rotation_stretch`) by more
        than ``rotation_stretch`` of the chord's elastic stretch, more than the gaps at its
        ends (without the stretch they would close) and more than
        :data:`~cgfem.solve.floating.STRETCH_FLOOR_H` element sizes."""
        ratio = self.policy.rotation_stretch
        if not self.contact or not self.floating.bodies or not np.isfinite(ratio) \
                or any(b.finite for b in self.bodies):
            return ""
        held = self.contact.held_at(u)
        for i in self.floating.bodies:
            mine = [(x, g) for s, m, x, g in held if i in (s, m)]
            if len(mine) < 2:
                continue
            a, b = self.offsets[i], self.offsets[i + 1]
            body = self.bodies[i]
            turn, spurious, elastic, room = rotation_stretch(body.space, u[a:b], np.array([x for x, _ in mine]),
                                                             np.array([g for _, g in mine]))
            if spurious > max(ratio * elastic, room, STRETCH_FLOOR_H * body.space.h):
                return (f"{body.name} turned {turn:.3g} rad: its linearized rotation stretches it by "
                        f"{spurious:.3g} m between its contacts, elastically {elastic:.3g} m, with "
                        f"{room:.3g} m of gap (more than rotation_stretch = {ratio:g} of it: beyond small strain)")
        return ""

    def recover(self, u: np.ndarray) -> list[np.ndarray]:
        """Every body's nodal recovered stress (n_nodes, 3, 3) (Pa) at ``u``."""
        return [item.recover(u) for item in self.body_items]

    def load_norm(self, t: float) -> float:
        """``|t f_ext|`` of every body's dead loads (N)."""
        return float(t * np.sqrt(sum(np.dot(b.load, b.load) for b in self.bodies)))

    def force_scale(self, u: np.ndarray) -> float:
        """Norm of the bulk internal force at ``u`` (N): the size of the forces in play,
        against which Newton's residual is measured (it does not shrink with the increment)."""
        total = 0.0
        for item in self.body_items:
            f = item.internal_force(u)
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

    @property
    def order(self) -> int:
        """The highest element order of the bodies (1 trilinear, 2 triquadratic)."""
        return max(b.space.element.order for b in self.bodies)

    def held_by_contact_alone(self) -> bool:
        """Whether a body has no displacement conditions of its own (with contact: held by
        contact alone, every rigid motion free until contact closes)."""
        return bool(self.contact) and any(not b.dirichlet for b in self.bodies)

    def near_null(self) -> np.ndarray:
        """Rigid-body modes of every body, block by block (n_dofs, 6 n_bodies); zero on the
        contact set's own unknowns."""
        blocks = [rigid_body_modes(b.space.coordinates) for b in self.bodies]
        modes = sp.block_diag(blocks).toarray()
        return np.vstack([modes, np.zeros((self.contact.n_extra, modes.shape[1]))])

