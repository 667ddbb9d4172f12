"""`cgfem warmup`: both small contact problems converge with every surface definition (a
broken solver must not pass for a warm cache), and the command reports each run and success."""

from __future__ import annotations

import re

from cgfem.cli import main
from cgfem.warmup import SURFACE_DEFINITIONS, _blocks, _links


def test_warmup_solves_both_problems_with_every_definition(capsys):
    assert main(["warmup"]) == 0
    err = capsys.readouterr().err
    runs = re.findall(r"(warmup_\w+) with (\w+): (\w+) \(", err)
    assert runs == [(name, surface, "converged") for name in ("warmup_links", "warmup_blocks")
                    for surface in SURFACE_DEFINITIONS]
    assert "numba kernels compiled and cached" in err
    # one problem per kinematics, each with contact
    assert {_links()["kinematics"], _blocks()["kinematics"]} == {"finite", "small"}
    assert _links()["contact"] and _blocks()["contact"]
