"""The ``facets`` surface definition: the marching-cubes polyhedron with exact crossings.

Checked: the triangle rules are exact to their degree; the facet surface is closed and the
moment-fitted volume rule integrates the same polyhedron as the surface rule (volume and
divergence theorem for fields of degree <= 2 per variable); a box gives the chamfered
polyhedron computed by hand; the volume error on curved bodies is O(h^2); ambiguous faces are
decided once for both of their elements.
"""

from __future__ import annotations

from functools import lru_cache
from math import factorial

import numpy as np
import pytest

from cgfem.embedding.facets import CUT, INSIDE, OUTSIDE, facet_embedding_parts
from cgfem.quadrature_rules import triangle_rule
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.lines import cast_lines, cast_z_lines
from cgfem.embedding.moments import VolumeRule
from cgfem.embedding.quadrature import grid_for
from cgfem.geometry.builders import build_solid
from cgfem.geometry.bvh import SurfaceIndex
from cgfem.geometry.measure import volume
from cgfem.geometry.solid import Solid
from cgfem.geometry.specs import BoxSpec, HalfTorusSpec, SphereSpec, TorusSpec

AXIS = np.array([1.0, 2.0, 3.0]) / np.linalg.norm([1.0, 2.0, 3.0])
KEEP = np.cross(AXIS, [0.0, 0.0, 1.0]) / np.linalg.norm(np.cross(AXIS, [0.0, 0.0, 1.0]))
OFFSET = (0.31, 0.17, 0.59)  # grid offsets in units of h0 (fixed, "random")
H0 = 0.08
SPECS = {
    "sphere": SphereSpec(center=(0.013, -0.021, 0.007), radius=0.1),
    "torus": TorusSpec(center=(0.011, -0.023, 0.005), axis=tuple(AXIS), major_radius=0.3, minor_radius=0.1),
    "half_torus": HalfTorusSpec(center=(0.011, 0.02, -0.004), axis=tuple(AXIS), major_radius=0.3,
                                minor_radius=0.1, keep=tuple(KEEP)),
    "thin_torus": TorusSpec(center=(0.011, -0.023, 0.005), axis=tuple(AXIS), major_radius=0.3,
                            minor_radius=0.03),
    "box": BoxSpec(min=(-0.231, -0.171, 0.052), max=(0.313, 0.263, 0.471)),
    # on a grid of offset 0: faces, the cap plane and tangent planes of the tube on grid planes
    "box_aligned": BoxSpec(min=(0.0, -0.08, 0.16), max=(0.32, 0.24, 0.4)),
    "half_torus_aligned": HalfTorusSpec(center=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), major_radius=0.32,
                                        minor_radius=0.08, keep=(0.0, 1.0, 0.0)),
}


def two_spheres() -> Solid:
    """Two disjoint spheres with a gap across the diagonal of the face ``z = 0.013`` of the
    element at the origin (grid of :func:`two_spheres_grid`): corners (0, 0) and (1, 1) of
    that face are inside, (1, 0), (0, 1) and the face centre outside."""
    a = build_solid(SphereSpec(center=(-0.02, -0.02, 0.013), radius=0.06))
    b = build_solid(SphereSpec(center=(0.12, 0.12, 0.013), radius=0.06))
    return Solid(a.patches + b.patches)


def two_spheres_grid() -> CartesianGrid:
    return CartesianGrid(0.1, (-0.2003, -0.2001, -0.1872), (5, 5, 4))


@lru_cache(maxsize=None)
def body(name: str):
    solid = two_spheres() if name == "two_spheres" else build_solid(SPECS[name])
    return solid, SurfaceIndex.build(solid)


@lru_cache(maxsize=None)
def facets(name: str, level: int):
    solid, index = body(name)
    if name == "two_spheres":
        grid = two_spheres_grid()
    elif name.endswith("aligned"):  # offset 0, one element of padding
        box = grid_for(solid, H0, 0, (0.0, 0.0, 0.0))
        lo, hi = np.array(box.origin), np.array(box.origin) + H0 * np.array(box.shape)
        grid = CartesianGrid.covering(lo - H0, hi + H0, H0, level)
    else:
        grid = grid_for(solid, H0, level, OFFSET)
    return facet_embedding_parts(solid, grid, index)


