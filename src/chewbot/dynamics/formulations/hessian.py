"""Inverse dynamics by the Hessian method (seed 000, Sects. 4 and 5.1; Abo-Shanab 2020).

The rates of the constraint Jacobians come from the Hessians H_i of the closure equations h_i with respect to
q = [theta; q_EE] (Eqs. 20-23): d/dt (dh_i/dq_j) = q_dot' H_i(:, j), so the i-th diagonal entry of J_theta_dot is
q_dot' H_i(:, i) and the i-th row of J_qEE_dot is q_dot' H_i(:, 7:n).

The Coriolis-centrifugal matrix comes from the Hessian of T with respect to U = [q_dot; q] (Eq. 48). Its block
H12 = H(1:n, n+1:2n) = d(M q_dot)/dq is *not* M_dot as Eq. (49) prints, but it has the two products that the
equations of motion need: H12 q_dot = M_dot q_dot and 1/2 H12' q_dot = dT/dq. Hence

    C = H12 - 1/2 H12'      (Eq. 52 with H12 for M_dot),

whose C q_dot = d/dt(dT/dq_dot) - M q_ddot - dT/dq is exact. The torques follow from Eqs. (53)-(54),
:mod:`chewbot.dynamics.formulations.dalembert`.
"""

from __future__ import annotations

import casadi as ca

from chewbot.dynamics.base import Dynamics
from chewbot.dynamics.contact import contact_kernels, frictionless_dynamics
from chewbot.dynamics.formulations.dalembert import Rates, reduced_kernel, reduced_sample_torques, reduced_torques
from chewbot.dynamics.energy import Energy, require_euler_angles
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model


def hessian_rates(e: Energy) -> Rates:
    """J_theta_dot, J_qEE_dot (Eqs. 20-23) and C (Eqs. 48-52) from Hessians of h_i and of T."""
    n, s = e.n, e.kin
    rows = [ca.mtimes(e.dq.T, ca.hessian(s.H[i], e.q)[0]) for i in range(6)]  # q_dot' H_i
    J_theta_dot = ca.vertcat(*(row[i] for i, row in enumerate(rows)))
    J_qEE_dot = ca.vertcat(*(row[6:] for row in rows))
    H = ca.hessian(e.T, ca.vertcat(e.dq, e.q))[0]
    H12 = H[:n, n:]
    return Rates(J_theta_dot, J_qEE_dot, H12 - 0.5 * H12.T)


def hessian(model: Model, kin: Kinematics, *, side: str | None = None, contact: str = "bilateral") -> Dynamics:
    """Minimum-norm actuator torques by the Hessian method (Eq. 54); the target's redundancy resolved by the
    pseudo-inverse, the 6RSS's torques unique; the target's normal forces N_L, N_R, and under the ``unilateral``
    ``contact`` model the unilateral fallback (:mod:`chewbot.dynamics.contact`). ``side`` overrides the bite side
    of ``kin``. The model is frictionless (no ``goal``, no ``friction``: those are Newton-Euler's)."""
    require_euler_angles(kin, "hessian")
    tau = reduced_torques(model, kin, "hessian", hessian_rates, side)
    return frictionless_dynamics("hessian", model, kin, tau, side=side, contact=contact,
                                 info={"equations": "seed 000 Eqs. 20-23, 37-54", "friction": False})


def kernels(mechanism: str, orientation: str) -> list:
    """The compiled kernels of a run: the terms of Eq. (53), and the target's normal-force map."""
    return [reduced_kernel(mechanism, "hessian", hessian_rates), *contact_kernels(mechanism)]


def sample_torques(mechanism: str):
    """A controller's inverse dynamics of one sample (:func:`chewbot.dynamics.formulations.dalembert.reduced_sample_torques`)."""
    return reduced_sample_torques(mechanism, "hessian", hessian_rates)
