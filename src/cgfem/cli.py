"""The ``cgfem`` command line.

``cgfem check CASE.yaml [--json]`` validates a case file, builds every body's exact geometry
and prints, per body, the B-rep volume and the area of each named patch (computed from the
NURBS surfaces alone). Exit codes: 0 success, 2 bad input (one line on stderr naming the
offending field, no traceback).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass

from cgfem import __version__
from cgfem.errors import InputError

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2


@dataclass(frozen=True)
class BodyReport:
    """What ``cgfem check`` reports of one body (SI units)."""

    name: str
    patch_areas: dict[str, float]
    brep_volume: float

    @property
    def brep_area(self) -> float:
        return sum(self.patch_areas.values())

    def as_dict(self) -> dict:
        return {"brep_volume": self.brep_volume, "brep_area": self.brep_area,
                "patches": {name: {"area": area} for name, area in self.patch_areas.items()}}


def check_case(path: str) -> list[BodyReport]:
    """Validate the case at ``path`` and measure its bodies; raises :class:`InputError`."""
    from cgfem.case import check_patch_names, load_case
    from cgfem.geometry.builders import build_solid
    from cgfem.geometry.measure import areas_by_name, volume

    case = load_case(path)
    solids = {}
    for body in case.bodies:
        try:
            solids[body.name] = build_solid(body.geometry)
        except InputError as err:
            raise err.within(f"bodies.{body.name}.geometry") from None
    check_patch_names(case, {name: solid.patch_names for name, solid in solids.items()})
    return [BodyReport(name, areas_by_name(solid), volume(solid)) for name, solid in solids.items()]


def _format_table(reports: Sequence[BodyReport]) -> str:
    lines = []
    for rep in reports:
        lines.append(f"body {rep.name}: B-rep volume {rep.brep_volume:.12g} m^3, "
                     f"area {rep.brep_area:.12g} m^2")
        width = max(len(n) for n in rep.patch_areas)
        for name, area in rep.patch_areas.items():
            lines.append(f"  patch {name:<{width}}  area {area:.12g} m^2")
    return "\n".join(lines)


def _cmd_check(args: argparse.Namespace) -> int:
    reports = check_case(args.case)
    if args.json:
        print(json.dumps({"bodies": {r.name: r.as_dict() for r in reports}}, indent=2))
    else:
        print(_format_table(reports))
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cgfem", description="Contact mechanics in the Cartesian "
                                     "grid finite element method with exact NURBS geometry.")
    parser.add_argument("--version", action="version", version=f"cgfem {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    check = sub.add_parser("check", help="validate a case file and print geometry statistics")
    check.add_argument("case", help="case file (YAML)")
    check.add_argument("--json", action="store_true", help="print JSON instead of a table")
    check.set_defaults(func=_cmd_check)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cgfem`` console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except InputError as err:
        print(f"cgfem: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # output piped into a pager or `head` that stopped reading
        sys.stdout = None
        return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
