"""The 6RSS core: the robot as a 6RSS in X_EE, per sample, the graph that the 6RSS-core formulation
(:mod:`chewbot.dynamics.formulations.core6rss`) and the normal-force map of every formulation (:mod:`chewbot.dynamics.contact`)
are built on.

The 6RSS's dynamics are written once in the six coordinates x = X_EE = [X, Y, Z, alpha, beta, gamma], with the
crank angles eliminated in closed form (Cheng et al., Mech. Ind. 24:28, 2023 build the target on this core):

* chain i: theta_i from the closed-form inverse kinematics on the working branch, S_i(theta_i),
  d_i = S_i - M_i, s_i = dS_i/dtheta_i, r_i = R M_i^M. Differentiating abs(d_i)^2 = L_r^2 gives
  theta_i_dot = j_i' t with j_i = [d_i; r_i x d_i] / (d_i . s_i) and the twist t = [v_OM; omega] = M_0a x_dot;
* kinetic energy T = 1/2 t' Lambda t, with the mandible's spatial inertia diag(m I3, R I_M R') plus, per chain,
  the crank I_i j_i j_i' and the coupler as an exact thin-rod integral m/3 (B'B + A'A) + m/6 (B'A + A'B),
  A = [I3, -[r_i]x] (velocity of M_i), B = s_i j_i' (velocity of S_i); M_6(x) = M_0a' Lambda M_0a;
* potential V = m g Z + sum m_i g (S_iz + M_iz) / 2; the actuators' virtual work theta_dot' tau with
  theta_dot = J_6 x_dot, J_6 = [j_i'] M_0a; the bite force's Q_6 = J_B6' F_B:

      J_6' tau = M_6 x_ddot + C_6 x_dot + G_6 - Q_6                     (the 6RSS, unique tau)

For the target x = phi(q_EE) carries the parasitic Z and gamma, x_dot = M_J q_EE_dot,
x_ddot = M_J q_EE_ddot + M_J_dot q_EE_dot. The HKP forces do no work along M_J (they are normal to the planes the
condyles slide on), so projecting onto M_J removes them:

      J_theta1' tau = M_f q_EE_ddot + C_f q_EE_dot + G_f - Q_B,   J_theta1 = J_6 M_J,
      M_f = M_J' M_6 M_J,  C_f = M_J' (M_6 M_J_dot + C_6 M_J),  G_f = M_J' G_6,  Q_B = M_J' Q_6,

the same Eq. (53) as the Hessian method (M_f and G_f identical, C_f q_EE_dot identical), solved for the
minimum-norm torques. M_6 and C_6 are built from the structure of T (:func:`_structured_inertia`): the mandible
with a point mass m_i/3 at each M_i as one rigid body, plus rank-one terms per chain; C_6 x_dot is exact and
M_6_dot - 2 C_6 is skew-symmetric (the property passivity-based controllers use). The torque-only kernel
takes the left-hand side through the bodies' accelerations instead, without forming M_6 or C_6.

Everything, the inverse kinematics included, is one CasADi graph per sample, compiled to C: the per-sample
kernels of :func:`chewbot.dynamics.formulations.core6rss.torque_kernel` and :func:`chewbot.dynamics.formulations.core6rss.dynamics_kernel`
are what ``chewbot export-c`` writes for the robot's controller.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from chewbot.kinematics.functions import lift_sx
from chewbot.compiled.cache import cached_graph
from chewbot.model.symbolic import SymbolicModel, parameter_input
from chewbot.rotation import R_omega_sx, matrix_from_euler_angles_sx


def _skew(v):
    """[v]x, the cross-product matrix: [v]x w = v x w."""
    return ca.vertcat(ca.horzcat(0, -v[2], v[1]), ca.horzcat(v[2], 0, -v[0]), ca.horzcat(-v[1], v[0], 0))


CORE_OUTPUTS = ("theta", "J6", "M6", "C6", "G6", "Q6", "f6")


def core_function(params: SymbolicModel) -> ca.Function:
    """The 6RSS core per sample on the model's numbers ``params``: (x, x_dot, x_ddot, B, F_B, p) -> theta, J_6, M_6,
    C_6, G_6, Q_6 and f_6 = M_6 x_ddot + C_6 x_dot + G_6 - Q_6 (module docstring); no p for a model's constants
    (folded in)."""
    return cached_graph(params, ("core6rss",), lambda: _core(params))


def _augmented_body(model: SymbolicModel) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The mandible with a point mass m_i/3 at each M_i (the couplers' share of |v_M|^2): mass, first moment and
    inertia about O_M, all in {M} and constant (functions of the parameters only)."""
    m3 = [model.coupler_mass[i] / 3 for i in range(6)]
    first = sum((mi * Mi for mi, Mi in zip(m3, model.M)), ca.SX.zeros(3))
    inertia = model.mandible_inertia + sum(mi * (ca.dot(Mi, Mi) * ca.SX.eye(3) - ca.mtimes(Mi, Mi.T)) for mi, Mi in zip(m3, model.M))
    return model.mandible_mass + sum(m3), first, inertia


