"""Impedance: springs and dampers in the task coordinates around the reference, on top of the inverse dynamics.

    tau = ID(q, q_dot, q_ddot_ref) + J_theta1 (J_theta1' J_theta1)^-1 J' [K (y_ref - y) + D (y_dot_ref - y_dot)],

y = (x, y, z of the molar point, alpha) (:func:`~chewbot.simulation.controllers.law.task_space_sx`, the target only):
the least-norm torques of the generalised force J' (K e + D e_dot), the molar point held to the reference by springs
and dampers, alpha likewise.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

import casadi as ca
import numpy as np

from chewbot.compiled.layout import Layout
from chewbot.simulation.controllers.gains import Entries, Gain, Section
from chewbot.simulation.controllers.law import CompiledLaw, inverse_function, task_space_sx


class Gains(Section):
    """``[impedance]``: the molar point's stiffness (N/m) and damping (N s/m) along x, y, z, alpha's (N m/rad,
    N m s/rad)."""

    stiffness_N_per_m: Annotated[Gain, Entries(3)]
    damping_Ns_per_m: Annotated[Gain, Entries(3)]
    angle_stiffness_Nm_per_rad: Annotated[Gain, Entries(1)]
    angle_damping_Nms_per_rad: Annotated[Gain, Entries(1)]

    VECTOR: ClassVar[str] = "K of x, y, z (N/m) and alpha (N m/rad), then D (N s/m, N m s/rad)"

    @classmethod
    def layout(cls, n: int) -> Layout:
        return Layout.of(stiffness=n, damping=n)

    def vector(self) -> np.ndarray:
        K = np.concatenate([self.stiffness_N_per_m, self.angle_stiffness_Nm_per_rad])
        return self.layout(K.size).pack(stiffness=K, damping=np.concatenate([self.damping_Ns_per_m, self.angle_damping_Nms_per_rad]))


def law(x: dict, mechanism: str, inverse):
    ID = inverse_function(mechanism, inverse)
    now = task_space_sx(x["q"], x["dq"], x["B"], x["p"], mechanism)
    ref = task_space_sx(x["q_ref"], x["dq_ref"], x["B"], x["p"], mechanism)
    g = Gains.layout(now["y"].numel()).split(x["gains"])
    wrench = g["stiffness"] * (ref["y"] - now["y"]) + g["damping"] * (ref["dy"] - now["dy"])
    J1 = now["J_theta1"]
    return (ID(x["q"], x["dq"], x["ddq_ref"], x["B"], x["F_B"], x["p"])
            + ca.mtimes(J1, ca.solve(ca.mtimes(J1.T, J1), ca.mtimes(now["J"].T, wrench))))


def build(parts) -> CompiledLaw:
    return CompiledLaw(parts)
