"""The kinematics of both mechanisms as CasADi expressions: one graph per (mechanism, orientation).

The model's numbers enter as a :class:`~chewbot.model.symbolic.SymbolicModel`: ``symbolic(symbols("target"),
orientation)`` is the graph of every target model (p a symbol), ``symbolic(folded(model), orientation)`` the same graph
with one model's numbers folded in (no p; :mod:`chewbot.compiled.cache`).

Generalised coordinates of the mandible, q_EE (docs/conventions.md):

| mechanism | orientation | q_EE | parasitic |
|---|---|---|---|
| target | euler-angles | X, Y, alpha, beta | Z, gamma |
| target | euler-parameters | X, Y, e0, e1, e2 (abs(e) = 1) | Z, e3 |
| 6rss | euler-angles | X, Y, Z, alpha, beta, gamma | - |
| 6rss | euler-parameters | X, Y, Z, e0, e1, e2, e3 (abs(e) = 1) | - |

Everything derived here is exact: Jacobians and their rates come from CasADi's automatic differentiation of
the defining equations (the closure equations h_i, Eq. 8 of seed 000, and the HKP plane equations, Eq. 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from chewbot.kinematics.options import check_orientation
from chewbot.compiled.cache import cached_graph
from chewbot.model.symbolic import SymbolicModel
from chewbot.rotation import E_sx, R_omega_sx, matrix_from_euler_angles_sx, matrix_from_euler_parameters_sx

COORDINATES = {
    ("target", "euler-angles"): ("X", "Y", "alpha", "beta"),
    ("target", "euler-parameters"): ("X", "Y", "e0", "e1", "e2"),
    ("6rss", "euler-angles"): ("X", "Y", "Z", "alpha", "beta", "gamma"),
    ("6rss", "euler-parameters"): ("X", "Y", "Z", "e0", "e1", "e2", "e3"),
}


def gamma_parasitic_sx(params: SymbolicModel, alpha, beta):
    """Parasitic gamma of the target from p1 R12 + R32 = 0 (difference of the two plane equations).

    R12 = -c_beta s_gamma, R32 = c_alpha s_beta s_gamma + s_alpha c_gamma, so
    tan(gamma) = s_alpha / (p1 c_beta - c_alpha s_beta). erratum (docs/conventions.md): seed 000 Eq. (5) prints
    "+ c_alpha s_beta", which violates the constraint.
    """
    p1 = params.hkp.p1
    return ca.atan2(ca.sin(alpha), p1 * ca.cos(beta) - ca.cos(alpha) * ca.sin(beta))


def e3_parasitic_sx(params: SymbolicModel, e0, e1, e2):
    """Parasitic e3 of the target from p1 R12 + R32 = 0: e3 = e1 (e0 + p1 e2) / (p1 e0 - e2)."""
    p1 = params.hkp.p1
    return e1 * (e0 + p1 * e2) / (p1 * e0 - e2)


def Z_parasitic_sx(params: SymbolicModel, X, R):
    """Parasitic Z of the target from the sum of the two plane equations (seed 000, Eq. 5)."""
    h = params.hkp
    t = ca.vertcat(h.T_L[0], 0.0, h.T_L[2])
    return -(h.p1 * X + h.p2 + ca.mtimes(h.p1 * R[0, :] + R[2, :], t))


@dataclass(frozen=True, eq=False)
class Symbolic:
    """Symbols and expressions of one mechanism in one orientation parametrisation.

    ``params``: the model's numbers (the symbol p, or one model's constants); ``q``, ``dq``, ``ddq``: q_EE and
    its rates; ``theta``, ``dtheta``: actuator angles and rates;
    ``p``, ``R``: position of O_M and orientation of {M} in {S}; ``pose``: X_EE in this parametrisation
    (parasitic motions included); ``H``: the closure equations h_i(theta_i, q_EE) (seed 000, Eq. 8);
    ``unit``: abs(e)^2 - 1 for Euler parameters, else None.
    """

    params: SymbolicModel
    orientation: str
    coords: tuple[str, ...]
    q: ca.SX
    dq: ca.SX
    ddq: ca.SX
    theta: ca.SX
    dtheta: ca.SX
    p: ca.SX
    R: ca.SX
    pose: ca.SX
    H: ca.SX
    unit: ca.SX | None

    @property
    def n(self) -> int:
        return self.q.numel()

    @property
    def mechanism(self) -> str:
        return self.params.mechanism

    def point(self, body_point) -> ca.SX:
        """Position in {S} of a point fixed in {M} (given in {M}, metres: numbers or an expression of p)."""
        if not isinstance(body_point, (ca.SX, ca.DM)):
            body_point = ca.DM(np.asarray(body_point, dtype=float))
        return self.p + ca.mtimes(self.R, body_point)

    def crank_tip(self, i: int, theta_i=None) -> ca.SX:
        """S_i = G_i + R_C0,i Rz(theta_i) [L_c, 0, 0] (seed 000, Eq. 9)."""
        m = self.params
        th = self.theta[i] if theta_i is None else theta_i
        u, v = m.R_C0[i][:, 0], m.R_C0[i][:, 1]
        return m.G[i] + m.crank_length[i] * (ca.cos(th) * u + ca.sin(th) * v)

    def coupler_end(self, i: int) -> ca.SX:
        """M_i in {S}."""
        return self.point(self.params.M[i])

    # ------------------------------------------------------------------ first order maps

    def J_theta(self) -> ca.SX:
        """dH/dtheta (6x6, diagonal: h_i depends on theta_i only; seed 000, Eq. 12)."""
        return ca.jacobian(self.H, self.theta)

    def J_qEE(self) -> ca.SX:
        """dH/dq_EE (6 x n; seed 000, Eq. 12)."""
        return ca.jacobian(self.H, self.q)

    def J_theta1(self) -> ca.SX:
        """theta_dot = J_theta1 q_EE_dot, J_theta1 = -J_theta^-1 J_qEE (seed 000, Eqs. 13-14)."""
        Jt = ca.diag(self.J_theta())
        return -self.J_qEE() / ca.repmat(Jt, 1, self.n)

    def J_theta2(self) -> ca.SX:
        """J_theta2 = -J_theta^-1 (J_theta_dot J_theta1 + J_qEE_dot) (seed 000, Eq. 17), with the rates of the
        Jacobians along (theta_dot, q_dot) = (J_theta1 q_dot, q_dot); theta_ddot = J_theta2 q_dot + J_theta1 q_ddot."""
        x = ca.vertcat(self.theta, self.q)
        J1 = self.J_theta1()
        dx = ca.vertcat(ca.mtimes(J1, self.dq), self.dq)
        Jt = ca.diag(self.J_theta())
        Jt_dot = ca.jtimes(Jt, x, dx)
        JqEE_dot = ca.reshape(ca.jtimes(ca.vec(self.J_qEE()), x, dx), 6, self.n)
        return -(ca.mtimes(ca.diag(Jt_dot), J1) + JqEE_dot) / ca.repmat(Jt, 1, self.n)

    def J_theta3(self) -> ca.SX:
        """q_dot = J_theta3 q_EE_dot with q = [theta; q_EE]: J_theta3 = [J_theta1; I] (seed 000, Eqs. 18-19)."""
        return ca.vertcat(self.J_theta1(), ca.SX.eye(self.n))

    def J_theta4(self) -> ca.SX:
        """q_ddot = J_theta3 q_EE_ddot + J_theta4 q_EE_dot: J_theta4 = [J_theta2; 0] (seed 000, Eqs. 18-19)."""
        return ca.vertcat(self.J_theta2(), ca.SX(self.n, self.n))

    def M_J(self) -> ca.SX:
        """d(pose)/dq_EE: the Jacobian of X_EE with respect to q_EE (seed 000, Eq. 32)."""
        return ca.jacobian(self.pose, self.q)

    def M_0a(self) -> ca.SX:
        """Twist = M_0a X_EE_dot: diag(I3, R_omega) for angles (Eq. 31), diag(I3, 2 E(e)) for parameters."""
        if self.orientation == "euler-angles":
            rot = R_omega_sx(self.pose[3], self.pose[4])
        else:
            rot = 2 * E_sx(*ca.vertsplit(self.pose[3:7]))
        return ca.diagcat(ca.SX.eye(3), rot)

    def M_0b(self) -> ca.SX:
        """Twist = M_0b q_EE_dot, M_0b = M_0a M_J (seed 000, Eq. 33; seed 001, Eq. 12)."""
        return ca.mtimes(self.M_0a(), self.M_J())

    def twist(self) -> ca.SX:
        """[v_OM; omega] in {S}."""
        return ca.mtimes(self.M_0b(), self.dq)

    def twist_rate(self) -> ca.SX:
        """d/dt twist = M_0b q_ddot + (d/dt M_0b) q_dot."""
        t = self.twist()
        return ca.mtimes(self.M_0b(), self.ddq) + ca.jtimes(t, self.q, self.dq)

    def theta_rates(self) -> tuple[ca.SX, ca.SX]:
        """theta_dot = J_theta1 q_dot and theta_ddot = J_theta2 q_dot + J_theta1 q_ddot (Eqs. 13, 16).

        theta_ddot comes from the second time derivative of H = 0 (Eq. 15), differentiated exactly.
        """
        J1 = self.J_theta1()
        dth = ca.mtimes(J1, self.dq)
        x = ca.vertcat(self.theta, self.q)
        dx = ca.vertcat(self.dtheta, self.dq)
        Jt = ca.diag(self.J_theta())
        # d/dt (J_theta theta_dot + J_qEE q_dot) = J_theta theta_ddot + J_qEE q_ddot + (J_dot terms)
        first = ca.mtimes(self.J_theta(), self.dtheta) + ca.mtimes(self.J_qEE(), self.dq)
        jdot_terms = ca.jtimes(first, x, dx)  # exact (J_theta_dot theta_dot + J_qEE_dot q_dot)
        ddth = -(ca.mtimes(self.J_qEE(), self.ddq) + jdot_terms) / Jt
        ddth = ca.substitute(ddth, self.dtheta, dth)
        return dth, ddth


def symbolic(params: SymbolicModel, orientation: str = "euler-angles") -> Symbolic:
    """The symbolic kinematics in ``orientation`` on the model's numbers ``params`` (a mechanism's symbol p,
    :func:`chewbot.compiled.cache.symbols`, or one model's constants, :func:`chewbot.compiled.cache.folded`); built
    once per numbers and orientation. Expressions of it are in its own ``params`` (use ``symbolic(...).params``)."""
    check_orientation(orientation)
    return cached_graph(params, ("symbolic", orientation), lambda: _build(params, orientation))


def _build(model: SymbolicModel, orientation: str) -> Symbolic:
    coords = COORDINATES[(model.mechanism, orientation)]
    n = len(coords)
    q = ca.SX.sym("q", n)
    dq = ca.SX.sym("dq", n)
    ddq = ca.SX.sym("ddq", n)
    theta = ca.SX.sym("theta", 6)
    dtheta = ca.SX.sym("dtheta", 6)
    unit = None
    if model.has_hkp:
        X, Y = q[0], q[1]
        if orientation == "euler-angles":
            alpha, beta = q[2], q[3]
            gamma = gamma_parasitic_sx(model, alpha, beta)
            R = matrix_from_euler_angles_sx(alpha, beta, gamma)
            Z = Z_parasitic_sx(model, X, R)
            pose = ca.vertcat(X, Y, Z, alpha, beta, gamma)
        else:
            e0, e1, e2 = q[2], q[3], q[4]
            e3 = e3_parasitic_sx(model, e0, e1, e2)
            R = matrix_from_euler_parameters_sx(e0, e1, e2, e3)
            Z = Z_parasitic_sx(model, X, R)
            pose = ca.vertcat(X, Y, Z, e0, e1, e2, e3)
            unit = e0**2 + e1**2 + e2**2 + e3**2 - 1
        p = ca.vertcat(X, Y, Z)
    else:
        p = q[0:3]
        pose = q
        if orientation == "euler-angles":
            R = matrix_from_euler_angles_sx(q[3], q[4], q[5])
        else:
            R = matrix_from_euler_parameters_sx(q[3], q[4], q[5], q[6])
            unit = ca.sumsqr(q[3:7]) - 1
    sym = Symbolic(model, orientation, coords, q, dq, ddq, theta, dtheta, p, R, pose, ca.SX.zeros(6), unit)
    h = []
    for i in range(6):
        d = sym.crank_tip(i) - sym.coupler_end(i)
        h.append(ca.dot(d, d) - model.coupler_length[i] ** 2)
    object.__setattr__(sym, "H", ca.vertcat(*h))
    return sym
