"""Per-sample CasADi functions of the kinematics, built once per (mechanism, orientation) and cached.

Each function of a mechanism (``"target"``, ``"6rss"``) takes the model's parameter vector p as its last input
(:meth:`chewbot.model.Model.vector`); each is meant to be mapped over a trajectory with
:func:`chewbot.compiled.kernels.evaluate`.
:func:`kinematics_kernel` is the compiled kernel of :func:`chewbot.kinematics.motion.solve_kinematics`: the whole
stage in one call.
"""

from __future__ import annotations

import casadi as ca

from chewbot.compiled.kernels import KernelSpec
from chewbot.kinematics.options import check_orientation
from chewbot.kinematics.symbolic import COORDINATES, Symbolic, Z_parasitic_sx, gamma_parasitic_sx, symbolic
from chewbot.compiled.cache import cached_graph, symbols
from chewbot.model.symbolic import SymbolicModel, c_name, parameter_input
from chewbot.rotation import matrix_from_euler_angles_sx


def _fn(mechanism: str, orientation: str, name: str, inputs, outputs):
    """The function ``name`` of the symbolic kinematics: ``inputs(s)`` and ``outputs(s)`` give dicts of names to
    expressions; p is appended to the inputs."""
    params = symbols(mechanism)

    def make():
        s = symbolic(params, orientation)
        ins, outs = inputs(s), outputs(s)
        extra, names = parameter_input(s.params)
        return ca.Function(name, [*ins.values(), *extra], list(outs.values()), [*ins, *names], list(outs))

    return cached_graph(params, ("fn", orientation, name), make)


def pose_function(mechanism: str, orientation: str) -> ca.Function:
    """q -> (pose, position, R): X_EE in the orientation's parametrisation, O_M (m) and R (3x3) in {S}."""

    return _fn(mechanism, orientation, "pose", lambda s: {"q": s.q}, lambda s: {"pose": s.pose, "position": s.p, "R": s.R})


def points_function(mechanism: str, orientation: str) -> ca.Function:
    """q -> positions in {S} of the condyles T_L, T_R, the incisor I and the molars B_L, B_R (m)."""

    return _fn(mechanism, orientation, "points", lambda s: {"q": s.q}, lambda s: dict(zip(POINTS, _points(s))))


POINTS = ("T_L", "T_R", "I", "B_L", "B_R")


def _points(s: Symbolic) -> list[ca.SX]:
    m = s.params
    return [s.point(x) for x in (m.hkp.T_L, m.hkp.T_R, m.incisor, m.molar_left, m.molar_right)]


def jacobians_function(mechanism: str, orientation: str) -> ca.Function:
    """(theta, q) -> J_theta (diagonal, as a 6-vector), J_qEE, J_theta1, M_J, M_0a, M_0b (seed 000, Sect. 4)."""

    def outputs(s: Symbolic):
        return {"J_theta": ca.diag(s.J_theta()), "J_qEE": s.J_qEE(), "J_theta1": s.J_theta1(), "M_J": s.M_J(),
                "M_0a": s.M_0a(), "M_0b": s.M_0b()}

    return _fn(mechanism, orientation, "jacobians", lambda s: {"theta": s.theta, "q": s.q}, outputs)


def jacobian_rates_function(mechanism: str, orientation: str) -> ca.Function:
    """(theta, q, dq) -> J_theta2, J_theta3, J_theta4 (seed 000, Eqs. 17-19)."""

    return _fn(mechanism, orientation, "jacobian_rates", lambda s: {"theta": s.theta, "q": s.q, "dq": s.dq},
               lambda s: {"J_theta2": s.J_theta2(), "J_theta3": s.J_theta3(), "J_theta4": s.J_theta4()})


def rates_function(mechanism: str, orientation: str) -> ca.Function:
    """(theta, q, dq, ddq) -> theta_dot, theta_ddot, twist, twist rate, pose rate, pose acceleration."""

    def outputs(s: Symbolic):
        dth, ddth = s.theta_rates()
        dpose, ddpose = _rates(s.pose, s.q, s.dq, s.ddq)
        return {"dtheta": dth, "ddtheta": ddth, "twist": s.twist(), "twist_rate": s.twist_rate(), "dpose": dpose, "ddpose": ddpose}

    return _fn(mechanism, orientation, "rates", lambda s: {"theta": s.theta, "q": s.q, "dq": s.dq, "ddq": s.ddq}, outputs)


