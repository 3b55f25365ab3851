"""The kinematics of a whole task: pose, parasitic motions, actuator angles and all rates, vectorised.

:func:`solve_kinematics` is the entry point: a :class:`~chewbot.task.base.Task` and a model in, a
:class:`Kinematics` (arrays, samples first) out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chewbot.casadi_tools import evaluate
from chewbot.errors import KinematicsError
from chewbot.kinematics.functions import jacobian_rates_function, jacobians_function, parasitic_function, points_function, pose_function, rates_function
from chewbot.kinematics.ik import inverse_kinematics, transmission
from chewbot.kinematics.symbolic import COORDINATES, check_orientation
from chewbot.model import Model
from chewbot.rotation import euler_angles_to_parameters
from chewbot.task.base import FULL_COORDS, TARGET_COORDS, Task

# A 6-coordinate task given to the target must already satisfy its HKPs: Z and gamma may differ from the
# parasitic values by no more than this (m and rad; 1 micrometre / 1 microradian).
PARASITIC_TOLERANCE = 1e-6
# Target with Euler parameters: e3 = e1 (e0 + p1 e2) / (p1 e0 - e2) is undefined where the denominator
# vanishes (seed 001, Sect. 5.1); closer than this is reported.
E3_DENOMINATOR_TOLERANCE = 1e-6
# Parallel (type II) singularity: J_theta1, its columns normalised, closer to rank deficiency than this (its
# smallest singular value over its largest): the actuators no longer determine the mandible's motion.
PARALLEL_SINGULAR_TOLERANCE = 1e-6


@dataclass(frozen=True, eq=False)
class Kinematics:
    """Kinematics of a task on one model (arrays samples first, SI units).

    ``q``, ``dq``, ``ddq``: the mechanism's q_EE in ``orientation`` (see
    :mod:`chewbot.kinematics.symbolic`); ``X``, ``dX``, ``ddX``: X_EE = [X, Y, Z, alpha, beta, gamma] and its
    rates whatever the orientation; ``e``, ``de``, ``dde``: the same motion in Euler parameters;
    ``theta``, ``dtheta``, ``ddtheta``: actuator angles (rad) and rates; ``twist``, ``twist_rate``:
    [v_OM; omega] in {S} and its time derivative; ``force``: bite force F_B (N) at the molar of ``side``;
    ``points``: positions (N, 3) in {S} of T_L, T_R, I, B_L, B_R; ``transmission``: (N, 6) sin of each
    chain's transmission angle (0 at a singularity).
    """

    model: Model
    orientation: str
    t: np.ndarray
    coords: tuple[str, ...]
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    X: np.ndarray
    dX: np.ndarray
    ddX: np.ndarray
    e: np.ndarray
    de: np.ndarray
    dde: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray
    ddtheta: np.ndarray
    twist: np.ndarray
    twist_rate: np.ndarray
    force: np.ndarray
    side: str
    points: dict
    transmission: np.ndarray
    task_name: str = ""

    @property
    def n(self) -> int:
        return self.t.shape[0]

    def euler_angle_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q_EE in Euler angles and its rates, (N, 4) or (N, 6), whatever ``orientation``: the same motion."""
        cols = euler_angle_columns(self.model)
        return self.X[:, cols], self.dX[:, cols], self.ddX[:, cols]

    def jacobians(self) -> dict[str, np.ndarray]:
        """J_theta (diagonal, (N, 6)), J_qEE, J_theta1 .. J_theta4, M_J, M_0a, M_0b along the task (seed 000,
        Sect. 4; seed 001 for Euler parameters)."""
        fn = jacobians_function(self.model, self.orientation)
        out = dict(zip(fn.name_out(), evaluate(fn, self.theta, self.q)))
        fn = jacobian_rates_function(self.model, self.orientation)
        out.update(zip(fn.name_out(), evaluate(fn, self.theta, self.q, self.dq)))
        return out


def euler_angle_columns(model: Model) -> list[int]:
    """Columns of X_EE = [X, Y, Z, alpha, beta, gamma] that form q_EE in Euler angles: X, Y, alpha, beta for the
    target (Z and gamma are parasitic), all six for the 6RSS."""
    return [0, 1, 3, 4] if model.has_hkp else list(range(6))


def full_motion(model: Model, task: Task) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """X_EE (N, 6) and its rates for a task, lifting a 4-coordinate task with the sockets' parasitic motions."""
    if task.coords == TARGET_COORDS:
        X, dX, ddX = evaluate(parasitic_function(model), task.q, task.dq, task.ddq)
        return X, dX, ddX
    if model.has_hkp:
        cols = euler_angle_columns(model)
        X, _, _ = evaluate(parasitic_function(model), task.q[:, cols], task.dq[:, cols], task.ddq[:, cols])
        dev = np.abs(X[:, [2, 5]] - task.q[:, [2, 5]])
        bad = np.flatnonzero(dev.max(axis=1) > PARASITIC_TOLERANCE)
        if bad.size:
            i = int(bad[0])
            raise KinematicsError(
                f"task {task.name!r}: Z and gamma do not satisfy the target's HKPs (off by {dev[i, 0]:.3g} m, "
                f"{dev[i, 1]:.3g} rad); give X, Y, alpha, beta only and let the model compute the parasitic motions",
                sample=i, time=float(task.t[i]))
    return np.array(task.q), np.array(task.dq), np.array(task.ddq)


