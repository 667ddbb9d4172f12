"""Is a set of NURBS patches the closed, outward-oriented boundary of a solid?

:func:`check_watertight` looks only at the patch boundaries. Every patch has four boundary
curves ("edges"): ``u = u0``, ``u = u1``, ``v = v0``, ``v = v1``, evaluated through the
surface itself. An edge whose points all coincide (a *collapsed* edge: sphere pole, disc
centre) bounds nothing and is skipped. Every other edge must be covered by the other edges
(of any patch, the same one included: the seam of a torus is its ``u = u0`` and ``u = u1``):

1. *closed* -- each edge is sampled at the ends of its knot spans and at
   :data:`SAMPLES_PER_SPAN` points inside each span; every sample must lie within
   ``rel_tol * diagonal`` (the diagonal of the bounding box of all control points) of some
   other non-collapsed edge. The distance from a point to an edge is found from the
   nearest sample of that edge and refined by a safeguarded 1D Newton iteration on the curve
   parameter, bracketed by the neighbouring samples. Partial covering by several edges
   (T-junctions, non-matching parametrizations) is fine.
2. *consistently oriented* -- each edge is traversed as the boundary of its patch
   (counterclockwise in ``(u, v)``, so that with the normal ``S_u x S_v`` it is the positive
   boundary); where two edges meet along a curve, their traversals must be opposite.
3. *outward* -- the enclosed volume (:func:`cgfem.geometry.measure.volume`) is positive.

Failures raise :class:`~cgfem.errors.InputError` with the field ``patches[i]`` of the
offending patch (or ``patches`` for the inward case).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from cgfem.errors import InputError
from cgfem.geometry.measure import volume
from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.solid import Solid

#: Samples strictly inside every knot span of an edge (the span ends are sampled too).
SAMPLES_PER_SPAN = 9

#: Two matched edges run in the same direction when the cosine of their oriented tangents
#: exceeds this (a shared curve gives -1 for consistent and +1 for inconsistent orientation;
#: edges that merely cross give about 0 and are not judged).
SAME_DIRECTION_COS = 0.5

_NEWTON_ITERATIONS = 60


@dataclass(frozen=True, eq=False)
class _Edge:
    """One boundary curve of a patch, ``C(t) = S(value, t)`` (``fixed = 0``) or
    ``S(t, value)`` (``fixed = 1``).

    ``sense`` is +1 where the patch boundary (counterclockwise in ``(u, v)``) runs toward
    increasing ``t``, else -1. ``t`` (m,) sample parameters, ``x`` (m, 3) sample points,
    ``dx`` (m, 3) tangents ``dC/dt`` there. ``collapsed``: all points coincide; ``closed``:
    the two ends coincide (a full circle), so the samples are neighbours cyclically.
    """

    patch: int
    surface: NurbsSurface
    fixed: int
    value: float
    sense: float
    t: np.ndarray
    x: np.ndarray
    dx: np.ndarray
    collapsed: bool
    closed: bool

    @property
    def label(self) -> str:
        return f"{'uv'[self.fixed]}={self.value:g}"

    def curve(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``C, dC/dt, d2C/dt2`` at parameters ``t`` (n,), each (n, 3)."""
        t = np.asarray(t, dtype=float)
        fixed = np.full(t.shape, self.value)
        uv = np.column_stack([fixed, t] if self.fixed == 0 else [t, fixed])
        d = self.surface.derivatives(uv, 2)
        if self.fixed == 0:
            return d[:, 0, 0], d[:, 0, 1], d[:, 0, 2]
        return d[:, 0, 0], d[:, 1, 0], d[:, 2, 0]


def _edge_parameters(breaks: np.ndarray) -> np.ndarray:
    """Span ends plus :data:`SAMPLES_PER_SPAN` equispaced points inside every span."""
    s = np.linspace(0.0, 1.0, SAMPLES_PER_SPAN + 2)[:-1]
    inner = (breaks[:-1, None] + (breaks[1:] - breaks[:-1])[:, None] * s).ravel()
    return np.append(inner, breaks[-1])


def _patch_edges(index: int, surface: NurbsSurface, tol: float) -> list[_Edge]:
    """The four edges ``u=u0, u=u1, v=v0, v=v1`` of a patch."""
    (u0, u1), (v0, v1) = surface.domain
    bu, bv = surface.breaks()
    edges = []
    for fixed, value, sense, breaks in ((0, u0, -1.0, bv), (0, u1, 1.0, bv),
                                        (1, v0, 1.0, bu), (1, v1, -1.0, bu)):
        t = _edge_parameters(breaks)
        stub = _Edge(index, surface, fixed, value, sense, t, np.empty((0, 3)), np.empty((0, 3)), False, False)
        x, dx, _ = stub.curve(t)
        collapsed = bool(np.max(np.linalg.norm(x - x[0], axis=1)) <= tol)
        closed = bool(np.linalg.norm(x[-1] - x[0]) <= tol)
        edges.append(_Edge(index, surface, fixed, value, sense, t, x, dx, collapsed, closed))
    return edges


