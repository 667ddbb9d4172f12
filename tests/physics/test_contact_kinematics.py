"""Contact kinematics: the ray-traced gap, its pairing and the consistent tangent.

A box (slave, its bottom face) pressed onto a sphere (master) with random displacement
fields on both bodies: points on several master elements, nonzero gaps of both signs, a
curved master. The tangent of the contact residual must equal its central finite
difference (paper eqs. 28-30 are exact), with small-strain (reference area, symmetric)
and finite-strain (current area, non-symmetric) weights.
"""

from __future__ import annotations

import copy
import functools

import numpy as np
import pytest
import scipy.sparse as sp

from cgfem.contact.pair import ContactPair, slave_gradients
from cgfem.contact.surfaces import FacetSurface, NurbsFeSurface
from cgfem.embedding.quadrature import embed, grid_for
from cgfem.fem.element import hexahedron
from cgfem.fem.space import Space
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import BoxSpec, SphereSpec


@functools.lru_cache(maxsize=None)
def _bodies(surface: str, degree: int = 2):
    """The sphere (master) and the box (slave) embedded with rules of ``degree`` (built once
    per test module and reused: the pairs built on them own all their state)."""
    master = build_solid(SphereSpec(center=(0, 0, 0), radius=1.0))
    slave = build_solid(BoxSpec(min=(-0.45, -0.4, 0.93), max=(0.4, 0.45, 1.5)))
    em = embed(master, grid_for(master, 0.5, 1, (0.13, 0.29, 0.41)), surface, degree=degree)
    es = embed(slave, grid_for(slave, 0.3, 1, (0.37, 0.71, 0.23)), surface, degree=degree)
    return master, slave, em, es


def _pair(definition: str, finite: bool, order: int = 1) -> ContactPair:
    """The box's bottom face on the sphere, with the hexahedra of ``order`` on both bodies."""
    quadrature = "facets" if definition == "facets" else "nurbs"
    element = hexahedron(order)
    master, slave, em, es = _bodies(quadrature, element.degree)
    Sm, Ss = Space.from_embedding(em, element), Space.from_embedding(es, element)
    zmin = np.array([i for i, p in enumerate(slave.patches) if p.name == "zmin"])
    rule = es.boundary.select(np.isin(es.boundary.patch, zmin))
    if definition == "nurbs_fe":
        frames = NurbsFeSurface(slave, Ss, rule, zmin).slave_frames(rule)
        target = NurbsFeSurface(master, Sm, em.surface, np.arange(len(master.patches)))
    else:
        fs, fm = es.facets, em.facets
        frames = FacetSurface(Ss, fs.triangles, fs.element, np.isin(fs.patch, zmin)).slave_frames(
            rule.piece, rule.uv, rule.w)
        target = FacetSurface(Sm, fm.triangles, fm.element, np.ones(fm.patch.size, bool))
    return ContactPair("test", 0, 1, Ss, Sm, frames, slave_gradients(Ss, frames), target,
                       eps=1e3, finite=finite, max_gap=0.5)


@pytest.fixture(scope="module", params=["nurbs_fe", "facets"])
def definition(request):
    return request.param


def test_the_tangent_in_chunks_is_the_tangent_at_once(definition, monkeypatch):
    """The active points' blocks are summed a chunk of points at a time (memory): the chunks'
    triplets, summed, are the one chunk's matrix, and the residual is the same."""
    import cgfem.contact.pair as pair_module

    pair = _pair(definition, False, 1)
    rng = np.random.default_rng(1)
    n_s, n_m = pair.slave_space.n_dofs, pair.master_space.n_dofs
    n = n_s + n_m
    u = 0.02 * rng.standard_normal(n)
    pair.state.p_N = 50.0 * rng.standard_normal(pair.n_points) - 20.0
    start = copy.deepcopy(pair.state)
    results = []
    for chunk in (10 ** 9, 1):               # one chunk; chunks of 64 points
        monkeypatch.setattr(pair_module, "CHUNK_POINTS", chunk)
        pair.state = copy.deepcopy(start)
        r_s, r_m, (rows, cols, vals) = pair.assemble(u[:n_s], u[n_s:], True)
        results.append((np.concatenate([r_s, r_m]), sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()))
    (r1, K1), (r2, K2) = results
    assert np.count_nonzero(pair.state.active) > 3 * 64      # several chunks
    np.testing.assert_array_equal(r1, r2)
    assert abs(K1 - K2).max() <= 1e-13 * abs(K1).max()


