"""The paper's planar example (config/cases/planar.yaml) with contact: the lower block is held
vertically by contact alone (its supports constrain x and y only), so the total contact force
equals the resultant of the lateral tractions t_z = 10e11 (0.01 - z) z as the discretization
integrates them (the dead-load vector of the lower body); on the exact surface (nurbs_fe)
that is 2 * 1e12 * 0.01^3 / 6 * 0.0025 N. Facets integrate the tractions on the marching-cubes
surface, whose chamfered edges change the resultant."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cgfem.case import load_case
from cgfem.run import build_models, run_case

CASE = Path(__file__).resolve().parents[1] / "config" / "cases" / "planar.yaml"
RESULTANT = 2.0 * 1e12 * 0.01 ** 3 / 6.0 * 0.0025


@pytest.mark.parametrize("surface", ["nurbs_fe", "facets"])
@pytest.mark.parametrize("level", [0, 1])
def test_contact_force_balances_the_tractions(tmp_path, surface, level):
    case = load_case(CASE)
    status = run_case(case, level, surface, tmp_path)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert status.status == "converged"
    step = summary["steps"][-1]
    force = np.asarray(step["contact"]["force"])
    lower = build_models(case, level, surface, lambda m: None)[0][0]
    load_z = lower.load[2::3].sum()
    assert abs(force[2] + load_z) <= 1e-8 * RESULTANT
    if surface == "nurbs_fe":
        assert abs(load_z - RESULTANT) <= 1e-9 * RESULTANT
    # frictionless: the force follows the current normals, tilted by the strain (~1e-4)
    assert np.all(np.abs(force[:2]) <= 1e-3 * RESULTANT)
    # the interface stays closed: most slave points active, all compressive
    assert step["contact"]["active_points"] > 0
    # about 4e7 Pa along the interface (the reference solution: 2.8e7 to 4.5e7 Pa); facets
    # peak at their chamfered edges
    assert 1e7 < step["contact"]["max_pressure"] < (2e8 if surface == "nurbs_fe" else 1e9)
    # the residual with every hit on the continuous surface: Newton's own last one unless an
    # active hit lies on a kept element's extension (facets: never counted)
    last = step["pass_residuals"][-1][-1] / step["newton_reference"]
    assert step["contact"]["continuous_residual"] <= case.solver.newton_tol
    if step["contact"]["extended_hits"] == 0:
        assert step["contact"]["continuous_residual"] == pytest.approx(last, rel=1e-3, abs=1e-11)
