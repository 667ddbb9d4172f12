"""Colour maps of result fields rendered off-screen with pyvista and laid out in a matplotlib
grid: sigma_y on chain2_steel (Fig. 14), |u| and the active contact points on chain2_rubber,
with the active points on the deformed slave link seen from the contact zone (Fig. 15), von
Mises on the middle link of chain3 (Fig. 17).

Fields are drawn on the triangulated boundary of ``boundary_NNN.vtu`` (the exact NURBS
surface, or the facets, which the active hexahedra overhang), smoothly shaded and warped by
the displacement where the figure asks; runs without that file are drawn as their cloud of
boundary points. Without a
display, VTK renders through EGL (``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``, set here
only when ``DISPLAY`` is unset and the variable is not already set).
"""

from __future__ import annotations

import math
import os

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize, TwoSlopeNorm
from matplotlib.figure import Figure

from cgfem.embedding.tessellate import keep_vertices
from cgfem.report.runs import ACTIVE, BODY, DISPLACEMENT, NORMAL, STRESS, VON_MISES, Run, load_runs, stress_component
from cgfem.report.style import new_figure

if not os.environ.get("DISPLAY"):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

#: pixels of one rendered panel
PANEL_PIXELS = (800, 600)
#: a view on points (Fig. 15c) frames at least this fraction of the body's largest extent
#: about them
FRAME_FRACTION = 0.1


def render(points: np.ndarray, values: np.ndarray, clim: tuple[float, float], cmap: str,
           triangles: np.ndarray | None = None, extra: np.ndarray | None = None,
           view: np.ndarray | None = None) -> np.ndarray:
    """RGB image (rows, cols, 3) of the surface ``triangles`` (m, 3) on ``points`` (n, 3),
    or of the points alone when ``triangles`` is None, coloured by ``values`` (n,) in
    ``clim``, with optional black ``extra`` points (k, 3) on top; isometric view, or looking
    along ``-view`` (a direction (3,) from the scene towards the camera) at the ``extra``
    points, framed with a margin (:data:`FRAME_FRACTION`)."""
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True, window_size=PANEL_PIXELS)
    plotter.set_background("white")
    points, values = np.asarray(points, float), np.asarray(values, float)
    if triangles is None:
        plotter.add_points(pv.PolyData(points), scalars=values, clim=clim, cmap=cmap, point_size=4.0,
                           render_points_as_spheres=True, show_scalar_bar=False)
    else:
        faces = np.hstack([np.full((len(triangles), 1), 3), np.asarray(triangles)]).ravel()
        plotter.add_mesh(pv.PolyData(points, faces), scalars=values, clim=clim, cmap=cmap,
                         smooth_shading=True, ambient=0.35, diffuse=0.65, specular=0.0,
                         show_scalar_bar=False)
    if extra is not None and len(extra):
        plotter.add_points(pv.PolyData(np.asarray(extra, float)), color="black", point_size=5.0,
                           render_points_as_spheres=True)
    if view is None:
        plotter.view_isometric()
        plotter.reset_camera()
    else:   # look along -view at the extra points, framed with a margin
        view = np.asarray(view, float) / np.linalg.norm(view)
        up = np.cross(view, [1.0, 0.0, 0.0] if abs(view[0]) < 0.9 else [0.0, 1.0, 0.0])
        focus = np.asarray(extra, float) if extra is not None and len(extra) else points
        centre = focus.mean(axis=0)
        half = np.maximum(np.ptp(focus, axis=0), FRAME_FRACTION * np.ptp(points, axis=0).max())
        plotter.camera_position = [tuple(centre + view), tuple(centre), tuple(up)]
        plotter.reset_camera(bounds=np.column_stack([centre - half, centre + half]).ravel())
    image = plotter.screenshot(return_img=True)
    plotter.close()
    return np.asarray(image)


