"""A loaded case: frozen, typed dataclasses (SI units), validated on construction.

Validation errors are :class:`~cgfem.errors.InputError`. Parts that sit inside a case file
entry (:class:`Material`, :class:`GridSpec`, ...) name the field relative to that entry
(``nu``, ``offset[1]``); the loader prefixes the entry's path. :class:`Case` checks the
references between entries and names full paths (``boundary[3].body``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, NamedTuple

from cgfem.case.expressions import Expression, VectorExpression
from cgfem.errors import InputError
from cgfem.geometry.specs import BUILDERS, GeometrySpec

__all__ = [
    "BODY_NAME",
    "DEFAULT_STEPS",
    "KINEMATICS",
    "LINEAR_SOLVERS",
    "MATERIAL_MODELS",
    "Body",
    "BoundaryCondition",
    "Case",
    "ContactPair",
    "DisplacementBC",
    "GridSpec",
    "Lame",
    "Material",
    "SolverOptions",
    "TractionBC",
]

KINEMATICS = ("small", "finite")
MATERIAL_MODELS = ("linear_elastic", "neo_hookean")
LINEAR_SOLVERS = ("auto", "superlu", "pyamg", "pardiso")
#: pattern of a body name
BODY_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
#: load steps when the case file does not say
DEFAULT_STEPS = 1
#: spec class -> builder name in a case file
_BUILDER_NAMES: dict[type, str] = {cls: name for name, cls in BUILDERS.items()}


def _finite(field: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(field, f"expected a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise InputError(field, f"must be finite, got {value!r}")
    return number


def _one_of(field: str, value: str, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise InputError(field, f"must be one of {', '.join(allowed)}, got {value!r}")
    return value


def _count(field: str, value: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise InputError(field, f"must be an integer >= 1, got {value!r}")
    return value


class Lame(NamedTuple):
    """Lamé parameters (Pa), always in this order: ``lam, mu = material.lame()``; the numba
    kernels take ``(mu, lam)``, so pass them by name (``l.mu, l.lam``) there."""

    lam: float
    mu: float


@dataclass(frozen=True)
class Material:
    """Isotropic hyperelastic material: Young's modulus ``E`` (Pa), Poisson's ratio ``nu``."""

    model: Literal["linear_elastic", "neo_hookean"]
    E: float
    nu: float

    def __post_init__(self) -> None:
        _one_of("model", self.model, MATERIAL_MODELS)
        E, nu = _finite("E", self.E), _finite("nu", self.nu)
        if not E > 0.0:
            raise InputError("E", f"must be > 0, got {self.E!r}")
        if not -1.0 < nu < 0.5:
            raise InputError("nu", f"must be in (-1, 0.5), got {self.nu!r}")
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "nu", nu)

    def lame(self) -> Lame:
        """Lamé parameters ``Lame(lam, mu)`` in Pa:
        ``lam = E nu / ((1 + nu)(1 - 2 nu))``, ``mu = E / (2 (1 + nu))``."""
        lam = self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))
        mu = self.E / (2.0 * (1.0 + self.nu))
        return Lame(lam, mu)


@dataclass(frozen=True)
class GridSpec:
    """Cartesian grid of a body: element size ``h0`` (m) at level 0 and the origin shift
    ``offset`` in units of ``h`` (each in ``[0, 1)``)."""

    h0: float
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        h0 = _finite("h0", self.h0)
        if not h0 > 0.0:
            raise InputError("h0", f"must be > 0, got {self.h0!r}")
        offset = tuple(self.offset)
        if len(offset) != 3:
            raise InputError("offset", f"expected 3 numbers, got {self.offset!r}")
        for i, value in enumerate(offset):
            if not 0.0 <= _finite(f"offset[{i}]", value) < 1.0:
                raise InputError(f"offset[{i}]", f"must be in [0, 1), got {value!r}")
        object.__setattr__(self, "h0", h0)
        object.__setattr__(self, "offset", tuple(float(v) for v in offset))

    def h(self, level: int) -> float:
        """Element size at refinement ``level``: ``h0 / 2**level`` (m)."""
        return self.h0 / 2.0**level


@dataclass(frozen=True)
class Body:
    """One deformable body: its geometry spec, material, grid, optional body force
    (N/m^3, a vector field in ``x, y, z``) and optional ``hold_spin``, the axis (3,) of a spin
    about its nodes' centroid held by a torsional spring (:mod:`cgfem.solve.spin`)."""

    name: str
    geometry: GeometrySpec
    material: Material
    grid: GridSpec
    body_force: VectorExpression | None = None
    hold_spin: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not BODY_NAME.match(self.name):
            raise InputError("name", f"must match {BODY_NAME.pattern}, got {self.name!r}")
        if type(self.geometry) not in _BUILDER_NAMES:
            raise InputError("geometry", f"expected a geometry spec, got {self.geometry!r}")
        if self.hold_spin is not None:
            axis = tuple(float(a) for a in self.hold_spin)
            if len(axis) != 3 or not all(math.isfinite(a) for a in axis) or not any(axis):
                raise InputError("hold_spin", f"expected an axis of three finite numbers, not all 0, "
                                              f"got {list(self.hold_spin)}")
            object.__setattr__(self, "hold_spin", axis)

    @property
    def builder(self) -> str:
        """The builder name of the geometry (``box``, ..., ``nurbs``)."""
        return _BUILDER_NAMES[type(self.geometry)]


