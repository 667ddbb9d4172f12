"""Monomial moments of cut elements from their boundary (divergence theorem), a reference for
the volume rules of :mod:`cgfem.embedding.columns` that shares none of their code.

In the local coordinates ``xi = (x - centre) / (h / 2)`` of an element, the moment
``mu_abc = int_V xi_0^a xi_1^b xi_2^c dV / (h / 2)^3`` of its material part ``V`` is, for any
axis ``k`` and side ``s = +-1``, with ``P(t) = (t^(a_k + 1) - s^(a_k + 1)) / (a_k + 1)`` (zero on
the face ``xi_k = s``),

    mu = sum_surface P(xi_k) prod_{j != k} xi_j^(a_j) n_k dA  +  P(-s) (-s) F_{-s}

over the element's piece of boundary and its face ``xi_k = -s``, where ``F`` is the face
region's moment of the other two monomials. ``F`` follows the same way in the face plane from
the trimming curves (in-plane normal ``m``) and the material intervals of one face edge (a
grid line), integrated in closed form. Of the six choices of ``(k, s)`` (and four per face)
the one whose terms cancel least is kept: for a sliver along the face ``xi_k = s`` the
surface terms are then of the size of the sliver, not of the element.
"""

from __future__ import annotations

import numpy as np

from cgfem.embedding.columns import LineHits
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.lines import line_axes
from cgfem.embedding.partition import TrimQuadrature


def _powers(t: np.ndarray, degree: int) -> np.ndarray:
    """``t^a`` for ``a = 0..degree`` -> (len(t), degree + 1)."""
    return np.asarray(t, float)[:, None] ** np.arange(degree + 1)[None, :]


def _anti(t: np.ndarray, degree: int, s: float) -> np.ndarray:
    """``(t^(a + 1) - s^(a + 1)) / (a + 1)`` for ``a = 0..degree`` -> (len(t), degree + 1)."""
    a = np.arange(degree + 1)
    return (np.asarray(t, float)[:, None] ** (a + 1) - s ** (a + 1)) / (a + 1)


def rule_moments(grid: CartesianGrid, elements: np.ndarray, x: np.ndarray, w: np.ndarray,
                 element: np.ndarray, degree: int, dim: int = 3) -> np.ndarray:
    """Monomial moments (len(elements), n, n, n), ``n = degree + 1``, of the rule ``x, w``
    summed per owning ``element`` (rows of ``elements``, sorted; other points ignored), in
    each element's local coordinates, weights divided by ``(h / 2)^dim``."""
    elements = np.asarray(elements)
    rows = np.searchsorted(elements, element)
    ok = (rows < elements.size) & (elements[np.minimum(rows, elements.size - 1)] == element)
    xi = (x[ok] - grid.element_center(grid.element_ijk(element[ok]))) / (0.5 * grid.h)
    p = [_powers(xi[:, d], degree) for d in range(3)]
    out = np.zeros((elements.size,) + (degree + 1,) * 3)
    np.add.at(out, rows[ok], np.einsum("i,ia,ib,ic->iabc", w[ok] / (0.5 * grid.h) ** dim, *p))
    return out


