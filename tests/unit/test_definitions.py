"""The registry of contact surface definitions (cgfem.definitions) is the one place that says
what each definition needs: the CLI, the embedding and the contact builder follow it."""

from __future__ import annotations

import pytest

from cgfem.cli import build_parser
from cgfem.definitions import DEFINITIONS, NAMES, NURBS_DEFINITIONS, surface_definition
from cgfem.embedding.quadrature import SURFACE_DEFINITIONS


def test_names_and_properties():
    assert NAMES == ("facets", "nurbs_fe", "nurbs_fit")
    assert NURBS_DEFINITIONS == ("nurbs_fe", "nurbs_fit")
    assert [DEFINITIONS[n].quadrature for n in NAMES] == ["facets", "nurbs", "nurbs"]
    assert [n for n in NAMES if DEFINITIONS[n].fitted] == ["nurbs_fit"]
    # every definition's boundary quadrature is one the embedding builds
    assert {d.quadrature for d in DEFINITIONS.values()} == set(SURFACE_DEFINITIONS)


def test_unknown_name_lists_the_known_ones():
    with pytest.raises(ValueError, match="unknown surface definition 'nurbs'.*facets, nurbs_fe, nurbs_fit"):
        surface_definition("nurbs")


def test_cli_offers_exactly_the_registry():
    parser = build_parser()
    run = next(a for a in parser._subparsers._group_actions[0].choices["run"]._actions if a.dest == "surface")
    assert sorted(run.choices) == sorted(NAMES)
