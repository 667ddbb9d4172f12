"""Contact surfaces of one body in the current configuration, per surface definition.

Both definitions put their points in the local form of :mod:`cgfem.contact.kinematics`:

- :class:`NurbsFeSurface` (``nurbs_fe``, eq. 16): ``x(theta) = Q(theta) + N(zeta(theta)) u``
  on the exact NURBS patches. ``zeta = (Q - X_e) / (h/2)`` in the grid element holding
  ``Q(theta)`` (eq. 6), so ``dzeta/dtheta = (2/h) Q_theta`` (eq. 7). The surface is C0 with
  kinks on the grid faces; which element a point belongs to changes as it moves.
- :class:`FacetSurface` (``facets``, eq. 11 on the displaced triangles): every marching-cubes
  triangle lies in one grid element; its vertices move with the FE field of that element and
  the current triangle is the flat one through the moved vertices, so the normal is constant
  on a triangle and the ray-triangle intersection is a 3x3 linear solve (the paper's
  "analytical solution"). ``theta`` are barycentric coordinates ``(l1, l2)``.

Master search (ray tracing, eq. 2) lives here too: from each slave point along its current
normal, both ways (the gap is signed), candidates are found with a k-d tree over the
current positions of dense samples of the master surface (its exact surface-rule points, or
triangle centroids), so one search costs O(n log n); each candidate is then solved exactly
(Newton on ``(xi, eta, g)`` for NURBS+FE, starting from the previous pairing when there is
one; closed form for facets). The nearest admissible hit (master normal opposing the slave
normal, ``|g| <= max_gap``) is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from cgfem.contact.kinematics import MasterPoints, SlaveFrames
from cgfem.embedding.partition import SurfaceQuadrature
from cgfem.fem.space import NODE_XI, Space, shape_functions
from cgfem.geometry.solid import Solid

#: Newton iterations of the NURBS+FE ray tracing (from a seed within about h of the hit it
#: converges quadratically in a few), and its tolerance (fraction of h)
MAX_RAY_NEWTON = 12
RAY_TOL = 1e-12
#: candidates (nearest seeds) tried per slave point
CANDIDATES = 4
#: barycentric tolerance of a facet hit
FACET_TOL = 1e-10


def shape_derivatives(xi: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H8 shape functions (n, 8), physical gradients (n, 8, 3) (:func:`shape_functions`) and
    physical second derivatives (n, 8, 3, 3) at local coordinates ``xi`` (n, 3) of a cube of
    size ``h``: ``d2N_a/dX_i dX_j = (2/h)^2 s_ai s_aj (1 + s_ak xi_k) / 8`` for ``i != j``
    (``k`` the third axis), zero on the diagonal."""
    xi = np.ascontiguousarray(xi, dtype=float)
    N, dN = shape_functions(xi, h)
    f = 1.0 + xi[:, None, :] * NODE_XI[None, :, :]                 # (n, 8, 3)
    s = NODE_XI * (2.0 / h)
    d2N = np.zeros(f.shape + (3,))
    for i, j, k in ((0, 1, 2), (0, 2, 1), (1, 2, 0)):
        d2N[..., i, j] = d2N[..., j, i] = s[None, :, i] * s[None, :, j] * f[..., k] / 8.0
    return N, dN, d2N


