"""Exact geometry and curved meshes of the chain examples for the body-fitted reference.

A chain case (``config/cases/chain*.yaml``) is a set of tori and half tori. Every body and
every load of these cases is symmetric under ``x -> -x`` and ``z -> -z``
(:func:`check_symmetry` proves it from the case), so the reference solves the quarter
``x >= 0, z >= 0`` with ``u_x = 0`` on ``x = 0`` and ``u_z = 0`` on ``z = 0``.

Each body's quarter is an OpenCascade solid (:mod:`netgen.occ`): the torus is the
revolution of the tube's disc about the axis (an exact toroidal surface), cut by the half
space of a half torus and by the two symmetry half spaces. Its boundary faces are named

- ``{body}_tube``: the toroidal surface (the contact candidate),
- ``{body}_cap``: the flat faces in the cut plane of a half torus (the quarter holds one
  half of one of its two caps, ``cap_a`` or ``cap_b``),
- ``sym_x`` and ``sym_z``: the faces in the symmetry planes.

Meshes are netgen tetrahedra of maximal size ``h`` (m), refined to ``h_contact`` within
``r_contact`` of the points where the tubes touch in the reference configuration
(:func:`touch_points`) and along the cap edges, the circles where a half torus's caps meet its
tube (:func:`cap_edge_points`; the solution is singular there, and an unrefined edge sets the
rate at which a nearly incompressible link's reaction converges), and curved to the element
order (``Mesh.Curve``): the geometry error of the curved mesh is ``O(h^(p+1))``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cgfem.case import Case
from cgfem.errors import InputError
from cgfem.geometry.specs import HalfTorusSpec, TorusSpec

__all__ = ["MeshSpec", "SYM_X", "SYM_Z", "build_mesh", "cap", "cap_edge_points",
           "check_symmetry", "mesh_level", "quarter_solid", "touch_points", "tube"]

SYM_X = "sym_x"
SYM_Z = "sym_z"
#: the reflections the quarter model relies on: x -> -x and z -> -z
REFLECTIONS = (np.diag([-1.0, 1.0, 1.0]), np.diag([1.0, 1.0, -1.0]))
#: relative tolerance of the symmetry checks
TOL = 1e-9
#: tolerance of the face classification, relative to R (OCC pads bounding boxes by 1e-7 m)
FACE_TOL = 1e-4


def tube(body: str) -> str:
    """Boundary name of the toroidal face of ``body``."""
    return f"{body}_tube"


def cap(body: str) -> str:
    """Boundary name of the cap faces of ``body`` (a half torus)."""
    return f"{body}_cap"


@dataclass(frozen=True)
class MeshSpec:
    """Mesh size ``h`` (m) everywhere, ``h_contact`` (m) within ``r_contact`` (m) of the
    touch points and along the cap edges, element order ``order`` (>= 2: curved elements)."""

    h: float
    h_contact: float
    r_contact: float
    order: int = 2

    def as_dict(self) -> dict:
        return {"h": self.h, "h_contact": self.h_contact, "r_contact": self.r_contact,
                "order": self.order}


#: level 0 of the reference meshes of the chains and the factor between two levels
H0, H_CONTACT0, R_CONTACT = 0.004, 0.001, 0.004
LEVEL_FACTOR = 2.0 ** -0.5


def mesh_level(level: int, order: int = 2, r_contact: float = R_CONTACT) -> MeshSpec:
    """The reference mesh ``level``: ``h = 4 mm`` and ``h_contact = 1 mm`` at level 0,
    both divided by ``sqrt 2`` per level (about 2.8 times the elements per level);
    ``h_contact`` within ``r_contact`` (m, the same on every level) of the touch points,
    which must hold the contact zone of every load step (the study reports its extent), and
    along the cap edges."""
    if level < 0:
        raise InputError("level", f"must be >= 0, got {level}")
    f = LEVEL_FACTOR ** level
    return MeshSpec(H0 * f, H_CONTACT0 * f, r_contact, order)


def _tori(case: Case) -> dict[str, TorusSpec]:
    specs = {}
    for body in case.bodies:
        if not isinstance(body.geometry, TorusSpec):
            raise InputError(f"bodies.{body.name}.geometry",
                             f"the torus reference needs tori and half tori, got {body.builder}")
        specs[body.name] = body.geometry
    return specs


def check_symmetry(case: Case) -> None:
    """Raise :class:`InputError` unless ``case`` is symmetric under ``x -> -x`` and
    ``z -> -z``: every torus centre on the y axis, every axis and ``keep`` mapped to
    ``+-`` itself (``keep`` to itself), every prescribed displacement constant with zero x
    and z components (or those left free), and no traction loads."""
    for name, spec in _tori(case).items():
        where = f"bodies.{name}.geometry"
        c, a = np.asarray(spec.center), np.asarray(spec.axis)
        tol = TOL * spec.major_radius
        for S in REFLECTIONS:
            if np.abs(S @ c - c).max() > tol:
                raise InputError(f"{where}.center", "must lie on the y axis (x = z = 0) for "
                                 "the quarter model")
            if min(np.abs(S @ a - a).max(), np.abs(S @ a + a).max()) > TOL:
                raise InputError(f"{where}.axis", "must be a coordinate axis for the quarter model")
            if isinstance(spec, HalfTorusSpec):
                k = np.asarray(spec.keep)
                if np.abs(S @ k - k).max() > TOL:
                    raise InputError(f"{where}.keep", "must be +-y for the quarter model")
    for i, bc in enumerate(case.boundary):
        if not hasattr(bc, "components"):
            raise InputError(f"boundary[{i}]", "the torus reference takes displacement supports only")
        for component, expr in bc.components:
            if not expr.is_constant:
                raise InputError(f"boundary[{i}]", "prescribed displacements must be constant")
            if component != 1 and expr.constant_value != 0.0:
                raise InputError(f"boundary[{i}]", "x and z displacements must be zero (symmetry)")


def _frame(spec: TorusSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit axis ``a`` and two unit vectors ``e1, e2`` completing it to a right-handed frame."""
    a = np.asarray(spec.axis, float)
    e1 = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = e1 - (e1 @ a) * a
    e1 /= np.linalg.norm(e1)
    return a, e1, np.cross(a, e1)