def mechanism_coordinates(model: Model, orientation: str, X, dX, ddX):
    """q_EE of the mechanism in ``orientation`` from a motion in Euler angles, plus (e, e_dot, e_ddot)."""
    e, de, dde = euler_angles_to_parameters(X[:, 3:6], dX[:, 3:6], ddX[:, 3:6])
    if orientation == "euler-angles":
        cols = euler_angle_columns(model)
        q, dq, ddq = X[:, cols], dX[:, cols], ddX[:, cols]
    else:
        k = 2 if model.has_hkp else 3
        ne = 3 if model.has_hkp else 4
        q = np.concatenate([X[:, :k], e[:, :ne]], axis=1)
        dq = np.concatenate([dX[:, :k], de[:, :ne]], axis=1)
        ddq = np.concatenate([ddX[:, :k], dde[:, :ne]], axis=1)
    return q, dq, ddq, e, de, dde


def check_workspace(model: Model, T_L: np.ndarray, T_R: np.ndarray, t: np.ndarray) -> None:
    """Both condyles inside their sockets (x and y bounds of docs/conventions.md); raises naming the first bad sample."""
    h = model.hkp
    slack = 1e-12
    for label, T, yr in (("left", T_L, h.y_left), ("right", T_R, h.y_right)):
        out_x = (T[:, 0] < h.x_range[0] - slack) | (T[:, 0] > h.x_range[1] + slack)
        out_y = (T[:, 1] < yr[0] - slack) | (T[:, 1] > yr[1] + slack)
        bad = np.flatnonzero(out_x | out_y)
        if bad.size:
            i = int(bad[0])
            raise KinematicsError(
                f"the {label} condyle leaves its socket: T = ({T[i, 0] * 1e3:.3f}, {T[i, 1] * 1e3:.3f}) mm, socket "
                f"x in [{h.x_range[0] * 1e3:g}, {h.x_range[1] * 1e3:g}] mm, y in [{yr[0] * 1e3:g}, {yr[1] * 1e3:g}] mm "
                f"({bad.size} sample(s) outside)",
                sample=i, time=float(t[i]))


def check_parallel_singularity(model: Model, orientation: str, theta: np.ndarray, q: np.ndarray, t: np.ndarray) -> None:
    """Raise :class:`KinematicsError` at the first sample where J_theta1 loses rank (type II singularity).

    The columns are normalised first, so the test does not depend on the units of q_EE; for Euler parameters
    the direction that changes abs(e) is not a motion and is left out (J_theta1 restricted to abs(e) = 1).
    """
    J1 = evaluate(jacobians_function(model, orientation), theta, q)[2]
    if orientation == "euler-parameters":
        J1 = J1 @ _unit_norm_tangent(model, q)
    J1 = J1 / np.linalg.norm(J1, axis=1, keepdims=True)
    sv = np.linalg.svd(J1, compute_uv=False)
    ratio = sv[:, -1] / sv[:, 0]
    bad = np.flatnonzero(ratio < PARALLEL_SINGULAR_TOLERANCE)
    if bad.size:
        i = int(bad[0])
        raise KinematicsError(f"parallel (type II) singularity: J_theta1 loses rank (singular-value ratio "
                              f"{ratio[i]:.2e} < {PARALLEL_SINGULAR_TOLERANCE:g}), the actuators do not fix the "
                              f"mandible's motion; {bad.size} sample(s) affected", sample=i, time=float(t[i]))


def _unit_norm_tangent(model: Model, q: np.ndarray) -> np.ndarray:
    """Orthonormal bases (N, n, n - 1) of the q_EE directions that keep abs(e) = 1."""
    from chewbot.kinematics.functions import closure_function

    theta0 = np.zeros((q.shape[0], 6))
    grad = evaluate(closure_function(model, "euler-parameters"), theta0, q)[3].reshape(q.shape[0], -1)
    _, _, vt = np.linalg.svd(grad[:, None, :])
    return np.swapaxes(vt[:, 1:, :], 1, 2)


def solve_kinematics(model: Model, task: Task, orientation: str = "euler-angles") -> Kinematics:
    """Inverse kinematics of a whole task: parasitic motions, workspace check, theta and all rates."""
    check_orientation(orientation)
    if task.coords not in (TARGET_COORDS, FULL_COORDS):
        raise KinematicsError(f"task {task.name!r} has coordinates {task.coords}")
    X, dX, ddX = full_motion(model, task)
    q, dq, ddq, e, de, dde = mechanism_coordinates(model, orientation, X, dX, ddX)
    if model.has_hkp and orientation == "euler-parameters":
        den = model.hkp.p1 * q[:, 2] - q[:, 4]
        bad = np.flatnonzero(np.abs(den) < E3_DENOMINATOR_TOLERANCE)
        if bad.size:
            raise KinematicsError("Euler parameters: p1 e0 - e2 = 0, the parasitic e3 is undefined here",
                                  sample=int(bad[0]), time=float(task.t[bad[0]]))
    _, p, R = evaluate(pose_function(model, orientation), q)
    T_L, T_R, I, B_L, B_R = evaluate(points_function(model, orientation), q)
    if model.has_hkp:
        check_workspace(model, T_L, T_R, task.t)
    theta = inverse_kinematics(model, p, R, task.t)
    check_parallel_singularity(model, orientation, theta, q, task.t)
    dtheta, ddtheta, twist, twist_rate, _, _ = evaluate(rates_function(model, orientation), theta, q, dq, ddq)
    return Kinematics(
        model=model,
        orientation=orientation,
        t=np.array(task.t),
        coords=COORDINATES[(model.mechanism, orientation)],
        q=q, dq=dq, ddq=ddq,
        X=X, dX=dX, ddX=ddX,
        e=e, de=de, dde=dde,
        theta=theta, dtheta=dtheta, ddtheta=ddtheta,
        twist=twist, twist_rate=twist_rate,
        force=np.array(task.force),
        side=task.side,
        points={"T_L": T_L, "T_R": T_R, "I": I, "B_L": B_L, "B_R": B_R},
        transmission=transmission(model, p, R),
        task_name=task.name,
    )
