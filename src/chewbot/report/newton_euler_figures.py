"""PNG figures of a Newton–Euler run, after seed 001's Figs. 10–13. Every axis says its unit.

Each takes a run's results table (columns of :func:`chewbot.dynamics.formulations.newton_euler.newton_euler`: ``tau1..6``,
``tau_f1..6``, ``N_L``, ``N_R``, ``fT_L_x..``, ``friction_share1..6``, ``FS1_x..``, ``MG1_x..``); the HKP
panels are left out for a mechanism without HKPs (6RSS).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chewbot.report.plotting import JOINTS, joint_columns, per_joint, save, subplots
from chewbot.table import Table


def torques_and_contacts(table: Table, path: Path) -> Path:
    """Actuating torques, actuator friction torques, HKP normal and friction forces (seed 001, Fig. 10)."""
    hkp = "N_L" in table
    fig, axes = subplots(4 if hkp else 2, 1, figsize=(11, 11 if hkp else 6), sharex=True)
    t = table["t"]
    per_joint(axes[0], t, joint_columns(table, "tau"), "τ", "N·m")
    per_joint(axes[1], t, joint_columns(table, "tau_f"), "τ_f", "N·m")
    axes[0].set_title("Actuating torques and actuator friction torques (Newton–Euler)")
    if hkp:
        for side in ("L", "R"):
            axes[2].plot(t, table[f"N_{side}"], label=f"N_{side}")
            f = np.linalg.norm(np.column_stack([table[f"fT_{side}_{c}"] for c in "xyz"]), axis=1)
            axes[3].plot(t, f, label=f"|f_T,{side}|")
        axes[2].set_ylabel("HKP normal force N [N]")
        axes[3].set_ylabel("HKP friction force |f_T| [N]")
        for ax in axes[2:]:
            ax.legend(loc="upper right", fontsize=8)
            ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time t [s]")
    return save(fig, path)


def friction_share(table: Table, path: Path) -> Path:
    """Friction share of each actuator, percent of its torque, on a log axis (seed 001, Fig. 11, Eq. 75)."""
    fig, ax = subplots(figsize=(11, 4))
    share = joint_columns(table, "friction_share")
    share = np.where(np.isfinite(share) & (share > 0), share, np.nan)
    per_joint(ax, table["t"], share, "share", "%")
    if np.isfinite(share).any():  # without friction every share is 0: nothing to draw on a log axis
        ax.set_yscale("log")
        ax.set_ylim(bottom=1e-2)  # shares below 0.01 % are invisible anyway; keeps the peaks readable
    ax.axhline(100.0, color="k", lw=0.6, ls="--")
    ax.set_xlabel("time t [s]")
    ax.set_title("Friction torque over actuating torque (100 %: dashed)")
    return save(fig, path)


def coupler_forces(table: Table, path: Path) -> Path:
    """Constraint forces at S_1..S_6 (crank on coupler), components in {S} (seed 001, Fig. 12)."""
    return _per_chain(table, path, "FS{}_{}", "xyz", "F_S", "N", "Constraint forces at S_i, in {S}")


def crank_moments(table: Table, path: Path) -> Path:
    """Constraint moments at G_1..G_6 about the x and y axes of {C_i0} (seed 001, Fig. 13)."""
    return _per_chain(table, path, "MG{}_{}", "xy", "M_G", "N·m", "Constraint moments at G_i, about x, y of {C_i0}")


def _per_chain(table, path, pattern, comps, label, unit, title) -> Path:
    fig, axes = subplots(3, 2, figsize=(11, 8), sharex=True)
    t = table["t"]
    for i, ax in zip(JOINTS, axes.ravel()):
        for c in comps:
            ax.plot(t, table[pattern.format(i, c)], lw=0.9, label=f"{label}{i},{c}")
        ax.set_ylabel(f"{label}{i} [{unit}]")
        ax.legend(loc="upper right", fontsize=7, ncol=3)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time t [s]")
    fig.suptitle(title)
    return save(fig, path)


# The Newton-Euler figures of a run: file name -> drawing function.
FIGURES = {"ne_torques_contacts.png": torques_and_contacts, "ne_friction_share.png": friction_share,
           "ne_coupler_forces.png": coupler_forces, "ne_crank_moments.png": crank_moments}