def _closest_on_edge(edge: _Edge, x: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance from points ``x`` (n, 3) to ``edge`` near its samples ``j`` (n,) (the nearest
    samples): safeguarded Newton on ``f(t) = (C(t) - x) . C'(t) = 0`` inside the bracket
    ``[t[j-1], t[j+1]]`` (on a closed edge, an end sample is also tried at the other end).
    Returns distances (n,) and foot parameters (n,)."""
    j = np.asarray(j)
    last = edge.t.size - 1
    if not edge.closed:
        return _closest_in_bracket(edge, x, j)
    d, t = _closest_in_bracket(edge, x, j)
    ends = np.flatnonzero((j == 0) | (j == last))
    if ends.size:
        d2, t2 = _closest_in_bracket(edge, x[ends], last - j[ends])
        better = d2 < d[ends]
        d[ends[better]], t[ends[better]] = d2[better], t2[better]
    return d, t


def _closest_in_bracket(edge: _Edge, x: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    last = edge.t.size - 1
    a = edge.t[np.maximum(j - 1, 0)]
    b = edge.t[np.minimum(j + 1, last)]
    t = edge.t[j].copy()
    best_d = np.linalg.norm(edge.x[j] - x, axis=1)
    best_t = t.copy()
    ca, c1a, _ = edge.curve(a)
    cb, c1b, _ = edge.curve(b)
    for c, ends in ((ca, a), (cb, b)):
        d = np.linalg.norm(c - x, axis=1)
        better = d < best_d
        best_d[better], best_t[better] = d[better], ends[better]
    fa = np.einsum("ij,ij->i", ca - x, c1a)
    fb = np.einsum("ij,ij->i", cb - x, c1b)
    # a minimum of |C - x|^2 inside the bracket: f changes sign from - to +
    active = np.flatnonzero((fa < 0.0) & (fb > 0.0))
    lo, hi, tt, xx = a[active], b[active], t[active], x[active]
    for _ in range(_NEWTON_ITERATIONS):
        if active.size == 0:
            break
        c, c1, c2 = edge.curve(tt)
        r = c - xx
        d = np.linalg.norm(r, axis=1)
        better = d < best_d[active]
        best_d[active[better]] = d[better]
        best_t[active[better]] = tt[better]
        f = np.einsum("ij,ij->i", r, c1)
        fp = np.einsum("ij,ij->i", c1, c1) + np.einsum("ij,ij->i", r, c2)
        lo = np.where(f < 0.0, tt, lo)
        hi = np.where(f > 0.0, tt, hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(fp > 0.0, f / fp, np.nan)
        new = tt - step
        outside = ~((new > lo) & (new < hi))
        new[outside] = 0.5 * (lo[outside] + hi[outside])
        eps = 4.0 * np.finfo(float).eps
        done = (f == 0.0) | (np.abs(new - tt) <= eps * np.maximum(np.abs(tt), np.abs(hi - lo)))
        done |= hi - lo <= eps * np.maximum(np.abs(lo), np.abs(hi))
        keep = ~done
        active, lo, hi, tt, xx = active[keep], lo[keep], hi[keep], new[keep], xx[keep]
    return best_d, best_t


def _distance_to_all(edges: list[_Edge], own: int, x: np.ndarray) -> np.ndarray:
    """Distance from points ``x`` (n, 3) to every non-collapsed edge but ``edges[own]``
    (inf if there is none)."""
    best = np.full(x.shape[0], np.inf)
    for k, edge in enumerate(edges):
        if k == own or edge.collapsed:
            continue
        j = np.argmin(np.linalg.norm(x[:, None, :] - edge.x[None, :, :], axis=2), axis=1)
        best = np.minimum(best, _closest_on_edge(edge, x, j)[0])
    return best


def _format_point(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.6g}" for c in x) + ")"


def check_watertight(solid: Solid, rel_tol: float = 1e-8) -> None:
    """Raise :class:`~cgfem.errors.InputError` unless ``solid``'s patches close up, are
    consistently oriented and point outward (see the module docstring).

    ``rel_tol`` is relative to the diagonal of the bounding box of all control points.
    """
    if not rel_tol > 0.0:
        raise ValueError(f"rel_tol must be positive, got {rel_tol}")
    corners = np.concatenate([p.surface.points.reshape(-1, 3) for p in solid.patches])
    diagonal = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
    tol = rel_tol * diagonal
    if diagonal == 0.0:
        raise InputError("patches", "all control points coincide")

    edges = [e for i, p in enumerate(solid.patches) for e in _patch_edges(i, p.surface, tol)]
    # all samples of the non-collapsed edges, flat
    open_ids = [k for k, e in enumerate(edges) if not e.collapsed]
    if not open_ids:
        _check_volume(solid, diagonal)
        return
    x = np.concatenate([edges[k].x for k in open_ids])
    owner = np.concatenate([np.full(edges[k].t.size, k) for k in open_ids])
    local = np.concatenate([np.arange(edges[k].t.size) for k in open_ids])
    count = np.concatenate([np.full(edges[k].t.size, edges[k].t.size) for k in open_ids])
    sense = np.concatenate([np.full(edges[k].t.size, edges[k].sense) for k in open_ids])
    dx = np.concatenate([edges[k].dx for k in open_ids])
    tree = cKDTree(x)

    # candidate pairs (sample i, other edge k, nearest sample j of k): i within reach of k
    pair_i, pair_k, pair_j, pair_d = [], [], [], []
    for k in open_ids:
        edge = edges[k]
        chord = np.linalg.norm(np.diff(edge.x, axis=0), axis=1).max()
        reach = 2.0 * chord + tol
        found = cKDTree(edge.x).sparse_distance_matrix(tree, reach, output_type="ndarray")
        found = found[owner[found["j"]] != k]
        pair_i.append(found["j"])
        pair_k.append(np.full(found.size, k))
        pair_j.append(found["i"])
        pair_d.append(found["v"])
    pi, pk, pj, pd = (np.concatenate(a) for a in (pair_i, pair_k, pair_j, pair_d))
    order = np.lexsort((pd, pk, pi))
    pi, pk, pj, pd = pi[order], pk[order], pj[order], pd[order]
    first = np.ones(pi.size, bool)
    first[1:] = (pi[1:] != pi[:-1]) | (pk[1:] != pk[:-1])
    pi, pk, pj, pd = pi[first], pk[first], pj[first], pd[first]

    # distance of each candidate pair, refined where the samples alone do not settle it
    foot = np.empty(pi.size)
    foot[:] = np.nan
    direct = pd <= tol
    for k in np.unique(pk[~direct]):
        sel = np.flatnonzero((pk == k) & ~direct)
        pd[sel], foot[sel] = _closest_on_edge(edges[k], x[pi[sel]], pj[sel])
    for k in np.unique(pk[direct]):
        sel = np.flatnonzero((pk == k) & direct)
        foot[sel] = edges[k].t[pj[sel]]
    matched = pd <= tol

    # 1. closed
    covered = np.zeros(x.shape[0], bool)
    covered[pi[matched]] = True
    if not covered.all():
        k = int(owner[np.flatnonzero(~covered).min()])
        edge = edges[k]
        d = _distance_to_all(edges, k, edge.x)
        worst = int(np.argmax(d))
        where = f"point {_format_point(edge.x[worst])}"
        if np.isfinite(d[worst]):
            detail = f"{where} is {d[worst]:.1e} from every other patch edge"
        else:
            detail = f"{where} is on no other patch edge (there is none)"
        raise InputError(f"patches[{edge.patch}]", f"edge {edge.label} is open: {detail}")

    # 2. consistently oriented: interior samples of an edge against every matching edge
    inner = matched & (local[pi] > 0) & (local[pi] < count[pi] - 1)
    mi, mk, mt = pi[inner], pk[inner], foot[inner]
    tangent_a = sense[mi, None] * dx[mi]
    tangent_b = np.empty_like(tangent_a)
    for k in np.unique(mk):
        sel = np.flatnonzero(mk == k)
        tangent_b[sel] = edges[k].sense * edges[k].curve(mt[sel])[1]
    norms = np.linalg.norm(tangent_a, axis=1) * np.linalg.norm(tangent_b, axis=1)
    dots = np.einsum("ij,ij->i", tangent_a, tangent_b)
    judged = (norms > 0.0) & (np.abs(dots) > SAME_DIRECTION_COS * norms)
    same = judged & (dots > 0.0)
    if same.any():
        _report_orientation(np.array([e.patch for e in edges]), owner[mi], mk, judged, same)

    # 3. outward
    _check_volume(solid, diagonal)


def _report_orientation(patch_of: np.ndarray, own: np.ndarray, other: np.ndarray,
                        judged: np.ndarray, same: np.ndarray) -> None:
    """Raise for the patch most likely flipped: the largest share of its samples matched to
    other patches run the same way (ties: most disagreeing partners, then lowest index).

    ``own``/``other`` (n,) edge indices of matched samples; ``judged`` (n,) the tangents are
    parallel; ``same`` (n,) they run the same way.
    """
    a, b = patch_of[own], patch_of[other]
    partners: dict[int, set[int]] = {}
    for pa, pb in zip(a[same], b[same]):
        partners.setdefault(int(pa), set()).add(int(pb))
        partners.setdefault(int(pb), set()).add(int(pa))

    def badness(i: int) -> tuple[float, int, int]:
        mine = judged & (a != b) & ((a == i) | (b == i))
        share = np.count_nonzero(mine & same) / max(np.count_nonzero(mine), 1)
        return (-share, -len(partners[i] - {i}), i)

    i = min(partners, key=badness)
    j = min(partners[i] - {i}, default=i)
    raise InputError(f"patches[{i}]", f"orientation is inconsistent with patches[{j}]")


def _check_volume(solid: Solid, diagonal: float) -> None:
    enclosed = volume(solid)
    if abs(enclosed) <= 1e-12 * diagonal**3:
        raise InputError("patches", f"the patches enclose no volume ({enclosed:.3g})")
    if enclosed < 0.0:
        raise InputError("patches", f"normals point inward (volume < 0: {enclosed:.6g})")
