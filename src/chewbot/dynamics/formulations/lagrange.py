"""Inverse dynamics by Lagrange's equations of the first kind (seed 000, Sect. 5.2, Eqs. 55-57).

With L = T - V over q = [theta; q_EE] and the closure equations H(q) = 0 (Eq. 11) adjoined by six multipliers
lambda, the generalised forces are the torques on theta and Q_B = J_B' F_B on q_EE (docs/conventions.md: the bite force
acts on the mandible, on the side of the actuators):

    D_theta = tau + J_theta' lambda          (Eq. 56, derived)
    D_E     = Q_B + J_qEE' lambda            (Eq. 55, derived)      D = d/dt (dL/dq_dot) - dL/dq.

D comes straight from automatic differentiation of L: d/dt(dL/dq_dot) is the directional derivative of
dL/dq_dot along (q_dot, q_ddot), with theta_dot and theta_ddot from the kinematics (the second time derivative of
H = 0), not from the Hessian route of Sect. 5.1.

The 10 (12) equations have 12 unknowns (tau, lambda): the target's torques are not unique. The minimum-norm
torques solve the KKT system of min 1/2 abs(tau)^2 subject to both equations. Eliminating lambda
(J_theta is diagonal and invertible) gives J_theta1' tau = J_theta3' D - Q_B, the same set as Eq. (53); the
printed Eq. (57), tau = -(J_theta1')^+ (J_theta3' D - F_EE), has the opposite overall sign to Eq. (54) and is not
used. For the 6RSS the KKT system is square and gives the unique torques.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.base import Dynamics, Sample, minimum_norm_sx
from chewbot.dynamics.contact import contact_kernels, frictionless_dynamics
from chewbot.dynamics.energy import energy, generalised_state, require_euler_angles
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.model.symbolic import c_name, parameter_input

LAGRANGE_OUTPUTS = ("D", "J_theta", "J_qEE", "Q_B")


def lagrange_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (q, q_dot, q_ddot, B, F_B, p) -> D (n), J_theta (diagonal, 6), J_qEE (6 x n_EE), Q_B (n_EE)."""
    name = f"lagrange_{c_name(mechanism)}"

    def build(params):
        e = energy(params)
        s = e.kin
        L = e.T - e.V
        dL_ddq = ca.gradient(L, e.dq)
        D = ca.jtimes(dL_ddq, ca.vertcat(e.q, e.dq), ca.vertcat(e.dq, e.ddq)) - ca.gradient(L, e.q)
        B, F = ca.SX.sym("B", 3), ca.SX.sym("F_B", 3)
        Q_B = ca.mtimes(ca.jacobian(s.p + ca.mtimes(s.R, B), s.q).T, F)
        extra, names = parameter_input(s.params)
        return ca.Function(name, [e.q, e.dq, e.ddq, B, F, *extra], [ca.densify(x) for x in (D, ca.diag(s.J_theta()), s.J_qEE(), Q_B)],
                           ["q", "dq", "ddq", "B", "F_B", *names], list(LAGRANGE_OUTPUTS), {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


def lagrange_terms(model: Model, kin: Kinematics, side: str | None = None) -> dict[str, np.ndarray]:
    """D (N, n), J_theta (N, 6), J_qEE (N, 6, n_EE), Q_B (N, n_EE) along the task."""
    q, dq, ddq = generalised_state(kin)
    out = evaluate(native(lagrange_kernel(model.mechanism)), q, dq, ddq, model.molar(side or kin.side), kin.force, model.vector())
    return dict(zip(LAGRANGE_OUTPUTS, out))


def solve_multipliers(terms: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Minimum-norm tau (N, 6) and lambda (N, 6) from the KKT system of Eqs. (55)-(56), all samples at once.

    Unknowns z = [tau; lambda] (12), constraints A z = d with A = [[I6, J_theta'], [0, J_qEE']] and
    d = [D_theta; D_E - Q_B]; the KKT matrix [[W, A'], [A, 0]] with W = diag(I6, 0) is regular because J_theta is
    (no singular configuration) and tau = -J_theta' lambda vanishes on no non-zero lambda of A's null space.
    """
    D, J_theta, J_qEE, Q_B = (terms[k] for k in LAGRANGE_OUTPUTS)
    N, n = D.shape
    A = np.zeros((N, n, 12))
    A[:, :6, :6] = np.eye(6)
    A[:, :6, 6:] = J_theta[:, :, None] * np.eye(6)  # J_theta' (diagonal)
    A[:, 6:, 6:] = np.swapaxes(J_qEE, 1, 2)
    K = np.zeros((N, 12 + n, 12 + n))
    K[:, :6, :6] = np.eye(6)
    K[:, :12, 12:] = np.swapaxes(A, 1, 2)
    K[:, 12:, :12] = A
    rhs = np.zeros((N, 12 + n))
    rhs[:, 12:] = np.hstack([D[:, :6], D[:, 6:] - Q_B])
    z = np.linalg.solve(K, rhs[..., None])[..., 0]
    return z[:, :6], z[:, 6:12]


def lagrange(model: Model, kin: Kinematics, *, side: str | None = None, contact: str = "bilateral") -> Dynamics:
    """Minimum-norm torques and the closure multipliers lambda1..6 (N/m: h_i is in m^2) by Lagrange's equations of
    the first kind, the target's normal forces and the ``contact`` model as :func:`chewbot.dynamics.formulations.hessian.hessian`.
    ``side`` overrides the bite side of ``kin``."""
    require_euler_angles(kin, "lagrange")
    terms = lagrange_terms(model, kin, side)
    tau, lam = solve_multipliers(terms)
    dyn = frictionless_dynamics("lagrange", model, kin, tau, side=side, contact=contact,
                                info={"equations": "seed 000 Eqs. 37-42, 55-56 (derived signs)", "friction": False})
    if dyn.tau is not tau:  # the unilateral fallback moved tau in the null space: lambda follows from Eq. (56)
        lam = (terms["D"][:, :6] - dyn.tau) / terms["J_theta"]
    dyn.table.add_block([f"lambda{i + 1}" for i in range(6)], lam, "N/m", "Lagrange multipliers of the closure equations h_i (m^2)")
    return dyn


def kernels(mechanism: str, orientation: str) -> list:
    """The compiled kernels of a run: Lagrange's D, J_theta, J_qEE, Q_B, and the target's normal-force map."""
    return [lagrange_kernel(mechanism), *contact_kernels(mechanism)]


def sample_torques(mechanism: str) -> ca.Function:
    """A controller's inverse dynamics of one sample (:class:`~chewbot.dynamics.base.Sample`): Lagrange's D, J_theta,
    J_qEE at q = [theta; q_EE] and the minimum-norm torques of J_theta1' tau = J_theta1' D_theta + D_E - Q_B (the
    multipliers of Eqs. 55-56 eliminated)."""
    s = Sample.of(mechanism)
    full = [ca.vertcat(s.kinematics[a], b) for a, b in (("theta", s.q), ("dtheta", s.dq), ("ddtheta", s.ddq))]
    D, J_theta, J_qEE, Q_B = lagrange_kernel(mechanism).graph()(*full, s.B, s.F, s.params.p)
    J1 = -J_qEE / ca.repmat(J_theta, 1, s.params.dof)
    return s.function(minimum_norm_sx(J1, ca.mtimes(J1.T, D[:6]) + D[6:] - Q_B, s.params.has_hkp))
