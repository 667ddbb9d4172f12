"""Triangulated boundaries (boundary_NNN.vtu): the NURBS tessellation is closed, outward,
holds every knot line, and its area and enclosed volume converge to the exact ones at second
order in the spacing; the facets' triangles enclose exactly the volume the facets definition
integrates."""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.embedding.quadrature import embed, grid_for
from cgfem.embedding.tessellate import boundary_tessellation, span_samples, tessellate_nurbs
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import SphereSpec, TorusSpec

R, r = 1.0, 0.4
TORUS = TorusSpec(center=(0.1, -0.2, 0.3), axis=(0.0, 0.6, 0.8), major_radius=R, minor_radius=r)
TORUS_AREA, TORUS_VOLUME = 4.0 * np.pi ** 2 * R * r, 2.0 * np.pi ** 2 * R * r ** 2


def area_and_volume(x: np.ndarray, triangles: np.ndarray) -> tuple[float, float]:
    """Total area and the volume enclosed by the divergence theorem, V = sum (c . n) A / 3,
    with the triangles' own orientation (positive when they face outward)."""
    a, b, c = (x[triangles[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(cross, axis=1).sum()
    volume = np.einsum("ij,ij->", (a + b + c) / 3.0, cross) / 6.0
    return float(area), float(volume)


def test_every_knot_is_a_sample_and_spans_are_resolved():
    solid = build_solid(TORUS)
    for patch in solid.patches:
        s = patch.surface
        u, v = span_samples(s, 0.05)
        for samples, knots in zip((u, v), s.breaks()):
            assert np.all(np.isin(knots, samples))
            assert np.all(np.diff(samples) > 0.0)
        # neighbouring samples along the surface at most ~ the spacing apart
        uv = np.stack(np.meshgrid(u, v, indexing="ij"), axis=-1)
        x = s.evaluate(uv.reshape(-1, 2)).reshape(uv.shape[:2] + (3,))
        assert np.linalg.norm(np.diff(x, axis=0), axis=2).max() <= 0.05 * 1.05
        assert np.linalg.norm(np.diff(x, axis=1), axis=2).max() <= 0.05 * 1.05


def test_nurbs_tessellation_converges_at_second_order():
    """Area and volume errors of the torus fall by ~4 when the spacing halves, and the
    enclosed volume is positive: the triangles face outward."""
    solid = build_solid(TORUS)
    errors = []
    for spacing in (0.1, 0.05):
        t = tessellate_nurbs(solid, solid.patch_names, spacing)
        area, volume = area_and_volume(t.x, t.triangles)
        assert volume > 0.0
        errors.append((abs(area / TORUS_AREA - 1.0), abs(volume / TORUS_VOLUME - 1.0)))
    (a0, v0), (a1, v1) = errors
    assert a1 < 2e-3 and v1 < 4e-3
    assert a0 / a1 > 3.5 and v0 / v1 > 3.5


@pytest.mark.parametrize("spec,h0", [(TORUS, 0.3), (SphereSpec((0.05, 0.02, -0.01), 1.0), 0.4)])
def test_facets_enclose_the_volume_the_facets_definition_integrates(spec, h0):
    """The marching-cubes triangles, as drawn, enclose the polyhedron whose volume the
    facets embedding integrates (to round-off), and every edge is shared by two triangles."""
    solid = build_solid(spec)
    emb = embed(solid, grid_for(solid, h0, 1, (0.13, 0.29, 0.41)), "facets")
    t = boundary_tessellation(solid, emb)
    _, volume = area_and_volume(t.x, t.triangles)
    assert volume == pytest.approx(float(emb.volume.w.sum()), rel=1e-10)
    # closed: merge coincident vertices, then each undirected edge has exactly two triangles
    _, ids = np.unique(np.round(t.x / h0, 9), axis=0, return_inverse=True)
    tri = ids.ravel()[t.triangles]
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)


def test_nurbs_boundary_default_spacing_is_half_the_element():
    solid = build_solid(TORUS)
    emb = embed(solid, grid_for(solid, 0.3, 1, (0.13, 0.29, 0.41)))
    t = boundary_tessellation(solid, emb)
    assert np.all(np.isin(t.patch, np.arange(len(emb.patch_names))))
    # the legs of every triangle (along u and v) stay within the spacing h / 2: vertices are
    # numbered i n_v + j in each patch, so of a triangle's three edges the diagonal joins the
    # two vertices whose numbers differ most (n_v + 1) and the other two are the legs
    tri = t.triangles
    ends = np.stack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], axis=1)        # (m, 3, 2)
    diagonal = np.argmax(np.abs(ends[:, :, 0] - ends[:, :, 1]), axis=1)
    legs = ends[np.arange(len(tri))[:, None], (diagonal[:, None] + [1, 2]) % 3].reshape(-1, 2)
    lengths = np.linalg.norm(t.x[legs[:, 1]] - t.x[legs[:, 0]], axis=1)
    assert lengths.max() <= 0.5 * emb.grid.h * 1.05


def test_keep_vertices_renumbers_the_triangles_left():
    from cgfem.embedding.tessellate import keep_vertices

    triangles = np.array([[0, 1, 2], [1, 3, 2], [3, 4, 2]])
    kept, used = keep_vertices(triangles, np.array([True, True, True, False, True]))
    assert np.array_equal(kept, [[0, 1, 2]]) and np.array_equal(used, [True, True, True, False, False])
