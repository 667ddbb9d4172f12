"""Fig. 9: relative energy-norm error against DOFs on the planar example, with fitted rates."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from cgfem.report.energy import TOTAL, ErrorRow, read_error_tables
from cgfem.report.style import new_figure, pen

#: spatial dimension: DOFs grow like h^-3 in the 3D slab
DIMENSION = 3
#: optimal energy-norm rate of trilinear (H8) elements, in h
OPTIMAL_RATE = 1.0


def fitted_rate(h: np.ndarray, error: np.ndarray) -> float:
    """Least-squares slope ``p`` of ``log error = p log h + c`` (the observed order in h)."""
    h, error = np.asarray(h, float), np.asarray(error, float)
    if h.size < 2:
        return float("nan")
    return float(np.polyfit(np.log(h), np.log(error), 1)[0])


def rates(rows: list[ErrorRow]) -> dict[tuple[str, str], float]:
    """Fitted rate in h per (surface, body) over all levels of the rows."""
    out = {}
    for key in sorted({(r.surface, r.body) for r in rows}):
        sel = sorted((r for r in rows if (r.surface, r.body) == key), key=lambda r: r.level)
        out[key] = fitted_rate([r.h for r in sel], [r.error for r in sel])
    return out


def _slope_triangle(ax, dofs: np.ndarray, error: np.ndarray, rate: float) -> None:
    """Triangle of slope ``-rate / DIMENSION`` (error vs DOFs) below the last data point."""
    x1, x0 = dofs.max(), dofs.max() / 4.0
    y0 = error.min() * 0.6
    y1 = y0 * (x1 / x0) ** (-rate / DIMENSION)
    ax.plot([x0, x1, x0, x0], [y0, y1, y1, y0], color="0.3", linewidth=0.8,
            label=f"optimal O(h) = O(DOF^-1/{DIMENSION})")


def fig09_energy_error(tables, bodies: tuple[str, ...] = (TOTAL,)) -> Figure:
    """Relative energy-norm error vs DOFs, one panel per entry of ``bodies`` (default: the
    whole problem), one line per surface definition (fitted rate in h in the legend) and the
    optimal-slope triangle. ``tables``: CSV paths of :func:`cgfem.report.energy.write_error_table`."""
    rows = [r for r in read_error_tables(tables) if r.body in bodies]
    fitted = rates(rows)
    fig, axes = new_figure(1, len(bodies), width=3.6 * len(bodies), height=2.8)
    for ax, body in zip(axes[0], bodies):
        for surface in sorted({r.surface for r in rows if r.body == body}):
            sel = sorted((r for r in rows if (r.surface, r.body) == (surface, body)),
                         key=lambda r: r.level)
            ax.loglog([r.dofs for r in sel], [r.error for r in sel], marker="o",
                      **pen(surface), label=f"{surface}: rate {fitted[surface, body]:.2f}")
        sel = [r for r in rows if r.body == body]
        _slope_triangle(ax, np.array([r.dofs for r in sel], float),
                        np.array([r.error for r in sel]), OPTIMAL_RATE)
        ax.set(title="planar" if body == TOTAL else f"planar, body {body}", xlabel="DOFs", ylabel="relative energy-norm error")
        ax.legend()
    return fig
