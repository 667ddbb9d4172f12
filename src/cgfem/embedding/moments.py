"""Volume quadrature of cut elements from exact moments (divergence theorem + moment fitting).

For a cut element with local coordinates ``xi = (x - x_c) / (h / 2)`` in ``[-1, 1]^3`` and
the tensor Legendre polynomials ``L_a(xi) L_b(eta) L_c(zeta)`` (``a, b, c < n``), the moments
over the material part ``V`` follow from two applications of the divergence theorem:

    int_V L_a L_b L_c = oint_{dV} A_a(xi) L_b L_c n_xi dA                      (3D)
                      = sum_surface A_a L_b L_c n_x w  +  2 delta_a0 int_{F+} L_b L_c dA
    int_{F+} L_b L_c  = sum_trim B_b(eta) L_c(zeta) m_y w  +  2 delta_b0 int_{E+} L_c dzeta  (2D)

with ``A_a = B_a`` the antiderivative of ``L_a`` from -1 (it vanishes on the faces
``xi = -1`` and ``eta = -1``), ``F+`` the material part of the face ``xi = +1``, and ``E+`` the
material part of that face's edge ``eta = +1`` (a grid line along z). So the boundary
quadrature of the element (surface points, trimming points on its +x face, the inside
intervals of one grid line) gives the moments exactly. The volume rule is then the
``n^3`` tensor Gauss points of the whole cube with weights fitted to the moments; by the
discrete orthogonality of Legendre polynomials at Gauss points the fit is explicit:

    w_q = g_q sum_{abc} M_abc / (c_a c_b c_c) L_a L_b L_c (xi_q),   c_a = 2 / (2a + 1).

It integrates every polynomial of degree < n in each variable exactly over ``V`` (``n = 3``
covers the stiffness and mass integrands of H8 elements); points may lie outside ``V`` and
weights may be negative.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cgfem.embedding.grid import CartesianGrid

#: Gauss points per direction of the fitted rule of a cut element.
DEFAULT_POINTS = 3


def legendre(n: int, x: np.ndarray) -> np.ndarray:
    """``L_0 .. L_{n-1}`` at ``x`` -> (n, *x.shape)."""
    x = np.asarray(x, float)
    out = np.empty((max(n, 2),) + x.shape)
    out[0] = 1.0
    out[1] = x
    for k in range(1, n - 1):
        out[k + 1] = ((2 * k + 1) * x * out[k] - k * out[k - 1]) / (k + 1)
    return out[:n]


def legendre_antiderivative(n: int, x: np.ndarray) -> np.ndarray:
    """``int_{-1}^x L_a`` for ``a < n`` at ``x`` -> (n, *x.shape)."""
    L = legendre(n + 1, x)
    out = np.empty((n,) + np.shape(x))
    out[0] = np.asarray(x, float) + 1.0
    for a in range(1, n):
        out[a] = (L[a + 1] - L[a - 1]) / (2 * a + 1)
    return out


@dataclass(frozen=True)
class VolumeRule:
    """Volume quadrature: points (m, 3), weights (m,), owning element id (m,)."""

    x: np.ndarray
    w: np.ndarray
    element: np.ndarray

    @classmethod
    def empty(cls) -> "VolumeRule":
        return cls(np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64))


def fitted_volume_rule(grid: CartesianGrid, elements: np.ndarray,
                       surf_x, surf_w, surf_nx, surf_element,
                       trim_x, trim_w, trim_my, trim_element,
                       edge_intervals: list[np.ndarray],
                       n: int = DEFAULT_POINTS) -> VolumeRule:
    """Moment-fitted rules of the cut ``elements`` (ids, sorted) from their boundary data.

    ``surf_*``: surface points, area weights, x components of the outward normals and their
    element ids; ``trim_*``: points of the trimming curves on the +x faces, length weights,
    in-plane normal y components, and the element whose +x face holds them;
    ``edge_intervals[e]``: (k, 2) inside intervals ``[z0, z1]`` of the grid line
    ``(x_{i+1}, y_{j+1})`` within the element's z range, for ``elements[e]``.
    """
    elements = np.asarray(elements, np.int64)
    m = elements.size
    if m == 0:
        return VolumeRule.empty()
    h = grid.h
    ijk = grid.element_ijk(elements)
    centre = grid.element_center(ijk)
    moments = np.zeros((m, n, n, n))

    def local(x, rows):
        return (np.asarray(x, float) - centre[rows]) / (0.5 * h)

    # surface term
    rows = np.searchsorted(elements, surf_element)
    ok = (rows < m) & (elements[np.minimum(rows, m - 1)] == surf_element)
    rows = rows[ok]
    xi = local(np.asarray(surf_x)[ok], rows)
    w = (2.0 / h) ** 2 * np.asarray(surf_w)[ok] * np.asarray(surf_nx)[ok]
    A = legendre_antiderivative(n, xi[:, 0])
    Lb = legendre(n, xi[:, 1])
    Lc = legendre(n, xi[:, 2])
    contrib = np.einsum("ap,bp,cp,p->pabc", A, Lb, Lc, w)
    np.add.at(moments, rows, contrib)
    # +x face: trimming curves
    face = np.zeros((m, n, n))
    rows = np.searchsorted(elements, trim_element)
    ok = (rows < m) & (elements[np.minimum(rows, m - 1)] == trim_element)
    rows = rows[ok]
    xi = local(np.asarray(trim_x)[ok], rows)
    w = (2.0 / h) * np.asarray(trim_w)[ok] * np.asarray(trim_my)[ok]
    B = legendre_antiderivative(n, xi[:, 1])
    Lc = legendre(n, xi[:, 2])
    np.add.at(face, rows, np.einsum("bp,cp,p->pbc", B, Lc, w))
    # +x face: its edge eta = +1
    for e, intervals in enumerate(edge_intervals):
        if len(intervals) == 0:
            continue
        zeta = (np.asarray(intervals, float) - centre[e, 2]) / (0.5 * h)
        ints = legendre_antiderivative(n, zeta[:, 1]) - legendre_antiderivative(n, zeta[:, 0])
        face[e, 0, :] += 2.0 * ints.sum(axis=1)
    moments[:, 0, :, :] += 2.0 * face
    # explicit fit at the tensor Gauss points
    g, gw = np.polynomial.legendre.leggauss(n)
    Lg = legendre(n, g)  # (n_poly, n_points)
    c = 2.0 / (2.0 * np.arange(n) + 1.0)
    scaled = moments / (c[:, None, None] * c[None, :, None] * c[None, None, :])
    weights = np.einsum("eabc,ai,bj,ck->eijk", scaled, Lg, Lg, Lg)
    weights *= (gw[:, None, None] * gw[None, :, None] * gw[None, None, :]) * (0.5 * h) ** 3
    gx = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    points = centre[:, None, :] + 0.5 * h * gx[None, :, :]
    return VolumeRule(points.reshape(-1, 3), weights.reshape(-1),
                      np.repeat(elements, n**3))
