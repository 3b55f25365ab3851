"""Computed torque: the inverse dynamics at the measured state with PD on the independent coordinates.

    tau = ID(q, q_dot, q_ddot_ref + kd e_dot + kp e),   e = q_ref - q,

with kp = (2 pi f)^2, kd = 2 zeta (2 pi f) per coordinate (``computed_torque.frequency_Hz``, ``.damping``): with the
exact model the error obeys e_ddot + kd e_dot + kp e = 0.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from chewbot.simulation.controllers.gains import COORDINATES, Entries, ErrorDynamics, Gain
from chewbot.simulation.controllers.law import CompiledLaw, inverse_function


class Gains(ErrorDynamics):
    """``[computed_torque]``: the error dynamics' natural frequency (Hz) and damping ratio, per coordinate."""

    frequency_Hz: Annotated[Gain, Entries(COORDINATES)]
    damping: Annotated[Gain, Entries(COORDINATES)]

    # the exported step's comment on its gains vector
    VECTOR: ClassVar[str] = "kp (1/s^2) of each coordinate, then kd (1/s): ddq = ddq_ref + kd e_dot + kp e"


def law(x: dict, mechanism: str, inverse):
    g = Gains.layout(x["q"].numel()).split(x["gains"])
    ddq = x["ddq_ref"] + g["kd"] * (x["dq_ref"] - x["dq"]) + g["kp"] * (x["q_ref"] - x["q"])
    return inverse_function(mechanism, inverse)(x["q"], x["dq"], ddq, x["B"], x["F_B"], x["p"])


def build(parts) -> CompiledLaw:
    return CompiledLaw(parts)
