"""Curved contact against Hertz's closed form, equal bodies (:data:`hertz_setup.EQUAL`): a half
cylinder on a block of the same material, both on grids of the same size (h0 = 0.2, a / h ~ 1
at level 0), kappa = 10 as in the paper's examples, the slab's y faces between grid planes.
The setup, the estimators and the closed form are described in ``tests/hertz_setup.py``;
``tests/physics/test_contact_hertz_indenter.py`` is the setup in which the contact surface
definitions are compared on the half-width and the peak pressure.

Here the discretization error of the bulk (the coarse trilinear cylinder is too stiff, which
narrows the contact) is of the same order as the chords' error of the faceted master, and the
two partly cancel in the integral measures taken at a run's own load (half-width, fitted
peak): facets' are the closer ones at levels 0 and 1 (strict xfails below). What separates
the definitions in this setup is the pressure profile: its L2 distance from Hertz's ellipse
and its largest value. nurbs_fe's load at the imposed approach converges to the reference's.
"""

from __future__ import annotations

import pytest

from tests.support.hertz_setup import EQUAL, R, SURFACES, HertzResult, assert_force_balance, solve_all

#: every test here solves a whole problem
pytestmark = pytest.mark.slow


LEVELS = (0, 1)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[tuple[int, str], HertzResult]:
    return solve_all(EQUAL, tmp_path_factory.mktemp("hertz"), LEVELS)


@pytest.mark.parametrize("surface", SURFACES)
@pytest.mark.parametrize("level", LEVELS)
def test_force_balance(runs, level, surface):
    run = runs[(level, surface)]
    assert_force_balance(run)
    # the load is about what Hertz needs for a / R ~ 0.2
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
    errors = [runs[(level, "nurbs_fe")].load / EQUAL.reference.load - 1.0 for level in LEVELS]
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
    "measured at level 0 (a / h ~ 1), at each run's own load: fitted p0 nurbs_fe +59.1 %, facets -17.2 %"))


@pytest.mark.parametrize("level", [pytest.param(0, marks=_P0_LEVEL_0), 1])
def test_nurbs_fe_peak_pressure_closer_than_facets(runs, level):
    # measured fitted p0: level 1 nurbs_fe +21.2 %, facets +45.0 %; level 2 +9.4 %, +13.0 %
    nurbs, facets = runs[(level, "nurbs_fe")], runs[(level, "facets")]
    assert abs(nurbs.error_p0) < abs(facets.error_p0)


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "measured at each run's own load: facets' half-width is closer to Hertz than nurbs_fe's (level 0: "
    "facets +3.8 %, nurbs_fe -35.5 %; level 1: -9.1 %, -16.4 %; level 2: -2.8 %, -6.8 %); the setup "
    "that compares the definitions on it is test_contact_hertz_indenter's"))
@pytest.mark.parametrize("level", LEVELS)
def test_nurbs_fe_half_width_closer_than_facets(runs, level):
    nurbs, facets = runs[(level, "nurbs_fe")], runs[(level, "facets")]
    assert abs(nurbs.error_a) < abs(facets.error_a)
