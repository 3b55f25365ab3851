"""How far the chains' Jacobian is from losing rank along a task: a conditioning measure without units.

J_theta1 = -J_theta^-1 J_qEE (seed 000, Sect. 4) maps the rates of the mandible's coordinates to the crank
rates, theta_dot = J_theta1 q_dot_EE. It loses rank at a parallel (type II) singularity, where the actuators no
longer fix the mandible's motion, and grows without bound at a serial one (a chain at its dead point, where the
transmission angle vanishes). Its condition number depends on the units of q_EE (m against rad), so its
columns are scaled to unit length first: by van der Sluis' theorem this equilibrated condition number is
within a factor sqrt(n) of the smallest that any choice of units gives, so a small kappa is a property of the
mechanism, not of the units. docs/conventions.md gives the threshold and what the default task reaches.
"""

from __future__ import annotations

import numpy as np

import casadi as ca

from chewbot.casadi_tools import compiled, evaluate
from chewbot.kinematics.motion import euler_angle_columns
from chewbot.kinematics.symbolic import symbolic
from chewbot.model import Model


def reciprocal_condition(J: np.ndarray) -> np.ndarray:
    """kappa = sigma_min / sigma_max of each matrix of J (N, 6, n) with its columns scaled to unit length: (N,),
    1 for orthonormal columns, 0 where J loses rank."""
    J = J / np.linalg.norm(J, axis=1, keepdims=True)
    sv = np.linalg.svd(J, compute_uv=False)
    return sv[:, -1] / sv[:, 0]


def jacobian_conditioning(model: Model, theta: np.ndarray, X: np.ndarray) -> np.ndarray:
    """kappa (N,) of J_theta1 along a motion: theta (N, 6) rad, X (N, 6) = [X, Y, Z, alpha, beta, gamma] (m, rad).

    Always evaluated in Euler angles (X, Y, alpha, beta for the target, all six for the 6RSS), so that the same
    motion gets the same value whichever orientation a run uses.
    """
    (J_theta1,) = evaluate(_chain_jacobian(model), theta, X[:, euler_angle_columns(model)])
    return reciprocal_condition(J_theta1)


def _chain_jacobian(model: Model) -> ca.Function:
    """(theta, q_EE in Euler angles) -> J_theta1, compiled (cached per model): J_theta1 alone, not the other
    Jacobians of chewbot.kinematics.functions.jacobians_function, costs a third of their time."""

    def build():
        s = symbolic(model, "euler-angles")
        return compiled(ca.Function(f"chain_jacobian_{model.mechanism}", [s.theta, s.q], [s.J_theta1()], ["theta", "q"], ["J_theta1"]))

    return model.cached(("conditioning", "J_theta1"), build)
