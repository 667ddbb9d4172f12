"""NURBS+FE ray tracing: the numba search against a slow, obvious reference.

A small sphere (slave) pressed into a larger one (master, a single patch that closes on its
seam and has poles) with random nodal displacements on the master: rays of both gap signs,
hits on several master elements. The reference redoes the search point by point: brute-force
nearest seeds of the samples of each ray, then Newton from each start with
:meth:`NurbsFeSurface.evaluate` and ``numpy.linalg.solve``; the hits (found, patch, theta,
g) must be the same. The kernel's pieces are checked on their own too.
"""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.contact import _ray_kernels as rk
from cgfem.contact.kinematics import state_of
from cgfem.contact.surfaces import (CANDIDATES, MAX_RAY_NEWTON, RAY_TOL, SAMPLE_REACH, NurbsFeSurface,
                                    RayHits, closed_directions, pack_patches, pairs_within, surface_tree)
from cgfem.embedding.quadrature import embed, grid_for
from cgfem.fem.space import LOCATE_TOL, Space
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import SphereSpec

MAX_GAP = 0.3


@pytest.fixture(scope="module")
def scene():
    """Master surface (n seeds), slave points ``x1``, normals ``n1`` (n, 3), master ``u``."""
    master = build_solid(SphereSpec(center=(0, 0, 0), radius=1.0))
    slave = build_solid(SphereSpec(center=(0.1, -0.05, 1.45), radius=0.5))
    em = embed(master, grid_for(master, 0.5, 0, (0.13, 0.29, 0.41)), "nurbs")
    es = embed(slave, grid_for(slave, 0.3, 0, (0.37, 0.71, 0.23)), "nurbs")
    Sm, Ss = Space.from_embedding(em), Space.from_embedding(es)
    surface = NurbsFeSurface(master, Sm, em.surface, np.arange(len(master.patches)))
    rule = es.boundary
    frames = NurbsFeSurface(slave, Ss, rule, np.arange(len(slave.patches))).slave_frames(rule)
    st = state_of(frames.X, frames.A, frames.B)         # undeformed
    u = 0.02 * np.random.default_rng(1).standard_normal(Sm.n_dofs)
    return surface, st.x, st.n, u


def _newton(surface: NurbsFeSurface, u, x1, n1, piece: int, theta: np.ndarray):
    """One start, written out: converged and admissible, theta (2,), g."""
    (u0, u1), (v0, v1) = surface.solid.patches[piece].surface.domain
    lo, hi = np.array([u0, v0]), np.array([u1, v1])
    closed = np.array(closed_directions(surface.solid.patches[piece].surface))
    th, g = np.array(theta, float), 0.0
    for _ in range(MAX_RAY_NEWTON):
        with np.errstate(invalid="ignore"):             # a start at a pole: no normal yet
            mp = surface.evaluate(u, np.array([piece]), th[None], second=False)
        F = mp.x[0] - x1 - g * n1
        J = np.column_stack([mp.t[0, 0], mp.t[0, 1], -n1])
        if np.linalg.norm(F) <= RAY_TOL * surface.h:
            return abs(g) <= MAX_GAP and mp.normal[0] @ n1 < 0.0, th, g
        if not abs(np.linalg.det(J)) > 1e-300 or abs(g) > 4.0 * MAX_GAP:
            return False, th, g
        step = -np.linalg.solve(J, F)
        new = th + step[:2]
        g += step[2]
        # across a seam: around; across an open edge: onto it (stuck if that is no move)
        moved = np.where(closed, lo + (new - lo) % (hi - lo), np.clip(new, lo, hi))
        moved = np.where(closed & (lo <= new) & (new < hi), new, moved)
        if np.all(moved == th) and np.any(moved != new):
            return False, th, g
        th = moved
    return False, th, g


