"""The paper's chain of two steel links (config/cases/chain2_steel.yaml), its first load step
(the pulled caps move 1 mm) at level 0, with both surface definitions: the step converges,
the contact force balances the reactions of both links exactly, and Newton converges
quadratically at the end of its solves."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest


from cgfem.case import parse_case, parse_yaml
from cgfem.run import run_case
from cgfem.solve.newton import observed_order

CASE = Path(__file__).resolve().parents[1] / "config" / "cases" / "chain2_steel.yaml"


@pytest.mark.parametrize("surface", ["nurbs_fe", "facets"])
def test_first_step_of_the_steel_chain(tmp_path, surface):
    data = parse_yaml(CASE.read_text())
    data["steps"] = 1
    pulled = data["boundary"][1]
    assert pulled["body"] == "link_b" and pulled["components"]["y"] == 0.005
    pulled["components"]["y"] = 0.001
    status = run_case(parse_case(data, CASE.parent), 0, surface, tmp_path)
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
    # (residuals below 1e-11 of the first are round-off of the assembled forces: left out)
    first = step["pass_residuals"][0]
    assert len(first) <= 12
    assert observed_order(first, floor=1e-11) >= 1.8
