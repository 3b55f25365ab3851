"""How far the chains' Jacobian is from losing rank along a task: a conditioning measure without units.

J_theta1 = -J_theta^-1 J_qEE (seed 000, Sect. 4) maps the rates of the mandible's coordinates to the crank
rates, theta_dot = J_theta1 q_dot_EE. It loses rank at a parallel (type II) singularity, where the actuators no
longer fix the mandible's motion, and grows without bound at a serial one (a chain at its dead point, where the
transmission angle vanishes). Its condition number depends on the units of q_EE (m against rad), so its
columns are scaled to unit length first: by van der Sluis' theorem this equilibrated condition number is
within a factor sqrt(n) of the smallest that any choice of units gives, so a small kappa is a property of the
mechanism, not of the units. It is always taken in Euler angles (the fused kinematics kernel gives J_theta1 in
them whatever the run's orientation), so the same motion gets the same value. docs/conventions.md gives the
threshold and what the default task reaches.
"""

from __future__ import annotations

import numpy as np


def reciprocal_condition(J: np.ndarray) -> np.ndarray:
    """kappa = sigma_min / sigma_max of each matrix of J (N, 6, n) with its columns scaled to unit length: (N,),
    1 for orthonormal columns, 0 where J loses rank (singular values, not the Gram matrix's eigenvalues, which
    would square the condition number and blur kappa below 1e-8)."""
    J = J / np.linalg.norm(J, axis=1, keepdims=True)
    sv = np.linalg.svd(J, compute_uv=False)
    return sv[:, -1] / sv[:, 0]


def jacobian_conditioning(model, q: np.ndarray) -> np.ndarray:
    """kappa (N,) of J_theta1 at poses q (N, 4) (target: X, Y, alpha, beta) or (N, 6) (6RSS: X_EE), m and rad."""
    from chewbot.compiled.kernels import evaluate, native
    from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel

    q = np.atleast_2d(q)
    out = evaluate(native(kinematics_kernel(model.mechanism, "euler-angles")), q, 0 * q, 0 * q, model.vector())
    return reciprocal_condition(out[KINEMATICS_OUTPUTS.index("J_theta1_angles")])
