"""PNG figures of a run (matplotlib), the equivalents of the papers' figures. Every axis says its unit."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from chewbot.results import Table  # noqa: E402

LEVELS = (("", "displacement"), ("d", "velocity"), ("dd", "acceleration"))


def _save(fig, path: Path) -> Path:
    """Save a figure (every figure has a title: its own or one of its panels')."""
    if not fig.get_suptitle() and not any(ax.get_title() for ax in fig.axes):
        plt.close(fig)
        raise ValueError(f"{path.name}: a figure without a title")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def task_space(table: Table, path: Path) -> Path:
    """Motion of the mandible: X, Y, Z and alpha, beta, gamma with rates (seed 000, Fig. 3)."""
    fig, axes = plt.subplots(3, 2, figsize=(11, 8), sharex=True)
    t = table["t"]
    for row, (prefix, level) in enumerate(LEVELS):
        tr, rot = axes[row]
        for name in ("X", "Y", "Z"):
            tr.plot(t, table[prefix + name] * 1e3, label=prefix + name)
        for name in ("alpha", "beta", "gamma"):
            rot.plot(t, np.degrees(table[prefix + name]), label=prefix + name)
        unit = ["", "/s", "/s²"][row]
        tr.set_ylabel(f"translation {level} [mm{unit}]")
        rot.set_ylabel(f"rotation {level} [deg{unit}]")
        for ax in (tr, rot):
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
            ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time t [s]")
    fig.suptitle("Motion of the mandible (task space)")
    return _save(fig, path)


def joint_space(table: Table, path: Path) -> Path:
    """Motion of the six actuators: theta, theta_dot, theta_ddot (seed 000, Fig. 4)."""
    fig, axes = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
    t = table["t"]
    for ax, (prefix, level), unit in zip(axes, LEVELS, ("deg", "deg/s", "deg/s²")):
        for i in range(1, 7):
            ax.plot(t, np.degrees(table[f"{prefix}theta{i}"]), label=f"{prefix}θ{i}")
        ax.set_ylabel(f"actuator {level} [{unit}]")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time t [s]")
    fig.suptitle("Motion of the actuators (joint space)")
    return _save(fig, path)


def bite_force(table: Table, path: Path) -> Path:
    """Bite force on the mandible in {S} (seed 000, Fig. 5)."""
    fig, ax = plt.subplots(figsize=(11, 3.5))
    for name in ("Fx", "Fy", "Fz"):
        ax.plot(table["t"], table[name], label=name)
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("bite force F_B [N]")
    ax.set_title("Bite force F_B on the mandible at the molar, in {S}")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)
