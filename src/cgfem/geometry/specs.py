"""Typed parameters of the solid builders, validated on construction.

Each spec is what a case file's ``geometry:`` entry says; :func:`cgfem.geometry.build_solid`
turns it into a :class:`~cgfem.geometry.solid.Solid`. Validation errors are
:class:`~cgfem.errors.InputError` whose field is the parameter name; the case loader
prefixes the path of the entry. Lengths in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cgfem.errors import InputError

#: Tolerance on |axis| - 1 and on the orthogonality of ``keep`` to ``axis``.
UNIT_TOL = 1e-9


def _point(name: str, value) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(name, f"expected 3 numbers, got {value!r}") from None
    if arr.shape != (3,):
        raise InputError(name, f"expected 3 numbers, got {value!r}")
    if not np.all(np.isfinite(arr)):
        raise InputError(name, f"must be finite, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _unit(name: str, value) -> tuple[float, float, float]:
    vec = _point(name, value)
    norm = math.sqrt(sum(c * c for c in vec))
    if norm == 0.0:
        raise InputError(name, "must be a unit vector, got the zero vector")
    if abs(norm - 1.0) > UNIT_TOL:
        raise InputError(name, f"must be a unit vector, got |{name}| = {norm:.12g}")
    return vec


def _keep(value, axis) -> tuple[float, float, float]:
    """``keep``: a unit vector perpendicular to ``axis`` (the half of the solid kept)."""
    keep = _unit("keep", value)
    if abs(float(np.dot(keep, axis))) > UNIT_TOL:
        raise InputError("keep", "must be perpendicular to axis")
    return keep


def _positive(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(name, f"expected a number, got {value!r}")
    if not math.isfinite(value) or value <= 0.0:
        raise InputError(name, f"must be a positive length, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class BoxSpec:
    """Axis-aligned box ``[min, max]``; patches ``xmin xmax ymin ymax zmin zmax``."""

    min: tuple[float, float, float]
    max: tuple[float, float, float]

    def __post_init__(self) -> None:
        lo, hi = _point("min", self.min), _point("max", self.max)
        object.__setattr__(self, "min", lo)
        object.__setattr__(self, "max", hi)
        for axis, a, b in zip("xyz", lo, hi):
            if not b > a:
                raise InputError("max", f"box has zero or negative size along {axis} ({a} to {b})")


@dataclass(frozen=True)
class SphereSpec:
    """Sphere; one patch ``surface``."""

    center: tuple[float, float, float]
    radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _point("center", self.center))
        object.__setattr__(self, "radius", _positive("radius", self.radius))


@dataclass(frozen=True)
class CylinderSpec:
    """Circular cylinder centred at ``center`` along unit ``axis``; patches ``side bottom top``
    (``bottom`` at ``center - axis * height / 2``)."""

    center: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius: float
    height: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _point("center", self.center))
        object.__setattr__(self, "axis", _unit("axis", self.axis))
        object.__setattr__(self, "radius", _positive("radius", self.radius))
        object.__setattr__(self, "height", _positive("height", self.height))


@dataclass(frozen=True)
class TorusSpec:
    """Ring torus about unit ``axis`` (``minor_radius < major_radius``); one patch ``surface``."""

    center: tuple[float, float, float]
    axis: tuple[float, float, float]
    major_radius: float
    minor_radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _point("center", self.center))
        object.__setattr__(self, "axis", _unit("axis", self.axis))
        R = _positive("major_radius", self.major_radius)
        r = _positive("minor_radius", self.minor_radius)
        if not r < R:
            raise InputError("minor_radius", f"must be smaller than major_radius ({r} >= {R})")
        object.__setattr__(self, "major_radius", R)
        object.__setattr__(self, "minor_radius", r)


@dataclass(frozen=True)
class HalfTorusSpec(TorusSpec):
    """The half of a torus where ``(p - center) . keep >= 0``; patches ``tube cap_a cap_b``.

    ``keep`` is a unit vector perpendicular to ``axis``. The cut plane contains ``axis`` and
    ``s = keep x axis``; ``cap_a`` is the disc centred at ``center + R s``, ``cap_b`` the one
    at ``center - R s``.
    """

    keep: tuple[float, float, float] = (1.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "keep", _keep(self.keep, self.axis))


@dataclass(frozen=True)
class HalfCylinderSpec(CylinderSpec):
    """The half of a cylinder where ``(p - center) . keep >= 0``; patches ``side flat bottom top``.

    ``keep`` is a unit vector perpendicular to ``axis``. ``side`` is the half of the curved
    face, ``flat`` the rectangle through the axis (outward normal ``-keep``), ``bottom`` and
    ``top`` the half discs at ``center -/+ axis * height / 2``.
    """

    keep: tuple[float, float, float] = (1.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "keep", _keep(self.keep, self.axis))


@dataclass(frozen=True)
class NurbsFileSpec:
    """A solid read from a NURBS JSON file (see :mod:`cgfem.geometry.io`)."""

    file: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "file", Path(self.file))


GeometrySpec = (BoxSpec | SphereSpec | CylinderSpec | TorusSpec | HalfTorusSpec | HalfCylinderSpec
                | NurbsFileSpec)

#: builder name in a case file -> spec class
BUILDERS: dict[str, type] = {
    "box": BoxSpec,
    "sphere": SphereSpec,
    "cylinder": CylinderSpec,
    "torus": TorusSpec,
    "half_torus": HalfTorusSpec,
    "half_cylinder": HalfCylinderSpec,
    "nurbs": NurbsFileSpec,
}

#: patch names each builder produces (``nurbs``: the names in the file)
PATCH_NAMES: dict[str, tuple[str, ...]] = {
    "box": ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax"),
    "sphere": ("surface",),
    "cylinder": ("side", "bottom", "top"),
    "torus": ("surface",),
    "half_torus": ("tube", "cap_a", "cap_b"),
    "half_cylinder": ("side", "flat", "bottom", "top"),
}
