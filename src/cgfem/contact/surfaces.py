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
(closed form for facets, the nearest admissible hit kept, the previous pairing's triangle
first while the ray meets its plane within ``STICKY`` of its edges; for NURBS+FE a Newton solve on
``(xi, eta, g)`` per start in the numba kernel :mod:`cgfem.contact._ray_kernels`, the previous
pairing first when there is one, the first admissible hit kept). Admissible: the master
normal opposes the slave normal and ``|g| <= max_gap``. A search given no candidate seeds
(``near``) first skips the rays whose segment cannot reach the master's element boxes
(:meth:`NurbsFeSurface._may_hit`); a contact pair always gives them (its Verlet list,
:meth:`cgfem.contact.pair.ContactPair.candidates`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy.spatial import cKDTree

from cgfem.contact import _ray_kernels as _rk
from cgfem.contact import _seed_kernels as _sk
from cgfem.contact._facet_kernels import triangle_hits
from cgfem.contact.kinematics import MasterPoints, SlaveFrames
from cgfem.embedding.partition import SurfaceQuadrature
from cgfem.fem.space import LOCATE_TOL, Space
from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.solid import Solid

#: Newton iterations of the NURBS+FE ray tracing (from a seed within about h of the hit it
#: converges quadratically in a few), and its tolerance (fraction of h)
MAX_RAY_NEWTON = 12
RAY_TOL = 1e-12
#: the nearest seed of a sample of a ray's segment counts only within this many seed
#: spacings of it (:meth:`RaySurface._starts`)
SAMPLE_REACH = 2.5
#: candidates (nearest seeds) tried per slave point
CANDIDATES = 4
#: barycentric tolerance of a facet hit
FACET_TOL = 1e-10
#: facet hits of one ray whose gaps differ by less than this fraction of h are a tie
#: (:meth:`FacetSurface._take`)
TIE = 1e-12


def element_values(space: Space, u: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """Nodal displacements (n, n_nodes, 3) of active elements ``slots``."""
    return u.reshape(-1, 3)[space.connectivity[slots]]


def surface_tree(points: np.ndarray) -> cKDTree:
    """A k-d tree of points (m, 3) on a surface, with sliding-midpoint splits and nodes not
    shrunk to their points: queried from off the surface (bounded nearest-point queries) it
    answers several times faster than scipy's default median splits (the Verlet list of
    :meth:`cgfem.contact.pair.ContactPair.candidates` on chain3's order-2 master: 0.02 s
    against 0.26 s), with the same distances."""
    return cKDTree(points, leafsize=32, balanced_tree=False, compact_nodes=False)


def pairs_within(x: np.ndarray, tree: cKDTree, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of a point ``x[i]`` (n, 3) and a point ``j`` of ``tree`` at most ``reach``
    apart, as two index arrays (m,) ``(i, j)``, in no particular order (callers must not
    depend on it): the dual-tree traversal of ``sparse_distance_matrix``, without a Python
    list per point."""
    found = surface_tree(x).sparse_distance_matrix(tree, reach, output_type="ndarray")
    return found["i"].astype(np.int64), found["j"].astype(np.int64)


def locate_points(space: Space, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Active element (n,) and local coordinates (n, 3) of surface points ``x`` (n, 3);
    every point of the boundary lies in a cut element, so none may be missing."""
    slots, xi = space.locate(np.ascontiguousarray(x, dtype=float))
    if np.any(slots < 0):
        raise ValueError(f"{int(np.sum(slots < 0))} surface points outside the active elements")
    return slots, xi


def closed_directions(surface: NurbsSurface, samples: int = 9) -> tuple[bool, bool]:
    """Whether the patch closes on itself along u and along v (a seam: its two boundary
    iso-curves of that direction coincide, to 1e-12 of its size), as a revolved surface does
    along its turn. A ray Newton step across a seam wraps around instead of stopping there."""
    (u0, u1), (v0, v1) = surface.domain
    s = np.linspace(0.0, 1.0, samples)
    lo, hi = surface.bounding_box()
    size = float(np.max(hi - lo))
    along_v, along_u = v0 + s * (v1 - v0), u0 + s * (u1 - u0)
    closed = []
    for a, b in ((np.column_stack([np.full(samples, u0), along_v]), np.column_stack([np.full(samples, u1), along_v])),
                 (np.column_stack([along_u, np.full(samples, v0)]), np.column_stack([along_u, np.full(samples, v1)]))):
        gap = np.linalg.norm(surface.evaluate(a) - surface.evaluate(b), axis=-1).max()
        closed.append(bool(gap <= 1e-12 * size))
    return closed[0], closed[1]


def pack_patches(surfaces: list[NurbsSurface]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """NURBS patches as the flat arrays of :mod:`cgfem.contact._ray_kernels`: ``layout``
    (n_patches, 8) rows ``(p, q, n_u, n_v, knot offset, control offset, closed along u,
    closed along v)`` (:func:`closed_directions`), ``knots`` (each patch's ``knots_u`` then
    ``knots_v``) and ``control`` (the homogeneous nets, raveled), both read-only."""
    layout = np.zeros((len(surfaces), 8), np.int64)
    ko = co = 0
    for k, s in enumerate(surfaces):
        nu, nv = s.control.shape[:2]
        layout[k] = (*s.degree, nu, nv, ko, co, *closed_directions(s))
        ko += s.knots_u.size + s.knots_v.size
        co += s.control.size
    knots = np.concatenate([np.concatenate([s.knots_u, s.knots_v]) for s in surfaces])
    control = np.concatenate([s.control.ravel() for s in surfaces])
    # read-only, as the patches' own arrays: the NURBS kernels the ray search shares with
    # the geometry are then compiled once, not once per flag
    knots.setflags(write=False)
    control.setflags(write=False)
    return layout, knots, control


def _segment_meets_box(d: np.ndarray, n: np.ndarray, c: np.ndarray, w: np.ndarray, length: float) -> np.ndarray:
    """(k,) bool: the segment ``d + g n``, ``|g| <= length`` ((k, 3) each) meets the box of
    centre ``c`` and half-widths ``w`` ((k, 3) or (1, 3)): slab test, a segment parallel to a
    slab being in it entirely or not at all."""
    inside = np.abs(d - c) <= w                                         # per axis
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (c - w - d) / n, (c + w - d) / n
    enter = np.where(n == 0.0, np.where(inside, -np.inf, np.inf), np.minimum(a, b)).max(axis=1)
    leave = np.where(n == 0.0, np.where(inside, np.inf, -np.inf), np.maximum(a, b)).min(axis=1)
    return np.maximum(enter, -length) <= np.minimum(leave, length)


@dataclass(frozen=True)
class RayHits:
    """Result of a search: ``found`` (n,) bool, ``piece`` (n,) patch or triangle, ``theta``
    (n, 2), ``g`` (n,) signed gap, ``slot`` (n,) the master element of each hit (-1: none;
    ``None``: not recorded)."""

    found: np.ndarray
    piece: np.ndarray
    theta: np.ndarray
    g: np.ndarray
    slot: np.ndarray | None = None

    def select(self, rows: np.ndarray) -> "RayHits":
        """The hits of rays ``rows``."""
        return RayHits(self.found[rows], self.piece[rows], self.theta[rows], self.g[rows],
                       None if self.slot is None else self.slot[rows])

    @classmethod
    def scatter(cls, sub: "RayHits", rows: np.ndarray, n: int) -> "RayHits":
        """Hits of ``n`` rays: ``sub`` at rays ``rows``, none elsewhere."""
        out = cls(np.zeros(n, bool), np.zeros(n, np.int64), np.zeros((n, 2)), np.full(n, np.inf),
                  np.full(n, -1, np.int64))
        out.found[rows], out.piece[rows], out.theta[rows], out.g[rows] = sub.found, sub.piece, sub.theta, sub.g
        if sub.slot is not None:
            out.slot[rows] = sub.slot
        return out


class RaySurface:
    """Ray tracing onto NURBS patches moved by a field (the shared part of
    :class:`NurbsFeSurface` and :class:`~cgfem.contact.fitted.FittedSurface`).

    A subclass sets ``seed_piece`` (n_seeds,) and ``seed_theta`` (n_seeds, 2) (its patches in
    the numbering of its packed ``_layout``, ``_knots``), how the seeds move (``_seed_X``
    (n_seeds, 3) their reference positions, ``_seed_coef`` and ``_seed_nodes`` (n_seeds, w)
    the basis and nodes each moves with, :func:`~cgfem.contact._seed_kernels.moved_seeds`),
    ``spacing`` (the largest distance from a seed to its nearest neighbour) and ``h``, and
    implements :meth:`_may_hit` and :meth:`_kernel_data`.
    """

    seed_piece: np.ndarray
    seed_theta: np.ndarray
    spacing: float
    h: float
    _layout: np.ndarray
    #: polish every hit onto the element holding it (the continuous surface, no STICKY
    #: extension; :func:`cgfem.contact._ray_kernels.trace`)
    polish: bool = False
    _knots: np.ndarray

    _seed_X: np.ndarray
    _seed_coef: np.ndarray
    _seed_nodes: np.ndarray

    def _seed_positions(self, u: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Current positions (n_seeds, 3) of the seeds (of seeds ``rows`` only) at the
        unknowns ``u`` (3 per node)."""
        rows = np.arange(self._seed_X.shape[0]) if rows is None else np.asarray(rows, np.int64)
        out = np.empty((rows.size, 3))
        _sk.moved_seeds(self._seed_X, self._seed_coef, self._seed_nodes, rows,
                        np.ascontiguousarray(u, dtype=float).reshape(-1, 3), out)
        return out

    def _may_hit(self, u: np.ndarray, x1: np.ndarray, max_gap: float, n1: np.ndarray) -> np.ndarray:
        """(n,) bool: the ray segments may meet the surface (False: skip them)."""
        raise NotImplementedError

    def _kernel_data(self, u: np.ndarray) -> tuple:
        """Arguments of :func:`cgfem.contact._ray_kernels.trace` at ``u``: ``(control, origin,
        h, shape, elements, connectivity, nodal displacements, ray_tol)``."""
        raise NotImplementedError

    def samples(self, u: np.ndarray) -> tuple[np.ndarray, float]:
        """Points (m, 3) of the current surface and a radius: every surface point lies within
        the radius of one of them (the seeds, twice their spacing)."""
        return self._seed_positions(u), 2.0 * self.spacing

    def search(self, u: np.ndarray, x1: np.ndarray, n1: np.ndarray, max_gap: float,
               previous: RayHits | None = None, near: np.ndarray | None = None,
               band: np.ndarray | None = None) -> RayHits:
        """Ray tracing from ``x1`` along ``n1`` (n, 3) to the current master surface, the
        segment ``|g| <= max_gap`` of each ray. Starts, in order: the previous pairing (if
        found; tried alone first, the seeds are looked up only for the rays it does not
        pair), then the seeds nearest to samples of the segment taken at the seeds' spacing,
        nearest to the ray first (those within twice the spacing of it, each seed once, from
        the first ``4 CANDIDATES`` samples' seeds); a ray no seed lies near has none. The first
        admissible hit of a point is kept (:func:`cgfem.contact._ray_kernels.trace`).
        ``near``: the seeds (indices of :meth:`samples`) that may start a ray (every seed
        within reach of the rays; default all, and then rays out of reach of the master's
        element boxes are skipped first, :meth:`_may_hit`). ``band`` (n,): how far past its
        faces the previous pairing's element is kept (default :data:`~._ray_kernels.STICKY`)."""
        n = x1.shape[0]
        band = np.full(n, _rk.STICKY) if band is None else np.asarray(band, float)
        best = RayHits(np.zeros(n, bool), np.zeros(n, np.int64), np.zeros((n, 2)), np.full(n, np.inf),
                       np.full(n, -1, np.int64))
        todo = np.arange(n)
        if previous is not None and previous.found.any():
            # the previous pairing alone first: from the second Newton iterate on it is
            # almost always the hit, and the seeds are then needed only for the rest
            rows = np.flatnonzero(previous.found)
            before = previous.slot[rows] if previous.slot is not None else np.full(rows.size, -1, np.int64)
            self._trace(u, x1, n1, rows, previous.piece[rows][:, None], previous.theta[rows][:, None],
                        before[:, None], band[rows], max_gap, best)
            todo = np.flatnonzero(~best.found)
        if near is None and todo.size:
            rows = todo[self._may_hit(u, x1[todo], max_gap, n1[todo])]
        else:
            rows = todo if near is None or near.size else todo[:0]
        if rows.size:
            piece, theta = self._starts(u, np.ascontiguousarray(x1[rows], dtype=float),
                                        np.ascontiguousarray(n1[rows], dtype=float), max_gap, near)
            self._trace(u, x1, n1, rows, piece, theta, np.full(piece.shape, -1, np.int64), band[rows], max_gap,
                        best)
        return best

    def _trace(self, u: np.ndarray, x1: np.ndarray, n1: np.ndarray, rows: np.ndarray, piece: np.ndarray,
               theta: np.ndarray, start_slot: np.ndarray, band: np.ndarray, max_gap: float,
               best: RayHits) -> None:
        """Newton from the starts ``piece`` (k, c), ``theta`` (k, c, 2), ``start_slot`` (k, c)
        (kept within ``band`` (k,) of their faces) of the rays ``rows`` (k,); their first
        admissible hits written into ``best``."""
        k = rows.size
        found, pc, th, g = np.zeros(k, bool), np.zeros(k, np.int64), np.zeros((k, 2)), np.full(k, np.inf)
        status = np.zeros(k, np.int64)
        slot = np.full(k, -1, np.int64)
        control, origin, h, shape, elements, connectivity, nodal, ray_tol = self._kernel_data(u)
        _rk.trace(np.ascontiguousarray(x1[rows], dtype=float), np.ascontiguousarray(n1[rows], dtype=float),
                  np.ascontiguousarray(piece), np.ascontiguousarray(theta),
                  np.ascontiguousarray(start_slot), np.ascontiguousarray(band, dtype=float), float(max_gap), ray_tol,
                  MAX_RAY_NEWTON, self._layout, self._knots, control, origin, h, shape, elements, LOCATE_TOL,
                  connectivity, nodal, found, pc, th, g, slot, status, self.polish)
        if np.any(status == _rk.OUTSIDE):
            raise ValueError(f"{int(np.sum(status == _rk.OUTSIDE))} surface points outside the active elements")
        best.found[rows], best.piece[rows], best.theta[rows], best.g[rows] = found, pc, th, g
        best.slot[rows] = np.where(found, slot, -1)

    def _starts(self, u: np.ndarray, x1: np.ndarray, n1: np.ndarray, max_gap: float,
                near: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Seed starts of rays ``x1``, ``n1`` (n, 3): patches (n, k) (-1 past the last) and
        parameters (n, k, 2), nearest to the ray first. The hit's nearest seed lies within
        the seeds' spacing of the ray: the segment is sampled at that spacing, the seeds
        nearest to the samples (those within :data:`SAMPLE_REACH` spacings of their sample)
        are sorted by their distance to the ray, and those within twice the spacing start
        Newton (none: no hit possible; such a seed is within 2.06 spacings of a sample). Further seeds matter: a
        start on the wrong side of a fold or a patch edge may not converge to the hit.
        ``near``: the seeds to use (default all)."""
        n = x1.shape[0]
        near = np.arange(self.seed_piece.size) if near is None else np.asarray(near, np.int64)
        seeds_x = self._seed_positions(u, near)
        m = int(np.ceil(2.0 * max_gap / self.spacing)) + 1
        ts = np.linspace(-max_gap, max_gap, m)
        samples = x1[:, None, :] + ts[None, :, None] * n1[:, None, :]
        tree = surface_tree(seeds_x)
        # a sample farther than SAMPLE_REACH spacings from every seed has none: the bounded
        # query is much cheaper for the many rays that miss (docs/performance.md)
        _, found = tree.query(samples.reshape(-1, 3), distance_upper_bound=SAMPLE_REACH * self.spacing,
                              workers=numba.get_num_threads())
        k = min(m, 4 * CANDIDATES)
        piece, theta = np.empty((n, k), np.int64), np.empty((n, k, 2))
        _sk.nearest_starts(seeds_x, found.reshape(n, m), near, x1, n1, 2.0 * self.spacing, self.seed_piece,
                           self.seed_theta, piece, theta)
        return piece, theta


class NurbsFeSurface(RaySurface):
    """NURBS+FE contact surface of a body (exact patches + the body's FE displacement, of the
element of its space)."""

    definition = "nurbs_fe"

    @property
    def width(self) -> int:
        """Nodes a surface point moves with (those of its grid element)."""
        return self.space.element.n_nodes

    @property
    def lebesgue(self) -> float:
        """No surface point moves further than this times the largest move of the nodes."""
        return self.space.element.lebesgue

    def __init__(self, solid: Solid, space: Space, surface: SurfaceQuadrature, patches: np.ndarray):
        """``surface``: a dense exact surface rule of the body (seeds of the search);
        ``patches``: ids of the patches that may touch."""
        self.solid, self.space = solid, space
        self.patches = np.asarray(patches, np.int64)
        keep = np.isin(surface.patch, self.patches)
        self.seed_piece = surface.patch[keep]
        self.seed_theta = surface.uv[keep]
        self._seed_slot, self._seed_xi = locate_points(space, surface.x[keep])
        self.h = space.h
        seeds = surface.x[keep]
        #: the largest distance from a seed to its nearest neighbour (about the distance from
        #: any surface point to its nearest seed)
        self.spacing = float(cKDTree(seeds).query(seeds, k=2)[0][:, 1].max()) if seeds.shape[0] > 1 else self.h
        # reference positions (n_seeds, 3) and shape functions (n_seeds, n_nodes) of the seeds
        self._seed_X = np.empty((self.seed_piece.size, 3))
        for pid in np.unique(self.seed_piece):
            rows = self.seed_piece == pid
            self._seed_X[rows] = solid.patches[pid].surface.evaluate(self.seed_theta[rows])
        #: the seeds' shape functions (n_seeds, n_nodes) on their elements' nodes
        self._seed_coef = np.ascontiguousarray(space.element.tabulate(self._seed_xi, self.h)[0])
        self._seed_nodes = np.ascontiguousarray(space.connectivity[self._seed_slot], dtype=np.int64)
        self._centres = space.centres()
        self._layout, self._knots, self._control = pack_patches([p.surface for p in solid.patches])

    # -- slave side ----------------------------------------------------------------------
    def slave_frames(self, rule: SurfaceQuadrature) -> SlaveFrames:
        """Slave data of the points of ``rule`` (exact surface points with ``patch``, ``uv``)."""
        n = rule.w.size
        A, B = np.empty((n, 3)), np.empty((n, 3))
        for pid in np.unique(rule.patch):
            rows = rule.patch == pid
            d = self.solid.patches[pid].surface.derivatives(rule.uv[rows], 1)
            A[rows], B[rows] = d[:, 1, 0], d[:, 0, 1]
        slots, xi = locate_points(self.space, rule.x)
        N, dN = self.space.element.tabulate(xi, self.h)
        ca = np.einsum("paj,pj->pa", dN, A)
        cb = np.einsum("paj,pj->pa", dN, B)
        return SlaveFrames(slots, self.space.connectivity[slots], rule.x.copy(), A, B, N, ca, cb, rule.w.copy())

    # -- master side ---------------------------------------------------------------------
    def evaluate(self, u: np.ndarray, piece: np.ndarray, theta: np.ndarray, second: bool = True,
                 slot: np.ndarray | None = None) -> MasterPoints:
        """The current master surface at ``(piece, theta)`` (n,), (n, 2); without
        ``second`` the second derivatives ``s`` are left zero (the search needs none).
        ``slot`` (n,): the master elements to evaluate in (those of the search's hits, which
        may keep an element a hit has just left by up to ``STICKY``); default: located."""
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
        if slot is None or np.any(np.asarray(slot) < 0):
            slots, xi = locate_points(self.space, X)
        else:
            slots = np.asarray(slot, np.int64)
            xi = (X - self._centres[slots]) / (0.5 * self.h)
        N, dN, d2N = self.space.element.tabulate(xi, self.h, second=True)
        U = element_values(self.space, u, np.maximum(slots, 0))
        psi = np.einsum("paj,pcj->pca", dN, Qt)                     # dN . Q_alpha  (n, 2, n_nodes)
        x = X + np.einsum("pa,pak->pk", N, U)
        t = Qt + np.einsum("pca,pak->pck", psi, U)
        s = np.zeros((n, 2, 2, 3))
        if second:
            Qs = np.stack([np.stack([Q[:, 2, 0], Q[:, 1, 1]], 1), np.stack([Q[:, 1, 1], Q[:, 0, 2]], 1)], 1)
            coef = (np.einsum("pajl,pcj,pdl->pcda", d2N, Qt, Qt)
                    + np.einsum("paj,pcdj->pcda", dN, Qs))           # (n, 2, 2, n_nodes)
            s = Qs + np.einsum("pcda,pak->pcdk", coef, U)
        m2 = np.cross(t[:, 0], t[:, 1])
        normal = m2 / np.linalg.norm(m2, axis=1)[:, None]
        return MasterPoints(x, t, s, N, psi, slots, normal, self.space.connectivity[np.maximum(slots, 0)])

    def _may_hit(self, u: np.ndarray, x1: np.ndarray, max_gap: float, n1: np.ndarray) -> np.ndarray:
        """(n,) bool: the ray segment ``x1 + g n1``, ``|g| <= max_gap`` ((n, 3) each), may
        meet the master. A master point ``x = Q + N . U2`` of element ``e`` lies in the box of
        the element's cube moved by the range of the Bernstein coefficients of its
        displacement (:attr:`~cgfem.fem.element.Hexahedron.to_bernstein`: the nodal values
        themselves at order 1, where ``N >= 0`` sums to 1); a segment that meets no such box (widened by a margin for the locator's and
        Newton's tolerances) has no hit, and its point is skipped. Boxes near the segment's
        midpoint are found with a k-d tree, then cut against the segment (slab test)."""
        U = u.reshape(-1, 3)[self.space.connectivity]                  # (n_el, n_nodes, 3)
        if self.space.element.order > 1:
            U = np.einsum("ab,ebk->eak", self.space.element.to_bernstein, U)
        lo, hi = U.min(axis=1), U.max(axis=1)
        centre = self._centres + 0.5 * (lo + hi)
        half = 0.5 * self.h + 0.5 * (hi - lo) + 1e-6 * self.h           # (n_el, 3)
        length = max_gap + 1e-6 * self.h
        may = np.zeros(x1.shape[0], bool)
        # ordinary boxes through a k-d tree with their own reach; the few boxes a distorted
        # iterate blows up (a radius over twice the cube's) against every point, so that one
        # of them does not widen the query of all
        radius = np.linalg.norm(half, axis=1)
        big = radius > np.sqrt(3.0) * self.h
        small = np.flatnonzero(~big)
        if small.size:
            reach = length + radius[small].max()
            tree = cKDTree(centre[small])
            rows = np.flatnonzero(tree.query(x1, distance_upper_bound=reach)[0] <= reach)
            for part in np.array_split(rows, max(1, -(-rows.size // 4096))):
                pt, el = pairs_within(x1[part], tree, reach)
                if pt.size:
                    pt, el = part[pt], small[el]
                    may[pt[_segment_meets_box(x1[pt], n1[pt], centre[el], half[el], length)]] = True
        for e in np.flatnonzero(big):
            rest = np.flatnonzero(~may)
            hit = _segment_meets_box(x1[rest], n1[rest], centre[e][None], half[e][None], length)
            may[rest[hit]] = True
        return may

    def _kernel_data(self, u: np.ndarray) -> tuple:
        grid = self.space.grid
        return (self._control, np.asarray(grid.origin, float), float(self.h), np.asarray(grid.shape, np.int64),
                self.space.elements, self.space.connectivity, np.ascontiguousarray(u, dtype=float).reshape(-1, 3),
                RAY_TOL)


class FacetSurface:
    """Linear-facet contact surface (marching-cubes triangles moved with the FE field)."""

    definition = "facets"

    @property
    def width(self) -> int:
        """Nodes a surface point moves with (those of its grid element)."""
        return self.space.element.n_nodes

    @property
    def lebesgue(self) -> float:
        """No surface point moves further than this times the largest move of the nodes (a
        point is a convex combination of its triangle's vertices, each moved by the element's
        field)."""
        return self.space.element.lebesgue

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
        self.vertex_N = space.element.tabulate(xi.reshape(-1, 3), space.h)[0].reshape(
            -1, 3, space.element.n_nodes)
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
        return SlaveFrames(self.slot[tri], self.space.connectivity[self.slot[tri]], X, A, B, phi, ca, cb,
                           np.asarray(w, float).copy())

    def evaluate(self, u: np.ndarray, piece: np.ndarray, theta: np.ndarray, second: bool = True,
                 slot: np.ndarray | None = None) -> MasterPoints:
        """The current (flat) master triangles at ``(piece, theta)``; ``s`` is zero (a
        triangle lies in one element: ``slot`` is that of the triangle)."""
        X, A, B, phi, ca, cb = self._coefficients(piece, theta)
        U = element_values(self.space, u, self.slot[piece])
        x = X + np.einsum("pa,pak->pk", phi, U)
        psi = np.stack([ca, cb], axis=1)
        t = np.stack([A, B], axis=1) + np.einsum("pca,pak->pck", psi, U)
        m2 = np.cross(t[:, 0], t[:, 1])
        normal = m2 / np.linalg.norm(m2, axis=1)[:, None]
        return MasterPoints(x, t, np.zeros((piece.size, 2, 2, 3)), phi, psi, self.slot[piece], normal,
                            self.space.connectivity[self.slot[piece]])

    def _vertices(self, u: np.ndarray, near: np.ndarray | None = None) -> np.ndarray:
        """Current vertices (m, 3, 3) of the candidate triangles (those ``near`` of them)."""
        cand = self.candidates if near is None else self.candidates[near]
        U = u.reshape(-1, 3)[self.space.connectivity[self.slot[cand]]]          # (m, n_nodes, 3)
        return self.triangles[cand] + np.einsum("mva,mak->mvk", self.vertex_N[cand], U)

    def samples(self, u: np.ndarray) -> tuple[np.ndarray, float]:
        """The candidate triangles' centroids (m, 3) and the largest distance from a centroid
        to its triangle's vertices."""
        verts = self._vertices(u)
        centroid = verts.mean(axis=1)
        return centroid, float(np.linalg.norm(verts - centroid[:, None], axis=2).max(initial=0.0))

    def search(self, u: np.ndarray, x1: np.ndarray, n1: np.ndarray, max_gap: float,
               previous: RayHits | None = None, near: np.ndarray | None = None,
               band: np.ndarray | None = None) -> RayHits:
        """Nearest admissible hit of each ray ``x1 + g n1`` (n, 3) on the current triangles.
        A point whose ``previous`` hit lay on a triangle keeps it while the ray meets that
        triangle's plane within ``STICKY`` (barycentric) of its edges: a hit on an edge
        otherwise jumps between the two triangles' normals from one Newton iterate to the
        next. ``near``: the triangles (indices of :meth:`samples`) the rays may hit (default
        all). ``band`` (n,): the band of each ray's kept triangle (default ``STICKY``)."""
        n = x1.shape[0]
        cand = self.candidates if near is None else self.candidates[near]
        best = RayHits(np.zeros(n, bool), np.zeros(n, np.int64), np.zeros((n, 2)), np.full(n, np.inf),
                       np.full(n, -1, np.int64))
        if cand.size == 0:
            return best
        verts = self._vertices(u, near)
        todo = np.arange(n)
        if previous is not None and previous.piece.shape == (n,) and previous.found.any():
            # the kept triangle alone first: where the ray still meets it (within STICKY) it
            # is the hit, whatever else the ray meets
            local = np.full(self.triangles.shape[0], -1, np.int64)
            local[cand] = np.arange(cand.size)
            rows = np.flatnonzero(previous.found)
            tris = local[previous.piece[rows]]
            rows, tris = rows[tris >= 0], tris[tris >= 0]
            width = _rk.STICKY if band is None else np.asarray(band, float)[rows]
            self._take(best, cand, *self._hits(x1, n1, rows, tris, verts, width, max_gap), nearest=False)
            todo = np.flatnonzero(~best.found)
        if todo.size == 0:
            return best
        centroid = verts.mean(axis=1)
        radius = np.linalg.norm(verts - centroid[:, None], axis=2).max()
        # the pairs' order does not matter: _take keeps per ray the nearest hit, ties to the
        # lowest triangle id
        rows, tris = pairs_within(x1[todo], surface_tree(centroid), max_gap + radius)
        if rows.size:
            self._take(best, cand, *self._hits(x1, n1, todo[rows], tris, verts, FACET_TOL, max_gap), nearest=True)
        return best

    def _hits(self, x1: np.ndarray, n1: np.ndarray, rows: np.ndarray, tris: np.ndarray, verts: np.ndarray,
              band: float | np.ndarray, max_gap: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Admissible hits of the pairs (ray ``rows[k]``, triangle ``tris[k]`` of ``verts``):
        barycentric coordinates within ``band`` (a number, or one per pair) of the triangle,
        normal against the ray, ``|g| <= max_gap``
        (:func:`cgfem.contact._facet_kernels.triangle_hits`). Returns the pairs that hit:
        their rays, triangles, ``l1``, ``l2`` and ``g``."""
        rows, tris = np.ascontiguousarray(rows, np.int64), np.ascontiguousarray(tris, np.int64)
        bands = np.ascontiguousarray(np.atleast_1d(np.asarray(band, float)))      # (1,) or one per pair
        hit, sol = triangle_hits(np.ascontiguousarray(x1, float), np.ascontiguousarray(n1, float), rows, tris,
                                 np.ascontiguousarray(verts, float), bands, float(max_gap), 1e-30 * self.h ** 2)
        k = np.flatnonzero(hit)
        return rows[k], tris[k], sol[k, 0], sol[k, 1], sol[k, 2]

    def _take(self, best: RayHits, cand: np.ndarray, rows: np.ndarray, tris: np.ndarray, l1: np.ndarray,
              l2: np.ndarray, g: np.ndarray, nearest: bool) -> None:
        """Write hits into ``best``: per ray the nearest (``nearest``) or its only one. Hits
        within ``TIE h`` of a ray's nearest (a ray through a shared edge meets both
        triangles at the same ``g`` up to round-off) go to the lowest triangle id, so the
        choice does not hinge on round-off."""
        if nearest and rows.size:
            size = np.abs(g)
            nearest_g = np.full(best.found.size, np.inf)
            np.minimum.at(nearest_g, rows, size)
            close = np.flatnonzero(size <= nearest_g[rows] + TIE * self.h)
            order = close[np.lexsort((cand[tris[close]], rows[close]))]
            first = order[np.concatenate([[True], rows[order][1:] != rows[order][:-1]])]
            rows, tris, l1, l2, g = rows[first], tris[first], l1[first], l2[first], g[first]
        best.found[rows] = True
        best.piece[rows] = cand[tris]
        best.theta[rows] = np.column_stack([l1, l2])
        best.g[rows] = g
        best.slot[rows] = self.slot[cand[tris]]
