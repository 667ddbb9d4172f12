"""Line plots from run results: surface profile (Fig. 10), reactions (Fig. 13) and our own
validation figures (Newton residuals, time per stage, geometry error)."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
from matplotlib.figure import Figure

from cgfem.report.runs import BODY, DISPLACEMENT, Run, load_runs
from cgfem.report.style import FAILED_STYLE, OUTER_NOT_CONVERGED_STYLE, colour, marker, new_figure, pen, short_log_ticks

AXES = {"x": 0, "y": 1, "z": 2}


def _style(run: Run) -> dict:
    """Line style of a run: colour by surface, marker by level; dashed with crosses if it
    failed, dotted with hollow markers if its outer loop did not converge."""
    style = {**pen(run.surface), "marker": marker(run.level)}
    if run.failed:
        style.update(FAILED_STYLE)
    elif run.outer_not_converged:
        style.update(OUTER_NOT_CONVERGED_STYLE)
    return style


def _label(run: Run) -> str:
    return f"{run.label} ({run.status_note})" if run.status_note else run.label


def surface_profile(run: Run, body: str, line: dict[str, float], along: str, component: str,
                    band: float, step: int = -1) -> tuple[np.ndarray, np.ndarray]:
    """Boundary points of ``body`` within ``band`` of a straight line parallel to ``along``
    (``line`` fixes the two other coordinates, e.g. ``{"x": 0.00125, "z": 0.01}``): their
    coordinate along it (sorted) and displacement ``component`` there, both (n,)."""
    cloud = run.surface_points(step)
    x = np.asarray(cloud.points, float)
    keep = np.asarray(cloud.point_data[BODY]).ravel() == run.body_index(body)
    for name, value in line.items():
        keep &= np.abs(x[:, AXES[name]] - value) <= band
    s = x[keep, AXES[along]]
    u = np.asarray(cloud.point_data[DISPLACEMENT], float)[keep, AXES[component]]
    order = np.argsort(s, kind="stable")
    return s[order], u[order]


def fitted_profile(rest, moved, line: dict[str, float], along: str, component: str,
                   samples: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """The fitted NURBS displacement along the line (as :func:`surface_profile`): the patch at
    ``rest`` and ``moved`` (same knots) is sampled on a ``samples``-square parameter lattice,
    and on each lattice line of the second parameter the point whose reference position
    meets the line is found by linear interpolation of the first coordinate ``line`` fixes
    (the other within a lattice step). Returns the coordinate along the line (sorted) and the
    fitted displacement ``component`` there, (m,) each."""
    (u0, u1), (v0, v1) = rest.domain
    a, b = np.linspace(u0, u1, samples), np.linspace(v0, v1, samples)
    uv = np.stack(np.meshgrid(a, b, indexing="ij"), -1).reshape(-1, 2)
    X = rest.evaluate(uv).reshape(samples, samples, 3)
    U = (moved.evaluate(uv) - rest.evaluate(uv)).reshape(samples, samples, 3)
    names = list(line)
    first, others = names[0], names[1:]
    c = AXES[first]
    s_out, u_out = [], []
    for grid_x, grid_u in ((X, U), (X.transpose(1, 0, 2), U.transpose(1, 0, 2))):
        f = grid_x[:, :, c] - line[first]                         # along the first parameter
        i, j = np.nonzero(f[:-1] * f[1:] <= 0.0)
        w = np.where(f[i, j] != f[i + 1, j], f[i, j] / (f[i, j] - f[i + 1, j] + 1e-300), 0.0)[:, None]
        x = (1 - w) * grid_x[i, j] + w * grid_x[i + 1, j]
        u = (1 - w) * grid_u[i, j] + w * grid_u[i + 1, j]
        step = np.abs(np.diff(grid_x, axis=0)).max()
        keep = np.all([np.abs(x[:, AXES[o]] - line[o]) <= step for o in others], axis=0) if others else np.ones(len(x), bool)
        s_out.append(x[keep, AXES[along]])
        u_out.append(u[keep, AXES[component]])
        if s_out[-1].size:
            break
    s, u = np.concatenate(s_out), np.concatenate(u_out)
    order = np.argsort(s, kind="stable")
    return s[order], u[order]


def fig10_surface_profile(summaries, body: str, line: dict[str, float], along: str = "y",
                          component: str = "z", band_fraction: float = 0.25) -> Figure:
    """Displacement ``component`` along a line across a body's surface at the last step, one
    line per run (the boundary points within ``band_fraction * h`` of the line); for
    ``nurbs_fit`` runs also the fitted NURBS of the body's contact patch along the same line
    (black, dashed)."""
    fig, axes = new_figure(1, 1, width=4.5, height=3.0)
    ax = axes[0, 0]
    for run in load_runs(summaries):
        band = band_fraction * float(run.body(body)["h"])
        s, u = surface_profile(run, body, line, along, component, band)
        ax.plot(s, u, label=_label(run), **{**_style(run), "linewidth": 0.8, "markersize": 2.5})
        for name, (rest, moved) in run.fitted_surfaces().items():
            if name.split("/")[0] == body:
                fs, fu = fitted_profile(rest, moved, line, along, component)
                if fs.size:
                    ax.plot(fs, fu, color="k", linewidth=0.8, linestyle="--", zorder=5,
                            label=f"{run.label}: fitted NURBS ({name.split('/')[1]})")
    where = ", ".join(f"{k} = {v:g}" for k, v in line.items())
    ax.set(title=f"{body}: u_{component} along {along} at {where}", xlabel=f"{along} (m)",
           ylabel=f"u_{component} (m)")
    ax.legend()
    return fig


def fig13_reactions(summaries, pulled: str, clamped: str, component: str = "y") -> Figure:
    """Reaction ``component`` on the pulled and on the clamped caps vs load factor, every run
    (failed runs dashed, to their last converged step; runs whose outer loop did not converge
    dotted, hollow markers), and the final pulled reaction vs level per definition (runs that
    reached the last step; a hollow marker where the outer loop did not converge)."""
    runs = load_runs(summaries)
    c = AXES[component]
    fig, axes = new_figure(1, 3, width=9.0, height=2.9)
    for ax, key, title in ((axes[0, 0], pulled, "pulled caps"), (axes[0, 1], clamped, "clamped caps")):
        for run in runs:
            force = np.concatenate([[0.0], run.reactions(key)[:, c]])
            load = np.concatenate([[0.0], run.load_factors()])
            ax.plot(load, force, label=_label(run), **_style(run))
        ax.set(title=f"{title} ({key})", xlabel="load factor", ylabel=f"reaction F_{component} (N)")
    axes[0, 0].legend(ncol=2)
    ax = axes[0, 2]
    for surface in sorted({r.surface for r in runs}):
        done = [r for r in runs if r.surface == surface and not r.failed]
        if not done:
            continue
        ax.plot([r.level for r in done], [r.reactions(pulled)[-1, c] for r in done], marker="o",
                **pen(surface), label=surface)
        outer = [r for r in done if r.outer_not_converged]
        if outer:
            ax.scatter([r.level for r in outer], [r.reactions(pulled)[-1, c] for r in outer],
                       marker="o", s=30, facecolors="white", edgecolors=colour(surface), zorder=3,
                       label=f"{surface}: outer loop not converged")
    ax.set(title="final pulled reaction vs level", xlabel="level", ylabel=f"F_{component} (N)")
    ax.legend()
    return fig


def fig_newton_residuals(summaries) -> Figure:
    """Relative Newton residual of every iteration (all outer passes) of the last converged
    load step of every run, one panel per example, two per row, each legend beside its
    panel. (All steps in a row would draw one hairball per example: chain2_rubber takes
    15 steps of about 12 iterations.)"""
    runs = [r for r in load_runs(summaries) if r.steps]
    cases = sorted({r.case for r in runs})
    n_cols = min(2, len(cases))
    n_rows = -(-len(cases) // n_cols)
    fig, axes = new_figure(n_rows, n_cols, width=7.0, height=2.6)
    for ax in axes.ravel()[len(cases):]:
        ax.set_axis_off()
    for ax, case in zip(axes.ravel(), cases):
        for run in (r for r in runs if r.case == case):
            res = run.newton_residuals(step=-1)
            ax.semilogy(np.arange(res.size), res, label=_label(run),
                        **{**_style(run), "linewidth": 0.8, "markersize": 2})
        ax.set(title=f"{case}: last converged step", xlabel="Newton iteration (all outer passes)",
               ylabel="relative residual")
        ax.legend(fontsize=5, loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False)
    return fig


def fig_timings(summaries, stages: tuple[str, ...] = ("build_s", "solve_s")) -> Figure:
    """Seconds per stage vs DOFs, one panel per stage, a line per (example, definition)."""
    runs = load_runs(summaries)
    fig, axes = new_figure(1, len(stages), width=3.3 * len(stages), height=2.8)
    groups = defaultdict(list)
    for run in runs:
        groups[run.case, run.surface].append(run)
    styles = ("-", "--", ":", "-.")
    cases = sorted({r.case for r in runs})
    for ax, stage in zip(axes[0], stages):
        for (case, surface), group in sorted(groups.items()):
            group.sort(key=lambda r: r.level)
            ax.loglog([r.dofs for r in group], [r.timings()[stage] for r in group], marker="o",
                      color=colour(surface), linestyle=styles[cases.index(case) % len(styles)],
                      label=f"{case} {surface}")
        ax.set(title=stage.removesuffix("_s"), xlabel="DOFs", ylabel="seconds")
        short_log_ticks(ax.xaxis)
        short_log_ticks(ax.yaxis)
    if groups:      # below the panels, where it hides no line
        fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center",
                   ncol=min(4, len(groups)), fontsize=6.5)
    return fig


def geometry_errors(run: Run) -> tuple[float, float]:
    """Relative error of the quadrature's total volume and area against the exact B-rep's."""
    bodies = run.summary["bodies"].values()
    v = sum(b["volume"] for b in bodies), sum(b["brep_volume"] for b in bodies)
    a = sum(b["area"] for b in bodies), sum(b["brep_area"] for b in bodies)
    return abs(v[0] - v[1]) / v[1], abs(a[0] - a[1]) / a[1]


#: floor of the geometry errors on the log axis (round-off)
ERROR_FLOOR = 1e-16


def fig_geometry_error(summaries) -> Figure:
    """Relative volume and area error of the quadrature vs level, a line per (example,
    definition); errors below ``ERROR_FLOOR`` are drawn at it."""
    runs = load_runs(summaries)
    groups = defaultdict(list)
    for run in runs:
        groups[run.case, run.surface].append(run)
    cases = sorted({r.case for r in runs})
    styles = ("-", "--", ":", "-.")
    fig, axes = new_figure(1, 2, width=7.0, height=2.8)
    for (case, surface), group in sorted(groups.items()):
        group.sort(key=lambda r: r.level)
        errors = np.maximum(np.array([geometry_errors(r) for r in group]), ERROR_FLOOR)
        for k, ax in enumerate(axes[0]):
            ax.semilogy([r.level for r in group], errors[:, k], marker="o", **pen(surface),
                        linestyle=styles[cases.index(case) % len(styles)], label=f"{case} {surface}")
    for ax, what in zip(axes[0], ("volume", "area")):
        ax.set(title=f"{what} of the quadrature", xlabel="level", ylabel=f"relative {what} error")
    axes[0, 0].legend(ncol=2)
    return fig
