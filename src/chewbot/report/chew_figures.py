"""PNG figures of a chewing sequence (``chewbot chew``): the particle size distribution after each cycle, X50 against
the cycles with the human reference, and the force and work per cycle. Every axis says its unit."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chewbot.report.plotting import save, subplots


def distribution(cycles: np.ndarray, sieves_mm: np.ndarray, fractions: np.ndarray, path: Path, title: str = "") -> Path:
    """The cumulative mass passing each sieve (%) against its aperture (mm), one curve per cycle (``fractions``:
    (cycles, sieves) retained on each sieve, the pan last)."""
    from matplotlib import colormaps

    fig, ax = subplots(figsize=(8, 5))
    passing = 1 - np.cumsum(fractions, axis=1)  # below each sieve: what it does not retain nor the coarser ones
    colours = colormaps["viridis"](np.linspace(0, 1, len(cycles)))
    every = max(1, int(np.ceil(len(cycles) / 8)))  # at most about eight curves named in the legend
    for i, (k, row, colour) in enumerate(zip(cycles, passing, colours)):
        named = i % every == 0 or i == len(cycles) - 1
        ax.plot(sieves_mm[:-1], 100 * row[:-1], marker="o", ms=3, lw=1.0, color=colour, label=f"cycle {int(k)}" if named else None)
    ax.set_xscale("log")
    return _finish(fig, ax, path, "sieve aperture [mm]", "cumulative mass passing [%]",
                   f"Particle size distribution per cycle{f': {title}' if title else ''}")


def x50(cycles: np.ndarray, x50_mm: np.ndarray, extrapolated: np.ndarray, path: Path, band: tuple | None = None,
        title: str = "") -> Path:
    """X50 (mm) against the cycles; extrapolated values hollow; ``band`` (low mm, high mm, label) the human reference."""
    fig, ax = subplots(figsize=(8, 5))
    ax.plot(cycles, x50_mm, color="C0", lw=1.0)
    inside = ~extrapolated
    ax.plot(cycles[inside], x50_mm[inside], "o", color="C0", ms=4, label="X50 (Rosin-Rammler fit)")
    if extrapolated.any():
        ax.plot(cycles[extrapolated], x50_mm[extrapolated], "o", mfc="none", color="C0", ms=4,
                label="X50 beyond the top sieve (extrapolated)")
    if band is not None:
        ax.axhspan(band[0], band[1], color="C2", alpha=0.25, label=band[2])
    ax.set_yscale("log")
    return _finish(fig, ax, path, "chewing cycles [1]", "median particle size X50 [mm]",
                   f"X50 against cycles{f': {title}' if title else ''}")


def _finish(fig, ax, path: Path, xlabel: str, ylabel: str, title: str) -> Path:
    """Label a one-panel figure (axes with their units, title, grid on both scales, legend) and save it."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return save(fig, path)


def force_per_cycle(cycles: np.ndarray, peak_N: np.ndarray, work_J: np.ndarray, path: Path, title: str = "") -> Path:
    """The peak force on the teeth (N) and the closing work (mJ) of each cycle."""
    fig, (top, bottom) = subplots(2, 1, figsize=(8, 6), sharex=True)
    top.bar(cycles, peak_N, color="C1")
    top.set_ylabel("peak force [N]")
    top.set_title(f"Force and work per cycle{f': {title}' if title else ''}")
    bottom.bar(cycles, 1e3 * work_J, color="C4")
    bottom.set_ylabel("closing work [mJ]")
    bottom.set_xlabel("chewing cycle [1]")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    return save(fig, path)


__all__ = ["distribution", "force_per_cycle", "x50"]
