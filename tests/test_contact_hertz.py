"""Curved contact against Hertz's closed form: plane-strain line contact of a half cylinder
(radius R, axis along y) pressed onto an elastic block, both linear elastic, small strain.

Plane strain by symmetry conditions: u_y = 0 on the block's ``ymin``/``ymax`` and on the half
cylinder's end half-discs ``bottom``/``top`` (thickness T along y). The block's ``zmin`` is
held in x and z; the cylinder's ``flat`` face (through its axis, at z = R) is held in x and
pushed down by DELTA in z (displacement control: a traction on ``flat`` leaves the cylinder
held in z by contact alone while other components are held, which the solver does not
stabilise -- it fails at the first load factor). The load per unit length P is therefore
measured, P = |F_z| / T with F the contact force, and the closed form is evaluated at that P.

Closed form (two equal materials): 1/E* = 2 (1 - nu^2) / E, half-width
a = sqrt(4 P R / (pi E*)), peak pressure p0 = 2 P / (pi a), p(x) = p0 sqrt(1 - x^2 / a^2).
The block (``zmax``) is the slave: its flat face carries evenly spaced points, rays along its
exact normal, and the curved master surface enters the gap through the master definition.

Measured from ``contact_NNN.vtu``: the half-width from the second moment of the pressure,
``a = 2 sqrt(sum p w (x - xc)^2 / sum p w)`` (Hertz: the moment is a^2 / 4), and the peak
pressure from a weighted least-squares fit of the ellipse ``p0 sqrt(1 - (x - xc)^2 / a^2)``
over all slave points (:func:`fit_ellipse`) (the largest single lambda_N scatters by tens of per cent between
neighbouring points, 3x p0 with facets; ``benchmarks/hertz_table.py`` prints it too).

The bodies are finite (about 5 a deep) and the gap is measured in the deformed configuration,
so Hertz's half-space is not this problem's limit. ``benchmarks/hertz_reference.py`` (an
independent plane-strain solution with quadratic elements, the arc exact and the contact
exact) gives it: ``P_REFERENCE`` at the imposed approach, the second-moment half-width at
0.964 a_H and p_max at 1.039 p0_H (Richardson over levels with 7e3 to 4.6e5 unknowns).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import meshio
import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from cgfem.case import parse_case
from cgfem.run import run_case

R, T = 1.0, 0.2            # cylinder radius and thickness along y, m
E, NU = 1.0e7, 0.3         # both bodies, Pa
E_STAR = E / (2.0 * (1.0 - NU**2))
DELTA = 0.05               # imposed approach of the cylinder's flat face, m (a / R ~ 0.2)
HALF_WIDTH, DEPTH = 1.0, 1.0   # block: x in [-1, 1], z in [-1, 0] (about 5 a deep, 10 a wide)
H0 = 0.2                   # level L: h = H0 / 2**L; a / h ~ 1 at level 0
P_REFERENCE = 187183.3      # N/m at DELTA: benchmarks/hertz_reference.py, converged to 1e-7


def hertz_case(cyl_offset: tuple[float, float, float] = (0.37, 0.21, 0.23)) -> dict:
    """The case file (as a dict) of the half cylinder on the block; ``cyl_offset``: the
    cylinder grid's offset (in element sizes)."""
    material = {"model": "linear_elastic", "E": E, "nu": NU}
    cylinder = {"geometry": {"builder": "half_cylinder", "center": [0.0, 0.5 * T, R], "axis": [0, 1, 0],
                             "radius": R, "height": T, "keep": [0, 0, -1]},
                "material": material, "grid": {"h0": H0, "offset": list(cyl_offset)}}
    block = {"geometry": {"builder": "box", "min": [-HALF_WIDTH, 0.0, -DEPTH], "max": [HALF_WIDTH, T, 0.0]},
             "material": material, "grid": {"h0": H0, "offset": [0.13, 0.29, 0.41]}}
    return {
        "name": "hertz", "kinematics": "small", "steps": 1,
        "bodies": {"cyl": cylinder, "block": block},
        "boundary": [
            {"body": "block", "patches": ["zmin"], "type": "displacement", "components": {"x": 0.0, "z": 0.0}},
            {"body": "block", "patches": ["ymin", "ymax"], "type": "displacement", "components": {"y": 0.0}},
            {"body": "cyl", "patches": ["bottom", "top"], "type": "displacement", "components": {"y": 0.0}},
            {"body": "cyl", "patches": ["flat"], "type": "displacement", "components": {"x": 0.0, "z": -DELTA}},
        ],
        "contact": [{"slave": "block", "master": "cyl", "kappa": 10.0,
                     "slave_patches": ["zmax"], "master_patches": ["side"]}],
        "solver": {"newton_tol": 1e-10, "outer_tol": 1e-8, "outer_passes": 40},
    }


