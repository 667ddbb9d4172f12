"""Body-fitted references of the chain examples (chain2_steel, chain2_rubber, chain3).

An independent solution of each chain case with NGSolve (curved tetrahedra of order ``p``
fitted to the exact tori, penalty contact; :mod:`cgfem.reference.tori_solve`), with its
uncertainty:

- **mesh**: the case is solved on every requested mesh level
  (:func:`cgfem.reference.tori_geometry.mesh_level`); the change of each level's reactions
  to the finest level's, ``max over steps and supports |R_L - R_finest| / |R_finest|``
  (y components), is reported; the mesh uncertainty is the larger of the finest-but-one's
  change and the error of the finest estimated from the last three levels
  (:func:`extrapolated_error`);
- **penalty**: on the finest level every load step is solved again with the penalty
  times ``PENALTY_STEP`` (10), from its converged state (a continuation in the penalty);
  the change of the reactions is the penalty uncertainty.

The meshes are refined to ``h_contact`` within ``--r-contact`` of the touch points
(default ``R_CONTACT``, 4 mm); every step records the extent of its contact zone (the
largest reference distance from the touch point of a tube vertex carrying contact,
:meth:`cgfem.reference.tori_solve.ToriProblem.contact_forces`), and the study reports the
finest run's largest, which must lie within ``r_contact`` plus one contact element
(``h_contact``: the vertices carrying contact reach one element beyond the zone) for the
refinement to cover the zone (the rubber links are pulled far into each other: chain2_rubber's zone reaches about
6 mm, so its study takes ``--r-contact 0.007``).

The reference is **accepted** when both are below ``ACCEPT`` (0.3 %). The values of the
reference are the finest level's at the nominal penalty, per load step: the reactions on
the supports (``body/patch+patch`` as in cgFEM's summaries, the force of the support on the
body, N), the contact force of every pair (force of the master on the slave, N), and the
peak von Mises stress of every body (Pa) with its position.

The JSON (:func:`study`) records the meshes (sizes, elements, dofs), order, penalties,
wall times, every run's per-step values, the versions of NGSolve and netgen, the SHA-256
of the case file and the **script version**: a hash of the code of the reference modules,
their sources without docstrings and comments (:func:`script_version`). The references are
committed as gold files; ``--from-gold`` checks that a gold file was made by the current
script version for the current case file and copies it (exit 1 with the regenerating
command if not).

Command line::

    python3 -m cgfem.reference.tori --case chain2_steel --out results/reference/chain2_steel.json \\
        [--meshes 1,2,3,4] [--order 2] [--penalty-factor 10000] [--r-contact 0.004] [--threads 1]
    python3 -m cgfem.reference.tori --case chain2_steel --from-gold config/reference/chain2_steel.json \\
        --out results/reference/chain2_steel.json

``--case`` takes a case file or the name of one in ``config/cases/``. Bad input: a one-line
message and exit code 2.
"""

from __future__ import annotations

import argparse
import ast
import hashlib
import io
import json
import platform
import shlex
import sys
import time
import tokenize
from pathlib import Path
from typing import Callable

import numpy as np

from cgfem.atomic import write_text_atomic
from cgfem.case import load_case
from cgfem.errors import InputError
from cgfem.reference.tori_geometry import R_CONTACT, check_symmetry, mesh_level

__all__ = ["ACCEPT", "PENALTY_FACTOR", "PENALTY_STEP", "SCHEMA", "StaleGold", "changes",
           "check_gold", "main", "script_version", "study"]

SCHEMA = "cgfem-reference-tori/1"
#: nominal penalty eps = PENALTY_FACTOR E_slave / r_slave and the factor of its check
PENALTY_FACTOR, PENALTY_STEP = 1.0e4, 10.0
#: acceptance: mesh and penalty changes of the reactions below this (relative)
ACCEPT = 0.003
#: the modules whose sources make the script version
SOURCES = ("tori.py", "tori_geometry.py", "tori_solve.py")
DEFAULT_MESHES = (1, 2, 3, 4)