@pytest.mark.parametrize("order", [1, pytest.param(2, marks=pytest.mark.slow)])
@pytest.mark.parametrize("finite", [False, True])
def test_tangent_equals_central_differences(definition, finite, order):
    pair = _pair(definition, finite, order)
    rng = np.random.default_rng(0)
    n_s, n_m = pair.slave_space.n_dofs, pair.master_space.n_dofs
    u = 0.02 * rng.standard_normal(n_s + n_m)
    pair.state.p_N = 50.0 * rng.standard_normal(pair.n_points) - 20.0
    r_s, r_m, (rows, cols, vals) = pair.assemble(u[:n_s], u[n_s:], True)
    hits, active = pair.state.hits, pair.state.active
    # the state exercises what it should: most points paired, on many master elements,
    # some active and some not, gaps of both signs
    assert hits.found.mean() > 0.9
    assert 0.2 < active.mean() < 0.9
    assert np.any(hits.g[hits.found] > 0) and np.any(hits.g[hits.found] < 0)
    masters = pair.surface.evaluate(u[n_s:], hits.piece[active], hits.theta[active]).slot
    assert np.unique(masters).size >= 8
    K = sp.coo_matrix((vals, (rows, cols)), shape=(n_s + n_m,) * 2).tocsr()

    def residual(v):
        a, b, _ = pair.assemble(v[:n_s], v[n_s:], False, update=False)
        return np.concatenate([a, b])

    d = rng.standard_normal(n_s + n_m)
    # fourth-order central differences: the triquadratic random field curves the surfaces so
    # much that the second-order stencil's truncation error (2e-4 at a step of 1e-6, falling
    # as the step squared) hides the comparison; a much larger step crosses an active-set or
    # element switch (the residual is only piecewise smooth)
    step = 2e-7
    fd = (8.0 * (residual(u + step * d) - residual(u - step * d))
          - (residual(u + 2.0 * step * d) - residual(u - 2.0 * step * d))) / (12.0 * step)
    exact = K @ d
    assert np.linalg.norm(fd - exact) <= 1e-6 * np.linalg.norm(exact)
    asym = abs(K - K.T).max() / abs(K).max()
    if finite:
        assert asym > 1e-3          # the current-area weight makes it non-symmetric
    else:
        assert asym < 1e-12


def test_gap_is_the_distance_along_the_normal(definition):
    """Undeformed: the ray from a slave point on z = 0.93 straight down hits the sphere at
    z = sqrt(1 - x^2 - y^2) (exactly for NURBS+FE, to O(h^2) for facets)."""
    pair = _pair(definition, False)
    n_s, n_m = pair.slave_space.n_dofs, pair.master_space.n_dofs
    pair.assemble(np.zeros(n_s), np.zeros(n_m), False)
    hits, X = pair.state.hits, pair.frames.X
    # facets chamfer the box's edges: their tilted triangles look sideways, past the sphere
    normal_z = np.cross(pair.frames.A, pair.frames.B)[:, 2] / np.linalg.norm(
        np.cross(pair.frames.A, pair.frames.B), axis=1)
    down = normal_z < -0.999
    assert down.mean() > 0.6
    assert hits.found[down].all()
    found = hits.found & down
    exact = 0.93 - np.sqrt(1.0 - X[found, 0] ** 2 - X[found, 1] ** 2)
    error = np.abs(hits.g[found] - exact).max()
    if definition == "nurbs_fe":
        assert error < 1e-12
    else:
        assert 1e-5 < error < 0.02      # facets chord error ~ h^2 / (8 R) with h = 0.25