def centred(values: np.ndarray, clim: tuple[float, float]) -> np.ndarray:
    """``values`` mapped onto [-1, 1] linearly on each side of zero (``clim[0] -> -1``,
    ``0 -> 0``, ``clim[1] -> 1``), for a diverging colour map centred on zero however
    unequal the two extremes; ``clim`` must straddle zero."""
    lo, hi = clim
    v = np.asarray(values, float)
    return np.where(v < 0.0, v / -lo, v / hi)


def image_grid(images: list[np.ndarray], titles: list[str], clim: tuple[float, float], cmap: str,
               label: str, max_cols: int = 3, zero_centred: bool = False) -> Figure:
    """Panels of rendered images with titles and one shared colour bar for ``clim``
    (``zero_centred``: the images were coloured by :func:`centred` values)."""
    n_cols = min(max_cols, len(images))
    n_rows = math.ceil(len(images) / n_cols)
    fig, axes = new_figure(n_rows, n_cols, width=2.4 * n_cols + 0.8, height=2.0)
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, image, title in zip(axes.ravel(), images, titles):
        ax.imshow(image)
        ax.set_title(title)
    norm = TwoSlopeNorm(0.0, *clim) if zero_centred else Normalize(*clim)
    mappable = ScalarMappable(norm, cmap)
    fig.colorbar(mappable, ax=axes.ravel().tolist(), label=label, shrink=0.8)
    return fig


def _clim(values: list[np.ndarray]) -> tuple[float, float]:
    lo = min(float(v.min()) for v in values)
    hi = max(float(v.max()) for v in values)
    return (lo, hi) if hi > lo else (lo - 1.0, hi + 1.0)


def _title(run: Run) -> str:
    return f"{run.label} ({run.status_note})" if run.status_note else run.label


def _surface(run: Run, body: str | None = None, warp: bool = True):
    """Points (n, 3), displacement (n, 3), point data and triangles (m, 3, or None for a
    cloud) of the last step's boundary, restricted to ``body`` if given; points warped by the
    displacement if ``warp``."""
    mesh = run.boundary()
    x = np.asarray(mesh.points, float)
    u = np.asarray(mesh.point_data[DISPLACEMENT], float)
    data = {k: np.asarray(v) for k, v in mesh.point_data.items()}
    cells = {c.type: c.data for c in mesh.cells}
    triangles = cells.get("triangle")
    if body is not None:
        keep = data[BODY].ravel() == run.body_index(body)
        if triangles is not None:   # the body's triangles, on the vertices they use
            triangles, keep = keep_vertices(triangles, keep)
        x, u, data = x[keep], u[keep], {k: v[keep] for k, v in data.items()}
    return (x + u if warp else x), u, data, triangles


def fig14_stress_maps(summaries, component: tuple[int, int] = (1, 1)) -> Figure:
    """Cauchy stress ``sigma_ij`` (default sigma_yy) at the last converged step of every run
    on the deformed boundary, one panel per run, one colour scale, white at zero when the
    values take both signs (each side scaled to its own extreme)."""
    runs = load_runs(summaries)
    surfaces = [_surface(r) for r in runs]
    values = [stress_component(s[2][STRESS], *component) for s in surfaces]
    clim = _clim(values)
    name = "xyz"[component[0]] + "xyz"[component[1]]
    if clim[0] < 0.0 < clim[1]:   # compression blue, tension red, zero white
        images = [render(s[0], centred(v, clim), (-1.0, 1.0), "coolwarm", s[3]) for s, v in zip(surfaces, values)]
        return image_grid(images, [_title(r) for r in runs], clim, "coolwarm", f"sigma_{name} (Pa)",
                          zero_centred=True)
    images = [render(s[0], v, clim, "coolwarm", s[3]) for s, v in zip(surfaces, values)]
    return image_grid(images, [_title(r) for r in runs], clim, "coolwarm", f"sigma_{name} (Pa)")