def interior_rule(grid: CartesianGrid, elements: np.ndarray) -> VolumeRule:
    """2x2x2 Gauss points of whole elements."""
    g = np.array([-1.0, 1.0]) / np.sqrt(3.0)
    local = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    x = grid.element_center(grid.element_ijk(elements))[:, None, :] + 0.5 * grid.h * local[None]
    return VolumeRule(x.reshape(-1, 3), np.full(x.shape[0] * 8, (0.5 * grid.h) ** 3), np.repeat(elements, 8))


def polyhedron_volume(fb) -> tuple[float, float]:
    """(1/3 sum x.n dA on the facets, sum of the volume rule of inside and cut elements)."""
    s = fb.surface
    by_surface = float(np.sum(np.einsum("ij,ij->i", s.x, s.normal) * s.w)) / 3.0
    by_volume = float(fb.cut_volume_rule().w.sum() + np.sum(fb.status == INSIDE) * fb.grid.h ** 3)
    return by_surface, by_volume


@pytest.mark.parametrize("degree", [4, 8, 11, 12, 13])
def test_triangle_rule_is_exact_to_its_degree(degree):
    bary, w = triangle_rule(degree)
    assert np.all(w > 0.0) and np.allclose(bary.sum(axis=1), 1.0, atol=1e-15)
    for p in range(degree + 1):
        for q in range(degree + 1 - p):
            exact = 2.0 * factorial(p) * factorial(q) / factorial(p + q + 2)  # mean of u^p v^q
            assert abs(np.sum(w * bary[:, 1] ** p * bary[:, 2] ** q) - exact) < 2e-15


def test_cast_lines_along_z_agrees_with_cast_z_lines():
    solid, index = body("torus")
    grid = grid_for(solid, H0, 1, OFFSET)
    z = cast_z_lines(index, grid)
    lines = cast_lines(index, grid, 2).paired()
    assert np.array_equal(lines.offsets, z.offsets) and np.array_equal(lines.coord, z.z)
    assert np.array_equal(lines.nodes_inside(), z.nodes_inside())
    for axis in (0, 1):  # parity along x and y lines gives the same nodes (no grazing rays)
        other = cast_lines(index, grid, axis)
        assert other.odd == 0 and np.array_equal(other.nodes_inside(), z.nodes_inside())


@pytest.mark.parametrize("name", ["sphere", "torus", "half_torus", "thin_torus", "box", "two_spheres",
                                  "box_aligned", "half_torus_aligned"])
def test_surface_is_closed_and_volume_rule_matches_it(name):
    fb = facets(name, 1)
    s = fb.surface
    area = s.w.sum()
    assert np.all(np.abs(np.sum(s.normal * s.w[:, None], axis=0)) < 1e-12 * area)
    by_surface, by_volume = polyhedron_volume(fb)
    assert abs(by_surface - by_volume) < 1e-12 * by_surface
    assert fb.misoriented == 0
    if not name.endswith("aligned"):  # nodes on the surface take the fallback
        assert fb.fallback_edges == 0
    # status by node signs; triangles only in cut elements
    assert set(np.unique(fb.status)) <= {OUTSIDE, INSIDE, CUT}
    assert np.all(fb.status[fb.triangle_element] == CUT)
    assert np.array_equal(np.unique(fb.triangle_element), fb.cut)
    # a triangle's patch is that of a crossing in its element (pairs element * n + patch)
    n = len(fb.vertex_patch) + 1
    has = fb.triangle_vertex >= 0
    owner = np.broadcast_to(fb.triangle_element[:, None], has.shape)[has]
    crossing_pairs = owner * n + fb.vertex_patch[fb.triangle_vertex[has]]
    assert np.all(np.isin(fb.triangle_element * n + fb.triangle_patch, crossing_pairs))