def pose_rates_function(mechanism: str, orientation: str) -> ca.Function:
    """(q, dq, ddq) -> pose, dpose, ddpose: X_EE in the orientation's parametrisation (with the parasitic
    coordinates of the target) and its exact first and second time derivatives."""

    return _fn(mechanism, orientation, "pose_rates", lambda s: {"q": s.q, "dq": s.dq, "ddq": s.ddq},
               lambda s: dict(zip(("pose", "dpose", "ddpose"), (s.pose, *_rates(s.pose, s.q, s.dq, s.ddq)))))


def _rates(x: ca.SX, q: ca.SX, dq: ca.SX, ddq: ca.SX) -> tuple[ca.SX, ca.SX]:
    """The first and second time derivatives of an expression x(q) along (q_dot, q_ddot), exact."""
    dx = ca.jtimes(x, q, dq)
    return dx, ca.jtimes(x, q, ddq) + ca.jtimes(dx, q, dq)


def closure_function(mechanism: str, orientation: str) -> ca.Function:
    """(theta, q) -> closure residual H (m^2), its Jacobian J_qEE, and the unit-norm residual (parameters)."""

    def outputs(s: Symbolic):
        unit = s.unit if s.unit is not None else ca.SX(0)
        return {"H": s.H, "J_qEE": s.J_qEE(), "unit": unit, "J_unit": ca.jacobian(unit, s.q)}

    return _fn(mechanism, orientation, "closure", lambda s: {"theta": s.theta, "q": s.q}, outputs)


def parasitic_function(params: SymbolicModel) -> ca.Function:
    """Lift a motion in (X, Y, alpha, beta) to the full X_EE with the sockets' parasitic Z and gamma.

    (q, dq, ddq) of the four independent coordinates -> X_EE, X_EE_dot, X_EE_ddot (6 each), exact chain rule.
    It uses the model's HKP geometry whatever the mechanism: for the 6RSS this gives the target's motion. Built on
    the model's numbers ``params`` (a mechanism's symbol p: p is its last input; one model's constants: folded in).
    """

    def build():
        q, dq, ddq = ca.SX.sym("q", 4), ca.SX.sym("dq", 4), ca.SX.sym("ddq", 4)
        x = lift_sx(params, q)
        dx, ddx = _rates(x, q, dq, ddq)
        extra, names = parameter_input(params)
        return ca.Function("parasitic", [q, dq, ddq, *extra], [x, dx, ddx], ["q", "dq", "ddq", *names], ["X", "dX", "ddX"])

    return cached_graph(params, ("fn", "parasitic"), build)


def lift_sx(params: SymbolicModel, q: ca.SX) -> ca.SX:
    """X_EE of the target from (X, Y, alpha, beta): the parasitic Z and gamma of the sockets."""
    gamma = gamma_parasitic_sx(params, q[2], q[3])
    Z = Z_parasitic_sx(params, q[0], matrix_from_euler_angles_sx(q[2], q[3], gamma))
    return ca.vertcat(q[0], q[1], Z, q[2], q[3], gamma)


def euler_parameters_sx(alpha, beta, gamma) -> ca.SX:
    """Euler parameters (e0 first) of R = Rx(alpha) Ry(beta) Rz(gamma): the product of the three half-angle
    rotations, smooth in the angles (e0 > 0 for rotations below pi, the sign of the NumPy conversion)."""
    ca_, sa, cb, sb, cg, sg = (f(x / 2) for x in (alpha, beta, gamma) for f in (ca.cos, ca.sin))
    return ca.vertcat(ca_ * cb * cg - sa * sb * sg, sa * cb * cg + ca_ * sb * sg,
                      ca_ * sb * cg - sa * cb * sg, ca_ * cb * sg + sa * sb * cg)


# The outputs of the kinematics kernel, in order (docs/api.md).
KINEMATICS_OUTPUTS = ("X", "dX", "ddX", "e", "de", "dde", "theta", "dtheta", "ddtheta", "twist", "twist_rate",
                      *POINTS, "reach", "transmission", "J_theta1", "J_unit", "e3_denominator", "J_theta1_angles")


