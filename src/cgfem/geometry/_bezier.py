"""Numba kernels evaluating rational Bezier patches (the leaves of :mod:`cgfem.geometry.bvh`
and the pieces of :mod:`cgfem.embedding.partition`) on their local square ``(s, t)`` in
``[0, 1]^2``.

A patch is a homogeneous net ``net`` of shape ``(p + 1, q + 1, 4)``, rows ``(w x, w y, w z,
w)``. Derivatives are in the layout of *The NURBS Book*: ``SKL[k, l]`` (3-vector) is
``d^{k+l} S / ds^k dt^l`` for ``k + l <= d``. The homogeneous derivatives are the B-spline
kernels' (:func:`~cgfem.geometry._nurbs_kernels.contract_net`) with the Bernstein basis, and
the quotient rule is A4.4 (:func:`~cgfem.geometry._nurbs_kernels.rat_surface_derivs`): one
evaluator for NURBS surfaces and Bezier patches.

Nothing here allocates per evaluation: the scratch arrays travel in a :class:`BezierWork`
made once per thread by :func:`bezier_work`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cgfem.geometry._nurbs_kernels import contract_net, rat_surface_derivs

#: Highest derivative order of :func:`bezier_derivs`.
MAX_ORDER = 2
#: Most Newton iterations on one leaf (closest point and ray queries).
MAX_NEWTON = 60
#: Depth of the explicit stack of a BVH traversal.
STACK = 128
#: Query points (or rays) per parallel task of the query kernels.
CHUNK = 256


class BezierWork(NamedTuple):
    """Scratch of :func:`bezier_derivs` for degrees up to ``pmax`` (numba takes it as a
    tuple): ``Bu``, ``Bv`` (3, pmax + 1) Bernstein derivatives, ``temp`` (pmax + 1, 4),
    ``SKLw`` (3, 3, 4) homogeneous derivatives, ``SKL`` (3, 3, 3) free for the caller."""

    Bu: np.ndarray
    Bv: np.ndarray
    temp: np.ndarray
    SKLw: np.ndarray
    SKL: np.ndarray


@njit(cache=True)
def bezier_work(pmax):
    """A :class:`BezierWork` for nets of degree up to ``pmax`` in each direction."""
    n = MAX_ORDER + 1
    return BezierWork(np.empty((n, pmax + 1)), np.empty((n, pmax + 1)), np.empty((pmax + 1, 4)),
                      np.empty((n, n, 4)), np.empty((n, n, 3)))


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
def bernstein_values(p, x, N):
    """Bernstein basis ``B_{i,p}(x)``, ``i <= p``, into ``N`` (>= p + 1,) (degree raising)."""
    N[0] = 1.0
    for k in range(1, p + 1):
        _raise_degree(N, k, x, 1.0 - x)


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


@njit(cache=True, inline='always')
def bezier_derivs(net, s, t, d, work, SKL):
    """Rational Bezier patch ``net`` (p + 1, q + 1, 4) and its derivatives up to order
    ``d <= 2`` at ``(s, t)`` into ``SKL`` (>= d + 1, >= d + 1, 3), entries ``k + l <= d``
    (others untouched). ``work``: a :class:`BezierWork` of degree >= p, q."""
    p = net.shape[0] - 1
    q = net.shape[1] - 1
    bernstein_ders(p, s, d, work.Bu)
    bernstein_ders(q, t, d, work.Bv)
    contract_net(net, 0, 0, work.Bu, work.Bv, p, q, d, work.temp, work.SKLw)
    rat_surface_derivs(work.SKLw, d, SKL)


@njit(cache=True)
def leaf_net(ctrl, off, p, q):
    """The net (p + 1, q + 1, 4) of a leaf stored row-major from row ``off`` of ``ctrl``
    (a view, see :mod:`cgfem.geometry.bvh`)."""
    return ctrl[off:off + (p + 1) * (q + 1)].reshape((p + 1, q + 1, 4))


@njit(cache=True)
def cross_into(a, b, sign, out):
    """``out = sign (a x b)`` (3,); returns ``|out|``."""
    out[0] = sign * (a[1] * b[2] - a[2] * b[1])
    out[1] = sign * (a[2] * b[0] - a[0] * b[2])
    out[2] = sign * (a[0] * b[1] - a[1] * b[0])
    return np.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2)


@njit(cache=True)
def norm3(a):
    return np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True)
def dist2(a, x):
    """``|a - x|^2`` of two 3-vectors."""
    return (a[0] - x[0]) ** 2 + (a[1] - x[1]) ** 2 + (a[2] - x[2]) ** 2


@njit(cache=True)
def clamp01(a):
    return 0.0 if a < 0.0 else (1.0 if a > 1.0 else a)


@njit(cache=True)
def leaf_normal(net, s, t, D, work, E, n):
    """Outward unit normal ``S_s x S_t / |S_s x S_t|`` at ``(s, t)`` into ``n`` (3,); ``D``
    (3, 3, 3) holds the derivatives up to order 2 at ``(s, t)``. At a collapsed edge
    (``S_s = 0`` along ``t = 0`` or ``1``, or ``S_t = 0`` along ``s = 0`` or ``1``) the limit
    from inside the leaf, ``S_s ~ (t - t_e) S_st`` (L'Hopital); failing that, the normal a
    little inside. Returns ``False`` if no normal was found. Scratch: ``work``, ``E`` (3, 3, 3)."""
    ls = norm3(D[1, 0])
    lt = norm3(D[0, 1])
    big = max(ls, lt)
    ln = cross_into(D[1, 0], D[0, 1], 1.0, n)
    if ln > 1e-10 * big * big and ln > 0.0:
        for c in range(3):
            n[c] /= ln
        return True
    edge = 1e-6
    if ls < lt and (t < edge or t > 1.0 - edge):
        ln = cross_into(D[1, 1], D[0, 1], 1.0 if t < 0.5 else -1.0, n)
        ok = ln > 1e-8 * norm3(D[1, 1]) * lt
    elif lt <= ls and (s < edge or s > 1.0 - edge):
        ln = cross_into(D[1, 0], D[1, 1], 1.0 if s < 0.5 else -1.0, n)
        ok = ln > 1e-8 * norm3(D[1, 1]) * ls
    else:
        ok = False
    if ok and ln > 0.0:
        for c in range(3):
            n[c] /= ln
        return True
    for attempt in range(4):
        step = 1e-6 * 100.0 ** attempt
        bezier_derivs(net, s + step * (0.5 - s), t + step * (0.5 - t), 1, work, E)
        ln = cross_into(E[1, 0], E[0, 1], 1.0, n)
        big = max(norm3(E[1, 0]), norm3(E[0, 1]))
        if ln > 1e-10 * big * big and ln > 0.0:
            for c in range(3):
                n[c] /= ln
            return True
    for c in range(3):
        n[c] = 0.0
    return False


@njit(cache=True)
def leaf_points_normals(leaf_degree, leaf_offset, ctrl, leaf, st, point, normal):
    """Points (m, 3) and unit normals (m, 3) of leaves ``leaf`` (m,) at local parameters
    ``st`` (m, 2)."""
    work = bezier_work(leaf_degree.max() if leaf_degree.size else 1)
    D = np.empty((3, 3, 3))
    E = np.empty((3, 3, 3))
    for k in range(leaf.shape[0]):
        lf = leaf[k]
        net = leaf_net(ctrl, leaf_offset[lf], leaf_degree[lf, 0], leaf_degree[lf, 1])
        bezier_derivs(net, st[k, 0], st[k, 1], 2, work, D)
        for c in range(3):
            point[k, c] = D[0, 0, c]
        leaf_normal(net, st[k, 0], st[k, 1], D, work, E, normal[k])