def test_triangles_in_a_face_take_its_patch():
    """A box whose side faces lie 1e-9 beyond grid planes (x and y), its top and bottom
    between planes: every node on the sides' planes is inside, so the polyhedron is the box
    but for slivers 1e-9 thick along its edges, and each face's triangles must cover that
    face exactly, with its normal. The loops of the cells outside a side face join the
    side's crossings (on the x or y edges of those cells) to the top's (on the z edges at
    the nodes of the side's plane); the fan triangles whose two crossings lie on the top lie
    in the side's plane. A vote over each triangle's own crossings gives them to the top
    (the x-min face kept 0.0592 of its 0.0672 m^2)."""
    eps = 1e-9
    spec = BoxSpec(min=(-eps, -0.08 - eps, 0.173), max=(0.32 + eps, 0.24 + eps, 0.383))
    solid = build_solid(spec)
    grid = CartesianGrid.covering(np.array(spec.min) - H0, np.array(spec.max) + H0, H0, 1)
    assert np.allclose(np.array(grid.origin) / grid.h, np.round(np.array(grid.origin) / grid.h))
    fb = facet_embedding_parts(solid, grid, SurfaceIndex.build(solid))
    s = fb.surface
    size = np.array(spec.max) - np.array(spec.min)
    names = solid.patch_names
    for axis, letter in enumerate("xyz"):
        face = np.prod(np.delete(size, axis))
        for side, sign in (("min", -1.0), ("max", 1.0)):
            on = s.patch == names.index(f"{letter}{side}")
            assert abs(s.w[on].sum() - face) < 1e-7 * face, (letter, side, s.w[on].sum(), face)
            normal = np.zeros(3)
            normal[axis] = sign
            # the slivers' triangles may face any way, but carry no area
            assert np.sum(s.w[on] * (1.0 - s.normal[on] @ normal)) < 1e-7 * face


def test_box_gives_the_chamfered_box():
    """Marching cubes keeps the flat faces exactly but chamfers every edge and corner of a box
    whose faces lie between grid planes: edge cells lose the triangle with legs (d_b, d_c)
    (the gaps between the faces and the first inside node planes) along the edge, corner
    cells keep only ``u + v + w >= 2`` of their box ``d_x d_y d_z`` (they lose 5/6 of it)."""
    fb = facets("box", 1)
    spec, grid = SPECS["box"], fb.grid
    lo, hi, origin = np.array(spec.min), np.array(spec.max), np.array(grid.origin)
    first = origin + (np.floor((lo - origin) / grid.h) + 1) * grid.h
    last = origin + (np.ceil((hi - origin) / grid.h) - 1) * grid.h
    gaps = np.stack([first - lo, hi - last])  # (side, axis)
    inner = last - first
    vol = np.prod(hi - lo)
    area = 2.0 * (inner[0] * inner[1] + inner[1] * inner[2] + inner[0] * inner[2])
    for a, (b, c) in enumerate([(1, 2), (0, 2), (0, 1)]):
        for db in gaps[:, b]:
            for dc in gaps[:, c]:
                vol -= 0.5 * db * dc * inner[a]
                area += np.hypot(db, dc) * inner[a]
    for dx in gaps[:, 0]:
        for dy in gaps[:, 1]:
            for dz in gaps[:, 2]:
                vol -= 5.0 / 6.0 * dx * dy * dz
                area += 0.5 * np.sqrt((dy * dz) ** 2 + (dx * dz) ** 2 + (dx * dy) ** 2)
    by_surface, by_volume = polyhedron_volume(fb)
    assert abs(by_surface - vol) < 1e-12 * vol and abs(by_volume - vol) < 1e-12 * vol
    assert abs(fb.surface.w.sum() - area) < 1e-12 * area
    assert np.all(gaps > 0.05 * grid.h)  # the case really chamfers (faces off the grid planes)


@pytest.mark.parametrize("name", ["sphere", "torus"])
def test_volume_error_is_second_order(name):
    solid, _ = body(name)
    exact = volume(solid)
    h, err = [], []
    for level in range(4):
        fb = facets(name, level)
        s = fb.surface
        vol = np.sum(np.einsum("ij,ij->i", s.x, s.normal) * s.w) / 3.0
        h.append(fb.grid.h)
        err.append(abs(vol - exact) / exact)
    order = np.polyfit(np.log(h), np.log(err), 1)[0]
    assert 1.8 <= order <= 2.3, (order, err)
    assert err[-1] < 0.01


FIELDS = {  # total degree of f: (f (n, 3), div f (n,)) of x (n, 3); degree <= 2 in each variable
    "linear": (1, lambda x, y, z: np.stack([x, y, z], -1), lambda x, y, z: 3.0 + 0.0 * x),
    "quartic": (4, lambda x, y, z: np.stack([x**2 * y**2, y * z**2, x * z], -1),
                lambda x, y, z: 2 * x * y**2 + z**2 + x),
    "mixed": (5, lambda x, y, z: np.stack([x**2 * y * z**2, x * y**2, y * z], -1),
              lambda x, y, z: 2 * x * y * z**2 + 2 * x * y + y),
    "solenoidal_x": (5, lambda x, y, z: np.stack([y**2 * z**2, x**2 * z**2, x**2 * y**2 * z], -1),
                     lambda x, y, z: x**2 * y**2),
    "full": (6, lambda x, y, z: np.stack([x**2 * y**2 * z**2] * 3, -1),
             lambda x, y, z: 2 * x * y * z * (y * z + x * z + x * y)),
}


