"""Bodies held by contact alone: their detection, tangent shift and step limit.

A body whose own conditions leave a rigid motion free (chain3's middle link in all six, the
planar example's lower block in two) has a singular tangent until contact holds it, and
along a frictionless spin always. :class:`FloatingBodies` finds such bodies from their first
tangent, adds a fading diagonal shift to the matrix Newton solves (never to the residual, so
the converged state is that of the unstabilized equations), near a solution cuts the
rotation of such a body in a Newton step to ``floating_rotation`` by the step that minimizes
Newton's model under that turn (:func:`bound_rotation`), limits the step so that no node of
such a body moves more than ``floating_step`` element sizes nor turns it by more than about
``floating_turn`` radians, and adapts the shift to how often steps had to be limited
(Levenberg-Marquardt). In small strain it also checks a
converged state for a floating body turned so far that its linearized rotation, strain-free
but not length-preserving, stretches it between its contacts (:func:`rotation_stretch`).
Measurements and reasons: ``docs/methods/contact.md``, "Bodies held by contact alone".
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.sparse as sp

from cgfem.solve._sparse_kernels import diagonal_positions
from cgfem.solve.linear import rigid_body_modes
from cgfem.solve.policy import DEFAULT_POLICY, SolverPolicy

#: a turn's stretch below this many element sizes is not rejected, whatever the elastic
#: stretch (a floating body's drift under its tangent shift where nothing loads it; a slack
#: chain's stretch is 0.3 h and more)
STRETCH_FLOOR_H = 1e-3


def free_rigid_modes(coordinates: np.ndarray, K: sp.spmatrix, free_mode: float) -> int:
    """How many rigid motions a body's own tangent ``K`` (3 n, 3 n; its conditions included,
    no contact) leaves free: eigenvalues of ``P^T K P`` on the orthonormalized rigid modes
    ``P`` (3 n, 6) of its nodes ``coordinates`` (n, 3) below ``free_mode`` times the mean
    absolute diagonal of ``K``. A body without Dirichlet conditions has six; one held along x
    and y on one face only may keep a translation and a rotation free."""
    P, _ = np.linalg.qr(rigid_body_modes(coordinates))
    S = P.T @ (K @ P)
    scale = float(np.mean(np.abs(K.diagonal())))
    return int(np.sum(np.linalg.eigvalsh(0.5 * (S + S.T)) < free_mode * scale))


def rigid_fit_rows(coordinates: np.ndarray) -> np.ndarray:
    """The rows (6, 3 n) that map a body's nodal displacement (3 n,) at its nodes
    ``coordinates`` (n, 3) to its least-squares rigid motion, linearized
    ``u ~ t + omega x (X - c)`` with ``c`` the nodes' centroid: the translation ``t`` (m)
    from rows 0-2, the rotation vector ``omega`` (rad) from rows 3-5."""
    P = rigid_body_modes(coordinates)
    r = np.asarray(coordinates, float) - np.asarray(coordinates, float).mean(axis=0)
    scale = max(float(np.sqrt((r ** 2).sum(axis=1).mean())), np.finfo(float).tiny)
    rows = np.linalg.solve(P.T @ P, P.T)
    rows[3:] /= scale
    return rows


def rigid_fit(coordinates: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rigid motion nearest to a body's nodal displacement ``u`` (n, 3) at its nodes
    ``coordinates`` (n, 3) (:func:`rigid_fit_rows`): the translation ``t`` (3,) (m), the
    rotation vector ``omega`` (3,) (rad) and the centroid ``c`` (3,) (m) of the nodes."""
    a = rigid_fit_rows(coordinates) @ np.asarray(u, float).ravel()
    return a[:3], a[3:], np.asarray(coordinates, float).mean(axis=0)


def bound_rotation(du: np.ndarray, rows: np.ndarray, span: slice, largest: float,
                   solve: Callable[[np.ndarray], np.ndarray]) -> np.ndarray | None:
    """Newton's step ``du`` (n,) with the rotation ``omega = rows @ du[span]`` of one body cut
    to ``largest`` (rad): ``du - W (G^T W)^-1 (omega - omega_cut)``, ``G`` (n, 3) the ``rows``
    placed on ``span``, ``W = K^-1 G`` by ``solve`` (the step's matrix ``K``), ``omega_cut``
    ``omega`` scaled to ``largest``. For a symmetric ``K`` it minimizes the quadratic model
    ``du^T K du / 2 + r^T du`` among steps that turn the body by ``omega_cut``. None if the
    rotation is within ``largest`` or ``G^T W`` is singular."""
    omega = rows @ du[span]
    norm = float(np.linalg.norm(omega))
    if not norm > largest:
        return None
    G = np.zeros((du.size, 3))
    G[span] = rows.T
    W = np.column_stack([solve(G[:, k]) for k in range(3)])
    try:
        lam = np.linalg.solve(G.T @ W, omega * (1.0 - largest / norm))
    except np.linalg.LinAlgError:
        return None
    return du - W @ lam if np.all(np.isfinite(lam)) else None


