"""The Lagrange-d'Alembert reduction shared by the Hessian and Liang formulations (seed 000, Sects. 4, 5.1.3).

With q = [theta; q_EE], theta_dot = J_theta1 q_EE_dot (Eq. 13) and theta_ddot = J_theta2 q_EE_dot + J_theta1 q_EE_ddot
(Eqs. 16-17, J_theta2 = -J_theta^-1 (J_theta_dot J_theta1 + J_qEE_dot)), so q_dot = J_theta3 q_EE_dot and
q_ddot = J_theta3 q_EE_ddot + J_theta4 q_EE_dot (Eqs. 18-19). The virtual work of the actuators, delta theta' tau,
and of the bite force, delta q_EE' Q_B with Q_B = J_B' F_B (J_B = dB/dq_EE), balance the Lagrangian terms; with
delta theta = J_theta1 delta q_EE (Eq. 45):

    J_theta1' tau = M_f q_EE_ddot + C_f q_EE_dot + G_f - Q_B                                 (Eq. 53)

    M_f = J_theta3' M J_theta3,  C_f = J_theta3' (M J_theta4 + C J_theta3),  G_f = J_theta3' dV/dq.

Seed 000's F_EE is -Q_B (docs/conventions.md: the bite force is the food's force on the mandible and enters on the side of
the actuators). The target is redundantly actuated (4 equations, 6 torques): the minimum-norm torques (Eq. 54).

A formulation gives the rates J_theta_dot, J_qEE_dot and the Coriolis-centrifugal matrix C (its own way: Hessians
for Sect. 5.1, Eq. 61 for Liang); everything else is here, once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.base import Sample, minimum_norm_sx
from chewbot.dynamics.energy import Energy, energy, generalised_state
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.model.symbolic import c_name, parameter_input


@dataclass(frozen=True)
class Rates:
    """What a formulation derives, as expressions of (q, q_dot) of :class:`~chewbot.dynamics.energy.Energy`.

    ``J_theta_dot``: the diagonal of d/dt J_theta (6,); ``J_qEE_dot``: d/dt J_qEE (6 x n_EE);
    ``C``: Coriolis-centrifugal matrix (n x n) with C q_dot = d/dt(dT/dq_dot) - M q_ddot - dT/dq.
    """

    J_theta_dot: ca.SX
    J_qEE_dot: ca.SX
    C: ca.SX


Derivation = Callable[[Energy], Rates]

REDUCED_OUTPUTS = ("J_theta1", "M_f", "C_f", "G_f", "Q_B")


def reduced_kernel(mechanism: str, name: str, derive: Derivation) -> KernelSpec:
    """Per-sample kernel (theta, q_EE, q_EE_dot, B, F_B, p) -> J_theta1, M_f, C_f, G_f, Q_B of Eq. (53).

    ``B``: the bite point in {M} (m); ``F_B``: the bite force on the mandible in {S} (N). ``derive`` builds the
    formulation's :class:`Rates`, ``name`` names it (``"hessian"``, ``"liang"``).
    """
    fname = f"{name}_{c_name(mechanism)}"

    def build(params):
        e = energy(params)
        s = e.kin
        rates = derive(e)
        J_theta, J1 = ca.diag(s.J_theta()), s.J_theta1()
        ne = s.n
        dq_full = ca.vertcat(ca.mtimes(J1, s.dq), s.dq)
        J_theta_dot, J_qEE_dot, C = (ca.substitute(x, e.dq, dq_full) for x in (rates.J_theta_dot, rates.J_qEE_dot, rates.C))
        J2 = -(ca.mtimes(ca.diag(J_theta_dot), J1) + J_qEE_dot) / ca.repmat(J_theta, 1, ne)  # J_theta diagonal
        J3 = ca.vertcat(J1, ca.SX.eye(ne))
        J4 = ca.vertcat(J2, ca.SX(ne, ne))
        M_f = ca.mtimes([J3.T, e.M, J3])
        C_f = ca.mtimes(J3.T, ca.mtimes(e.M, J4) + ca.mtimes(C, J3))
        G_f = ca.mtimes(J3.T, ca.gradient(e.V, e.q))
        B, F = ca.SX.sym("B", 3), ca.SX.sym("F_B", 3)
        Q_B = ca.mtimes(ca.jacobian(s.p + ca.mtimes(s.R, B), s.q).T, F)
        extra, names = parameter_input(s.params)
        return ca.Function(fname, [s.theta, s.q, s.dq, B, F, *extra], [ca.densify(x) for x in (J1, M_f, C_f, G_f, Q_B)],
                           ["theta", "q", "dq", "B", "F_B", *names], list(REDUCED_OUTPUTS), {"cse": True})

    return KernelSpec(fname, build, (mechanism, name), mechanism)


def reduced_terms(model: Model, kin: Kinematics, name: str, derive: Derivation, side: str | None = None) -> dict[str, np.ndarray]:
    """J_theta1 (N, 6, n_EE), M_f, C_f (N, n_EE, n_EE), G_f, Q_B (N, n_EE) of Eq. (53) along the task."""
    q, dq, _ = generalised_state(kin)
    B = model.molar(side or kin.side)
    fn = native(reduced_kernel(model.mechanism, name, derive))
    out = evaluate(fn, q[:, :6], q[:, 6:], dq[:, 6:], B, kin.force, model.vector())
    return dict(zip(REDUCED_OUTPUTS, out))


def reduced_rhs(terms: dict[str, np.ndarray], kin: Kinematics) -> np.ndarray:
    """M_f q_EE_ddot + C_f q_EE_dot + G_f - Q_B (N, n_EE): the right-hand side of Eq. (53)."""
    _, dq, ddq = generalised_state(kin)
    return (np.einsum("nij,nj->ni", terms["M_f"], ddq[:, 6:]) + np.einsum("nij,nj->ni", terms["C_f"], dq[:, 6:])
            + terms["G_f"] - terms["Q_B"])


def minimum_norm(J_theta1: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """The least-norm tau with J_theta1' tau = rhs at every sample (Eq. 54), (N, 6).

    tau = (J_theta1')^+ rhs, computed from the QR factors J_theta1 = Q R (tau = Q R'^-1 rhs) rather than from
    J_theta1 (J_theta1' J_theta1)^-1, which squares the condition number; for the 6RSS (J_theta1 square) it is the
    unique solution.
    """
    Q, R = np.linalg.qr(J_theta1)
    y = np.linalg.solve(np.swapaxes(R, 1, 2), rhs[..., None])
    return (Q @ y)[..., 0]


def reduced_torques(model: Model, kin: Kinematics, name: str, derive: Derivation, side: str | None = None) -> np.ndarray:
    """Minimum-norm actuator torques (N, 6), N m, of Eq. (54) with the formulation's :class:`Rates`."""
    terms = reduced_terms(model, kin, name, derive, side)
    return minimum_norm(terms["J_theta1"], reduced_rhs(terms, kin))


def reduced_sample_torques(mechanism: str, name: str, derive: Derivation) -> ca.Function:
    """A controller's inverse dynamics of one sample by the formulation ``name`` (:class:`~chewbot.dynamics.base.Sample`):
    the terms of Eq. (53) from :func:`reduced_kernel` (theta from the closed-form inverse kinematics) and the
    minimum-norm torques of Eq. (54)."""
    s = Sample.of(mechanism)
    J1, M_f, C_f, G_f, Q_B = reduced_kernel(mechanism, name, derive).graph()(s.kinematics["theta"], s.q, s.dq, s.B, s.F, s.params.p)
    return s.function(minimum_norm_sx(J1, ca.mtimes(M_f, s.ddq) + ca.mtimes(C_f, s.dq) + G_f - Q_B, s.params.has_hkp))
