"""One contact pair: slave points, ray tracing onto the master, residual and tangent.

Stabilized Lagrangian with the condensed multiplier (paper eqs. 23-27). At every slave
quadrature point ``g`` (weight ``w``)

    lambda_N = p_N + eps g_N         if p_N + eps g_N <= 0   (active; compression < 0)
    lambda_N = 0                     otherwise,                eps = kappa E_slave / h_slave,

with ``p_N = n . sigma* . n`` the normal stress of the slave's recovered (SPR) Cauchy stress
at the point. The contact virtual work ``sum_g w lambda_N delta g_N`` enters the residual
``r = f_int - f_ext + sum_g w lambda_N g_{N,v}`` (a compressive ``lambda_N`` pushes the slave
away from the master), and the consistent tangent is

    K_c = sum_g w eps g_{,v} g_{,v}^T + w lambda_N g_{,vv} + lambda_N g_{,v} w_{,v}^T

(:mod:`cgfem.contact.kinematics`). In finite strain ``w`` is the current area of the slave
point (``lambda_N`` is a Cauchy traction) and the last term makes ``K_c`` non-symmetric; in
small strain ``w`` is the reference area and ``K_c`` is symmetric.

``p_N`` is frozen during a Newton solve, like the recovered stress of the weak Dirichlet
conditions: :meth:`ContactPair.freeze` computes it from ``sigma*`` and the current normal at
the start of each pass of the outer loop, which refreshes both.

The active set is re-evaluated at every residual evaluation (a semismooth Newton method);
a point counts as active up to ``p_N + eps g <= eps CLOSED_GAP_H h``, so surfaces that touch
initially (a gap of round-off size) start in contact. A point within round-off of that
threshold (:data:`TIE`) keeps its last status: the decision does not hinge on round-off.
Chattering protection: once a point has switched :data:`MAX_SWITCHES` times within one
Newton solve (one pass of the outer loop), its status is held as it is for the rest of that
solve, in the residual and the tangent alike (an active point keeps ``lambda_N = p_N + eps g``
whatever its sign), so Newton sees a smooth problem and converges. The held status may
contradict the point's own rule at the converged state; :meth:`ContactPair.contradicted`
counts such points, and the outer loop does not call contact settled while there are any:
its next pass releases every point and solves again from there.

A hit can chatter the same way between two master pieces (triangles, or NURBS+FE elements)
across the kink between them: where the equilibrium puts it on the kink, each piece's
Newton step carries it onto the other. Once an active point's hit has returned
:data:`MAX_RETURNS` times to the piece it had just left (A to B and back to A counts one;
a hit sliding on over A, B, C, ... counts none) within one increment, its piece is held: the search keeps it
while the ray meets it within :data:`~cgfem.contact._ray_kernels.HOLD_BAND` of its edges
(instead of ``STICKY``), on the piece's extension past the kink, for the rest of the
increment (every pass of its outer loop). What that changes is measured after the step on
the continuous surface (:meth:`~cgfem.contact.assembly.ContactSet.continuous`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from threadpoolctl import ThreadpoolController

from cgfem.contact import _ray_kernels as _rk
from cgfem.contact.kinematics import (SlaveFrames, SlaveState, area_weight, gap_derivatives,
                                      gap_gradient_direction, state_of)
from cgfem.contact.surfaces import FacetSurface, NurbsFeSurface, RayHits, surface_tree

#: slave points whose (D, D) tangents (D = 48 for NURBS+FE and facets with trilinear
#: elements, 162 with triquadratic ones) are formed at once at D = 48, and proportionally
#: fewer at larger D (memory: about 0.3 GB per chunk with the temporaries of the second
#: derivatives)
CHUNK_POINTS = 2048
#: the BLAS libraries loaded (numpy's and scipy's OpenBLAS): their thread count is held at one
#: around the tangent blocks' small matrix products (:func:`_group_blocks`), where threads
#: only contend
_BLAS = ThreadpoolController()
#: switches of one point's active status in one Newton solve before its status is held
MAX_SWITCHES = 10
#: returns of one active point's hit to the master piece it had just left, in one increment,
#: before its piece is held (:data:`~cgfem.contact._ray_kernels.HOLD_BAND`)
MAX_RETURNS = 3
#: largest |gap| searched, in element sizes: a point is active only while
#: p_N + (kappa E / h) g <= 0, i.e. for gaps below |p_N| h / (kappa E), far below h
MAX_GAP_H = 1.0
#: skin of the search's candidate list, in units of the largest gap searched
SKIN = 0.25
#: a gap below this fraction of h counts as closed when the active set is decided (initially
#: touching surfaces, round-off of the facet intersections); lambda_N itself is unchanged
CLOSED_GAP_H = 1e-9
#: the tie band of the active set: a point whose trial ``p_N + eps g`` lies within
#: ``TIE (|p_N| + eps h)`` of the threshold (a gap of 1e-12 h, a hundred times the
#: round-off of the examples' gaps) keeps the status it had at the last linearization point,
#: so that two runs differing by round-off decide it alike
TIE = 1e-12


@dataclass
class ContactState:
    """Per slave point: the frozen stabilizing stress ``p_N``, the last pairing, the last
    active status and the switch count of the increment."""

    p_N: np.ndarray
    hits: RayHits | None = None
    active: np.ndarray | None = None
    switches: np.ndarray | None = None
    #: points whose status is held (``held``) and the status they hold (``held_active``)
    held: np.ndarray | None = None
    held_active: np.ndarray | None = None
    #: the points' own rule at the last linearization point, held or not
    natural: np.ndarray | None = None
    #: the Verlet list of the search (:meth:`ContactPair.candidates`): the slave points, the
    #: master samples and the kinematic vectors it was built at
    candidates: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    #: per point, the piece its hit left at its last move (:func:`_master_key`; -1: none
    #: yet) and the returns to such a piece in this increment (:attr:`piece_held`)
    left: np.ndarray | None = None
    returns: np.ndarray | None = None
    #: what changed between the last two linearization points: the points that switched
    #: status, the active points whose hit moved to another master piece
    #: (:func:`_master_key`), and those moves' pieces before and after (k, 2, 2)
    last_switched: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    last_moved: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    last_pieces: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2), np.int64))

    @property
    def piece_held(self) -> np.ndarray | None:
        """(n,) the points whose master piece is held: :data:`MAX_RETURNS` returns in this
        increment (None before the first pass)."""
        return None if self.returns is None else self.returns >= MAX_RETURNS


@dataclass(frozen=True)
class ContactPoints:
    """Slave points of a pair in the current configuration (what ``contact_NNN.vtu`` shows).

    x (n, 3), normal (n, 3) slave normal, gap (n,) (NaN: no master hit), pressure (n,)
    lambda_N (Pa, negative in compression, 0 where inactive), active (n,) bool, weight (n,)
    area weight, p_N (n,) the frozen stabilizing stress, point_force (n, 3) the force the
    master exerts on the slave at the point, ``-w lambda_N q`` with ``q = dg/dx1`` (the
    master normal scaled by ``1 / (n2 . n1)``): along ``pressure * weight * normal`` when the
    surfaces are parallel, and exactly the force the residual applies in any case;
    displacement (n, 3) ``x`` minus the point's reference position
    """

    x: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    pressure: np.ndarray
    active: np.ndarray
    weight: np.ndarray
    p_N: np.ndarray
    point_force: np.ndarray
    displacement: np.ndarray

    @property
    def force(self) -> np.ndarray:
        """Force (3,) the master exerts on the slave (equal and opposite on the master)."""
        return self.point_force.sum(axis=0)


@dataclass
class ContactPair:
    """A slave body's points against a master body's surface.

    slave, master : index of the bodies in the system
    frames : slave point data; grad_N (n, n_nodes, 3) shape gradients at the slave points
    slave_surface : the slave side's surface when its points move with unknowns other than
        the slave body's dofs (``nurbs_fit``: a :class:`~cgfem.contact.fitted.FittedSurface`);
        None: they move with the body's FE field

    The kinematic vectors ``u_s``, ``u_m`` of :meth:`assemble` and :meth:`points` are the
    unknowns the slave points and the master surface move with: the bodies' dofs, or the
    fitted surfaces' control displacements (:class:`~cgfem.contact.assembly.ContactSet`
    gathers them).
    """

    name: str
    slave: int
    master: int
    slave_space: object
    master_space: object
    frames: SlaveFrames
    grad_N: np.ndarray
    surface: NurbsFeSurface | FacetSurface
    eps: float
    finite: bool
    max_gap: float
    slave_surface: object | None = None
    state: ContactState = field(init=False)

    def __post_init__(self) -> None:
        self.state = ContactState(np.zeros(self.frames.size))
        self._maps = None
        #: the last search and what it depended on (:meth:`search`)
        self._memo: _SearchMemo | None = None
        # (n, n_nodes) the slave's FE shape functions at its points, where :meth:`freeze`
        # reads the recovered stress: the points' own interpolation, or (a fitted surface)
        # the FE element's at the reference point
        self._stress_N = self.frames.phi if self.slave_surface is None else \
            self.slave_space.element.tabulate(_reference_xi(self.slave_space, self.frames), self.slave_space.h)[0]

    @property
    def n_points(self) -> int:
        return self.frames.size

    @property
    def _slave_lebesgue(self) -> float:
        """No slave point moves further than this times the largest move of its nodes."""
        return self.slave_space.element.lebesgue if self.slave_surface is None else self.slave_surface.lebesgue

    # -- kinematics ------------------------------------------------------------------------
    def _slave(self, u_s: np.ndarray) -> SlaveState:
        """The current geometry of every slave point from the kinematic vector ``u_s``: the
        sparse products of :meth:`_slave_maps`: ``x = X + phi . U1``, ``a = A + ca . U1``,
        ``b = B + cb . U1``."""
        if self._maps is None or self._maps[0].shape[1] != u_s.size // 3:
            self._maps = self._slave_maps(u_s.size // 3)
        U = u_s.reshape(-1, 3)
        f = self.frames
        return state_of(f.X + self._maps[0] @ U, f.A + self._maps[1] @ U, f.B + self._maps[2] @ U)

    def _slave_maps(self, n_nodes: int) -> tuple[sp.csr_matrix, ...]:
        """``phi``, ``ca`` and ``cb`` of the slave points as sparse (n_points, n_nodes) matrices
        (a point's repeated padding nodes summed, their coefficients being zero)."""
        nodes = self.frames.nodes
        k = nodes.shape[1]
        indptr = np.arange(0, k * nodes.shape[0] + 1, k)
        return tuple(sp.csr_matrix((c.ravel(), nodes.ravel(), indptr), shape=(nodes.shape[0], n_nodes))
                     for c in (self.frames.phi, self.frames.ca, self.frames.cb))

    def search(self, u_s: np.ndarray, u_m: np.ndarray) -> tuple:
        """Current slave geometry (:class:`SlaveState`) and its master hits (the previous
        pairing first), searched for the candidate points only (:meth:`candidates`).

        The last search's result is returned again, the same objects, where nothing it
        depends on has changed: the same kinematic vectors (equal values), the same
        recorded pairing (the same object: a pairing is replaced, never changed), Verlet
        list and polishing, and the same held pieces (equal values). The onset limit's gaps
        at a Newton step's end point are searched again by the residual there otherwise."""
        held = self.state.piece_held
        memo = self._memo
        if memo is not None and memo.matches(self, u_s, u_m, held):
            return memo.result
        st = self._slave(u_s)
        rows, near = self.candidates(u_s, u_m, st.x)
        previous = None if self.state.hits is None else self.state.hits.select(rows)
        band = None if held is None else np.where(held[rows], _rk.HOLD_BAND, _rk.STICKY)
        sub = self.surface.search(u_m, st.x[rows], st.n[rows], self.max_gap, previous, near, band)
        result = st, RayHits.scatter(sub, rows, self.n_points)
        self._memo = _SearchMemo(self, u_s, u_m, held, result)
        return result

    def candidates(self, u_s: np.ndarray, u_m: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A Verlet list of the search: the slave points (indices) that may have a master
        hit, those within ``reach = max_gap + radius + skin`` of one of the master's surface
        samples (:meth:`samples`, every surface point within ``radius`` of one) when the list
        was built, and the samples within ``reach`` of one of those points (the only seeds or
        triangles their rays can need); ``skin = SKIN * max_gap``. It is rebuilt once the
        slave points and the master surface may have moved towards each other by more than
        ``skin``: the largest nodal move of the slave's and of the master's kinematic vector,
        each times the Lebesgue constant of its interpolation (1 where points are convex
        combinations of their nodes: trilinear, barycentric and NURBS weights are
        non-negative; :attr:`~cgfem.fem.element.Hexahedron.lebesgue` for the triquadratic
        field). ``x`` (n, 3): the current slave points."""
        skin = SKIN * self.max_gap
        c = self.state.candidates
        if c is not None and c[2].shape == u_s.shape and c[3].shape == u_m.shape \
                and self._slave_lebesgue * _largest_move(u_s - c[2]) \
                + self.surface.lebesgue * _largest_move(u_m - c[3]) <= skin:
            return c[0], c[1]
        points, radius = self.surface.samples(u_m)
        reach = self.max_gap + radius + skin
        rows = near = np.zeros(0, np.int64)
        if points.shape[0] and x.shape[0]:
            rows = np.flatnonzero(surface_tree(points).query(x, distance_upper_bound=reach)[0] <= reach)
            if rows.size:
                near = np.flatnonzero(surface_tree(x[rows]).query(points, distance_upper_bound=reach)[0] <= reach)
        self.state.candidates = (rows, near, u_s.copy(), u_m.copy())
        return rows, near

    def freeze(self, u_s: np.ndarray, u_body: np.ndarray, recovered: np.ndarray | None) -> None:
        """Freeze ``p_N = n . sigma* . n`` at the slave points from the slave's recovered
        stress (nodal, (n_nodes, 3, 3): Cauchy in small strain, first Piola-Kirchhoff in
        finite strain) and the current normal (from the kinematic vector ``u_s``);
        ``u_body``: the slave body's dofs (its deformation gradient); ``None``: ``p_N = 0``
        (first pass)."""
        if recovered is None:
            self.state.p_N = np.zeros(self.n_points)
            return
        st = self._slave(u_s)
        conn = self.slave_space.connectivity[self.frames.slot]
        stress = np.einsum("pa,paij->pij", self._stress_N, recovered[conn])      # (n, 3, 3)
        if self.finite:
            U = u_body.reshape(-1, 3)[conn]
            F = np.eye(3) + np.einsum("pak,paj->pkj", U, self.grad_N)
            stress = np.einsum("pij,pkj->pik", stress, F) / np.linalg.det(F)[:, None, None]
        self.state.p_N = np.einsum("pi,pij,pj->p", st.n, stress, st.n)

    def begin_pass(self, increment: bool = True) -> None:
        """A new Newton solve: switch counts to zero, every held status released; with
        ``increment`` (its first pass) the held pieces too."""
        n = self.n_points
        self.state.switches = np.zeros(n, np.int64)
        self.state.held, self.state.held_active = np.zeros(n, bool), np.zeros(n, bool)
        if increment or self.state.returns is None:
            self.state.left = np.full((n, 2), -1, np.int64)
            self.state.returns = np.zeros(n, np.int64)

    def contradicted(self) -> int:
        """Held points whose own rule disagrees with the status they hold (last
        linearization point)."""
        return int(self.contradicted_points().size)

    def contradicted_points(self) -> np.ndarray:
        """Indices of the held points whose own rule disagrees with the status they hold
        (last linearization point), ascending."""
        st = self.state
        if st.held is None or st.natural is None:
            return np.zeros(0, np.int64)
        return np.flatnonzero(st.held & (st.natural != st.held_active))

    # -- residual and tangent --------------------------------------------------------------
    def assemble(self, u_s: np.ndarray, u_m: np.ndarray, tangent: bool, update: bool = True):
        """Residual contributions ``(r_s (n_s,), r_m (n_m,))`` and, if asked, the tangent as
        COO triplets ``(rows, cols, values)`` on the local dofs ``(slave dofs, master dofs
        + n_s)``. ``update``: record the pairing and active set (a Newton iterate)."""
        st, hits = self.search(u_s, u_m)
        lam, active, natural = self._multiplier(hits)
        if update:
            self._record(hits, active, natural)
        r_s = np.zeros(u_s.size)
        r_m = np.zeros(u_m.size)
        rows = np.flatnonzero(active)
        if tangent and rows.size:
            # points of one (slave element, master piece and element) group next to each
            # other, so that their blocks are summed within a chunk (:meth:`_add_points`)
            slot = hits.slot[rows] if hits.slot is not None else np.full(rows.size, -1, np.int64)
            rows = rows[np.lexsort((hits.piece[rows], slot, self.frames.slot[rows]))]
        n = u_s.size + u_m.size
        # points in chunks: each carries (D, D) blocks and their temporaries (a few kB at D = 48);
        # the triplets of several chunks are summed within each chunk (memory), and the
        # chunks' sums returned one after the other (the system sums them with the rest)
        d = 3 * (self.frames.phi.shape[1] + self.surface.width)
        per_chunk = max(64, CHUNK_POINTS * 48 ** 2 // d ** 2)
        chunks = [c for c in np.array_split(rows, max(1, -(-rows.size // per_chunk))) if c.size]
        parts = []
        for chunk in chunks:
            trip = self._add_points(chunk, st, hits, lam, u_s, u_m, tangent, r_s, r_m)
            if trip is not None and len(chunks) > 1:
                parts.append(sp.coo_matrix((trip[2], (trip[0], trip[1])), shape=(n, n)).tocsr().tocoo())
            elif trip is not None:
                return r_s, r_m, trip
        if not tangent:
            return r_s, r_m, None
        if not parts:
            return r_s, r_m, (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
        return r_s, r_m, (np.concatenate([p.row for p in parts]).astype(np.int64),
                          np.concatenate([p.col for p in parts]).astype(np.int64),
                          np.concatenate([p.data for p in parts]))

    def _add_points(self, rows, st, hits, lam, u_s, u_m, tangent, r_s, r_m) -> tuple | None:
        """Residual of the slave points ``rows`` added to ``r_s``, ``r_m``; their tangent (COO
        triplets ``(rows, cols, values)`` on the local dofs: slave dofs, then master dofs +
        ``u_s.size``; duplicates not summed) if asked."""
        frames = self.frames.select(rows)
        st_r = type(st)(*(getattr(st, f)[rows] for f in ("x", "a", "b", "m", "n", "norm_m")))
        mp = self.surface.evaluate(u_m, hits.piece[rows], hits.theta[rows], slot=_slots(hits, rows))
        d = gap_derivatives(frames, st_r, mp, hits.g[rows], self.finite, second=tangent)
        lam_r = lam[rows]
        dofs_s = node_dofs(frames.nodes)                                          # (k, 3 A)
        dofs_m = node_dofs(mp.nodes)                                              # (k, 3 B)
        s1 = dofs_s.shape[1]
        f = (d.w * lam_r)[:, None] * d.dg                                         # (k, D)
        np.add.at(r_s, dofs_s, f[:, :s1])
        np.add.at(r_m, dofs_m, f[:, s1:])
        if not tangent:
            return None
        # K_c = w eps dg dg^T + w lam g_vv + lam dg dw^T, from the factors of g_vv
        c = (d.w * lam_r)[:, None, None]
        u = np.concatenate([d.dg[:, None], d.u], axis=1)                          # (k, 7, D)
        v = np.concatenate([((d.w * self.eps)[:, None] * d.dg + lam_r[:, None] * d.dw)[:, None], c * d.v], axis=1)
        dofs = np.concatenate([dofs_s, dofs_m + u_s.size], axis=1)                # (k, D)
        dofs, K = _group_blocks(dofs, u, v, d.s, c * d.t)
        size = dofs.shape[1]
        rr = np.repeat(dofs, size, axis=1).ravel()
        cc = np.tile(dofs, (1, size)).ravel()
        return rr, cc, K.ravel()

    def _multiplier(self, hits: RayHits) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``lambda_N`` (n,), the status used (n,) (held points as held) and the points' own
        rule (n,)."""
        st, h = self.state, self.slave_space.h
        trial = np.where(hits.found, st.p_N + self.eps * np.where(hits.found, hits.g, 0.0), np.inf)
        threshold = self.eps * CLOSED_GAP_H * h
        natural = hits.found & (trial <= threshold)
        if st.active is not None:       # a tie keeps the last status (:data:`TIE`)
            tie = hits.found & (np.abs(trial - threshold) <= TIE * (np.abs(st.p_N) + self.eps * h))
            natural = np.where(tie, st.active, natural)
        active = natural if st.held is None else np.where(st.held, st.held_active & hits.found, natural)
        return np.where(active, trial, 0.0), active, natural

    def _record(self, hits: RayHits, active: np.ndarray, natural: np.ndarray) -> None:
        st = self.state
        if st.active is not None:
            switched = active != st.active
            # st.hits: the pairing recorded with st.active
            key, before = _master_key(hits), _master_key(st.hits)
            moved = active & st.active & np.any(key != before, axis=1)
            st.last_switched, st.last_moved = np.flatnonzero(switched), np.flatnonzero(moved)
            st.last_pieces = np.stack([before[moved], key[moved]], axis=1)
            if st.returns is not None:
                st.returns += moved & np.all(key == st.left, axis=1)
                st.left[moved] = before[moved]
            if st.switches is not None:
                st.switches += switched
                if st.held is not None:
                    hold = ~st.held & (st.switches >= MAX_SWITCHES)
                    st.held |= hold
                    st.held_active[hold] = active[hold]
        st.active, st.hits, st.natural = active, hits, natural

    def held_point(self, u_s: np.ndarray) -> tuple[np.ndarray, float] | None:
        """Where the pair holds its slave (current position (3,), from the kinematic vector
        ``u_s``) and the gap there (m): the mean of the points active at the last
        linearization point and 0, or if none is, the point nearest its master (least gap
        among those with a master hit) and its gap; None without hits."""
        st = self.state
        if st.active is None or st.hits is None or not st.hits.found.any():
            return None
        x = self._slave(u_s).x
        if st.active.any():
            return x[st.active].mean(axis=0), 0.0
        nearest = int(np.argmin(np.where(st.hits.found, st.hits.g, np.inf)))
        return x[nearest], max(float(st.hits.g[nearest]), 0.0)

    def gaps(self, u_s: np.ndarray, u_m: np.ndarray) -> np.ndarray:
        """Every slave point's gap at ``(u_s, u_m)`` (n,), NaN without a master hit; the
        active set and pairing are not recorded."""
        hits = self.search(u_s, u_m)[1]
        return np.where(hits.found, hits.g, np.nan)

    # -- outputs ---------------------------------------------------------------------------
    def points(self, u_s: np.ndarray, u_m: np.ndarray) -> ContactPoints:
        """The slave points at ``(u_s, u_m)`` with their gaps, pressures and weights."""
        st, hits = self.search(u_s, u_m)
        lam, active, _ = self._multiplier(hits)
        w = area_weight(self.frames, st.norm_m, self.finite)
        force = np.zeros((self.n_points, 3))
        rows = np.flatnonzero(active)
        if rows.size:
            t = self.surface.evaluate(u_m, hits.piece[rows], hits.theta[rows], second=False,
                                      slot=_slots(hits, rows)).t
            force[rows] = -(w[rows] * lam[rows])[:, None] * gap_gradient_direction(t, st.n[rows])
        return ContactPoints(st.x, st.n, np.where(hits.found, hits.g, np.nan), lam, active, w,
                             self.state.p_N.copy(), force, st.x - self.frames.X)


class _SearchMemo:
    """A pair's last search (:meth:`ContactPair.search`): its ``result`` and its inputs, the
    kinematic vectors and held pieces as copies, the pairing, Verlet list and polishing as
    they stood after it. It keeps about 170 bytes per slave point alive until the next
    search (the slave geometry and the hits), besides the two kinematic vectors."""

    def __init__(self, pair: ContactPair, u_s: np.ndarray, u_m: np.ndarray, held: np.ndarray | None,
                 result: tuple) -> None:
        self.u_s, self.u_m = u_s.copy(), u_m.copy()
        self.held = None if held is None else held.copy()
        self.hits, self.candidates = pair.state.hits, pair.state.candidates
        self.polish = getattr(pair.surface, "polish", False)
        self.result = result

    def matches(self, pair: ContactPair, u_s: np.ndarray, u_m: np.ndarray, held: np.ndarray | None) -> bool:
        """Whether a search of ``pair`` at ``(u_s, u_m)`` with the pieces ``held`` would
        repeat this one."""
        if pair.state.hits is not self.hits or pair.state.candidates is not self.candidates \
                or getattr(pair.surface, "polish", False) != self.polish:
            return False
        same_held = held is self.held or (held is not None and self.held is not None
                                          and np.array_equal(held, self.held))
        return same_held and np.array_equal(u_s, self.u_s) and np.array_equal(u_m, self.u_m)


def _group_blocks(dofs: np.ndarray, u: np.ndarray, v: np.ndarray, s: np.ndarray, t: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The tangent blocks ``sum_r u_r v_r^T + [[sum_r s_r t_r^T, 0], [0, 0]]`` of points
    (``u``, ``v`` (k, R, D), ``s``, ``t`` (k, R', S), S <= D) summed over the points of equal
    dof rows ``dofs`` (k, D): the distinct rows (g, D) and their blocks (g, D, D). Points of
    one slave element paired with one master element share their dofs (dozens per group with
    triquadratic elements): each group's block is one matrix product of its stacked factors,
    and the sparse assembly gets a block per group instead of one per point. Rows equal up
    to their order are not merged (they stay correct, only not summed)."""
    k, size = dofs.shape
    new = np.r_[True, np.any(dofs[1:] != dofs[:-1], axis=1)]
    if k > 1 and new.all():
        # not grouped by the caller's order: group by sorting
        inverse = np.unique(dofs, axis=0, return_inverse=True)[1].ravel()
        if inverse.max() + 1 < k:
            order = np.argsort(inverse, kind="stable")
            dofs, u, v, s, t = dofs[order], u[order], v[order], s[order], t[order]
            new = np.r_[True, np.any(dofs[1:] != dofs[:-1], axis=1)]
    starts = np.flatnonzero(new)
    ends = np.r_[starts[1:], k]
    S = s.shape[2]
    K = np.empty((starts.size, size, size))
    with _BLAS.limit(limits=1, user_api="blas"):
        for i, (a, b) in enumerate(zip(starts, ends)):
            K[i] = u[a:b].reshape(-1, size).T @ v[a:b].reshape(-1, size)
            K[i, :S, :S] += s[a:b].reshape(-1, S).T @ t[a:b].reshape(-1, S)
    return dofs[starts], K


def _largest_move(du: np.ndarray) -> float:
    """The largest nodal displacement norm of ``du`` (3 n,)."""
    return float(np.sqrt(np.max(np.sum(du.reshape(-1, 3) ** 2, axis=1), initial=0.0)))


def node_dofs(nodes: np.ndarray) -> np.ndarray:
    """Dofs (k, 3 A) of nodes (k, A), node-major: ``3 node + component``."""
    return (3 * nodes[:, :, None] + np.arange(3)).reshape(nodes.shape[0], -1)


def _master_key(hits: RayHits) -> np.ndarray:
    """Per hit (n, 2), the master piece it lies on: the triangle (facets), or the patch and
    the master element (NURBS+FE, whose surface is kinked at the elements' faces)."""
    slot = np.full(hits.piece.shape, -1, np.int64) if hits.slot is None else hits.slot
    return np.column_stack([hits.piece, slot])


def _slots(hits: RayHits, rows: np.ndarray) -> np.ndarray | None:
    """The master elements of hits ``rows`` as the search chose them (None if unrecorded)."""
    return None if hits.slot is None else hits.slot[rows]


def _reference_xi(space, frames: SlaveFrames) -> np.ndarray:
    """(n, 3) local coordinates of the slave points' reference positions in their elements."""
    return (frames.X - space.centres()[frames.slot]) / (0.5 * space.h)


def slave_gradients(space, frames: SlaveFrames) -> np.ndarray:
    """Shape gradients (n, n_nodes, 3) at the slave points (from their reference positions)."""
    return space.element.tabulate(_reference_xi(space, frames), space.h)[1]
