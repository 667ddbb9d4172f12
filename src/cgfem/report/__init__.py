"""Figures and the claims table, drawn from result files alone (run folders of ``cgfem run``
and the planar error tables). Every figure function returns a matplotlib ``Figure``; saving
it is the caller's (:func:`cgfem.report.style.save_figure`).

The package imports none of its modules: a job that needs one module (the planar error
tables: :mod:`cgfem.report.energy`) does not load matplotlib and every figure's code."""

from __future__ import annotations

import importlib

#: figure name -> ``module:function`` of this package, imported on first use
FIGURES = {
    "fig09": "convergence:fig09_energy_error",
    "fig10": "curves:fig10_surface_profile",
    "fig13": "curves:fig13_reactions",
    "fig14": "maps:fig14_stress_maps",
    "fig15": "maps:fig15_deformed_shapes",
    "fig17": "maps:fig17_von_mises",
    "newton": "curves:fig_newton_residuals",
    "timings": "curves:fig_timings",
    "geometry": "curves:fig_geometry_error",
    "validation": "validation:fig_validation",
    "accuracy": "accuracy:fig_accuracy",
}


def figure(name: str, inputs: list[str], **options):
    """Draw figure ``name`` (a key of :data:`FIGURES`) from ``inputs`` (run summaries, error
    tables or reference JSONs)."""
    module, _, function = FIGURES[name].partition(":")
    return getattr(importlib.import_module(f"{__name__}.{module}"), function)(list(inputs), **options)
