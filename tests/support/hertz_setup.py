"""Plane-strain Hertz line contact for the curved-contact tests: a half cylinder (radius R,
axis along y) pressed onto an elastic block, both linear elastic, small strain.

Plane strain by symmetry conditions: u_y = 0 on the block's ``ymin``/``ymax`` and on the half
cylinder's end half-discs ``bottom``/``top`` (thickness T along y). The block's ``zmin`` is
held in x and z; the cylinder's ``flat`` face (through its axis, at z = R) is held in x and
pushed down by ``delta`` in z (displacement control: a traction on ``flat`` leaves the
cylinder held in z by contact alone while other components are held, which the solver does
not stabilise -- it fails at the first load factor). The block's top (``zmax``) is the slave,
the cylinder's ``side`` the master.

Closed form: 1/E* = (1 - nu^2) / E_block + (1 - nu^2) / E_cylinder, half-width
a = sqrt(4 P R / (pi E*)), peak pressure p0 = 2 P / (pi a), p(x) = p0 sqrt(1 - x^2 / a^2),
for a load P per unit length.

Measured from ``contact_NNN.vtu`` (current positions): the half-width from the second moment
of the pressure, ``a = 2 sqrt(sum p w (x - xc)^2 / sum p w)`` (Hertz: the moment is a^2 / 4),
and the peak pressure from a weighted least-squares fit of the ellipse
``p0 sqrt(1 - (x - xc)^2 / a^2)`` over all slave points (:func:`fit_ellipse`; the largest
single lambda_N scatters by tens of per cent between neighbouring points).

The bodies are finite (about 5 a deep) and the gap is measured in the deformed
configuration, so Hertz's half-space is not these problems' limit.
``benchmarks/hertz_reference.py`` (an independent plane-strain solution with quadratic
elements, the arc exact and the contact exact, converged to 1e-6) gives it per setup: the
load at the imposed approach and, with the estimators above applied to its pressure profile,
the half-width and the fitted peak (:class:`Reference`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import meshio
import numpy as np
from scipy.optimize import minimize_scalar

from cgfem.case import parse_case
from cgfem.run import run_case

R = 1.0                    # cylinder radius, m
E, NU = 1.0e7, 0.3         # the block; the cylinder has E * e_ratio
HALF_WIDTH, DEPTH = 1.0, 1.0   # block: x in [-1, 1], z in [-1, 0]
SLIVER = 1e-9              # aligned setups: faces this far beyond their grid planes


@dataclass(frozen=True)
class Reference:
    """The converged solution of a setup (``benchmarks/hertz_reference.py``): load P (N/m) at
    the imposed approach, second-moment half-width a (m) and fitted peak p0 (Pa)."""

    load: float
    a: float
    p0: float


@dataclass(frozen=True)
class Setup:
    """One Hertz problem and its discretization.

    e_ratio : the cylinder's Young's modulus over the block's
    h_cyl, h_block : level-0 element sizes; level L has h0 / 2**L
    aligned : the y faces of both bodies lie ``SLIVER`` beyond grid planes (y offset 0, T a
        multiple of both sizes), so no chamfer runs along them; otherwise they lie between
        grid planes, at the offsets ``cyl_offset`` / ``block_offset`` (in element sizes)
    """

    thickness: float
    e_ratio: float
    delta: float
    kappa: float
    h_cyl: float
    h_block: float
    aligned: bool
    reference: Reference
    cyl_offset: tuple[float, float, float] = (0.37, 0.21, 0.23)
    block_offset: tuple[float, float, float] = (0.13, 0.29, 0.41)
    solver: dict = field(default_factory=lambda: {"newton_tol": 1e-10, "outer_tol": 1e-8, "outer_passes": 40})

    @property
    def e_star(self) -> float:
        return 1.0 / ((1.0 - NU**2) / E + (1.0 - NU**2) / (self.e_ratio * E))

    def hertz(self, load: float) -> tuple[float, float]:
        """Hertz's half-width (m) and peak pressure (Pa) at a load ``load`` (N/m)."""
        a = math.sqrt(4.0 * load * R / (math.pi * self.e_star))
        return a, 2.0 * load / (math.pi * a)

    def case(self, cyl_offset: tuple[float, float, float] | None = None) -> dict:
        """The case file (as a dict); ``cyl_offset``: another offset of the cylinder's grid."""
        T, eps = self.thickness, SLIVER if self.aligned else 0.0
        cyl_offset = list(self.cyl_offset if cyl_offset is None else cyl_offset)
        block_offset = list(self.block_offset)
        if self.aligned:
            cyl_offset[1] = block_offset[1] = 0.0
        cylinder = {"geometry": {"builder": "half_cylinder", "center": [0.0, 0.5 * T, R], "axis": [0, 1, 0],
                                 "radius": R, "height": T + 2 * eps, "keep": [0, 0, -1]},
                    "material": {"model": "linear_elastic", "E": self.e_ratio * E, "nu": NU},
                    "grid": {"h0": self.h_cyl, "offset": cyl_offset}}
        block = {"geometry": {"builder": "box", "min": [-HALF_WIDTH, -eps, -DEPTH], "max": [HALF_WIDTH, T + eps, 0.0]},
                 "material": {"model": "linear_elastic", "E": E, "nu": NU},
                 "grid": {"h0": self.h_block, "offset": block_offset}}
        return {
            "name": "hertz", "kinematics": "small", "steps": 1,
            "bodies": {"cyl": cylinder, "block": block},
            "boundary": [
                {"body": "block", "patches": ["zmin"], "type": "displacement", "components": {"x": 0.0, "z": 0.0}},
                {"body": "block", "patches": ["ymin", "ymax"], "type": "displacement", "components": {"y": 0.0}},
                {"body": "cyl", "patches": ["bottom", "top"], "type": "displacement", "components": {"y": 0.0}},
                {"body": "cyl", "patches": ["flat"], "type": "displacement",
                 "components": {"x": 0.0, "z": -self.delta}},
            ],
            "contact": [{"slave": "block", "master": "cyl", "kappa": self.kappa,
                         "slave_patches": ["zmax"], "master_patches": ["side"]}],
            "solver": dict(self.solver),
        }


