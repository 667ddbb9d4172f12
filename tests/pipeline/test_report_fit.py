"""The fitted NURBS of a nurbs_fit run in the result files, and the paper's Fig. 10 curve
drawn from them (planar example, level 0)."""

from __future__ import annotations


import numpy as np
import pytest

from cgfem.case.load import load_case
from cgfem.report.curves import fig10_surface_profile, fitted_profile, surface_profile
from cgfem.report.runs import Run
from cgfem.run import run_case

from tests.support.paths import REPO

#: every test here solves a whole problem
pytestmark = pytest.mark.slow


LINE = {"x": 0.00125, "z": 0.01}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("planar_fit") / "L0_nurbs_fit"
    status = run_case(load_case(REPO / "config" / "cases" / "planar.yaml"), 0, "nurbs_fit", out)
    assert status.status == "converged"
    return Run.load(out / "summary.json")


def test_fit_files_and_summary(run):
    fits = run.steps[-1]["contact"]["fits"]
    assert set(fits) == {"lower/zmax", "upper/zmin"}
    assert all(0.0 < f["relative_l2_error"] < 0.01 and f["control_points"] > 9 for f in fits.values())
    surfaces = run.fitted_surfaces()
    assert set(surfaces) == set(fits)
    rest, moved = surfaces["lower/zmax"]
    assert np.array_equal(rest.knots_u, moved.knots_u) and np.array_equal(rest.weights, moved.weights)
    # the planar contact force is the lateral tractions' resultant (833.33 N)
    assert run.contact_force()[2] == pytest.approx(-2500.0 / 3.0, rel=1e-8)


def test_fitted_profile_follows_the_fe_displacement(run):
    """Along the line, the fitted u_z follows the FE u_z at the boundary points: within 1 %
    of its largest value away from the ends, within 6 % at the ends, where the FE field
    rises sharply towards the upper block's corners and a fit with spans of h smooths it
    (4.7 % measured at level 0)."""
    rest, moved = run.fitted_surfaces()["lower/zmax"]
    s, u = fitted_profile(rest, moved, LINE, "y", "z")
    assert s.size > 100 and s.min() == pytest.approx(0.0, abs=1e-12) and s.max() == pytest.approx(0.01)
    fe_s, fe_u = surface_profile(run, "lower", LINE, "y", "z", band=0.25 * run.body("lower")["h"])
    inside = (fe_s > s.min()) & (fe_s < s.max())
    assert inside.sum() > 10
    error = np.abs(np.interp(fe_s[inside], s, u) - fe_u[inside]) / np.abs(fe_u).max()
    middle = (fe_s[inside] > 0.1 * s.max()) & (fe_s[inside] < 0.9 * s.max())
    assert error[middle].max() < 0.01 and error.max() < 0.06
    fig = fig10_surface_profile([run.folder / "summary.json"], "lower", LINE)
    labels = [line.get_label() for line in fig.axes[0].lines]
    assert labels == ["nurbs_fit L0", "nurbs_fit L0: fitted NURBS (zmax)"]