@dataclass(frozen=True)
class HertzResult:
    """One run: measured and closed-form half-width ``a`` (m) and peak pressure ``p0`` (Pa)."""

    status: str
    load: float            # P, N/m
    a: float
    p0: float
    p_max: float           # largest single |lambda_N|
    a_exact: float
    p0_exact: float
    summary: dict
    points: dict           # contact VTU point data, plus "x": (n, 3) points

    @property
    def error_a(self) -> float:
        return self.a / self.a_exact - 1.0

    @property
    def error_p0(self) -> float:
        return self.p0 / self.p0_exact - 1.0

    @property
    def profile_distance(self) -> float:
        """Relative L2 distance of the pressure profile from Hertz's ellipse at this load,
        ``sqrt(sum w (p - p_H)^2 / sum w p_H^2)`` over the slave points."""
        x, p, w = self.points["x"][:, 0], -self.points["pressure"], self.points["weight"]
        hertz = self.p0_exact * np.sqrt(np.clip(1.0 - (x / self.a_exact) ** 2, 0.0, None))
        return math.sqrt(np.sum(w * (p - hertz) ** 2) / np.sum(w * hertz**2))


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


def measure(summary: dict, points: dict) -> HertzResult:
    """Half-width and peak pressure of the last step's contact points against Hertz."""
    x = points["x"][:, 0]
    p, w = -points["pressure"], points["weight"]
    load = abs(summary["steps"][-1]["contact"]["force"][2]) / T
    a_exact = math.sqrt(4.0 * load * R / (math.pi * E_STAR))
    p0_exact = 2.0 * load / (math.pi * a_exact)
    pw = p * w
    xc = np.sum(pw * x) / np.sum(pw)
    a = 2.0 * math.sqrt(np.sum(pw * (x - xc) ** 2) / np.sum(pw))

    p0, _ = fit_ellipse(x - xc, p, w, a)
    return HertzResult(summary["status"], load, a, p0, float(p.max()), a_exact, p0_exact, summary, points)


def solve(level: int, surface: str, out: Path, cyl_offset: tuple[float, float, float] | None = None
          ) -> HertzResult:
    """Run the Hertz case at ``level`` with ``surface`` into ``out`` and measure it
    (``cyl_offset``: another offset of the cylinder's grid)."""
    case = hertz_case() if cyl_offset is None else hertz_case(cyl_offset)
    status = run_case(parse_case(case, out), level, surface, out)
    summary = json.loads((out / "summary.json").read_text())
    mesh = meshio.read(out / f"contact_{len(summary['steps']):03d}.vtu")
    result = measure(summary, {**mesh.point_data, "x": mesh.points})
    assert result.status == status.status
    return result


LEVELS = (0, 1)
SURFACES = ("nurbs_fe", "facets")


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[tuple[int, str], HertzResult]:
    base = tmp_path_factory.mktemp("hertz")
    return {(level, surface): solve(level, surface, base / f"{surface}_{level}")
            for level in LEVELS for surface in SURFACES}


