"""nurbs_fit in the solver: the fitted surface's kinematics, its consistent tangent and the
seam ties that keep a closed fitted surface closed.

Scene of :mod:`test_contact_kinematics`: a box's bottom face (slave) over a sphere (master),
both fitted in the ``auto`` space (spans about h), random control displacements on both.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp

from cgfem.contact.fit import build_fits, c1_extraction, fit_space
from cgfem.contact.fitted import FittedSurface, merge_columns
from cgfem.contact.pair import ContactPair, slave_gradients
from cgfem.embedding.quadrature import embed, grid_for
from cgfem.fem.element import hexahedron
from cgfem.fem.space import Space
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import BoxSpec, SphereSpec, TorusSpec


@functools.lru_cache(maxsize=None)
def _bodies(order: int):
    """The sphere (master) and the box (slave), embedded for the hexahedra of ``order``, and
    their spaces (built once per module; the pairs built on them own all their state)."""
    element = hexahedron(order)
    master = build_solid(SphereSpec(center=(0, 0, 0), radius=1.0))
    slave = build_solid(BoxSpec(min=(-0.45, -0.4, 0.93), max=(0.4, 0.45, 1.5)))
    em = embed(master, grid_for(master, 0.5, 1, (0.13, 0.29, 0.41)), "nurbs", degree=element.degree)
    es = embed(slave, grid_for(slave, 0.3, 1, (0.37, 0.71, 0.23)), "nurbs", degree=element.degree)
    return master, slave, em, es, Space.from_embedding(em, element), Space.from_embedding(es, element)


def _pair(finite: bool, refine="auto", order: int = 1) -> ContactPair:
    """The box's bottom face on the sphere, fitted to FE fields of the hexahedra of ``order``
    (the fit's ``G``; the slave points are the boundary rule of that element's degree)."""
    master, slave, em, es, Sm, Ss = _bodies(order)
    zmin = np.array([i for i, p in enumerate(slave.patches) if p.name == "zmin"])
    rule = es.boundary.select(np.isin(es.boundary.patch, zmin))
    slave_srf = FittedSurface(0, build_fits(slave, es.surface, Ss, zmin, refine), es.surface, 1.0)
    master_srf = FittedSurface(1, build_fits(master, em.surface, Sm, np.arange(len(master.patches)), refine),
                               em.surface, 1.0)
    frames = slave_srf.slave_frames(rule)
    return ContactPair("test", 0, 1, Ss, Sm, frames, slave_gradients(Ss, frames), master_srf,
                       eps=1e3, finite=finite, max_gap=0.5, slave_surface=slave_srf)


def test_unmoved_fitted_surface_is_the_geometry():
    """Z = 0: slave frames and master points are the exact NURBS points, tangents and second
    derivatives (the fitting space keeps the geometry and its parametrisation)."""
    pair = _pair(False)
    master, frames = pair.surface, pair.frames
    fit = master.fits[0]
    rng = np.random.default_rng(1)
    (u0, u1), (v0, v1) = fit.surface.domain
    theta = np.column_stack([rng.uniform(u0, u1, 50), rng.uniform(v0, v1, 50)])
    mp = master.evaluate(np.zeros(3 * master.n_nodes), np.zeros(50, np.int64), theta)
    original = build_solid(SphereSpec(center=(0, 0, 0), radius=1.0)).patches[fit.patch].surface
    d = original.derivatives(theta, 2)
    np.testing.assert_allclose(mp.x, d[:, 0, 0], atol=1e-13)
    np.testing.assert_allclose(mp.t[:, 0], d[:, 1, 0], atol=1e-12)
    np.testing.assert_allclose(mp.s[:, 0, 1], d[:, 1, 1], atol=1e-11)
    np.testing.assert_allclose(mp.s[:, 1, 1], d[:, 0, 2], atol=1e-11)
    # coefficients on the free controls: partition of unity (x moves rigidly with a uniform Z)
    np.testing.assert_allclose(mp.phi.sum(axis=1), 1.0, atol=1e-13)
    np.testing.assert_allclose(frames.phi.sum(axis=1), 1.0, atol=1e-13)
    np.testing.assert_allclose(frames.ca.sum(axis=1), 0.0, atol=1e-12)


@pytest.mark.parametrize("finite, order", [(False, 1), (True, 1), pytest.param(False, 2, marks=pytest.mark.slow),
                                           pytest.param(True, 2, marks=pytest.mark.long)])
def test_tangent_equals_central_differences(finite, order):
    pair = _pair(finite, order=order)
    rng = np.random.default_rng(0)
    n_s, n_m = 3 * pair.slave_surface.n_nodes, 3 * pair.surface.n_nodes
    z = 0.02 * rng.standard_normal(n_s + n_m)
    pair.state.p_N = 50.0 * rng.standard_normal(pair.n_points) - 20.0
    r_s, r_m, (rows, cols, vals) = pair.assemble(z[:n_s], z[n_s:], True)
    hits, active = pair.state.hits, pair.state.active
    assert hits.found.mean() > 0.9
    assert 0.2 < active.mean() < 0.9
    assert np.any(hits.g[hits.found] > 0) and np.any(hits.g[hits.found] < 0)
    # the active points lie on many knot spans of the master's fitting space
    fit = pair.surface.fits[0]
    ku, kv = np.unique(fit.surface.knots_u), np.unique(fit.surface.knots_v)
    th = hits.theta[active & (hits.piece == 0)]
    spans = np.unique(np.searchsorted(ku, th[:, 0]) * 1000 + np.searchsorted(kv, th[:, 1]))
    assert spans.size >= 8
    K = sp.coo_matrix((vals, (rows, cols)), shape=(n_s + n_m,) * 2).tocsr()

    def residual(v):
        a, b, _ = pair.assemble(v[:n_s], v[n_s:], False, update=False)
        return np.concatenate([a, b])

    d = rng.standard_normal(n_s + n_m)
    # fourth-order central differences at a small step (the second-order stencil's
    # truncation error reaches 1e-5 with the order-2 rule's points; a larger step crosses
    # an active-set switch)
    step = 2e-7
    fd = (8.0 * (residual(z + step * d) - residual(z - step * d))
          - (residual(z + 2.0 * step * d) - residual(z - 2.0 * step * d))) / (12.0 * step)
    exact = K @ d
    assert np.linalg.norm(fd - exact) <= 1e-6 * np.linalg.norm(exact)
    asym = abs(K - K.T).max() / abs(K).max()
    assert (asym > 1e-3) if finite else (asym < 1e-12)


def test_closed_directions_stay_closed():
    """A torus closes along both directions: its fitting space's seam rows are tied
    (V_0 = V_{n-1} = a V_{n-2} + (1 - a) V_1), so any free Z gives a closed fitted surface
    whose displacement is C1 across the seams as the geometry is."""
    solid = build_solid(TorusSpec((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.02, 0.005))
    surface = fit_space(solid.patches[0].surface, 0.002, "auto")
    T, free = c1_extraction(surface)
    n_u, n_v = surface.control.shape[:2]
    assert free[0] <= n_u - 2 and free[1] <= n_v - 2
    rng = np.random.default_rng(2)
    V = (T @ rng.standard_normal((T.shape[1], 3))).reshape(n_u, n_v, 3)
    np.testing.assert_allclose(V[0], V[-1], atol=1e-14)
    np.testing.assert_allclose(V[:, 0], V[:, -1], atol=1e-14)
    pts = surface.points
    moved = surface.from_points(surface.degree, surface.knots_u, surface.knots_v, pts + 1e-3 * V, surface.weights)
    (u0, u1), (v0, v1) = surface.domain
    s = np.linspace(v0, v1, 7)
    a = moved.derivatives(np.column_stack([np.full(7, u0), s]), 1)
    b = moved.derivatives(np.column_stack([np.full(7, u1), s]), 1)
    np.testing.assert_allclose(a[:, 0, 0], b[:, 0, 0], atol=1e-15)
    # C1: the same derivative across the seam, as the geometry's (which is C1 there)
    ga = surface.derivatives(np.column_stack([np.full(7, u0), s]), 1)
    gb = surface.derivatives(np.column_stack([np.full(7, u1), s]), 1)
    ratio = np.linalg.norm(ga[:, 1, 0], axis=1) / np.linalg.norm(gb[:, 1, 0], axis=1)
    np.testing.assert_allclose(a[:, 1, 0], b[:, 1, 0] * ratio[:, None], rtol=1e-9, atol=1e-12)


def test_merged_columns_move_points_as_the_raw_basis():
    """Merging a point's equal controls (ties spread one control over several free ones)
    keeps ``coef @ Z`` and leaves each point with distinct controls only."""
    rng = np.random.default_rng(3)
    n, w = 40, 12
    nodes = rng.integers(0, 7, (n, w))
    coef = rng.normal(size=(n, 6, w))
    valid = rng.random((n, w)) < 0.8
    valid[:, 0] = True
    Z = rng.normal(size=(7, 3))
    merged_nodes, merged_coef = merge_columns(nodes, coef, valid)
    raw = np.einsum("prw,pwk->prk", np.where(valid[:, None], coef, 0.0), Z[nodes])
    np.testing.assert_allclose(np.einsum("prw,pwk->prk", merged_coef, Z[merged_nodes]), raw, atol=1e-13)
    for row, c in zip(merged_nodes, merged_coef[:, 0]):
        live = row[c != 0.0]
        assert live.size == np.unique(live).size
    assert merged_nodes.shape[1] == max(np.unique(nodes[i][valid[i]]).size for i in range(n))


def test_merged_columns_sum_equal_controls_in_column_order_and_pad_with_the_first():
    """Bit for bit the sums of a plain loop over each row's columns (from 0.0, in column
    order), the controls ascending, rows padded with their smallest control and 0; a row
    with no valid entry with :data:`~cgfem.contact._fit_kernels.NO_CONTROL`."""
    from cgfem.contact._fit_kernels import NO_CONTROL
    rng = np.random.default_rng(5)
    n, w = 30, 10
    nodes = rng.integers(0, 5, (n, w))
    coef = rng.normal(size=(n, 2, w))
    valid = rng.random((n, w)) < 0.7
    valid[0] = False
    merged_nodes, merged_coef = merge_columns(nodes, coef, valid)
    width = merged_nodes.shape[1]
    for p in range(n):
        sums: dict[int, list[float]] = {}
        for a in range(w):
            if valid[p, a]:
                row = sums.setdefault(int(nodes[p, a]), [0.0, 0.0])
                row[0] += coef[p, 0, a]
                row[1] += coef[p, 1, a]
        controls = sorted(sums)
        pad = controls[0] if controls else NO_CONTROL
        expected = np.array(controls + [pad] * (width - len(controls)))
        expected_coef = np.zeros((2, width))
        expected_coef[:, :len(controls)] = np.array([sums[c] for c in controls]).T.reshape(2, -1)
        assert np.array_equal(merged_nodes[p], expected)
        assert np.array_equal(merged_coef[p], expected_coef)


def test_the_basis_in_chunks_is_the_basis_at_once(monkeypatch):
    """The fitted surface evaluates its basis a chunk of points at a time: the reference
    geometry, coefficients and controls of the sphere's seeds are those of one evaluation,
    array for array; and chunks whose points have fewer distinct controls than the widest
    (random controls, as in the test above) are padded as :func:`merge_columns` pads."""
    from cgfem.contact import fitted
    master = _pair(False).surface
    piece, theta = master.seed_piece, master.seed_theta
    whole = master._basis(piece, theta)
    monkeypatch.setattr(fitted, "BASIS_CHUNK", 37)
    assert piece.size > 100 * fitted.BASIS_CHUNK
    for a, b in zip(whole, master._basis(piece, theta)):
        assert a.shape == b.shape and np.array_equal(a, b)

    rng = np.random.default_rng(4)
    n, w = 200, 12
    nodes = rng.integers(0, 9, (n, w))
    nodes[:100, 6:] = nodes[:100, :1]                  # the first chunks' points: fewer controls
    coef = rng.normal(size=(n, 6, w))
    valid = np.ones((n, w), bool)
    ref = rng.normal(size=(n, 6, 3))

    def merged(rows):
        controls, values = merge_columns(nodes[rows], coef[rows], valid[rows])
        return ref[rows], values, controls

    class Raw:
        def _basis_chunk(self, rows, _theta):
            return merged(rows)
    expected = merged(np.arange(n))
    chunked = FittedSurface._basis(Raw(), np.arange(n), np.zeros((n, 2)))
    assert merged(np.arange(37))[2].shape[1] < expected[2].shape[1]
    for a, b in zip(expected, chunked):
        assert a.shape == b.shape and np.array_equal(a, b)
