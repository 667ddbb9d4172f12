"""The hexahedral elements (cgfem.fem.element) against independent references: VTK's own
triquadratic hexahedron, polynomial completeness, finite differences of the derivatives, and
a space of each order whose neighbouring elements share their face nodes."""

from __future__ import annotations

import numpy as np
import pytest
from vtkmodules.vtkCommonDataModel import vtkHexahedron, vtkTriQuadraticHexahedron

from cgfem.embedding.grid import CartesianGrid
from cgfem.fem.element import HEX8, HEX27, ORDERS, hexahedron
from cgfem.fem.elasticity import reference_matrix
from cgfem.fem._material_kernels import LINEAR_ELASTIC, tangent_batch
from cgfem.fem.space import Space

ELEMENTS = [HEX8, HEX27]
H = 0.3


def test_orders_and_counts():
    assert [(e.order, e.n_nodes, e.n_dofs, e.degree, e.gauss_points, e.cell_type) for e in ELEMENTS] == \
        [(1, 8, 24, 2, 2, "hexahedron"), (2, 27, 81, 4, 3, "hexahedron27")]
    assert hexahedron(2) is HEX27 and sorted(ORDERS) == [1, 2]
    with pytest.raises(ValueError, match="order must be one of"):
        hexahedron(3)


def test_nodes_and_shape_functions_are_vtks():
    """Node positions and shape functions equal VTK's hexahedron and triquadratic hexahedron
    (its parametric cube is [0, 1]^3)."""
    for element, cell in ((HEX8, vtkHexahedron()), (HEX27, vtkTriQuadraticHexahedron())):
        pcoords = cell.GetParametricCoords()
        nodes = np.array([pcoords[i] for i in range(3 * element.n_nodes)]).reshape(-1, 3)
        assert np.array_equal(2.0 * nodes - 1.0, element.node_xi)
        xi = np.random.default_rng(0).uniform(-1.0, 1.0, (50, 3))
        N = element.tabulate(xi, H)[0]
        for p in range(xi.shape[0]):
            weights = [0.0] * element.n_nodes
            cell.InterpolateFunctions(tuple(0.5 * (xi[p] + 1.0)), weights)
            assert np.abs(N[p] - weights).max() < 1e-14


@pytest.mark.parametrize("element", ELEMENTS, ids=lambda e: e.cell_type)
def test_completeness_to_the_order_per_variable(element):
    """Every polynomial of degree <= order in each variable is reproduced with its gradient;
    the next degree is not."""
    xi = np.random.default_rng(1).uniform(-1.2, 1.2, (200, 3))     # also outside the cube
    N, dN = element.tabulate(xi, H)
    x_nodes = 0.5 * H * element.node_xi
    x = 0.5 * H * xi
    p = element.order
    for a in range(p + 1):
        for b in range(p + 1):
            for c in range(p + 1):
                f = x_nodes[:, 0] ** a * x_nodes[:, 1] ** b * x_nodes[:, 2] ** c
                exact = x[:, 0] ** a * x[:, 1] ** b * x[:, 2] ** c
                grad = np.stack([a * x[:, 0] ** max(a - 1, 0) * x[:, 1] ** b * x[:, 2] ** c,
                                 b * x[:, 0] ** a * x[:, 1] ** max(b - 1, 0) * x[:, 2] ** c,
                                 c * x[:, 0] ** a * x[:, 1] ** b * x[:, 2] ** max(c - 1, 0)], axis=1)
                assert np.abs(N @ f - exact).max() < 1e-14
                assert np.abs(np.einsum("pad,a->pd", dN, f) - grad).max() < 1e-13
    f = x_nodes[:, 0] ** (p + 1)
    assert np.abs(N @ f - x[:, 0] ** (p + 1)).max() > 1e-4 * H ** (p + 1)


@pytest.mark.parametrize("element", ELEMENTS, ids=lambda e: e.cell_type)
def test_derivatives_match_central_differences(element):
    xi = np.random.default_rng(2).uniform(-1.0, 1.0, (100, 3))
    N, dN, d2N = element.tabulate(xi, H, second=True)
    step = 1e-6
    for d in range(3):
        e = np.zeros(3)
        e[d] = step
        plus, minus = element.tabulate(xi + e, H), element.tabulate(xi - e, H)
        scale = 2.0 / H / (2 * step)
        assert np.abs((plus[0] - minus[0]) * scale - dN[:, :, d]).max() * H < 1e-8
        assert np.abs((plus[1] - minus[1]) * scale - d2N[:, :, :, d]).max() * H ** 2 < 1e-7
    assert np.array_equal(d2N, d2N.transpose(0, 1, 3, 2))