def spurious_stretch(omega: np.ndarray, chord: np.ndarray) -> float:
    """How much longer a linearized rotation ``omega`` (3,) (rad) makes a chord ``chord`` (3,)
    (m) than the rotation itself would: ``|omega x d|^2 / (2 |d|)`` (m), the second-order term
    small strain drops (``X + omega x d`` has length ``|d| sqrt(1 + |omega x d|^2 / |d|^2)``)."""
    d = float(np.linalg.norm(chord))
    if not d > 0.0:
        return 0.0
    turned = np.cross(omega, chord)
    return float(np.dot(turned, turned) / (2.0 * d))


def rotation_stretch(space, u: np.ndarray, points: np.ndarray, gaps: np.ndarray | None = None
                     ) -> tuple[float, float, float, float]:
    """For a body (its FE ``space``, nodal displacement ``u`` (3 n,)) held at ``points`` (k, 3)
    (current positions, one per contact, k >= 2, with the ``gaps`` (k,) (m) there, 0 if
    None): its rigid rotation ``|omega|`` (rad, :func:`rigid_fit`), and for the chord between
    two points that the turn stretches most, that :func:`spurious_stretch` (m), the chord's
    elastic stretch, the change of its length by the displacement less the rigid motion (m),
    and the room its ends had, the sum of their gaps (m). A point in no active element of the
    body has no elastic displacement here."""
    U = np.asarray(u, float).reshape(-1, 3)
    t, omega, c = rigid_fit(space.coordinates, U)
    x = np.asarray(points, float)
    room = np.zeros(len(x)) if gaps is None else np.asarray(gaps, float)
    X = x - t - np.cross(omega, x - c)          # reference positions, to first order
    slots, xi = space.locate(X)
    elastic = np.zeros_like(X)
    inside = slots >= 0
    if inside.any():
        elastic[inside] = space.interpolate(U, slots[inside], xi[inside]) - t \
            - np.cross(omega, X[inside] - c)
    worst = stretch = gap = 0.0
    for a in range(len(X)):
        for b in range(a + 1, len(X)):
            d = X[b] - X[a]
            spurious = spurious_stretch(omega, d)
            if spurious >= worst:
                worst, gap = spurious, float(room[a] + room[b])
                stretch = abs(float(np.dot(d, elastic[b] - elastic[a]))) / max(float(np.linalg.norm(d)),
                                                                                np.finfo(float).tiny)
    return float(np.linalg.norm(omega)), worst, stretch, gap


def shift_factor(norm: float, largest: float, floor: float = DEFAULT_POLICY.shift_floor) -> float:
    """``norm / largest`` kept in ``[floor, 1]`` (1 if ``largest`` is not positive)."""
    if not largest > 0.0:
        return 1.0
    return float(min(1.0, max(norm / largest, floor)))


