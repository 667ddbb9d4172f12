"""Colour maps of result fields rendered off-screen with pyvista and laid out in a matplotlib
grid: sigma_y on chain2_steel (Fig. 14), |u| and the active contact points on chain2_rubber
(Fig. 15), von Mises on the middle link of chain3 (Fig. 17).

Fields are drawn on the boundary points of ``surface_NNN.vtu`` (the exact surface, which the
active hexahedra overhang), warped by their displacement where the figure asks. Without a
display, VTK renders through EGL (``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``, set here
only when ``DISPLAY`` is unset and the variable is not already set).
"""

from __future__ import annotations

import math
import os

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from cgfem.report.runs import ACTIVE, BODY, DISPLACEMENT, STRESS, VON_MISES, Run, load_runs, stress_component
from cgfem.report.style import new_figure

if not os.environ.get("DISPLAY"):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

#: pixels of one rendered panel
PANEL_PIXELS = (800, 600)


def render_points(points: np.ndarray, values: np.ndarray, clim: tuple[float, float], cmap: str,
                  extra: np.ndarray | None = None) -> np.ndarray:
    """RGB image (rows, cols, 3) of a point cloud ``points`` (n, 3) coloured by ``values``
    (n,) in ``clim``, with optional black ``extra`` points (m, 3) on top; isometric view."""
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True, window_size=PANEL_PIXELS)
    plotter.set_background("white")
    plotter.add_points(pv.PolyData(np.asarray(points, float)), scalars=np.asarray(values, float),
                       clim=clim, cmap=cmap, point_size=4.0, render_points_as_spheres=True,
                       show_scalar_bar=False)
    if extra is not None and len(extra):
        plotter.add_points(pv.PolyData(np.asarray(extra, float)), color="black", point_size=6.0,
                           render_points_as_spheres=True)
    plotter.view_isometric()
    plotter.reset_camera()
    image = plotter.screenshot(return_img=True)
    plotter.close()
    return np.asarray(image)


def image_grid(images: list[np.ndarray], titles: list[str], clim: tuple[float, float], cmap: str,
               label: str, max_cols: int = 3) -> Figure:
    """Panels of rendered images with titles and one shared colour bar for ``clim``."""
    n_cols = min(max_cols, len(images))
    n_rows = math.ceil(len(images) / n_cols)
    fig, axes = new_figure(n_rows, n_cols, width=2.4 * n_cols + 0.8, height=2.0)
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, image, title in zip(axes.ravel(), images, titles):
        ax.imshow(image)
        ax.set_title(title)
    mappable = ScalarMappable(Normalize(*clim), cmap)
    fig.colorbar(mappable, ax=axes.ravel().tolist(), label=label, shrink=0.8)
    return fig


def _clim(values: list[np.ndarray]) -> tuple[float, float]:
    lo = min(float(v.min()) for v in values)
    hi = max(float(v.max()) for v in values)
    return (lo, hi) if hi > lo else (lo - 1.0, hi + 1.0)


def _title(run: Run) -> str:
    return f"{run.label} ({run.status_note})" if run.status_note else run.label


def _cloud(run: Run, body: str | None = None, warp: bool = True):
    """Points (n, 3), displacement (n, 3) and the mesh of the last step's boundary cloud,
    restricted to ``body`` if given; points warped by the displacement if ``warp``."""
    cloud = run.surface_points()
    x = np.asarray(cloud.points, float)
    u = np.asarray(cloud.point_data[DISPLACEMENT], float)
    keep = np.ones(x.shape[0], bool)
    if body is not None:
        keep = np.asarray(cloud.point_data[BODY]).ravel() == run.body_index(body)
    return (x + u if warp else x)[keep], u[keep], {k: np.asarray(v)[keep] for k, v in cloud.point_data.items()}


def fig14_stress_maps(summaries, component: tuple[int, int] = (1, 1)) -> Figure:
    """Cauchy stress ``sigma_ij`` (default sigma_yy) at the last converged step of every run
    on the deformed boundary, one panel per run, one colour scale."""
    runs = load_runs(summaries)
    clouds = [_cloud(r) for r in runs]
    values = [stress_component(c[2][STRESS], *component) for c in clouds]
    clim = _clim(values)
    images = [render_points(c[0], v, clim, "coolwarm") for c, v in zip(clouds, values)]
    name = "xyz"[component[0]] + "xyz"[component[1]]
    return image_grid(images, [_title(r) for r in runs], clim, "coolwarm", f"sigma_{name} (Pa)")


def active_contact_points(run: Run, step: int = -1) -> np.ndarray:
    """(m, 3) active contact points of a step, as stored: ``contact_NNN.vtu`` holds them at
    their current positions, beside the boundary cloud warped to its current positions."""
    cloud = run.contact_points(step)
    x = np.asarray(cloud.points, float)
    return x[np.asarray(cloud.point_data[ACTIVE]).ravel() > 0]


def fig15_deformed_shapes(summaries) -> Figure:
    """Deformed boundary coloured by |u| at the last step and the active contact points,
    one panel per run."""
    runs = load_runs(summaries)
    clouds = [_cloud(r) for r in runs]
    values = [np.linalg.norm(c[1], axis=1) for c in clouds]
    clim = _clim(values)
    active = [active_contact_points(r) for r in runs]
    images = [render_points(c[0], v, clim, "viridis", extra=a) for c, v, a in zip(clouds, values, active)]
    titles = [f"{_title(r)}: {len(a)} active points" for r, a in zip(runs, active)]
    return image_grid(images, titles, clim, "viridis", "|u| (m)")


def fig17_von_mises(summaries, body: str) -> Figure:
    """Von Mises stress on the boundary of ``body`` (undeformed) at the last step, one panel
    per run (two per row: facets beside nurbs_fe at each level), one colour scale; titles
    give the run's peak von Mises of that body."""
    runs = load_runs(summaries)
    clouds = [_cloud(r, body, warp=False) for r in runs]
    values = [np.asarray(c[2][VON_MISES], float).ravel() for c in clouds]
    clim = _clim(values)
    images = [render_points(c[0], v, clim, "jet") for c, v in zip(clouds, values)]
    titles = [f"{_title(r)}: peak {r.max_von_mises(body) / 1e6:.4g} MPa" for r in runs]
    return image_grid(images, titles, clim, "jet", f"von Mises on {body} (Pa)", max_cols=2)