def _patches(patches: tuple[str, ...]) -> tuple[str, ...]:
    patches = tuple(patches)
    if not patches:
        raise InputError("patches", "must list at least one patch")
    for j, name in enumerate(patches):
        if not isinstance(name, str) or not name:
            raise InputError(f"patches[{j}]", f"expected a patch name, got {name!r}")
        if name in patches[:j]:
            raise InputError(f"patches[{j}]", f"duplicate patch name {name!r}")
    return patches


@dataclass(frozen=True)
class DisplacementBC:
    """Prescribed displacement (m) on ``patches`` of ``body``: ``components`` pairs a
    component index (0, 1, 2 for x, y, z; increasing) with its value at load factor 1.
    Components not listed stay free."""

    body: str
    patches: tuple[str, ...]
    components: tuple[tuple[int, Expression], ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "patches", _patches(self.patches))
        components = tuple((int(i), e) for i, e in self.components)
        indices = [i for i, _ in components]
        if not components:
            raise InputError("components", "must set at least one of x, y, z")
        if indices != sorted(set(indices)) or not set(indices) <= {0, 1, 2}:
            raise InputError("components", f"indices must be distinct, increasing, in 0..2, got {indices}")
        if not all(isinstance(e, Expression) for _, e in components):
            raise InputError("components", "values must be Expressions")
        object.__setattr__(self, "components", components)


@dataclass(frozen=True)
class TractionBC:
    """Prescribed traction ``value`` (Pa, a vector field in ``x, y, z``) on ``patches``."""

    body: str
    patches: tuple[str, ...]
    value: VectorExpression

    def __post_init__(self) -> None:
        object.__setattr__(self, "patches", _patches(self.patches))


BoundaryCondition = DisplacementBC | TractionBC


#: slave rules of a contact pair: the slave's boundary rule (the paper's) or the slave split
#: at both grids' planes (:mod:`cgfem.contact.rule`)
CONTACT_RULES = ("boundary", "segmented")


@dataclass(frozen=True)
class ContactPair:
    """Contact of the ``slave`` body's surface against the ``master`` body; penalty
    ``kappa * E / h`` with ``E`` of the slave."""

    slave: str
    master: str
    kappa: float = 10.0
    slave_patches: tuple[str, ...] | None = None     # None: every patch of the body
    master_patches: tuple[str, ...] | None = None
    #: the fitting space of ``nurbs_fit`` (:func:`cgfem.contact.fit.fit_space`): "auto",
    #: "none" or a number of knots inserted per span
    fit: str | int = "auto"
    #: where the contact work is integrated on the slave (:mod:`cgfem.contact.rule`), one
    #: of :data:`CONTACT_RULES`
    rule: str = "boundary"

    def __post_init__(self) -> None:
        if self.slave == self.master:
            raise InputError("master", f"must differ from slave ({self.slave!r})")
        fit = self.fit
        if not (fit in ("auto", "none") or (isinstance(fit, int) and not isinstance(fit, bool) and fit >= 0)):
            raise InputError("fit", f"expected 'auto', 'none' or an integer >= 0, got {fit!r}")
        if self.rule not in CONTACT_RULES:
            raise InputError("rule", f"expected one of {', '.join(CONTACT_RULES)}, got {self.rule!r}")
        for name in ("slave_patches", "master_patches"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _patches(getattr(self, name)))
        kappa = _finite("kappa", self.kappa)
        if not kappa > 0.0:
            raise InputError("kappa", f"must be > 0, got {self.kappa!r}")
        object.__setattr__(self, "kappa", kappa)


