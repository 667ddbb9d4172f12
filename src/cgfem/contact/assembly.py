"""Every contact pair of a case, on the stacked unknowns of the solver's system.

:class:`ContactSet` adds the pairs' residuals to the global residual and their tangents as
off-diagonal blocks (COO triplets on global dofs), freezes ``p_N`` for each pass of the
outer loop, and reports what the outer loop needs to decide that contact has settled: the
change of the frozen ``p_N`` and of the active set between passes.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from cgfem.contact.pair import ContactPair, ContactPoints


class ContactSet:
    """The contact pairs of a system whose body ``i`` owns dofs ``offsets[i]:offsets[i+1]``."""

    def __init__(self, pairs: list[ContactPair], offsets: np.ndarray):
        self.pairs = pairs
        self.offsets = np.asarray(offsets, np.int64)

    def __bool__(self) -> bool:
        return bool(self.pairs)

    @property
    def n_extra(self) -> int:
        """Unknowns the contact set owns beyond the bodies' dofs (none yet)."""
        return 0

    @property
    def symmetric(self) -> bool:
        """Small strain gives symmetric contact tangents, finite strain does not."""
        return not any(p.finite for p in self.pairs)

    def _split(self, u: np.ndarray, pair: ContactPair) -> tuple[np.ndarray, np.ndarray]:
        o = self.offsets
        return u[o[pair.slave]:o[pair.slave + 1]], u[o[pair.master]:o[pair.master + 1]]

    def begin_pass(self) -> None:
        """A new Newton solve: every pair's switch counts reset and held points released."""
        for p in self.pairs:
            p.begin_pass()

    def contradicted(self) -> int:
        """Held points (all pairs) whose own rule disagrees with the status they hold."""
        return sum(p.contradicted() for p in self.pairs)

    def freeze(self, u: np.ndarray, recovered: list[np.ndarray | None]) -> None:
        """Freeze every pair's ``p_N`` from the slaves' recovered stress at ``u``."""
        for p in self.pairs:
            us = self._split(u, p)[0]
            p.freeze(us, us, recovered[p.slave])

    def frozen(self) -> list[np.ndarray]:
        return [p.state.p_N.copy() for p in self.pairs]

    def active(self) -> list[np.ndarray]:
        return [np.zeros(p.n_points, bool) if p.state.active is None else p.state.active.copy()
                for p in self.pairs]

    def add(self, u: np.ndarray, r: np.ndarray, tangent: bool, update: bool = True) -> sp.coo_matrix | None:
        """Add the contact residual to ``r`` (n_dofs,) in place; the tangent (COO, global)."""
        rows, cols, vals = [], [], []
        o = self.offsets
        for p in self.pairs:
            us, um = self._split(u, p)
            # only linearization points (tangent evaluations) move the recorded pairing and
            # active set: line-search trials must not count as active-set switches
            r_s, r_m, trip = p.assemble(us, um, tangent, update and tangent)
            r[o[p.slave]:o[p.slave + 1]] += r_s
            r[o[p.master]:o[p.master + 1]] += r_m
            if trip is not None:
                rr, cc, vv = trip
                glob = np.concatenate([np.arange(us.size) + o[p.slave], np.arange(um.size) + o[p.master]])
                rows.append(glob[rr])
                cols.append(glob[cc])
                vals.append(vv)
        if not tangent:
            return None
        n = int(o[-1])
        if not rows:
            return sp.coo_matrix((n, n))
        return sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))

    def points(self, u: np.ndarray) -> list[ContactPoints]:
        return [p.points(*self._split(u, p)) for p in self.pairs]


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
