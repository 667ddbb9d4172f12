"""`cgfem warmup`: both small contact problems converge with every surface definition and
carry the loads they must (a broken solver must not pass for a warm cache), and the command
reports each run and success."""

from __future__ import annotations

import re

import pytest

from cgfem.cli import main
from cgfem import warmup
from cgfem.warmup import SURFACE_DEFINITIONS

#: every test here solves a whole problem
pytestmark = pytest.mark.slow

#: the pressure on the lower box's bottom face (Pa) over its unit area: the contact force
#: that holds the box along z
PRESSURE_FORCE = 1.0e6


def test_every_warmup_run_converges_and_carries_its_load(monkeypatch, capsys):
    done: list[warmup.WarmupRun] = []
    real = warmup.warm_up
    monkeypatch.setattr(warmup, "warm_up", lambda log: done.extend(real(log)) or done)
    assert main(["warmup"]) == 0
    err = capsys.readouterr().err
    logged = re.findall(r"(warmup_\w+) with (\w+): (\w+) \(", err)
    assert logged == [(name, surface, "converged") for name in ("warmup_links", "warmup_blocks")
                      for surface in SURFACE_DEFINITIONS]
    assert "numba kernels compiled and cached" in err
    runs = {(r.problem, r.surface): r for r in done}
    for surface in SURFACE_DEFINITIONS:
        # the pulled link is held back by the fixed one: the force on the slave points to -y
        assert runs["warmup_links", surface].contact_force[1] < 0.0
        # the lower box, held along z by contact alone, passes its whole load to the upper
        # one, whose support takes it: the contact force equals that reaction to round-off;
        # and it is the exact load on the exact boundary (facets integrate the traction over
        # the tessellated face, whose chamfer triangles at the box's edges add 5.3 % area)
        blocks = runs["warmup_blocks", surface]
        fz = blocks.contact_force[2]
        assert fz == pytest.approx(blocks.reactions["upper/zmax"][2], rel=1e-8)
        if surface != "facets":
            assert fz == pytest.approx(-PRESSURE_FORCE, rel=1e-8)


def test_a_failed_warmup_run_exits_1_with_one_line(monkeypatch, capsys):
    def broken(log):
        raise RuntimeError("warm-up run warmup_links with facets ended failed: no convergence")
    monkeypatch.setattr(warmup, "warm_up", broken)
    assert main(["warmup"]) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == ["cgfem: error: warm-up run warmup_links with facets ended failed: no convergence"]
