"""The one H8 basis and the one Gauss rule, against independent references."""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.embedding.grid import CartesianGrid
from cgfem.fem.element import HEX8
from cgfem.quadrature_rules import gauss_legendre, tensor_gauss


def _lagrange_reference(x: np.ndarray, corner: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Trilinear Lagrange functions (n, 8) and gradients (n, 8, 3) at physical points ``x``
    (n, 3) of the cube whose nodes are ``corner`` (8, 3), written from the 1D hats
    ``1 - |x - x_a| / h`` (no local coordinates, no sign table)."""
    hat = 1.0 - np.abs(x[:, None, :] - corner[None, :, :]) / h          # (n, 8, 3)
    slope = -np.sign(x[:, None, :] - corner[None, :, :]) / h
    N = hat.prod(axis=2)
    dN = np.stack([slope[..., d] * np.delete(hat, d, axis=2).prod(axis=2) for d in range(3)], axis=2)
    return N, dN


@pytest.fixture
def cube():
    """One element of a grid (h = 0.3) with its node coordinates in the grid's H8 order."""
    grid = CartesianGrid(0.3, (0.1, -0.2, 0.05), (3, 4, 2))
    element = grid.element_id(np.array([[1, 2, 0]]))
    corner = grid.node_coordinates(np.column_stack(np.unravel_index(grid.element_nodes(element)[0],
                                                                    grid.node_shape)))
    centre = grid.element_center(grid.element_ijk(element))[0]
    return grid.h, corner, centre


def test_basis_matches_lagrange_reference(cube):
    h, corner, centre = cube
    xi = np.random.default_rng(1).uniform(-1.0, 1.0, (500, 3))
    N, dN = HEX8.tabulate(xi, h)
    N_ref, dN_ref = _lagrange_reference(centre + 0.5 * h * xi, corner, h)
    assert N.shape == (500, 8) and dN.shape == (500, 8, 3)
    assert np.abs(N - N_ref).max() < 1e-14
    assert np.abs(dN - dN_ref).max() * h < 1e-13


def test_partition_of_unity_and_kronecker(cube):
    h, corner, centre = cube
    xi = np.random.default_rng(2).uniform(-1.3, 1.3, (400, 3))   # also outside the cube
    N, dN = HEX8.tabulate(xi, h)
    assert np.abs(N.sum(axis=1) - 1.0).max() < 1e-15
    assert np.abs(dN.sum(axis=1)).max() * h < 1e-14
    # linear completeness: sum_a N_a x_a = x and sum_a x_a (x) dN_a = I
    x = centre + 0.5 * h * xi
    assert np.abs(N @ corner - x).max() < 1e-15
    assert np.abs(np.einsum("ai,paj->pij", corner, dN) - np.eye(3)).max() < 1e-13
    # at its own nodes (local coordinates from the grid's node positions) N_a = delta_ab
    N_nodes, _ = HEX8.tabulate((corner - centre) / (0.5 * h), h)
    assert np.abs(N_nodes - np.eye(8)).max() < 1e-15


def test_gradients_match_central_differences(cube):
    h = cube[0]
    xi = np.random.default_rng(3).uniform(-1.0, 1.0, (200, 3))
    _, dN = HEX8.tabulate(xi, h)
    step = 1e-6
    for d in range(3):
        e = np.zeros(3)
        e[d] = step
        fd = (HEX8.tabulate(xi + e, h)[0] - HEX8.tabulate(xi - e, h)[0]) / (2 * step) * (2.0 / h)
        assert np.abs(fd - dN[:, :, d]).max() * h < 1e-9


def test_gauss_rules_exact_for_cubics_per_variable():
    x, w = gauss_legendre(2)
    assert np.allclose(x, [-1 / np.sqrt(3), 1 / np.sqrt(3)], rtol=0, atol=1e-15)
    assert np.allclose(w, [1.0, 1.0], rtol=0, atol=1e-15)
    points, weights = tensor_gauss(2, 3)
    assert points.shape == (8, 3) and abs(weights.sum() - 8.0) < 1e-14

    def exact(k):  # int_{-1}^{1} t^k dt
        return 0.0 if k % 2 else 2.0 / (k + 1)

    for a in range(4):
        for b in range(4):
            for c in range(4):
                q = weights @ (points[:, 0] ** a * points[:, 1] ** b * points[:, 2] ** c)
                assert abs(q - exact(a) * exact(b) * exact(c)) < 1e-14, (a, b, c)
    # and not beyond: t^4 is integrated as 2/9, not 2/5
    q4 = weights @ points[:, 2] ** 4
    assert abs(q4 - 4 * exact(4)) > 0.1
    # the 2D face rule and higher orders follow the same law (n points: degree 2n - 1)
    for n in (1, 3, 5):
        p, wq = tensor_gauss(n, 2)
        assert abs(wq @ (p[:, 0] ** (2 * n - 2) * p[:, 1] ** (2 * n - 2)) - exact(2 * n - 2) ** 2) < 1e-14
    with pytest.raises(ValueError):
        gauss_legendre(0)