@dataclass(frozen=True)
class SolverOptions:
    """Newton tolerance (relative residual), iteration limits, linear solver choice, the
    outer-loop tolerance on the recovered stress and its cap ``outer_passes`` (a step whose
    loop reaches the cap above ``outer_tol`` is reported ``outer_converged: false``), the
    number of step cut-backs, and the weak-Dirichlet (``kappa_dirichlet``) and
    ghost-penalty (``ghost_penalty``) parameters (None: the element's own,
    :attr:`cgfem.fem.element.Hexahedron.kappa_dirichlet` and ``.ghost_penalty``)."""

    newton_tol: float = 1e-9
    max_newton: int = 30
    outer_passes: int = 50
    linear: Literal["auto", "superlu", "pyamg", "pardiso"] = "auto"
    outer_tol: float = 1e-6
    max_cutbacks: int = 5
    kappa_dirichlet: float | None = None
    ghost_penalty: float | None = None

    def __post_init__(self) -> None:
        for name in ("newton_tol", "outer_tol", "kappa_dirichlet"):
            if name == "kappa_dirichlet" and self.kappa_dirichlet is None:   # the element's
                continue
            value = _finite(name, getattr(self, name))
            if not value > 0.0:
                raise InputError(name, f"must be > 0, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)
        if self.ghost_penalty is not None:
            gamma = _finite("ghost_penalty", self.ghost_penalty)
            if gamma < 0.0:
                raise InputError("ghost_penalty", f"must be >= 0, got {self.ghost_penalty!r}")
            object.__setattr__(self, "ghost_penalty", gamma)
        _count("max_newton", self.max_newton)
        _count("outer_passes", self.outer_passes)
        if isinstance(self.max_cutbacks, bool) or not isinstance(self.max_cutbacks, int) \
                or self.max_cutbacks < 0:
            raise InputError("max_cutbacks", f"must be an integer >= 0, got {self.max_cutbacks!r}")
        _one_of("linear", self.linear, LINEAR_SOLVERS)


def require_body(names: tuple[str, ...], name: str, field: str) -> None:
    """Raise :class:`InputError` at ``field`` unless ``name`` is one of ``names``."""
    if name not in names:
        raise InputError(field, f"unknown body {name!r} (known: {', '.join(names)})")


@dataclass(frozen=True)
class Case:
    """A whole case file: bodies in file order, boundary conditions, contact pairs, solver
    options; ``source`` is the file it was read from, if any."""

    name: str
    kinematics: Literal["small", "finite"]
    steps: int
    bodies: tuple[Body, ...]
    boundary: tuple[BoundaryCondition, ...]
    contact: tuple[ContactPair, ...]
    solver: SolverOptions
    source: Path | None = None

    def __post_init__(self) -> None:
        _one_of("kinematics", self.kinematics, KINEMATICS)
        _count("steps", self.steps)
        for name in ("bodies", "boundary", "contact"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if not self.bodies:
            raise InputError("bodies", "must define at least one body")
        names = tuple(b.name for b in self.bodies)
        for i, name in enumerate(names):
            if name in names[:i]:
                raise InputError(f"bodies.{name}", "duplicate body name")
        if self.kinematics == "finite":
            for body in self.bodies:
                if body.material.model != "neo_hookean":
                    raise InputError(f"bodies.{body.name}.material.model", "finite kinematics need "
                                     f"neo_hookean, got {body.material.model!r}")
        for i, bc in enumerate(self.boundary):
            require_body(names, bc.body, f"boundary[{i}].body")
        for i, pair in enumerate(self.contact):
            require_body(names, pair.slave, f"contact[{i}].slave")
            require_body(names, pair.master, f"contact[{i}].master")
            for j, other in enumerate(self.contact[:i]):
                if {other.slave, other.master} == {pair.slave, pair.master}:
                    raise InputError(f"contact[{i}]", f"bodies {pair.slave!r} and {pair.master!r} "
                                     f"are already paired by contact[{j}]")

    @property
    def held_by_contact_alone(self) -> bool:
        """Whether a body has no displacement conditions (with contact: held by contact
        alone), as :meth:`cgfem.solve.system.System.held_by_contact_alone` decides on the
        built bodies."""
        supported = {bc.body for bc in self.boundary if isinstance(bc, DisplacementBC)}
        return bool(self.contact) and any(b.name not in supported for b in self.bodies)

    @property
    def symmetric(self) -> bool:
        """Whether the Newton matrices are symmetric: not with contact in finite strain (the
        current-area weight), as :attr:`cgfem.solve.system.System.symmetric` decides on the
        built pairs."""
        return not (self.contact and self.kinematics == "finite")

    @property
    def body_names(self) -> tuple[str, ...]:
        """Names of the bodies, in file order."""
        return tuple(b.name for b in self.bodies)

    def body(self, name: str) -> Body:
        """The body called ``name``; ``KeyError`` if there is none."""
        for body in self.bodies:
            if body.name == name:
                return body
        raise KeyError(name)
