"""The kinematics of a whole task: pose, parasitic motions, actuator angles and all rates, vectorised.

:func:`solve_kinematics` is the entry point: a :class:`~chewbot.kinematics.task.Task` and a model in, a
:class:`Kinematics` (arrays, samples first) out. The whole stage is one call of the compiled
:func:`~chewbot.kinematics.functions.kinematics_kernel` over the task; the checks (reach, singular chains,
sockets, parallel singularity, the parasitic e3's denominator) then read its outputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from chewbot.compiled.cache import symbols
from chewbot.compiled.kernels import evaluate, native
from chewbot.errors import KinematicsError
from chewbot.kinematics.functions import (KINEMATICS_OUTPUTS, jacobian_rates_function, jacobians_function, kinematics_kernel,
                                         parasitic_function, pose_rates_function)
from chewbot.kinematics.conditioning import reciprocal_condition
from chewbot.kinematics.ik import check_chains, continuous
from chewbot.kinematics.options import check_orientation
from chewbot.kinematics.symbolic import COORDINATES
from chewbot.model import Model
from chewbot.rotation import euler_parameters_to_angles
from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task
from chewbot.units import factor

# A 6-coordinate task given to the target must already satisfy its HKPs: Z and gamma may differ from the
# parasitic values by no more than this (m and rad; 1 micrometre / 1 microradian).
PARASITIC_TOLERANCE = 1e-6
# Target with Euler parameters: e3 = e1 (e0 + p1 e2) / (p1 e0 - e2) is undefined where the denominator
# vanishes (seed 001, Sect. 5.1); closer than this is reported.
E3_DENOMINATOR_TOLERANCE = 1e-6
# Parallel (type II) singularity: J_theta1, its columns normalised, closer to rank deficiency than this (its
# smallest singular value over its largest): the actuators no longer determine the mandible's motion.
PARALLEL_SINGULAR_TOLERANCE = 1e-6
# A motion given in Euler parameters must keep abs(e) = 1 at every level: abs(e)^2 - 1, its rate 2 e.e_dot and its
# second rate 2 (e.e_ddot + abs(e_dot)^2) may differ from 0 by this, relative to 1 + the rates' sizes (rounding of
# a conversion leaves about 1e-16; an optimiser's equality constraint, chewbot.task.incisor's, 1e-9).
UNIT_NORM_TOLERANCE = 1e-8


@dataclass(frozen=True, eq=False)
class Kinematics:
    """Kinematics of a task on one model (arrays samples first, SI units).

    ``q``, ``dq``, ``ddq``: the mechanism's q_EE in ``orientation`` (see
    :mod:`chewbot.kinematics.symbolic`); ``X``, ``dX``, ``ddX``: X_EE = [X, Y, Z, alpha, beta, gamma] and its
    rates whatever the orientation; ``e``, ``de``, ``dde``: the same motion in Euler parameters;
    ``theta``, ``dtheta``, ``ddtheta``: actuator angles (rad) and rates; ``twist``, ``twist_rate``:
    [v_OM; omega] in {S} and its time derivative; ``force``: bite force F_B (N) at the molar of ``side``;
    ``points``: positions (N, 3) in {S} of T_L, T_R, I, B_L, B_R; ``transmission``: (N, 6) sin of each
    chain's transmission angle (0 at a singularity); ``J_theta1_angles``: (N, 6, n) the chains' Jacobian J_theta1 in
    Euler angles whatever the orientation, from which ``kappa`` (its reciprocal condition number,
    :mod:`chewbot.kinematics.conditioning`) is computed when first asked (a sweep whose outputs do not need it
    does not pay for the singular values).
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
    J_theta1_angles: np.ndarray | None = None

    @cached_property
    def kappa(self) -> np.ndarray | None:
        """kappa (N,) of the chains' Jacobian (columns scaled; 1 best, 0 singular); None without the Jacobian."""
        return None if self.J_theta1_angles is None else reciprocal_condition(self.J_theta1_angles)

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
        m, p = self.model.mechanism, self.model.vector()
        fn = jacobians_function(m, self.orientation)
        out = dict(zip(fn.name_out(), evaluate(fn, self.theta, self.q, p)))
        fn = jacobian_rates_function(m, self.orientation)
        out.update(zip(fn.name_out(), evaluate(fn, self.theta, self.q, self.dq, p)))
        return out


