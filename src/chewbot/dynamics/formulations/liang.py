"""Inverse dynamics with Liang's derivative method (seed 000, Eq. 61; Liang et al. 2017).

Same Lagrange-d'Alembert model as the Hessian method (:mod:`chewbot.dynamics.formulations.dalembert`), but the rates come from
the partial derivatives of the matrices themselves:

    J_dot = dJ/dq' (q_dot kron I_c)                                  (c: columns of J)
    C     = dM/dq' (q_dot kron I_n) - 1/2 (I_n kron q_dot)' dM/dq

with dA/dq' = [dA/dq_1 ... dA/dq_n] (side by side) and dA/dq = [dA/dq_1; ...; dA/dq_n] (stacked). The first term
of C is M_dot, the second has the rows q_dot' dM/dq_i, so C q_dot = M_dot q_dot - dT/dq: as a matrix this C
differs from the Hessian method's (H12 - 1/2 H12'), C q_dot is the same.
"""

from __future__ import annotations

import casadi as ca

from chewbot.dynamics.base import Dynamics
from chewbot.dynamics.contact import contact_kernels, frictionless_dynamics
from chewbot.dynamics.formulations.dalembert import Rates, reduced_kernel, reduced_sample_torques, reduced_torques
from chewbot.dynamics.energy import Energy, require_euler_angles
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model


def _partials(A: ca.SX, q: ca.SX) -> list[ca.SX]:
    """[dA/dq_1, ..., dA/dq_n], each the shape of A."""
    jac = ca.jacobian(ca.vec(A), q)
    return [ca.reshape(jac[:, k], A.size1(), A.size2()) for k in range(q.numel())]


def matrix_rate(A: ca.SX, q: ca.SX, dq: ca.SX) -> ca.SX:
    """A_dot = dA/dq' (q_dot kron I) (Eq. 61, first two lines)."""
    return ca.mtimes(ca.horzcat(*_partials(A, q)), ca.kron(dq, ca.SX.eye(A.size2())))


def liang_rates(e: Energy) -> Rates:
    """J_theta_dot, J_qEE_dot and C of Eq. (61)."""
    s, n = e.kin, e.n
    dM = _partials(e.M, e.q)
    C = (ca.mtimes(ca.horzcat(*dM), ca.kron(e.dq, ca.SX.eye(n)))
         - 0.5 * ca.mtimes(ca.kron(ca.SX.eye(n), e.dq).T, ca.vertcat(*dM)))
    return Rates(ca.diag(matrix_rate(s.J_theta(), e.q, e.dq)), matrix_rate(s.J_qEE(), e.q, e.dq), C)


def liang(model: Model, kin: Kinematics, *, side: str | None = None, contact: str = "bilateral") -> Dynamics:
    """Minimum-norm actuator torques (Eq. 54) with J_dot and C by Liang's method (Eq. 61), the target's normal
    forces and the ``contact`` model as :func:`chewbot.dynamics.formulations.hessian.hessian`. ``side`` overrides the bite side
    of ``kin``."""
    require_euler_angles(kin, "liang")
    tau = reduced_torques(model, kin, "liang", liang_rates, side)
    return frictionless_dynamics("liang", model, kin, tau, side=side, contact=contact,
                                 info={"equations": "seed 000 Eqs. 37-54, 61", "friction": False})


def kernels(mechanism: str, orientation: str) -> list:
    """The compiled kernels of a run: the terms of Eq. (53), and the target's normal-force map."""
    return [reduced_kernel(mechanism, "liang", liang_rates), *contact_kernels(mechanism)]


def sample_torques(mechanism: str):
    """A controller's inverse dynamics of one sample (:func:`chewbot.dynamics.formulations.dalembert.reduced_sample_torques`)."""
    return reduced_sample_torques(mechanism, "liang", liang_rates)