def quarter_solid(name: str, spec: TorusSpec):
    """The quarter ``x >= 0, z >= 0`` of a torus or half torus as a named
    :class:`netgen.occ` solid (faces named as the module says, the solid ``name``)."""
    from netgen.occ import Axes, Axis, Box, WorkPlane

    c = np.asarray(spec.center, float)
    R, r = spec.major_radius, spec.minor_radius
    a, e1, e2 = _frame(spec)
    plane = WorkPlane(Axes(tuple(c + R * e1), n=tuple(e2), h=tuple(e1)))
    solid = plane.Circle(0.0, 0.0, r).Face().Revolve(Axis(tuple(c), tuple(a)), 360)
    big = 10.0 * (R + r) + float(np.abs(c).max())
    solid = solid * Box((0.0, -big, 0.0), (big, big, big))
    cut_y = None
    if isinstance(spec, HalfTorusSpec):
        cut_y = c[1]
        lo, hi = (cut_y, big) if spec.keep[1] > 0 else (-big, cut_y)
        solid = solid * Box((-big, lo, -big), (big, hi, big))
    tol = FACE_TOL * R
    for face in solid.faces:
        pmin, pmax = (np.array([p.x, p.y, p.z]) for p in face.bounding_box)
        if pmax[0] - pmin[0] < tol and abs(pmin[0]) < tol:
            face.name = SYM_X
        elif pmax[2] - pmin[2] < tol and abs(pmin[2]) < tol:
            face.name = SYM_Z
        elif cut_y is not None and pmax[1] - pmin[1] < tol and abs(pmin[1] - cut_y) < tol:
            face.name = cap(name)
        else:
            face.name = tube(name)
    solid.solids.name = name
    return solid