def euler_angle_columns(model: Model) -> list[int]:
    """Columns of X_EE = [X, Y, Z, alpha, beta, gamma] that form q_EE in Euler angles: X, Y, alpha, beta for the
    target (Z and gamma are parasitic), all six for the 6RSS."""
    return [0, 1, 3, 4] if model.has_hkp else list(range(6))


def task_coordinates(model: Model, task: Task) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mechanism's independent coordinates in Euler angles and their rates, (N, 4) or (N, 6), from a task:
    a 4-coordinate task on the 6RSS is lifted with the sockets' parasitic motions; a 6-coordinate task on the
    target is checked against them after the kinematics (:func:`check_parasitic`)."""
    if task.coords == TARGET_COORDS and not model.has_hkp:
        return tuple(evaluate(parasitic_function(symbols(model.mechanism)), task.q, task.dq, task.ddq, model.vector()))
    if task.coords == FULL_COORDS and model.has_hkp:
        cols = euler_angle_columns(model)
        return task.q[:, cols], task.dq[:, cols], task.ddq[:, cols]
    return task.q, task.dq, task.ddq


def check_parasitic(model: Model, task: Task, X: np.ndarray) -> None:
    """A 6-coordinate task given to the target must already satisfy its HKPs: its Z and gamma equal the
    parasitic ones of X_EE (within :data:`PARASITIC_TOLERANCE`)."""
    if not (model.has_hkp and task.coords == FULL_COORDS):
        return
    dev = np.abs(X[:, [2, 5]] - task.q[:, [2, 5]])
    bad = np.flatnonzero(dev.max(axis=1) > PARASITIC_TOLERANCE)
    if bad.size:
        i = int(bad[0])
        raise KinematicsError(
            f"task {task.name!r}: Z and gamma do not satisfy the target's HKPs (off by {dev[i, 0]:.3g} m, "
            f"{dev[i, 1]:.3g} rad); give X, Y, alpha, beta only and let the model compute the parasitic motions",
            sample=i, time=float(task.t[i]))


def mechanism_coordinates(model: Model, orientation: str, X, dX, ddX, e, de, dde):
    """q_EE of the mechanism in ``orientation`` and its rates, from X_EE and the Euler parameters."""
    if orientation == "euler-angles":
        cols = euler_angle_columns(model)
        return X[:, cols], dX[:, cols], ddX[:, cols]
    k, ne = (2, 3) if model.has_hkp else (3, 4)
    return tuple(np.concatenate([x[:, :k], y[:, :ne]], axis=1) for x, y in ((X, e), (dX, de), (ddX, dde)))


def euler_angle_motion(model: Model, orientation: str, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
                       times: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The inverse of :func:`mechanism_coordinates`: q_EE in ``orientation`` and its rates (N, n) -> the same motion in
    the mechanism's Euler-angle coordinates (X, Y, alpha, beta for the target, X_EE for the 6RSS) and its rates,
    exact (the pose and its rates by automatic differentiation, the angles' by
    :func:`chewbot.rotation.euler_parameters_to_angles`). Euler parameters off abs(e) = 1 at any level (position,
    velocity, acceleration; :data:`UNIT_NORM_TOLERANCE`) and gimbal lock raise :class:`KinematicsError` naming the
    first such sample."""
    check_orientation(orientation)
    if orientation == "euler-angles":
        return q, dq, ddq
    x, dx, ddx = evaluate(pose_rates_function(model.mechanism, orientation), q, dq, ddq, model.vector())
    e, de, dde = x[:, -4:], dx[:, -4:], ddx[:, -4:]
    levels = (("abs(e)^2 - 1", np.sum(e * e, axis=1) - 1, 1.0),
              ("its rate 2 e.e_dot", 2 * np.sum(e * de, axis=1), 1 + np.sum(np.abs(de), axis=1)),
              ("its second rate 2 (e.e_ddot + abs(e_dot)^2)", 2 * (np.sum(e * dde, axis=1) + np.sum(de * de, axis=1)),
               1 + np.sum(np.abs(dde), axis=1) + np.sum(de * de, axis=1)))
    for what, value, scale in levels:
        bad = np.flatnonzero(~(np.abs(value) <= UNIT_NORM_TOLERANCE * scale))
        if bad.size:
            k = int(bad[0])
            raise KinematicsError(f"the Euler parameters leave abs(e) = 1: {what} = {value[k]:.3g} (tolerance "
                                  f"{UNIT_NORM_TOLERANCE:g}); {bad.size} sample(s) affected", sample=k,
                                  time=None if times is None else float(times[k]))
    k = 2 if model.has_hkp else 3  # the independent positions, then as many angles
    angles = euler_parameters_to_angles(e, de, dde, times)
    return tuple(np.column_stack([lin[:, :k], ang[:, :k]]) for lin, ang in zip((x, dx, ddx), angles))