@pytest.mark.parametrize("name", ["sphere", "half_torus", "two_spheres"])
def test_divergence_theorem_on_the_polyhedron(name):
    fb = facets(name, 1)
    grid = fb.grid
    centre = grid.element_center(grid.element_ijk(fb.cut)).mean(axis=0)
    cut = fb.cut_volume_rule(3)
    inner = interior_rule(grid, np.flatnonzero(fb.status == INSIDE))
    vx = np.concatenate([cut.x, inner.x]) - centre
    vw = np.concatenate([cut.w, inner.w])
    for degree, surface in ((8, fb.surface_rule(8)), (fb.degree, fb.surface)):
        sx = surface.x - centre
        for key, (total, f, div) in FIELDS.items():
            if total > degree:  # the rule integrates f.n exactly only up to its degree
                continue
            flux = np.einsum("ij,ij->i", f(*sx.T), surface.normal) * surface.w
            source = np.sum(div(*vx.T) * vw)
            assert abs(source - flux.sum()) < 1e-10 * np.sum(np.abs(flux)), key


@pytest.mark.parametrize("name", ["thin_torus", "two_spheres"])
def test_ambiguous_faces_are_decided_once(name):
    fb = facets(name, 1)
    assert fb.ambiguous_face_key.size > 0
    if name == "two_spheres":  # the gap separates the inside corners: centre outside
        assert np.any(~fb.ambiguous_face_inside)
    else:  # the thin tube joins them
        assert np.any(fb.ambiguous_face_inside)
    # every face segment is in exactly two elements, traversed in opposite directions
    key = np.column_stack([fb.segment_face_key, np.sort(fb.segments, axis=1)])
    groups, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    assert np.all(counts == 2)
    order = np.argsort(inverse.ravel(), kind="stable")
    first, second = order[0::2], order[1::2]
    assert np.all(fb.segment_element[first] != fb.segment_element[second])
    assert np.array_equal(fb.segments[first], fb.segments[second][:, ::-1])
    # ambiguous faces hold two segments per element
    on_ambiguous = np.isin(fb.segment_face_key, fb.ambiguous_face_key)
    pairs = np.unique(np.column_stack([fb.segment_face_key, fb.segment_element])[on_ambiguous], axis=0,
                      return_counts=True)[1]
    assert pairs.size == 2 * fb.ambiguous_face_key.size and np.all(pairs == 2)


def test_kernel_matches_its_python_run():
    """The numba kernel and its plain-Python function give the same polyhedron (the kernel's
    lines are exercised without JIT)."""
    from cgfem.embedding import facets as mod

    fb = facets("thin_torus", 1)
    cut = fb.cut
    cap = 12 * cut.size
    out = [np.empty((cap, 3, 3)), np.empty((cap, 3), np.int64)]
    out += [np.empty(cap, np.int64) for _ in range(2)] + [np.empty((cap, 2), np.int64)]
    out += [np.empty(cap, np.int64) for _ in range(3)] + [np.zeros(3, np.int64)]
    mod._facet_kernel.py_func(cut, np.asarray(fb.grid.shape, np.int64), fb.node_inside, fb.vertex_key,
                              fb.vertex_x, fb.vertex_patch, fb.vertex_normal, fb.ambiguous_face_key,
                              fb.ambiguous_face_inside,
                              mod._CORNERS, mod._EDGES, mod._FACES, mod._FACE_LOWER, mod._FACE_EDGES, *out)
    nt, ns, errors = out[-1]
    assert errors == 0 and nt == len(fb.triangles) and ns == len(fb.segments)
    assert np.array_equal(out[0][:nt], fb.triangles) and np.array_equal(out[3][:nt], fb.triangle_patch)
    assert np.array_equal(out[4][:ns], fb.segments) and np.array_equal(out[5][:ns], fb.segment_element)
