"""Independent PD on the crank angles.

    tau_i = kp_i (theta_ref,i - theta_i) + kd_i (theta_dot_ref,i - theta_dot_i)

on each crank, the crank angles and rates of the state and of the reference from the controller's model (its inverse
kinematics); the angles' difference wrapped to (-pi, pi]. No inverse dynamics.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

import casadi as ca
import numpy as np

from chewbot.compiled.layout import Layout
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.simulation.controllers.gains import Entries, Gain, Section
from chewbot.simulation.controllers.law import CompiledLaw
from chewbot.simulation.forward import ORIENTATION


class Gains(Section):
    """``[pd]``: stiffness (N m/rad) and damping (N m s/rad) of each crank."""

    kp_Nm_per_rad: Annotated[Gain, Entries(6)]
    kd_Nms_per_rad: Annotated[Gain, Entries(6)]

    VECTOR: ClassVar[str] = "kp (N m/rad) of the six cranks, then kd (N m s/rad)"

    @classmethod
    def layout(cls, n: int) -> Layout:
        return Layout.of(kp=6, kd=6)

    def vector(self) -> np.ndarray:
        return self.layout(6).pack(kp=self.kp_Nm_per_rad, kd=self.kd_Nms_per_rad)


def law(x: dict, mechanism: str, inverse):
    n = x["q"].numel()
    g = Gains.layout(n).split(x["gains"])
    kin = kinematics_kernel(mechanism, ORIENTATION).graph()
    i_theta, i_dtheta = KINEMATICS_OUTPUTS.index("theta"), KINEMATICS_OUTPUTS.index("dtheta")
    now, ref = kin(x["q"], x["dq"], ca.SX.zeros(n), x["p"]), kin(x["q_ref"], x["dq_ref"], ca.SX.zeros(n), x["p"])
    d_theta = ref[i_theta] - now[i_theta]
    d_theta = ca.atan2(ca.sin(d_theta), ca.cos(d_theta))  # the angles are within +-2 pi: their difference wrapped
    return g["kp"] * d_theta + g["kd"] * (ref[i_dtheta] - now[i_dtheta])


def build(parts) -> CompiledLaw:
    return CompiledLaw(parts)
