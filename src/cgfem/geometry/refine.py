"""Exact refinement of NURBS: knot insertion, knot refinement, degree elevation, splitting.

Every operation works on the homogeneous control points ``(w x, w y, w z, w)``: the
homogeneous curve or surface is a polynomial B-spline, so refining it and projecting back
gives exactly the same rational geometry (up to round-off). Algorithms are those of *The
NURBS Book* (Piegl & Tiller, 2nd ed.) with the book's variable names:

- A5.1 CurveKnotIns (:func:`curve_insert_knot`) and A5.3 SurfaceKnotIns
  (:func:`insert_knot`, the curve algorithm applied to every row of the net at once);
- A5.4 RefineKnotVectCurve (:func:`curve_refine_knots`) and A5.5 RefineKnotVectSurface
  (:func:`refine_knots`);
- A5.9 DegreeElevateCurve (:func:`curve_elevate_degree`), applied to every row of the net for
  surfaces (:func:`elevate_degree`).

Curve functions take a knot vector ``U`` (clamped, length ``n + p + 2``) and a control net
``Pw`` of shape ``(n + 1, ...)``: axis 0 runs along the curve and any trailing axes (a
homogeneous coordinate, or a whole row of a surface net) are carried along. They return new
arrays ``(U_new, Qw)``. Surface functions return new :class:`NurbsSurface` objects.

Knot multiplicities are counted with exact equality: a knot to insert equal to an existing
knot raises that knot's multiplicity; a knot differing from it by round-off creates a new
(tiny) span. These are not hot loops: vectorized numpy, clarity first.
"""

from __future__ import annotations

from math import comb

import numpy as np

from cgfem.errors import InputError
from cgfem.geometry.nurbs import NurbsSurface

__all__ = [
    "insert_knot",
    "refine_knots",
    "elevate_degree",
    "bezier_patches",
    "split",
    "curve_insert_knot",
    "curve_refine_knots",
    "curve_elevate_degree",
    "curve_split",
]


# ----------------------------------------------------------------------------------------
# validation helpers
# ----------------------------------------------------------------------------------------
def _check_direction(direction) -> int:
    if direction not in (0, 1) or isinstance(direction, bool):
        raise InputError("direction", f"expected 0 (u) or 1 (v), got {direction!r}")
    return int(direction)