def _face_moments(grid: CartesianGrid, ijk: np.ndarray, k: int, side: int, trims: TrimQuadrature,
                  lines: LineHits, degree: int) -> tuple[np.ndarray, float]:
    """Moments (n, n) of the material region of the face ``xi_k = side`` of element ``ijk``
    (monomials of the in-plane axes ``(u, v)``, ``u < v``, local 2D units) and the absolute
    mass of the terms of the least cancelling choice."""
    n = degree + 1
    axes = [d for d in range(3) if d != k]
    below = ijk.copy()
    below[k] += 0 if side > 0 else -1           # the element whose +k face this is
    if below[k] < 0:
        return np.zeros((n, n)), 0.0
    owner = grid.element_id(below[None])[0]
    on = (trims.axis == k) & (trims.element == owner)
    centre = grid.element_center(ijk[None])[0]
    half = 0.5 * grid.h
    tx = (trims.x[on] - centre) / half
    tw = trims.w[on] / half
    best, best_mass = None, np.inf
    for iu, u in enumerate(axes):
        v = axes[1 - iu]
        for t in (-1.0, 1.0):
            terms = np.einsum("i,ia,ib->iab", tw * trims.normal[on, u], _anti(tx[:, u], degree, t),
                              _powers(tx[:, v], degree))
            moments = terms.sum(axis=0)
            mass = np.abs(terms[:, 0, 0]).sum()
            # the edge xi_u = -t of the face: the grid line along v
            nodes = ijk.copy()
            nodes[k] += 1 if side > 0 else 0
            nodes[u] += 1 if t < 0 else 0
            b, c = line_axes(v)
            line = nodes[b] * grid.node_shape[c] + nodes[c]
            hits = lines.coord[v][lines.offsets[v][line]:lines.offsets[v][line + 1]].reshape(-1, 2)
            lo = grid.plane(v, ijk[v])
            z0 = (np.clip(hits[:, 0], lo, lo + grid.h) - centre[v]) / half
            z1 = (np.clip(hits[:, 1], lo, lo + grid.h) - centre[v]) / half
            a = np.arange(n)
            edge = ((z1[:, None] ** (a + 1) - z0[:, None] ** (a + 1)) / (a + 1)).sum(axis=0)
            scale = (-t) * _anti(np.array([-t]), degree, t)[0]     # P(-t) times the normal -t
            edge_terms = scale[:, None] * edge[None, :]
            moments = moments + edge_terms
            mass += abs(edge_terms[0, 0])
            if iu == 1:   # moments indexed (a_v, a_u): back to (a_first, a_second)
                moments = moments.T
            if mass < best_mass:
                best, best_mass = moments, mass
    return best, best_mass


def divergence_moments(grid: CartesianGrid, elements: np.ndarray, surface, trims: TrimQuadrature,
                       lines: LineHits, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Monomial moments (m, n, n, n) of the material parts of ``elements`` (sorted ids) from
    the boundary rule ``surface`` (x, w, normal, element), the trimming rules ``trims`` of the
    grid planes and the grid lines' material intervals ``lines`` (module docstring), and the
    spread (m,): the largest difference of a moment between the two least cancelling
    choices of axis and side (exact boundary rules give equal moments: an estimate of the
    reference's own error)."""
    elements = np.asarray(elements, np.int64)
    n = degree + 1
    half = 0.5 * grid.h
    order = np.argsort(surface.element, kind="stable")
    s_el = surface.element[order]
    out = np.zeros((elements.size, n, n, n))
    spread = np.zeros(elements.size)
    for r, e in enumerate(elements):
        rows = order[np.searchsorted(s_el, e):np.searchsorted(s_el, e, side="right")]
        ijk = grid.element_ijk(np.array([e]))[0]
        xi = (surface.x[rows] - grid.element_center(ijk[None])[0]) / half
        wn = surface.w[rows] / half**2
        p = [_powers(xi[:, d], degree) for d in range(3)]
        estimates, masses = [], []
        for k in range(3):
            for s in (-1.0, 1.0):
                factors = list(p)
                factors[k] = _anti(xi[:, k], degree, s)
                terms = np.einsum("i,ia,ib,ic->iabc", wn * surface.normal[rows, k], *factors)
                moments = terms.sum(axis=0)
                mass = np.abs(terms[:, 0, 0, 0]).sum()
                face, face_mass = _face_moments(grid, ijk, k, -int(s), trims, lines, degree)
                scale = (-s) * _anti(np.array([-s]), degree, s)[0]       # P(-s) times the normal -s
                shape = [1, 1, 1]
                shape[k] = n
                full = np.expand_dims(face, k) * scale.reshape(shape)
                moments = moments + full
                mass += abs(scale[0]) * face_mass
                estimates.append(moments)
                masses.append(mass)
        first, second = np.argsort(masses)[:2]
        out[r] = estimates[first]
        spread[r] = np.abs(estimates[first] - estimates[second]).max()
    return out, spread
