"""PNG figures of the inverse dynamics and the inertia coupling, after seed 000's Figs. 6-8. Every axis says its unit.

The first two take a run's results table (``tau1..tau6``, ``MCI1..MCI6``); the others take arrays from several runs
and serve the seed-000 study.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chewbot.report.plotting import JOINTS, joint_columns, per_joint, save, subplots
from chewbot.table import Table

def torques(table: Table, path: Path, method: str = "", contact: str = "") -> Path:
    """Actuator torques over time with the bite force below them (seed 000, Fig. 6a), and the HKP normal forces
    N_L, N_R where the run has them (the target), titled with the ``contact`` model."""
    hkp = "N_L" in table
    fig, axes = subplots(3 if hkp else 2, 1, figsize=(11, 8.5 if hkp else 6), sharex=True,
                             height_ratios=(2, 1, 1) if hkp else (2, 1))
    ax, axf = axes[0], axes[1]
    t = table["t"]
    per_joint(ax, t, joint_columns(table, "tau"), "τ", "N·m")
    ax.set_title(f"Actuator torques{f' ({method})' if method else ''}")
    _lines(axf, t, {name: table[name] for name in ("Fx", "Fy", "Fz")}, "bite force F_B [N]")
    if hkp:
        _lines(axes[2], t, {name: table[name] for name in ("N_L", "N_R")}, "HKP normal force N [N]")
        axes[2].axhline(0.0, color="k", lw=0.6)
        axes[2].set_title(f"Normal force of each plane on its condyle (> 0: pushes){f'; {contact} contact' if contact else ''}")
    axes[-1].set_xlabel("time t [s]")
    return save(fig, path)


def _lines(ax, t, series: dict, ylabel: str) -> None:
    """A few named series on ``ax``, legend at the right."""
    for name, y in series.items():
        ax.plot(t, y, label=name)
    ax.set_ylabel(ylabel)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(alpha=0.3)


def coupling_indices(table: Table, path: Path) -> Path:
    """MCI_i of the six joints over time (seed 000, Fig. 7, one column)."""
    fig, ax = subplots(figsize=(11, 4))
    per_joint(ax, table["t"], joint_columns(table, "MCI"), "MCI", "-")
    ax.set_xlabel("time t [s]")
    ax.set_title("Inertia coupling index MCI_i (Eq. 60)")
    return save(fig, path)


def torque_comparison(t: np.ndarray, panels: dict[str, np.ndarray], path: Path) -> Path:
    """Torques or torque differences (N, 6), one panel per entry, e.g. left, differences between methods, right
    (seed 000, Fig. 6)."""
    fig, axes = subplots(len(panels), 1, figsize=(11, 3.2 * len(panels)), sharex=True, squeeze=False)
    for ax, (title, tau) in zip(axes[:, 0], panels.items()):
        per_joint(ax, t, tau, "τ", "N·m")
        ax.set_title(title)
    axes[-1, 0].set_xlabel("time t [s]")
    return save(fig, path)


def mci_comparison(t: np.ndarray, panels: dict[str, np.ndarray], path: Path) -> Path:
    """MCI_i over time, one panel per mechanism (seed 000, Fig. 7)."""
    fig, axes = subplots(len(panels), 1, figsize=(11, 3.2 * len(panels)), sharex=True, sharey=True, squeeze=False)
    for ax, (title, values) in zip(axes[:, 0], panels.items()):
        per_joint(ax, t, values, "MCI", "-")
        ax.set_title(title)
    axes[-1, 0].set_xlabel("time t [s]")
    return save(fig, path)


def mci_means(means: dict[str, np.ndarray], path: Path) -> Path:
    """Mean MCI_i over the task as grouped bars, one colour per mechanism (seed 000, Fig. 8)."""
    fig, ax = subplots(figsize=(8, 4))
    width = 0.8 / len(means)
    x = np.arange(6)
    for k, (label, values) in enumerate(means.items()):
        ax.bar(x + (k - (len(means) - 1) / 2) * width, values, width, label=label)
    ax.set_xticks(x, [f"MCI{i}" for i in JOINTS])
    ax.set_ylabel("mean MCI_i over the task [-]")
    ax.set_title("Mean inertia coupling index per joint")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    return save(fig, path)
