"""Inertia coupling among the six actuated joints (seed 000, Sect. 6), and the related indices it cites.

Joint-space inertia (Eqs. 58-59): q_dot = J_theta5 theta_dot with J_theta5 = [I6; J_theta1^+], so
T = 1/2 theta_dot' M_A theta_dot with M_A = J_theta5' M J_theta5 (6 x 6, kg m^2, every theta in rad). For the 6RSS
J_theta1^+ = J_theta1^-1. For the target J_theta1 (6 x 4) has full column rank and J_theta1^+ = (J_theta1' J_theta1)^-1
J_theta1' is its left inverse: it maps a theta_dot outside the range of J_theta1 (one the HKPs forbid) to its
least-squares q_EE_dot in the metric of theta (all rad). It does not depend on how q_EE is scaled or
parametrised (pinv(J T) = T^-1 pinv(J) for any invertible T), so M_A is the same in mm or m, Euler angles or
parameters.

Indices, per sample (d_i = M_A(i,i), o_ik = abs(M_A(i,k)) for i != k; 6 joints, 30 off-diagonal entries):

* MCI_i = ln(sum_{k != i} o_ik / (5 d_i) + 1)     (Eq. 60, Guo et al. 2022): coupling of joint i to the others.
* joint-reflected inertia = mean_i d_i                      (Shao et al. 2012), kg m^2.
* inertia variation = std_i d_i / mean_i d_i               (coefficient of variation, Mo et al. 2017): imbalance
  of the inertia among the chains (0: isotropic).
* branch-coupling absolute inertia = mean_{i != k} o_ik     (kg m^2) and
* branch-coupling inertia variation = std_{i != k} o_ik / mean_{i != k} o_ik: the off-diagonal counterparts of the
  two above, as Zou et al. (2022) name them. Zou et al.'s own formulas are not reproduced in seed 000; these are
  our definitions, built to mirror the diagonal pair (std: population standard deviation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import casadi as ca

from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.base import householder_minimum_norm_sx
from chewbot.dynamics.formulations.dalembert import reduced_kernel
from chewbot.dynamics.energy import energy, generalised_state
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.model.symbolic import c_name, parameter_input

_OFF = ~np.eye(6, dtype=bool)


@dataclass(frozen=True, eq=False)
class Coupling:
    """Inertia coupling along a task (arrays samples first).

    ``M_A``: (N, 6, 6) joint-space inertia, kg m^2; ``MCI``: (N, 6) Eq. (60), dimensionless;
    ``reflected``: (N,) joint-reflected inertia, kg m^2; ``variation``: (N,) its coefficient of variation;
    ``branch``: (N,) branch-coupling absolute inertia, kg m^2; ``branch_variation``: (N,) its variation.
    """

    M_A: np.ndarray
    MCI: np.ndarray
    reflected: np.ndarray
    variation: np.ndarray
    branch: np.ndarray
    branch_variation: np.ndarray

    def means(self) -> dict[str, float | list[float]]:
        """Each index averaged over the task (MCI per joint, as seed 000's Fig. 8)."""
        return {"MCI": self.MCI.mean(axis=0).tolist(), "reflected": float(self.reflected.mean()),
                "variation": float(self.variation.mean()), "branch": float(self.branch.mean()),
                "branch_variation": float(self.branch_variation.mean())}


def coupling_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (theta, q_EE, p) -> M_A (6 x 6, kg m^2), MCI (6) (Eqs. 58-60), q_EE in Euler angles (no p
    for a model: its numbers folded in).

    J_theta1^+ is (J_theta1' J_theta1)^-1 J_theta1' for the target and J_theta1^-1 for the 6RSS, solved inside the
    graph, so the kernel is one straight-line C function (exported for the controller by ``chewbot export-c``).
    """
    name = f"coupling_{c_name(mechanism)}"

    def build(params):
        e = energy(params)
        s = e.kin
        J1 = s.J_theta1()
        J1_pinv = ca.solve(ca.mtimes(J1.T, J1), J1.T) if s.params.has_hkp else ca.inv(J1)
        J5 = ca.vertcat(ca.SX.eye(6), J1_pinv)
        M_A = ca.mtimes([J5.T, e.M, J5])
        a = ca.fabs(M_A)
        diag = ca.diag(a)
        MCI = ca.log((ca.sum2(a) - diag) / (5 * diag) + 1)
        extra, names = parameter_input(s.params)
        return ca.Function(name, [s.theta, s.q, *extra], [ca.densify(M_A), MCI], ["theta", "q", *names], ["M_A", "MCI"], {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


def torques_coupling_kernel(mechanism: str, method: str, rates) -> KernelSpec:
    """Per-sample kernel (theta, q_EE, q_EE_dot, q_EE_ddot, B, F_B, p) -> tau (6, N m), MCI (6): the minimum-norm
    torques of Eq. (54) from the terms of Eq. (53) of the Lagrange-d'Alembert formulation ``method`` (its ``rates``,
    :func:`chewbot.dynamics.formulations.dalembert.reduced_kernel`) and the coupling index of :func:`coupling_kernel`, in one
    straight-line function (the mass matrix shared).

    What a sweep computes when its outputs need only the torques and MCI: one call per evaluation instead of the
    run's two kernels, the QR factors and the products in NumPy. The least-norm solution is by Householder QR
    inside the graph (:func:`chewbot.dynamics.base.householder_minimum_norm_sx`), the algorithm of the run's
    LAPACK route, so the two differ by rounding only (tests/test_sweep_fast.py: 1e-12 of max abs(tau)).
    """
    name = f"{c_name(method)}_coupling_{c_name(mechanism)}"

    def build(params):
        reduced = reduced_kernel(mechanism, method, rates).graph(params)
        theta, q, dq, B, F, *extra = reduced.sx_in()
        ddq = ca.SX.sym("ddq", q.size1())
        J1, M_f, C_f, G_f, Q_B = reduced(theta, q, dq, B, F, *extra)
        tau = householder_minimum_norm_sx(J1, ca.mtimes(M_f, ddq) + ca.mtimes(C_f, dq) + G_f - Q_B)
        _, MCI = coupling_kernel(mechanism).graph(params)(theta, q, *extra)
        _, names = parameter_input(params)
        return ca.Function(name, [theta, q, dq, ddq, B, F, *extra], [tau, MCI], ["theta", "q", "dq", "ddq", "B", "F_B", *names],
                           ["tau", "MCI"], {"cse": True})

    return KernelSpec(name, build, (mechanism, method), mechanism)


def torques_coupling(model: Model, kin: Kinematics, method: str, rates, side: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """tau (N, 6), N m, and MCI (N, 6) along the task by :func:`torques_coupling_kernel` (``side``: the bite side,
    overriding the task's)."""
    q, dq, ddq = generalised_state(kin)
    fn = native(torques_coupling_kernel(model.mechanism, method, rates))
    tau, MCI = evaluate(fn, q[:, :6], q[:, 6:], dq[:, 6:], ddq[:, 6:], model.molar(side or kin.side), kin.force, model.vector())
    return tau, MCI


def joint_space_inertia(model: Model, kin: Kinematics) -> np.ndarray:
    """M_A = J_theta5' M J_theta5 along the task (Eqs. 58-59), (N, 6, 6), kg m^2."""
    q, _, _ = generalised_state(kin)
    return evaluate(native(coupling_kernel(model.mechanism)), q[:, :6], q[:, 6:], model.vector())[0]


def mci(M_A: np.ndarray) -> np.ndarray:
    """MCI_i = ln(sum_{k != i} abs(M_A(i,k)) / (5 abs(M_A(i,i))) + 1) (Eq. 60), (N, 6)."""
    a = np.abs(M_A)
    diag = np.diagonal(a, axis1=1, axis2=2)
    return np.log((a.sum(axis=2) - diag) / (5 * diag) + 1)


def coupling(model: Model, kin: Kinematics) -> Coupling:
    """All inertia-coupling indices of the module docstring along the task."""
    M_A = joint_space_inertia(model, kin)
    d = np.diagonal(M_A, axis1=1, axis2=2)
    o = np.abs(M_A[:, _OFF])
    return Coupling(M_A, mci(M_A), d.mean(axis=1), d.std(axis=1) / d.mean(axis=1), o.mean(axis=1),
                    o.std(axis=1) / o.mean(axis=1))
