"""`cgfem warmup`: both small contact problems converge with every surface definition (a
broken solver must not pass for a warm cache), and the command reports success."""

from __future__ import annotations

from cgfem.cli import main
from cgfem.warmup import SURFACE_DEFINITIONS, _blocks, _links, warm_up


def test_warm_up_solves_both_problems_with_every_definition():
    done = warm_up()
    assert [(name, surface) for name, surface, _, _ in done] == [
        (name, surface) for name in ("warmup_links", "warmup_blocks") for surface in SURFACE_DEFINITIONS]
    assert all(status == "converged" for _, _, status, _ in done)
    # one problem per kinematics, each with contact
    assert {_links()["kinematics"], _blocks()["kinematics"]} == {"finite", "small"}


def test_warmup_command_exits_zero(capsys):
    assert main(["warmup"]) == 0
    assert "numba kernels compiled and cached" in capsys.readouterr().err