@pytest.mark.parametrize("element", ELEMENTS, ids=lambda e: e.cell_type)
def test_reference_stiffness_has_the_rigid_modes_as_kernel(element):
    """The whole-cube stiffness is symmetric, positive semi-definite with exactly the six
    rigid motions in its kernel, and its energy of a linear field equals the exact one."""
    E, nu = 2.0e9, 0.3
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    A = tangent_batch(LINEAR_ELASTIC, np.zeros((1, 3, 3)), mu, lam)[2][0]
    K = reference_matrix(A, H, element)
    assert np.abs(K - K.T).max() < 1e-12 * np.abs(K).max()
    eig = np.linalg.eigvalsh(K)
    assert np.sum(eig < 1e-10 * eig.max()) == 6 and eig.min() > -1e-10 * eig.max()
    G = np.array([[1e-3, 2e-3, -1e-3], [0.5e-3, -2e-3, 1e-3], [3e-3, 1e-3, 0.0]])
    u = (0.5 * H * element.node_xi @ G.T).ravel()
    strain = 0.5 * (G + G.T)
    energy = 0.5 * (lam * np.trace(strain) ** 2 + 2 * mu * np.sum(strain ** 2)) * H ** 3
    assert 0.5 * u @ K @ u == pytest.approx(energy, rel=1e-12)


@pytest.mark.parametrize("element", ELEMENTS, ids=lambda e: e.cell_type)
def test_space_nodes_are_shared_across_faces(element):
    """Every node of the space sits where its elements' local coordinates put it, and
    elements that share a face share (order + 1)^2 nodes, an edge order + 1, a corner 1."""
    grid = CartesianGrid(H, (0.1, -0.2, 0.05), (3, 3, 2))
    elements = np.arange(grid.n_elements)
    space = Space.of_elements(grid, elements, np.zeros(elements.size, bool), element)
    p = element.order
    assert space.n_nodes == np.prod([p * n + 1 for n in grid.shape])
    centres = space.centres()
    expected = centres[:, None, :] + 0.5 * H * element.node_xi[None, :, :]
    assert np.abs(space.coordinates[space.connectivity] - expected).max() < 1e-14
    ijk = grid.element_ijk(elements)
    for a in range(elements.size):
        for b in range(a + 1, elements.size):
            steps = np.abs(ijk[a] - ijk[b])
            if steps.max() > 1:
                continue
            shared = np.intersect1d(space.connectivity[a], space.connectivity[b]).size
            assert shared == (p + 1) ** (3 - steps.sum()), (ijk[a], ijk[b])
    assert space.element_dofs.shape == (elements.size, element.n_dofs)


@pytest.mark.parametrize("element", ELEMENTS, ids=lambda e: e.cell_type)
def test_lebesgue_constant_and_bernstein_hull(element):
    """``lebesgue`` is the maximum of sum |N_a| over the cube (reached at xi = +-1/2 at order 2),
    and a random field on the element stays within the range of its Bernstein coefficients
    (``to_bernstein``), which the nodal values alone do not bound at order 2."""
    t = np.linspace(-1.0, 1.0, 41)
    xi = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    N = element.tabulate(xi, H)[0]
    assert np.abs(N).sum(axis=1).max() == pytest.approx(element.lebesgue, rel=1e-12)
    rng = np.random.default_rng(3)
    for _ in range(20):
        u = rng.standard_normal(element.n_nodes)
        b = element.to_bernstein @ u
        v = N @ u
        assert b.min() - 1e-12 <= v.min() and v.max() <= b.max() + 1e-12
        # the Bernstein coefficients reproduce the field: at the corners they equal the values
        np.testing.assert_allclose(b[:8], u[:8], atol=1e-12)
    if element.order == 2:   # the quadratic field overshoots its nodal values somewhere
        assert any((element.tabulate(xi, H)[0] @ u).max() > u.max() + 1e-9
                   for u in rng.standard_normal((20, element.n_nodes)))
