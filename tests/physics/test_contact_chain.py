"""The paper's chain of two steel links (config/cases/chain2_steel.yaml), its first load step
(the pulled caps move 1 mm) at level 0, with both surface definitions: the step converges,
the contact force balances the reactions of both links exactly, and Newton converges
quadratically at the end of its first solve, with trilinear and with triquadratic hexahedra (the order of Newton's map along the directions
of its last iterates, as in ``test_newton_order.py``: with the onset limit nurbs_fe's
residuals end 2.8e-3, 2.1e-5, 7.1e-8, 8.2e-15 of the first, which read 1.16 from the last
three above 1e-11)."""

from __future__ import annotations

import json

import numpy as np
import pytest


from cgfem.case import parse_case, parse_yaml
from cgfem.definitions import NAMES
from cgfem.run import run_case
from tests.support.newton import record_errors
from tests.support.paths import CASES

#: every test here solves a whole problem
pytestmark = pytest.mark.slow


CASE = CASES / "chain2_steel.yaml"


@pytest.mark.parametrize("surface, order", [("nurbs_fe", 1), ("facets", 1),
                                            *(pytest.param(s, 2, marks=pytest.mark.long) for s in NAMES)])
def test_first_step_of_the_steel_chain(tmp_path, monkeypatch, surface, order):
    solves = record_errors(monkeypatch)
    data = parse_yaml(CASE.read_text())
    data["steps"] = 1
    pulled = data["boundary"][1]
    assert pulled["body"] == "link_b" and pulled["components"]["y"] == 0.005
    pulled["components"]["y"] = 0.001
    status = run_case(parse_case(data, CASE.parent), 0, surface, tmp_path, order=order)
    assert status.status == "converged"
    step = json.loads((tmp_path / "summary.json").read_text())["steps"][-1]
    pulled_r = np.asarray(step["reactions"]["link_b/cap_a+cap_b"])
    clamped_r = np.asarray(step["reactions"]["link_a/cap_a+cap_b"])
    force = np.asarray(step["contact"]["force"])            # master (link_a) on slave (link_b)
    scale = np.linalg.norm(force)
    assert pulled_r[1] > 0.0 > clamped_r[1]                  # pulled along +y, held at y = 0
    assert np.linalg.norm(pulled_r + force) <= 1e-8 * scale  # link_b: support + contact = 0
    assert np.linalg.norm(clamped_r - force) <= 1e-8 * scale  # link_a carries the reverse
    # the first Newton solve of the step ends quadratically (the later passes start from
    # modified Newton and are linear by design)
    first = step["pass_residuals"][0]
    assert len(first) <= 12
    assert solves[0]["residuals"] == first
    assert solves[0]["order"] >= 1.8 and solves[0]["constant"] <= 100.0, solves[0]