def code_of(source: str) -> str:
    """The code of a Python module's ``source`` without its docstrings, comments, blank
    lines and trailing blanks: what the script version hashes, so that editing the
    documentation does not make a gold file stale."""
    tree = ast.parse(source)
    lines = source.splitlines()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(body, list) and body and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)):
            doc = body[0]
            for i in range(doc.lineno - 1, doc.end_lineno):
                lines[i] = ""
    kept = []
    tokens = tokenize.generate_tokens(io.StringIO("\n".join(lines) + "\n").readline)
    comments = {(t.start[0], t.start[1]) for t in tokens if t.type == tokenize.COMMENT}
    for number, line in enumerate(lines, start=1):
        cut = min((col for row, col in comments if row == number), default=len(line))
        line = line[:cut].rstrip()
        if line.strip():
            kept.append(line)
    return "\n".join(kept) + "\n"


def script_version() -> str:
    """First 16 hex digits of the SHA-256 of the code (:func:`code_of`) of the reference
    modules (``SOURCES``, in that order): what a gold file must have been made with."""
    digest = hashlib.sha256()
    here = Path(__file__).resolve().parent
    for name in SOURCES:
        digest.update(name.encode())
        digest.update(code_of((here / name).read_text(encoding="utf-8")).encode())
    return digest.hexdigest()[:16]


def file_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def resolve_case(text: str) -> Path:
    """A case file path, or ``config/cases/{text}.yaml`` for a bare name."""
    path = Path(text)
    if path.suffix in (".yaml", ".yml") or path.exists():
        return path
    return Path("config/cases") / f"{text}.yaml"


def _y(run: dict, kind: str) -> np.ndarray:
    """(n_steps, n_entries) y components of ``kind`` ("reactions" or "contact") of a run."""
    rows = []
    for step in run["steps"]:
        values = step[kind]
        rows.append([(v["force"] if kind == "contact" else v)[1] for _, v in sorted(values.items())])
    return np.array(rows, float)


def changes(run: dict, finest: dict) -> float:
    """Largest relative change of the y reactions of ``run`` to ``finest`` over all steps
    and supports: ``max |R - R_f| / |R_f|`` (nan if the runs do not hold the same steps)."""
    a, b = _y(run, "reactions"), _y(finest, "reactions")
    if a.shape != b.shape or not run["converged"] or not finest["converged"]:
        return float("nan")
    return float(np.max(np.abs(a - b) / np.abs(b)))


def extrapolated_error(runs: list[dict]) -> float:
    """Estimated relative error of the finest run's final reactions from the last three
    levels (geometric convergence): with ``d1 = R_(L-1) - R_(L-2)``, ``d2 = R_L - R_(L-1)``
    and ``q = d2 / d1`` in (0, 1), ``|d2| q / (1 - q) / |R_L|``, the largest over the
    supports; nan if the three do not converge geometrically (then the change alone counts)."""
    if len(runs) < 3 or not all(r["converged"] for r in runs[-3:]):
        return float("nan")
    r0, r1, r2 = (_y(r, "reactions")[-1] for r in runs[-3:])
    d1, d2 = r1 - r0, r2 - r1
    with np.errstate(divide="ignore", invalid="ignore"):
        q = d2 / d1
        est = np.abs(d2) * q / (1.0 - q) / np.abs(r2)
    ok = (q > 0.0) & (q < 1.0)
    return float(est[ok].max()) if ok.all() else float("nan")


def _peak_change(run: dict, finest: dict) -> dict[str, float]:
    out = {}
    for body, value in finest["steps"][-1]["max_von_mises"].items():
        if run["converged"] and run["steps"]:
            out[body] = abs(run["steps"][-1]["max_von_mises"][body] - value) / value
    return out


def _entries(case) -> dict[str, str]:
    """Support keys: the pulled one (its prescribed y is nonzero) and the clamped one."""
    roles = {}
    for bc in case.boundary:
        key = f"{bc.body}/{'+'.join(bc.patches)}"
        moving = any(c == 1 and e.constant_value != 0.0 for c, e in bc.components)
        roles["pulled" if moving else "clamped"] = key
    return roles


def _extent(run: dict) -> float:
    """Largest contact-zone extent (m) of a run over its steps and pairs (0 without contact)."""
    return max((v for step in run["steps"] for v in step["contact_extent"].values()), default=0.0)