def kinematics_kernel(mechanism: str, orientation: str) -> KernelSpec:
    """The whole kinematics of a sample in one compiled call: (q, dq, ddq, p) -> :data:`KINEMATICS_OUTPUTS`.

    Inputs: the independent coordinates of the motion in Euler angles, whatever ``orientation`` (X, Y, alpha, beta
    for the target, X, Y, Z, alpha, beta, gamma for the 6RSS; m, rad) and their rates, and p. Outputs: X_EE
    (with the parasitic Z and gamma) and its rates; the Euler parameters e and rates; theta from the closed-form
    inverse kinematics on the working branch (the branch signs of p; within (-2 pi, 2 pi], unwrapped along a
    trajectory by the caller), theta_dot, theta_ddot; the twist [v_OM; omega] and its rate; the points T_L,
    T_R, I, B_L, B_R in {S}; per chain the reachability ratio abs(C)/sqrt(A^2 + B^2) (> 1: out of reach) and the
    sine of the transmission angle; J_theta1 in ``orientation``'s q_EE (for the parallel-singularity check); for
    Euler parameters the gradient J_unit of abs(e)^2 - 1 and the target's p1 e0 - e2 (the denominator of the
    parasitic e3), zero otherwise; J_theta1 in Euler angles (d theta / d q, whatever ``orientation``, for the
    conditioning measure of :mod:`chewbot.kinematics.conditioning`). Everything past the inputs is computed by ``orientation``'s graph from its
    own q_EE, itself computed from the inputs (exact chain rule).
    """
    check_orientation(orientation)
    name = f"kinematics_{c_name(mechanism)}_{orientation.replace('-', '_')}"
    return KernelSpec(name, lambda params: _kinematics(params, orientation, name), (mechanism, orientation), mechanism)


def _kinematics(params: SymbolicModel, orientation: str, name: str) -> ca.Function:
    s = symbolic(params, orientation)
    m = s.params
    n = len(COORDINATES[(m.mechanism, "euler-angles")])
    q, dq, ddq = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n)
    X = lift_sx(m, q) if m.has_hkp else q
    dX, ddX = _rates(X, q, dq, ddq)
    e = euler_parameters_sx(X[3], X[4], X[5])
    de, dde = _rates(e, q, dq, ddq)
    if orientation == "euler-angles":
        qo, dqo, ddqo = q, dq, ddq
    else:
        qo = ca.vertcat(X[:2], e[:3]) if m.has_hkp else ca.vertcat(X[:3], e)
        dqo, ddqo = _rates(qo, q, dq, ddq)

    theta, ratio, sin_mu = [], [], []
    for i in range(6):  # closed-form inverse kinematics (docs/conventions.md)
        u, v = m.R_C0[i][:, 0], m.R_C0[i][:, 1]
        Lc, Lr = m.crank_length[i], m.coupler_length[i]
        d = s.coupler_end(i) - m.G[i]
        A, B, C = 2 * Lc * ca.dot(u, d), 2 * Lc * ca.dot(v, d), Lc**2 + ca.dot(d, d) - Lr**2
        ratio.append(C / ca.sqrt(A**2 + B**2))
        theta.append(ca.atan2(B, A) + m.branch[i] * ca.acos(ratio[-1]))
        sin_mu.append(ca.sqrt(ca.fmax(A**2 + B**2 - C**2, 0)) / (2 * Lc * Lr))  # kinematics.ik.transmission
    theta, ratio = ca.vertcat(*theta), ca.vertcat(*ratio)
    dth, ddth = s.theta_rates()
    J1 = s.J_theta1()
    if s.unit is not None:
        J_unit = ca.jacobian(s.unit, s.q)
        den = m.hkp.p1 * s.q[2] - s.q[4] if m.has_hkp else ca.SX(1, 1)
    else:
        J_unit, den = ca.SX(1, s.n), ca.SX(1, 1)
    outs = [X, dX, ddX, e, de, dde, theta, dth, ddth, s.twist(), s.twist_rate(), *_points(s),
            ca.fabs(ratio), ca.vertcat(*sin_mu), J1, J_unit, den]
    outs = ca.substitute(outs, [s.theta], [theta])  # theta_dot, theta_ddot and J_theta1 at the solved theta
    outs = ca.substitute(outs, [s.q, s.dq, s.ddq], [qo, dqo, ddqo])
    outs.append(ca.jacobian(outs[KINEMATICS_OUTPUTS.index("theta")], q))  # J_theta1 in Euler angles: d theta / d q
    extra, extra_names = parameter_input(m)
    return ca.Function(name, [q, dq, ddq, *extra], [ca.densify(o) for o in outs], ["q", "dq", "ddq", *extra_names],
                       list(KINEMATICS_OUTPUTS), {"cse": True})
