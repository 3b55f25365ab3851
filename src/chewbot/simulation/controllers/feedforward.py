"""Feedforward: the inverse dynamics of the reference, no feedback.

    tau = ID(q_ref, q_dot_ref, q_ddot_ref, F_B)

with the controller's inverse dynamics ID (:class:`~chewbot.simulation.options.ControllerDynamics`) and the bite
force it knows. Open-loop unstable on both robots (errors grow like e^(15 t) on the target): what the model alone
does, for comparison.
"""

from __future__ import annotations

from chewbot.simulation.controllers.law import CompiledLaw, inverse_function

Gains = None  # no gains


def law(x: dict, mechanism: str, inverse):
    """tau of :data:`~chewbot.simulation.controllers.law.CONTROL_INPUTS` ``x``."""
    return inverse_function(mechanism, inverse)(x["q_ref"], x["dq_ref"], x["ddq_ref"], x["B"], x["F_B"], x["p"])


def build(parts) -> CompiledLaw:
    return CompiledLaw(parts)
