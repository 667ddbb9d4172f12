"""Distance of the cgFEM runs of the chain examples to their body-fitted references.

A reference is the JSON of :mod:`cgfem.reference.tori` (``results/reference/{case}.json``):
per load step the reactions (``body/patch+patch``, N) and the peak von Mises stress of every
body (Pa) of the whole chain, and its uncertainty (the larger of its mesh and penalty
changes, relative). The distance of a run to it is the signed relative error
``(F_run - F_ref) / |F_ref|`` of the y component of the pulled reaction at every load step
both hold, and of the peak von Mises stress of a body at the last step.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cgfem.report.runs import SUMMARY, Run, load_runs
from cgfem.report.style import colour, marker, new_figure, pen, short_log_ticks

__all__ = ["Reference", "final_error", "fig_validation", "load_references", "run_errors",
           "von_mises_error"]

#: y, the component of every reaction compared
Y = 1


@dataclass(frozen=True)
class Reference:
    """One reference JSON: case name, the key of its pulled support, load factors (n,),
    reactions per support key ((n, 3) N), peak von Mises per body at the last step (Pa),
    uncertainty of the reactions (the larger of the mesh and penalty changes, relative),
    and of each body's peak von Mises stress (the change of the finest-but-one mesh's peak
    to the finest's, relative; empty if the JSON has one mesh)."""

    case: str
    pulled: str
    load_factors: np.ndarray
    reactions: dict[str, np.ndarray]
    max_von_mises: dict[str, float]
    uncertainty: float
    accepted: bool
    dofs: int
    path: Path
    von_mises_uncertainty: dict[str, float]

    @classmethod
    def load(cls, path: str | Path) -> "Reference":
        data = json.loads(Path(path).read_text())
        steps = data["reference"]["steps"]
        keys = steps[0]["reactions"] if steps else {}
        u = data["uncertainty"]
        meshes = u.get("meshes", [])
        peaks = meshes[-2].get("von_mises_change_to_finest", {}) if len(meshes) > 1 else {}
        return cls(str(data["case"]), str(data["supports"]["pulled"]),
                   np.array([s["load_factor"] for s in steps], float),
                   {k: np.array([s["reactions"][k] for s in steps], float) for k in keys},
                   dict(steps[-1]["max_von_mises"]) if steps else {},
                   float(np.nanmax([u["mesh"], u["penalty"]])), bool(u["accepted"]),
                   int(data["reference"]["dofs"]), Path(path),
                   {k: float(v) for k, v in peaks.items()})


def load_references(paths) -> dict[str, Reference]:
    """References by case name."""
    return {r.case: r for r in (Reference.load(p) for p in paths)}


def split_inputs(paths) -> tuple[list[str], list[str]]:
    """(run summaries, reference JSONs) of a figure's inputs, told apart by file name."""
    runs = [str(p) for p in paths if Path(p).name == SUMMARY]
    return runs, [str(p) for p in paths if Path(p).name != SUMMARY]


def run_errors(run: Run, ref: Reference, key: str) -> tuple[np.ndarray, np.ndarray]:
    """Load factors (m,) of the run's converged steps that the reference holds and the
    signed relative error (m,) of the y reaction ``key`` there."""
    if not run.n_steps or key not in ref.reactions:
        return np.zeros(0), np.zeros(0)
    loads, forces = run.load_factors(), run.reactions(key)[:, Y]
    lf, err = [], []
    for t, f in zip(loads, forces):
        hit = np.flatnonzero(np.isclose(ref.load_factors, t, rtol=0.0, atol=1e-9))
        if hit.size:
            r = ref.reactions[key][hit[0], Y]
            lf.append(t)
            err.append((f - r) / abs(r))
    return np.array(lf), np.array(err)


def final_error(run: Run, ref: Reference, key: str) -> float:
    """Signed relative error of the y reaction ``key`` at the reference's last load step
    (nan if the run did not reach it)."""
    lf, err = run_errors(run, ref, key)
    if not lf.size or not np.isclose(lf[-1], ref.load_factors[-1]):
        return float("nan")
    return float(err[-1])


def von_mises_error(run: Run, ref: Reference, body: str) -> float:
    """Signed relative error of the run's peak von Mises stress in ``body`` at the last
    step (nan if it did not reach the reference's last step)."""
    if (not run.n_steps or body not in ref.max_von_mises
            or not np.isclose(run.load_factors()[-1], ref.load_factors[-1])):
        return float("nan")
    r = ref.max_von_mises[body]
    return (run.max_von_mises(body) - r) / r


def _runs_by_case(runs: list[Run]) -> dict[str, list[Run]]:
    out: dict[str, list[Run]] = {}
    for run in runs:
        out.setdefault(run.case, []).append(run)
    return out