def _structured_inertia(model: SymbolicModel, x, R, M_0a, dx, chains):
    """M_6 and C_6 from the structure of the kinetic energy, without the 42-row Jacobian products:

    T = 1/2 t' Lambda t + sum_i [1/2 a_i theta_i_dot^2 + m_i/6 theta_i_dot (s_i . v_M,i)], t = M_0a x_dot, where
    Lambda is the spatial inertia about O_M of the mandible with a point mass m_i/3 at each M_i and
    a_i = I_i + m_i L_c,i^2/3 (the crank and the coupler's end S_i; abs(s_i) = L_c,i).

    C_6 x_dot is exact and M_6_dot - 2 C_6 is skew-symmetric: for the chains C = W' K W_dot over the true
    Jacobians of theta_i(x), S_i(x), M_i(x); for the rigid body C = A' (Lambda A_dot + (Lambda_dot / 2 + S) A),
    A = M_0a, Lambda_dot = Om Lambda - Lambda Om (Om = diag([w]x, [w]x)) and the skew-symmetric
    S = [[0, -[w]x[h]x / 2], [[h]x[w]x / 2, -[I w + v x h]x / 2]], which makes (Lambda_dot / 2 + S) t the rigid
    body's bias [w x (w x h); w x I w] (h: first moment, I: inertia about O_M, both in {S}).
    """
    mass, first, inertia = _augmented_body(model)
    h = ca.mtimes(R, first)
    I_O = ca.mtimes([R, inertia, R.T])
    Lam = ca.vertcat(ca.horzcat(mass * ca.SX.eye(3), -_skew(h)), ca.horzcat(_skew(h), I_O))
    t = ca.mtimes(M_0a, dx)
    v, w = t[0:3], t[3:6]
    A_dot = ca.reshape(ca.jtimes(ca.vec(M_0a), x, dx), 6, 6)
    Om = ca.diagcat(_skew(w), _skew(w))
    Lam_dot = ca.mtimes(Om, Lam) - ca.mtimes(Lam, Om)
    Sk = ca.vertcat(ca.horzcat(ca.SX(3, 3), -0.5 * ca.mtimes(_skew(w), _skew(h))),
                    ca.horzcat(0.5 * ca.mtimes(_skew(h), _skew(w)), -0.5 * _skew(ca.mtimes(I_O, w) + ca.cross(v, h))))
    M6 = ca.mtimes([M_0a.T, Lam, M_0a])
    C6 = ca.mtimes(M_0a.T, ca.mtimes(Lam, A_dot) + ca.mtimes(0.5 * Lam_dot + Sk, M_0a))
    for i, (J6_i, r, s, rGS) in enumerate(chains):
        m = model.coupler_mass[i]
        a = model.crank_total_inertia[i] + m * model.crank_length[i] ** 2 / 3
        j = J6_i.T  # column
        j_dot = ca.jtimes(j, x, dx)
        wM = ca.mtimes(M_0a.T, ca.vertcat(s, ca.cross(r, s)))  # W_M' s: s . v_M = wM' x_dot
        s_dot = -ca.mtimes(J6_i, dx) * rGS  # s turns with the crank
        r_dot = ca.cross(w, r)
        sWM_dot = (ca.mtimes(M_0a.T, ca.vertcat(ca.SX(3, 1), ca.cross(r_dot, s)))  # s' W_M_dot, as a column
                   + ca.mtimes(A_dot.T, ca.vertcat(s, ca.cross(r, s))))
        wM_sdot = ca.mtimes(M_0a.T, ca.vertcat(s_dot, ca.cross(r, s_dot)))  # W_M' s_dot
        M6 += a * ca.mtimes(j, j.T) + m / 6 * (ca.mtimes(j, wM.T) + ca.mtimes(wM, j.T))
        C6 += a * ca.mtimes(j, j_dot.T) + m / 6 * (ca.mtimes(j, sWM_dot.T) + ca.mtimes(wM_sdot, j.T) + ca.mtimes(wM, j_dot.T))
    return M6, C6


