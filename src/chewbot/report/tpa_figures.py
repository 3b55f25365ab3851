"""PNG figures of a texture test (``chewbot tpa``): the force over time and over the gap, the sample's force from
the plant and from the torques. Every axis says its unit."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chewbot.report.plotting import save, subplots
from chewbot.units import factor

_LABELS = {"plant": "plant (the food's force)", "estimated": "estimated from the torques"}


def force_time(curves: dict, path: Path, title: str = "") -> Path:
    """The sample's force (N) over time (s), each curve of ``curves`` ({label: (t, gap, force)})."""
    fig, ax = subplots(figsize=(10, 4.5))
    for label, (t, _, F) in curves.items():
        ax.plot(t, F, lw=1.0, label=_LABELS.get(label, label), ls="-" if label == "plant" else "--")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("force on the teeth F [N]")
    ax.set_title(f"Two-bite texture test{f': {title}' if title else ''}")
    ax.grid(alpha=0.3)
    ax.legend()
    return save(fig, path)


def force_displacement(curves: dict, path: Path, height: float | None, title: str = "") -> Path:
    """The sample's force (N) over its compression h0 - g (mm), loading and unloading, both bites; over the closing
    of the gap, -g (mm), where the height is not known (``height`` None: a log)."""
    fig, ax = subplots(figsize=(7, 5))
    base = 0.0 if height is None else height
    for label, (_, g, F) in curves.items():
        ax.plot((base - np.asarray(g)) / factor("mm"), F, lw=1.0, label=_LABELS.get(label, label), ls="-" if label == "plant" else "--")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set_xlabel("compression h0 - g [mm]" if height is not None else "closing of the gap -g [mm]")
    ax.set_ylabel("force on the teeth F [N]")
    ax.set_title(f"Force-displacement{f': {title}' if title else ''}")
    ax.grid(alpha=0.3)
    ax.legend()
    return save(fig, path)