def reference_search(surface: NurbsFeSurface, u, x1, n1, previous: RayHits | None) -> RayHits:
    """Point by point: the previous pairing, then the brute-force nearest seeds of the ray's
    samples nearest to the ray first (within twice the spacing, each once); the first
    admissible hit."""
    n = x1.shape[0]
    hits = RayHits(np.zeros(n, bool), np.zeros(n, np.int64), np.zeros((n, 2)), np.full(n, np.inf))
    with np.errstate(invalid="ignore"):                 # normals at the poles: unused
        seeds = surface.evaluate(u, surface.seed_piece, surface.seed_theta, second=False).x
    m = int(np.ceil(2.0 * MAX_GAP / surface.spacing)) + 1
    ts = np.linspace(-MAX_GAP, MAX_GAP, m)
    for p in range(n):
        samples = x1[p] + ts[:, None] * n1[p]
        d = np.linalg.norm(samples[:, None] - seeds[None], axis=2)
        nearest = np.argmin(d, axis=1)
        v = seeds[nearest] - x1[p]
        off = np.linalg.norm(v - (v @ n1[p])[:, None] * n1[p], axis=1)
        off[d[np.arange(m), nearest] > SAMPLE_REACH * surface.spacing] = np.inf
        order = np.argsort(off, kind="stable")[:min(m, 4 * CANDIDATES)]
        starts = [(previous.piece[p], previous.theta[p])] if previous is not None and previous.found[p] else []
        starts += [(surface.seed_piece[nearest[j]], surface.seed_theta[nearest[j]])
                   for c, j in enumerate(order) if off[j] <= 2.0 * surface.spacing
                   and nearest[j] not in nearest[order[:c]]]
        for piece, theta in starts:
            ok, th, g = _newton(surface, u, x1[p], n1[p], piece, theta)
            if ok:
                hits.found[p], hits.piece[p], hits.theta[p], hits.g[p] = True, piece, th, g
                break
    return hits


