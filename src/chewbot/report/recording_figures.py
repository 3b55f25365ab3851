"""The figure of an imported recording (``chewbot import-motion``): the recorded and the reproduced incisor path
side by side, as SVG text (written with chewbot's marker, beside the task)."""

from __future__ import annotations

import io

import numpy as np

from chewbot.report.plotting import layout, subplots


def incisor_paths_svg(t: np.ndarray, recorded: np.ndarray, reproduced: np.ndarray, title: str) -> str:
    """:func:`incisor_paths` as SVG text without its XML declaration."""
    fig = incisor_paths(t, recorded, reproduced, title)
    out = io.StringIO()
    fig.savefig(out, format="svg")
    text = out.getvalue()
    return text[text.index("?>") + 2:].lstrip() if text.startswith("<?xml") else text


def incisor_paths(t: np.ndarray, recorded: np.ndarray, reproduced: np.ndarray, title: str):
    """Three panels: the incisor point's path in the sagittal plane (x, z of {S}) and in the frontal plane (y, z),
    recorded (registered, scale 1) and reproduced by the robot, and its distance from the first frame over time;
    ``recorded``, ``reproduced`` (N, 3) m. Returns the figure, laid out."""
    fig, (side, front, time) = subplots(1, 3, figsize=(13.0, 4.0))
    rec, rep = recorded / 1e-3, reproduced / 1e-3
    for ax, (i, j), name in ((side, (0, 2), "sagittal"), (front, (1, 2), "frontal")):
        ax.plot(rec[:, i], rec[:, j], color="0.55", lw=2.2, label="recorded")
        ax.plot(rep[:, i], rep[:, j], color="C0", lw=1.0, label="reproduced")
        ax.set_xlabel(f"{'xy'[i]} in {{S}} [mm]")
        ax.set_ylabel("z in {S} [mm]")
        ax.set_title(f"incisor path, {name} plane")
        ax.set_aspect("equal", adjustable="datalim")
    side.legend(loc="best", fontsize=8)
    time.plot(t, np.linalg.norm(rec - rec[0], axis=1), color="0.55", lw=2.2, label="recorded")
    time.plot(t, np.linalg.norm(rep - rep[0], axis=1), color="C0", lw=1.0, label="reproduced")
    time.set_xlabel("t [s]")
    time.set_ylabel("incisal excursion [mm]")
    time.set_title("distance from the first frame")
    fig.suptitle(title, fontsize=10)
    layout(fig)
    return fig
