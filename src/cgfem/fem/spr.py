"""Superconvergent patch recovery (SPR, Zienkiewicz-Zhu) on cut grids and the ZZ estimate.

The recovered stress ``sigma*`` is continuous and interpolated with the space's own shape
functions, ``sigma* = sum_a N_a sigma*_a``, with nodal values from least-squares fits of
complete polynomials in scaled local coordinates ``(x - x_b) / h`` to FE stress samples, one
fit per grid vertex ``b`` and per component (the operator is the same for all: six
independent fits for a symmetric tensor).

Sampling and fits. Order 1: one sample per active element at the centre of its cube (where
the trilinear gradient of a smooth field is superconvergent, ``O(h^2)``), complete linear
fits. Order 2: the 2x2x2 Gauss points of every active element (the triquadratic field's
superconvergent points), complete quadratic fits. Cut elements are sampled too, whether the
point lies in the material or not (the FE stress is a polynomial on the whole cube); all
samples weigh the same.

Patches. A vertex's patch is the active elements sharing it, enlarged ring by ring while the
fit is ill posed (too few samples or degenerate ones) or extrapolates too much; see
:mod:`cgfem.fem._spr_kernels` for the exact rule (a constant fallback when nothing is well
posed within two enlargements).

Nodal values. ZZ's averaging: ``sigma*_a`` is the mean, over the vertices ``b`` of the elements
holding node ``a``, of ``b``'s patch polynomial at ``x_a``. At boundary nodes this blends
one-sided extrapolations with the fits of interior neighbours. The choice of this variant
among others (sampling points, own-patch values, weights of cut samples) is measured in
docs/methods/elasticity.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from cgfem.fem._spr_kernels import average_rows, patch_operators
from cgfem.fem.space import ElementPoints, Space
from cgfem.quadrature_rules import tensor_gauss

#: patch enlargements tried before the constant fallback
MAX_LEVEL = 2
#: largest accepted Lebesgue constant ``sum_s |C_s[0]|`` of a node's own fit (a guard: a
#: one-sided fit over a level-0 patch of grid-centre samples stays below 3.1)
MAX_LEBESGUE = 4.0
#: smallest eigenvalue of the scaled normal matrix ``G / n`` of a well-posed fit
MIN_EIG = 1e-6


def sampling_points(space: Space) -> tuple[np.ndarray, np.ndarray]:
    """Where the caller evaluates the FE stress for :func:`recover`: ``(slots (m,), xi (m, 3))``
    in element order. Order 1: the centre ``xi = 0`` of every active element (``m =
    n_elements``); order 2: the 2x2x2 Gauss points ``xi = +-1/sqrt(3)`` of every active element
    (``m = 8 n_elements``), where the triquadratic field's gradient is superconvergent."""
    n = space.n_elements
    if space.element.order == 1:
        return np.arange(n, dtype=np.int64), np.zeros((n, 3))
    local, _ = tensor_gauss(2, 3)
    return np.repeat(np.arange(n, dtype=np.int64), local.shape[0]), np.tile(local, (n, 1))


def fit_terms(space: Space) -> int:
    """Terms of the patch polynomial: complete linear (4) for order 1, complete quadratic (10)
    for order 2."""
    return 4 if space.element.order == 1 else 10


@dataclass(frozen=True)
class Recovery:
    """Precomputed recovery of one space.

    matrix : (n_nodes, m) CSR, nodal recovered value = ``matrix @ samples``
    level : (n_nodes,) enlargement level of every node's own patch (0: its elements)
    linear : (n_nodes,) False where a node's own fit fell back to a constant
    """

    matrix: sp.csr_matrix
    level: np.ndarray
    linear: np.ndarray

    @property
    def n_samples(self) -> int:
        return int(self.matrix.shape[1])


