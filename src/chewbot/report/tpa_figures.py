"""PNG figures of a texture test (``chewbot tpa``): the force over time and over the gap, the sample's force from
the plant and from the torques. Every axis says its unit."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chewbot.report.plotting import save, subplots
from chewbot.units import factor

_LABELS = {"plant": "plant (the food's force)", "estimated": "estimated from the torques"}


# The plant's curve under the estimate: wide and solid, the estimate thin and dashed on top, so both stay visible.
_STYLE = {"plant": {"lw": 2.4, "ls": "-", "color": "#1f77b4", "zorder": 2},
          "estimated": {"lw": 1.0, "ls": "--", "color": "#d62728", "zorder": 3}}
# The areas a texture analyser's software shades: (from anchor, to anchor, colour, label).
_AREAS = (("contact_1", "deepest_1", "#9ecae1", "first compression"), ("deepest_1", "split", "#c7e9c0", "first withdrawal"),
          ("contact_2", "split_end", "#fdd0a2", "second bite (A2)"))
_MARKS = {"contact_1": ("contact", (4, 6)), "fracture": ("fracture", (4, 6)), "peak_1": ("hardness (first peak)", (4, 6)),
          "deepest_1": ("deepest", (4, -12)), "contact_2": None, "peak_2": None, "deepest_2": None}


def force_time(curves: dict, anchors: dict, path: Path, title: str = "") -> Path:
    """The sample's force (N) over time (s), each curve of ``curves`` ({label: (t, gap, force)}); the areas of the
    first curve's analysis shaded between its ``anchors`` ({label: tpa.json's anchors}) and its anchors marked."""
    fig, ax = subplots(figsize=(11, 4.8))
    first = next(iter(curves))
    t, _, F = (np.asarray(x, float) for x in curves[first])
    marks = anchors.get(first) or {}
    at = {k: v["index"] for k, v in marks.items() if isinstance(v, dict) and "index" in v}
    at["split_end"] = t.size - 1
    if "split" in marks and marks["split"]:
        at["split"] = marks["split"]["index"]
    for start, stop, colour, label in _AREAS:
        if start in at and stop in at:
            span = slice(at[start], at[stop] + 1)
            ax.fill_between(t[span], 0, np.maximum(F[span], 0), color=colour, alpha=0.8, lw=0, label=label, zorder=1)
    for label, (tc, _, Fc) in curves.items():
        ax.plot(tc, Fc, label=_LABELS.get(label, label), **_STYLE.get(label, {}))
    for key, label in _MARKS.items():
        a = marks.get(key)
        if isinstance(a, dict):
            ax.plot(a["t_s"], a["force_N"], "ko", ms=4, zorder=4)
            if label:
                ax.annotate(label[0], (a["t_s"], a["force_N"]), textcoords="offset points", xytext=label[1], fontsize=8)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("force on the teeth F [N]")
    ax.set_title(f"Two-bite texture test{f': {title}' if title else ''}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save(fig, path)


def force_displacement(curves: dict, path: Path, height: float | None, title: str = "") -> Path:
    """The sample's force (N) over its compression h0 - g (mm), loading and unloading, both bites; over the closing
    of the gap, -g (mm), where the height is not known (``height`` None: a log)."""
    fig, ax = subplots(figsize=(7, 5))
    base = 0.0 if height is None else height
    for label, (_, g, F) in curves.items():
        ax.plot((base - np.asarray(g)) / factor("mm"), F, label=_LABELS.get(label, label), **_STYLE.get(label, {}))
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set_xlabel("compression h0 - g [mm]" if height is not None else "closing of the gap -g [mm]")
    ax.set_ylabel("force on the teeth F [N]")
    ax.set_title(f"Force-displacement{f': {title}' if title else ''}")
    ax.grid(alpha=0.3)
    ax.legend()
    return save(fig, path)
