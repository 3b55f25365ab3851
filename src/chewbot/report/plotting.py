"""What every PNG figure of chewbot shares (matplotlib): figures made without pyplot, laid out once, saved small.

Each figure is drawn once: its margins are set from what surrounds its axes (:func:`layout`: labels, titles,
the legends beside the axes) rather than measured by matplotlib's tight layout, which lays the whole figure out
once more before it is drawn (as long as the drawing). The figures are made without pyplot (no figure manager),
and the PNG is compressed at zlib's fastest level (files about 10 % larger, written in a fifth of the time).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chewbot.table import Table

DPI = 110
PNG_COMPRESSION = 1  # zlib level: 1 fastest, 9 smallest


def subplots(nrows: int = 1, ncols: int = 1, figsize=None, **kwargs):
    """A new figure and its axes, as ``matplotlib.pyplot.subplots`` gives them (without pyplot). matplotlib is
    imported here, on first use: a process that draws nothing does not load it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig, fig.subplots(nrows, ncols, **kwargs)


# Text sizes for the margins (inches), for the default font (DejaVu Sans) at the sizes the figures use.
_CHAR_IN = {7: 0.058, 8: 0.066, 10: 0.083, 12: 0.1}


def layout(fig) -> None:
    """Margins and gaps (in inches, converted to the figure's fractions) that leave room for the tick labels and
    the y labels on the left of each column of axes, the legends placed beside the axes on their right, the
    titles above, the x labels below."""
    width, height = fig.get_size_inches()
    axes = fig.axes
    rows, cols = axes[0].get_subplotspec().get_gridspec().get_geometry()
    legend = 0.0
    for ax in axes:
        leg = ax.get_legend()
        if leg is not None and leg.get_bbox_to_anchor().x0 > ax.bbox.x1:  # anchored beside the axes
            size = _CHAR_IN.get(round(leg.get_texts()[0].get_fontsize()), 0.066)
            legend = max(legend, 0.45 + size * max(len(t.get_text()) for t in leg.get_texts()))
    titled = any(ax.get_title() for ax in axes)
    top = 0.2 + 0.35 * bool(fig.get_suptitle()) + 0.25 * titled
    bottom = 0.55 if any(ax.get_xlabel() for ax in axes) else 0.35
    left, right = 0.95, 0.2 + legend
    wspace = left + right
    hspace = 0.15 + (0.3 if titled and rows > 1 else 0.0) + (0.3 if not axes[0].get_shared_x_axes().joined(axes[0], axes[-1]) else 0.0)
    axis_w = (width - left - right - (cols - 1) * wspace) / cols
    axis_h = (height - top - bottom - (rows - 1) * hspace) / rows
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height, top=1 - top / height,
                        wspace=wspace / axis_w, hspace=hspace / axis_h)


def save(fig, path: Path) -> Path:
    """Lay out and save a figure (every figure has a title: its own or one of its panels')."""
    if not fig.get_suptitle() and not any(ax.get_title() for ax in fig.axes):
        raise ValueError(f"{path.name}: a figure without a title")
    layout(fig)
    fig.savefig(path, dpi=DPI, pil_kwargs={"compress_level": PNG_COMPRESSION})
    return path


JOINTS = range(1, 7)


def per_joint(ax, t, values, label, unit):
    """One line per actuator on ``ax``."""
    for i in JOINTS:
        ax.plot(t, values[:, i - 1], lw=0.9, label=f"{label}{i}")
    ax.set_ylabel(f"{label} [{unit}]")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(alpha=0.3)


def joint_columns(table: Table, prefix: str) -> np.ndarray:
    """The columns PREFIX1..PREFIX6 side by side, (n, 6)."""
    return np.column_stack([table[f"{prefix}{i}"] for i in JOINTS])
