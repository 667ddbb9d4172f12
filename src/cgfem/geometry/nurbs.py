"""Rational B-spline (NURBS) surfaces: an immutable patch and its vectorized evaluation.

A :class:`NurbsSurface` stores its control net as homogeneous points ``(w x, w y, w z, w)``,
shape ``(n_u, n_v, 4)``, with clamped (open) knot vectors. Evaluation runs in the numba
kernels of :mod:`cgfem.geometry._nurbs_kernels`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cgfem.errors import InputError
from cgfem.geometry import _nurbs_kernels as _k


def _check_knots(field: str, knots: np.ndarray, degree: int, n_ctrl: int) -> None:
    if knots.ndim != 1 or knots.size != n_ctrl + degree + 1:
        raise InputError(field, f"expected {n_ctrl + degree + 1} knots for {n_ctrl} control points "
                                f"of degree {degree}, got {knots.size}")
    if not np.all(np.isfinite(knots)):
        raise InputError(field, "knots must be finite")
    if np.any(np.diff(knots) < 0.0):
        raise InputError(field, "knots must be non-decreasing")
    first, last = knots[0], knots[-1]
    if not (np.all(knots[: degree + 1] == first) and np.all(knots[-degree - 1:] == last)):
        raise InputError(field, f"knot vector must be clamped (first and last knots repeated {degree + 1} times)")
    if not last > first:
        raise InputError(field, "knot vector spans an empty interval")
    inner = knots[degree + 1: -degree - 1]
    if inner.size and np.max(np.unique(inner, return_counts=True)[1]) > degree:
        raise InputError(field, f"an interior knot is repeated more than the degree ({degree}) times")


@dataclass(frozen=True, eq=False)
class NurbsSurface:
    """A NURBS surface patch.

    Attributes
    ----------
    degree : (p, q)
    knots_u : (n_u + p + 1,) clamped knot vector in u
    knots_v : (n_v + q + 1,) clamped knot vector in v
    control : (n_u, n_v, 4) homogeneous control points ``(w x, w y, w z, w)``, ``w > 0``
    """

    degree: tuple[int, int]
    knots_u: np.ndarray
    knots_v: np.ndarray
    control: np.ndarray

    def __post_init__(self) -> None:
        p, q = (int(d) for d in self.degree)
        if p < 1 or q < 1:
            raise InputError("degree", f"degrees must be >= 1, got {self.degree}")
        object.__setattr__(self, "degree", (p, q))
        control = np.ascontiguousarray(self.control, dtype=float)
        if control.ndim != 3 or control.shape[2] != 4:
            raise InputError("control", f"expected shape (n_u, n_v, 4), got {control.shape}")
        if control.shape[0] < p + 1 or control.shape[1] < q + 1:
            raise InputError("control", f"need at least degree + 1 control points per direction, got {control.shape[:2]}")
        if not np.all(np.isfinite(control)):
            raise InputError("control", "control points must be finite")
        if not np.all(control[..., 3] > 0.0):
            raise InputError("control", "weights must be positive")
        ku = np.ascontiguousarray(self.knots_u, dtype=float)
        kv = np.ascontiguousarray(self.knots_v, dtype=float)
        _check_knots("knots_u", ku, p, control.shape[0])
        _check_knots("knots_v", kv, q, control.shape[1])
        for name, arr in (("control", control), ("knots_u", ku), ("knots_v", kv)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    # -- construction -------------------------------------------------------------------
    @classmethod
    def from_points(cls, degree: tuple[int, int], knots_u, knots_v, points, weights=None) -> "NurbsSurface":
        """Build from Cartesian control points ``points`` (n_u, n_v, 3) and ``weights``
        (n_u, n_v), default 1."""
        points = np.asarray(points, dtype=float)
        w = np.ones(points.shape[:2]) if weights is None else np.asarray(weights, dtype=float)
        control = np.concatenate([points * w[..., None], w[..., None]], axis=-1)
        return cls(degree, np.asarray(knots_u, float), np.asarray(knots_v, float), control)

    # -- views ---------------------------------------------------------------------------
    @property
    def points(self) -> np.ndarray:
        """Cartesian control points, (n_u, n_v, 3)."""
        return self.control[..., :3] / self.control[..., 3:]

    @property
    def weights(self) -> np.ndarray:
        """Weights, (n_u, n_v)."""
        return self.control[..., 3]

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Parameter domain ``((u0, u1), (v0, v1))``."""
        return ((float(self.knots_u[0]), float(self.knots_u[-1])),
                (float(self.knots_v[0]), float(self.knots_v[-1])))

    def breaks(self) -> tuple[np.ndarray, np.ndarray]:
        """Distinct knots in u and v: the boundaries of the non-empty knot spans."""
        return np.unique(self.knots_u), np.unique(self.knots_v)

    # -- evaluation ------------------------------------------------------------------------
    def _args(self):
        p, q = self.degree
        return p, q, self.knots_u, self.knots_v, self.control

    def evaluate(self, uv) -> np.ndarray:
        """Surface points at parameters ``uv`` (n, 2) -> (n, 3)."""
        uv = _as_uv(uv)
        out = np.empty((uv.shape[0], 3))
        _k.surface_points_batch(*self._args(), uv, out)
        return out

    def derivatives(self, uv, order: int = 1) -> np.ndarray:
        """Partial derivatives up to total ``order`` at ``uv`` (n, 2) -> (n, order+1, order+1, 3);
        ``[:, k, l]`` is ``d^{k+l} S / du^k dv^l`` (zero where ``k + l > order``)."""
        if order < 0:
            raise ValueError("order must be >= 0")
        uv = _as_uv(uv)
        out = np.empty((uv.shape[0], order + 1, order + 1, 3))
        _k.surface_derivs_batch(*self._args(), uv, int(order), out)
        return out

    def normals(self, uv) -> np.ndarray:
        """Unit normals ``S_u x S_v / |S_u x S_v|`` at ``uv`` (n, 2) -> (n, 3); at collapsed
        edges (poles) the limit from inside the domain."""
        uv = _as_uv(uv)
        out = np.empty((uv.shape[0], 3))
        _k.unit_normals_batch(*self._args(), uv, out)
        return out

    # -- transformations --------------------------------------------------------------------
    def transformed(self, rotation: np.ndarray, translation) -> "NurbsSurface":
        """The surface under ``x -> rotation @ x + translation`` (an exact operation on the
        control points)."""
        pts = self.points @ np.asarray(rotation, float).T + np.asarray(translation, float)
        return NurbsSurface.from_points(self.degree, self.knots_u, self.knots_v, pts, self.weights)

    def reversed_u(self) -> "NurbsSurface":
        """The same surface with u reversed (flips the normal)."""
        a, b = self.knots_u[0], self.knots_u[-1]
        return NurbsSurface(self.degree, (a + b - self.knots_u)[::-1], self.knots_v, self.control[::-1])

    def bounding_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box of the control points (contains the surface: convex hull property)."""
        pts = self.points.reshape(-1, 3)
        return pts.min(axis=0), pts.max(axis=0)


def _as_uv(uv) -> np.ndarray:
    uv = np.ascontiguousarray(uv, dtype=float)
    if uv.ndim == 1:
        uv = uv.reshape(1, 2)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must have shape (n, 2), got {uv.shape}")
    return uv
