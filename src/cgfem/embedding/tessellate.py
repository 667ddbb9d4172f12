"""Triangulated boundaries of embedded bodies, for viewing results on a surface.

The boundary rule's points (``surface_NNN.vtu``) are a cloud: a viewer can only draw them as
dots. :func:`boundary_tessellation` gives the body's boundary as triangles instead:

- NURBS definitions (``nurbs_fe``, ``nurbs_fit``): every patch sampled on a structured grid
  of parameters that holds every knot (a triangle never straddles a knot line) with at most
  ``spacing`` between neighbouring samples along the surface, two triangles per cell,
  ordered so that ``S_u x S_v`` is their normal. Vertices lie on the exact surface.
- ``facets``: the marching-cubes triangles themselves, each with its own three vertices.

Vertices of different patches (and of different facets) are not merged: fields that are
continuous across them take the same values there, so a viewer shows no seam.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cgfem.embedding.quadrature import Embedding
from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.solid import Solid

#: samples per knot span and direction used to measure the span's length
_PROBES = 9


@dataclass(frozen=True)
class Tessellation:
    """Triangles on a body's boundary.

    x : (n, 3) vertices (reference configuration)
    triangles : (m, 3) vertex indices
    patch : (n,) patch of each vertex (index in the embedding's ``patch_names``)
    """

    x: np.ndarray
    triangles: np.ndarray
    patch: np.ndarray


def keep_vertices(triangles: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangles (m', 3) whose three vertices are all kept (``keep`` (n,) bool),
    renumbered onto the vertices they use, and those vertices (n,) bool."""
    inside = keep[triangles].all(axis=1)
    used = np.zeros(keep.size, bool)
    used[triangles[inside]] = True
    return (np.cumsum(used) - 1)[triangles[inside]], used


def span_samples(surface: NurbsSurface, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Parameters in u and in v: every distinct knot, and within each knot span enough
    equally spaced values that neighbouring samples lie at most about ``spacing`` apart along
    the surface (the span's fastest stretch of a few iso-parameter lines through it sets the
    count; at least ``degree`` cells per span, so curved spans are never drawn by one chord)."""
    if not spacing > 0.0:
        raise ValueError(f"spacing must be positive, got {spacing}")
    breaks = surface.breaks()
    out = []
    for axis in (0, 1):
        knots, other = breaks[axis], breaks[1 - axis]
        across = np.linspace(other[0], other[-1], _PROBES)
        t = np.linspace(0.0, 1.0, _PROBES)
        values = [knots[:1]]
        for a, b in zip(knots[:-1], knots[1:]):
            along = a + (b - a) * t
            grid = np.stack(np.meshgrid(along, across, indexing="ij"), axis=-1).reshape(-1, 2)
            uv = grid if axis == 0 else grid[:, ::-1]
            x = surface.evaluate(uv).reshape(_PROBES, _PROBES, 3)
            # the span's length at its fastest speed, so that no cell is longer than spacing
            reach = float(np.linalg.norm(np.diff(x, axis=0), axis=2).max()) * (_PROBES - 1)
            cells = max(surface.degree[axis], int(np.ceil(reach / spacing)))
            values.append(np.linspace(a, b, cells + 1)[1:])
        out.append(np.concatenate(values))
    return out[0], out[1]


def grid_triangles(n_u: int, n_v: int) -> np.ndarray:
    """(2 (n_u - 1)(n_v - 1), 3) triangles of an ``n_u`` x ``n_v`` grid of vertices numbered
    ``i * n_v + j``, counterclockwise in (u, v)."""
    i, j = np.meshgrid(np.arange(n_u - 1), np.arange(n_v - 1), indexing="ij")
    a = (i * n_v + j).ravel()
    b, c, d = a + n_v, a + n_v + 1, a + 1
    return np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])


def tessellate_nurbs(solid: Solid, patch_names: tuple[str, ...], spacing: float) -> Tessellation:
    """Every patch of ``solid`` sampled by :func:`span_samples`; ``patch`` indexes
    ``patch_names``."""
    xs, tris, patches, shift = [], [], [], 0
    for patch in solid.patches:
        u, v = span_samples(patch.surface, spacing)
        uv = np.stack(np.meshgrid(u, v, indexing="ij"), axis=-1).reshape(-1, 2)
        xs.append(patch.surface.evaluate(uv))
        tris.append(grid_triangles(u.size, v.size) + shift)
        patches.append(np.full(uv.shape[0], patch_names.index(patch.name), np.int32))
        shift += uv.shape[0]
    return Tessellation(np.concatenate(xs), np.concatenate(tris), np.concatenate(patches))


def boundary_tessellation(solid: Solid, embedding: Embedding, spacing: float | None = None) -> Tessellation:
    """The boundary of ``solid`` as ``embedding``'s surface definition draws it: the facets
    of ``facets``, else the exact NURBS patches sampled at ``spacing`` (default: half the
    grid's element size)."""
    facets = embedding.facets
    if facets is not None:
        m = facets.triangles.shape[0]
        return Tessellation(facets.triangles.reshape(-1, 3).copy(), np.arange(3 * m).reshape(m, 3),
                            np.repeat(np.asarray(facets.patch, np.int32), 3))
    h = float(embedding.grid.h)
    return tessellate_nurbs(solid, embedding.patch_names, 0.5 * h if spacing is None else spacing)