def _check_count(field: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise InputError(field, f"expected a non-negative integer, got {value!r}")
    return int(value)


def _check_interior(field: str, p: int, U: np.ndarray, u) -> float:
    """``u`` as a float strictly inside the domain ``(U[p], U[-p-1])``."""
    try:
        u = float(u)
    except (TypeError, ValueError):
        raise InputError(field, f"expected a number, got {u!r}") from None
    if not (U[p] < u < U[-p - 1]):
        raise InputError(field, f"{u!r} is not strictly inside the parameter domain "
                                f"({U[p]!r}, {U[-p - 1]!r})")
    return u


def _multiplicity(U: np.ndarray, u: float) -> int:
    return int(np.count_nonzero(U == u))


# ----------------------------------------------------------------------------------------
# curves: homogeneous nets (n + 1, ...)
# ----------------------------------------------------------------------------------------
def curve_insert_knot(p: int, U, Pw, u: float, r: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A5.1 CurveKnotIns: insert ``u`` ``r`` times.

    Parameters
    ----------
    p : degree
    U : (n + p + 2,) clamped knot vector
    Pw : (n + 1, ...) homogeneous control net; trailing axes are carried along
    u : knot strictly inside the domain; its multiplicity ``s`` must satisfy ``s + r <= p``
    r : number of insertions (``0`` returns copies)

    Returns
    -------
    UQ : (n + p + 2 + r,) new knot vector
    Qw : (n + 1 + r, ...) new control net
    """
    U = np.asarray(U, dtype=float)
    Pw = np.asarray(Pw, dtype=float)
    r = _check_count("times", r)
    u = _check_interior("knot", p, U, u)
    s = _multiplicity(U, u)
    if s + r > p:
        raise InputError("times", f"inserting {u!r} {r} times would raise its multiplicity "
                                  f"from {s} to {s + r}, above the degree {p}")
    if r == 0:
        return U.copy(), Pw.copy()
    n = Pw.shape[0] - 1
    k = int(np.searchsorted(U, u, side="right")) - 1  # U[k] <= u < U[k + 1]
    UQ = np.concatenate([U[: k + 1], np.full(r, u), U[k + 1:]])
    Qw = np.empty((n + 1 + r,) + Pw.shape[1:])
    Qw[: k - p + 1] = Pw[: k - p + 1]
    Qw[k - s + r:] = Pw[k - s:]
    Rw = Pw[k - p: k - s + 1].copy()
    for j in range(1, r + 1):
        L = k - p + j
        for i in range(p - j - s + 1):
            alpha = (u - U[L + i]) / (U[i + k + 1] - U[L + i])
            Rw[i] = alpha * Rw[i + 1] + (1.0 - alpha) * Rw[i]
        Qw[L] = Rw[0]
        Qw[k + r - j - s] = Rw[p - j - s]
    L = k - p + r
    for i in range(L + 1, k - s):
        Qw[i] = Rw[i - L]
    return UQ, Qw


def curve_refine_knots(p: int, U, Pw, X) -> tuple[np.ndarray, np.ndarray]:
    """A5.4 RefineKnotVectCurve: insert all knots of ``X`` at once.

    Parameters
    ----------
    p : degree
    U : (n + p + 2,) clamped knot vector
    Pw : (n + 1, ...) homogeneous control net
    X : (r + 1,) knots to insert, in any order (sorted here), each strictly inside the
        domain; repeated values are inserted repeatedly; no resulting multiplicity may
        exceed ``p``

    Returns
    -------
    Ubar : (n + p + 2 + r + 1,) refined knot vector
    Qw : (n + r + 2, ...) refined control net
    """
    U = np.asarray(U, dtype=float)
    Pw = np.asarray(Pw, dtype=float)
    X = np.sort(np.asarray(X, dtype=float).ravel())
    if X.size == 0:
        return U.copy(), Pw.copy()
    for x in X:
        _check_interior("new_knots", p, U, x)
    values, counts = np.unique(X, return_counts=True)
    for x, c in zip(values, counts):
        if _multiplicity(U, x) + c > p:
            raise InputError("new_knots", f"knot {x!r} would get multiplicity "
                                          f"{_multiplicity(U, x) + c}, above the degree {p}")
    n = Pw.shape[0] - 1
    m = n + p + 1
    r = X.size - 1
    a = int(np.searchsorted(U, X[0], side="right")) - 1
    b = int(np.searchsorted(U, X[r], side="right"))  # FindSpan(X[r]) + 1
    Qw = np.empty((n + r + 2,) + Pw.shape[1:])
    Ubar = np.empty(m + r + 2)
    Qw[: a - p + 1] = Pw[: a - p + 1]
    Qw[b + r: n + r + 2] = Pw[b - 1: n + 1]
    Ubar[: a + 1] = U[: a + 1]
    Ubar[b + p + r + 1:] = U[b + p:]
    i = b + p - 1
    k = b + p + r
    for j in range(r, -1, -1):
        while X[j] <= U[i] and i > a:
            Qw[k - p - 1] = Pw[i - p - 1]
            Ubar[k] = U[i]
            k -= 1
            i -= 1
        Qw[k - p - 1] = Qw[k - p]
        for l in range(1, p + 1):
            ind = k - p + l
            alfa = Ubar[k + l] - X[j]
            if alfa == 0.0:
                Qw[ind - 1] = Qw[ind]
            else:
                alfa = alfa / (Ubar[k + l] - U[i - p + l])
                Qw[ind - 1] = alfa * Qw[ind - 1] + (1.0 - alfa) * Qw[ind]
        Ubar[k] = X[j]
        k -= 1
    return Ubar, Qw


def curve_elevate_degree(p: int, U, Pw, t: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A5.9 DegreeElevateCurve: raise the degree from ``p`` to ``p + t``.

    The curve is cut into Bezier segments by knot insertion (one segment at a time), each
    segment is degree-elevated with Eq. (5.36), and the knots inserted are removed again, so
    that every distinct knot keeps its continuity: its multiplicity grows by ``t``.

    Parameters
    ----------
    p : degree
    U : (n + p + 2,) clamped knot vector with ``s`` distinct interior knots
    Pw : (n + 1, ...) homogeneous control net
    t : number of degree elevations (``0`` returns copies)

    Returns
    -------
    Uh : (n + p + 2 + t (s + 2),) knot vector of degree ``p + t``
    Qw : (n + 1 + t (s + 1), ...) control net
    """
    U = np.asarray(U, dtype=float)
    Pw = np.asarray(Pw, dtype=float)
    t = _check_count("times", t)
    if t == 0:
        return U.copy(), Pw.copy()
    n = Pw.shape[0] - 1
    m = n + p + 1
    ph = p + t
    rest = Pw.shape[1:]
    n_interior = np.unique(U).size - 2
    # Eq. (5.36): coefficients of the degree-elevated Bezier points
    bezalfs = np.zeros((ph + 1, p + 1))
    for i in range(ph + 1):
        for j in range(max(0, i - t), min(p, i) + 1):
            bezalfs[i, j] = comb(p, j) * comb(t, i - j) / comb(ph, i)
    Qw = np.zeros((n + 1 + t * (n_interior + 1),) + rest)
    Uh = np.zeros(Qw.shape[0] + ph + 1)
    bpts = np.empty((p + 1,) + rest)      # Bezier points of the current segment
    ebpts = np.zeros((ph + 1,) + rest)    # its degree-elevated points
    Nextbpts = np.empty((max(p - 1, 1),) + rest)  # leftmost points of the next segment
    alfs = np.empty(max(p - 1, 1))

    mh = ph
    kind = ph + 1
    r = -1
    a = p
    b = p + 1
    cind = 1
    ua = U[0]
    Qw[0] = Pw[0]
    Uh[: ph + 1] = ua
    bpts[:] = Pw[: p + 1]
    while b < m:
        i = b
        while b < m and U[b] == U[b + 1]:
            b += 1
        mul = b - i + 1
        mh = mh + mul + t
        ub = U[b]
        oldr = r
        r = p - mul
        lbz = (oldr + 2) // 2 if oldr > 0 else 1
        rbz = ph - (r + 1) // 2 if r > 0 else ph
        if r > 0:
            # insert ub r times to close the Bezier segment [ua, ub]
            numer = ub - ua
            for k in range(p, mul, -1):
                alfs[k - mul - 1] = numer / (U[a + k] - ua)
            for j in range(1, r + 1):
                save = r - j
                s = mul + j
                for k in range(p, s - 1, -1):
                    bpts[k] = alfs[k - s] * bpts[k] + (1.0 - alfs[k - s]) * bpts[k - 1]
                Nextbpts[save] = bpts[p]
        # degree-elevate the Bezier segment (only points lbz..ph are used below)
        for i in range(lbz, ph + 1):
            lo, hi = max(0, i - t), min(p, i)
            ebpts[i] = np.tensordot(bezalfs[i, lo: hi + 1], bpts[lo: hi + 1], axes=(0, 0))
        if oldr > 1:
            # remove the knot ua oldr - 1 times (it was inserted oldr times)
            first = kind - 2
            last = kind
            den = ub - ua
            bet = (ub - Uh[kind - 1]) / den
            for tr in range(1, oldr):
                i = first
                j = last
                kj = j - kind + 1
                while j - i > tr:
                    if i < cind:
                        alf = (ub - Uh[i]) / (ua - Uh[i])
                        Qw[i] = alf * Qw[i] + (1.0 - alf) * Qw[i - 1]
                    if j >= lbz:
                        if j - tr <= kind - ph + oldr:
                            gam = (ub - Uh[j - tr]) / den
                            ebpts[kj] = gam * ebpts[kj] + (1.0 - gam) * ebpts[kj + 1]
                        else:
                            ebpts[kj] = bet * ebpts[kj] + (1.0 - bet) * ebpts[kj + 1]
                    i += 1
                    j -= 1
                    kj -= 1
                first -= 1
                last += 1
        if a != p:
            # load the knot ua
            Uh[kind: kind + ph - oldr] = ua
            kind += ph - oldr
        Qw[cind: cind + rbz - lbz + 1] = ebpts[lbz: rbz + 1]
        cind += rbz - lbz + 1
        if b < m:
            # set up the next segment
            bpts[:r] = Nextbpts[:r]
            bpts[r:] = Pw[b - p + r: b + 1]
            a = b
            b += 1
            ua = ub
        else:
            Uh[kind: kind + ph + 1] = ub
    nh = mh - ph - 1
    assert nh + 1 == Qw.shape[0] and cind == Qw.shape[0], "A5.9 size bookkeeping"
    return Uh, Qw


def curve_split(p: int, U, Pw, u: float):
    """Split a curve at ``u`` (strictly inside the domain) into two curves.

    ``u`` is inserted up to multiplicity ``p``; the shared control point lies on the curve.

    Returns
    -------
    (U_left, Qw_left), (U_right, Qw_right) : knot vectors on ``[U[0], u]`` and ``[u, U[-1]]``
    and their control nets, (j, ...) and (N - j + 1, ...) with ``N`` the refined point count
    """
    U = np.asarray(U, dtype=float)
    u = _check_interior("knot", p, U, u)
    s = _multiplicity(U, u)
    Ubar, Qw = curve_insert_knot(p, U, Pw, u, p - s)
    j = int(np.searchsorted(Ubar, u, side="left"))  # first occurrence of u in Ubar
    left = (np.concatenate([Ubar[: j + p], [u]]), Qw[:j].copy())
    right = (np.concatenate([[u], Ubar[j:]]), Qw[j - 1:].copy())
    return left, right


# ----------------------------------------------------------------------------------------
# surfaces
# ----------------------------------------------------------------------------------------
def _net_along(surface: NurbsSurface, direction: int) -> tuple[int, np.ndarray, np.ndarray]:
    """Degree, knot vector and control net with ``direction`` as axis 0 (n, m, 4)."""
    if direction == 0:
        return surface.degree[0], surface.knots_u, surface.control
    return surface.degree[1], surface.knots_v, surface.control.transpose(1, 0, 2)


def _rebuild(surface: NurbsSurface, direction: int, degree: int, knots, net) -> NurbsSurface:
    """Inverse of :func:`_net_along`: a new surface with the given data in ``direction``."""
    p, q = surface.degree
    if direction == 0:
        return NurbsSurface((degree, q), knots, surface.knots_v, net)
    return NurbsSurface((p, degree), surface.knots_u, knots, net.transpose(1, 0, 2))


def insert_knot(surface: NurbsSurface, direction: int, knot: float, times: int = 1) -> NurbsSurface:
    """A5.3 SurfaceKnotIns: the same surface with ``knot`` inserted ``times`` times in
    ``direction`` (0: u, 1: v).

    The knot must lie strictly inside the domain, and its multiplicity after insertion must
    not exceed the degree (:class:`InputError` otherwise). The net grows by ``times`` rows.
    """
    direction = _check_direction(direction)
    p, U, Pw = _net_along(surface, direction)
    Ubar, Qw = curve_insert_knot(p, U, Pw, knot, times)
    return _rebuild(surface, direction, p, Ubar, Qw)


def refine_knots(surface: NurbsSurface, direction: int, new_knots) -> NurbsSurface:
    """A5.5 RefineKnotVectSurface: the same surface with all ``new_knots`` inserted in
    ``direction`` (0: u, 1: v). See :func:`curve_refine_knots` for the rules on the knots."""
    direction = _check_direction(direction)
    p, U, Pw = _net_along(surface, direction)
    Ubar, Qw = curve_refine_knots(p, U, Pw, new_knots)
    return _rebuild(surface, direction, p, Ubar, Qw)


def elevate_degree(surface: NurbsSurface, direction: int, times: int = 1) -> NurbsSurface:
    """The same surface with its degree in ``direction`` (0: u, 1: v) raised by ``times``:
    A5.9 DegreeElevateCurve applied to every row of the homogeneous net. Every distinct knot
    of that direction gains ``times`` in multiplicity (continuity is kept)."""
    direction = _check_direction(direction)
    p, U, Pw = _net_along(surface, direction)
    Uh, Qw = curve_elevate_degree(p, U, Pw, times)
    return _rebuild(surface, direction, p + _check_count("times", times), Uh, Qw)


def split(surface: NurbsSurface, direction: int, knot: float) -> tuple[NurbsSurface, NurbsSurface]:
    """Split at ``knot`` (strictly inside the domain) in ``direction`` (0: u, 1: v) into the
    pieces on ``[a, knot]`` and ``[knot, b]``; each keeps the original parametrization."""
    direction = _check_direction(direction)
    p, U, Pw = _net_along(surface, direction)
    (UL, QL), (UR, QR) = curve_split(p, U, Pw, knot)
    return (_rebuild(surface, direction, p, UL, QL), _rebuild(surface, direction, p, UR, QR))


def _bezier_segments(p: int, U: np.ndarray, Pw: np.ndarray):
    """Bezier extraction along axis 0: every interior knot raised to multiplicity ``p``.

    Returns the refined net (N, ...) and the list of (start row, (u0, u1)) per segment; the
    rows of segment ``i`` are ``start .. start + p``.
    """
    breaks, counts = np.unique(U[p + 1: -p - 1], return_counts=True)
    X = np.repeat(breaks, p - counts)
    _, Qw = curve_refine_knots(p, U, Pw, X)
    edges = np.concatenate([[U[0]], breaks, [U[-1]]])
    return Qw, [(i * p, (float(edges[i]), float(edges[i + 1]))) for i in range(edges.size - 1)]


def bezier_patches(surface: NurbsSurface) -> list[tuple[NurbsSurface, tuple[float, float], tuple[float, float]]]:
    """Bezier decomposition: one piece per non-empty knot span ``[u0, u1] x [v0, v1]``.

    Every interior knot is raised to full multiplicity (the degree) and the net is sliced.
    Each piece has ``(p + 1, q + 1)`` control points and the knot vectors
    ``(u0,)*(p+1) + (u1,)*(p+1)`` and ``(v0,)*(q+1) + (v1,)*(q+1)``, so that it evaluates at
    ``(u, v)`` to the whole surface at ``(u, v)``.

    Returns
    -------
    list of ``(piece, (u0, u1), (v0, v1))``, u-spans outer, v-spans inner
    """
    p, q = surface.degree
    net, seg_u = _bezier_segments(p, surface.knots_u, surface.control)
    net, seg_v = _bezier_segments(q, surface.knots_v, net.transpose(1, 0, 2))
    net = net.transpose(1, 0, 2)
    pieces = []
    for iu, (u0, u1) in seg_u:
        for iv, (v0, v1) in seg_v:
            piece = NurbsSurface((p, q),
                                 np.repeat([u0, u1], p + 1),
                                 np.repeat([v0, v1], q + 1),
                                 net[iu: iu + p + 1, iv: iv + q + 1].copy())
            pieces.append((piece, (u0, u1), (v0, v1)))
    return pieces
