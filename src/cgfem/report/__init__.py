"""Figures and the claims table, drawn from result files alone (run folders of ``cgfem run``
and the planar error tables). Every figure function returns a matplotlib ``Figure``; saving
it is the caller's (:func:`cgfem.report.style.save_figure`)."""

from __future__ import annotations

from cgfem.report.accuracy import fig_accuracy
from cgfem.report.convergence import fig09_energy_error
from cgfem.report.curves import (fig10_surface_profile, fig13_reactions, fig_geometry_error,
                                 fig_newton_residuals, fig_timings)
from cgfem.report.validation import fig_validation

#: figure name -> function(inputs, **options); the map figures import pyvista on first use
FIGURES = {
    "fig09": fig09_energy_error,
    "fig10": fig10_surface_profile,
    "fig13": fig13_reactions,
    "newton": fig_newton_residuals,
    "timings": fig_timings,
    "geometry": fig_geometry_error,
    "validation": fig_validation,
    "accuracy": fig_accuracy,
}


def figure(name: str, inputs: list[str], **options):
    """Draw figure ``name`` from ``inputs`` (run summaries, error tables or reference JSONs)."""
    if name in ("fig14", "fig15", "fig17"):
        from cgfem.report import maps

        function = {"fig14": maps.fig14_stress_maps, "fig15": maps.fig15_deformed_shapes,
                    "fig17": maps.fig17_von_mises}[name]
    else:
        function = FIGURES[name]
    return function(list(inputs), **options)