def _two_states(definition: str, seed: int) -> tuple[ContactPair, int, np.ndarray, np.ndarray]:
    """A small-strain pair with ``p_N = 0`` at the start of an increment, and two nearby
    states of its unknowns (the slave moved by 0.004 between them): ``(pair, n_s, u0, u1)``."""
    pair = _pair(definition, False)
    n_s, n_m = pair.slave_space.n_dofs, pair.master_space.n_dofs
    rng = np.random.default_rng(seed)
    u0 = 0.01 * rng.standard_normal(n_s + n_m)
    u1 = u0.copy()
    u1[:n_s] += 0.004 * rng.standard_normal(n_s)
    pair.state.p_N = np.zeros(pair.n_points)
    pair.begin_pass()
    return pair, n_s, u0, u1


def test_chattering_points_are_held_then_released():
    """Points whose status flips at every linearization point are held after MAX_SWITCHES
    flips, as they were, in the residual too (an active one keeps lambda = p_N + eps g even in
    tension); ``contradicted`` counts held points against their own rule; a new pass releases
    them."""
    from cgfem.contact.pair import MAX_SWITCHES
    pair, n_s, u0, u1 = _two_states("nurbs_fe", 5)
    states = []
    for k in range(MAX_SWITCHES + 2):
        pair.assemble(*(np.split(u0 if k % 2 == 0 else u1, [n_s])), True)
        states.append(pair.state.natural.copy())
    flips = states[0] != states[1]
    assert flips.sum() >= 5                                # the scene makes points chatter
    held = pair.state.held
    np.testing.assert_array_equal(held, flips)              # exactly the chattering ones
    # the first evaluation sets the status, the next MAX_SWITCHES flip it: held at the last
    # of those (at u0); the one after (at u1) contradicts their rule
    np.testing.assert_array_equal(pair.state.held_active[held], states[0][held])
    assert pair.contradicted() == flips.sum()
    # residual: a held-active point in tension carries lambda = p_N + eps g > 0
    pair.assemble(*np.split(u1, [n_s]), False, update=False)
    lam, active, natural = pair._multiplier(pair.state.hits)
    tension = held & active & ~natural
    assert tension.any() and np.all(lam[tension] > 0.0)
    assert np.all(lam[held & ~active] == 0.0)
    pair.begin_pass()
    assert pair.contradicted() == 0 and not pair.state.held.any()