def check_workspace(model: Model, T_L: np.ndarray, T_R: np.ndarray, t: np.ndarray) -> None:
    """Both condyles inside their sockets (x and y bounds of docs/conventions.md); raises naming the first bad sample."""
    h, mm = model.hkp, factor("mm")
    slack = 1e-12
    for label, T, yr in (("left", T_L, h.y_left), ("right", T_R, h.y_right)):
        out_x = (T[:, 0] < h.x_range[0] - slack) | (T[:, 0] > h.x_range[1] + slack)
        out_y = (T[:, 1] < yr[0] - slack) | (T[:, 1] > yr[1] + slack)
        bad = np.flatnonzero(out_x | out_y)
        if bad.size:
            i = int(bad[0])
            raise KinematicsError(
                f"the {label} condyle leaves its socket: T = ({T[i, 0] / mm:.3f}, {T[i, 1] / mm:.3f}) mm, socket "
                f"x in [{h.x_range[0] / mm:g}, {h.x_range[1] / mm:g}] mm, y in [{yr[0] / mm:g}, {yr[1] / mm:g}] mm "
                f"({bad.size} sample(s) outside)",
                sample=i, time=float(t[i]))


def check_parallel_singularity(J_theta1: np.ndarray, J_unit: np.ndarray | None, t: np.ndarray) -> None:
    """Raise :class:`KinematicsError` at the first sample where J_theta1 loses rank (type II singularity).

    The columns are normalised first, so the test does not depend on the units of q_EE; for Euler parameters
    (``J_unit``: the gradient of abs(e)^2 - 1, (N, 1, n)) the direction that changes abs(e) is not a motion and is
    left out (J_theta1 restricted to an orthonormal basis of abs(e) = 1's tangent space). The test is on the ratio
    of the smallest to the largest singular value; it is computed only where a cheap bound cannot exclude it: with
    G = J' J (columns of unit length, so trace G = n), sigma_min / sigma_max < tol implies
    det G < tol^2 sigma_max^(2 n) <= tol^2 n^n.
    """
    J1 = J_theta1 if J_unit is None else J_theta1 @ _unit_norm_tangent(J_unit)
    J1 = J1 / np.linalg.norm(J1, axis=1, keepdims=True)
    n = J1.shape[2]
    gram = np.swapaxes(J1, 1, 2) @ J1
    candidates = np.flatnonzero(np.linalg.det(gram) < PARALLEL_SINGULAR_TOLERANCE**2 * float(n) ** n)
    if not candidates.size:
        return
    sv = np.linalg.svd(J1[candidates], compute_uv=False)
    ratio = sv[:, -1] / sv[:, 0]
    bad = candidates[ratio < PARALLEL_SINGULAR_TOLERANCE]
    if bad.size:
        i = int(bad[0])
        raise KinematicsError(f"parallel (type II) singularity: J_theta1 loses rank (singular-value ratio "
                              f"{ratio[np.searchsorted(candidates, i)]:.2e} < {PARALLEL_SINGULAR_TOLERANCE:g}), the "
                              f"actuators do not fix the mandible's motion; {bad.size} sample(s) affected",
                              sample=i, time=float(t[i]))


