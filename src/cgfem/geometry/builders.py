"""Exact NURBS solids: box, sphere, cylinder, half cylinder, torus and half torus.

Curved patches are rational quadratic surfaces of revolution (the 9-point circle with
weights ``1, sqrt(2)/2, ...``), so they represent the analytic surfaces exactly. Every patch
is oriented with ``S_u x S_v`` pointing out of the solid.

Surfaces of revolution are built from a profile in the meridian half-plane ``(rho, z)``
(``rho`` distance from the axis, ``z`` along it); a profile traversed with the material on
its left (counterclockwise around the material, ``rho`` to the right) gives outward normals.
"""

from __future__ import annotations

import math

import numpy as np

from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.solid import Patch, Solid
from cgfem.geometry.specs import (BoxSpec, CylinderSpec, GeometrySpec, HalfCylinderSpec,
                                  HalfTorusSpec, NurbsFileSpec, SphereSpec, TorusSpec)

_S = math.sqrt(0.5)

#: Rational quadratic full circle (unit radius): square corners, weights and knots.
CIRCLE_XY = np.array([(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0)], float)
CIRCLE_W = np.array([1, _S, 1, _S, 1, _S, 1, _S, 1], float)
CIRCLE_KNOTS = np.array([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1], float)

#: Rational quadratic half circle (angles 0 to pi).
HALF_XY = CIRCLE_XY[:5]
HALF_W = CIRCLE_W[:5]
HALF_KNOTS = np.array([0, 0, 0, 0.5, 0.5, 1, 1, 1], float)