@pytest.mark.parametrize("surface", SURFACES)
@pytest.mark.parametrize("level", LEVELS)
def test_force_balance(runs, level, surface):
    run = runs[(level, surface)]
    assert run.status == "converged"
    step = run.summary["steps"][-1]
    force = np.asarray(step["contact"]["force"])      # on the slave (block)
    cyl = sum(np.asarray(v) for k, v in step["reactions"].items() if k.startswith("cyl/"))
    block = sum(np.asarray(v) for k, v in step["reactions"].items() if k.startswith("block/"))
    # the cylinder's supports carry exactly what the contact passes to the block, the block's the opposite
    assert np.linalg.norm(cyl - force) <= 1e-8 * np.linalg.norm(force)
    assert np.linalg.norm(block + force) <= 1e-8 * np.linalg.norm(force)
    np.testing.assert_allclose(run.points["force"].sum(axis=0), force, rtol=0, atol=1e-10 * abs(force[2]))
    # pressing: the block is pushed down, the load is about what Hertz needs for a / R ~ 0.2
    assert force[2] < 0.0 and abs(force[0]) < 0.03 * abs(force[2])
    assert 0.15 < run.a_exact / R < 0.25


def test_nurbs_fe_approaches_hertz_as_the_level_rises(runs):
    coarse, fine = runs[(0, "nurbs_fe")], runs[(1, "nurbs_fe")]
    # measured (h0 = 0.2): a -35.5 % -> -16.4 %, p0 +59 % -> +21 % (level 2: -6.8 %, +9.4 %)
    assert abs(fine.error_a) < 0.6 * abs(coarse.error_a)
    assert abs(fine.error_p0) < 0.5 * abs(coarse.error_p0)
    assert abs(fine.error_a) < 0.2 and abs(fine.error_p0) < 0.25


def test_nurbs_fe_load_converges_to_the_reference(runs):
    """The load the imposed approach needs, against the converged plane-strain solution
    (measured: +19.5 % at level 0, +4.1 % at level 1, +0.76 % at level 2)."""
    errors = [runs[(level, "nurbs_fe")].load / P_REFERENCE - 1.0 for level in LEVELS]
    assert 0.0 < errors[1] < 0.05 and errors[1] < 0.3 * errors[0]


@pytest.mark.parametrize("level", LEVELS)
def test_nurbs_fe_pressure_profile_closer_than_facets(runs, level):
    """The whole profile, not one of its measures: relative L2 distance from Hertz's ellipse
    (measured: nurbs_fe 0.72 and 0.39 at levels 0 and 1, facets 1.94 and 1.35)."""
    nurbs, facets = runs[(level, "nurbs_fe")], runs[(level, "facets")]
    assert nurbs.profile_distance < 0.5 * facets.profile_distance


@pytest.mark.parametrize("level", LEVELS)
def test_nurbs_fe_largest_pressure_closer_than_facets(runs, level):
    # measured max |lambda_N| / p0: level 0 nurbs_fe 2.96, facets 7.25; level 1 1.55, 3.28
    nurbs, facets = runs[(level, "nurbs_fe")], runs[(level, "facets")]
    assert abs(nurbs.p_max / nurbs.p0_exact - 1.0) < abs(facets.p_max / facets.p0_exact - 1.0)


_P0_LEVEL_0 = pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "measured at level 0 (a / h ~ 1): fitted p0 nurbs_fe +59.1 %, facets -17.2 %"))


@pytest.mark.parametrize("level", [pytest.param(0, marks=_P0_LEVEL_0), 1])
def test_nurbs_fe_peak_pressure_closer_than_facets(runs, level):
    # measured fitted p0: level 1 nurbs_fe +21.2 %, facets +45.0 %; level 2 +9.4 %, +13.0 %
    nurbs, facets = runs[(level, "nurbs_fe")], runs[(level, "facets")]
    assert abs(nurbs.error_p0) < abs(facets.error_p0)


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "measured: facets' half-width is closer to Hertz than nurbs_fe's (level 0: facets +3.8 %, "
    "nurbs_fe -35.5 %; level 1: -9.1 %, -16.4 %; level 2: -2.8 %, -6.8 %); see benchmarks/hertz_table.py"))
@pytest.mark.parametrize("level", LEVELS)
def test_nurbs_fe_half_width_closer_than_facets(runs, level):
    nurbs, facets = runs[(level, "nurbs_fe")], runs[(level, "facets")]
    assert abs(nurbs.error_a) < abs(facets.error_a)
