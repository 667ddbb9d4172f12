"""The one plotting style of the report: colours per surface definition, figure sizes, and
saving (PNG at print resolution and PDF), which is the caller's job."""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # noqa: E402

from cgfem.atomic import write_bytes_atomic  # noqa: E402

#: colour of each contact-surface definition
SURFACE_COLOURS = {"facets": "#d95f02", "nurbs_fe": "#1b9e77", "nurbs_fit": "#7570b3"}
#: line width and marker size of each definition: nurbs_fe and nurbs_fit often coincide to
#: plotting accuracy, so nurbs_fe is drawn wide beneath nurbs_fit's thin line and both show
SURFACE_WIDTHS = {"facets": (1.2, 4.0), "nurbs_fe": (2.8, 6.5), "nurbs_fit": (1.0, 3.0)}
#: marker of each mesh level
LEVEL_MARKERS = ("o", "s", "^", "D", "v", "P")
#: line style of a run that failed to converge (stopped before its last step)
FAILED_STYLE = {"linestyle": "--", "marker": "x"}
#: line style of a run that reached every step with an outer loop stopped at its cap
OUTER_NOT_CONVERGED_STYLE = {"linestyle": ":", "markerfacecolor": "white"}
#: print resolution of the PNG files (dots per inch)
PRINT_DPI = 300

RC = {"font.size": 8, "axes.titlesize": 8, "axes.labelsize": 8, "legend.fontsize": 6.5,
      "xtick.labelsize": 7, "ytick.labelsize": 7, "lines.linewidth": 1.2, "lines.markersize": 4,
      "axes.grid": True, "grid.alpha": 0.3, "figure.dpi": 100, "savefig.bbox": "tight"}
plt.rcParams.update(RC)  # the report's style, for every figure drawn after this import


def colour(surface: str) -> str:
    return SURFACE_COLOURS.get(surface, "black")


def pen(surface: str) -> dict:
    """Matplotlib line keywords of ``surface``: colour, line width, marker size."""
    width, size = SURFACE_WIDTHS.get(surface, (1.2, 4.0))
    return {"color": colour(surface), "linewidth": width, "markersize": size}


def marker(level: int) -> str:
    return LEVEL_MARKERS[level % len(LEVEL_MARKERS)]


def new_figure(n_rows: int = 1, n_cols: int = 1, width: float = 6.5, height: float = 2.6,
               **kwargs) -> tuple[Figure, object]:
    """A figure of ``n_rows x n_cols`` axes in the report style; ``height`` per row (inches)."""
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(width, height * n_rows),
                             squeeze=False, layout="constrained", **kwargs)
    return fig, axes


def save_figure(fig: Figure, png: str | Path, pdf: str | Path) -> None:
    """Write ``fig`` as PNG (``PRINT_DPI``) and PDF, each atomically (a reader never sees a
    part of a file), then close it. The PDF carries no creation date, so that the same figure
    drawn again is the same file."""
    for path, options in ((png, {"format": "png", "dpi": PRINT_DPI}),
                          (pdf, {"format": "pdf", "metadata": {"CreationDate": None}})):
        buffer = io.BytesIO()
        fig.savefig(buffer, **options)
        write_bytes_atomic(Path(path), buffer.getvalue())
    plt.close(fig)


def short_number(value: float) -> str:
    """``value`` in at most four significant digits, with a k or M suffix from 10^4 on:
    ``2000``, ``20k``, ``1.5M``, ``0.5``."""
    for above, unit, suffix in ((1e6, 1e6, "M"), (1e4, 1e3, "k")):
        if abs(value) >= above:
            return f"{value / unit:.3g}{suffix}"
    return f"{value:.4g}"


def short_log_ticks(axis) -> None:
    """Label a log ``axis`` (``ax.xaxis`` or ``ax.yaxis``) at 1, 2 and 5 times the powers of
    ten in :func:`short_number`, without minor labels (which run into each other)."""
    axis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FuncFormatter(lambda value, _: short_number(value)))
    axis.set_minor_formatter(NullFormatter())
