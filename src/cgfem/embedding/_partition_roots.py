"""Root machinery of the partition kernels (:mod:`cgfem.embedding._partition_kernels`).

A cell of a Bezier piece is integrable when every grid plane that cuts it is, along one
common inner direction, strictly monotone (its zero set is a graph over the outer
direction) or constant (its zero set is a line ``outer = const``): :func:`_classify`
decides it from Bernstein coefficients. The other kernels find the roots of those planes on
inner lines, where two graph roots cross, and the sums of roots the adaptive outer
integration checks. Kept apart from the integration driver only for size; the caveat of
numba caching across modules applies (clear ``__pycache__`` after editing one of them).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cgfem.embedding._bernstein import _inner_root

#: smallest derivative coefficient, relative to the largest, of a monotone function
MONOTONE_MARGIN = 0.1
#: steepest zero curve (cell coordinates) integrated along a direction; steeper: the other
MAX_SLOPE = np.inf

@njit(cache=True)
def _classify(cnet, fk, fc, nf, inner, kinds):
    """For each function: 1 if its zero curve is a graph over the outer direction with a
    bounded slope, 2 if the function is constant along ``inner``; returns False if some
    function is neither (the cell is then split, or the other direction tried).

    Graph: every Bernstein coefficient of the inner derivative has one sign and exceeds
    ``MONOTONE_MARGIN`` times the largest (a derivative that vanishes on a cell edge, such
    as a fold on a knot line, is not taken for monotone on round-off), and the bound
    ``max |F_outer| / min |F_inner| <= MAX_SLOPE`` holds on the cell: a steep curve is
    integrated along the other direction, where it is flat.
    """
    p = cnet.shape[0] - 1
    q = cnet.shape[1] - 1
    for f in range(nf):
        k = fk[f]
        c = fc[f]
        big = 0.0
        dmax = 0.0
        omax = 0.0
        for i in range(p + 1):
            for j in range(q + 1):
                v = cnet[i, j, k] - c * cnet[i, j, 3]
                big = max(big, abs(v))
                if j < q:
                    dq = q * abs((cnet[i, j + 1, k] - c * cnet[i, j + 1, 3]) - v)
                    if inner == 1:
                        dmax = max(dmax, dq)
                    else:
                        omax = max(omax, dq)
                if i < p:
                    dp = p * abs((cnet[i + 1, j, k] - c * cnet[i + 1, j, 3]) - v)
                    if inner == 0:
                        dmax = max(dmax, dp)
                    else:
                        omax = max(omax, dp)
        # constant along inner: the Cartesian control coordinates x_k do not change along it
        # (with tensor-product weights the surface coordinate then does not depend on it)
        cvar = 0.0
        cbig = abs(c)
        for i in range(p + 1):
            for j in range(q + 1):
                xk = cnet[i, j, k] / cnet[i, j, 3]
                cbig = max(cbig, abs(xk))
                if inner == 1 and j < q:
                    cvar = max(cvar, abs(cnet[i, j + 1, k] / cnet[i, j + 1, 3] - xk))
                elif inner == 0 and i < p:
                    cvar = max(cvar, abs(cnet[i + 1, j, k] / cnet[i + 1, j, 3] - xk))
        if dmax <= 1e-13 * big or cvar <= 1e-14 * cbig:
            kinds[f] = 2
            continue
        pos = True
        neg = True
        dmin = np.inf
        margin = MONOTONE_MARGIN * dmax
        for i in range(p + 1):
            for j in range(q + 1):
                if inner == 1 and j < q:
                    d = q * ((cnet[i, j + 1, k] - c * cnet[i, j + 1, 3]) - (cnet[i, j, k] - c * cnet[i, j, 3]))
                elif inner == 0 and i < p:
                    d = p * ((cnet[i + 1, j, k] - c * cnet[i + 1, j, 3]) - (cnet[i, j, k] - c * cnet[i, j, 3]))
                else:
                    continue
                dmin = min(dmin, abs(d))
                if not d > margin:
                    pos = False
                if not d < -margin:
                    neg = False
        if (pos or neg) and omax <= MAX_SLOPE * dmin:
            kinds[f] = 1
        else:
            return False
    return True


@njit(cache=True)
def _boundary_coef(onet, f_k, f_c, side, coef):
    """Coefficients along the outer direction of ``x_k - c`` (times w) on the cell's inner
    boundary ``side`` (0: first, 1: last) of the outer-major cell net ``onet``."""
    j = 0 if side == 0 else onet.shape[1] - 1
    for i in range(onet.shape[0]):
        coef[i] = onet[i, j, f_k] - f_c * onet[i, j, 3]


@njit(cache=True)
def _roots_at(pn, fk, fc, kinds, nf, sigma, ia, ib, coef, rts, rfs):
    """Sorted inner roots of the graph functions on the inner line ``sigma``."""
    n = 0
    for f in range(nf):
        if kinds[f] != 1:
            continue
        r = _inner_root(pn, fk[f], fc[f], sigma, ia, ib, coef)
        if r >= 0.0:
            rts[n] = r
            rfs[n] = f
            n += 1
    for i in range(1, n):
        v = rts[i]
        fv = rfs[i]
        j = i - 1
        while j >= 0 and rts[j] > v:
            rts[j + 1] = rts[j]
            rfs[j + 1] = rfs[j]
            j -= 1
        rts[j + 1] = v
        rfs[j + 1] = fv
    return n


@njit(cache=True)
def _line_segments(pn, fk, fc, kinds, nf, sigma, ia, ib, icoef, rts, rfs, seg):
    """Split the inner line ``sigma`` at the sorted roots of the graph functions: ``seg``
    receives ``ia, roots..., ib``; returns the number of roots."""
    n = _roots_at(pn, fk, fc, kinds, nf, sigma, ia, ib, icoef, rts, rfs)
    seg[0] = ia
    for r in range(n):
        seg[r + 1] = rts[r]
    seg[n + 1] = ib
    return n


@njit(cache=True)
def _crossing(pn, ka, ca, kb, cb, lo, hi, ia, ib, coef):
    """Outer coordinate in ``[lo, hi]`` where the inner roots of two planes coincide (their
    difference changes sign between ``lo`` and ``hi``), by the Illinois method."""
    ra = _inner_root(pn, ka, ca, lo, ia, ib, coef)
    rb = _inner_root(pn, kb, cb, lo, ia, ib, coef)
    dlo = ra - rb
    ra = _inner_root(pn, ka, ca, hi, ia, ib, coef)
    rb = _inner_root(pn, kb, cb, hi, ia, ib, coef)
    dhi = ra - rb
    side = 0
    x = 0.5 * (lo + hi)
    for _ in range(200):
        x = (lo * dhi - hi * dlo) / (dhi - dlo) if dhi != dlo else 0.5 * (lo + hi)
        if not (lo < x < hi):
            x = 0.5 * (lo + hi)
        ra = _inner_root(pn, ka, ca, x, ia, ib, coef)
        rb = _inner_root(pn, kb, cb, x, ia, ib, coef)
        d = ra - rb
        if d == 0.0 or hi - lo <= 1e-15 * max(1.0, abs(x)):
            return x
        if (d > 0.0) == (dlo > 0.0):
            lo = x
            dlo = d
            if side == -1:
                dhi *= 0.5
            side = -1
        else:
            hi = x
            dhi = d
            if side == 1:
                dlo *= 0.5
            side = 1
    return x


@njit(cache=True)
def _map_st(sigma, tau, swapped):
    if swapped:
        return tau, sigma
    return sigma, tau


@njit(cache=True)
def _root_sum(pn, fk, fc, kinds, nf, a, b, n, GX, GW, ia, ib, icoef, rts, rfs):
    """n-point Gauss integral over ``[a, b]`` of the sum of the inner roots."""
    total = 0.0
    for g in range(n):
        sigma = a + GX[n, g] * (b - a)
        nr = _roots_at(pn, fk, fc, kinds, nf, sigma, ia, ib, icoef, rts, rfs)
        acc = 0.0
        for r in range(nr):
            acc += rts[r]
        total += GW[n, g] * (b - a) * acc
    return total