@dataclass(frozen=True)
class HertzResult:
    """One run: the load P (N/m), half-width ``a`` (m) and fitted peak ``p0`` (Pa) it
    measures, and the closed form at that load (``a_exact``, ``p0_exact``)."""

    setup: Setup
    status: str
    load: float
    a: float
    p0: float
    p_max: float           # largest single |lambda_N|
    a_exact: float
    p0_exact: float
    summary: dict
    points: dict           # contact VTU point data, plus "x": (n, 3) points

    @property
    def error_a(self) -> float:
        """Against Hertz at the run's own load: the shape of the contact."""
        return self.a / self.a_exact - 1.0

    @property
    def error_p0(self) -> float:
        return self.p0 / self.p0_exact - 1.0

    def error_vs_hertz(self) -> tuple[float, float]:
        """(a, p0) against Hertz at the converged load of the imposed approach: what the
        approach produces, the load's error included."""
        a, p0 = self.setup.hertz(self.setup.reference.load)
        return self.a / a - 1.0, self.p0 / p0 - 1.0

    def error_vs_reference(self) -> tuple[float, float]:
        """(a, p0) against the converged solution of the same problem."""
        ref = self.setup.reference
        return self.a / ref.a - 1.0, self.p0 / ref.p0 - 1.0

    @property
    def profile_distance(self) -> float:
        """Relative L2 distance of the pressure profile from Hertz's ellipse at this load,
        ``sqrt(sum w (p - p_H)^2 / sum w p_H^2)`` over the slave points."""
        x, p, w = self.points["x"][:, 0], -self.points["pressure"], self.points["weight"]
        hertz = self.p0_exact * np.sqrt(np.clip(1.0 - (x / self.a_exact) ** 2, 0.0, None))
        return math.sqrt(np.sum(w * (p - hertz) ** 2) / np.sum(w * hertz**2))


def assert_force_balance(run: HertzResult) -> None:
    """The run converged, pushes the block down, and its supports carry exactly the contact
    force (the cylinder's what the contact passes to the block, the block's the opposite),
    which is the sum of the points' forces."""
    assert run.status == "converged"
    step = run.summary["steps"][-1]
    force = np.asarray(step["contact"]["force"])      # on the slave (block)
    cyl = sum(np.asarray(v) for k, v in step["reactions"].items() if k.startswith("cyl/"))
    block = sum(np.asarray(v) for k, v in step["reactions"].items() if k.startswith("block/"))
    assert np.linalg.norm(cyl - force) <= 1e-8 * np.linalg.norm(force)
    assert np.linalg.norm(block + force) <= 1e-8 * np.linalg.norm(force)
    np.testing.assert_allclose(run.points["force"].sum(axis=0), force, rtol=0, atol=1e-10 * abs(force[2]))
    assert force[2] < 0.0 and abs(force[0]) < 0.03 * abs(force[2])