def study(case_path: Path, meshes: tuple[int, ...], order: int, penalty_factor: float,
          log: Callable[[str], None], command: str = "", r_contact: float = R_CONTACT) -> dict:
    """Solve ``case_path`` on every mesh level (refined to ``h_contact`` within
    ``r_contact`` m of the touch points), on the finest also with the penalty times
    ``PENALTY_STEP``; the reference JSON (see the module)."""
    from cgfem.reference.tori_solve import solve
    import netgen
    import ngsolve

    case = load_case(case_path)
    check_symmetry(case)
    t0 = time.perf_counter()
    runs, check = [], None
    levels = sorted(meshes)
    for level in levels:
        finest = level == levels[-1]
        log(f"{case.name}: mesh level {level}, order {order}, penalty factor {penalty_factor:g}, "
            f"r_contact {r_contact:g} m" + (f" (and times {PENALTY_STEP:g})" if finest else ""))
        solution = solve(case, mesh_level(level, order, r_contact), penalty_factor, log=log,
                         check_factor=PENALTY_STEP if finest else None)
        runs.append({"level": level, **solution.as_dict()})
        check = solution.check
    finest = runs[-1]
    penalty_run = {"level": finest["level"], **check.as_dict()}
    mesh_rows = [{"level": r["level"], "dofs": r["mesh"]["dofs"], "elements": r["mesh"]["elements"],
                  "h": r["mesh"]["h"], "h_contact": r["mesh"]["h_contact"],
                  "r_contact": r["mesh"]["r_contact"], "contact_extent": _extent(r),
                  "final_reactions": r["steps"][-1]["reactions"] if r["steps"] else None,
                  "change_to_finest": changes(r, finest),
                  "von_mises_change_to_finest": _peak_change(r, finest)} for r in runs]
    mesh_change = mesh_rows[-2]["change_to_finest"] if len(mesh_rows) > 1 else float("nan")
    mesh_extrapolated = extrapolated_error(runs)
    mesh_u = float(np.nanmax([mesh_change, mesh_extrapolated]))
    penalty_u = changes(penalty_run, finest)
    accepted = bool(len(runs) >= 3 and all(r["converged"] for r in runs) and penalty_run["converged"]
                    and mesh_u < ACCEPT and penalty_u < ACCEPT)
    return {
        "schema": SCHEMA,
        "case": case.name,
        "case_file": str(case_path),
        "case_sha256": file_sha256(case_path),
        "script_version": script_version(),
        "command": command,
        "software": {"ngsolve": ngsolve.__version__, "netgen": netgen.__version__,
                     "python": platform.python_version()},
        "formulation": {
            "model": "quarter x >= 0, z >= 0 (symmetry planes u_x = 0, u_z = 0); forces of the "
                     "whole chain (y times 4, x and z zero by symmetry)",
            "kinematics": case.kinematics,
            "material": "Neo-Hookean W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2" if case.kinematics == "finite"
                        else "linear elastic",
            "elements": f"curved tetrahedra, VectorH1 of order {order}",
            "contact": "penalty eps/2 <g>_+^2 on the slave's reference area, g on current positions, "
                       "eps = penalty_factor E_slave / r_slave",
            "penalty_factor": penalty_factor, "penalty_check_factor": penalty_factor * PENALTY_STEP,
        },
        "supports": _entries(case),
        "runs": runs,
        "penalty_run": penalty_run,
        "uncertainty": {
            "meshes": mesh_rows,
            "mesh_change": mesh_change,
            "mesh_extrapolated": mesh_extrapolated,
            "mesh": mesh_u,
            "penalty": penalty_u,
            "contact_extent": _extent(finest),
            "r_contact": r_contact,
            "accept_below": ACCEPT,
            "accepted": accepted,
        },
        "reference": {"level": finest["level"], "order": order, "penalty_factor": penalty_factor,
                      "dofs": finest["mesh"]["dofs"], "steps": finest["steps"]},
        "seconds": time.perf_counter() - t0,
    }


class StaleGold(Exception):
    """A gold file not made by the current script version or for the current case file."""


