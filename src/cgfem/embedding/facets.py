"""The ``facets`` surface definition: the marching-cubes polyhedron of a solid in its grid.

The body is replaced by the polyhedron whose vertices are the *exact* crossings of the
boundary with the grid edges (paper, "Surface topology with the Marching cubes algorithm" and
"Surface definition using linear facets"):

1. Every grid line along x, y and z is cast through the exact NURBS boundary
   (:func:`cgfem.embedding.lines.cast_lines`). The inside status of a node is the parity of
   the hits before it on its z line (as in :func:`cgfem.embedding.quadrature.embed`); where
   that is unreliable (a line through the node has an odd number of hits, i.e. a grazing ray,
   or the parities along x, y and z disagree) it is decided by
   :func:`cgfem.geometry.inside.points_inside`, and nodes on the boundary of the grid (which
   covers the body, so they can at most touch it) are outside, so the surface is closed. An
   edge whose end nodes differ holds one facet vertex: the middle hit of the odd number of
   hits inside it (with its patch, ``(xi, eta)`` and normal), placed exactly on the edge.
   Edges whose nodes agree hold none, whatever passes between them (thin features are
   invisible to facets). If the hits inside a changing edge are even in number (a tangency,
   a node on the surface), the vertex is the nearest hit of the line clamped to the edge (the
   edge midpoint if the line has none) with the patch, parameters and normal of its closest
   surface point; ``FacetBoundary.fallback_edges`` counts them.
2. In an element with mixed node signs, each face gets segments joining its crossings: one
   for two crossings; for four (diagonal signs, an ambiguous face) the inside status of the
   face centre (:func:`cgfem.geometry.inside.points_inside`, once per face, so both elements
   sharing the face agree) decides whether the two inside corners are joined (centre inside)
   or separated. A face segment is directed so that the material part of the face is on its
   left seen from outside the element; the surface traverses it backwards, which chains the
   segments of the element into closed loops oriented with the outward normal of the body
   (every crossing is the end of one segment and the start of another). Each loop is
   triangulated as a fan around the centroid of its vertices (a triangle of three vertices is
   kept whole): robust for the non-planar loops of 4 to 12 vertices, every triangle lies in
   the (convex) element, and neighbours share the segments of their common face, so the
   surface is closed. ``FacetBoundary.misoriented`` counts triangles whose normal opposes
   the mean exact normal of their crossings (a diagnostic; the orientation is topological).
3. A triangle's patch (:func:`_triangle_patch`): that of a crossing of its loop in whose
   face's plane it lies, else the majority patch of its own crossings (ties: the first).
   A facet point has no exact parameters: its quadrature points carry the triangle
   (``piece``) and their barycentric coordinates ``(l1, l2)`` in it as ``uv``.

Element status for facets: OUTSIDE (all nodes outside), INSIDE (all inside), CUT (mixed).
The material part of a cut element is bounded by its triangles and by the polygonal material
parts of its faces, so :func:`cgfem.embedding.moments.fitted_volume_rule` gives the exact
volume rule of the polyhedron from: the triangles (Gauss rule exact for degree ``2n + 1``),
the face segments on the element's ``+x`` face (``n``-point Gauss on each, ``m`` the in-plane
normal out of the material section) and the material interval of the element's z edge
``(x_{i+1}, y_{j+1})`` from its node signs and its single crossing
(:meth:`FacetBoundary.fitted_volume_args`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.lines import cast_lines, line_axes
from cgfem.embedding.moments import DEFAULT_POINTS, VolumeRule, fitted_volume_rule
from cgfem.embedding.partition import SurfaceQuadrature, TrimQuadrature
from cgfem.geometry.bvh import SurfaceIndex
from cgfem.geometry.inside import points_inside
from cgfem.geometry.query import closest_points
from cgfem.geometry.solid import Solid
from cgfem.quadrature_rules import triangle_rule

#: Element status, the values of :mod:`cgfem.embedding.quadrature` (duplicated here because
#: that module imports this one).
OUTSIDE, INSIDE, CUT = 0, 1, 2
#: Default polynomial degree of the triangle rule of :attr:`FacetBoundary.surface`.
DEFAULT_DEGREE = 4


def facet_surface_degree(degree: int) -> int:
    """Total degree of the triangle rule kept as the facets' boundary rule when the volume
    and reduced boundary rules are exact for ``degree`` per variable: ``3 degree``, the
    total degree of the products of shape functions on a tilted triangle (12 for
    triquadratic elements); degree 2 keeps :data:`DEFAULT_DEGREE` (exact for the products of
    trilinear shape functions on triangles in a coordinate plane, total degree 4)."""
    return DEFAULT_DEGREE if degree <= 2 else 3 * degree


def volume_surface_degree(degree: int) -> int:
    """Total degree of the triangle rule the volume rules of degree ``degree`` per variable
    need: the column (and moment-fitting) integrand, an antiderivative of degree
    ``degree + 1`` along one axis times degree ``degree`` along the other two."""
    return 3 * degree + 1


# ------------------------------------------------------------------------------------------
# cube topology (H8 corner order of CartesianGrid.element_nodes)
# ------------------------------------------------------------------------------------------
_CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                     [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], np.int64)
#: edges as (lower corner, upper corner); edge e runs along axis e // 4
_EDGES = np.array([[0, 1], [3, 2], [4, 5], [7, 6], [0, 3], [1, 2], [4, 7], [5, 6],
                   [0, 4], [1, 5], [2, 6], [3, 7]], np.int64)
#: faces -x +x -y +y -z +z, corners counterclockwise seen from outside the element
_FACES = np.array([[0, 4, 7, 3], [1, 2, 6, 5], [0, 1, 5, 4], [3, 7, 6, 2],
                   [0, 3, 2, 1], [4, 5, 6, 7]], np.int64)
#: the corner of each face with the lowest node indices
_FACE_LOWER = np.array([f[np.argmin(_CORNERS[f].sum(axis=1))] for f in _FACES], np.int64)
_EDGE_OF = {frozenset(map(int, pair)): e for e, pair in enumerate(_EDGES)}
#: _FACE_EDGES[f, k]: the edge from corner _FACES[f, k] to _FACES[f, k + 1]
_FACE_EDGES = np.array([[_EDGE_OF[frozenset((int(f[k]), int(f[(k + 1) % 4])))] for k in range(4)]
                        for f in _FACES], np.int64)
#: A triangle (not a sliver) is counted as misoriented when its normal makes more than 120
#: degrees with the mean exact normal of its crossings (facets of a surface through grid
#: nodes may be perpendicular to it, which is not an orientation error).
MISORIENTED_COS = -0.5


#: ``1 - cos`` below which a triangle lies in a crossing's face (flat: ~1e-16; chamfer: ~0.1)
IN_PLANE = 1e-10


@njit(cache=True)
def _triangle_patch(corners, loop, n_loop, vid, vpatch, vnormal, vote):
    """Patch of the triangle ``corners`` (3, 3) cut from the loop ``vid[loop[:n_loop]]``:
    that of a crossing of the loop in whose face's plane it lies (its unit normal within
    ``IN_PLANE`` of the crossing's exact normal), else ``vote`` (the majority patch of its
    own crossings). Outside a box's side just beyond a grid plane, fan triangles with two
    crossings on the top lie in the side; chamfers and curved pieces keep the vote."""
    mixed = False
    for r in range(1, n_loop):
        mixed = mixed or vpatch[vid[loop[r]]] != vpatch[vid[loop[0]]]
    if not mixed:
        return vote
    a = corners[1] - corners[0]
    b = corners[2] - corners[0]
    n = np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])
    size = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    if size == 0.0:
        return vote
    best = 1.0 - IN_PLANE
    patch = vote
    for r in range(n_loop):
        v = vid[loop[r]]
        score = (n[0] * vnormal[v, 0] + n[1] * vnormal[v, 1] + n[2] * vnormal[v, 2]) / size
        if score > best:
            best = score
            patch = vpatch[v]
    return patch


@njit(cache=True)
def _facet_kernel(cut, shape, node_inside, vkeys, vpos, vpatch, vnormal, fkeys, finside,
                  corners, edges, faces, face_lower, face_edges,
                  tri, tri_vid, tri_elem, tri_patch, seg, seg_elem, seg_face, seg_fkey, counts):
    """Marching-cubes loops and fan triangles of the ``cut`` elements (see module docstring).

    cut (n,) element ids; shape (3,) elements per axis; node_inside (n_nodes,);
    vkeys (nv,) sorted edge keys ``axis * n_nodes + lower node id`` of the crossings at
    vpos (nv, 3) with vpatch (nv,) and exact vnormal (nv, 3); fkeys (nf,) sorted face keys
    ``axis * n_nodes + lowest node id`` of the ambiguous faces with the centre status finside
    (nf,). Outputs (capacity 12 n): tri (., 3, 3), tri_vid (., 3) crossing ids (-1: a
    centroid), tri_elem, tri_patch (:func:`_triangle_patch`); seg (., 2) crossing ids of the
    face segments (material on the left seen from outside the element), seg_elem, seg_face
    (0..5), seg_fkey; counts = [n_tri, n_seg, n_errors].
    """
    ny1 = shape[1] + 1
    nz1 = shape[2] + 1
    n_nodes = (shape[0] + 1) * ny1 * nz1
    nid = np.empty(8, np.int64)
    sgn = np.empty(8, np.bool_)
    vid = np.empty(12, np.int64)
    nxt = np.empty(12, np.int64)
    seen = np.empty(12, np.bool_)
    loop = np.empty(12, np.int64)
    nt = 0
    ns = 0
    for e in range(cut.size):
        el = cut[e]
        i = el // (shape[1] * shape[2])
        j = (el // shape[2]) % shape[1]
        k = el % shape[2]
        for c in range(8):
            nid[c] = ((i + corners[c, 0]) * ny1 + j + corners[c, 1]) * nz1 + k + corners[c, 2]
            sgn[c] = node_inside[nid[c]]
        for g in range(12):
            vid[g] = -1
            nxt[g] = -1
            seen[g] = False
            if sgn[edges[g, 0]] != sgn[edges[g, 1]]:
                key = (g // 4) * n_nodes + nid[edges[g, 0]]
                p = np.searchsorted(vkeys, key)
                if p < vkeys.size and vkeys[p] == key:
                    vid[g] = p
                else:
                    counts[2] += 1
        for f in range(6):
            fkey = (f // 2) * n_nodes + nid[face_lower[f]]
            n_cross = 0
            for q in range(4):
                if sgn[faces[f, q]] != sgn[faces[f, (q + 1) % 4]]:
                    n_cross += 1
            if n_cross == 0:
                continue
            centre_in = False
            if n_cross == 4:
                p = np.searchsorted(fkeys, fkey)
                if p < fkeys.size and fkeys[p] == fkey:
                    centre_in = finside[p]
                else:
                    counts[2] += 1
            for q in range(4):
                a = sgn[faces[f, q]]
                b = sgn[faces[f, (q + 1) % 4]]
                ex = -1
                en = -1
                if n_cross == 2:
                    if a and not b:  # material ends on edge q: exit; the entry is the other
                        ex = face_edges[f, q]
                        for r in range(4):
                            if (not sgn[faces[f, r]]) and sgn[faces[f, (r + 1) % 4]]:
                                en = face_edges[f, r]
                elif centre_in:
                    if not a:  # cut off the outside corner q
                        ex = face_edges[f, (q + 3) % 4]
                        en = face_edges[f, q]
                elif a:  # centre outside: cut off the inside corner q
                    ex = face_edges[f, q]
                    en = face_edges[f, (q + 3) % 4]
                if ex < 0:
                    continue
                nxt[en] = ex  # the surface runs against the face segment
                seg[ns, 0] = vid[ex]
                seg[ns, 1] = vid[en]
                seg_elem[ns] = el
                seg_face[ns] = f
                seg_fkey[ns] = fkey
                ns += 1
        for g0 in range(12):
            if vid[g0] < 0 or seen[g0]:
                continue
            n_loop = 0
            g = g0
            while g >= 0 and not seen[g]:
                seen[g] = True
                loop[n_loop] = g
                n_loop += 1
                g = nxt[g]
            if g != g0 or n_loop < 3:
                counts[2] += 1
                continue
            if n_loop == 3:
                for r in range(3):
                    v = vid[loop[r]]
                    tri_vid[nt, r] = v
                    for d in range(3):
                        tri[nt, r, d] = vpos[v, d]
                pa, pb, pc = vpatch[tri_vid[nt, 0]], vpatch[tri_vid[nt, 1]], vpatch[tri_vid[nt, 2]]
                vote = pb if (pb == pc and pa != pb) else pa
                tri_patch[nt] = _triangle_patch(tri[nt], loop, n_loop, vid, vpatch, vnormal, vote)
                tri_elem[nt] = el
                nt += 1
                continue
            centre = np.zeros(3)
            for r in range(n_loop):
                for d in range(3):
                    centre[d] += vpos[vid[loop[r]], d] / n_loop
            for r in range(n_loop):
                va = vid[loop[r]]
                vb = vid[loop[(r + 1) % n_loop]]
                tri_vid[nt, 0] = -1
                tri_vid[nt, 1] = va
                tri_vid[nt, 2] = vb
                for d in range(3):
                    tri[nt, 0, d] = centre[d]
                    tri[nt, 1, d] = vpos[va, d]
                    tri[nt, 2, d] = vpos[vb, d]
                # two crossings: a tie unless equal, the first
                tri_patch[nt] = _triangle_patch(tri[nt], loop, n_loop, vid, vpatch, vnormal, vpatch[va])
                tri_elem[nt] = el
                nt += 1
    counts[0] = nt
    counts[1] = ns


# ------------------------------------------------------------------------------------------
# the polyhedron and its quadrature
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FacetSurface:
    """The triangles of the ``facets`` surface definition, kept on the embedding.

    triangles : (m, 3, 3) vertex positions (reference configuration), counterclockwise
        about the outward normal
    element : (m,) id of the grid element owning each triangle
    patch : (m,) patch of each triangle (index in ``Embedding.patch_names``)

    Row ``k`` is the triangle of the surface-rule points with ``piece == k``.
    """

    triangles: np.ndarray
    element: np.ndarray
    patch: np.ndarray


@dataclass(frozen=True)
class FacetBoundary:
    """The marching-cubes polyhedron of a body in its grid, and its boundary quadrature.

    status : (n_elements,) int8, OUTSIDE / INSIDE / CUT by node signs
    node_inside : (n_nodes,) bool, parity of the z grid-line hits
    vertex_key : (nv,) sorted ``axis * n_nodes + node id`` of the lower node of each
        crossing's grid edge; vertex_x (nv, 3) the crossing (on the edge and on the exact
        surface), vertex_patch (nv,), vertex_uv (nv, 2), vertex_normal (nv, 3) exact data
    triangles : (m, 3, 3) vertices, counterclockwise about the outward normal
    triangle_vertex : (m, 3) crossing ids of the triangle's vertices, -1 for a loop centroid
    triangle_element : (m,) owning (cut) element id; triangle_patch : (m,)
    segments : (s, 2) crossing ids of the face segments, directed with the face's material
        part on the left seen from outside the element; segment_element (s,),
        segment_face (s,) local face 0..5 (-x +x -y +y -z +z), segment_face_key (s,)
        ``axis * n_nodes + lowest node id`` of the face (shared by both of its elements)
    edge_intervals : per cut element (ascending ids), (k, 2) material intervals ``[z0, z1]``
        of its z edge ``(x_{i+1}, y_{j+1})`` on the polyhedron (k = 0 or 1)
    surface : Gauss rule of total ``degree`` on the triangles (flat normals; ``piece`` the
        triangle, ``uv`` the barycentrics ``(l1, l2)`` of the point in it)
    trims : ``points``-point Gauss rules on the segments of the cut elements' + faces
    ambiguous_face_key : (f,) sorted keys of the faces with four crossings;
        ambiguous_face_inside (f,) the inside status of their centres (the decision)
    fallback_edges : changing edges whose exact hits were even in number (see module doc)
    misoriented : triangles whose normal opposes (``MISORIENTED_COS``) the mean exact normal
        at their crossings; 0 unless the orientation logic is broken
    """

    grid: CartesianGrid
    status: np.ndarray
    node_inside: np.ndarray
    vertex_key: np.ndarray
    vertex_x: np.ndarray
    vertex_patch: np.ndarray
    vertex_uv: np.ndarray
    vertex_normal: np.ndarray
    triangles: np.ndarray
    triangle_vertex: np.ndarray
    triangle_element: np.ndarray
    triangle_patch: np.ndarray
    segments: np.ndarray
    segment_element: np.ndarray
    segment_face: np.ndarray
    segment_face_key: np.ndarray
    edge_intervals: tuple[np.ndarray, ...]
    ambiguous_face_key: np.ndarray
    ambiguous_face_inside: np.ndarray
    surface: SurfaceQuadrature
    trims: TrimQuadrature
    degree: int
    points: int
    fallback_edges: int
    misoriented: int

    @property
    def cut(self) -> np.ndarray:
        """Ids of the cut elements, ascending."""
        return np.flatnonzero(self.status == CUT)

    def surface_rule(self, degree: int) -> SurfaceQuadrature:
        """Gauss rule exact for polynomials of total ``degree`` on every triangle of positive
        area: (m * q,) rows with the triangle's unit normal, patch and id (``piece``, a row of
        :attr:`triangles`), and ``uv`` the barycentric coordinates ``(l1, l2)`` of the point
        in its triangle (``x = (1 - l1 - l2) v0 + l1 v1 + l2 v2``)."""
        bary, wq = triangle_rule(degree)
        t = self.triangles
        cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        twice_area = np.linalg.norm(cross, axis=1)
        keep = np.flatnonzero(twice_area > 0.0)
        t, cross, twice_area = t[keep], cross[keep], twice_area[keep]
        q = wq.size
        x = np.einsum("qa,tad->tqd", bary, t).reshape(-1, 3)
        w = (0.5 * twice_area[:, None] * wq[None, :]).reshape(-1)
        normal = np.repeat(cross / twice_area[:, None], q, axis=0)
        patch = np.repeat(self.triangle_patch[keep], q)
        element = np.repeat(self.triangle_element[keep], q)
        uv = np.tile(bary[:, 1:], (keep.size, 1))
        return SurfaceQuadrature(patch, uv, x, w, normal, element, np.repeat(keep, q))

    def facet_surface(self) -> "FacetSurface":
        """The triangles with their owning elements and patches (what the embedding keeps)."""
        return FacetSurface(self.triangles, self.triangle_element, self.triangle_patch)

    def trim_rule(self, points: int) -> TrimQuadrature:
        """``points``-point Gauss rules on the segments of the cut elements' +x, +y and +z
        faces (exact for degree ``2 points - 1``; every face between two cut elements is the
        + face of one of them): (s * points,) rows with the in-plane normal out of the
        face's material part."""
        plus = self.segment_face % 2 == 1
        a = self.vertex_x[self.segments[plus, 0]]
        d = self.vertex_x[self.segments[plus, 1]] - a
        axis = self.segment_face[plus] // 2
        length = np.linalg.norm(d, axis=1)
        keep = length > 0.0
        a, d, length, axis = a[keep], d[keep], length[keep], axis[keep]
        g, gw = np.polynomial.legendre.leggauss(points)
        g, gw = 0.5 * (g + 1.0), 0.5 * gw
        x = (a[:, None, :] + g[None, :, None] * d[:, None, :]).reshape(-1, 3)
        w = (length[:, None] * gw[None, :]).reshape(-1)
        # material on the left of d seen from outside the face (along -e_axis): m = d x e_axis
        m = np.cross(d, np.eye(3)[axis]) / length[:, None]
        element = np.repeat(self.segment_element[plus][keep], points)
        return TrimQuadrature(x, w, np.repeat(m, points, axis=0), np.repeat(axis, points), element)

    def line_hits(self) -> "LineHits":
        """The polyhedron's crossings of the grid lines (one per changing edge, at the facet
        vertex), for the column rules of :mod:`cgfem.embedding.columns`."""
        from cgfem.embedding.columns import LineHits
        n = self.grid.n_nodes
        return LineHits.from_crossings(self.grid, self.vertex_key // n, self.vertex_key % n,
                                       self.vertex_x[np.arange(self.vertex_key.size), self.vertex_key // n])

    def fitted_volume_args(self, points: int = DEFAULT_POINTS) -> dict:
        """Keyword arguments of :func:`cgfem.embedding.moments.fitted_volume_rule` (with the
        grid) for the exact ``points^3`` rules of the polyhedron's cut elements: the triangle
        rule is exact for total degree ``3 points - 2`` and the segment rule for
        ``2 points - 1``, the degrees of the moment integrands (an antiderivative of degree
        ``points`` times ``points - 1`` per other variable)."""
        need = volume_surface_degree(points - 1)
        s = self.surface if self.degree >= need else self.surface_rule(need)
        t = self.trims if self.points >= points else self.trim_rule(points)
        t = t.select(t.axis == 0)
        return dict(elements=self.cut, surf_x=s.x, surf_w=s.w, surf_nx=s.normal[:, 0],
                    surf_element=s.element, trim_x=t.x, trim_w=t.w, trim_my=t.normal[:, 1],
                    trim_element=t.element, edge_intervals=list(self.edge_intervals), n=points)

    def cut_volume_rule(self, points: int = DEFAULT_POINTS) -> VolumeRule:
        """Moment-fitted ``points^3`` rules of the cut elements, exact on the polyhedron for
        polynomials of degree < ``points`` in each variable."""
        return fitted_volume_rule(self.grid, **self.fitted_volume_args(points))


def _node_status(index: SurfaceIndex, grid: CartesianGrid, lines) -> np.ndarray:
    """Inside status (n_nodes,) of the grid nodes from the hits of the lines along x, y, z
    (all hits, unpaired): z-line parity, checked against the other two (see module doc)."""
    parity, unsure = [], np.zeros(grid.n_nodes, bool)
    for axis_lines in lines:
        n = grid.node_shape[axis_lines.axis]
        odd = np.diff(axis_lines.offsets) % 2 == 1
        unsure |= axis_lines.to_node_order(np.repeat(odd[:, None], n, axis=1))
        parity.append(axis_lines.nodes_inside())
    unsure |= (parity[0] != parity[2]) | (parity[1] != parity[2])
    inside = parity[2].copy()
    if np.any(unsure):
        ijk = np.column_stack(np.unravel_index(np.flatnonzero(unsure), grid.node_shape))
        inside[unsure] = points_inside(index, grid.node_coordinates(ijk))
    border = np.ones(grid.node_shape, bool)
    border[1:-1, 1:-1, 1:-1] = False
    inside[border.ravel()] = False
    return inside


def _edge_crossings(index: SurfaceIndex, grid: CartesianGrid, lines, inside3: np.ndarray):
    """The facet vertex of every grid edge along ``lines.axis`` whose end nodes differ:
    keys (v,), x (v, 3), patch (v,), uv (v, 2), normal (v, 3), number of fallbacks."""
    axis = lines.axis
    b, c = line_axes(axis)
    n = grid.node_shape[axis]
    signs = np.moveaxis(inside3, axis, 2).reshape(-1, n)  # (n_lines, n), line order (b, c)
    line, m = np.nonzero(signs[:, :-1] != signs[:, 1:])
    counts = lines.bucket_counts()
    before = np.cumsum(counts, axis=1)
    count = counts[line, m + 1]
    hit = lines.offsets[line] + before[line, m] + count // 2
    lo, hi = grid.plane(axis, m), grid.plane(axis, m + 1)
    if lines.coord.size:
        safe = np.minimum(hit, lines.coord.size - 1)
        coord, patch, uv, normal = lines.coord[safe], lines.patch[safe], lines.uv[safe], lines.normal[safe]
    else:
        coord, patch, uv, normal = np.zeros(line.size), np.zeros(line.size, np.int64), \
            np.zeros((line.size, 2)), np.zeros((line.size, 3))
    p, q = line // grid.node_shape[c], line % grid.node_shape[c]
    x = np.empty((line.size, 3))
    x[:, b] = grid.plane(b, p)
    x[:, c] = grid.plane(c, q)
    bad = np.flatnonzero(count % 2 == 0)
    for r in bad:  # tangencies, nodes on the surface: the nearest hit of the line, else the midpoint
        hits = slice(lines.offsets[line[r]], lines.offsets[line[r] + 1])
        if hits.stop > hits.start:
            gap = np.maximum(np.maximum(lo[r] - lines.coord[hits], lines.coord[hits] - hi[r]), 0.0)
            coord[r] = lines.coord[hits.start + int(np.argmin(gap))]
        else:
            coord[r] = 0.5 * (lo[r] + hi[r])
    x[:, axis] = np.clip(coord, lo, hi)
    if bad.size:  # surface data of the closest points
        foot = closest_points(index, x[bad])
        patch[bad], uv[bad], normal[bad] = foot.patch, foot.uv, foot.normal
    ijk = np.empty((line.size, 3), np.int64)
    ijk[:, axis], ijk[:, b], ijk[:, c] = m, p, q
    keys = axis * grid.n_nodes + grid.node_id(ijk)
    return keys, x, patch, uv, normal, bad.size


def _ambiguous_faces(index: SurfaceIndex, grid: CartesianGrid, inside3: np.ndarray):
    """Faces with four crossings (diagonal corner signs) and the inside status of their
    centres: sorted keys (f,), bool (f,)."""
    keys, centres = [], []
    for axis in range(3):
        b, c = line_axes(axis)
        t = np.moveaxis(inside3, axis, 0)  # (n_axis, n_b, n_c)
        s00, s10, s01, s11 = t[:, :-1, :-1], t[:, 1:, :-1], t[:, :-1, 1:], t[:, 1:, 1:]
        m, p, q = np.nonzero((s00 == s11) & (s10 == s01) & (s00 != s10))
        ijk = np.empty((m.size, 3), np.int64)
        ijk[:, axis], ijk[:, b], ijk[:, c] = m, p, q
        centre = grid.node_coordinates(ijk)
        centre[:, [b, c]] += 0.5 * grid.h
        keys.append(axis * grid.n_nodes + grid.node_id(ijk))
        centres.append(centre)
    keys, centres = np.concatenate(keys), np.concatenate(centres)
    order = np.argsort(keys)
    inside = points_inside(index, centres[order]) if keys.size else np.zeros(0, bool)
    return keys[order], inside


def facet_embedding_parts(solid: Solid, grid: CartesianGrid, index: SurfaceIndex | None = None,
                          degree: int = DEFAULT_DEGREE, points: int = DEFAULT_POINTS) -> FacetBoundary:
    """The marching-cubes polyhedron of ``solid`` in ``grid`` with its surface rule of total
    ``degree`` and its ``points``-point +x face segment rules (see the module docstring)."""
    index = SurfaceIndex.build(solid) if index is None else index
    lines = [cast_lines(index, grid, axis) for axis in range(3)]
    node_inside = _node_status(index, grid, lines)
    inside3 = node_inside.reshape(grid.node_shape)
    n_in = sum(inside3[i:i + grid.shape[0], j:j + grid.shape[1], k:k + grid.shape[2]].astype(np.int8)
               for i, j, k in _CORNERS)
    status = np.where(n_in == 8, INSIDE, np.where(n_in == 0, OUTSIDE, CUT)).astype(np.int8).ravel()
    parts = [_edge_crossings(index, grid, lines[axis], inside3) for axis in range(3)]
    keys = np.concatenate([p[0] for p in parts])
    order = np.argsort(keys)
    vkey, vx, vpatch, vuv, vnormal = (np.concatenate([p[r] for p in parts])[order] for r in range(5))
    vpatch = vpatch.astype(np.int64)
    fkeys, finside = _ambiguous_faces(index, grid, inside3)

    cut = np.flatnonzero(status == CUT)
    cap = 12 * cut.size
    tri, tri_vid = np.empty((cap, 3, 3)), np.empty((cap, 3), np.int64)
    tri_elem, tri_patch = np.empty(cap, np.int64), np.empty(cap, np.int64)
    seg, seg_elem = np.empty((cap, 2), np.int64), np.empty(cap, np.int64)
    seg_face, seg_fkey = np.empty(cap, np.int64), np.empty(cap, np.int64)
    counts = np.zeros(3, np.int64)
    _facet_kernel(cut, np.asarray(grid.shape, np.int64), node_inside, vkey, vx, vpatch, vnormal, fkeys, finside,
                  _CORNERS, _EDGES, _FACES, _FACE_LOWER, _FACE_EDGES,
                  tri, tri_vid, tri_elem, tri_patch, seg, seg_elem, seg_face, seg_fkey, counts)
    if counts[2]:
        raise RuntimeError(f"marching cubes: {counts[2]} inconsistent edges, faces or loops")
    nt, ns = int(counts[0]), int(counts[1])
    tri, tri_vid, tri_elem, tri_patch = tri[:nt], tri_vid[:nt], tri_elem[:nt], tri_patch[:nt]

    # material interval of each cut element's z edge (x_{i+1}, y_{j+1}) on the polyhedron
    ijk = grid.element_ijk(cut)
    lower = grid.node_id(ijk + [1, 1, 0])
    s0, s1 = node_inside[lower], node_inside[grid.node_id(ijk + [1, 1, 1])]
    z0, z1 = grid.plane(2, ijk[:, 2]), grid.plane(2, ijk[:, 2] + 1)
    at = np.minimum(np.searchsorted(vkey, 2 * grid.n_nodes + lower), max(vkey.size - 1, 0))
    zc = vx[at, 2] if vkey.size else z0
    lo = np.where(s0, z0, zc)
    hi = np.where(s1, z1, zc)
    full = s0 | s1
    edge_intervals = tuple(np.array([[a, b]]) if f else np.zeros((0, 2)) for a, b, f in zip(lo, hi, full))

    mean_normal = np.zeros((nt, 3))
    for r in range(3):
        has = tri_vid[:, r] >= 0
        mean_normal[has] += vnormal[tri_vid[has, r]]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    twice_area = np.linalg.norm(cross, axis=1)
    size = twice_area * np.linalg.norm(mean_normal, axis=1)
    misoriented = int(np.sum((np.einsum("ij,ij->i", cross, mean_normal) < MISORIENTED_COS * size)
                             & (twice_area > 1e-10 * grid.h**2)))  # slivers have no direction

    partial = FacetBoundary(grid, status, node_inside, vkey, vx, vpatch, vuv, vnormal,
                            tri, tri_vid, tri_elem, tri_patch, seg[:ns], seg_elem[:ns], seg_face[:ns],
                            seg_fkey[:ns], edge_intervals, fkeys, finside, None, None, degree, points,
                            int(sum(p[5] for p in parts)), misoriented)
    return replace(partial, surface=partial.surface_rule(degree), trims=partial.trim_rule(points))