def _centreline(spec: TorusSpec, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (m, 3) of the centre circle of ``spec`` at the angles ``t`` that lie in the
    quarter and in the kept half, and those angles (m,)."""
    c = np.asarray(spec.center, float)
    a, e1, e2 = _frame(spec)
    p = c + spec.major_radius * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2)
    keep = (p[:, 0] >= -1e-12) & (p[:, 2] >= -1e-12)
    if isinstance(spec, HalfTorusSpec):
        keep &= (p - c) @ np.asarray(spec.keep) >= -1e-12
    return p[keep], t[keep]


def _closest(s: TorusSpec, m: TorusSpec, ts: np.ndarray, tm: np.ndarray) -> tuple[float, float, float]:
    ps, ts = _centreline(s, ts)
    pm, tm = _centreline(m, tm)
    d = np.linalg.norm(ps[:, None, :] - pm[None, :, :], axis=-1)
    i, j = np.unravel_index(np.argmin(d), d.shape)
    return float(d[i, j]), float(ts[i]), float(tm[j])


def touch_points(case: Case, n: int = 720, rounds: int = 4) -> list[np.ndarray]:
    """Point (3,) where the tubes of each contact pair of ``case`` are closest in the
    reference configuration (in the quarter): on the segment between the nearest points of
    the two centre circles, ``r_slave`` from the slave's. The nearest points are found on
    ``n`` angles per circle, then ``rounds`` times on ``n`` angles around the best pair in
    a window ``n / 4`` times narrower (angles to about ``(2 pi / n) (4 / n)^rounds``)."""
    specs, points = _tori(case), []
    for pair in case.contact:
        s, m = specs[pair.slave], specs[pair.master]
        width = 2.0 * np.pi
        _, a, b = _closest(s, m, np.linspace(0.0, width, n, endpoint=False),
                           np.linspace(0.0, width, n, endpoint=False))
        for _ in range(rounds):
            width *= 8.0 / n
            _, a, b = _closest(s, m, np.linspace(a - width, a + width, n),
                               np.linspace(b - width, b + width, n))
        p, q = _centreline(s, np.array([a]))[0][0], _centreline(m, np.array([b]))[0][0]
        points.append(p + s.minor_radius * (q - p) / np.linalg.norm(q - p))
    return points


def _surface_samples(spec: TorusSpec, centre: np.ndarray, radius: float, step: float) -> np.ndarray:
    """Points of the tube surface of ``spec`` within ``radius`` of ``centre``, about
    ``step`` apart."""
    c = np.asarray(spec.center, float)
    R, r = spec.major_radius, spec.minor_radius
    a, e1, e2 = _frame(spec)
    n_t = max(8, int(np.ceil(2.0 * np.pi * (R + r) / step)))
    n_p = max(8, int(np.ceil(2.0 * np.pi * r / step)))
    t = np.linspace(0.0, 2.0 * np.pi, n_t, endpoint=False)[:, None, None]
    p = np.linspace(0.0, 2.0 * np.pi, n_p, endpoint=False)[None, :, None]
    radial = np.cos(t) * e1 + np.sin(t) * e2
    x = (c + (R + r * np.cos(p)) * radial + r * np.sin(p) * a).reshape(-1, 3)
    return x[np.linalg.norm(x - centre, axis=1) <= radius]


def cap_edge_points(spec: TorusSpec, step: float) -> np.ndarray:
    """Points (m, 3) of the cap edges of ``spec`` about ``step`` apart, in the quarter
    ``x >= 0, z >= 0``; none for a full torus. A half torus is cut by the plane through its
    centre with normal ``keep``, which meets the tube in two circles of radius ``r`` about
    ``c +- R e``, ``e = axis x keep``, in the plane spanned by ``e`` and the axis."""
    if not isinstance(spec, HalfTorusSpec):
        return np.zeros((0, 3))
    a = np.asarray(spec.axis, float)
    e = np.cross(a, np.asarray(spec.keep, float))
    e /= np.linalg.norm(e)
    phi = np.linspace(0.0, 2.0 * np.pi, max(8, int(np.ceil(2.0 * np.pi * spec.minor_radius / step))),
                      endpoint=False)[:, None]
    ring = spec.minor_radius * (np.cos(phi) * e + np.sin(phi) * a)
    c = np.asarray(spec.center, float)
    x = np.concatenate([c + sign * spec.major_radius * e + ring for sign in (1.0, -1.0)])
    return x[(x[:, 0] >= -1e-12) & (x[:, 2] >= -1e-12)]


def build_mesh(case: Case, spec: MeshSpec):
    """The curved quarter mesh of ``case`` (an :class:`ngsolve.Mesh` of order
    ``spec.order``), one material per body, boundaries named as the module says."""
    from netgen.meshing import MeshingParameters
    from netgen.occ import Compound, OCCGeometry
    from ngsolve import Mesh

    check_symmetry(case)
    tori = _tori(case)
    solids = [quarter_solid(name, s) for name, s in tori.items()]
    parameters = MeshingParameters(maxh=spec.h, grading=0.3)
    refined = [q for point in touch_points(case) for s in tori.values()
               for q in _surface_samples(s, point, spec.r_contact, spec.h_contact)
               if q[0] >= -1e-12 and q[2] >= -1e-12]
    refined += [q for s in tori.values() for q in cap_edge_points(s, spec.h_contact)]
    for q in refined:
        parameters.RestrictH(x=float(q[0]), y=float(q[1]), z=float(q[2]), h=spec.h_contact)
    mesh = Mesh(OCCGeometry(Compound(solids)).GenerateMesh(parameters))
    mesh.Curve(spec.order)
    return mesh
