"""Per-sample CasADi functions of the kinematics, built once per (model, orientation) and cached.

Each is meant to be mapped over a trajectory with :func:`chewbot.casadi_tools.evaluate`.
"""

from __future__ import annotations

import casadi as ca

from chewbot.kinematics.symbolic import Symbolic, Z_parasitic_sx, gamma_parasitic_sx, symbolic
from chewbot.model import Model
from chewbot.rotation import matrix_from_euler_angles_sx


def _fn(model: Model, orientation: str, name: str, build):
    return model.cached(("fn", orientation, name), lambda: build(symbolic(model, orientation)))


def pose_function(model: Model, orientation: str) -> ca.Function:
    """q -> (pose, p, R): X_EE in the orientation's parametrisation, O_M (m) and R (3x3) in {S}."""

    def build(s: Symbolic):
        return ca.Function("pose", [s.q], [s.pose, s.p, s.R], ["q"], ["pose", "p", "R"])

    return _fn(model, orientation, "pose", build)


def points_function(model: Model, orientation: str) -> ca.Function:
    """q -> positions in {S} of the condyles T_L, T_R, the incisor I and the molars B_L, B_R (m)."""

    def build(s: Symbolic):
        m = model
        pts = [s.point(x) for x in (m.hkp.T_L, m.hkp.T_R, m.incisor, m.molar_left, m.molar_right)]
        return ca.Function("points", [s.q], pts, ["q"], ["T_L", "T_R", "I", "B_L", "B_R"])

    return _fn(model, orientation, "points", build)


def point_jacobian_function(model: Model, orientation: str, body_point) -> ca.Function:
    """q -> (position, Jacobian d position / d q_EE) of a point fixed in {M}."""
    s = symbolic(model, orientation)
    x = s.point(body_point)
    return ca.Function("point_jacobian", [s.q], [x, ca.jacobian(x, s.q)], ["q"], ["x", "J"])


def jacobians_function(model: Model, orientation: str) -> ca.Function:
    """(theta, q) -> J_theta (diagonal, as a 6-vector), J_qEE, J_theta1, M_J, M_0a, M_0b (seed 000, Sect. 4)."""

    def build(s: Symbolic):
        return ca.Function(
            "jacobians",
            [s.theta, s.q],
            [ca.diag(s.J_theta()), s.J_qEE(), s.J_theta1(), s.M_J(), s.M_0a(), s.M_0b()],
            ["theta", "q"],
            ["J_theta", "J_qEE", "J_theta1", "M_J", "M_0a", "M_0b"],
        )

    return _fn(model, orientation, "jacobians", build)


def jacobian_rates_function(model: Model, orientation: str) -> ca.Function:
    """(theta, q, dq) -> J_theta2, J_theta3, J_theta4 (seed 000, Eqs. 17-19)."""

    def build(s: Symbolic):
        return ca.Function("jacobian_rates", [s.theta, s.q, s.dq], [s.J_theta2(), s.J_theta3(), s.J_theta4()],
                           ["theta", "q", "dq"], ["J_theta2", "J_theta3", "J_theta4"])

    return _fn(model, orientation, "jacobian_rates", build)


def rates_function(model: Model, orientation: str) -> ca.Function:
    """(theta, q, dq, ddq) -> theta_dot, theta_ddot, twist, twist rate, pose rate, pose acceleration."""

    def build(s: Symbolic):
        dth, ddth = s.theta_rates()
        dpose = ca.mtimes(s.M_J(), s.dq)
        ddpose = ca.mtimes(s.M_J(), s.ddq) + ca.jtimes(dpose, s.q, s.dq)
        return ca.Function(
            "rates",
            [s.theta, s.q, s.dq, s.ddq],
            [dth, ddth, s.twist(), s.twist_rate(), dpose, ddpose],
            ["theta", "q", "dq", "ddq"],
            ["dtheta", "ddtheta", "twist", "twist_rate", "dpose", "ddpose"],
        )

    return _fn(model, orientation, "rates", build)


def closure_function(model: Model, orientation: str) -> ca.Function:
    """(theta, q) -> closure residual H (m^2), its Jacobian J_qEE, and the unit-norm residual (parameters)."""

    def build(s: Symbolic):
        unit = s.unit if s.unit is not None else ca.SX(0)
        return ca.Function(
            "closure",
            [s.theta, s.q],
            [s.H, s.J_qEE(), unit, ca.jacobian(unit, s.q)],
            ["theta", "q"],
            ["H", "J_qEE", "unit", "J_unit"],
        )

    return _fn(model, orientation, "closure", build)


def parasitic_function(model: Model) -> ca.Function:
    """Lift a motion in (X, Y, alpha, beta) to the full X_EE with the sockets' parasitic Z and gamma.

    (q, dq, ddq) of the four independent coordinates -> X_EE, X_EE_dot, X_EE_ddot (6 each), exact chain rule.
    It uses the model's HKP geometry whatever the mechanism: for the 6RSS this gives the target's motion.
    """

    def build():
        q, dq, ddq = ca.SX.sym("q", 4), ca.SX.sym("dq", 4), ca.SX.sym("ddq", 4)
        gamma = gamma_parasitic_sx(model, q[2], q[3])
        Z = Z_parasitic_sx(model, q[0], matrix_from_euler_angles_sx(q[2], q[3], gamma))
        x = ca.vertcat(q[0], q[1], Z, q[2], q[3], gamma)
        dx = ca.jtimes(x, q, dq)
        ddx = ca.jtimes(x, q, ddq) + ca.jtimes(dx, q, dq)
        return ca.Function("parasitic", [q, dq, ddq], [x, dx, ddx], ["q", "dq", "ddq"], ["X", "dX", "ddX"])

    return model.cached(("fn", "parasitic"), build)
