"""Facet ray tracing (:meth:`FacetSurface.search`) against a brute-force reference, and its
stickiness: a hit keeps the triangle of the previous pairing while the ray meets that
triangle's plane within ``STICKY`` (barycentric) of its edges, and only then.

The master is a sphere's marching-cubes surface with random nodal displacements; its
triangles are flat and the ray-triangle intersection is closed form, so the reference solves
every (point, triangle) pair and keeps the nearest admissible hit.
"""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.contact._ray_kernels import STICKY
from cgfem.contact.surfaces import FacetSurface, RayHits
from cgfem.embedding.quadrature import embed, grid_for
from cgfem.fem.space import Space
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import SphereSpec

MAX_GAP = 0.3


@pytest.fixture(scope="module")
def scene():
    master = build_solid(SphereSpec(center=(0, 0, 0), radius=1.0))
    em = embed(master, grid_for(master, 0.5, 1, (0.13, 0.29, 0.41)), "facets")
    space = Space.from_embedding(em)
    f = em.facets
    surface = FacetSurface(space, f.triangles, f.element, np.ones(f.patch.size, bool))
    u = 0.01 * np.random.default_rng(3).standard_normal(space.n_dofs)
    U = u.reshape(-1, 3)[space.connectivity[surface.slot]]
    verts = surface.triangles + np.einsum("mva,mak->mvk", surface.vertex_N, U)
    return surface, u, verts


def _rays(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Points on a sphere of radius 1.15 +- 0.3 looking roughly at the centre (the farthest
    ones miss: beyond MAX_GAP)."""
    rng = np.random.default_rng(seed)
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    x1 = d * (1.15 + 0.3 * rng.uniform(-1, 1, (n, 1)))
    n1 = -d + 0.1 * rng.standard_normal((n, 3))
    return x1, n1 / np.linalg.norm(n1, axis=1)[:, None]


def _reference(verts: np.ndarray, x1: np.ndarray, n1: np.ndarray) -> RayHits:
    n = x1.shape[0]
    hits = RayHits(np.zeros(n, bool), np.zeros(n, np.int64), np.zeros((n, 2)), np.full(n, np.inf))
    for p in range(n):
        for t, v in enumerate(verts):
            e1, e2 = v[1] - v[0], v[2] - v[0]
            l1, l2, g = np.linalg.solve(np.column_stack([e1, e2, -n1[p]]), x1[p] - v[0])
            inside = min(l1, l2) >= -1e-10 and l1 + l2 <= 1.0 + 1e-10
            if inside and np.cross(e1, e2) @ n1[p] < 0.0 and abs(g) <= MAX_GAP and abs(g) < abs(hits.g[p]):
                hits.found[p], hits.piece[p], hits.theta[p], hits.g[p] = True, t, (l1, l2), g
    return hits


def test_search_equals_brute_force(scene):
    surface, u, verts = scene
    x1, n1 = _rays(150, 0)
    got = surface.search(u, x1, n1, MAX_GAP)
    ref = _reference(verts, x1, n1)
    assert ref.found.sum() > 80 and (~ref.found).sum() > 0   # and misses
    np.testing.assert_array_equal(got.found, ref.found)
    np.testing.assert_array_equal(got.piece[ref.found], ref.piece[ref.found])
    np.testing.assert_allclose(got.theta[ref.found], ref.theta[ref.found], atol=1e-12)
    np.testing.assert_allclose(got.g[ref.found], ref.g[ref.found], atol=1e-12)


def test_triangles_facing_the_ray_are_no_hits(scene):
    """Points 0.1 inside the sphere whose normals point out: the ray meets the near triangles
    at g ~ 0.1, but their normals go the ray's way (not opposing the slave's), so there is no
    admissible hit within MAX_GAP; with the normals turned in, every ray hits at g ~ -0.1."""
    surface, u, verts = scene
    d = np.random.default_rng(1).standard_normal((150, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    x1 = 0.9 * d
    out = surface.search(u, x1, d, MAX_GAP)
    assert not out.found.any() and not _reference(verts, x1, d).found.any()
    inward = surface.search(u, x1, -d, MAX_GAP)
    assert inward.found.all()
    np.testing.assert_allclose(inward.g, -0.1, atol=0.04)   # chords and the random field: 0.024


def test_ray_near_an_edge_hits_its_own_triangle(scene):
    """Rays along the inward normal of a triangle through a point 1e-4 (barycentric) inside
    each of its edges hit that triangle, at the constructed point: a neighbour's plane
    extended past the shared edge lies just above it on a convex surface and would be the
    nearer hit if hits were admitted a little outside a triangle."""
    surface, u, verts = scene
    rng = np.random.default_rng(5)
    tris = rng.choice(len(verts), 60, replace=False)
    near_edge = np.array([[0.5, 0.5 - 1e-4], [1e-4, 0.5], [0.5, 1e-4]])   # l1 + l2 = 1, l1 = 0, l2 = 0
    t = np.repeat(tris, 3)
    theta = np.tile(near_edge, (tris.size, 1))
    v = verts[t]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    point = v[:, 0] + theta[:, :1] * e1 + theta[:, 1:] * e2
    m = np.cross(e1, e2)
    m /= np.linalg.norm(m, axis=1)[:, None]
    hits = surface.search(u, point + 0.05 * m, -m, MAX_GAP)
    assert hits.found.all()
    np.testing.assert_array_equal(hits.piece, t)
    np.testing.assert_allclose(hits.theta, theta, atol=1e-9)
    np.testing.assert_allclose(hits.g, 0.05, atol=1e-12)


@pytest.mark.parametrize("past, kept", [(0.5 * STICKY, True), (2.0 * STICKY, False)])
def test_previous_triangle_is_kept_within_the_band(scene, past, kept):
    """Rays perpendicular to a triangle, through its plane ``past`` beyond one of its edges
    (barycentric), with that triangle as the previous pairing."""
    surface, u, verts = scene
    rng = np.random.default_rng(4)
    tri = rng.choice(verts.shape[0], 40, replace=False)
    v = verts[tri]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    normal = np.cross(e1, e2)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    foot = v[:, 0] - past * e1 + 0.5 * e2            # l1 = -past, l2 = 0.5: past edge v0-v2
    x1 = foot + 0.05 * normal                        # outside, looking in
    previous = RayHits(np.ones(tri.size, bool), tri.astype(np.int64), np.zeros((tri.size, 2)),
                       np.zeros(tri.size))
    got = surface.search(u, x1, -normal, MAX_GAP, previous)
    assert got.found.all()                           # the neighbour across the edge otherwise
    assert np.all((got.piece == tri) == kept)
    if kept:
        np.testing.assert_allclose(got.theta, np.column_stack([np.full(tri.size, -past),
                                                                np.full(tri.size, 0.5)]), atol=1e-12)
        np.testing.assert_allclose(got.g, 0.05, atol=1e-12)
    # without a previous pairing the same rays never land outside a triangle
    fresh = surface.search(u, x1, -normal, MAX_GAP)
    assert np.all(fresh.piece != tri) and fresh.found.all()
    assert fresh.theta.min() >= -1e-10 and (fresh.theta.sum(axis=1) <= 1.0 + 1e-10).all()
