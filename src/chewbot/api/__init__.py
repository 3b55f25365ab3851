"""The Python API: the verbs a dynamics user expects, as free functions of a model (Pinocchio's style), one call
each, on one sample or many (docs/api.md).

``load_model`` (the model, immutable), ``inverse_kinematics``, ``forward_kinematics``, ``inverse_dynamics``,
``forward_dynamics``, ``read_results`` (a results folder as a DataFrame), ``simulate`` (``chewbot simulate`` in
memory). They wrap the functions of the layers below,
which keep their names in their modules (:func:`chewbot.dynamics.registry.inverse_dynamics`,
:mod:`chewbot.kinematics.ik`, :func:`chewbot.simulation.forward.forward_dynamics`); ``chewbot.NAME`` gives each.
"""

from chewbot.api.dynamics import ForwardDynamics, InverseDynamics, forward_dynamics, inverse_dynamics
from chewbot.api.kinematics import forward_kinematics, inverse_kinematics
from chewbot.api.simulation import simulate
from chewbot.model.params import load_model
from chewbot.outputs.record import read_frame as read_results

__all__ = ["ForwardDynamics", "InverseDynamics", "forward_dynamics", "forward_kinematics", "inverse_dynamics",
           "inverse_kinematics", "load_model", "read_results", "simulate"]