@pytest.mark.parametrize("order", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_candidate_list_keeps_every_hit(definition, order):
    """The search runs on a Verlet list of slave points (``ContactPair.candidates``): it
    finds exactly the hits of a search over all points, is reused while the bodies move by
    less than its skin (the nodal move times the element's Lebesgue constant) and rebuilt
    after, and drops points out of reach."""
    from cgfem.contact.pair import SKIN
    pair = _pair(definition, False, order)
    lebesgue = pair.slave_space.element.lebesgue
    n_s, n_m = pair.slave_space.n_dofs, pair.master_space.n_dofs
    rng = np.random.default_rng(4)
    u = 0.02 * rng.standard_normal(n_s + n_m)
    down = np.zeros(n_s + n_m)
    down[2:n_s:3] = -1.0                                     # slave translation along -z

    def same_as_full(v):
        st, hits = pair.search(v[:n_s], v[n_s:])
        full = pair.surface.search(v[n_s:], st.x, st.n, pair.max_gap)
        np.testing.assert_array_equal(hits.found, full.found)
        np.testing.assert_allclose(hits.g[hits.found], full.g[full.found], atol=1e-12)
        return hits

    assert same_as_full(u).found.sum() > 50
    built = pair.state.candidates[0]
    same_as_full(u + 0.4 / lebesgue * SKIN * pair.max_gap * down)     # within the skin: reused
    assert pair.state.candidates[0] is built
    same_as_full(u + 1.5 * SKIN * pair.max_gap * down)                 # beyond it: rebuilt
    assert pair.state.candidates[0] is not built
    far = u - 10.0 * pair.max_gap * down                    # lifted far off the sphere
    assert not same_as_full(far).found.any()
    assert pair.state.candidates[0].size == 0 and pair.state.candidates[1].size == 0


def test_hits_that_keep_changing_piece_are_held(definition):
    """Active hits that go back and forth between two master pieces (triangles, or NURBS+FE
    elements) at every linearization point are held on their piece after MAX_RETURNS
    returns: at the other state they stay on it, on its extension past the kink (still
    exactly on their ray), while every other hit is the search's own; later passes of the
    increment keep the hold, a new increment releases it."""
    from cgfem.contact.pair import MAX_RETURNS, _master_key
    pair, n_s, u0, u1 = _two_states(definition, 6)
    states = [u0 if k % 2 == 0 else u1 for k in range(MAX_RETURNS + 2)]
    assert states[-1] is u0
    keys, active = [], []
    for u in states:
        pair.assemble(*np.split(u, [n_s]), True)
        keys.append(_master_key(pair.state.hits))
        active.append(pair.state.active.copy())
    # A, B, A, B, A: one move and MAX_RETURNS returns
    always = np.logical_and.reduce(active)
    back_and_forth = always & np.logical_and.reduce(
        [np.any(k != l, axis=1) for k, l in zip(keys, keys[1:])]
        + [np.all(k == l, axis=1) for k, l in zip(keys, keys[2:])])
    assert back_and_forth.sum() >= 3                           # the scene moves some hits
    np.testing.assert_array_equal(pair.state.piece_held, back_and_forth)
    moving = back_and_forth
    both = active[-1] & active[-2]
    # at u1 the held hits keep u0's piece, on its extension, exactly on their ray
    pair.begin_pass(increment=False)                           # a later pass: still held
    x = pair._slave(u1[:n_s])
    hits = pair.search(*np.split(u1, [n_s]))[1]
    np.testing.assert_array_equal(_master_key(hits)[moving], keys[-1][moving])
    mp = pair.surface.evaluate(u1[n_s:], hits.piece[moving], hits.theta[moving], second=False,
                               slot=None if hits.slot is None else hits.slot[moving])
    np.testing.assert_allclose(mp.x, x.x[moving] + hits.g[moving, None] * x.n[moving], rtol=0.0, atol=1e-10)
    # not held: the hit the search finds without the hold
    np.testing.assert_array_equal(_master_key(hits)[both & ~moving], keys[-2][both & ~moving])
    pair.begin_pass()                                          # a new increment
    assert not pair.state.piece_held.any() and not pair.state.returns.any()


def test_only_hits_going_back_are_held():
    """The hold counts returns to the piece a hit has just left, not moves: over five
    linearization points a hit going back and forth (A B A B A: 3 returns) is held, one
    sliding on (A B C D E) is not, nor one that came back once and stayed (A B A A A)."""
    from cgfem.contact.pair import MAX_RETURNS
    from cgfem.contact.surfaces import RayHits
    assert MAX_RETURNS == 3
    pair = _pair("facets", False)
    n = pair.n_points
    pair.begin_pass()
    paths = {0: [1, 2, 1, 2, 1], 1: [1, 2, 3, 4, 5], 2: [1, 2, 1, 1, 1]}
    active = np.zeros(n, bool)
    active[list(paths)] = True
    for k in range(5):
        piece = np.zeros(n, np.int64)
        for p, path in paths.items():
            piece[p] = path[k]
        hits = RayHits(active.copy(), piece, np.zeros((n, 2)), np.zeros(n), np.zeros(n, np.int64))
        pair._record(hits, active.copy(), active.copy())
    np.testing.assert_array_equal(np.flatnonzero(pair.state.piece_held), [0])
    np.testing.assert_array_equal(pair.state.returns[:3], [3, 0, 1])