def element_values(space: Space, u: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """Nodal displacements (n, 8, 3) of active elements ``slots``."""
    return u.reshape(-1, 3)[space.connectivity[slots]]


def _locate(space: Space, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Active element (n,) and local coordinates (n, 3) of surface points ``x`` (n, 3);
    every point of the boundary lies in a cut element, so none may be missing."""
    slots, xi = space.locate(np.ascontiguousarray(x, dtype=float))
    if np.any(slots < 0):
        raise ValueError(f"{int(np.sum(slots < 0))} surface points outside the active elements")
    return slots, xi


@dataclass(frozen=True)
class RayHits:
    """Result of a search: ``found`` (n,) bool, ``piece`` (n,) patch or triangle, ``theta``
    (n, 2), ``g`` (n,) signed gap."""

    found: np.ndarray
    piece: np.ndarray
    theta: np.ndarray
    g: np.ndarray


class NurbsFeSurface:
    """NURBS+FE contact surface of a body (exact patches + the body's H8 displacement)."""

    definition = "nurbs_fe"

    def __init__(self, solid: Solid, space: Space, surface: SurfaceQuadrature, patches: np.ndarray):
        """``surface``: a dense exact surface rule of the body (seeds of the search);
        ``patches``: ids of the patches that may touch."""
        self.solid, self.space = solid, space
        self.patches = np.asarray(patches, np.int64)
        keep = np.isin(surface.patch, self.patches)
        self.seed_piece = surface.patch[keep]
        self.seed_theta = surface.uv[keep]
        self._seed_slot, self._seed_xi = _locate(space, surface.x[keep])
        self.h = space.h
        seeds = surface.x[keep]
        #: the largest distance from a seed to its nearest neighbour (about the distance from
        #: any surface point to its nearest seed)
        self.spacing = float(cKDTree(seeds).query(seeds, k=2)[0][:, 1].max()) if seeds.shape[0] > 1 else self.h

    # -- slave side ----------------------------------------------------------------------
    def slave_frames(self, rule: SurfaceQuadrature) -> SlaveFrames:
        """Slave data of the points of ``rule`` (exact surface points with ``patch``, ``uv``)."""
        n = rule.w.size
        A, B = np.empty((n, 3)), np.empty((n, 3))
        for pid in np.unique(rule.patch):
            rows = rule.patch == pid
            d = self.solid.patches[pid].surface.derivatives(rule.uv[rows], 1)
            A[rows], B[rows] = d[:, 1, 0], d[:, 0, 1]
        slots, xi = _locate(self.space, rule.x)
        N, dN, _ = shape_derivatives(xi, self.h)
        ca = np.einsum("paj,pj->pa", dN, A)
        cb = np.einsum("paj,pj->pa", dN, B)
        return SlaveFrames(slots, rule.x.copy(), A, B, N, ca, cb, rule.w.copy())

    # -- master side ---------------------------------------------------------------------
    def evaluate(self, u: np.ndarray, piece: np.ndarray, theta: np.ndarray, second: bool = True) -> MasterPoints:
        """The current master surface at ``(piece, theta)`` (n,), (n, 2); without
        ``second`` the second derivatives ``s`` are left zero (the search needs none)."""
        n = piece.size
        order = 2 if second else 1
        Q = np.zeros((n, 3, 3, 3))
        for pid in np.unique(piece):
            rows = piece == pid
            srf = self.solid.patches[pid].surface
            (u0, u1), (v0, v1) = srf.domain
            uv = np.column_stack([np.clip(theta[rows, 0], u0, u1), np.clip(theta[rows, 1], v0, v1)])
            Q[rows, :order + 1, :order + 1] = srf.derivatives(uv, order)
        X, Qt = Q[:, 0, 0], np.stack([Q[:, 1, 0], Q[:, 0, 1]], axis=1)
        slots, xi = _locate(self.space, X)
        N, dN, d2N = shape_derivatives(xi, self.h)
        U = element_values(self.space, u, np.maximum(slots, 0))
        psi = np.einsum("paj,pcj->pca", dN, Qt)                     # dN . Q_alpha  (n, 2, 8)
        x = X + np.einsum("pa,pak->pk", N, U)
        t = Qt + np.einsum("pca,pak->pck", psi, U)
        s = np.zeros((n, 2, 2, 3))
        if second:
            Qs = np.stack([np.stack([Q[:, 2, 0], Q[:, 1, 1]], 1), np.stack([Q[:, 1, 1], Q[:, 0, 2]], 1)], 1)
            coef = (np.einsum("pajl,pcj,pdl->pcda", d2N, Qt, Qt)
                    + np.einsum("paj,pcdj->pcda", dN, Qs))           # (n, 2, 2, 8)
            s = Qs + np.einsum("pcda,pak->pcdk", coef, U)
        m2 = np.cross(t[:, 0], t[:, 1])
        normal = m2 / np.linalg.norm(m2, axis=1)[:, None]
        return MasterPoints(x, t, s, N, psi, slots, normal)

    def search(self, u: np.ndarray, x1: np.ndarray, n1: np.ndarray, max_gap: float,
               previous: RayHits | None = None) -> RayHits:
        """Ray tracing from ``x1`` along ``n1`` (n, 3) to the current master surface."""
        n = x1.shape[0]
        best = RayHits(np.zeros(n, bool), np.zeros(n, np.int64), np.zeros((n, 2)), np.full(n, np.inf))
        seeds_x = self._seed_positions(u)
        tree = cKDTree(seeds_x)
        # the hit's nearest seed lies within the seeds' spacing of the ray: sample the ray
        # segment |g| <= max_gap at that spacing, keep the seeds nearest to the samples, and
        # start from those closest to the ray (none close: no hit possible)
        m = int(np.ceil(2.0 * max_gap / self.spacing)) + 1
        ts = np.linspace(-max_gap, max_gap, m)
        samples = x1[:, None, :] + ts[None, :, None] * n1[:, None, :]
        _, idx = tree.query(samples.reshape(-1, 3))
        idx = idx.reshape(n, m)
        v = seeds_x[idx] - x1[:, None, :]
        off_ray = np.linalg.norm(v - np.einsum("pjk,pk->pj", v, n1)[:, :, None] * n1[:, None, :], axis=2)
        order = np.argsort(off_ray, axis=1, kind="stable")
        near = np.take_along_axis(idx, order, axis=1)
        close = np.take_along_axis(off_ray, order, axis=1) <= 2.0 * self.spacing
        unresolved = close[:, 0].copy()
        if previous is not None and np.any(previous.found):
            # the previous pairing first: if it is still an admissible hit, it stays
            rows = np.flatnonzero(previous.found)
            self._try(u, x1, n1, max_gap, rows, previous.piece[rows], previous.theta[rows], best)
            unresolved &= ~best.found
        tried = np.full((n, 0), -1)
        for c in range(min(m, 4 * CANDIDATES)):
            rows = np.flatnonzero(unresolved & close[:, c] & np.all(tried != near[:, c:c + 1], axis=1))
            tried = np.concatenate([tried, near[:, c:c + 1]], axis=1)
            if rows.size == 0 or tried.shape[1] > CANDIDATES and not np.any(unresolved):
                continue
            seeds = near[rows, c]
            # further seeds matter: a patch may close on itself (a seam), where Newton from
            # one side stops at the domain's edge while the hit lies just across
            self._try(u, x1, n1, max_gap, rows, self.seed_piece[seeds], self.seed_theta[seeds], best)
            unresolved &= ~best.found
        return best

    def _try(self, u, x1, n1, max_gap, rows, piece, theta, best: RayHits) -> None:
        """Ray Newton for points ``rows`` from ``(piece, theta)``; admissible hits nearer
        than the best so far replace it (in place)."""
        ok, th, g = self._ray_newton(u, x1[rows], n1[rows], piece, theta.copy(), max_gap)
        admissible = ok & (np.abs(g) <= max_gap)
        if np.any(admissible):
            mp = self.evaluate(u, piece, th, second=False)
            admissible &= np.einsum("pk,pk->p", mp.normal, n1[rows]) < 0.0
        better = admissible & (np.abs(g) < np.abs(best.g[rows]) - 1e-14 * self.h)
        r = rows[better]
        best.found[r] = True
        best.piece[r] = piece[better]
        best.theta[r] = th[better]
        best.g[r] = g[better]

    def _seed_positions(self, u: np.ndarray) -> np.ndarray:
        N, _, _ = shape_derivatives(self._seed_xi, self.h)
        U = element_values(self.space, u, self._seed_slot)
        X = np.empty((self.seed_piece.size, 3))
        for pid in np.unique(self.seed_piece):
            rows = self.seed_piece == pid
            X[rows] = self.solid.patches[pid].surface.evaluate(self.seed_theta[rows])
        return X + np.einsum("pa,pak->pk", N, U)

    def _ray_newton(self, u, x1, n1, piece, theta, max_gap):
        """Newton on ``x2(theta) - x1 - g n1 = 0`` for ``(theta, g)``; converged (n,), theta, g."""
        n = x1.shape[0]
        g = np.zeros(n)
        ok = np.zeros(n, bool)
        active = np.arange(n)
        lo = np.array([[self.solid.patches[p].surface.domain[0][0], self.solid.patches[p].surface.domain[1][0]]
                       for p in range(len(self.solid.patches))])
        hi = np.array([[self.solid.patches[p].surface.domain[0][1], self.solid.patches[p].surface.domain[1][1]]
                       for p in range(len(self.solid.patches))])
        for _ in range(MAX_RAY_NEWTON):
            if active.size == 0:
                break
            mp = self.evaluate(u, piece[active], theta[active], second=False)
            F = mp.x - x1[active] - g[active, None] * n1[active]
            J = np.stack([mp.t[:, 0], mp.t[:, 1], -n1[active]], axis=2)
            det_ok = np.abs(np.linalg.det(J)) > 1e-300
            step = np.zeros((active.size, 3))
            step[det_ok] = -np.linalg.solve(J[det_ok], F[det_ok][..., None])[..., 0]
            done = np.linalg.norm(F, axis=1) <= RAY_TOL * self.h
            ok[active[done]] = True
            # a ray that runs far beyond the search distance is no hit from this start
            go = ~done & det_ok & (np.abs(g[active]) <= 4.0 * max_gap)
            idx = active[go]
            theta[idx] += step[go, :2]
            g[idx] += step[go, 2]
            pl, ph = lo[piece[idx]], hi[piece[idx]]
            # a step that leaves the patch's domain is cut back onto it; a point that stays
            # outside is no hit on this patch (a neighbouring patch's seed finds it)
            clipped = np.clip(theta[idx], pl, ph)
            stuck = np.all(clipped == theta[idx] - step[go, :2], axis=1) & np.any(clipped != theta[idx], axis=1)
            theta[idx] = clipped
            active = idx[~stuck]
        return ok, theta, g


class FacetSurface:
    """Linear-facet contact surface (marching-cubes triangles moved with the FE field)."""

    definition = "facets"

    def __init__(self, space: Space, triangles: np.ndarray, elements: np.ndarray, keep: np.ndarray):
        """``triangles`` (m, 3, 3) reference vertices (counterclockwise about the outward
        normal), ``elements`` (m,) their grid elements; ``keep`` (m,) bool: triangles of the
        candidate patches."""
        self.space, self.h = space, space.h
        self.triangles = np.asarray(triangles, float)
        self.slot = space.slot(np.asarray(elements, np.int64))
        if np.any(self.slot < 0):
            raise ValueError("facet triangle in an inactive element")
        centre = space.centres()[self.slot]
        xi = (self.triangles - centre[:, None, :]) / (0.5 * space.h)
        self.vertex_N = shape_derivatives(xi.reshape(-1, 3), space.h)[0].reshape(-1, 3, 8)
        self.candidates = np.flatnonzero(keep)

    def _coefficients(self, tri: np.ndarray, theta: np.ndarray):
        V, NV = self.triangles[tri], self.vertex_N[tri]
        l1, l2 = theta[:, 0:1], theta[:, 1:2]
        X = V[:, 0] + l1 * (V[:, 1] - V[:, 0]) + l2 * (V[:, 2] - V[:, 0])
        phi = NV[:, 0] + l1 * (NV[:, 1] - NV[:, 0]) + l2 * (NV[:, 2] - NV[:, 0])
        A, B = V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]
        return X, A, B, phi, NV[:, 1] - NV[:, 0], NV[:, 2] - NV[:, 0]

    def slave_frames(self, tri: np.ndarray, theta: np.ndarray, w: np.ndarray) -> SlaveFrames:
        """Slave data of points with barycentric ``theta`` (n, 2) in triangles ``tri`` (n,)."""
        X, A, B, phi, ca, cb = self._coefficients(tri, theta)
        return SlaveFrames(self.slot[tri], X, A, B, phi, ca, cb, np.asarray(w, float).copy())

    def evaluate(self, u: np.ndarray, piece: np.ndarray, theta: np.ndarray, second: bool = True) -> MasterPoints:
        """The current (flat) master triangles at ``(piece, theta)``; ``s`` is zero."""
        X, A, B, phi, ca, cb = self._coefficients(piece, theta)
        U = element_values(self.space, u, self.slot[piece])
        x = X + np.einsum("pa,pak->pk", phi, U)
        psi = np.stack([ca, cb], axis=1)
        t = np.stack([A, B], axis=1) + np.einsum("pca,pak->pck", psi, U)
        m2 = np.cross(t[:, 0], t[:, 1])
        normal = m2 / np.linalg.norm(m2, axis=1)[:, None]
        return MasterPoints(x, t, np.zeros((piece.size, 2, 2, 3)), phi, psi, self.slot[piece], normal)

    def search(self, u: np.ndarray, x1: np.ndarray, n1: np.ndarray, max_gap: float,
               previous: RayHits | None = None) -> RayHits:
        n = x1.shape[0]
        cand = self.candidates
        U = u.reshape(-1, 3)[self.space.connectivity[self.slot[cand]]]          # (m, 8, 3)
        verts = self.triangles[cand] + np.einsum("mva,mak->mvk", self.vertex_N[cand], U)
        centroid = verts.mean(axis=1)
        radius = np.linalg.norm(verts - centroid[:, None], axis=2).max()
        tree = cKDTree(centroid)
        best = RayHits(np.zeros(n, bool), np.zeros(n, np.int64), np.zeros((n, 2)), np.full(n, np.inf))
        pairs = tree.query_ball_point(x1, r=max_gap + radius)
        rows = np.repeat(np.arange(n), [len(p) for p in pairs])
        if rows.size == 0:
            return best
        tris = np.concatenate([np.asarray(p, np.int64) for p in pairs if len(p)])
        v = verts[tris]
        e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
        J = np.stack([e1, e2, -n1[rows]], axis=2)
        det = np.linalg.det(J)
        good = np.abs(det) > 1e-30 * self.h ** 2
        sol = np.full((rows.size, 3), np.nan)
        sol[good] = np.linalg.solve(J[good], (x1[rows] - v[:, 0])[good][..., None])[..., 0]
        l1, l2, g = sol[:, 0], sol[:, 1], sol[:, 2]
        inside = good & (l1 >= -FACET_TOL) & (l2 >= -FACET_TOL) & (l1 + l2 <= 1.0 + FACET_TOL)
        normal = np.cross(e1, e2)
        inside &= (np.einsum("pk,pk->p", normal, n1[rows]) < 0.0) & (np.abs(g) <= max_gap)
        hit = np.flatnonzero(inside)
        order = hit[np.lexsort((np.abs(g[hit]), rows[hit]))]
        first = order[np.concatenate([[True], rows[order][1:] != rows[order][:-1]])] if order.size else order
        r = rows[first]
        best.found[r] = True
        best.piece[r] = cand[tris[first]]
        best.theta[r] = np.column_stack([l1[first], l2[first]])
        best.g[r] = g[first]
        return best
