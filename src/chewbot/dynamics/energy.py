"""Kinetic and potential energy of the whole robot, and its inertia matrix M(q) (seed 000, Sect. 5.1.1-5.1.2).

The generalised coordinates are q = [theta_1..theta_6, q_EE] with q_EE in XYZ Euler angles
(10 for the target, 12 for the 6RSS); they are not independent: the closure equations H(q) = 0 tie them.

* Cranks (Eq. 24): they spin about their shafts with the mass centre on the shaft, T = 1/2 sum I_i theta_i_dot^2;
  their potential energy is constant (left out).
* Couplers (Eqs. 25-30): uniform thin rods, the points P(s) = (1 - s) S_i + s M_i, s in [0, 1]. Eq. (30)'s integral
  is done exactly: int_0^1 abs((1 - s) v_S + s v_M)^2 ds = (abs(v_S)^2 + v_S.v_M + abs(v_M)^2) / 3, so
  M_SM = m/3 (J_S' J_S + J_M' J_M) + m/6 (J_S' J_M + J_M' J_S) with J_S = dS_i/dq, J_M = dM_i/dq. Potential
  energy m g z of the midpoint (Eqs. 39-40).
* Mandible (Eqs. 31-36): T = 1/2 t' diag(m I3, R I_M R') t with the twist t = [v_OM; omega] = M_0b q_EE_dot, so
  M_EE = M_0b' diag(m I3, R I_M R') M_0b; potential energy m g Z (Eq. 41).

M(q) (Eq. 38) is the sum of the three, T = 1/2 q_dot' M q_dot (Eq. 37), V their sum (Eq. 42).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from chewbot.compiled.cache import cached_graph
from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.errors import ChewbotError
from chewbot.kinematics.motion import Kinematics
from chewbot.kinematics.symbolic import Symbolic, symbolic
from chewbot.model import Model
from chewbot.model.symbolic import SymbolicModel, c_name, parameter_input

ORIENTATION = "euler-angles"


@dataclass(frozen=True, eq=False)
class Energy:
    """The energies of one mechanism as CasADi expressions of q = [theta; q_EE], q_dot and the parameters.

    ``kin``: the symbolic kinematics (Euler angles; ``kin.params``: the model's numbers); ``q``, ``dq``, ``ddq``: the generalised coordinates and
    their rates (symbols); ``M``: inertia matrix (Eq. 38, kg m^2, m and rad mixed as the coordinates are);
    ``M_cranks``, ``M_couplers`` (one per chain), ``M_mandible``: its parts (Eqs. 24, 30, 36);
    ``T``: kinetic energy (J); ``V``: potential energy (J, constant crank terms left out).
    """

    kin: Symbolic
    q: ca.SX
    dq: ca.SX
    ddq: ca.SX
    M_cranks: ca.SX
    M_couplers: tuple[ca.SX, ...]
    M_mandible: ca.SX
    M: ca.SX
    T: ca.SX
    V: ca.SX

    @property
    def n(self) -> int:
        """Number of generalised coordinates (10 or 12)."""
        return self.q.numel()


def require_euler_angles(kin: Kinematics, method: str) -> None:
    """Raise a ChewbotError unless ``kin`` is in Euler angles: the energy-based formulations are built on them."""
    if kin.orientation != ORIENTATION:
        raise ChewbotError(
            f"method {method!r} takes Euler angles (q_EE with XYZ Euler angles), not {kin.orientation!r}; "
            "run it with --orientation euler-angles (the torques of a motion do not depend on how its "
            "orientation is parametrised) or use a formulation written for Euler parameters")


def energy(params: SymbolicModel) -> Energy:
    """The symbolic energies on the model's numbers ``params`` (a mechanism's symbol p, or one model's constants);
    built once per numbers."""
    return cached_graph(params, ("energy",), lambda: _build(symbolic(params, ORIENTATION)))


def _build(s: Symbolic) -> Energy:
    model = s.params
    q = ca.vertcat(s.theta, s.q)
    dq = ca.vertcat(s.dtheta, s.dq)
    ddq = ca.vertcat(ca.SX.sym("ddtheta", 6), s.ddq)
    n = q.numel()

    M_cranks = ca.SX(n, n)
    M_cranks[:6, :6] = ca.diag(model.crank_total_inertia)

    couplers = []
    V = ca.SX(0)
    for i in range(6):
        S, Mi = s.crank_tip(i), s.coupler_end(i)
        J_S, J_M = ca.jacobian(S, q), ca.jacobian(Mi, q)
        m = model.coupler_mass[i]
        cross = ca.mtimes(J_S.T, J_M)
        couplers.append(m / 3 * (ca.mtimes(J_S.T, J_S) + ca.mtimes(J_M.T, J_M)) + m / 6 * (cross + cross.T))
        V += m * model.g * (S[2] + Mi[2]) / 2

    M_0b = s.M_0b()
    I_S = ca.mtimes([s.R, model.mandible_inertia, s.R.T])
    spatial = ca.diagcat(model.mandible_mass * ca.SX.eye(3), I_S)
    M_mandible = ca.SX(n, n)
    M_mandible[6:, 6:] = ca.mtimes([M_0b.T, spatial, M_0b])
    V += model.mandible_mass * model.g * s.p[2]

    M = M_cranks + sum(couplers[1:], couplers[0]) + M_mandible
    T = 0.5 * ca.bilin(M, dq, dq)
    return Energy(s, q, dq, ddq, M_cranks, tuple(couplers), M_mandible, M, T, V)


def energy_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (q, q_dot, p) -> (T [J], V [J], M [kg m^2 ...])."""
    name = f"energy_{c_name(mechanism)}"

    def build(params):
        e = energy(params)
        extra, names = parameter_input(e.kin.params)
        return ca.Function(name, [e.q, e.dq, *extra], [e.T, e.V, ca.densify(e.M)], ["q", "dq", *names], ["T", "V", "M"])

    return KernelSpec(name, build, (mechanism,), mechanism)


def generalised_state(kin: Kinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q = [theta, q_EE] (Euler angles) and its rates along the task, (N, n) each.

    q_EE is taken from X_EE in Euler angles, whatever ``kin.orientation``: it is the same motion.
    """
    q, dq, ddq = kin.euler_angle_state()
    return np.hstack([kin.theta, q]), np.hstack([kin.dtheta, dq]), np.hstack([kin.ddtheta, ddq])


def energies(model: Model, kin: Kinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kinetic energy T (N,), potential energy V (N,) (J) and inertia matrix M (N, n, n) along the task."""
    q, dq, _ = generalised_state(kin)
    T, V, M = evaluate(native(energy_kernel(model.mechanism)), q, dq, model.vector())
    return T[:, 0], V[:, 0], M