def active_contact_points(run: Run, step: int = -1) -> np.ndarray:
    """(m, 3) active contact points of a step, as stored: ``contact_NNN.vtu`` holds them at
    their current positions, beside the boundary cloud warped to its current positions."""
    cloud = run.contact_points(step)
    x = np.asarray(cloud.points, float)
    return x[np.asarray(cloud.point_data[ACTIVE]).ravel() > 0]


def slave_body(run: Run, step: int = -1) -> str:
    """The slave body of the first contact pair of a step (pairs are ``"slave/master"``)."""
    pairs = run.steps[step]["contact"]["pairs"]
    return next(iter(pairs)).split("/")[0]


def contact_panel(run: Run, step: int = -1) -> dict:
    """What panel (c) of Fig. 15 draws: the deformed boundary of the slave body of the run's
    first pair (``body``; ``points``, ``displacement``, ``triangles`` as :func:`_surface`),
    its active surface integration points (``active``, (m, 3), current positions) and the
    direction the camera looks from (``view``: the mean current slave normal of the active
    points, so the contact zone faces the viewer; isometric if none is active)."""
    body = slave_body(run, step)
    points, u, _, triangles = _surface(run, body)
    cloud = run.contact_points(step)
    on = np.asarray(cloud.point_data[ACTIVE]).ravel() > 0
    active = np.asarray(cloud.points, float)[on]
    normal = np.asarray(cloud.point_data[NORMAL], float)[on].sum(axis=0)
    view = normal / np.linalg.norm(normal) if np.linalg.norm(normal) > 0 else None
    return {"body": body, "points": points, "displacement": u, "triangles": triangles,
            "active": active, "view": view}


def fig15_deformed_shapes(summaries) -> Figure:
    """The paper's Fig. 15: (a), (b), ... the deformed boundary coloured by |u| at the last
    step and the active contact points, one panel per run; last panel, the paper's (c): the
    active surface integration points on the deformed slave link of the last run (nurbs_fe
    in the paper's comparison), seen from the contact zone (:func:`contact_panel`); none if
    that run's last step has no contact pair."""
    runs = load_runs(summaries)
    surfaces = [_surface(r) for r in runs]
    values = [np.linalg.norm(s[1], axis=1) for s in surfaces]
    has_pairs = runs[-1].n_steps > 0 and bool(runs[-1].steps[-1].get("contact", {}).get("pairs"))
    last = contact_panel(runs[-1]) if has_pairs else None     # no contact: no panel (c)
    clim = _clim([*values, *([np.linalg.norm(last["displacement"], axis=1)] if last else [])])
    active = [active_contact_points(r) for r in runs]
    images = [render(s[0], v, clim, "viridis", s[3], extra=a) for s, v, a in zip(surfaces, values, active)]
    titles = [f"({chr(97 + k)}) {_title(r)}: {len(a)} active points" for k, (r, a) in enumerate(zip(runs, active))]
    if last is not None:
        images.append(render(last["points"], np.linalg.norm(last["displacement"], axis=1), clim, "viridis",
                             last["triangles"], extra=last["active"], view=last["view"]))
        titles.append(f"({chr(97 + len(runs))}) {runs[-1].label}: {len(last['active'])} active points "
                      f"on {last['body']}")
    return image_grid(images, titles, clim, "viridis", "|u| (m)")


def fig17_von_mises(summaries, body: str) -> Figure:
    """Von Mises stress on the boundary of ``body`` (undeformed) at the last step, one panel
    per run (two per row: facets beside nurbs_fe at each level), one colour scale; titles
    give the run's peak von Mises of that body."""
    runs = load_runs(summaries)
    surfaces = [_surface(r, body, warp=False) for r in runs]
    values = [np.asarray(s[2][VON_MISES], float).ravel() for s in surfaces]
    clim = _clim(values)
    images = [render(s[0], v, clim, "jet", s[3]) for s, v in zip(surfaces, values)]
    titles = [f"{_title(r)}: peak {r.max_von_mises(body) / 1e6:.4g} MPa" for r in runs]
    return image_grid(images, titles, clim, "jet", f"von Mises on {body} (Pa)", max_cols=2)
