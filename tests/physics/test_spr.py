"""Superconvergent patch recovery on cut grids and the ZZ estimate (cgfem.fem.spr)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from cgfem.embedding.quadrature import embed, grid_for
from cgfem.fem import spr
from cgfem.fem.space import NODE_XI, Space
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import SphereSpec, TorusSpec

#: the fixtures embed the unit sphere at levels 0-3 (a minute)
pytestmark = pytest.mark.slow

OFFSET = (0.13, 0.29, 0.41)
MU, LAM = 1.0, 1.5
H0 = 0.4
LEVELS = (0, 1, 2, 3)  # h = 0.4, 0.2, 0.1, 0.05 on the unit sphere


@pytest.fixture(scope="module")
def sphere_levels():
    solid = build_solid(SphereSpec((0.0, 0.0, 0.0), 1.0))
    out = []
    for level in LEVELS:
        emb = embed(solid, grid_for(solid, H0, level, OFFSET))
        out.append((emb, Space.from_embedding(emb)))
    return out


@pytest.fixture(scope="module")
def torus():
    axis = np.array([0.3, -0.5, 0.8])
    solid = build_solid(TorusSpec((0.05, -0.02, 0.01), tuple(axis / np.linalg.norm(axis)), 1.0, 0.4))
    emb = embed(solid, grid_for(solid, H0, 1, OFFSET))
    return emb, Space.from_embedding(emb)


# -- fields ---------------------------------------------------------------------------------
def u_exact(x):
    X, Y, Z = x[:, 0], x[:, 1], x[:, 2]
    return np.stack([np.sin(1.3 * X) * np.cos(0.9 * Y),
                     np.sin(1.1 * Y) * np.cos(1.4 * Z),
                     np.sin(1.7 * Z) * np.cos(0.8 * X)], axis=-1)


def grad_exact(x):
    X, Y, Z = x[:, 0], x[:, 1], x[:, 2]
    G = np.zeros((x.shape[0], 3, 3))
    G[:, 0, 0] = 1.3 * np.cos(1.3 * X) * np.cos(0.9 * Y)
    G[:, 0, 1] = -0.9 * np.sin(1.3 * X) * np.sin(0.9 * Y)
    G[:, 1, 1] = 1.1 * np.cos(1.1 * Y) * np.cos(1.4 * Z)
    G[:, 1, 2] = -1.4 * np.sin(1.1 * Y) * np.sin(1.4 * Z)
    G[:, 2, 2] = 1.7 * np.cos(1.7 * Z) * np.cos(0.8 * X)
    G[:, 2, 0] = -0.8 * np.sin(1.7 * Z) * np.sin(0.8 * X)
    return G


def stress(grad):
    eps = 0.5 * (grad + np.swapaxes(grad, 1, 2))
    return LAM * np.einsum("nii->n", eps)[:, None, None] * np.eye(3) + 2.0 * MU * eps


def fe_grad(space, nodal_u, slots, xi):
    """H8 displacement gradient at local points: dN/dx = (2/h) dN/dxi."""
    f = 1.0 + xi[:, None, :] * NODE_XI[None]  # (n, 8, 3)
    dN = np.empty(f.shape)
    for k in range(3):
        i, j = [d for d in range(3) if d != k]
        dN[:, :, k] = NODE_XI[None, :, k] * f[:, :, i] * f[:, :, j] / 8.0
    return np.einsum("pai,paj->pij", nodal_u[space.connectivity[slots]], dN * (2.0 / space.h))


def linear_stress_field(rng):
    coefs = rng.normal(size=(4, 3, 3))
    coefs = 0.5 * (coefs + np.swapaxes(coefs, 1, 2))
    return lambda x: coefs[0] + np.einsum("nk,kij->nij", x, coefs[1:])


def sample_positions(space):
    slots, xi = spr.sampling_points(space)
    return slots, xi, space.centres()[slots] + 0.5 * space.h * xi


# -- 1. exactness -----------------------------------------------------------------------------
@pytest.mark.parametrize("body", ["sphere", "torus"])
def test_linear_fields_are_recovered_exactly_at_every_node(body, sphere_levels, torus):
    emb, space = sphere_levels[1] if body == "sphere" else torus
    assert space.cut.sum() > 100
    rec = spr.build_recovery(space)
    assert rec.linear.all()
    slots, xi, x = sample_positions(space)
    rng = np.random.default_rng(7)
    for _ in range(3):
        field = linear_stress_field(rng)
        nodal = spr.recover(rec, field(x))
        exact = field(space.coordinates)
        scale = np.abs(exact).max()
        cut_nodes = np.unique(space.connectivity[space.cut])
        assert np.abs(nodal[cut_nodes] - exact[cut_nodes]).max() <= 1e-10 * scale
        assert np.abs(nodal - exact).max() <= 1e-10 * scale
        # and so is the recovered field everywhere in the elements (volume points)
        pts = space.volume_points(emb)
        star = spr.recovered_at(space, nodal, pts.element, pts.xi)
        assert np.abs(star - field(pts.x)).max() <= 1e-10 * scale


def test_quadratic_fields_are_recovered_exactly_at_every_node_at_order_2():
    """Triquadratic space on a cut sphere: every vertex fit is a complete quadratic and the
    nodal values (vertices, edges, faces, centres) are means of fits, so a quadratic stress
    field sampled at the 2x2x2 Gauss points comes back exactly, at every node and inside
    every element."""
    from cgfem.fem.element import HEX27

    solid = build_solid(SphereSpec((0.0, 0.0, 0.0), 1.0))
    emb = embed(solid, grid_for(solid, H0, 1, OFFSET), degree=4)
    space = Space.from_embedding(emb, HEX27)
    assert space.cut.sum() > 100
    rec = spr.build_recovery(space)
    vertices = np.unique(space.connectivity[:, :8])
    assert rec.linear[vertices].all() and set(np.unique(rec.level[vertices])) <= {0, 1}
    slots, xi, x = sample_positions(space)
    rng = np.random.default_rng(11)
    coefs = rng.normal(size=(10, 3, 3))
    coefs = 0.5 * (coefs + np.swapaxes(coefs, 1, 2))

    def field(p):
        X, Y, Z = p[:, 0], p[:, 1], p[:, 2]
        terms = np.stack([np.ones_like(X), X, Y, Z, X * X, Y * Y, Z * Z, X * Y, Y * Z, X * Z], axis=1)
        return np.einsum("nk,kij->nij", terms, coefs)
    nodal = spr.recover(rec, field(x))
    exact = field(space.coordinates)
    scale = np.abs(exact).max()
    assert np.abs(nodal - exact).max() <= 1e-9 * scale
    pts = space.volume_points(emb)
    assert np.abs(spr.recovered_at(space, nodal, pts.element, pts.xi) - field(pts.x)).max() <= 1e-9 * scale


# -- 2 and 3. convergence and effectivity --------------------------------------------------------
@pytest.fixture(scope="module")
def convergence(sphere_levels):
    rows = []
    for emb, space in sphere_levels:
        rec = spr.build_recovery(space)
        nodal_u = u_exact(space.coordinates)
        slots, xi = spr.sampling_points(space)
        nodal = spr.recover(rec, stress(fe_grad(space, nodal_u, slots, xi)))
        pts = space.volume_points(emb)
        exact = stress(grad_exact(pts.x))
        sigma_h = stress(fe_grad(space, nodal_u, pts.element, pts.xi))
        sigma_star = spr.recovered_at(space, nodal, pts.element, pts.xi)

        def l2(d):
            return np.sqrt(np.sum(pts.w * np.einsum("nij,nij->n", d, d)))

        eta, per_element = spr.zz_estimate(space, pts, sigma_h, sigma_star, MU, LAM)
        # per element, the complementary energy of the error, C^-1 : e : e =
        # (e : e - lam / (3 lam + 2 mu) tr(e)^2) / (2 mu), integrated by the element's rule
        # (positive weights: the estimate's clip of round-off below zero never acts here)
        e = sigma_star - sigma_h
        tr = np.trace(e, axis1=1, axis2=2)
        density = (np.einsum("nij,nij->n", e, e) - LAM / (3.0 * LAM + 2.0 * MU) * tr**2) / (2.0 * MU)
        direct = np.bincount(pts.element, pts.w * density, minlength=space.n_elements)
        assert pts.w.min() > 0.0
        np.testing.assert_allclose(per_element, direct, rtol=1e-10, atol=1e-14 * direct.max())
        assert eta == pytest.approx(np.sqrt(direct.sum()), rel=1e-12)
        true = spr.energy_norm(pts, exact - sigma_h, MU, LAM)
        rows.append((space.h, l2(exact - sigma_h), l2(exact - sigma_star), eta / true))
    return np.array(rows)


def test_recovered_stress_converges_faster_than_the_fe_stress(convergence):
    h, raw, recovered = convergence[:, 0], convergence[:, 1], convergence[:, 2]
    order_raw = np.polyfit(np.log(h), np.log(raw), 1)[0]
    order_rec = np.polyfit(np.log(h), np.log(recovered), 1)[0]
    # measured: 1.03 and 2.07
    assert 0.9 <= order_raw <= 1.15
    assert order_rec >= 1.5
    assert order_rec >= 1.9
    assert np.all(recovered < 0.4 * raw)
    assert recovered[-1] < 0.05 * raw[-1]


def test_zz_effectivity_on_the_finest_levels(convergence):
    effectivity = convergence[-2:, 3]
    assert np.all((0.7 <= effectivity) & (effectivity <= 1.5))
    # measured: 1.010 and 1.003
    assert np.all(np.abs(effectivity - 1.0) < 0.05)


# -- 4. linearity and sparsity ---------------------------------------------------------------------
def test_recover_is_linear_and_local(sphere_levels):
    emb, space = sphere_levels[2]
    rec = spr.build_recovery(space)
    slots, _, _ = sample_positions(space)
    m = slots.size
    assert isinstance(rec.matrix, sp.csr_matrix) and rec.matrix.shape == (space.n_nodes, m)
    rng = np.random.default_rng(3)
    s1, s2 = rng.normal(size=(2, m, 3, 3))
    a, b = 0.7, -2.3
    combined = spr.recover(rec, a * s1 + b * s2)
    assert np.allclose(combined, a * spr.recover(rec, s1) + b * spr.recover(rec, s2),
                       rtol=0, atol=1e-12)
    # components are recovered independently: symmetric samples give symmetric values
    sym = s1 + np.swapaxes(s1, 1, 2)
    assert np.array_equal(spr.recover(rec, sym), np.swapaxes(spr.recover(rec, sym), 1, 2))
    assert np.allclose(spr.recover(rec, s1)[:, 0, 1], rec.matrix @ s1[:, 0, 1], rtol=0, atol=1e-12)

    # Row a references only samples of the patches of a's neighbours (nodes sharing an
    # element with a): one sample per element, in the element block [a - 2 - K, a + 1 + K]
    # (node / element grid indices) where K is the largest enlargement level among them.
    grid = space.grid
    n_el = space.n_elements
    incidence = sp.csr_matrix((np.ones(8 * n_el), (space.connectivity.ravel(),
                                                   np.repeat(np.arange(n_el), 8))),
                              shape=(space.n_nodes, n_el))
    neighbours = (incidence @ incidence.T).tocsr()
    K = np.array([rec.level[neighbours.indices[neighbours.indptr[i]:neighbours.indptr[i + 1]]].max()
                  for i in range(space.n_nodes)])
    assert rec.level.max() <= spr.MAX_LEVEL and np.any(rec.level > 0)
    coo = rec.matrix.tocoo()
    node_ijk = np.rint((space.coordinates - np.asarray(grid.origin)) / grid.h).astype(np.int64)
    elem_ijk = grid.element_ijk(space.elements[slots[coo.col]])
    offset = elem_ijk - node_ijk[coo.row]
    k = K[coo.row][:, None]
    assert np.all((offset >= -2 - k) & (offset <= 1 + k))
    # where every neighbour uses its own elements (level 0), exactly within their patches
    level0 = K[coo.row] == 0
    support = (neighbours @ incidence).tocsr()
    assert np.all(np.asarray(support[coo.row[level0], slots[coo.col[level0]]]).ravel() > 0)
    # a node deep inside references exactly the 64 elements of its 4x4x4 block
    inner = np.flatnonzero(np.linalg.norm(space.coordinates, axis=1) < 0.5)
    assert np.all(np.diff(rec.matrix.indptr)[inner] == 64)


# -- energy norm -------------------------------------------------------------------------------------
def test_energy_norm_is_the_complementary_energy(sphere_levels):
    emb, space = sphere_levels[1]
    pts = space.volume_points(emb)
    rng = np.random.default_rng(5)
    s = rng.normal(size=(3, 3))
    s = s + s.T
    # C as a 9x9 matrix on the full tensor, inverted on symmetric tensors
    eye = np.eye(3)
    C = (LAM * np.einsum("ij,kl->ijkl", eye, eye)
         + MU * (np.einsum("ik,jl->ijkl", eye, eye) + np.einsum("il,jk->ijkl", eye, eye)))
    strain = np.linalg.lstsq(C.reshape(9, 9), s.ravel(), rcond=None)[0]
    density = float(s.ravel() @ strain)
    volume = 4.0 / 3.0 * np.pi
    sigma = np.broadcast_to(s, (pts.w.size, 3, 3))
    assert spr.energy_norm(pts, sigma, MU, LAM) == pytest.approx(np.sqrt(volume * density), rel=1e-8)
    eta, per = spr.zz_estimate(space, pts, np.zeros_like(sigma), sigma, MU, LAM)
    assert eta == pytest.approx(np.sqrt(volume * density), rel=1e-8)
    assert per.shape == (space.n_elements,)


def test_too_small_patches_fall_back_to_constants():
    # a sphere in two elements: no node has 4 non-coplanar samples within two enlargements
    solid = build_solid(SphereSpec((0.01, 0.02, 0.03), 0.05))
    emb = embed(solid, grid_for(solid, H0, 0, OFFSET))
    space = Space.from_embedding(emb)
    rec = spr.build_recovery(space)
    assert space.n_elements < 4 and not rec.linear.any()
    assert np.allclose(np.asarray(rec.matrix.sum(axis=1)).ravel(), 1.0, rtol=0, atol=1e-14)
    s = np.broadcast_to(np.diag([1.0, 2.0, 3.0]), (space.n_elements, 3, 3))
    assert np.allclose(spr.recover(rec, s), np.diag([1.0, 2.0, 3.0]), rtol=0, atol=1e-14)
