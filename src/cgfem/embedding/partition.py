"""Exact partition of a solid's NURBS boundary by the planes of a Cartesian grid.

:func:`partition_surface` returns the surface quadrature of every grid element the boundary
passes through (NURBS-enhanced: points on the exact surface, with their ``(xi, eta)``) and
the quadrature of the trimming curves on the grid planes (used for the exact
volume rules of cut elements, :mod:`cgfem.embedding.moments`). The pieces of surface of
neighbouring elements meet exactly along the true intersection curves; the algorithm is in
:mod:`cgfem.embedding._partition_kernels`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Collection

import numpy as np

from cgfem.embedding import _partition_kernels as _k
from cgfem.embedding.grid import CartesianGrid
from cgfem.geometry.refine import bezier_patches
from cgfem.geometry.solid import Solid

#: Target relative accuracy of every Gauss interval of the partition (error model in
#: :func:`cgfem.embedding._partition_kernels.gauss_order`), and the fewest and most points
#: per direction and interval. Two points integrate the bilinear products of H8 shape
#: functions exactly on flat faces.
DEFAULT_TOL = 1e-9
MIN_POINTS = 2
MAX_POINTS = 12
#: Subdivision depth at which a cell is integrated without exact splitting (tangencies only).
MAX_DEPTH = 40


def partition_min_points(degree: int) -> int:
    """Fewest Gauss points per direction and interval for volume rules exact for polynomials
    of degree ``degree`` per variable (:func:`cgfem.embedding.quadrature.embed`).

    The error model of :func:`cgfem.embedding._partition_kernels.gauss_order` follows the
    Bezier piece, not the element: on a cell a fraction of the piece wide it may pick 2 to 4
    points, while the column integrands are polynomials of degree ``3 degree + 1`` in the
    element's local coordinates. Above degree 2 the minimum is ``(3 degree + 1) // 2 + 2``:
    one point beyond exactness for that degree on a flat piece, for the rational map and its
    area element (8 for degree 4). Degree 2 keeps :data:`MIN_POINTS`."""
    return MIN_POINTS if degree <= 2 else (3 * degree + 1) // 2 + 2


_SURFACE_FIELDS = ("patch", "uv", "x", "w", "normal", "element", "piece")


@dataclass(frozen=True)
class SurfaceQuadrature:
    """Quadrature of (a part of) the boundary, one row per point.

    patch : (n,) index of the patch in ``solid.patches``
    uv : (n, 2) NURBS parameters ``(xi, eta)``
    x : (n, 3) points on the exact surface
    w : (n,) area weights
    normal : (n, 3) outward unit normals
    element : (n,) linear id of the grid element holding the point
    piece : (n,) int, the piece of surface the point lies on: for the NURBS boundary the
        Bezier piece of its patch (in the order of
        :func:`cgfem.geometry.refine.bezier_patches`, numbered from 0 in every patch); for
        facets the triangle (row of ``Embedding.facets.triangles``), and then ``uv`` holds
        the barycentric coordinates ``(l1, l2)`` of the point in that triangle
        (``x = (1 - l1 - l2) v0 + l1 v1 + l2 v2``)
    """

    patch: np.ndarray
    uv: np.ndarray
    x: np.ndarray
    w: np.ndarray
    normal: np.ndarray
    element: np.ndarray
    piece: np.ndarray

    def select(self, mask: np.ndarray) -> "SurfaceQuadrature":
        """The rows where ``mask`` holds (a boolean mask or row indices)."""
        return SurfaceQuadrature(*(getattr(self, f)[mask] for f in _SURFACE_FIELDS))


@dataclass(frozen=True)
class TrimQuadrature:
    """Quadrature of the curves where the boundary crosses the grid planes.

    x : (m, 3) points; w : (m,) length weights; normal : (m, 3) unit normal to the curve, in
    its plane, pointing out of the solid's section (zero along ``axis``); axis : (m,) the
    axis normal to the point's plane; element : (m,) the element whose ``+axis`` face holds
    the point (-1 if that face is not in the grid).
    """

    x: np.ndarray
    w: np.ndarray
    normal: np.ndarray
    axis: np.ndarray
    element: np.ndarray

    def select(self, mask: np.ndarray) -> "TrimQuadrature":
        """The rows where ``mask`` holds."""
        return TrimQuadrature(*(getattr(self, f)[mask] for f in ("x", "w", "normal", "axis", "element")))


@dataclass(frozen=True)
class SurfacePartition:
    surface: SurfaceQuadrature
    trims: TrimQuadrature
    approximate_cells: int


def gauss_tables(n_max: int) -> tuple[np.ndarray, np.ndarray]:
    """``GX[n, :n], GW[n, :n]``: the n-point Gauss-Legendre rules on [0, 1], n <= n_max."""
    GX = np.zeros((n_max + 1, n_max))
    GW = np.zeros((n_max + 1, n_max))
    for n in range(1, n_max + 1):
        g, w = np.polynomial.legendre.leggauss(n)
        GX[n, :n] = 0.5 * (g + 1.0)
        GW[n, :n] = 0.5 * w
    return GX, GW


def _run_piece(net, grid: CartesianGrid, GX, GW, rule, capacity: int, cut_by: CartesianGrid | None = None):
    while True:
        out_st = np.empty((capacity, 2))
        out_x = np.empty((capacity, 3))
        out_w = np.empty(capacity)
        out_n = np.empty((capacity, 3))
        out_e = np.empty((capacity, 3), np.int64)
        trim_x = np.empty((capacity, 3))
        trim_w = np.empty(capacity)
        trim_m = np.empty((capacity, 3))
        trim_axis = np.empty(capacity, np.int64)
        trim_plane = np.empty(capacity, np.int64)
        trim_st = np.empty((capacity, 2))
        counts = np.zeros(4, np.int64)
        _k.partition_piece(net, np.asarray(grid.origin, float), float(grid.h),
                           np.asarray(grid.shape, np.int64),
                           np.asarray(grid.origin if cut_by is None else cut_by.origin, float),
                           0.0 if cut_by is None else float(cut_by.h), GX, GW, rule, MAX_DEPTH,
                           out_st, out_x, out_w, out_n, out_e,
                           trim_x, trim_w, trim_m, trim_axis, trim_plane, trim_st, counts)
        if counts[3] == 0:
            ns, nt = int(counts[0]), int(counts[1])
            return (out_st[:ns], out_x[:ns], out_w[:ns], out_n[:ns], out_e[:ns],
                    trim_x[:nt], trim_w[:nt], trim_m[:nt], trim_axis[:nt], trim_plane[:nt], int(counts[2]))
        capacity *= 4


def partition_surface(solid: Solid, grid: CartesianGrid, tol: float = DEFAULT_TOL,
                      min_points: int = MIN_POINTS, max_points: int = MAX_POINTS,
                      cut_by: CartesianGrid | None = None,
                      patches: Collection[int] | None = None) -> SurfacePartition:
    """Surface and grid-plane trimming quadratures of ``solid`` cut by ``grid``; ``tol`` is
    the target relative accuracy of each Gauss interval. ``cut_by``: a second grid whose
    planes also split the surface (its elements are not reported and its planes give no
    trimming points); ``patches``: the patch indices to partition (default all)."""
    GX, GW = gauss_tables(max_points)
    rule = np.array([np.log(tol), min_points, max_points], float)
    rows = {k: [] for k in _SURFACE_FIELDS}
    trims = {k: [] for k in ("x", "w", "normal", "axis", "element")}
    approx = 0
    for ip, patch in enumerate(solid.patches):
        if patches is not None and ip not in patches:
            continue
        for leaf, (piece, (u0, u1), (v0, v1)) in enumerate(bezier_patches(patch.surface)):
            net = np.ascontiguousarray(piece.control)
            capacity = 4096
            (st, x, w, n, e, tx, tw, tm, taxis, tplane, n_approx) = _run_piece(net, grid, GX, GW, rule, capacity,
                                                                               cut_by)
            approx += n_approx
            uv = np.column_stack([u0 + st[:, 0] * (u1 - u0), v0 + st[:, 1] * (v1 - v0)])
            rows["patch"].append(np.full(w.shape, ip, np.int64))
            rows["uv"].append(uv)
            rows["x"].append(x)
            rows["w"].append(w)  # |S_s x S_t| ds dt is already dA
            rows["normal"].append(n)
            rows["element"].append(grid.element_id(e))
            rows["piece"].append(np.full(w.shape, leaf, np.int64))
            ijk = np.floor((tx - np.asarray(grid.origin)) / grid.h).astype(np.int64)
            ijk = np.clip(ijk, 0, np.asarray(grid.shape) - 1)
            rows_ = np.arange(tx.shape[0])
            ijk[rows_, taxis] = tplane - 1  # the element below the plane
            inside = np.all((ijk >= 0) & (ijk < np.asarray(grid.shape)), axis=1)
            trims["x"].append(tx)
            trims["w"].append(tw)
            trims["normal"].append(tm)
            trims["axis"].append(taxis)
            trims["element"].append(np.where(inside, grid.element_id(np.where(inside[:, None], ijk, 0)), -1))
    surface = SurfaceQuadrature(*(np.concatenate(rows[k]) for k in _SURFACE_FIELDS))
    trim = TrimQuadrature(*(np.concatenate(trims[k]) for k in ("x", "w", "normal", "axis", "element")))
    return SurfacePartition(surface, trim, approx)
