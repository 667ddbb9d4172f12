"""Closest points and ray intersections on a solid's exact NURBS boundary.

Both queries traverse the bounding-volume hierarchy of a :class:`SurfaceIndex` with an
explicit stack and then solve a small Newton problem on each candidate Bezier leaf, in the
leaf's local parameters ``(s, t)`` in ``[0, 1]^2`` (see :mod:`cgfem.geometry.bvh`):

- **closest point** (branch and bound): phase 1 walks the tree (nearer child first) and
  collects the leaves whose lower bound (distance to the leaf's box and to its normal slab)
  does not exceed an upper bound (distance to the leaves' corner control points, which lie
  on the surface); phase 2 projects onto them in order of lower bound until that bound
  exceeds the best distance found. Projection: from the best sample of a
  ``_SEED_GRID^2`` grid, projected Newton for ``min f = |S(s, t) - x|^2`` with the full
  Hessian ``[S_a . S_b + S_ab . (S - x)]``, the active-set rule at the box ``[0, 1]^2`` (a
  bound variable whose gradient points outward stays fixed; the other one minimises along
  the edge), a Gauss-Newton/Levenberg step where the Hessian is not positive definite, and a
  backtracking line search for steps that are not yet small. Converged when a step moves
  less than ``_STEP_TOL`` (local parameters): the feet are accurate to about 1e-14 of the
  solid's size.
- **ray intersection** (box and slab tests): the leaf's homogeneous net is projected on two
  planes through the ray, which gives a planar polynomial Bezier map ``G(s, t)`` whose zeros
  are the hits. It is halved (de Casteljau; parameter aspect ratio kept below ``_ASPECT``)
  until each piece is either excluded (the convex hull of its net misses the origin) or
  provably one-to-one (every s-difference and t-difference of its net have a cross product
  of one sign, so ``G_s`` and ``G_t`` never align), at most ``_MAX_DEPTH`` times. A
  one-to-one piece holds at most one root: Newton on ``S(s, t) - (o + tau d) = 0`` in
  ``(s, t, tau)`` from its centre; if that ends outside the piece, the piece is halved again
  (at the depth limit, Newton also starts from its corners). Roots inside the leaf's box (up
  to ``_BOX_TOL``) are kept, and roots whose points coincide (within ``MERGE_TOL`` times the
  solid's diagonal, e.g. a hit on an edge shared by two leaves) are merged. So every
  transversal hit is found, except two hits closer together than a piece at the depth limit
  (a nearly tangent ray); tangent (double) roots are found when Newton reaches them.

Among candidate feet whose distances tie (within ``TIE_TOL`` times the diagonal: the foot
lies on an edge shared by patches or leaves), the one whose normal is best aligned with
``x - foot`` is kept: at an edge this is the face that ``x`` actually faces, which makes the
inside test of :mod:`cgfem.geometry.inside` exact there. At collapsed edges (sphere poles,
disc centres) the normal is the limit from inside the leaf (L'Hopital on ``S_s x S_t``).

All numba kernels of the queries live in this module (numba's cache only watches the file
of a kernel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from cgfem.geometry.bvh import SurfaceIndex, as_index

#: Distances within this fraction of the solid's diagonal tie (see module docstring).
TIE_TOL = 1e-11
#: Ray hits whose points are closer than this fraction of the diagonal are one hit.
MERGE_TOL = 1e-10
#: Roots within this distance (in local parameters) outside a leaf's box are kept.
_BOX_TOL = 1e-11
#: Newton stops when a step moves less than this in local parameters.
_STEP_TOL = 1e-15
_MAX_NEWTON = 60
_SEED_GRID = 3
_MAX_DEPTH = 16
_ASPECT = 4.0
#: A Newton root this close (local parameters) to a sub-box belongs to it.
_SUB_PAD = 1e-9
_STACK = 128
_CHUNK = 256


@dataclass(frozen=True)
class ClosestPoints:
    """Closest points ("feet") on the surface of ``n`` query points.

    Attributes
    ----------
    patch : (n,) int, index of the foot's patch in ``solid.patches``
    uv : (n, 2) the foot's parameters in its patch
    point : (n, 3) the foot ``S(u, v)``
    distance : (n,) ``|x - foot|``
    normal : (n, 3) outward unit normal at the foot (limit normal at collapsed edges); where
        the foot lies on an edge, that of the face best aligned with ``x - foot``
    leaf : (n,) int, the leaf of the index holding the foot
    on_edge : (n,) bool, the foot lies on the boundary of its leaf's parameter box
    """

    patch: np.ndarray
    uv: np.ndarray
    point: np.ndarray
    distance: np.ndarray
    normal: np.ndarray
    leaf: np.ndarray
    on_edge: np.ndarray


@dataclass(frozen=True)
class RayHits:
    """Intersections of ``n`` rays with the surface, CSR-like: the hits of ray ``i`` are
    ``offsets[i]:offsets[i + 1]``, sorted by ``t``.

    Attributes
    ----------
    offsets : (n + 1,) int
    ray : (m,) int, the ray of each hit
    t : (m,) ray parameter, ``point = origin + t direction``
    patch : (m,) int, index in ``solid.patches``
    uv : (m, 2) parameters of the hit in its patch
    point : (m, 3) the hit ``S(u, v)`` (exactly on the surface)
    normal : (m, 3) outward unit normal there
    """

    offsets: np.ndarray
    ray: np.ndarray
    t: np.ndarray
    patch: np.ndarray
    uv: np.ndarray
    point: np.ndarray
    normal: np.ndarray

    def count(self) -> np.ndarray:
        """Number of hits per ray, (n,)."""
        return np.diff(self.offsets)


# ------------------------------------------------------------------------------------------
# public functions
# ------------------------------------------------------------------------------------------
def closest_points(index, points) -> ClosestPoints:
    """Closest points on the boundary of the indexed solid.

    Parameters
    ----------
    index : :class:`SurfaceIndex` (or a :class:`~cgfem.geometry.solid.Solid`, indexed here)
    points : (n, 3) query points
    """
    index = as_index(index)
    x = _as_points(points, "points")
    n = x.shape[0]
    leaf = np.empty(n, dtype=np.int64)
    st = np.empty((n, 2))
    foot = np.empty((n, 3))
    dist = np.empty(n)
    normal = np.empty((n, 3))
    _closest_points_kernel(*index.kernel_args(), x, TIE_TOL * index.diagonal, leaf, st, foot, dist, normal)
    on_edge = np.any((st == 0.0) | (st == 1.0), axis=1)
    return ClosestPoints(patch=index.leaf_patch[leaf], uv=_patch_uv(index, leaf, st), point=foot,
                         distance=dist, normal=normal, leaf=leaf, on_edge=on_edge)


def ray_intersections(index, origins, directions, t_min: float = 0.0, t_max: float = np.inf) -> RayHits:
    """Every transversal intersection of the rays ``origin + t direction``,
    ``t_min <= t <= t_max``, with the boundary of the indexed solid.

    Parameters
    ----------
    index : :class:`SurfaceIndex` (or a :class:`~cgfem.geometry.solid.Solid`, indexed here)
    origins : (n, 3)
    directions : (n, 3), non-zero (not necessarily unit: ``t`` is in units of ``|direction|``)
    """
    index = as_index(index)
    o = _as_points(origins, "origins")
    d = _as_points(directions, "directions")
    if o.shape != d.shape:
        raise ValueError(f"origins {o.shape} and directions {d.shape} differ in shape")
    if np.any(np.all(d == 0.0, axis=1)):
        raise ValueError("a ray direction is zero")
    n = o.shape[0]
    capacity = 8
    while True:
        t = np.empty((n, capacity))
        leaf = np.empty((n, capacity), dtype=np.int64)
        st = np.empty((n, capacity, 2))
        count = np.empty(n, dtype=np.int64)
        _ray_kernel(*index.kernel_args(), o, d, float(t_min), float(t_max), MERGE_TOL * index.diagonal,
                    t, leaf, st, count)
        if n == 0 or count.max() <= capacity:
            break
        capacity = 4 * int(count.max())
    keep = np.arange(capacity)[None, :] < count[:, None]
    t, leaf, st = t[keep], leaf[keep], st[keep]
    point = np.empty((t.size, 3))
    normal = np.empty((t.size, 3))
    _leaf_points_normals(index.leaf_degree, index.leaf_offset, index.control, leaf, st, point, normal)
    offsets = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
    return RayHits(offsets=offsets, ray=np.repeat(np.arange(n), count), t=t, patch=index.leaf_patch[leaf],
                   uv=_patch_uv(index, leaf, st), point=point, normal=normal)


def _as_points(points, name: str) -> np.ndarray:
    x = np.ascontiguousarray(points, dtype=float)
    if x.ndim == 1 and x.size == 3:
        x = x.reshape(1, 3)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} must be finite")
    return x


def _patch_uv(index: SurfaceIndex, leaf: np.ndarray, st: np.ndarray) -> np.ndarray:
    box = index.leaf_param[leaf]
    return np.column_stack([box[:, 0] + st[:, 0] * (box[:, 1] - box[:, 0]),
                            box[:, 2] + st[:, 1] * (box[:, 3] - box[:, 2])])


# ------------------------------------------------------------------------------------------
# rational Bezier leaves
# ------------------------------------------------------------------------------------------
@njit(cache=True)
def _raise_degree(N, k, x, y):
    """Bernstein values of degree ``k - 1`` in ``N[:k]`` -> degree ``k`` in ``N[:k + 1]``."""
    saved = 0.0
    for j in range(k):
        tmp = N[j]
        N[j] = saved + y * tmp
        saved = x * tmp
    N[k] = saved


@njit(cache=True)
def bernstein_ders(p, x, order, B):
    """``B[k, i] = d^k B_{i,p}(x) / dx^k`` for ``k <= order <= 2``, ``i <= p``, from the
    Bernstein values of degrees ``p - 2`` and ``p - 1``:
    ``B' = p (b^{p-1}_{i-1} - b^{p-1}_i)``, ``B'' = p (p-1) (b^{p-2}_{i-2} - 2 b^{p-2}_{i-1} + b^{p-2}_i)``.
    ``B`` has shape ``(3, >= p + 1)``."""
    y = 1.0 - x
    N = B[0]
    N[0] = 1.0
    k = 0
    if order >= 2:
        for i in range(p + 1):
            B[2, i] = 0.0
        if p >= 2:
            while k < p - 2:
                k += 1
                _raise_degree(N, k, x, y)
            c = p * (p - 1.0)
            for i in range(p + 1):
                acc = 0.0
                if i <= p - 2:
                    acc += N[i]
                if 1 <= i <= p - 1:
                    acc -= 2.0 * N[i - 1]
                if i >= 2:
                    acc += N[i - 2]
                B[2, i] = c * acc
    if order >= 1:
        for i in range(p + 1):
            B[1, i] = 0.0
        while k < p - 1:
            k += 1
            _raise_degree(N, k, x, y)
        for i in range(p + 1):
            acc = 0.0
            if i <= p - 1:
                acc -= N[i]
            if i >= 1:
                acc += N[i - 1]
            B[1, i] = p * acc
    while k < p:
        k += 1
        _raise_degree(N, k, x, y)


@njit(cache=True)
def bezier_derivs(ctrl, off, p, q, s, t, order, Bu, Bv, Aw, D):
    """Rational Bezier leaf (homogeneous net ``ctrl[off + i (q + 1) + j]``) and its
    derivatives at ``(s, t)`` up to ``order <= 2`` into ``D`` (6, 3): rows
    ``S, S_s, S_t, S_ss, S_st, S_tt`` (quotient rule on ``A / w``). Scratch: ``Bu``, ``Bv``
    (3, >= p + 1 / q + 1), ``Aw`` (6, 4)."""
    bernstein_ders(p, s, order, Bu)
    bernstein_ders(q, t, order, Bv)
    nd = 1 if order == 0 else (3 if order == 1 else 6)
    for m in range(nd):
        for c in range(4):
            Aw[m, c] = 0.0
    for i in range(p + 1):
        for j in range(q + 1):
            r = off + i * (q + 1) + j
            b0 = Bu[0, i] * Bv[0, j]
            for c in range(4):
                Aw[0, c] += b0 * ctrl[r, c]
            if order >= 1:
                b1 = Bu[1, i] * Bv[0, j]
                b2 = Bu[0, i] * Bv[1, j]
                for c in range(4):
                    Aw[1, c] += b1 * ctrl[r, c]
                    Aw[2, c] += b2 * ctrl[r, c]
            if order >= 2:
                b3 = Bu[2, i] * Bv[0, j]
                b4 = Bu[1, i] * Bv[1, j]
                b5 = Bu[0, i] * Bv[2, j]
                for c in range(4):
                    Aw[3, c] += b3 * ctrl[r, c]
                    Aw[4, c] += b4 * ctrl[r, c]
                    Aw[5, c] += b5 * ctrl[r, c]
    w = Aw[0, 3]
    for c in range(3):
        D[0, c] = Aw[0, c] / w
    if order >= 1:
        ws = Aw[1, 3]
        wt = Aw[2, 3]
        for c in range(3):
            D[1, c] = (Aw[1, c] - ws * D[0, c]) / w
            D[2, c] = (Aw[2, c] - wt * D[0, c]) / w
        if order >= 2:
            for c in range(3):
                D[3, c] = (Aw[3, c] - 2.0 * ws * D[1, c] - Aw[3, 3] * D[0, c]) / w
                D[4, c] = (Aw[4, c] - ws * D[2, c] - wt * D[1, c] - Aw[4, 3] * D[0, c]) / w
                D[5, c] = (Aw[5, c] - 2.0 * wt * D[2, c] - Aw[5, 3] * D[0, c]) / w


@njit(cache=True)
def _cross_into(a, b, sign, out):
    out[0] = sign * (a[1] * b[2] - a[2] * b[1])
    out[1] = sign * (a[2] * b[0] - a[0] * b[2])
    out[2] = sign * (a[0] * b[1] - a[1] * b[0])
    return np.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2)


@njit(cache=True)
def _norm3(a):
    return np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True)
def leaf_normal(ctrl, off, p, q, s, t, D, Bu, Bv, Aw, E, n):
    """Outward unit normal ``S_s x S_t / |S_s x S_t|`` at ``(s, t)`` into ``n`` (3,); ``D``
    holds the derivatives up to order 2 at ``(s, t)``. At a collapsed edge (``S_s = 0`` along
    ``t = 0`` or ``1``, or ``S_t = 0`` along ``s = 0`` or ``1``) the limit from inside the
    leaf, ``S_s ~ (t - t_e) S_st`` (L'Hopital); failing that, the normal a little inside.
    Returns ``False`` if no normal was found. Scratch: ``Bu``, ``Bv``, ``Aw``, ``E`` (6, 3)."""
    ls = _norm3(D[1])
    lt = _norm3(D[2])
    big = max(ls, lt)
    ln = _cross_into(D[1], D[2], 1.0, n)
    if ln > 1e-10 * big * big and ln > 0.0:
        for c in range(3):
            n[c] /= ln
        return True
    edge = 1e-6
    if ls < lt and (t < edge or t > 1.0 - edge):
        ln = _cross_into(D[4], D[2], 1.0 if t < 0.5 else -1.0, n)
        ok = ln > 1e-8 * _norm3(D[4]) * lt
    elif lt <= ls and (s < edge or s > 1.0 - edge):
        ln = _cross_into(D[1], D[4], 1.0 if s < 0.5 else -1.0, n)
        ok = ln > 1e-8 * _norm3(D[4]) * ls
    else:
        ok = False
    if ok and ln > 0.0:
        for c in range(3):
            n[c] /= ln
        return True
    for attempt in range(4):
        step = 1e-6 * 100.0 ** attempt
        bezier_derivs(ctrl, off, p, q, s + step * (0.5 - s), t + step * (0.5 - t), 1, Bu, Bv, Aw, E)
        ln = _cross_into(E[1], E[2], 1.0, n)
        big = max(_norm3(E[1]), _norm3(E[2]))
        if ln > 1e-10 * big * big and ln > 0.0:
            for c in range(3):
                n[c] /= ln
            return True
    for c in range(3):
        n[c] = 0.0
    return False


@njit(cache=True)
def _leaf_points_normals(leaf_degree, leaf_offset, ctrl, leaf, st, point, normal):
    """Points and unit normals of leaves ``leaf`` (m,) at local parameters ``st`` (m, 2)."""
    pmax = leaf_degree.max() if leaf_degree.size else 1
    Bu = np.empty((3, pmax + 1))
    Bv = np.empty((3, pmax + 1))
    Aw = np.empty((6, 4))
    D = np.empty((6, 3))
    E = np.empty((6, 3))
    for k in range(leaf.shape[0]):
        lf = leaf[k]
        p = leaf_degree[lf, 0]
        q = leaf_degree[lf, 1]
        off = leaf_offset[lf]
        bezier_derivs(ctrl, off, p, q, st[k, 0], st[k, 1], 2, Bu, Bv, Aw, D)
        for c in range(3):
            point[k, c] = D[0, c]
        leaf_normal(ctrl, off, p, q, st[k, 0], st[k, 1], D, Bu, Bv, Aw, E, normal[k])


# ------------------------------------------------------------------------------------------
# boxes
# ------------------------------------------------------------------------------------------
@njit(cache=True)
def _box_distance2(lo, hi, x):
    """Squared distance from ``x`` to the box ``[lo, hi]`` (0 inside)."""
    acc = 0.0
    for c in range(3):
        if x[c] < lo[c]:
            acc += (lo[c] - x[c]) ** 2
        elif x[c] > hi[c]:
            acc += (x[c] - hi[c]) ** 2
    return acc


@njit(cache=True)
def _ray_hits_box(lo, hi, o, d, t_min, t_max):
    """Slab test: does ``o + t d``, ``t_min <= t <= t_max``, meet the box ``[lo, hi]``?"""
    t0 = t_min
    t1 = t_max
    for c in range(3):
        if d[c] == 0.0:
            if o[c] < lo[c] or o[c] > hi[c]:
                return False
        else:
            a = (lo[c] - o[c]) / d[c]
            b = (hi[c] - o[c]) / d[c]
            if a > b:
                a, b = b, a
            if a > t0:
                t0 = a
            if b < t1:
                t1 = b
            if t0 > t1:
                return False
    return True


# ------------------------------------------------------------------------------------------
# closest points
# ------------------------------------------------------------------------------------------
@njit(cache=True)
def _dist2(a, x):
    return (a[0] - x[0]) ** 2 + (a[1] - x[1]) ** 2 + (a[2] - x[2]) ** 2


@njit(cache=True)
def _clamp01(a):
    return 0.0 if a < 0.0 else (1.0 if a > 1.0 else a)


@njit(cache=True)
def _seed_on_leaf(ctrl, off, p, q, x, Bu, Bv, Aw, D):
    """Best ``(s, t)`` of a ``_SEED_GRID^2`` grid of samples including the corners."""
    g = _SEED_GRID
    best = np.inf
    bs = 0.5
    bt = 0.5
    for i in range(g):
        s = i / (g - 1.0)
        for j in range(g):
            t = j / (g - 1.0)
            bezier_derivs(ctrl, off, p, q, s, t, 0, Bu, Bv, Aw, D)
            f = _dist2(D[0], x)
            if f < best:
                best = f
                bs = s
                bt = t
    return bs, bt


@njit(cache=True)
def _project_on_leaf(ctrl, off, p, q, x, s, t, Bu, Bv, Aw, D, Dn):
    """Projected Newton for ``min |S(s, t) - x|^2`` on ``[0, 1]^2`` from ``(s, t)``.

    Returns ``(s, t, f)``; ``D`` (6, 3) holds the derivatives at the result. ``Dn`` is
    scratch for trial points."""
    bezier_derivs(ctrl, off, p, q, s, t, 2, Bu, Bv, Aw, D)
    f = _dist2(D[0], x)
    for it in range(_MAX_NEWTON):
        r0 = D[0, 0] - x[0]
        r1 = D[0, 1] - x[1]
        r2 = D[0, 2] - x[2]
        gs = D[1, 0] * r0 + D[1, 1] * r1 + D[1, 2] * r2
        gt = D[2, 0] * r0 + D[2, 1] * r1 + D[2, 2] * r2
        a = D[1, 0] ** 2 + D[1, 1] ** 2 + D[1, 2] ** 2
        b = D[1, 0] * D[2, 0] + D[1, 1] * D[2, 1] + D[1, 2] * D[2, 2]
        c = D[2, 0] ** 2 + D[2, 1] ** 2 + D[2, 2] ** 2
        hss = a + D[3, 0] * r0 + D[3, 1] * r1 + D[3, 2] * r2
        hst = b + D[4, 0] * r0 + D[4, 1] * r1 + D[4, 2] * r2
        htt = c + D[5, 0] * r0 + D[5, 1] * r1 + D[5, 2] * r2
        mu = 1e-12 * (a + c) + 1e-300
        free_s = not ((s <= 0.0 and gs > 0.0) or (s >= 1.0 and gs < 0.0))
        free_t = not ((t <= 0.0 and gt > 0.0) or (t >= 1.0 and gt < 0.0))
        ds = 0.0
        dt = 0.0
        newton = False
        if free_s and free_t:
            det = hss * htt - hst * hst
            if hss > 0.0 and htt > 0.0 and det > 1e-12 * hss * htt:
                ds = -(htt * gs - hst * gt) / det
                dt = -(hss * gt - hst * gs) / det
                newton = True
            else:  # not convex here: Gauss-Newton (J^T J, Levenberg-damped)
                aa = a + mu
                cc = c + mu
                det = aa * cc - b * b
                if det <= 0.0:
                    det = aa * cc
                ds = -(cc * gs - b * gt) / det
                dt = -(aa * gt - b * gs) / det
        elif free_s:
            if hss > 1e-12 * a:
                ds = -gs / hss
                newton = True
            else:
                ds = -gs / (a + mu)
        elif free_t:
            if htt > 1e-12 * c:
                dt = -gt / htt
                newton = True
            else:
                dt = -gt / (c + mu)
        else:
            break
        size = max(abs(ds), abs(dt))
        if size > 0.5:
            ds *= 0.5 / size
            dt *= 0.5 / size
            size = 0.5
        if not size > 0.0:
            break
        alpha = 1.0
        accepted = False
        sn = s
        tn = t
        fn = f
        for ls in range(60):
            sn = _clamp01(s + alpha * ds)
            tn = _clamp01(t + alpha * dt)
            bezier_derivs(ctrl, off, p, q, sn, tn, 2, Bu, Bv, Aw, Dn)
            fn = _dist2(Dn[0], x)
            # Near a minimum round-off hides the decrease of f: trust small Newton steps.
            if fn <= f or (newton and alpha * size < 1e-6):
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            break
        moved = max(abs(sn - s), abs(tn - t))
        s = sn
        t = tn
        f = fn
        for m in range(6):
            for cc3 in range(3):
                D[m, cc3] = Dn[m, cc3]
        if moved <= _STEP_TOL:
            break
    return s, t, f


@njit(cache=True)
def _slab_distance(axis, slab, x):
    """Distance from ``x`` to the slab ``slab[0] <= axis . y <= slab[1]`` (0 inside)."""
    h = axis[0] * x[0] + axis[1] * x[1] + axis[2] * x[2]
    if h < slab[0]:
        return slab[0] - h
    if h > slab[1]:
        return h - slab[1]
    return 0.0


@njit(cache=True)
def _corner_distance(ctrl, off, p, q, x):
    """Smallest distance from ``x`` to the four corner control points of a Bezier leaf (they
    lie on the surface: an upper bound of the distance to the leaf)."""
    best = np.inf
    for r in (off, off + q, off + p * (q + 1), off + p * (q + 1) + q):
        w = ctrl[r, 3]
        d2 = (ctrl[r, 0] / w - x[0]) ** 2 + (ctrl[r, 1] / w - x[1]) ** 2 + (ctrl[r, 2] / w - x[2]) ** 2
        if d2 < best:
            best = d2
    return np.sqrt(best)


@njit(cache=True)
def _closest_point(node_lo, node_hi, node_child, node_start, node_count, leaf_lo, leaf_hi, leaf_axis,
                   leaf_slab, leaf_degree, leaf_offset, ctrl, x, tie, i,
                   out_leaf, out_st, out_point, out_dist, out_normal, Bu, Bv, Aw, D, Dn, E, nrm, stack,
                   cand, cand_lb):
    """Branch and bound for one point ``x``, results into row ``i`` of the outputs (see
    :func:`_closest_points_kernel`); the rest is scratch (``cand``, ``cand_lb`` (n_leaf,)).

    Phase 1 walks the tree (nearer child first) and collects the leaves whose lower bound
    (distance to box and slab) is below the upper bound given by the leaves' corners; phase 2
    projects on them in order of lower bound until the bound exceeds the best distance."""
    ub = np.inf
    n_cand = 0
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        lim = ub + tie
        if _box_distance2(node_lo[node], node_hi[node], x) > lim * lim:
            continue
        c0 = node_child[node, 0]
        if c0 >= 0:
            c1 = node_child[node, 1]
            if _box_distance2(node_lo[c0], node_hi[c0], x) <= _box_distance2(node_lo[c1], node_hi[c1], x):
                stack[sp] = c1
                stack[sp + 1] = c0
            else:
                stack[sp] = c0
                stack[sp + 1] = c1
            sp += 2
            continue
        for k in range(node_start[node], node_start[node] + node_count[node]):
            lb = max(np.sqrt(_box_distance2(leaf_lo[k], leaf_hi[k], x)),
                     _slab_distance(leaf_axis[k], leaf_slab[k], x))
            if lb > ub + tie:
                continue
            cd = _corner_distance(ctrl, leaf_offset[k], leaf_degree[k, 0], leaf_degree[k, 1], x)
            if cd < ub:
                ub = cd
            # insertion into the candidates sorted by lower bound
            j = n_cand
            while j > 0 and cand_lb[j - 1] > lb:
                cand[j] = cand[j - 1]
                cand_lb[j] = cand_lb[j - 1]
                j -= 1
            cand[j] = k
            cand_lb[j] = lb
            n_cand += 1
    min_d = np.inf
    best_d = np.inf
    best_cos = -1.0
    best_leaf = -1
    for j in range(n_cand):
        lim = min_d + tie
        if cand_lb[j] > lim:
            break
        k = cand[j]
        p = leaf_degree[k, 0]
        q = leaf_degree[k, 1]
        off = leaf_offset[k]
        s, t = _seed_on_leaf(ctrl, off, p, q, x, Bu, Bv, Aw, D)
        s, t, f = _project_on_leaf(ctrl, off, p, q, x, s, t, Bu, Bv, Aw, D, Dn)
        d = np.sqrt(f)
        if d > lim:
            continue
        leaf_normal(ctrl, off, p, q, s, t, D, Bu, Bv, Aw, E, nrm)
        if d > 0.0:
            cos = abs((x[0] - D[0, 0]) * nrm[0] + (x[1] - D[0, 1]) * nrm[1] + (x[2] - D[0, 2]) * nrm[2]) / d
        else:
            cos = 1.0
        if d < min_d:
            min_d = d
        if best_leaf < 0 or best_d > min_d + tie or cos > best_cos:
            best_d = d
            best_cos = cos
            best_leaf = k
            out_st[i, 0] = s
            out_st[i, 1] = t
            for c in range(3):
                out_point[i, c] = D[0, c]
                out_normal[i, c] = nrm[c]
    out_leaf[i] = best_leaf
    out_dist[i] = best_d


@njit(cache=True, parallel=True)
def _closest_points_kernel(node_lo, node_hi, node_child, node_start, node_count, leaf_lo, leaf_hi,
                           leaf_axis, leaf_slab, leaf_degree, leaf_offset, ctrl, points, tie,
                           out_leaf, out_st, out_point, out_dist, out_normal):
    """Branch and bound over the BVH for every row of ``points`` (n, 3); results into
    ``out_leaf`` (n,), ``out_st`` (n, 2) local parameters, ``out_point`` (n, 3),
    ``out_dist`` (n,), ``out_normal`` (n, 3). Lower bounds: distance to a node's box, to a
    leaf's box and slab. Candidates within ``tie`` of the smallest distance compete by
    ``|cos|`` of the angle between ``x - foot`` and their normal. Parallel over chunks of
    ``_CHUNK`` points."""
    n = points.shape[0]
    pmax = leaf_degree.max()
    for chunk in prange((n + _CHUNK - 1) // _CHUNK):
        Bu = np.empty((3, pmax + 1))
        Bv = np.empty((3, pmax + 1))
        Aw = np.empty((6, 4))
        D = np.empty((6, 3))
        Dn = np.empty((6, 3))
        E = np.empty((6, 3))
        nrm = np.empty(3)
        stack = np.empty(_STACK, dtype=np.int64)
        cand = np.empty(leaf_degree.shape[0], dtype=np.int64)
        cand_lb = np.empty(leaf_degree.shape[0])
        for i in range(chunk * _CHUNK, min(n, (chunk + 1) * _CHUNK)):
            _closest_point(node_lo, node_hi, node_child, node_start, node_count, leaf_lo, leaf_hi,
                           leaf_axis, leaf_slab, leaf_degree, leaf_offset, ctrl, points[i], tie, i,
                           out_leaf, out_st, out_point, out_dist, out_normal, Bu, Bv, Aw, D, Dn, E, nrm, stack,
                           cand, cand_lb)


# ------------------------------------------------------------------------------------------
# ray intersections
# ------------------------------------------------------------------------------------------
@njit(cache=True)
def _ray_planes(d, n1, n2):
    """Two unit vectors ``n1``, ``n2`` spanning the plane perpendicular to ``d``."""
    k = 0
    if abs(d[1]) < abs(d[k]):
        k = 1
    if abs(d[2]) < abs(d[k]):
        k = 2
    e = np.zeros(3)
    e[k] = 1.0
    ln = _cross_into(d, e, 1.0, n1)
    for c in range(3):
        n1[c] /= ln
    ln = _cross_into(d, n1, 1.0, n2)
    for c in range(3):
        n2[c] /= ln


@njit(cache=True)
def _excluded(G, p, q, angles):
    """The net ``G`` (p + 1, q + 1, 2) cannot vanish: its convex hull misses the origin, i.e.
    the directions of its points leave an angular gap larger than pi. Scratch ``angles``
    ((p + 1) (q + 1),)."""
    m = 0
    for i in range(p + 1):
        for j in range(q + 1):
            if G[i, j, 0] == 0.0 and G[i, j, 1] == 0.0:
                return False
            a = np.arctan2(G[i, j, 1], G[i, j, 0])
            k = m
            while k > 0 and angles[k - 1] > a:
                angles[k] = angles[k - 1]
                k -= 1
            angles[k] = a
            m += 1
    gap = 2.0 * np.pi - (angles[m - 1] - angles[0])
    for k in range(1, m):
        gap = max(gap, angles[k] - angles[k - 1])
    return gap > np.pi


@njit(cache=True)
def _injective(G, p, q, tiny):
    """Sufficient test that the planar Bezier map of the net ``G`` is one-to-one: every
    s-difference ``a`` and t-difference ``b`` of the net (the generators of the cones of
    ``G_s`` and ``G_t``) have ``det(a, b)`` of one strict sign. Differences shorter than
    ``tiny`` (a collapsed edge) are skipped."""
    sign = 0
    for i in range(p):
        for j in range(q + 1):
            a0 = G[i + 1, j, 0] - G[i, j, 0]
            a1 = G[i + 1, j, 1] - G[i, j, 1]
            if abs(a0) + abs(a1) <= tiny:
                continue
            for k in range(p + 1):
                for l in range(q):
                    b0 = G[k, l + 1, 0] - G[k, l, 0]
                    b1 = G[k, l + 1, 1] - G[k, l, 1]
                    if abs(b0) + abs(b1) <= tiny:
                        continue
                    det = a0 * b1 - a1 * b0
                    if det > 0.0:
                        if sign < 0:
                            return False
                        sign = 1
                    elif det < 0.0:
                        if sign > 0:
                            return False
                        sign = -1
                    else:
                        return False
    return sign != 0


@njit(cache=True)
def _halve(G, p, q, direction, left, right):
    """de Casteljau at 1/2 of the net ``G`` (p + 1, q + 1, 2) along s (``direction`` 0) or t
    into ``left`` and ``right``."""
    n = p if direction == 0 else q
    m = q if direction == 0 else p
    tmp = np.empty(n + 1)
    for j in range(m + 1):
        for comp in range(2):
            for i in range(n + 1):
                tmp[i] = G[i, j, comp] if direction == 0 else G[j, i, comp]
            for r in range(n + 1):
                if r > 0:
                    for i in range(n - r + 1):
                        tmp[i] = 0.5 * (tmp[i] + tmp[i + 1])
                if direction == 0:
                    left[r, j, comp] = tmp[0]
                    right[n - r, j, comp] = tmp[n - r]
                else:
                    left[j, r, comp] = tmp[0]
                    right[j, n - r, comp] = tmp[n - r]


@njit(cache=True)
def _ray_newton(ctrl, off, p, q, o, d, s, t, Bu, Bv, Aw, D, n):
    """Newton on ``S(s, t) - o - tau d = 0`` from ``(s, t)`` (``tau`` from the projection of
    ``S(s, t)`` on the ray). Returns ``(ok, s, t, tau)``; fails when an iterate leaves ``[-0.5, 1.5]^2``.
    Scratch ``n`` (3,)."""
    dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    bezier_derivs(ctrl, off, p, q, s, t, 0, Bu, Bv, Aw, D)
    tau = ((D[0, 0] - o[0]) * d[0] + (D[0, 1] - o[1]) * d[1] + (D[0, 2] - o[2]) * d[2]) / dd
    for it in range(_MAX_NEWTON):
        bezier_derivs(ctrl, off, p, q, s, t, 1, Bu, Bv, Aw, D)
        f0 = o[0] + tau * d[0] - D[0, 0]  # -F
        f1 = o[1] + tau * d[1] - D[0, 1]
        f2 = o[2] + tau * d[2] - D[0, 2]
        # J = [S_s, S_t, -d]: Cramer's rule for J y = -F
        _cross_into(D[1], D[2], 1.0, n)
        det = -(n[0] * d[0] + n[1] * d[1] + n[2] * d[2])
        scale = _norm3(D[1]) * _norm3(D[2]) * np.sqrt(dd)
        if not abs(det) > 1e-14 * scale:
            return False, s, t, tau
        bx = -(D[2, 1] * d[2] - D[2, 2] * d[1])  # S_t x (-d)
        by = -(D[2, 2] * d[0] - D[2, 0] * d[2])
        bz = -(D[2, 0] * d[1] - D[2, 1] * d[0])
        y0 = (f0 * bx + f1 * by + f2 * bz) / det
        cx = -(f1 * d[2] - f2 * d[1])  # (-F) x (-d)
        cy = -(f2 * d[0] - f0 * d[2])
        cz = -(f0 * d[1] - f1 * d[0])
        y1 = (D[1, 0] * cx + D[1, 1] * cy + D[1, 2] * cz) / det
        ex = D[2, 1] * f2 - D[2, 2] * f1  # S_t x (-F)
        ey = D[2, 2] * f0 - D[2, 0] * f2
        ez = D[2, 0] * f1 - D[2, 1] * f0
        y2 = (D[1, 0] * ex + D[1, 1] * ey + D[1, 2] * ez) / det
        s += y0
        t += y1
        tau += y2
        if not (-0.5 <= s <= 1.5 and -0.5 <= t <= 1.5):  # heading away from this leaf
            return False, s, t, tau
        if max(abs(y0), abs(y1)) <= 1e-14:
            size = _norm3(D[1]) + _norm3(D[2])
            bezier_derivs(ctrl, off, p, q, s, t, 0, Bu, Bv, Aw, D)
            res = np.sqrt((o[0] + tau * d[0] - D[0, 0]) ** 2 + (o[1] + tau * d[1] - D[0, 1]) ** 2
                          + (o[2] + tau * d[2] - D[0, 2]) ** 2)
            return res <= 1e-9 * size, s, t, tau
    return False, s, t, tau


@njit(cache=True)
def _ray_slab(axis, slab, o, d, t_min, t_max):
    """Does ``o + t d``, ``t_min <= t <= t_max``, meet the slab ``slab[0] <= axis . y <= slab[1]``?"""
    h = axis[0] * o[0] + axis[1] * o[1] + axis[2] * o[2]
    rate = axis[0] * d[0] + axis[1] * d[1] + axis[2] * d[2]
    if rate == 0.0:
        return slab[0] <= h <= slab[1]
    a = (slab[0] - h) / rate
    b = (slab[1] - h) / rate
    if a > b:
        a, b = b, a
    return max(a, t_min) <= min(b, t_max)


@njit(cache=True, parallel=True)
def _ray_kernel(node_lo, node_hi, node_child, node_start, node_count, leaf_lo, leaf_hi, leaf_axis,
                leaf_slab, leaf_degree, leaf_offset, ctrl, origins, directions, t_min, t_max, merge,
                out_t, out_leaf, out_st, out_count):
    """All roots of every ray ``origins[i] + t directions[i]`` (n, 3) into ``out_t``,
    ``out_leaf``, ``out_st`` (n, K[, 2]) sorted by ``t``; ``out_count`` (n,) their number
    (larger than K when the buffers were too small: only K are stored then). Parallel over
    chunks of ``_CHUNK`` rays."""
    n = origins.shape[0]
    K = out_t.shape[1]
    pmax = leaf_degree.max()
    for chunk in prange((n + _CHUNK - 1) // _CHUNK):
        Bu = np.empty((3, pmax + 1))
        Bv = np.empty((3, pmax + 1))
        Aw = np.empty((6, 4))
        D = np.empty((6, 3))
        nv = np.empty(3)
        n1 = np.empty(3)
        n2 = np.empty(3)
        pts = np.empty((K, 3))
        nets = np.empty((_MAX_DEPTH + 2, pmax + 1, pmax + 1, 2))
        boxes = np.empty((_MAX_DEPTH + 2, 4))
        depth = np.empty(_MAX_DEPTH + 2, dtype=np.int64)
        left = np.empty((pmax + 1, pmax + 1, 2))
        angles = np.empty((pmax + 1) * (pmax + 1))
        stack = np.empty(_STACK, dtype=np.int64)
        for i in range(chunk * _CHUNK, min(n, (chunk + 1) * _CHUNK)):
            _ray_roots(node_lo, node_hi, node_child, node_start, node_count, leaf_lo, leaf_hi, leaf_axis,
                       leaf_slab, leaf_degree, leaf_offset, ctrl, origins[i], directions[i], t_min, t_max,
                       merge, i, out_t, out_leaf, out_st, out_count,
                       Bu, Bv, Aw, D, nv, n1, n2, pts, nets, boxes, depth, left, angles, stack)


@njit(cache=True)
def _ray_roots(node_lo, node_hi, node_child, node_start, node_count, leaf_lo, leaf_hi, leaf_axis,
               leaf_slab, leaf_degree, leaf_offset, ctrl, o, d, t_min, t_max, merge, i,
               out_t, out_leaf, out_st, out_count,
               Bu, Bv, Aw, D, nv, n1, n2, pts, nets, boxes, depth, left, angles, stack):
    """The roots of one ray into row ``i`` of the outputs (see :func:`_ray_kernel`); the rest
    is scratch.

    In a leaf that the ray meets (box and slab tests), the homogeneous net is projected on
    two planes through the ray, ``G_ij = (n_k . (P_ij - o)) w_ij`` (a polynomial Bezier map
    whose zeros are the hits), and subdivided (de Casteljau) until a sub-box is excluded (a
    component of ``G`` has one sign) or ``G`` is one-to-one there (:func:`_injective`); then
    Newton from the sub-box centre (or its corners) finds its root."""
    K = out_t.shape[1]
    _ray_planes(d, n1, n2)
    o1 = n1[0] * o[0] + n1[1] * o[1] + n1[2] * o[2]
    o2 = n2[0] * o[0] + n2[1] * o[1] + n2[2] * o[2]
    count = 0
    stored = 0
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if not _ray_hits_box(node_lo[node], node_hi[node], o, d, t_min, t_max):
            continue
        if node_child[node, 0] >= 0:
            stack[sp] = node_child[node, 1]
            stack[sp + 1] = node_child[node, 0]
            sp += 2
            continue
        for k in range(node_start[node], node_start[node] + node_count[node]):
            if not _ray_hits_box(leaf_lo[k], leaf_hi[k], o, d, t_min, t_max):
                continue
            if not _ray_slab(leaf_axis[k], leaf_slab[k], o, d, t_min, t_max):
                continue
            p = leaf_degree[k, 0]
            q = leaf_degree[k, 1]
            off = leaf_offset[k]
            size = 0.0
            for c in range(3):
                size = max(size, leaf_hi[k, c] - leaf_lo[k, c])
            for a in range(p + 1):
                for b in range(q + 1):
                    r = off + a * (q + 1) + b
                    w = ctrl[r, 3]
                    nets[0, a, b, 0] = n1[0] * ctrl[r, 0] + n1[1] * ctrl[r, 1] + n1[2] * ctrl[r, 2] - o1 * w
                    nets[0, a, b, 1] = n2[0] * ctrl[r, 0] + n2[1] * ctrl[r, 1] + n2[2] * ctrl[r, 2] - o2 * w
            boxes[0, 0] = 0.0
            boxes[0, 1] = 1.0
            boxes[0, 2] = 0.0
            boxes[0, 3] = 1.0
            depth[0] = 0
            top = 1
            while top > 0:
                top -= 1
                G = nets[top]
                if _excluded(G, p, q, angles):
                    continue
                s0 = boxes[top, 0]
                s1 = boxes[top, 1]
                t0 = boxes[top, 2]
                t1 = boxes[top, 3]
                at_limit = depth[top] >= _MAX_DEPTH
                if at_limit or _injective(G, p, q, 1e-13 * size):
                    # at most one root here: Newton from the centre (at the depth limit also from the
                    # corners); subdivide further unless it lands inside
                    found = False
                    for attempt in range(5 if at_limit else 1):
                        ss = 0.5 * (s0 + s1) if attempt == 0 else (s0 if attempt % 2 == 1 else s1)
                        tt = 0.5 * (t0 + t1) if attempt == 0 else (t0 if attempt <= 2 else t1)
                        ok, s, t, tau = _ray_newton(ctrl, off, p, q, o, d, ss, tt, Bu, Bv, Aw, D, nv)
                        if not ok:
                            continue
                        found = s0 - _SUB_PAD <= s <= s1 + _SUB_PAD and t0 - _SUB_PAD <= t <= t1 + _SUB_PAD
                        if (-_BOX_TOL <= s <= 1.0 + _BOX_TOL and -_BOX_TOL <= t <= 1.0 + _BOX_TOL
                                and t_min <= tau <= t_max):
                            s = _clamp01(s)
                            t = _clamp01(t)
                            bezier_derivs(ctrl, off, p, q, s, t, 0, Bu, Bv, Aw, D)
                            duplicate = False
                            for h in range(stored):
                                if _dist2(pts[h], D[0]) <= merge * merge:
                                    duplicate = True
                            if not duplicate:
                                count += 1
                                if stored < K:
                                    out_t[i, stored] = tau
                                    out_leaf[i, stored] = k
                                    out_st[i, stored, 0] = s
                                    out_st[i, stored, 1] = t
                                    for c in range(3):
                                        pts[stored, c] = D[0, c]
                                    stored += 1
                        if found and not at_limit:
                            break
                    if found or at_limit:
                        continue
                # halve along the direction in which the net is longer, keeping the parameter
                # aspect ratio below _ASPECT (so that two roots near a fold get separated)
                ls = 0.0
                lt = 0.0
                for a in range(p + 1):
                    for b in range(q + 1):
                        if a < p:
                            ls += abs(G[a + 1, b, 0] - G[a, b, 0]) + abs(G[a + 1, b, 1] - G[a, b, 1])
                        if b < q:
                            lt += abs(G[a, b + 1, 0] - G[a, b, 0]) + abs(G[a, b + 1, 1] - G[a, b, 1])
                direction = 0 if ls * q >= lt * p else 1
                if s1 - s0 > _ASPECT * (t1 - t0):
                    direction = 0
                elif t1 - t0 > _ASPECT * (s1 - s0):
                    direction = 1
                _halve(G, p, q, direction, left, nets[top + 1])
                for a in range(p + 1):
                    for b in range(q + 1):
                        for c in range(2):
                            G[a, b, c] = left[a, b, c]
                depth[top + 1] = depth[top] + 1
                depth[top] += 1
                for c in range(4):
                    boxes[top + 1, c] = boxes[top, c]
                if direction == 0:
                    boxes[top, 1] = 0.5 * (s0 + s1)
                    boxes[top + 1, 0] = 0.5 * (s0 + s1)
                else:
                    boxes[top, 3] = 0.5 * (t0 + t1)
                    boxes[top + 1, 2] = 0.5 * (t0 + t1)
                top += 2
    # insertion sort of the stored hits by t
    for a in range(1, stored):
        b = a
        while b > 0 and out_t[i, b - 1] > out_t[i, b]:
            out_t[i, b - 1], out_t[i, b] = out_t[i, b], out_t[i, b - 1]
            out_leaf[i, b - 1], out_leaf[i, b] = out_leaf[i, b], out_leaf[i, b - 1]
            for c in range(2):
                out_st[i, b - 1, c], out_st[i, b, c] = out_st[i, b, c], out_st[i, b - 1, c]
            b -= 1
    out_count[i] = count