def _core(model: SymbolicModel) -> ca.Function:
    x, dx, ddx = ca.SX.sym("x", 6), ca.SX.sym("dx", 6), ca.SX.sym("ddx", 6)
    B, F = ca.SX.sym("B", 3), ca.SX.sym("F_B", 3)
    p, R = x[0:3], matrix_from_euler_angles_sx(x[3], x[4], x[5])
    W_omega = ca.horzcat(ca.SX(3, 3), R_omega_sx(x[3], x[4]))  # omega = W_omega x_dot
    M_0a = ca.diagcat(ca.SX.eye(3), R_omega_sx(x[3], x[4]))
    I_S = ca.mtimes([R, model.mandible_inertia, R.T])
    sigma = model.branch
    # Velocity Jacobians of every body (rows: theta_i_dot of each crank, v_S and v_M of each coupler) and the
    # constant weights of their kinetic energies: T = 1/2 x_dot' W' K W x_dot + mandible.
    blocks, weights, theta, chains = [], [], [], []
    V = model.mandible_mass * model.g * p[2]
    for i in range(6):
        u, v = model.R_C0[i][:, 0], model.R_C0[i][:, 1]
        Lc, Lr = model.crank_length[i], model.coupler_length[i]
        r = ca.mtimes(R, model.M[i])
        Mi = p + r
        d0 = Mi - model.G[i]
        A_, B_, C_ = 2 * Lc * ca.dot(u, d0), 2 * Lc * ca.dot(v, d0), Lc**2 + ca.dot(d0, d0) - Lr**2
        th = ca.atan2(B_, A_) + sigma[i] * ca.acos(C_ / ca.sqrt(A_**2 + B_**2))
        rGS = Lc * (ca.cos(th) * u + ca.sin(th) * v)
        S = model.G[i] + rGS
        s = Lc * (-ca.sin(th) * u + ca.cos(th) * v)
        d = S - Mi
        J6_i = ca.mtimes(ca.vertcat(d, ca.cross(r, d)).T / ca.dot(d, s), M_0a)  # theta_i_dot = J6_i x_dot
        W_M = ca.mtimes(ca.horzcat(ca.SX.eye(3), -_skew(r)), M_0a)  # v_M = v + omega x r
        m = model.coupler_mass[i]
        blocks += [J6_i, ca.mtimes(s, J6_i), W_M]
        weights += [model.crank_total_inertia[i], ca.DM(np.kron([[1 / 3, 1 / 6], [1 / 6, 1 / 3]], np.eye(3))) * m]
        chains.append((J6_i, r, s, rGS))
        V += m * model.g * (S[2] + Mi[2]) / 2
        theta.append(th)
    W = ca.vertcat(*blocks)
    K = ca.diagcat(*weights)
    W_dot = ca.reshape(ca.jtimes(ca.vec(W), x, dx), W.size1(), W.size2())
    W_omega_dot = ca.reshape(ca.jtimes(ca.vec(W_omega), x, dx), 3, 6)
    omega = ca.mtimes(W_omega, dx)
    mm = model.mandible_mass
    M6, C6 = _structured_inertia(model, x, R, M_0a, dx, chains)
    J6 = ca.vertcat(*blocks[0::3])
    Q6 = ca.mtimes(ca.jacobian(p + ca.mtimes(R, B), x).T, F)
    G6 = ca.gradient(V, x)
    # The same left-hand side without forming M_6 and C_6 (what a torque-only kernel needs): every W is the
    # Jacobian of a position or angle, so the bodies' accelerations are W x_ddot + W_dot x_dot and the
    # generalised inertia forces W' K (W x_ddot + W_dot x_dot), plus the mandible's Newton-Euler terms.
    acc = ca.mtimes(W, ddx) + ca.mtimes(W_dot, dx)
    domega = ca.mtimes(W_omega, ddx) + ca.mtimes(W_omega_dot, dx)
    f6 = (ca.mtimes(W.T, ca.mtimes(K, acc)) + ca.vertcat(mm * ddx[0:3], ca.SX(3, 1))
          + ca.mtimes(W_omega.T, ca.mtimes(I_S, domega) + ca.cross(omega, ca.mtimes(I_S, omega))) + G6 - Q6)
    extra, names = parameter_input(model)
    return ca.Function("core6rss", [x, dx, ddx, B, F, *extra], [ca.vertcat(*theta), J6, M6, C6, G6, Q6, f6],
                       ["x", "dx", "ddx", "B", "F_B", *names], list(CORE_OUTPUTS))


@dataclass(frozen=True)
class LiftedCore:
    """The 6RSS core evaluated along q_EE (Euler angles) as CasADi expressions: the kernel's ``inputs``
    (q, q_dot, q_ddot, B, F_B and p where the graph takes it), the model's numbers ``params``, x = X_EE(q_EE)
    with M_J = dx/dq_EE and its rate, and the core's outputs by name (:data:`CORE_OUTPUTS`)."""

    inputs: list
    params: SymbolicModel
    q: ca.SX
    dq: ca.SX
    ddq: ca.SX
    x: ca.SX
    M_J: ca.SX
    dM_J: ca.SX
    core: dict


def lifted_core(params: SymbolicModel) -> LiftedCore:
    """The 6RSS core along the mechanism's own coordinates q_EE: x = phi(q_EE) (the parasitic Z and gamma of the
    target), x_dot = M_J q_EE_dot, x_ddot = M_J q_EE_ddot + M_J_dot q_EE_dot (module docstring), on the model's
    numbers ``params``."""
    model = params
    extra, _ = parameter_input(model)
    n = model.dof
    q, dq, ddq = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n)
    B, F = ca.SX.sym("B", 3), ca.SX.sym("F_B", 3)
    x = lift_sx(model, q) if model.has_hkp else q
    M_J = ca.jacobian(x, q)
    dx = ca.mtimes(M_J, dq)
    dM_J = ca.jtimes(M_J, q, dq)
    ddx = ca.mtimes(M_J, ddq) + ca.mtimes(dM_J, dq)
    core = dict(zip(CORE_OUTPUTS, core_function(params)(x, dx, ddx, B, F, *extra)))
    return LiftedCore([q, dq, ddq, B, F, *extra], model, q, dq, ddq, x, M_J, dM_J, core)
