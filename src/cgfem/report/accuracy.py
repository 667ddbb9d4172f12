"""Accuracy against cost of the two element orders on the chain examples
(``paper_figures/accuracy``).

Per chain example, the final pulled reaction (the component of the displacement entry of the
pulled caps that fig13 draws, at the last load step) of every run that reached it, against
the run's unknowns and against its wall time (``timings.build_s + timings.solve_s`` of
``summary.json``), one line per (definition, element order). The best value at hand is drawn
as a horizontal line: the body-fitted reference of the example (:mod:`cgfem.reference.tori`,
``results/reference/{case}.json``) where the configuration has it, else the finest order-2
run, labelled as such.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from cgfem.definitions import NURBS_DEFINITIONS
from cgfem.report.curves import AXES
from cgfem.report.runs import Run, load_runs
from cgfem.report.style import new_figure, pen
from cgfem.report.validation import Reference, load_references, split_inputs, readable_log_x

__all__ = ["CHAINS", "Line", "Target", "accuracy_lines", "best_target", "fig_accuracy",
           "final_reaction", "wall_seconds"]

#: the chain examples, in the order of the figure's rows
CHAINS = ("chain2_steel", "chain2_rubber", "chain3")
#: line style and marker of each element order
ORDER_STYLES = {1: {"linestyle": "-", "marker": "o"}, 2: {"linestyle": "--", "marker": "s"}}
#: the definitions in the order a finest order-2 value is taken from among equal levels (the
#: exact NURBS surface first)
TARGET_PREFERENCE = (*NURBS_DEFINITIONS, "facets")


def final_reaction(run: Run, key: str, component: int) -> float:
    """The reaction ``component`` (N) of the displacement entry ``key`` at the run's last
    step, or nan if the run stopped before the last load step (failed or interrupted)."""
    if run.failed or not run.n_steps:
        return float("nan")
    if key not in run.steps[-1]["reactions"]:
        raise ValueError(f"{run.folder}: no reaction entry {key!r} (it has "
                         f"{', '.join(sorted(run.steps[-1]['reactions']))})")
    return float(run.reactions(key)[-1, component])


def wall_seconds(run: Run) -> float:
    """Build and solve seconds of the run (nan if it has no timings)."""
    timings = run.timings()
    if "build_s" not in timings or "solve_s" not in timings:
        return float("nan")
    return timings["build_s"] + timings["solve_s"]


@dataclass(frozen=True)
class Line:
    """The runs of one (example, definition, element order) that reached the last load step,
    by level: their levels, unknowns, seconds and final reactions (N), (n,) each."""

    case: str
    surface: str
    order: int
    levels: np.ndarray
    dofs: np.ndarray
    seconds: np.ndarray
    force: np.ndarray

    @property
    def label(self) -> str:
        return f"{self.surface}, order {self.order}"


def accuracy_lines(runs: list[Run], key: str, component: int) -> list[Line]:
    """One :class:`Line` per (example, definition, order) of ``runs`` with at least one run
    that reached the last load step, sorted by (example, order, definition)."""
    groups: dict[tuple[str, str, int], list[Run]] = {}
    for run in runs:
        if np.isfinite(final_reaction(run, key, component)):
            groups.setdefault((run.case, run.surface, run.order), []).append(run)
    lines = []
    for (case, surface, order), group in sorted(groups.items(), key=lambda g: (g[0][0], g[0][2], g[0][1])):
        group = sorted(group, key=lambda r: r.level)
        lines.append(Line(case, surface, order, np.array([r.level for r in group]),
                          np.array([r.dofs for r in group], float),
                          np.array([wall_seconds(r) for r in group], float),
                          np.array([final_reaction(r, key, component) for r in group])))
    return lines


@dataclass(frozen=True)
class Target:
    """The best value at hand of an example's final pulled reaction (N), what it is, and its
    relative uncertainty (nan when not known)."""

    value: float
    label: str
    uncertainty: float = float("nan")


def best_target(case: str, runs: list[Run], refs: dict[str, Reference], key: str,
                component: int) -> Target | None:
    """The body-fitted reference of ``case`` (its last step's reaction ``key``, or its own
    pulled entry) if ``refs`` holds it; else the finest order-2 run of ``case`` that reached
    the last load step (the highest level, the exact NURBS definitions first among equal
    levels); None if neither exists."""
    ref = refs.get(case)
    if ref is not None:
        entry = key if key in ref.reactions else ref.pulled
        value = float(ref.reactions[entry][-1, component])
        return Target(value, f"body-fitted reference ({ref.dofs} DOFs, NGSolve): {value:.6g} N",
                      ref.uncertainty)
    candidates = [r for r in runs if r.case == case and r.order == 2
                  and np.isfinite(final_reaction(r, key, component))]
    if not candidates:
        return None
    rank = {s: i for i, s in enumerate(TARGET_PREFERENCE)}
    finest = min(candidates, key=lambda r: (-r.level, rank.get(r.surface, len(rank))))
    value = final_reaction(finest, key, component)
    return Target(value, f"finest order 2 ({finest.surface} L{finest.level}; no body-fitted "
                         f"reference): {value:.6g} N")


def fig_accuracy(inputs, pulled: str = "link_b/cap_a+cap_b", component: str = "y",
                 cases: tuple[str, ...] = CHAINS) -> Figure:
    """One row per chain example among the runs of ``inputs`` (run summaries of both orders
    and reference JSONs): the final pulled reaction ``component`` of the entry ``pulled``
    (a) against the run's DOFs and (b) against its wall time, a line per (definition, order),
    the best target (:func:`best_target`) as a horizontal black line, shaded by its
    uncertainty where it is a body-fitted reference. Runs that stopped before the last load
    step are not drawn; the panel title names them."""
    summaries, references = split_inputs(inputs)
    runs = load_runs(summaries)
    refs = load_references(references)
    if component not in AXES:
        raise ValueError(f"component: must be one of x, y, z (got {component!r})")
    c = AXES[component]
    rows = [case for case in cases if any(r.case == case for r in runs)] or list(cases[:1])
    fig, axes = new_figure(len(rows), 2, width=8.0, height=2.8)
    for row, case in zip(axes, rows):
        mine = [r for r in runs if r.case == case]
        target = best_target(case, mine, refs, pulled, c)
        stopped = [f"{r.label} ({r.status})" for r in mine if not np.isfinite(final_reaction(r, pulled, c))]
        for ax, x_of, what in ((row[0], "dofs", "DOFs"), (row[1], "seconds", "wall time, build + solve (s)")):
            _panel(ax, accuracy_lines(mine, pulled, c), x_of, target, legend=x_of == "dofs")
            title = f"{case}: final pulled reaction vs {'unknowns' if x_of == 'dofs' else 'wall time'}"
            if stopped:
                title += "\nnot drawn (stopped early): " + ", ".join(stopped)
            if target is None:
                title += "\nno reference: no body-fitted reference nor order-2 run"
            ax.set(title=title, xlabel=what, ylabel=f"F_{component} (N)")
    return fig


def _panel(ax, lines: list[Line], x_of: str, target: Target | None, legend: bool = True) -> None:
    """Draw ``lines`` (x: their ``x_of`` attribute, log scale) and the target line; the
    legend if ``legend`` (a row's second panel has the same lines)."""
    for line in lines:
        x = getattr(line, x_of)
        ok = np.isfinite(x) & (x > 0)
        if ok.any():
            ax.plot(x[ok], line.force[ok], label=line.label,
                    **{**pen(line.surface), "linewidth": 1.0, **ORDER_STYLES.get(line.order, {})})
    if target is not None:
        ax.axhline(target.value, color="k", linewidth=0.8, label=target.label)
        if np.isfinite(target.uncertainty) and target.uncertainty > 0:
            half = abs(target.value) * target.uncertainty
            ax.axhspan(target.value - half, target.value + half, color="0.85", zorder=0)
    ax.set_xscale("log")
    readable_log_x(ax)
    if legend and (lines or target is not None):
        ax.legend(fontsize=5.5, framealpha=0.85)