def _assert_same(a: RayHits, b: RayHits) -> None:
    np.testing.assert_array_equal(a.found, b.found)
    np.testing.assert_array_equal(a.piece[a.found], b.piece[a.found])
    np.testing.assert_allclose(a.theta[a.found], b.theta[a.found], rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(a.g[a.found], b.g[a.found], rtol=0.0, atol=1e-12)


@pytest.mark.slow
def test_search_equals_reference(scene):
    surface, x1, n1, u = scene
    fast = surface.search(u, x1, n1, MAX_GAP)
    slow = reference_search(surface, u, x1, n1, None)
    _assert_same(fast, slow)
    # not vacuous: many hits, of both gap signs, and some rays with none
    g = fast.g[fast.found]
    assert 50 <= g.size < x1.shape[0] and g.min() < -0.01 and g.max() > 0.01
    # the hits are on the rays: x2(theta) = x1 + g n1, the master normal against n1
    mp = surface.evaluate(u, fast.piece[fast.found], fast.theta[fast.found])
    np.testing.assert_allclose(mp.x, x1[fast.found] + g[:, None] * n1[fast.found], rtol=0.0, atol=1e-11)
    assert np.all(np.einsum("pk,pk->p", mp.normal, n1[fast.found]) < 0.0)


def test_seeds_move_with_the_surface(scene):
    """The seeds' current positions are the current surface at their parameters."""
    surface, _, _, u = scene
    rows = np.arange(0, surface.seed_piece.size, 3)
    with np.errstate(invalid="ignore"):                 # normals at the poles: unused
        x = surface.evaluate(u, surface.seed_piece[rows], surface.seed_theta[rows], second=False).x
    np.testing.assert_allclose(surface._seed_positions(u, rows), x, rtol=0.0, atol=1e-12)
    np.testing.assert_array_equal(surface._seed_positions(u)[rows], surface._seed_positions(u, rows))


def test_starts_are_the_nearest_seeds_of_the_samples(scene):
    """Every ray's starts, against brute force: the nearest seeds of its segment's samples
    (within SAMPLE_REACH spacings), nearest to the ray first (ties in sample order), those
    within twice the spacing and each once; then no start (-1)."""
    surface, x1, n1, u = scene
    piece, theta = surface._starts(u, x1, n1, MAX_GAP)
    seeds = surface._seed_positions(u)
    m = int(np.ceil(2.0 * MAX_GAP / surface.spacing)) + 1
    assert piece.shape == (x1.shape[0], min(m, 4 * CANDIDATES)) and theta.shape == piece.shape + (2,)
    ts = np.linspace(-MAX_GAP, MAX_GAP, m)
    counts = []
    for p in range(x1.shape[0]):
        samples = x1[p] + ts[:, None] * n1[p]
        d = np.linalg.norm(samples[:, None] - seeds[None], axis=2)
        nearest = np.argmin(d, axis=1)
        v = seeds[nearest] - x1[p]
        off = np.linalg.norm(np.cross(v, n1[p]), axis=1)
        off[d[np.arange(m), nearest] > SAMPLE_REACH * surface.spacing] = np.inf
        order = np.argsort(off, kind="stable")[:piece.shape[1]]
        chosen = [nearest[j] for c, j in enumerate(order)
                  if off[j] <= 2.0 * surface.spacing and nearest[j] not in nearest[order[:c]]]
        k = len(chosen)
        counts.append(k)
        np.testing.assert_array_equal(piece[p, :k], surface.seed_piece[chosen])
        np.testing.assert_array_equal(theta[p, :k], surface.seed_theta[chosen])
        assert np.all(piece[p, k:] == -1)
    # not vacuous: rays with several starts and rays with none
    assert max(counts) >= 3 and min(counts) == 0


def test_master_facing_the_ray_is_no_hit(scene):
    """Points 0.1 inside the master sphere whose normals point out: the ray meets the surface
    at g ~ 0.1, but its normal goes the ray's way (not opposing the slave's), so there is no
    admissible hit within MAX_GAP; with the normals turned in, every ray hits at g ~ -0.1."""
    surface, _, _, u = scene
    rng = np.random.default_rng(7)
    d = rng.standard_normal((100, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    x1 = 0.9 * d
    assert not surface.search(u, x1, d, MAX_GAP).found.any()
    inward = surface.search(u, x1, -d, MAX_GAP)
    assert inward.found.all()
    np.testing.assert_allclose(inward.g, -0.1, atol=0.045)    # the random field (0.02 per dof): 0.030


@pytest.mark.slow
def test_search_from_previous_pairing_equals_reference(scene):
    """From a previous pairing whose master elements are not recorded (``slot=None``), the
    search equals the reference point by point."""
    surface, x1, n1, u = scene
    first = surface.search(0.7 * u, x1, n1, MAX_GAP)
    previous = RayHits(first.found, first.piece, first.theta, first.g)
    fast = surface.search(u, x1, n1, MAX_GAP, previous)
    _assert_same(fast, reference_search(surface, u, x1, n1, previous))
    assert np.sum(previous.found & fast.found) >= 50


def test_a_hit_keeps_its_master_element_across_a_face(scene):
    """With the previous pairing's elements recorded, a hit that moved out of its element by
    less than STICKY (in local coordinates) stays in it: the master surface is evaluated with
    that element's field (extrapolated), the hit still lies on the ray in it, and every hit
    farther out, or without a previous pairing, is in the element that holds it."""
    from cgfem.contact._ray_kernels import STICKY
    surface, x1, n1, u = scene
    first = surface.search(0.7 * u, x1, n1, MAX_GAP)
    fast = surface.search(u, x1, n1, MAX_GAP, first)
    rows = np.flatnonzero(fast.found)
    mp = surface.evaluate(u, fast.piece[rows], fast.theta[rows], slot=fast.slot[rows])
    np.testing.assert_allclose(mp.x, x1[rows] + fast.g[rows, None] * n1[rows], rtol=0.0, atol=1e-11)
    X = mp.x - np.einsum("pa,pak->pk", mp.phi, u.reshape(-1, 3)[surface.space.connectivity[mp.slot]])
    located, _ = surface.space.locate(X)
    xi = (X - surface.space.centres()[fast.slot[rows]]) / (0.5 * surface.space.h)
    kept = located != fast.slot[rows]
    assert kept.sum() >= 1                      # this scene has a hit that crossed a face
    assert np.all(np.abs(xi[kept]).max(axis=1) <= 1.0 + STICKY)
    assert np.all(first.slot[rows[kept]] == fast.slot[rows[kept]])
    # without a previous pairing every hit is in the element holding its reference point
    fresh = surface.search(u, x1, n1, MAX_GAP)
    f = np.flatnonzero(fresh.found)
    mf = surface.evaluate(u, fresh.piece[f], fresh.theta[f], second=False)
    Xf = mf.x - np.einsum("pa,pak->pk", mf.phi, u.reshape(-1, 3)[surface.space.connectivity[mf.slot]])
    np.testing.assert_array_equal(fresh.slot[f], surface.space.locate(Xf)[0])


def test_polished_hits_are_on_the_continuous_surface(scene):
    """With ``polish`` the hits that the previous pairing kept on an element's extension are
    moved onto the element holding them: every hit then equals the fresh search's (no
    previous pairing) point by point, elements included, and lies on its ray."""
    surface, x1, n1, u = scene
    first = surface.search(0.7 * u, x1, n1, MAX_GAP)
    kept = surface.search(u, x1, n1, MAX_GAP, first)
    fresh = surface.search(u, x1, n1, MAX_GAP)
    surface.polish = True
    try:
        polished = surface.search(u, x1, n1, MAX_GAP, first)
    finally:
        surface.polish = False
    both = kept.found & fresh.found
    assert np.sum(both & (kept.slot != fresh.slot)) >= 1      # the scene keeps some element
    np.testing.assert_array_equal(polished.found, fresh.found)
    f = np.flatnonzero(fresh.found)
    np.testing.assert_array_equal(polished.slot[f], fresh.slot[f])
    np.testing.assert_allclose(polished.g[f], fresh.g[f], rtol=0.0, atol=1e-10 * surface.h)   # the ray tolerance
    mp = surface.evaluate(u, polished.piece[f], polished.theta[f], second=False)
    np.testing.assert_array_equal(mp.slot, polished.slot[f])
    np.testing.assert_allclose(mp.x, x1[f] + polished.g[f, None] * n1[f], rtol=0.0, atol=1e-11)


def test_prefilter_keeps_every_ray_through_the_master(scene):
    """The box prefilter drops slave rays (not vacuous), but never one whose segment passes
    through a master point: rays through the seeds in random directions are all kept."""
    surface, x1, n1, u = scene
    assert 0 < np.sum(~surface._may_hit(u, x1, MAX_GAP, n1)) < x1.shape[0]
    with np.errstate(invalid="ignore"):
        seeds = surface.evaluate(u, surface.seed_piece, surface.seed_theta, second=False).x
    rng = np.random.default_rng(4)
    d = rng.standard_normal(seeds.shape)
    d /= np.linalg.norm(d, axis=1)[:, None]
    g = rng.uniform(-MAX_GAP, MAX_GAP, seeds.shape[0])
    g[:10] = MAX_GAP                                                  # segment ends on the seed
    assert np.all(surface._may_hit(u, seeds - g[:, None] * d, MAX_GAP, d))


def test_master_point_equals_evaluate(scene):
    surface, _, _, u = scene
    layout, knots, control = pack_patches([p.surface for p in surface.solid.patches])
    rng = np.random.default_rng(2)
    (u0, u1), (v0, v1) = surface.solid.patches[0].surface.domain
    theta = np.column_stack([rng.uniform(u0, u1, 20), rng.uniform(v0, v1, 20)])
    mp = surface.evaluate(u, np.zeros(20, np.int64), theta, second=False)
    grid = surface.space.grid
    x, t = np.empty(3), np.empty((2, 3))
    for p in range(20):
        slot = rk.master_point(0, theta[p, 0], theta[p, 1], layout, knots, control, np.asarray(grid.origin, float),
                               grid.h, np.asarray(grid.shape, np.int64), surface.space.elements, LOCATE_TOL,
                               surface.space.connectivity, u.reshape(-1, 3), x, t)
        assert slot == mp.slot[p]
        np.testing.assert_allclose(x, mp.x[p], rtol=0.0, atol=1e-14)
        np.testing.assert_allclose(t, mp.t[p], rtol=0.0, atol=1e-13)


def test_solve3_equals_numpy():
    rng = np.random.default_rng(3)
    step = np.empty(3)
    for _ in range(20):
        J, F = rng.standard_normal((3, 3)), rng.standard_normal(3)
        assert rk.solve3(J.copy(), F, step)
        np.testing.assert_allclose(step, -np.linalg.solve(J, F), rtol=1e-12, atol=1e-12)
    singular = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    assert not rk.solve3(singular, np.ones(3), step)


def test_sticky_band_is_exactly_the_band():
    """An element is kept for a point within 1 + band of its cube in local coordinates (the
    band of every hit, STICKY, and of a held piece, HOLD_BAND), and left just outside, on
    every axis and side."""
    from cgfem.contact._ray_kernels import HOLD_BAND, STICKY, sticky_xi
    origin, h, shape = np.zeros(3), 0.5, np.array([3, 3, 3], np.int64)
    elements = np.arange(27, dtype=np.int64)
    centre = np.full(3, 1.5 * h)                    # element (1, 1, 1), slot 13
    xi = np.empty(3)
    for band in (STICKY, HOLD_BAND):
        for axis in range(3):
            for side in (-1.0, 1.0):
                for extra, kept in ((0.5 * band, True), (2.0 * band, False)):
                    Q = centre.copy()
                    Q[axis] += side * (1.0 + extra) * 0.5 * h
                    assert sticky_xi(Q, 13, band, origin, h, shape, elements, xi) == kept
                    assert abs(xi[axis] - side * (1.0 + extra)) < 1e-12
    assert not sticky_xi(centre, -1, STICKY, origin, h, shape, elements, xi)


def test_newton_wraps_across_a_seam(scene):
    """The sphere closes on itself along u: a ray hitting just before the seam, started just
    after it, converges to the hit by going around (the clipped step used to stop at the seam:
    a penetrating point of chain3's middle torus went unpaired). The meridian direction is
    open: a start past its end stays clipped."""
    surface, _, _, u = scene
    patch = surface.solid.patches[0].surface
    assert closed_directions(patch) == (True, False)
    layout, knots, control = pack_patches([p.surface for p in surface.solid.patches])
    (u0, u1), (v0, v1) = patch.domain
    grid = surface.space.grid
    args = (layout, knots, control, np.asarray(grid.origin, float), grid.h, np.asarray(grid.shape, np.int64),
            surface.space.elements, LOCATE_TOL, surface.space.connectivity, u.reshape(-1, 3))
    out = np.empty(4)
    for v in np.linspace(v0, v1, 7)[1:-1]:
        target = np.array([u1 - 1e-3 * (u1 - u0), v])
        mp = surface.evaluate(u, np.zeros(1, np.int64), target[None], second=False)
        n1 = -mp.normal[0]                            # from outside, against the outward normal
        x1 = mp.x[0] - 0.01 * n1
        for start in (u0 + 2e-3 * (u1 - u0), u1 - 5e-3 * (u1 - u0)):
            r = rk.ray_newton(x1, n1, 0, start, v, 0.0, MAX_GAP, RAY_TOL, MAX_RAY_NEWTON, *args, -1, rk.STICKY, out)
            assert r == 1
            np.testing.assert_allclose(out[:2], target, atol=1e-10)
            np.testing.assert_allclose(out[2], 0.01, atol=1e-12)


def test_pairs_within_are_exactly_the_pairs_at_most_reach_apart():
    rng = np.random.default_rng(3)
    x, y = rng.uniform(0.0, 1.0, (300, 3)), rng.uniform(0.0, 1.0, (200, 3))
    reach = 0.15
    i, j = pairs_within(x, surface_tree(y), reach)
    d = np.linalg.norm(x[:, None] - y[None], axis=2)
    expected = set(zip(*np.nonzero(d <= reach)))
    assert i.dtype == j.dtype == np.int64
    assert len(i) == len(expected) > 300
    assert set(zip(i.tolist(), j.tolist())) == expected