def orthonormal_frame(axis, first=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-handed frame ``(e1, e2, a)`` with ``e1 x e2 = a``; ``e1 = first`` if given
    (it must be a unit vector perpendicular to ``axis``)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    if first is None:
        trial = np.eye(3)[int(np.argmin(np.abs(a)))]
        e1 = trial - np.dot(trial, a) * a
        e1 /= np.linalg.norm(e1)
    else:
        e1 = np.asarray(first, float)
    e2 = np.cross(a, e1)
    return e1, e2, a


def revolve(profile_rz, profile_w, profile_knots, profile_degree: int, frame, center,
            half: bool = False) -> NurbsSurface:
    """Surface of revolution of a rational profile about the frame's axis.

    ``profile_rz`` (m, 2) control points ``(rho, z)`` with weights ``profile_w`` (m,);
    u runs around the axis (from ``e1`` toward ``e2``; a half turn if ``half``),
    v along the profile. Exact (NURBS Book A8.1 with the 9-point circle).
    """
    e1, e2, a = frame
    xy, wc, knots_u = (HALF_XY, HALF_W, HALF_KNOTS) if half else (CIRCLE_XY, CIRCLE_W, CIRCLE_KNOTS)
    rz = np.asarray(profile_rz, float)
    rho, z = rz[:, 0], rz[:, 1]
    # P[i, j] = center + rho_j (X_i e1 + Y_i e2) + z_j a ; w[i, j] = wc_i * wp_j
    radial = xy[:, 0, None, None] * e1 + xy[:, 1, None, None] * e2  # (n_u, 1, 3)
    points = np.asarray(center, float) + rho[None, :, None] * radial + z[None, :, None] * a
    weights = wc[:, None] * np.asarray(profile_w, float)[None, :]
    return NurbsSurface.from_points((2, profile_degree), knots_u, profile_knots, points, weights)


def disc(center, e_x, e_y, radius: float, half: bool = False) -> NurbsSurface:
    """Flat disc ``center + rho (cos t e_x + sin t e_y)``, ``rho <= radius``; u around the rim
    (``t`` in ``[0, pi]`` if ``half``: the half disc on the ``e_y`` side), v from the rim
    (v = 0) to the centre (v = 1, a collapsed edge). Normal ``e_x x e_y``."""
    xy, wc, knots = (HALF_XY, HALF_W, HALF_KNOTS) if half else (CIRCLE_XY, CIRCLE_W, CIRCLE_KNOTS)
    rim = np.asarray(center, float) + radius * (xy[:, 0, None] * np.asarray(e_x, float)
                                                + xy[:, 1, None] * np.asarray(e_y, float))
    points = np.stack([rim, np.broadcast_to(np.asarray(center, float), rim.shape)], axis=1)
    weights = np.repeat(wc[:, None], 2, axis=1)
    return NurbsSurface.from_points((2, 1), knots, [0, 0, 1, 1], points, weights)


def _quad(origin, du, dv) -> NurbsSurface:
    """Bilinear patch ``origin + s du + t dv``, normal along ``du x dv``."""
    o, du, dv = (np.asarray(x, float) for x in (origin, du, dv))
    points = np.array([[o, o + dv], [o + du, o + du + dv]])
    return NurbsSurface.from_points((1, 1), [0, 0, 1, 1], [0, 0, 1, 1], points)


def box(spec: BoxSpec) -> Solid:
    """Six bilinear faces ``xmin xmax ymin ymax zmin zmax`` of an axis-aligned box."""
    lo, hi = np.asarray(spec.min, float), np.asarray(spec.max, float)
    dx, dy, dz = np.diag(hi - lo)
    faces = {
        "xmin": _quad(lo, dz, dy),
        "xmax": _quad(lo + dx, dy, dz),
        "ymin": _quad(lo, dx, dz),
        "ymax": _quad(lo + dy, dz, dx),
        "zmin": _quad(lo, dy, dx),
        "zmax": _quad(lo + dz, dx, dy),
    }
    return Solid(tuple(Patch(name, surf) for name, surf in faces.items()))


def sphere(spec: SphereSpec) -> Solid:
    """One patch ``surface``: a half circle meridian (south to north pole) revolved."""
    r = spec.radius
    profile = [(0, -r), (r, -r), (r, 0), (r, r), (0, r)]
    surf = revolve(profile, HALF_W, HALF_KNOTS, 2, orthonormal_frame((0, 0, 1)), spec.center)
    return Solid((Patch("surface", surf),))


def cylinder(spec: CylinderSpec) -> Solid:
    """Patches ``side`` (revolved segment), ``bottom`` and ``top`` (discs)."""
    e1, e2, a = orthonormal_frame(spec.axis)
    c = np.asarray(spec.center, float)
    r, half_h = spec.radius, 0.5 * spec.height
    side = revolve([(r, -half_h), (r, half_h)], [1, 1], [0, 0, 1, 1], 1, (e1, e2, a), c)
    bottom = disc(c - half_h * a, e2, e1, r)
    top = disc(c + half_h * a, e1, e2, r)
    return Solid((Patch("side", side), Patch("bottom", bottom), Patch("top", top)))


def half_cylinder(spec: HalfCylinderSpec) -> Solid:
    """Patches ``side`` (half a turn, on the ``keep`` side), ``flat`` (the rectangle through the
    axis), ``bottom`` and ``top`` (half discs at ``center -/+ axis * height / 2``)."""
    a = np.asarray(spec.axis, float)
    keep = np.asarray(spec.keep, float)
    e1, e2, a = orthonormal_frame(a, first=np.cross(keep, a))  # e2 = a x e1 = keep
    c = np.asarray(spec.center, float)
    r, half_h = spec.radius, 0.5 * spec.height
    side = revolve([(r, -half_h), (r, half_h)], [1, 1], [0, 0, 1, 1], 1, (e1, e2, a), c, half=True)
    flat = _quad(c - r * e1 - half_h * a, 2.0 * r * e1, spec.height * a)  # normal e1 x a = -keep
    bottom = disc(c - half_h * a, -e1, e2, r, half=True)  # normal -e1 x e2 = -a
    top = disc(c + half_h * a, e1, e2, r, half=True)
    return Solid((Patch("side", side), Patch("flat", flat), Patch("bottom", bottom), Patch("top", top)))


def _tube_profile(R: float, r: float) -> np.ndarray:
    """Control points of the tube cross-section circle in the ``(rho, z)`` half-plane,
    counterclockwise from its outermost point."""
    return np.column_stack([R + r * CIRCLE_XY[:, 0], r * CIRCLE_XY[:, 1]])


def torus(spec: TorusSpec) -> Solid:
    """One patch ``surface``: the tube circle revolved a full turn."""
    frame = orthonormal_frame(spec.axis)
    surf = revolve(_tube_profile(spec.major_radius, spec.minor_radius), CIRCLE_W, CIRCLE_KNOTS, 2,
                   frame, spec.center)
    return Solid((Patch("surface", surf),))


def half_torus(spec: HalfTorusSpec) -> Solid:
    """Patches ``tube`` (half a turn, on the ``keep`` side) and the discs ``cap_a`` (centred at
    ``center + R s``, ``s = keep x axis``) and ``cap_b`` (at ``center - R s``)."""
    a = np.asarray(spec.axis, float)
    keep = np.asarray(spec.keep, float)
    s = np.cross(keep, a)
    e1, e2, a = orthonormal_frame(a, first=s)  # e2 = a x s = keep
    c = np.asarray(spec.center, float)
    R, r = spec.major_radius, spec.minor_radius
    tube = revolve(_tube_profile(R, r), CIRCLE_W, CIRCLE_KNOTS, 2, (e1, e2, a), c, half=True)
    cap_a = disc(c + R * e1, e1, a, r)  # normal e1 x a = -keep (outward)
    cap_b = disc(c - R * e1, e1, a, r)
    return Solid((Patch("tube", tube), Patch("cap_a", cap_a), Patch("cap_b", cap_b)))


def build_solid(spec: GeometrySpec) -> Solid:
    """The solid a geometry spec describes."""
    if isinstance(spec, BoxSpec):
        return box(spec)
    if isinstance(spec, SphereSpec):
        return sphere(spec)
    if isinstance(spec, HalfCylinderSpec):  # before CylinderSpec: it is a subclass
        return half_cylinder(spec)
    if isinstance(spec, CylinderSpec):
        return cylinder(spec)
    if isinstance(spec, HalfTorusSpec):  # before TorusSpec: it is a subclass
        return half_torus(spec)
    if isinstance(spec, TorusSpec):
        return torus(spec)
    if isinstance(spec, NurbsFileSpec):
        from cgfem.geometry.io import read_solid

        return read_solid(spec.file)
    raise TypeError(f"unknown geometry spec {type(spec).__name__}")
