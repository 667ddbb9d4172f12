"""The paper's four claims, decided from the result files (docs/validation.md, "The paper's
claims").

1. The energy-norm error converges at the optimal rate for all three definitions (planar).
2. ``facets`` on the coarsest chain2 mesh fails or is poor, while the NURBS definitions
   converge there ("poor": its final pulled reaction is further from the reference, the
   NURBS+FE reaction on the finest converged mesh, than every NURBS definition's on that mesh).
3. ``facets`` gives a lower pulled reaction on mesh 2 than the NURBS definitions.
4. ``facets`` gives a lower peak von Mises stress than ``nurbs_fe`` in the middle link of chain3
   (the paper compares them on its meshes a and b, our levels 0 and 1).

A last line asks whether claims 3 and 4 still hold with triquadratic elements (``cgfem run
--order 2``): each is decided on the order-2 runs as above, at the levels the configuration
names for them; the line says "not decided" when the runs it needs are absent.

"The definitions" are those the results hold; the claim's text names them. "Converge" means
status ``converged``: a run whose outer loop stopped at its cap (``outer_not_converged``) does
not count as converged.

Every claim on the chains also names the distance of each run it uses to the body-fitted
reference of its example (:mod:`cgfem.report.validation`), when the pipeline has one: the
relative error of the final pulled reaction and, for claim 4, of the peak von Mises stress.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from cgfem.atomic import write_text_atomic
from cgfem.definitions import NAMES, NURBS_DEFINITIONS
from cgfem.report.convergence import OPTIMAL_RATE, rates
from cgfem.report.energy import TOTAL, read_error_tables
from cgfem.report.runs import Run, load_runs
from cgfem.report.validation import Reference, final_error, load_references, von_mises_error

#: the definitions in the order the claims list them (:mod:`cgfem.definitions`)
NURBS = NURBS_DEFINITIONS
SURFACES = NAMES


def present(surfaces, among: tuple[str, ...] = SURFACES) -> tuple[str, ...]:
    """The definitions of ``among`` that occur in ``surfaces``, in the order of ``among``."""
    found = set(surfaces)
    return tuple(s for s in among if s in found)


@dataclass(frozen=True)
class Claim:
    number: int
    text: str
    reproduced: bool
    numbers: str
    #: distance of the runs the claim uses to the body-fitted reference ("" if none applies)
    distance: str = ""
    #: False when the runs the claim needs are absent (or none of them is comparable)
    decided: bool = True
    #: the table's first column ("" for the claim's number)
    row: str = ""

    @property
    def verdict(self) -> str:
        """"yes", "no" or "not decided" (a claim of the paper's four says "no" then)."""
        if not self.decided and self.row:
            return "not decided"
        return "yes" if self.reproduced else "no"


def _find(runs: list[Run], surface: str, level: int) -> Run | None:
    return next((r for r in runs if (r.surface, r.level) == (surface, level)), None)


def claim_optimal_rate(error_tables, tolerance: float) -> Claim:
    """Claim 1: the fitted rate in h of the whole problem's relative energy-norm error of every
    definition in the tables (``facets`` and at least one NURBS definition needed) is at least
    ``OPTIMAL_RATE - tolerance``."""
    rows = [r for r in read_error_tables(error_tables) if r.body == TOTAL]
    fitted = rates(rows)
    surfaces = present(r.surface for r in rows)
    rate = {s: fitted.get((s, TOTAL), np.nan) for s in surfaces}
    ok = ("facets" in rate and len(rate) > 1
          and all(np.isfinite(v) and v >= OPTIMAL_RATE - tolerance for v in rate.values()))
    numbers = ", ".join(f"{s} {rate[s]:.3f}" if np.isfinite(rate[s])
                        else f"{s} none (fewer than two levels)" for s in surfaces)
    return Claim(1, f"optimal energy-norm rate (O(h), at least {OPTIMAL_RATE - tolerance:g}) "
                 f"for every definition run ({', '.join(surfaces) or 'none'}), planar", bool(ok),
                 f"fitted rates in h: {numbers or 'no planar error tables'}")


def _final_reaction(run: Run, key: str, component: int) -> float:
    return float(run.reactions(key)[-1, component])


def claim_coarse_facets(runs: list[Run], pulled: str, component: int) -> Claim:
    """Claim 2 on the runs of one chain2 example (all levels and definitions)."""
    names = present((r.surface for r in runs), NURBS) or NURBS
    text = ("facets fails or is poor on the coarsest chain2 mesh while the NURBS definitions "
            f"({', '.join(names)}) converge")
    if not runs:
        return Claim(2, text, False, "no chain2 runs")
    coarse = min(r.level for r in runs)
    facets = _find(runs, "facets", coarse)
    nurbs = {s: _find(runs, s, coarse) for s in names}
    fe_done = [r for r in runs if r.surface == "nurbs_fe" and r.converged]
    if facets is None or any(r is None for r in nurbs.values()) or not fe_done:
        return Claim(2, text, False, f"missing runs at level {coarse} or no converged nurbs_fe run")
    reference = max(fe_done, key=lambda r: r.level)
    target = _final_reaction(reference, pulled, component)
    status = ", ".join(f"{s}: {r.status}" for s, r in [("facets", facets), *nurbs.items()])
    nurbs_ok = all(r.converged for r in nurbs.values())
    if not facets.converged:
        return Claim(2, text, nurbs_ok, f"level {coarse}: {status}")
    error = {s: abs(_final_reaction(r, pulled, component) - target) / abs(target)
             for s, r in [("facets", facets), *nurbs.items()] if r.converged}
    poor = all(error["facets"] > error[s] for s in nurbs if s in error)
    return Claim(2, text, bool(nurbs_ok and poor),
                 f"level {coarse}: {status}; final reaction off the nurbs_fe L{reference.level} value "
                 f"({target:.6g} N) by " + ", ".join(f"{s} {e:.2%}" for s, e in error.items()))


def claim_lower_reaction(runs: list[Run], level: int, pulled: str, component: int) -> Claim:
    """Claim 3: |pulled reaction| of facets below every NURBS definition run at ``level``,
    compared at the largest load factor all of them reached."""
    nurbs = present((r.surface for r in runs), NURBS) or NURBS
    text = (f"facets gives a lower reaction than the NURBS definitions ({', '.join(nurbs)}) "
            f"on chain2 mesh {level}")
    chosen = {s: _find(runs, s, level) for s in ("facets", *nurbs)}
    if any(r is None or r.n_steps == 0 for r in chosen.values()):
        return Claim(3, text, False, f"missing or empty runs at level {level}", decided=False)
    load = min(r.load_factors()[-1] for r in chosen.values())
    force = {}
    for s, r in chosen.items():
        step = int(np.flatnonzero(np.isclose(r.load_factors(), load))[0])
        force[s] = abs(float(r.reactions(pulled)[step, component]))
    lower = all(force["facets"] < force[s] for s in nurbs)
    return Claim(3, text, bool(lower), f"|F| at load factor {load:g}: "
                 + ", ".join(f"{s} {f:.6g} N" for s, f in force.items()))


#: a chain3 run whose contact force is below this fraction of nurbs_fe's carries no load: its
#: links never touched (facets at level 0 chord the tubes apart), so its stresses are not a
#: comparison
CARRIES_LOAD = 0.01


def claim_lower_von_mises(runs: list[Run], levels: Sequence[int], body: str) -> Claim:
    """Claim 4: peak von Mises of ``body`` with facets below nurbs_fe at each of ``levels``
    where it can be decided (both runs converged and carrying the load through contact:
    :data:`CARRIES_LOAD`). Reproduced when it is decided on at least one level and holds on
    every level decided; the numbers give each level, undecided ones with the reason."""
    meshes = ", ".join(str(level) for level in levels)
    text = (f"facets gives a lower peak von Mises than nurbs_fe in {body} of chain3 "
            f"(mesh{'es' if len(levels) > 1 else ''} {meshes})")
    decided, numbers = [], []
    for level in levels:
        verdict, note = _von_mises_at(runs, level, body)
        if verdict is not None:
            decided.append(verdict)
        numbers.append(f"L{level}: {note}")
    return Claim(4, text, bool(decided) and all(decided), "; ".join(numbers), decided=bool(decided))


def _von_mises_at(runs: list[Run], level: int, body: str) -> tuple[bool | None, str]:
    """Claim 4 at one level: whether facets' peak is lower (None: not decided) and why."""
    chosen = {s: _find(runs, s, level) for s in ("facets", "nurbs_fe")}
    if any(r is None or not r.converged for r in chosen.values()):
        return None, ("not decided, missing or unconverged runs: "
                      + ", ".join(f"{s} {r.status if r else 'missing'}" for s, r in chosen.items()))
    load = {s: float(np.linalg.norm(r.contact_force())) for s, r in chosen.items()}
    if load["facets"] < CARRIES_LOAD * load["nurbs_fe"]:
        return None, (f"not decided, facets carries no load through contact (contact force "
                      f"{load['facets']:.3g} N against nurbs_fe's {load['nurbs_fe']:.6g} N): the links never touch")
    peak = {s: r.max_von_mises(body) for s, r in chosen.items()}
    return peak["facets"] < peak["nurbs_fe"], ", ".join(f"{s} {p / 1e6:.6g} MPa" for s, p in peak.items())


def claim_order2(chain2: list[Run], chain3: list[Run], *, reaction_level: int, pulled: str,
                 component: int, von_mises_levels: Sequence[int], body: str,
                 refs: dict[str, Reference] | None = None) -> Claim:
    """Claims 3 and 4 on the order-2 runs of chain2 and chain3 (runs of other orders are left
    out), each decided as at order 1 at ``reaction_level`` and ``von_mises_levels``: "yes"
    when both are decided and hold, "no" when one decided fails, "not decided" otherwise."""
    chain2 = [r for r in chain2 if r.order == 2]
    chain3 = [r for r in chain3 if r.order == 2]
    three = claim_lower_reaction(chain2, reaction_level, pulled, component)
    four = claim_lower_von_mises(chain3, von_mises_levels, body)
    failed = any(c.decided and not c.reproduced for c in (three, four))
    decided = failed or (three.decided and four.decided)
    text = f"claims 3 and 4 still hold with triquadratic elements (order 2): {three.text}; {four.text}"
    numbers = "; ".join(f"claim {c.number}{'' if c.decided else ' (not decided)'}: {c.numbers}"
                        for c in (three, four))
    distance = ""
    if refs:
        used3 = [r for r in chain2 if r.level == reaction_level]
        used4 = [r for r in chain3 if r.level in von_mises_levels and r.surface in ("facets", "nurbs_fe")]
        distance = (f"claim 3: {reference_distance(used3, refs)}; "
                    f"claim 4: {reference_distance(used4, refs, body)}")
    return Claim(3, text, bool(decided and not failed), numbers, distance, decided=bool(decided),
                 row="3, 4 (order 2)")


def claims(error_tables, chain2_summaries, chain3_summaries, *, rate_tolerance: float,
           reaction_level: int, pulled: str, component: int, von_mises_levels: Sequence[int],
           von_mises_body: str, references: Sequence = (), order2: dict | None = None,
           order2_summaries: Sequence = ()) -> list[Claim]:
    """The four claims from the planar error tables and the chain2 and chain3 run folders;
    ``references``: reference JSONs of :mod:`cgfem.reference.tori` (any of the chain
    examples), whose distance to the runs each claim uses is added to it. With ``order2``
    (``reaction_level``, ``von_mises_levels``), a fifth line decides claims 3 and 4 on the
    order-2 run folders ``order2_summaries`` (:func:`claim_order2`). Runs of other orders
    than 1 among the first summaries are left out of the four claims."""
    chain2 = [r for r in load_runs(chain2_summaries) if r.order == 1]
    chain3 = [r for r in load_runs(chain3_summaries) if r.order == 1]
    found = [claim_optimal_rate(error_tables, rate_tolerance),
             claim_coarse_facets(chain2, pulled, component),
             claim_lower_reaction(chain2, reaction_level, pulled, component),
             claim_lower_von_mises(chain3, von_mises_levels, von_mises_body)]
    refs = load_references(references)
    used = {2: _claim2_runs(chain2), 3: [r for r in chain2 if r.level == reaction_level],
            4: [r for r in chain3 if r.level in von_mises_levels and r.surface in ("facets", "nurbs_fe")]}
    out = [replace(found[0], distance="energy-norm errors against the planar reference (numbers)")]
    for claim in found[1:]:
        out.append(replace(claim, distance=reference_distance(
            used[claim.number], refs, von_mises_body if claim.number == 4 else None)))
    if order2 is not None:
        runs = load_runs(order2_summaries)
        out.append(claim_order2([r for r in runs if r.case.startswith("chain2")],
                                [r for r in runs if r.case == "chain3"],
                                reaction_level=order2["reaction_level"], pulled=pulled,
                                component=component, von_mises_levels=order2["von_mises_levels"],
                                body=von_mises_body, refs=refs))
    return out


def _claim2_runs(runs: list[Run]) -> list[Run]:
    """The runs claim 2 uses: the coarsest level's and the finest converged nurbs_fe."""
    if not runs:
        return []
    coarse = min(r.level for r in runs)
    done = [r for r in runs if r.surface == "nurbs_fe" and r.converged]
    chosen = [r for r in runs if r.level == coarse]
    if done:
        finest = max(done, key=lambda r: r.level)
        chosen += [finest] if finest not in chosen else []
    return chosen


def reference_distance(runs: list[Run], refs: dict[str, Reference], body: str | None = None) -> str:
    """``"run: +x.xx %, ..."``: relative error of each run's final pulled reaction (and, with
    ``body``, of its peak von Mises stress there) against its example's reference, headed by
    the reference's uncertainties."""
    if not runs:
        return "no runs"
    parts = []
    for run in runs:
        ref = refs.get(run.case)
        if ref is None:
            return f"no reference of {run.case} in this configuration"
        text = f"{run.label} {_percent(final_error(run, ref, ref.pulled))}"
        if body is not None:
            text += f" (von Mises {_percent(von_mises_error(run, ref, body))})"
        parts.append(text)
    some = refs[runs[0].case]
    head = f"pulled reaction vs reference ({some.uncertainty:.2%} uncertain"
    if body is not None and body in some.von_mises_uncertainty:
        head += f", its peak von Mises {some.von_mises_uncertainty[body]:.2%}"
    return head + "): " + ", ".join(parts)


def _percent(value: float) -> str:
    return "not reached" if not np.isfinite(value) else f"{value:+.2%}"


def claims_markdown(found: list[Claim]) -> str:
    lines = ["# The paper's claims, checked on our results", "",
             "Generated by the pipeline (rule `claims`, `cgfem.report.claims`) from the result "
             "files; not edited by hand.", "",
             "| # | claim | reproduced | numbers | distance to the reference |",
             "|---|---|---|---|---|"]
    lines += [f"| {c.row or c.number} | {c.text} | {c.verdict} | {c.numbers} | "
              f"{c.distance or 'no reference'} |" for c in found]
    return "\n".join(lines) + "\n"


def write_claims(path: str | Path, found: list[Claim]) -> Path:
    return write_text_atomic(Path(path), claims_markdown(found))
