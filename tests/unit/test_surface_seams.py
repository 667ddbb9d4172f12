"""What the embedding keeps for contact: every boundary point's patch, piece and
parameters (exact ``(xi, eta)`` on NURBS, barycentrics on facets), the facet triangles, and
the surface definition's name."""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.case.model import Body, GridSpec, Material
from cgfem.embedding.quadrature import embed, grid_for
from cgfem.fem.boundary import BoundaryPoints
from cgfem.fem.space import Space
from cgfem.geometry.builders import build_solid
from cgfem.geometry.refine import bezier_patches
from cgfem.geometry.specs import HalfTorusSpec
from cgfem.run import embed_body

SPEC = HalfTorusSpec((0.0004, -0.0007, 0.0002), (0.0, 0.0, 1.0), 0.02, 0.005, (0.0, 1.0, 0.0))
SCALE = 0.025


@pytest.fixture(scope="module")
def solid():
    return build_solid(SPEC)


@pytest.fixture(scope="module")
def embeddings(solid):
    grid = grid_for(solid, 0.005, 1, (0.37, 0.11, 0.64))
    return {s: embed(solid, grid, s) for s in ("nurbs", "facets")}


def _on_triangles(facets, rule) -> np.ndarray:
    """Points (n, 3) rebuilt from their triangle and barycentrics ``(l1, l2)``."""
    t = facets.triangles[rule.piece]
    l1, l2 = rule.uv[:, 0:1], rule.uv[:, 1:2]
    return (1.0 - l1 - l2) * t[:, 0] + l1 * t[:, 1] + l2 * t[:, 2]


def _on_patches(solid, rule) -> np.ndarray:
    """Points (n, 3) of the exact surface at the rule's ``(patch, uv)``."""
    out = np.full((rule.uv.shape[0], 3), np.nan)
    for ip, patch in enumerate(solid.patches):
        rows = rule.patch == ip
        out[rows] = patch.surface.evaluate(rule.uv[rows])
    return out


def test_nurbs_points_keep_patch_piece_and_parameters(solid, embeddings):
    emb = embeddings["nurbs"]
    assert emb.facets is None and emb.definition == "nurbs_fe"
    for rule in (emb.surface, emb.boundary):                        # exact and reduced rules
        assert np.abs(_on_patches(solid, rule) - rule.x).max() < 1e-14 * SCALE
        for ip, patch in enumerate(solid.patches):
            pieces = bezier_patches(patch.surface)
            rows = np.flatnonzero(rule.patch == ip)
            assert rows.size and rule.piece[rows].min() >= 0 and rule.piece[rows].max() < len(pieces)
            lo = np.array([[p[1][0], p[2][0]] for p in pieces])[rule.piece[rows]]
            hi = np.array([[p[1][1], p[2][1]] for p in pieces])[rule.piece[rows]]
            uv = rule.uv[rows]
            assert np.all((uv >= lo - 1e-12) & (uv <= hi + 1e-12))   # in its Bezier piece's box
    # the reduction keeps rows of the exact rule with all their data
    exact = {tuple(row) for row in np.column_stack([emb.surface.x, emb.surface.piece, emb.surface.patch])}
    kept = np.column_stack([emb.boundary.x, emb.boundary.piece, emb.boundary.patch])
    assert all(tuple(row) in exact for row in kept)


def test_facet_points_keep_their_triangle_and_barycentrics(embeddings):
    emb = embeddings["facets"]
    facets = emb.facets
    assert emb.definition == "facets"
    m = facets.triangles.shape[0]
    assert facets.triangles.shape == (m, 3, 3) and facets.element.shape == facets.patch.shape == (m,)
    cross = np.cross(facets.triangles[:, 1] - facets.triangles[:, 0], facets.triangles[:, 2] - facets.triangles[:, 0])
    # a closed polyhedron, counterclockwise about the outward normal: its divergence-theorem
    # volume is the volume rule's, which is exact on the polyhedron
    assert np.abs(cross.sum(axis=0)).max() < 1e-12 * SCALE**2
    volume = np.einsum("ij,ij->", facets.triangles[:, 0], cross) / 6.0
    assert abs(volume - emb.volume.w.sum()) < 1e-10 * volume
    # the element owning each triangle holds it
    centre = emb.grid.element_center(emb.grid.element_ijk(facets.element))
    assert np.abs(facets.triangles - centre[:, None, :]).max() <= 0.5 * emb.grid.h * (1 + 1e-12)
    for rule in (emb.surface, emb.boundary):
        assert np.all((rule.piece >= 0) & (rule.piece < m))
        assert np.abs(_on_triangles(facets, rule) - rule.x).max() < 1e-15 * SCALE
        assert np.all(rule.uv >= 0.0) and np.all(rule.uv.sum(axis=1) <= 1.0)
        assert np.array_equal(rule.element, facets.element[rule.piece])
        assert np.array_equal(rule.patch, facets.patch[rule.piece])
        unit = cross[rule.piece] / np.linalg.norm(cross[rule.piece], axis=1)[:, None]
        assert np.abs(unit - rule.normal).max() < 1e-12
    # the triangle areas are the rule's weights summed per triangle
    area = np.bincount(emb.surface.piece, emb.surface.w, minlength=m)
    assert np.abs(area - 0.5 * np.linalg.norm(cross, axis=1)).max() < 1e-13 * SCALE**2


@pytest.mark.parametrize("surface", ["nurbs", "facets"])
def test_boundary_points_carry_patch_uv_piece_through_the_grouping(solid, embeddings, surface):
    emb = embeddings[surface]
    space = Space.from_embedding(emb)
    rule = emb.boundary.select(np.random.default_rng(0).permutation(emb.boundary.w.size))  # shuffled
    mask = rule.patch != 1                                          # some patches, not all
    points = BoundaryPoints.of(space, rule, mask)
    n = int(mask.sum())
    assert points.patch.shape == points.piece.shape == (n,) and points.uv.shape == (n, 2)
    assert not np.any(points.patch == 1)
    assert not np.array_equal(points.points.x, rule.x[mask])          # the grouping permutes
    rebuilt = _on_triangles(emb.facets, points) if surface == "facets" else _on_patches(solid, points)
    assert np.abs(rebuilt - points.points.x).max() < 1e-14 * SCALE
    centre = space.centres()[points.slots]
    assert np.abs(centre + 0.5 * space.h * points.points.xi - points.points.x).max() < 1e-15


def test_definition_name_reaches_the_embedding_and_the_model(solid):
    grid = grid_for(solid, 0.01, 0, (0.37, 0.11, 0.64))
    assert embed(solid, grid, "nurbs", definition="nurbs_fit").definition == "nurbs_fit"
    with pytest.raises(ValueError, match="nurbs_fit"):
        embed(solid, grid, "facets", definition="nurbs_fit")
    body = Body("link", SPEC, Material("linear_elastic", 1e9, 0.3), GridSpec(0.01, (0.37, 0.11, 0.64)))
    for name in ("nurbs_fe", "nurbs_fit", "facets"):
        emb = embed_body(solid, body, 0, name)
        assert emb.definition == name and (emb.facets is None) == (name != "facets")