def check_gold(gold: Path, case_path: Path) -> dict:
    """The gold reference ``gold`` if it was made by the current :func:`script_version`
    for the current content of ``case_path``; :class:`StaleGold` (naming the command that
    regenerates it) otherwise."""
    data = json.loads(Path(gold).read_text())
    if data.get("schema") != SCHEMA:
        raise InputError(str(gold), f"not a torus reference (schema {data.get('schema')!r})")
    problems = []
    if data["script_version"] != script_version():
        problems.append(f"made by script version {data['script_version']}, the current is {script_version()}")
    if data["case_sha256"] != file_sha256(case_path):
        problems.append(f"made for another content of {case_path}")
    if problems:
        raise StaleGold(f"{gold}: {'; '.join(problems)}; regenerate it with: {data.get('command', '?')}")
    return data


def verdict(data: dict) -> str:
    u = data["uncertainty"]
    return (f"{data['case']}: contact zone {u['contact_extent'] * 1e3:.2f} mm within r_contact "
            f"{u['r_contact'] * 1e3:.2f} mm; mesh uncertainty {u['mesh']:.3%} (change {u['mesh_change']:.3%}, "
            f"extrapolated {u['mesh_extrapolated']:.3%}), penalty change {u['penalty']:.3%} "
            f"(accept below {u['accept_below']:.1%}): {'ACCEPTED' if u['accepted'] else 'NOT ACCEPTED'}")


def _levels(text: str) -> tuple[int, ...]:
    try:
        levels = tuple(sorted({int(v) for v in text.split(",") if v.strip()}))
    except ValueError:
        raise InputError("--meshes", f"expected comma-separated levels, got {text!r}") from None
    if len(levels) < 3 or min(levels) < 0:
        raise InputError("--meshes", f"need at least three levels >= 0, got {text!r}")
    return levels


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m cgfem.reference.tori",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--case", required=True, help="case file, or a name in config/cases/")
    parser.add_argument("--out", required=True, help="reference JSON to write")
    parser.add_argument("--meshes", default=",".join(map(str, DEFAULT_MESHES)),
                        help="mesh levels, at least three (default %(default)s)")
    parser.add_argument("--order", type=int, default=2, help="element order >= 2 (default 2)")
    parser.add_argument("--penalty-factor", type=float, default=PENALTY_FACTOR,
                        help="eps = factor E_slave / r_slave (default %(default)g)")
    parser.add_argument("--r-contact", type=float, default=R_CONTACT,
                        help="radius (m) about the touch points meshed at h_contact; must hold "
                             "the contact zone of the last load step (default %(default)g)")
    parser.add_argument("--threads", type=int, default=1, help="NGSolve threads (default 1)")
    parser.add_argument("--from-gold", metavar="GOLD", help="check a gold file and copy it to --out")
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    try:
        case_path = resolve_case(args.case)
        if not case_path.is_file():
            raise InputError("--case", f"no case file {case_path}")
        if args.order < 2:
            raise InputError("--order", f"must be >= 2, got {args.order}")
        if not args.penalty_factor > 0.0:
            raise InputError("--penalty-factor", f"must be > 0, got {args.penalty_factor}")
        if not args.r_contact > 0.0:
            raise InputError("--r-contact", f"must be > 0, got {args.r_contact}")
        if args.threads < 1:
            raise InputError("--threads", f"must be >= 1, got {args.threads}")
        levels = _levels(args.meshes)
        out = Path(args.out)
        if out.is_dir():
            raise InputError("--out", f"{out} is a directory")
        if args.from_gold:
            data = check_gold(Path(args.from_gold), case_path)
        else:
            case = load_case(case_path)
            check_symmetry(case)
    except InputError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except StaleGold as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if not args.from_gold:
        import ngsolve

        def log(text: str) -> None:
            print(text, file=sys.stderr, flush=True)

        command = "python3 -m cgfem.reference.tori " + " ".join(shlex.quote(a) for a in argv)
        ngsolve.SetNumThreads(args.threads)
        with ngsolve.TaskManager():
            data = study(case_path, levels, args.order, args.penalty_factor, log, command,
                         args.r_contact)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out, json.dumps(data, indent=1) + "\n")
    print(verdict(data), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