class FloatingBodies:
    """The tangent shift and step limit of the bodies of a system held by contact alone.

    ``offsets`` (n_bodies + 1,): body ``i`` owns unknowns ``offsets[i]:offsets[i+1]``;
    ``h`` (n_bodies,): element sizes (m); ``coordinates``: per body its nodes (n_i, 3) (m);
    ``order``: the elements' (rotations are cut from ``policy.rotation_cut_min_order`` on);
    ``held``: indices of bodies whose spin a spring holds (:mod:`cgfem.solve.spin`), whose
    rotation is never cut: the cut contains a free spin, and cutting the turns a held body
    still makes stalls Newton. Until :meth:`detect` has run, :attr:`bodies` is None.
    """

    def __init__(self, offsets: np.ndarray, h: list[float], coordinates: list[np.ndarray],
                 policy: SolverPolicy = DEFAULT_POLICY, order: int = 1, held: frozenset[int] = frozenset()):
        self.offsets = np.asarray(offsets, np.int64)
        self.h, self.coordinates, self.policy = list(h), coordinates, policy
        #: per body, the RMS distance of its nodes to their centroid (m)
        self.radius = [float(np.sqrt(((x - x.mean(axis=0)) ** 2).sum(axis=1).mean())) if len(x) else 0.0
                       for x in coordinates]
        #: indices of the floating bodies (None before :meth:`detect`)
        self.bodies: list[int] | None = None
        #: per body, the rigid motions its own conditions leave free
        self.free_modes: dict[int, int] = {}
        #: the shift's multiplier (:meth:`limit`), raised when a step had to be limited
        self.damping = 1.0
        #: per floating body, the norm of the force the shift put into the last Newton step (N)
        self.stabilizing: dict[int, float] = {}
        #: the shift's diagonal (n,) before its scale, and the rows where it is not zero
        self._shift: np.ndarray | None = None
        self._shifted_rows = np.zeros(0, np.int64)
        self._scale = 0.0
        self._fading = 1.0
        self._largest: tuple[float, float] | None = None
        #: the elements' order (:attr:`_cuts`), and per floating body its rotation rows
        #: (:func:`rigid_fit_rows`, built on first use)
        self._order = order
        self._rows: dict[int, np.ndarray] = {}
        self._held = frozenset(held)

    def adopt(self, policy: SolverPolicy) -> None:
        """Use ``policy`` from the next Newton step on (a run's fallback), its increment's
        shift and damping started afresh as in a new increment; the shift is taken again from
        the next tangent's diagonal where ``floating_shift`` changed."""
        if policy.floating_shift != self.policy.floating_shift:
            self._shift = None
        self._largest, self.damping, self.stabilizing = None, 1.0, {}
        self.policy = policy

    @property
    def _cuts(self) -> bool:
        """Whether :meth:`limit` cuts rotations (the elements' order and the policy's)."""
        p = self.policy
        return self._order >= p.rotation_cut_min_order and bool(np.isfinite(p.floating_rotation))

    def detect(self, tangents: list[sp.spmatrix]) -> list[int]:
        """Find the floating bodies from each body's own first tangent (once)."""
        if self.bodies is None:
            self.free_modes = {i: free_rigid_modes(x, K, self.policy.free_mode)
                               for i, (x, K) in enumerate(zip(self.coordinates, tangents))}
            self.bodies = [i for i, n in self.free_modes.items() if n]
        return self.bodies

    def shifted(self, K: sp.csr_matrix, t: float, norm: float, overwrite: bool = False) -> sp.csr_matrix:
        """``K`` plus the floating bodies' shift: ``floating_shift`` times the diagonal of the
        first tangent, times ``damping`` and the fading factor ``norm`` over the largest
        residual norm seen at load factor ``t`` (kept in ``[shift_floor, 1]``). ``K`` itself
        when no body floats. The fading lets Newton converge fast on a soft rigid mode of
        stiffness ``k``, corrected at the rate ``shift / (k + shift)`` per iteration.
        ``overwrite``: ``K`` is the caller's to change; where it holds the diagonal entry of
        every shifted row the shift is added to its values in place (the same numbers, without
        a copy of them)."""
        if not self.bodies:
            return K
        damping = self.damping      # a new increment's first tangent keeps the last damping
        if self._largest is None or self._largest[0] != t:
            self._largest = (t, norm)
            self.damping = 1.0
            self.stabilizing = {}
        self._largest = (t, max(self._largest[1], norm))
        self._fading = shift_factor(norm, self._largest[1], self.policy.shift_floor)
        self._scale = damping * self._fading
        if self._shift is None:
            d = np.zeros(K.shape[0])
            diag = K.diagonal()
            for i in self.bodies:
                a, b = self.offsets[i], self.offsets[i + 1]
                d[a:b] = self.policy.floating_shift * diag[a:b]
            self._shift, self._shifted_rows = d, np.flatnonzero(d)
        shift = self._scale * self._shift
        rows = self._shifted_rows
        at = diagonal_positions(K.indptr, K.indices, rows) if K.has_canonical_format else None
        if at is None or np.any(at < 0):
            return K + sp.diags(shift, format="csr")
        # the sum scipy forms, without its pass over every entry
        if overwrite:
            K.data[at] += shift[rows]
            return K
        data = K.data.copy()
        data[at] += shift[rows]
        return sp.csr_matrix((data, K.indices, K.indptr), shape=K.shape)

    def limit(self, du: np.ndarray, solve: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
        """The Newton step ``du``, first (elements of order ``rotation_cut_min_order`` or above,
        given ``solve``, a solve with the step's matrix, and with the residual below
        ``rotation_cut_below`` of the increment's largest) with each floating body's rotation
        cut to ``floating_rotation`` by :func:`bound_rotation` (not those whose spin is held), then
        scaled down (all of it: the bodies' equations are coupled)
        so that no node of a floating body moves by more than ``floating_step`` of its
        element size, nor more than ``floating_turn`` times its radius (:attr:`radius`: a
        turn of that many radians); ``du`` itself if none does. A step shortened to a
        fraction ``f`` while the residual is above ``damping_above`` of the increment's largest multiplies the
        shift of the next tangents by ``1 / f``; any other step by ``damping_decay``, within
        ``[1, damping_max]``. Records :attr:`stabilizing`."""
        p = self.policy
        if self._cuts and solve is not None and self._fading < p.rotation_cut_below:
            for i in self.bodies or ():
                if i in self._held:
                    continue
                if i not in self._rows:
                    self._rows[i] = rigid_fit_rows(self.coordinates[i])[3:]
                cut = bound_rotation(du, self._rows[i], slice(self.offsets[i], self.offsets[i + 1]),
                                     p.floating_rotation, solve)
                du = du if cut is None else cut
        factor = 1.0
        shift = None if not self.bodies else self._shift
        for i in self.bodies or ():
            a, b = self.offsets[i], self.offsets[i + 1]
            if shift is not None:
                self.stabilizing[i] = float(np.linalg.norm(self._scale * shift[a:b] * du[a:b]))
            move = float(np.abs(du[a:b]).max(initial=0.0))
            allowed = min(p.floating_step * self.h[i], p.floating_turn * self.radius[i])
            if move > allowed:
                factor = min(factor, allowed / move)
        raise_ = factor < 1.0 and self._fading >= p.damping_above
        self.damping = float(np.clip(self.damping / factor if raise_ else self.damping * p.damping_decay,
                                     1.0, p.damping_max))
        return du if factor == 1.0 else factor * du
