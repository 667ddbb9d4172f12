"""How much of a chain's reaction error is the unresolved contact zone?

The body-fitted reference of a chain case (``config/reference/{case}.json``,
:mod:`cgfem.reference.tori`) meshes the touch points finer (``h_contact = h / 4``) than the
rest. This benchmark solves the same body-fitted problem (curved tetrahedra of order 2,
penalty factor 1e4) on meshes *without* that refinement, of the element sizes of the
case's Cartesian grids at the given levels (``h0 / 2^level``), and prints per level: the
element size, the contact zone's extent in the reference (its largest, over the pairs) in
units of that size, the unknowns of the quarter model, the pulled reaction and its error
against the reference. A body-fitted order-2 solution that is still far off at a grid's
element size says that the error of the cut-cell runs at that level is the contact zone's
resolution, which no element order removes (``docs/performance.md``, "Time to 1 % on
chain3").

    python3 -m benchmarks.bench_contact_zone [--case config/cases/chain3.yaml] [--levels 0 1 2]

One thread (set ``OMP_NUM_THREADS`` before); level 2 of chain3 takes about 1.5 min.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "config" / "cases" / "chain3.yaml"
#: the reference's penalty factor (eps = factor E_slave / r_slave)
PENALTY_FACTOR = 1e4


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench_contact_zone", description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, default=CASE, help="a chain case with a reference file")
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2], help="grid levels")
    args = parser.parse_args(argv)

    from benchmarks.bench_order import reference_of
    from cgfem.case.load import load_case
    from cgfem.errors import InputError
    from cgfem.reference.tori_geometry import R_CONTACT, MeshSpec
    from cgfem.reference.tori_solve import solve

    try:
        case = load_case(args.case)
    except InputError as error:
        print(f"bench_contact_zone: --case: {error}", file=sys.stderr)
        return 2
    ref_path = ROOT / "config" / "reference" / f"{case.name}.json"
    reference = reference_of(case.name)
    if reference is None or any(level < 0 for level in args.levels):
        print(f"bench_contact_zone: {'--levels: must be >= 0' if reference else f'no reference {ref_path}'}",
              file=sys.stderr)
        return 2
    pulled, value = reference
    finest = json.loads(ref_path.read_text())["runs"][-1]
    extent = max(v for step in finest["steps"] for v in step["contact_extent"].values())
    h0 = min(body.grid.h0 for body in case.bodies)
    print(f"{case.name}: reference {value:.8g} N ({pulled}), contact zone extent {1e3 * extent:.3f} mm")
    print(f"{'level':>5} {'h mm':>7} {'extent/h':>8} {'unknowns':>9} {'reaction y N':>14} {'error %':>9} {'s':>7}")
    for level in args.levels:
        h = h0 / 2.0**level
        t0 = time.perf_counter()
        solution = solve(case, MeshSpec(h, h, R_CONTACT, 2), PENALTY_FACTOR)
        seconds = time.perf_counter() - t0
        if not solution.converged:
            print(f"{level:>5} {1e3 * h:>7.3f} {extent / h:>8.2f}  not converged: {solution.message}")
            continue
        y = float(solution.steps[-1].reactions[pulled][1])
        print(f"{level:>5} {1e3 * h:>7.3f} {extent / h:>8.2f} {solution.mesh['dofs']:>9} {y:>14.8g} "
              f"{100 * (y / value - 1.0):>+9.3f} {seconds:>7.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