def fig_validation(inputs, von_mises: dict | None = None) -> Figure:
    """One row per chain example with a reference (``inputs``: reference JSONs and run
    summaries): (a) signed relative error (%) of the pulled reaction (the reference's
    ``supports.pulled``) at every load step, every run, the reference's uncertainty shaded; (b) |relative error| of the final pulled
    reaction against the run's DOFs (log-log), a line per definition and element order (order 2
    dashed), the reference's
    uncertainty dotted; (c) the same for the peak von Mises stress of the body
    ``von_mises[case]`` (chain3: ``link_c``), dotted the change of the reference's peak
    between its two finest meshes, or, without one, the final pulled reaction
    (N) against DOFs with the reference and its uncertainty band."""
    summaries, references = split_inputs(inputs)
    refs = load_references(references)
    by_case = _runs_by_case(load_runs(summaries))
    von_mises = {"chain3": "link_c"} if von_mises is None else von_mises
    cases = [c for c in sorted(refs) if c in by_case] or sorted(refs)
    fig, axes = new_figure(max(1, len(cases)), 3, width=9.5, height=2.7)
    for row, case in zip(axes, cases):
        ref, runs = refs[case], by_case.get(case, [])
        pulled = ref.pulled
        _panel_steps(row[0], case, ref, runs, pulled)
        _panel_dofs(row[1], case, ref, runs, lambda r: final_error(r, ref, pulled),
                    "final pulled reaction", ref.uncertainty)
        body = von_mises.get(case)
        if body:
            _panel_dofs(row[2], case, ref, runs, lambda r: von_mises_error(r, ref, body),
                        f"peak von Mises in {body}", ref.von_mises_uncertainty.get(body, np.nan))
        else:
            _panel_absolute(row[2], case, ref, runs, pulled)
    if not cases:
        axes[0, 0].set_title("no reference")
    return fig


def readable_log_x(ax, span: float = 4.0) -> None:
    """Make a log x axis readable: widened to at least the ratio ``span`` about its centre
    (the runs' DOFs may be nearly equal) and labelled by :func:`~cgfem.report.style.short_log_ticks`."""
    lo, hi = ax.get_xlim()
    if lo > 0 and hi / lo < span:
        centre = np.sqrt(lo * hi)
        ax.set_xlim(centre / np.sqrt(span), centre * np.sqrt(span))
    short_log_ticks(ax.xaxis)


def _panel_steps(ax, case: str, ref: Reference, runs: list[Run], key: str) -> None:
    for run in runs:
        lf, err = run_errors(run, ref, key)
        if lf.size:
            ax.plot(lf, 100.0 * err, label=run.label, marker=marker(run.level),
                    **{**pen(run.surface), "linewidth": 1.0})
    ax.axhline(0.0, color="k", linewidth=0.6)
    ax.axhspan(-100 * ref.uncertainty, 100 * ref.uncertainty, color="0.85", zorder=0)
    ax.set(title=f"{case}: pulled reaction vs reference", xlabel="load factor",
           ylabel="relative error (%)")
    if runs:
        ax.legend(ncol=2, fontsize=5.5)


def _order_style(order: int) -> dict:
    """Marker and line of an element order's series: order 1 solid with circles, order 2
    dashed with squares."""
    return {"marker": "o", "linestyle": "-"} if order == 1 else {"marker": "s", "linestyle": "--"}


def _series(runs: list[Run]) -> list[tuple[str, int, list[Run]]]:
    """The runs as one series per (definition, element order), each by level, with its
    label (``surface``, and `` o2`` for order 2)."""
    out = []
    for surface, order in sorted({(r.surface, r.order) for r in runs}):
        group = sorted((r for r in runs if r.surface == surface and r.order == order), key=lambda r: r.level)
        out.append((surface + (f" o{order}" if order != 1 else ""), order, group))
    return out


def _panel_dofs(ax, case: str, ref: Reference, runs: list[Run], error, what: str,
                uncertainty: float) -> None:
    for label, order, group in _series(runs):
        dofs = np.array([r.dofs for r in group], float)
        err = np.abs(np.array([error(r) for r in group], float))
        ok = np.isfinite(err) & (err > 0)
        if ok.any():
            ax.loglog(dofs[ok], err[ok], label=label,
                      **{**pen(group[0].surface), "linewidth": 1.0, **_order_style(order)})
    if uncertainty > 0:
        ax.axhline(uncertainty, color="k", linestyle=":", linewidth=0.8,
                   label=f"reference uncertainty ({uncertainty:.2%})")
    ax.set(title=f"{case}: {what}", xlabel="DOFs", ylabel="|relative error|")
    readable_log_x(ax)
    ax.legend(fontsize=5.5)


def _panel_absolute(ax, case: str, ref: Reference, runs: list[Run], key: str) -> None:
    target = ref.reactions[key][-1, Y] if key in ref.reactions else np.nan
    for label, order, series in _series(runs):
        group = [r for r in series if r.n_steps and np.isclose(r.load_factors()[-1], ref.load_factors[-1])]
        if group:
            ax.semilogx([r.dofs for r in group], [r.reactions(key)[-1, Y] for r in group],
                        **_order_style(order), color=colour(group[0].surface), label=label)
    ax.axhline(target, color="k", linewidth=0.8, label=f"reference ({ref.dofs} DOFs, NGSolve)")
    ax.axhspan(target * (1 - ref.uncertainty), target * (1 + ref.uncertainty), color="0.85", zorder=0)
    ax.set(title=f"{case}: final pulled reaction", xlabel="DOFs", ylabel="F_y (N)")
    readable_log_x(ax)
    ax.legend(fontsize=5.5)