def node_elements(space: Space) -> tuple[np.ndarray, np.ndarray]:
    """Node -> active element CSR ``(ptr (n_nodes + 1,), elements)``."""
    flat = space.connectivity.ravel()
    order = np.argsort(flat, kind="stable")
    ptr = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=space.n_nodes))])
    return ptr.astype(np.int64), (order // space.element.n_nodes).astype(np.int64)


def build_recovery(space: Space) -> Recovery:
    """Per-node least-squares operators and their averaged sparse matrix for ``space``."""
    slots, xi = sampling_points(space)
    samples = space.points_at(slots, xi)
    x, sample_ptr = samples.x, samples.offsets
    node_ptr, elements = node_elements(space)
    conn = np.ascontiguousarray(space.connectivity, np.int64)
    coords = np.ascontiguousarray(space.coordinates, float)
    h = float(space.h)
    vertex = np.zeros(space.n_nodes, bool)
    vertex[space.connectivity[:, :8]] = True
    row_ptr, cols, coef, level, linear = patch_operators(
        conn, coords, node_ptr, elements, sample_ptr, x, h,
        MAX_LEVEL, MAX_LEBESGUE, MIN_EIG, fit_terms(space), vertex)
    indptr, indices, data = average_rows(row_ptr, cols, coef, linear, vertex, coords, h, conn,
                                         node_ptr, elements, slots.size)
    matrix = sp.csr_matrix((data, indices, indptr), shape=(space.n_nodes, slots.size))
    matrix.sort_indices()
    return Recovery(matrix, level, linear)


def recover(recovery: Recovery, samples: np.ndarray) -> np.ndarray:
    """Stress samples (m, 3, 3) at :func:`sampling_points` -> nodal recovered stress
    (n_nodes, 3, 3). The same operator acts on every component, so symmetric samples give
    exactly symmetric nodal values (six independent fits); a non-symmetric tensor (first
    Piola-Kirchhoff stress) is recovered component by component, not symmetrised."""
    samples = np.asarray(samples, float)
    if samples.shape != (recovery.n_samples, 3, 3):
        raise ValueError(f"expected samples of shape ({recovery.n_samples}, 3, 3), "
                         f"got {samples.shape}")
    return np.asarray(recovery.matrix @ samples.reshape(-1, 9)).reshape(-1, 3, 3)


def recovered_at(space: Space, nodal: np.ndarray, slots, xi) -> np.ndarray:
    """``sigma* = sum_a N_a sigma*_a`` (n, 3, 3) at local points ``xi`` of elements ``slots``."""
    return space.interpolate(np.asarray(nodal, float), np.asarray(slots, np.int64),
                             np.asarray(xi, float))


def complementary_density(sigma: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """``sigma : C^-1 : sigma`` (n,) for isotropic ``C`` (Lamé ``mu``, ``lam``):
    ``C^-1 : s = (s - lam / (3 lam + 2 mu) tr(s) I) / (2 mu)``."""
    sigma = np.asarray(sigma, float)
    tr = np.einsum("nii->n", sigma)
    return (np.einsum("nij,nij->n", sigma, sigma) - lam / (3.0 * lam + 2.0 * mu) * tr**2) / (2.0 * mu)


def zz_estimate(space: Space, points: ElementPoints, sigma_h: np.ndarray, sigma_star: np.ndarray,
                mu: float, lam: float) -> tuple[float, np.ndarray]:
    """ZZ estimate ``eta^2 = int (s* - s_h) : C^-1 : (s* - s_h) dV`` over the volume rule
    ``points``; returns ``(eta, per-element eta^2 (n_elements,))``.

    The integrand is a polynomial of degree <= 2 in each variable on every element, which the
    volume rules integrate exactly; per-element values below zero (round-off of the
    moment-fitted weights, which may be negative) are clipped to zero.
    """
    error = np.asarray(sigma_star, float) - np.asarray(sigma_h, float)
    density = complementary_density(error, mu, lam) * points.w
    per_element = np.maximum(np.bincount(points.element, density, minlength=space.n_elements), 0.0)
    return float(np.sqrt(per_element.sum())), per_element


def energy_norm(points: ElementPoints, sigma: np.ndarray, mu: float, lam: float) -> float:
    """``sqrt(int sigma : C^-1 : sigma dV)`` over the volume rule ``points``."""
    total = float(np.sum(complementary_density(sigma, mu, lam) * points.w))
    return float(np.sqrt(max(total, 0.0)))