def _unit_norm_tangent(J_unit: np.ndarray) -> np.ndarray:
    """Orthonormal bases (N, n, n - 1) of the q_EE directions that keep abs(e) = 1 (normal to J_unit): the
    Householder reflection that maps the gradient g onto a coordinate axis k (its largest entry), without column k."""
    g = J_unit.reshape(J_unit.shape[0], -1)
    N, n = g.shape
    k = np.argmax(np.abs(g), axis=1)
    v = g / np.linalg.norm(g, axis=1, keepdims=True)
    v[np.arange(N), k] += np.where(g[np.arange(N), k] < 0, -1.0, 1.0)
    H = np.eye(n) - 2 * v[:, :, None] * v[:, None, :] / np.einsum("ni,ni->n", v, v)[:, None, None]
    keep = np.argsort(np.arange(n)[None, :] == k[:, None], axis=1, kind="stable")[:, :n - 1]
    return np.take_along_axis(H, keep[:, None, :], axis=2)


def check_e3_denominator(denominator: np.ndarray, t: np.ndarray) -> None:
    """Target with Euler parameters: e3 = e1 (e0 + p1 e2) / (p1 e0 - e2) is undefined where p1 e0 - e2 = 0."""
    bad = np.flatnonzero(np.abs(denominator) < E3_DENOMINATOR_TOLERANCE)
    if bad.size:
        raise KinematicsError("Euler parameters: p1 e0 - e2 = 0, the parasitic e3 is undefined here",
                              sample=int(bad[0]), time=float(t[bad[0]]))


def solve_kinematics(model: Model, task: Task, orientation: str = "euler-angles") -> Kinematics:
    """Inverse kinematics of a whole task: parasitic motions, workspace check, theta and all rates.

    One call of the compiled :func:`~chewbot.kinematics.functions.kinematics_kernel`; then the checks, in this
    order: the task's parasitic Z and gamma, the e3 denominator (target, Euler parameters), the sockets, the
    reach and the singular configuration of every chain, the parallel singularity. Each raises
    :class:`KinematicsError` naming the first bad sample (its time, and the chain where there is one).
    """
    check_orientation(orientation)
    if task.coords not in (TARGET_COORDS, FULL_COORDS):
        raise KinematicsError(f"task {task.name!r} has coordinates {task.coords}")
    q, dq, ddq = task_coordinates(model, task)
    fn = native(kinematics_kernel(model.mechanism, orientation))
    out = dict(zip(KINEMATICS_OUTPUTS, evaluate(fn, q, dq, ddq, model.vector())))
    check_parasitic(model, task, out["X"])
    euler_parameters = orientation == "euler-parameters"
    if euler_parameters and model.has_hkp:
        check_e3_denominator(out["e3_denominator"][:, 0], task.t)
    if model.has_hkp:
        check_workspace(model, out["T_L"], out["T_R"], task.t)
    check_chains(out["reach"], out["transmission"], task.t)
    check_parallel_singularity(out["J_theta1"], out["J_unit"] if euler_parameters else None, task.t)
    X, dX, ddX, e, de, dde = (out[k] for k in ("X", "dX", "ddX", "e", "de", "dde"))
    qo, dqo, ddqo = mechanism_coordinates(model, orientation, X, dX, ddX, e, de, dde)
    return Kinematics(
        model=model,
        orientation=orientation,
        t=np.array(task.t),
        coords=COORDINATES[(model.mechanism, orientation)],
        q=qo, dq=dqo, ddq=ddqo,
        X=X, dX=dX, ddX=ddX,
        e=e, de=de, dde=dde,
        theta=continuous(out["theta"]), dtheta=out["dtheta"], ddtheta=out["ddtheta"],
        twist=out["twist"], twist_rate=out["twist_rate"],
        force=np.array(task.force),
        side=task.side,
        points={k: out[k] for k in ("T_L", "T_R", "I", "B_L", "B_R")},
        transmission=out["transmission"],
        J_theta1_angles=out["J_theta1_angles"],
    )