def fit_ellipse(x: np.ndarray, p: np.ndarray, w: np.ndarray, a_guess: float) -> tuple[float, float]:
    """Weighted least-squares ``(p0, a)`` of ``p ~ p0 sqrt(1 - x^2 / a^2)`` over ``x, p, w`` (n,).

    For a fixed ``a`` the best ``p0`` is linear; the misfit is then scanned over
    ``a in [0.3, 2] a_guess`` (2000 values: the misfit has several local minima where the
    ellipse's edge passes a point, so a local search from a guess is not reproducible) and
    refined by a bounded scalar search around the best value.
    """
    def best(a: float) -> tuple[float, float]:
        phi = np.sqrt(np.clip(1.0 - (x / a) ** 2, 0.0, None))
        p0 = np.sum(w * p * phi) / np.sum(w * phi * phi)
        return float(np.sum(w * (p - p0 * phi) ** 2)), float(p0)
    grid = np.linspace(0.3, 2.0, 2000) * a_guess
    i = int(np.argmin([best(a)[0] for a in grid]))
    step = grid[1] - grid[0]
    a = float(minimize_scalar(lambda a: best(a)[0], bounds=(grid[i] - step, grid[i] + step),
                              method="bounded", options={"xatol": 1e-12 * a_guess}).x)
    return best(a)[1], a


def measure(setup: Setup, summary: dict, points: dict) -> HertzResult:
    """Half-width and peak pressure of the last step's contact points against Hertz."""
    x = points["x"][:, 0]
    p, w = -points["pressure"], points["weight"]
    load = abs(summary["steps"][-1]["contact"]["force"][2]) / setup.thickness
    a_exact, p0_exact = setup.hertz(load)
    pw = p * w
    xc = np.sum(pw * x) / np.sum(pw)
    a = 2.0 * math.sqrt(np.sum(pw * (x - xc) ** 2) / np.sum(pw))
    p0, _ = fit_ellipse(x - xc, p, w, a)
    return HertzResult(setup, summary["status"], load, a, p0, float(p.max()), a_exact, p0_exact, summary, points)


def solve(setup: Setup, level: int, surface: str, out: Path,
          cyl_offset: tuple[float, float, float] | None = None, order: int = 1) -> HertzResult:
    """Run ``setup`` at ``level`` with ``surface`` and the hexahedra of ``order`` into
    ``out`` and measure it."""
    status = run_case(parse_case(setup.case(cyl_offset), out), level, surface, out, order=order)
    summary = json.loads((out / "summary.json").read_text())
    mesh = meshio.read(out / f"contact_{len(summary['steps']):03d}.vtu")
    result = measure(setup, summary, {**mesh.point_data, "x": mesh.points})
    assert result.status == status.status
    return result


SURFACES = ("nurbs_fe", "facets")


def solve_all(setup: Setup, base: Path, levels: tuple[int, ...]) -> dict[tuple[int, str], HertzResult]:
    """Every (level, surface) run of ``setup`` into folders of ``base``."""
    return {(level, surface): solve(setup, level, surface, base / f"{surface}_{level}")
            for level in levels for surface in SURFACES}


#: equal bodies on grids of the same size, kappa = 10 as in the paper's examples, the y faces
#: between grid planes (a / R ~ 0.2, a / h ~ 1 at level 0)
EQUAL = Setup(thickness=0.2, e_ratio=1.0, delta=0.05, kappa=10.0, h_cyl=0.2, h_block=0.2, aligned=False,
              reference=Reference(load=187183.3, a=0.200795, p0=592787.1))

#: a stiff indenter (E x 100) on a coarse grid (h0 0.4 against the block's 0.1; a / h_cyl
#: ~ 0.37 at level 0), kappa = 1, every y face SLIVER beyond a grid plane; Newton to 1e-12 of
#: the first residual (1.4e8 N, the stiff indenter's imposed approach): at 1e-10 the last outer
#: passes stop at 4e-3 N, and the supports' reactions match the contact force to only 5e-8
INDENTER = Setup(thickness=0.4, e_ratio=100.0, delta=0.03, kappa=1.0, h_cyl=0.4, h_block=0.1, aligned=True,
                 reference=Reference(load=199347.95, a=0.148586, p0=853156.8),
                 solver={"newton_tol": 1e-12, "outer_tol": 1e-8, "outer_passes": 40})
