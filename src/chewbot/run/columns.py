"""The columns of results.csv that every run has: the kinematics of the task (:func:`kinematics_table`) and the
transmission angles and conditioning of the chains (:func:`singularity_columns`). Their names are fixed: later
stages, the report and users' scripts rely on them."""

from __future__ import annotations

import numpy as np

from chewbot.kinematics.motion import Kinematics
from chewbot.table import Table
from chewbot.units import rate_unit

POSE_NAMES = ("X", "Y", "Z", "alpha", "beta", "gamma")
POSE_UNITS = ("m", "m", "m", "rad", "rad", "rad")

_LEVEL = ("", "rate of the ", "second rate of the ")


def kinematics_table(kin: Kinematics) -> Table:
    """The kinematic columns of ``results.csv`` (names fixed: later stages and scripts rely on them)."""
    table = Table()
    table.add("t", kin.t, "s", "time")
    for order, (arr, prefix) in enumerate(((kin.X, ""), (kin.dX, "d"), (kin.ddX, "dd"))):
        for j, name in enumerate(POSE_NAMES):
            table.add(prefix + name, arr[:, j], rate_unit(POSE_UNITS[j], order),
                      _LEVEL[order] + "pose of the mandible: O_M in {S}, XYZ Euler angles")
    for order, (arr, prefix) in enumerate(((kin.theta, ""), (kin.dtheta, "d"), (kin.ddtheta, "dd"))):
        table.add_block([f"{prefix}theta{i + 1}" for i in range(6)], arr, rate_unit("rad", order), _LEVEL[order] + "actuator angle")
    if kin.orientation == "euler-parameters":
        for order, (arr, prefix) in enumerate(((kin.e, ""), (kin.de, "d"), (kin.dde, "dd"))):
            table.add_block([f"{prefix}e{i}" for i in range(4)], arr, "1" if order == 0 else rate_unit("1", order),
                            _LEVEL[order] + "Euler parameters of the mandible (e0 scalar)")
    table.add_block(["Fx", "Fy", "Fz"], kin.force, "N", "bite force on the mandible at the molar, in {S}")
    return table


def singularity_columns(table: Table, kin: Kinematics) -> None:
    """The transmission angles mu1..mu6 and kappa_J of the chains' Jacobian (docs/conventions.md)."""
    table.add_block([f"mu{i + 1}" for i in range(6)], np.arcsin(np.clip(kin.transmission, 0.0, 1.0)), "rad",
                    "transmission angle of chain i (90 deg best, 0 at the dead point)")
    table.add("kappa_J", kin.kappa, "1", "reciprocal condition number of the chains' Jacobian J_theta1, columns scaled (0: singular)")
