"""A plain reference: Newton–Euler torques in NumPy and the friction-aware distributions by SciPy's SLSQP.

Written the straightforward way, independently of the CasADi graphs: every body's Newton–Euler equations with
vectors and matrices (batched over the samples for the frictionless torques), and the optimal distribution
solved sample by sample with ``scipy.optimize.minimize(method="SLSQP")`` with the exact gradients of the goal and of the
limits, each sample warm-started from the previous one's solution.
It serves two purposes: an independent route for the tests, and the baseline of ``chewbot bench``.

The equations (seed 001, Sects. 4.1–4.4; :mod:`chewbot.dynamics.formulations.newton_euler` has the derivation):
coupler i (thin rod, mass m, length L, axis u from S to M) carries an axial force k_i and a transverse force fixed
by its two transverse Euler equations, u x g = u x c, c = -(m/2)(a_E - g_vec) - (m L/12) u_ddot, where g is its
force on the mandible; the crank pushes it at S with F_S = g + m (a_E - g_vec); the mandible's six equations
give k; tau_i = I_i theta_ddot_i + z_i . ((S_i - G_i) x F_S,i) (+ the actuator's friction).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from chewbot.errors import ChewbotError
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.rotation import matrix_from_euler_angles


@dataclass(frozen=True)
class _Sample:
    """Everything of the Newton–Euler equations that does not depend on the HKP forces, samples first."""

    A: np.ndarray  # (N, 6, 6) columns [u_i; r_i x u_i]
    w: np.ndarray  # (N, 6) mandible wrench balance without the coupler axial forces and the HKPs
    u: np.ndarray  # (N, 6, 3) coupler axes
    F_rest: np.ndarray  # (N, 6, 3) F_S,i without its axial part k_i u_i
    lever: np.ndarray  # (N, 6, 3) z_i x (S_i - G_i): tau_i = I theta_ddot + lever . F_S
    inertial: np.ndarray  # (N, 6) I_i theta_ddot_i
    P: np.ndarray  # (N, 6, nN) wrench of a unit normal force at T_j
    v_T: np.ndarray  # (N, nN, 3) velocities of the ball centres
    r_T: np.ndarray  # (N, nN, 3) ball centres from O_M


def _equations(model: Model, kin: Kinematics, side: str | None) -> _Sample:
    R = matrix_from_euler_angles(kin.X[:, 3:6])
    v, w_, a, dw = kin.twist[:, :3], kin.twist[:, 3:], kin.twist_rate[:, :3], kin.twist_rate[:, 3:]
    grav = np.array([0.0, 0.0, -model.g])
    I_S = R @ model.mandible_inertia @ np.swapaxes(R, 1, 2)
    r_B = R @ model.molar(side or kin.side)
    F_B = kin.force
    n = kin.n
    A = np.zeros((n, 6, 6))
    u_all, F_rest, lever = np.zeros((n, 6, 3)), np.zeros((n, 6, 3)), np.zeros((n, 6, 3))
    g_perp_sum, m_perp_sum = np.zeros((n, 3)), np.zeros((n, 3))
    for i in range(6):
        ux, uy, z = model.R_C0[i][:, 0], model.R_C0[i][:, 1], model.R_C0[i][:, 2]
        th, dth, ddth = kin.theta[:, i], kin.dtheta[:, i], kin.ddtheta[:, i]
        rGS = model.crank_length[i] * (np.cos(th)[:, None] * ux + np.sin(th)[:, None] * uy)
        a_S = ddth[:, None] * np.cross(z, rGS) - (dth**2)[:, None] * rGS
        r = R @ model.M[i]
        a_M = a + np.cross(dw, r) + np.cross(w_, np.cross(w_, r))
        L, m = model.coupler_length[i], model.coupler_mass[i]
        u = (kin.X[:, :3] + r - model.G[i] - rGS) / L
        a_E = (a_S + a_M) / 2
        c = -(m / 2) * (a_E - grav) - (m * L / 12) * (a_M - a_S) / L
        g_perp = c - np.sum(u * c, axis=1, keepdims=True) * u
        A[:, :3, i] = u
        A[:, 3:, i] = np.cross(r, u)
        g_perp_sum += g_perp
        m_perp_sum += np.cross(r, g_perp)
        u_all[:, i] = u
        F_rest[:, i] = g_perp + m * (a_E - grav)
        lever[:, i] = np.cross(z, rGS)
    wrench = np.concatenate([
        model.mandible_mass * (a - grav) - F_B - g_perp_sum,
        np.einsum("nij,nj->ni", I_S, dw) + np.cross(w_, np.einsum("nij,nj->ni", I_S, w_)) - np.cross(r_B, F_B) - m_perp_sum,
    ], axis=1)
    if model.has_hkp:
        nvec = model.hkp.normal
        r_T = np.stack([R @ model.hkp.T_L, R @ model.hkp.T_R], axis=1)
        P = np.stack([np.concatenate([np.broadcast_to(nvec, (n, 3)), np.cross(r_T[:, j], nvec)], axis=1) for j in range(2)], axis=2)
        v_T = v[:, None, :] + np.cross(w_[:, None, :], r_T)
    else:
        r_T, P, v_T = np.zeros((n, 0, 3)), np.zeros((n, 6, 0)), np.zeros((n, 0, 3))
    inertial = model.crank_total_inertia * kin.ddtheta
    return _Sample(A, wrench, u_all, F_rest, lever, inertial, P, v_T, r_T)


def frictionless_torques(model: Model, kin: Kinematics, side: str | None = None) -> np.ndarray:
    """Minimum-norm (target) or unique (6RSS) torques (N, 6) without friction, NumPy, all samples at once."""
    e = _equations(model, kin, side)
    rhs = np.concatenate([e.w[..., None], -e.P], axis=2)  # A k = w - P N
    K = np.linalg.solve(e.A, rhs)  # (N, 6, 1 + nN)
    # tau_i = inertial_i + lever_i . (F_rest_i + k_i u_i): affine in N
    lu = np.sum(e.lever * e.u, axis=2)  # (N, 6)
    tau0 = e.inertial + np.sum(e.lever * e.F_rest, axis=2) + lu * K[:, :, 0]
    if not model.has_hkp:
        return tau0
    T = lu[:, :, None] * K[:, :, 1:]  # (N, 6, 2)
    N = -np.linalg.solve(np.swapaxes(T, 1, 2) @ T, np.einsum("nji,nj->ni", T, tau0)[..., None])[..., 0]
    return tau0 + np.einsum("nij,nj->ni", T, N)


def _sample_torques(model: Model, e: _Sample, k: int, N: np.ndarray, dtheta: np.ndarray,
                    eps_theta_dot: float, eps_v: float, delta: float):
    """Torques (6,) and the bearing forces F_G (6, 3) of sample k with friction, for the normal forces N (2,), and
    their exact derivatives with respect to N: dtau (6, 2) and dF_G (6, 3, 2)."""
    fr = model.friction
    wrench = e.w[k] - e.P[k] @ N
    dwrench = -e.P[k].copy()  # (6, nN)
    for j in range(N.size):
        v = e.v_T[k, j]
        vhat = v / np.sqrt(v @ v + eps_v**2)
        size = np.sqrt(N[j] ** 2 + delta**2)
        f_T = -(fr.hkp_coulomb * size * vhat + fr.hkp_viscous * v)
        wrench = wrench - np.concatenate([f_T, np.cross(e.r_T[k, j], f_T)])
        dwrench[:, j] += fr.hkp_coulomb * N[j] / size * np.concatenate([vhat, np.cross(e.r_T[k, j], vhat)])
    kax = np.linalg.solve(e.A[k], np.column_stack([wrench, dwrench]))
    F_S = e.F_rest[k] + kax[:, :1] * e.u[k]
    dF_S = e.u[k][:, :, None] * kax[:, None, 1:]  # (6, 3, nN): the axial force's share
    F_G = F_S + np.outer(model.crank_mass * model.g, [0.0, 0.0, 1.0])
    sgn = dtheta / np.sqrt(dtheta**2 + eps_theta_dot**2)
    size_G = np.sqrt(np.sum(F_G**2, axis=1) + delta**2)
    arm = fr.actuator_arm * fr.actuator_coulomb * sgn
    tau_f = arm * size_G + fr.actuator_viscous * dtheta
    tau = e.inertial[k] + np.sum(e.lever[k] * F_S, axis=1) + tau_f
    dtau = np.einsum("ic,icj->ij", e.lever[k], dF_S) + (arm / size_G)[:, None] * np.einsum("ic,icj->ij", F_G, dF_S)
    return tau, F_G, dtau, dF_S


def slsqp_distribution(model: Model, kin: Kinematics, goal: str = "min-torque", samples: np.ndarray | None = None,
                       side: str | None = None, lower: float | None = None, eps_theta_dot: float = 1e-3,
                       eps_v: float = 1e-5, delta: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """An optimal distribution with friction (seed 001, Sect. 4.5) by SciPy's SLSQP, one sample after the other,
    each warm-started from the sample before where that was solved, under the actuator limits (torque, power, axial
    and radial load), with the exact gradients of the goal and the limits (:func:`_sample_torques`).

    ``goal``: ``min-torque`` (G1, sum tau_i^2), ``min-coupler-force`` (G2, sum abs(F_S,i)^2), ``min-hkp-force``
    (G3, N_L^2 + N_R^2); ``lower``: N_L, N_R >= lower (a unilateral contact) or None; ``samples``: indices to solve
    (default all). The friction regularisations are those of the Newton–Euler model. Returns (tau (n, 6), N (n, 2))
    for the samples solved.
    """
    if not model.has_hkp:
        raise ValueError("the 6RSS has nothing to distribute")
    e = _equations(model, kin, side)
    idx = np.arange(kin.n) if samples is None else np.asarray(samples)
    lim = model.limits
    z = np.array([model.R_C0[i][:, 2] for i in range(6)])
    weight = np.outer(model.crank_mass * model.g, [0.0, 0.0, 1.0])  # F_G = F_S + weight
    taus, Ns = [], []
    start = np.zeros(2) if lower is None else np.full(2, lower)
    x0, previous = start, None
    for k in idx:
        x0 = x0 if previous == k - 1 else start  # warm start from the sample before only
        dth = kin.dtheta[k]
        last: dict = {}

        def evaluate(N, k=k, dth=dth, last=last):
            """The sample's torques, limits and their derivatives at N, computed once per N."""
            if last.get("N") is None or not np.array_equal(last["N"], N):
                tau, F_G, dtau, dF_G = _sample_torques(model, e, k, N, dth, eps_theta_dot, eps_v, delta)
                axial = np.sum(F_G * z, axis=1)
                across = F_G - axial[:, None] * z
                radial = np.linalg.norm(across, axis=1)
                daxial = np.einsum("ic,icj->ij", z, dF_G)
                dradial = np.einsum("ic,icj->ij", across, dF_G) / radial[:, None]
                power = tau * dth
                if goal == "min-torque":
                    J, grad = float(tau @ tau), 2 * dtau.T @ tau
                elif goal == "min-coupler-force":  # F_S = F_G - weight, dF_S = dF_G
                    J, grad = float(np.sum((F_G - weight) ** 2)), 2 * np.einsum("ic,icj->j", F_G - weight, dF_G)
                else:
                    J, grad = float(N @ N), 2 * N
                last.update(N=N.copy(), tau=tau, J=J, grad=grad,
                            c=np.concatenate([lim.torque - np.abs(tau), lim.power - np.abs(power), lim.axial_load - np.abs(axial),
                                              lim.radial_load - radial]),
                            dc=-np.concatenate([np.sign(tau)[:, None] * dtau, np.sign(power)[:, None] * dth[:, None] * dtau,
                                                np.sign(axial)[:, None] * daxial, dradial]))
            return last

        res = minimize(lambda N, f=evaluate: f(N)["J"], x0, jac=lambda N, f=evaluate: f(N)["grad"], method="SLSQP",
                       bounds=None if lower is None else [(lower, None)] * 2,
                       constraints=[{"type": "ineq", "fun": lambda N, f=evaluate: f(N)["c"], "jac": lambda N, f=evaluate: f(N)["dc"]}],
                       options={"ftol": 1e-16, "maxiter": 200})
        if not res.success:
            raise ChewbotError(f"SciPy SLSQP failed at sample {k} (t = {kin.t[k]:.6g} s): {res.message}")
        x0, previous = res.x, k
        taus.append(evaluate(res.x)["tau"])
        Ns.append(res.x)
    return np.array(taus), np.array(Ns)


def slsqp_min_torque(model: Model, kin: Kinematics, samples: np.ndarray | None = None, side: str | None = None,
                     **smoothing) -> tuple[np.ndarray, np.ndarray]:
    """Goal G1 by :func:`slsqp_distribution` (the bilateral contact): the baseline of ``chewbot bench``."""
    return slsqp_distribution(model, kin, "min-torque", samples, side, **smoothing)
