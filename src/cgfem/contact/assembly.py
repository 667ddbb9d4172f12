"""Every contact pair of a case, on the stacked unknowns of the solver's system.

:class:`ContactSet` adds the pairs' residuals to the global residual and their tangents as
off-diagonal blocks (COO triplets on global dofs), freezes ``p_N`` for each pass of the
outer loop, and reports what the outer loop needs to decide that contact has settled: the
change of the frozen ``p_N`` and of the active set between passes.

With ``nurbs_fit`` the set also owns unknowns of its own, after the bodies' dofs: per fitted
patch (one per body and patch, shared by the pairs that use it) its control displacements
``Z`` and the multipliers ``mu`` of the fit constraint, with the constraint's equations
(:mod:`cgfem.contact.fitted`). A pair's kinematic vectors are then the ``Z`` of its fitted
surfaces instead of the bodies' dofs.
"""

from __future__ import annotations

import copy

import numpy as np
import scipy.sparse as sp

from cgfem.contact.fitted import FitBlock, FittedSurface
from cgfem.contact.pair import ContactPair, ContactPoints
from cgfem.contact.surfaces import FacetSurface, NurbsFeSurface
from cgfem.solve.items import Couplings


class PairItem:
    """One contact pair as an item of the system (:mod:`cgfem.solve.items`): its residual
    on the global unknowns ``slave`` and ``master`` (the kinematic vectors of its two sides:
    bodies' dofs, or the ``Z`` of fitted patches) and its tangent couplings between them. Its
    state (frozen ``p_N``, active set, pairing, held points) is the pair's own."""

    def __init__(self, pair: ContactPair, slave: np.ndarray, master: np.ndarray):
        self.pair, self.slave, self.master = pair, slave, master
        self._glob = np.concatenate([slave, master])

    def add(self, u: np.ndarray, t: float, r: np.ndarray, tangent: bool, update: bool = True
            ) -> Couplings | None:
        """Add the pair's residual (N) to ``r`` in place; its tangent couplings (N/m) if
        ``tangent``. Only linearization points (``tangent`` and ``update``) move the recorded
        pairing and active set: line-search trials must not count as active-set switches.
        The load factor ``t`` does not enter (contact carries no load of its own)."""
        r_s, r_m, trip = self.pair.assemble(u[self.slave], u[self.master], tangent, update and tangent)
        r[self.slave] += r_s
        r[self.master] += r_m
        if not tangent:
            return None
        if trip is None:
            return Couplings(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
        rr, cc, vv = trip
        return Couplings(self._glob[rr], self._glob[cc], vv)


class FitConstraintItem:
    """The fit constraints of ``nurbs_fit`` (:meth:`ContactSet._constraints`, linear in the
    unknowns: ``C u``) as an item of the system; stateless."""

    def __init__(self, C: sp.coo_matrix):
        self.C = C

    def add(self, u: np.ndarray, t: float, r: np.ndarray, tangent: bool, update: bool = True
            ) -> Couplings | None:
        r += self.C @ u
        return Couplings(self.C.row, self.C.col, self.C.data) if tangent else None


def couplings_matrix(parts: list[Couplings], n: int) -> sp.coo_matrix:
    """The (n, n) COO matrix of the entries of ``parts``, in their order (duplicates summed
    when converted)."""
    parts = [p for p in parts if p.values.size]
    if not parts:
        return sp.coo_matrix((n, n))
    return sp.coo_matrix((np.concatenate([p.values for p in parts]),
                          (np.concatenate([p.rows for p in parts]), np.concatenate([p.cols for p in parts]))),
                         shape=(n, n))


class ContactSet:
    """The contact pairs of a system whose body ``i`` owns dofs ``offsets[i]:offsets[i+1]``;
    the set's own unknowns (fitted patches) follow ``offsets[-1]``."""

    def __init__(self, pairs: list[ContactPair], offsets: np.ndarray):
        self.pairs = pairs
        self.offsets = np.asarray(offsets, np.int64)
        self.blocks: list[FitBlock] = []
        self._block_of: dict[tuple[int, int], FitBlock] = {}
        self._index = [(self._kinematic_index(p.slave_surface, p.slave),
                        self._kinematic_index(p.surface, p.master)) for p in pairs]
        self._constraint: sp.coo_matrix | None = None
        self._items: list | None = None

    def __bool__(self) -> bool:
        return bool(self.pairs)

    def saved(self) -> list:
        """A copy of every pair's state (its last pairing, statuses, held points and pieces,
        :class:`~cgfem.contact.pair.ContactState`), for :meth:`restore`."""
        return [copy.deepcopy(p.state) for p in self.pairs]

    def restore(self, states: list) -> None:
        """Every pair's state as :meth:`saved` copied it (the copy kept for a later restore)."""
        for pair, state in zip(self.pairs, states):
            pair.state = copy.deepcopy(state)

    @property
    def n_extra(self) -> int:
        """Unknowns the contact set owns beyond the bodies' dofs: ``Z`` and ``mu`` of every
        fitted patch."""
        return int(sum(2 * b.z.size for b in self.blocks))

    @property
    def symmetric(self) -> bool:
        """Small strain gives symmetric contact tangents, finite strain does not."""
        return not any(p.finite for p in self.pairs)

    def _kinematic_index(self, surface, body: int) -> np.ndarray:
        """Global indices of the vector a pair side moves with: the body's dofs, or the ``Z``
        of its fitted patches (blocks registered on first use)."""
        if not isinstance(surface, FittedSurface):
            return np.arange(self.offsets[body], self.offsets[body + 1])
        parts = []
        for fit in surface.fits:
            key = (surface.body, fit.patch)
            if key not in self._block_of:
                start = int(self.offsets[-1]) + self.n_extra
                size = 3 * fit.n_free
                self._block_of[key] = FitBlock(surface.body, fit, surface.scale, np.arange(start, start + size),
                                               np.arange(start + size, start + 2 * size))
                self.blocks.append(self._block_of[key])
            parts.append(self._block_of[key].z)
        return np.concatenate(parts)

    def _split(self, u: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The kinematic vectors of pair ``k``."""
        s, m = self._index[k]
        return u[s], u[m]

    def body(self, u: np.ndarray, i: int) -> np.ndarray:
        return u[self.offsets[i]:self.offsets[i + 1]]

    def begin_pass(self, increment: bool = True) -> None:
        """A new Newton solve: every pair's switch counts reset and held points released;
        with ``increment`` (the first pass of an increment) the held master pieces too."""
        for p in self.pairs:
            p.begin_pass(increment)

    def contradicted(self) -> int:
        """Held points (all pairs) whose own rule disagrees with the status they hold."""
        return sum(p.contradicted() for p in self.pairs)

    def contradicted_state(self) -> tuple:
        """Which held points contradict their rule and the status each holds, per pair
        (hashable, equal for equal states)."""
        return tuple((tuple(idx), tuple(p.state.held_active[idx]))
                     for p in self.pairs for idx in [p.contradicted_points()])

    def describe_contradicted(self, limit: int = 8) -> str:
        """The held points that contradict their rule, per pair: ``pair: points i, j (held
        active|inactive)``, at most ``limit`` indices per pair; empty if there are none."""
        parts = []
        for p in self.pairs:
            idx = p.contradicted_points()
            if idx.size:
                held = np.where(p.state.held_active[idx], "active", "inactive")
                listed = ", ".join(f"{i} ({h})" for i, h in zip(idx[:limit], held[:limit]))
                more = f" and {idx.size - limit} more" if idx.size > limit else ""
                parts.append(f"{p.name}: points {listed}{more}")
        return "; ".join(parts)

    def freeze(self, u: np.ndarray, recovered: list[np.ndarray | None]) -> None:
        """Freeze every pair's ``p_N`` from the slaves' recovered stress at ``u``."""
        for k, p in enumerate(self.pairs):
            p.freeze(self._split(u, k)[0], self.body(u, p.slave), recovered[p.slave])

    def frozen(self) -> list[np.ndarray]:
        return [p.state.p_N.copy() for p in self.pairs]

    def changes(self, limit: int = 8) -> str:
        """What the contact set did at the last linearization point, for a failure message:
        active points, and since the point before, status switches and active points whose
        master hit moved to another triangle or element, each named by pair and point index
        (at most ``limit`` per pair; a move with its pieces, ``patch/element`` or the
        triangle)."""
        active = sum(int(p.state.active.sum()) for p in self.pairs if p.state.active is not None)
        switched = sum(p.state.last_switched.size for p in self.pairs)
        moved = sum(p.state.last_moved.size for p in self.pairs)

        def piece(key) -> str:
            return f"{key[0]}" if key[1] < 0 else f"{key[0]}/{key[1]}"

        def named(lists) -> str:
            parts = []
            for p, items in zip(self.pairs, lists):
                if items:
                    more = f" and {len(items) - limit} more" if len(items) > limit else ""
                    parts.append(f"{p.name}: {', '.join(items[:limit])}{more}")
            return f" ({'; '.join(parts)})" if parts else ""

        which = named([[f"point {i}" for i in p.state.last_switched] for p in self.pairs])
        where = named([[f"point {i} from {piece(a)} to {piece(b)}" for i, (a, b) in
                        zip(p.state.last_moved, p.state.last_pieces)] for p in self.pairs])
        return (f"{active} active contact points; at the last iteration {switched} switched status{which} "
                f"and {moved} active ones moved to another master triangle or element{where}")

    def active(self) -> list[np.ndarray]:
        return [np.zeros(p.n_points, bool) if p.state.active is None else p.state.active.copy()
                for p in self.pairs]

    @property
    def items(self) -> list:
        """The set's items (:mod:`cgfem.solve.items`): one :class:`PairItem` per pair, then
        the :class:`FitConstraintItem` of the fitted patches if there are any."""
        if self._items is None:
            self._items = [PairItem(p, *self._index[k]) for k, p in enumerate(self.pairs)]
            if self.blocks:
                self._items.append(FitConstraintItem(self._constraints()))
        return self._items

    def add(self, u: np.ndarray, r: np.ndarray, tangent: bool, update: bool = True) -> sp.coo_matrix | None:
        """Add the contact residual (and the fit constraints' equations) to ``r`` (n,) in
        place; the tangent (COO on all n unknowns, :attr:`n_extra` included)."""
        parts = self.parts(u, r, tangent, update)
        return couplings_matrix(parts, r.size) if tangent else None

    def parts(self, u: np.ndarray, r: np.ndarray, tangent: bool, update: bool = True) -> list[Couplings]:
        """:meth:`add`'s residual, and its tangent as the items' entries (empty if not
        ``tangent``), for a caller that merges them with entries of its own."""
        parts = [item.add(u, 0.0, r, tangent, update) for item in self.items]
        return [p for p in parts if p is not None]

    def continuous(self, u: np.ndarray, r: np.ndarray) -> int:
        """Add to ``r`` (n,) in place the contact residual (and the fit constraints'
        equations) at ``u`` with every hit on the continuous surface: a NURBS+FE hit in the
        element holding it, a facet hit on the triangle the ray meets (a fresh search), not on
        the extension of the piece its pairing kept (:data:`~cgfem.contact._ray_kernels.STICKY`,
        ``HOLD_BAND``); the recorded pairing is left as it is. Returns how many active hits
        lay on such an extension."""
        kept = [p.state.hits for p in self.pairs]
        extended = 0
        try:
            for k, p in enumerate(self.pairs):
                if p.state.hits is None or not isinstance(p.surface, (NurbsFeSurface, FacetSurface)):
                    continue
                if isinstance(p.surface, NurbsFeSurface):
                    p.surface.polish = True
                    try:
                        hits = p.search(*self._split(u, k))[1]
                    finally:
                        p.surface.polish = False
                    moved = hits.slot != kept[k].slot
                else:
                    p.state.hits = None
                    hits = p.search(*self._split(u, k))[1]
                    moved = hits.piece != kept[k].piece
                if p.state.active is not None:
                    extended += int(np.sum(p.state.active & moved))
                p.state.hits = hits
            self.add(u, r, False)
        finally:
            for p, hits in zip(self.pairs, kept):
                p.state.hits = hits
        return extended

    def _constraints(self) -> sp.coo_matrix:
        """The fit constraints' part of the system, linear in the unknowns: per block
        ``-s G^T mu`` on the body's rows, ``s M mu`` on the ``Z`` rows and ``s (M Z - G u)``
        on the ``mu`` rows (``G``, ``M`` per displacement component)."""
        if self._constraint is None:
            n = int(self.offsets[-1]) + self.n_extra
            parts = []
            eye = sp.identity(3, format="csr")
            for b in self.blocks:
                G = sp.kron(b.fit.G, eye, format="coo")
                M = sp.kron(b.fit.M, eye, format="coo")
                body = int(self.offsets[b.body])
                for A, cols, sign in ((G, body + G.col, -1.0), (M, b.z[M.col], 1.0)):
                    # the mu rows, and their transposes on the body's and Z's rows
                    mu_rows = b.mu[A.row]
                    parts.append((mu_rows, cols, sign * b.scale * A.data))
                    parts.append((cols, mu_rows, sign * b.scale * A.data))
            r = np.concatenate([p[0] for p in parts])
            c = np.concatenate([p[1] for p in parts])
            v = np.concatenate([p[2] for p in parts])
            self._constraint = sp.coo_matrix((v, (r, c)), shape=(n, n))
        return self._constraint

    def fits(self, u: np.ndarray) -> list[tuple[FitBlock, np.ndarray]]:
        """Every fitted patch with its control displacements ``V = T Z`` (n_ctrl, 3) at ``u``."""
        return [(b, b.fit.T @ u[b.z].reshape(-1, 3)) for b in self.blocks]

    def held_at(self, u: np.ndarray) -> list[tuple[int, int, np.ndarray, float]]:
        """Per pair with master hits: its slave and master bodies, where it holds the slave
        (current position (3,)) and the gap there (m) (:meth:`ContactPair.held_point`)."""
        out = []
        for k, p in enumerate(self.pairs):
            held = p.held_point(self._split(u, k)[0])
            if held is not None:
                out.append((p.slave, p.master, *held))
        return out

    def gaps(self, u: np.ndarray) -> list[np.ndarray]:
        """Every pair's slave-point gaps at ``u`` (NaN: no master hit)."""
        return [p.gaps(*self._split(u, k)) for k, p in enumerate(self.pairs)]

    def points(self, u: np.ndarray) -> list[ContactPoints]:
        return [p.points(*self._split(u, k)) for k, p in enumerate(self.pairs)]


def active_changes(new: list[np.ndarray], old: list[np.ndarray]) -> int:
    """Number of slave points whose active status differs between two passes."""
    return int(sum(np.count_nonzero(a != b) for a, b in zip(new, old)))


def summary(points: list[ContactPoints], names: list[str]) -> dict:
    """The ``contact`` entry of a step in ``summary.json``: total force on the slaves (N),
    active points, the largest compressive pressure magnitude (Pa), and the same per pair."""
    pairs = {}
    for name, pts in zip(names, points):
        pairs[name] = {"force": pts.force.tolist(), "active_points": int(pts.active.sum()),
                       "max_pressure": float(np.max(-pts.pressure, initial=0.0))}
    total = np.sum([pts.force for pts in points], axis=0) if points else np.zeros(3)
    return {"force": np.asarray(total).tolist(),
            "active_points": int(sum(v["active_points"] for v in pairs.values())),
            "max_pressure": float(max([v["max_pressure"] for v in pairs.values()], default=0.0)),
            "pairs": pairs}
