"""Numba kernels on Bernstein (Bezier) polynomials and rational Bezier patches.

Local coordinates are ``[0, 1]``; a rational patch is a homogeneous net ``(p + 1, q + 1, 4)``
of ``(w x, w y, w z, w)``. Used by :mod:`cgfem.embedding._partition_kernels`; rational evaluation is
:mod:`cgfem.geometry._bezier`'s. (numba's cache follows the imports: :mod:`cgfem._numba_cache`.)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cgfem.geometry._bezier import bernstein_values, bezier_derivs, bezier_work


@njit(cache=True)
def point_derivs(net, s, t, work, x, xs, xt):
    """Rational point ``x`` and first derivatives ``xs, xt`` (3,) of the Bernstein net ``net``
    (p + 1, q + 1, 4) at local ``(s, t)``: :func:`~cgfem.geometry._bezier.bezier_derivs` of
    order 1 with the scratch ``work`` (a :class:`~cgfem.geometry._bezier.BezierWork`)."""
    D = work.SKL
    bezier_derivs(net, s, t, 1, work, D)
    for c in range(3):
        x[c] = D[0, 0, c]
        xs[c] = D[1, 0, c]
        xt[c] = D[0, 1, c]


@njit(cache=True)
def net_work(net):
    """A :class:`~cgfem.geometry._bezier.BezierWork` for ``net`` (either orientation)."""
    return bezier_work(max(net.shape[0], net.shape[1]) - 1)


@njit(cache=True)
def _split_net(net, axis, a):
    """de Casteljau subdivision of ``net`` at local ``a`` along ``axis`` (0 or 1)."""
    left = net.copy()
    right = net.copy()
    n = net.shape[axis] - 1
    other = net.shape[1 - axis]
    tmp = np.empty((n + 1, 4))
    for o in range(other):
        for i in range(n + 1):
            for c in range(4):
                tmp[i, c] = net[i, o, c] if axis == 0 else net[o, i, c]
        for r in range(n + 1):
            for c in range(4):
                if axis == 0:
                    left[r, o, c] = tmp[0, c]
                    right[n - r, o, c] = tmp[n - r, c]
                else:
                    left[o, r, c] = tmp[0, c]
                    right[o, n - r, c] = tmp[n - r, c]
            for i in range(n - r):
                for c in range(4):
                    tmp[i, c] = (1.0 - a) * tmp[i, c] + a * tmp[i + 1, c]
    return left, right


@njit(cache=True)
def _casteljau(coef, x):
    """Value and derivative of the univariate Bernstein polynomial ``coef`` at ``x``."""
    n = coef.shape[0] - 1
    if n == 0:
        return coef[0], 0.0
    b = coef.copy()
    for r in range(1, n):
        for i in range(n - r + 1):
            b[i] = (1.0 - x) * b[i] + x * b[i + 1]
    value = (1.0 - x) * b[0] + x * b[1]
    return value, n * (b[1] - b[0])


@njit(cache=True)
def _bracketed_root(coef, lo, hi):
    """The root of ``coef`` in ``[lo, hi]`` (values of opposite sign at the ends), by
    Newton steps safeguarded with bisection."""
    flo, _ = _casteljau(coef, lo)
    x = 0.5 * (lo + hi)
    for _ in range(100):
        f, df = _casteljau(coef, x)
        if f == 0.0:
            return x
        if (f < 0.0) == (flo < 0.0):
            lo = x
            flo = f
        else:
            hi = x
        xn = x - f / df if df != 0.0 else 0.5 * (lo + hi)
        if not (lo < xn < hi):
            xn = 0.5 * (lo + hi)
        if abs(xn - x) <= 1e-16 + 2e-16 * abs(x) or hi - lo <= 4e-16:
            return xn
        x = xn
    return x


@njit(cache=True)
def _sign_changes(coef):
    changes = 0
    prev = coef[0] >= 0.0
    for i in range(1, coef.shape[0]):
        cur = coef[i] >= 0.0
        if cur != prev:
            changes += 1
        prev = cur
    return changes


@njit(cache=True)
def univariate_roots(coef, roots):
    """Roots in ``[0, 1)`` of the Bernstein polynomial ``coef`` (ascending) into ``roots``;
    returns their number. Isolation by subdivision (a single sign change of the Bernstein
    coefficients means exactly one root), refinement by safeguarded Newton."""
    n = coef.shape[0] - 1
    count = 0
    stack_c = np.empty((64, n + 1))
    stack_a = np.empty(64)
    stack_b = np.empty(64)
    stack_d = np.empty(64, np.int64)
    top = 0
    stack_c[0] = coef
    stack_a[0] = 0.0
    stack_b[0] = 1.0
    stack_d[0] = 0
    top = 1
    while top > 0:
        top -= 1
        c = stack_c[top].copy()
        a = stack_a[top]
        b = stack_b[top]
        d = stack_d[top]
        ch = _sign_changes(c)
        if ch == 0:
            continue
        if ch == 1 or d >= 48:
            if ch == 1:
                r = _bracketed_root(c, 0.0, 1.0)
            else:
                r = 0.5
            x = a + r * (b - a)
            if x < 1.0 and count < roots.shape[0]:
                roots[count] = x
                count += 1
            continue
        # split at the middle: right half pushed first so the left is processed first
        left = c.copy()
        right = c.copy()
        tmp = c.copy()
        for r in range(n + 1):
            left[r] = tmp[0]
            right[n - r] = tmp[n - r]
            for i in range(n - r):
                tmp[i] = 0.5 * (tmp[i] + tmp[i + 1])
        m = 0.5 * (a + b)
        if top + 2 > 64:
            continue
        stack_c[top] = right
        stack_a[top] = m
        stack_b[top] = b
        stack_d[top] = d + 1
        top += 1
        stack_c[top] = left
        stack_a[top] = a
        stack_b[top] = m
        stack_d[top] = d + 1
        top += 1
    # ascending order
    for i in range(1, count):
        v = roots[i]
        j = i - 1
        while j >= 0 and roots[j] > v:
            roots[j + 1] = roots[j]
            j -= 1
        roots[j + 1] = v
    return count


@njit(cache=True)
def _line_coef(pnet, axis_k, c, sigma, coef):
    """Bernstein coefficients along the inner direction of ``x_k - c`` (times w) on the
    line ``outer = sigma`` of the (possibly transposed) piece net ``pnet``."""
    p = pnet.shape[0] - 1
    q = pnet.shape[1] - 1
    B = np.empty(p + 1)
    bernstein_values(p, sigma, B)
    for j in range(q + 1):
        acc = 0.0
        for i in range(p + 1):
            acc += B[i] * (pnet[i, j, axis_k] - c * pnet[i, j, 3])
        coef[j] = acc


@njit(cache=True)
def _inner_root(pnet, axis_k, c, sigma, lo, hi, coef):
    """Root in ``[lo, hi]`` of plane ``x_k = c`` on the inner line at ``sigma``, or -1 if
    the values at ``lo`` and ``hi`` have the same sign."""
    _line_coef(pnet, axis_k, c, sigma, coef)
    flo, _ = _casteljau(coef, lo)
    fhi, _ = _casteljau(coef, hi)
    if (flo >= 0.0) == (fhi >= 0.0):
        return -1.0
    return _bracketed_root(coef, lo, hi)
