"""PNG figures of a simulation (``chewbot simulate``) and of a comparison of controllers. Every axis says its unit."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chewbot.report.plotting import joint_columns, per_joint, save, subplots
from chewbot.table import Table
from chewbot.units import factor, shown


def error_columns(table: Table) -> list[str]:
    """The tracking-error columns e_X, e_Y, ... of a simulation's table."""
    return [name for name in table.columns if name.startswith("e_")]


def tracking_error(table: Table, path: Path, title: str = "") -> Path:
    """The tracking error of each independent coordinate over time, lengths in mm and angles in deg."""
    names = error_columns(table)
    fig, axes = subplots(len(names), 1, figsize=(10, 1.8 * len(names) + 1), sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        scale, unit = shown(table.units[name])
        ax.plot(table["t"], table[name] * scale, lw=0.9)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(f"{name} [{unit}]")
        ax.grid(alpha=0.3)
    axes[0, 0].set_title(f"Tracking error, reference minus simulated{f' ({title})' if title else ''}")
    axes[-1, 0].set_xlabel("time t [s]")
    return save(fig, path)


def saturation(table: Table, path: Path, limit: float) -> Path:
    """The commanded torques with the actuators' limit; the applied ones are these clipped at it."""
    fig, ax = subplots(figsize=(11, 4.5))
    t = table["t"]
    per_joint(ax, t, joint_columns(table, "tau_cmd"), "τ_cmd", "N·m")
    for sign in (-1, 1):
        ax.axhline(sign * limit, color="#b4461a", ls="--", lw=1.0)
    saturated = np.any(joint_columns(table, "tau_cmd") != joint_columns(table, "tau"), axis=1)
    if saturated.any():
        ax.fill_between(t, 0, 1, where=saturated, transform=ax.get_xaxis_transform(), color="#b4461a", alpha=0.15, lw=0)
    ax.set_title(f"Commanded torques and the limit ±{limit:g} N·m (shaded: saturated, {saturated.mean() * 100:.3g} % of the rows)")
    ax.set_xlabel("time t [s]")
    return save(fig, path)


def comparison(tables: dict[str, Table], path: Path) -> Path:
    """The simulations of a comparison (controllers, or engines) together: the norm of the translational (mm) and of the angular (deg) tracking
    errors, and the largest abs(tau_i) (N m), over time."""
    fig, axes = subplots(3, 1, figsize=(11, 8), sharex=True)
    for label, table in tables.items():
        t = table["t"]
        names = error_columns(table)
        lin = [n for n in names if table.units[n] == "m"]
        ang = [n for n in names if table.units[n] == "rad"]
        axes[0].plot(t, np.linalg.norm(np.column_stack([table[n] for n in lin]), axis=1) / factor("mm"), lw=0.9, label=label)
        axes[1].plot(t, np.degrees(np.linalg.norm(np.column_stack([table[n] for n in ang]), axis=1)), lw=0.9, label=label)
        axes[2].plot(t, np.max(np.abs(joint_columns(table, "tau")), axis=1), lw=0.9, label=label)
    for ax, label in zip(axes, ("position error [mm]", "orientation error [deg]", "largest abs(τ_i) [N·m]")):
        ax.set_ylabel(label)
        ax.set_yscale("log") if ax is not axes[2] else None
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    axes[0].set_title("Simulations compared: tracking error (norms over the coordinates) and torques")
    axes[-1].set_xlabel("time t [s]")
    return save(fig, path)
