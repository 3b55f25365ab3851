"""Orientation of the mandible: XYZ Euler angles and Euler parameters, symbolic and batched.

Conventions (docs/conventions.md): R rotates {M} into {S}.

* XYZ Euler angles: R = Rx(alpha) Ry(beta) Rz(gamma) (seed 000, Eq. 3); the angular velocity in {S} is
  omega = R_omega(alpha, beta) [alpha_dot, beta_dot, gamma_dot] with
  R_omega = [[1, 0, s_beta], [0, c_alpha, -s_alpha c_beta], [0, s_alpha, c_alpha c_beta]]
  (erratum (docs/conventions.md): seed 000 prints -c_alpha c_beta in the last entry).
* Euler parameters e = (e0, e1, e2, e3), e0 the scalar part, abs(e) = 1:
  R = (e0^2 - ev.ev) I + 2 ev ev^T + 2 e0 [ev]x, and omega = 2 E(e) e_dot with E = [-ev, e0 I + [ev]x].

The ``*_sx`` functions build CasADi expressions (for exact derivatives); the others work on NumPy arrays
with samples first (shape (N, ...)), like SciPy's ``Rotation``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from chewbot.errors import KinematicsError

# |cos(beta)| below this is gimbal lock of the XYZ angles: R_omega is singular there.
GIMBAL_LOCK_TOLERANCE = 1e-6


def matrix_from_euler_angles_sx(alpha, beta, gamma):
    """R = Rx(alpha) Ry(beta) Rz(gamma) as a CasADi expression (seed 000, Eq. 3)."""
    ca_, sa, cb, sb, cg, sg = ca.cos(alpha), ca.sin(alpha), ca.cos(beta), ca.sin(beta), ca.cos(gamma), ca.sin(gamma)
    return ca.vertcat(
        ca.horzcat(cb * cg, -cb * sg, sb),
        ca.horzcat(sa * sb * cg + ca_ * sg, -sa * sb * sg + ca_ * cg, -sa * cb),
        ca.horzcat(-ca_ * sb * cg + sa * sg, ca_ * sb * sg + sa * cg, ca_ * cb),
    )


def matrix_from_euler_parameters_sx(e0, e1, e2, e3):
    """Rotation matrix of the Euler parameters (e0 scalar part) as a CasADi expression."""
    return ca.vertcat(
        ca.horzcat(e0**2 + e1**2 - e2**2 - e3**2, 2 * (e1 * e2 - e0 * e3), 2 * (e1 * e3 + e0 * e2)),
        ca.horzcat(2 * (e1 * e2 + e0 * e3), e0**2 - e1**2 + e2**2 - e3**2, 2 * (e2 * e3 - e0 * e1)),
        ca.horzcat(2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), e0**2 - e1**2 - e2**2 + e3**2),
    )


def R_omega_sx(alpha, beta):
    """The map from XYZ Euler-angle rates to the angular velocity in {S} (docs/conventions.md, with the erratum)."""
    return ca.vertcat(
        ca.horzcat(1, 0, ca.sin(beta)),
        ca.horzcat(0, ca.cos(alpha), -ca.sin(alpha) * ca.cos(beta)),
        ca.horzcat(0, ca.sin(alpha), ca.cos(alpha) * ca.cos(beta)),
    )


def E_sx(e0, e1, e2, e3):
    """E(e), 3x4, with omega = 2 E(e) e_dot (angular velocity in {S})."""
    return ca.vertcat(
        ca.horzcat(-e1, e0, -e3, e2),
        ca.horzcat(-e2, e3, e0, -e1),
        ca.horzcat(-e3, -e2, e1, e0),
    )


# ---------------------------------------------------------------- batched NumPy (samples first)


def matrix_from_euler_angles(angles: np.ndarray) -> np.ndarray:
    """(N, 3) XYZ angles -> (N, 3, 3) rotation matrices."""
    a, b, c = np.moveaxis(np.atleast_2d(angles), -1, 0)
    ca_, sa, cb, sb, cg, sg = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    return np.stack(
        [
            np.stack([cb * cg, -cb * sg, sb], -1),
            np.stack([sa * sb * cg + ca_ * sg, -sa * sb * sg + ca_ * cg, -sa * cb], -1),
            np.stack([-ca_ * sb * cg + sa * sg, ca_ * sb * sg + sa * cg, ca_ * cb], -1),
        ],
        -2,
    )


def matrix_from_euler_parameters(e: np.ndarray) -> np.ndarray:
    """(N, 4) Euler parameters (e0 first) -> (N, 3, 3) rotation matrices."""
    e0, e1, e2, e3 = np.moveaxis(np.atleast_2d(e), -1, 0)
    return np.stack(
        [
            np.stack([e0**2 + e1**2 - e2**2 - e3**2, 2 * (e1 * e2 - e0 * e3), 2 * (e1 * e3 + e0 * e2)], -1),
            np.stack([2 * (e1 * e2 + e0 * e3), e0**2 - e1**2 + e2**2 - e3**2, 2 * (e2 * e3 - e0 * e1)], -1),
            np.stack([2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), e0**2 - e1**2 - e2**2 + e3**2], -1),
        ],
        -2,
    )


def R_omega(angles: np.ndarray) -> np.ndarray:
    """(N, 3) XYZ angles -> (N, 3, 3) maps from angle rates to omega in {S}."""
    a, b = np.atleast_2d(angles)[:, 0], np.atleast_2d(angles)[:, 1]
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack(
        [
            np.stack([o, z, np.sin(b)], -1),
            np.stack([z, np.cos(a), -np.sin(a) * np.cos(b)], -1),
            np.stack([z, np.sin(a), np.cos(a) * np.cos(b)], -1),
        ],
        -2,
    )


def R_omega_dot(angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """(N, 3) XYZ angles and their rates -> (N, 3, 3) the time derivative of :func:`R_omega`."""
    a, b = angles[:, 0], angles[:, 1]
    da, db = rates[:, 0], rates[:, 1]
    z = np.zeros_like(a)
    return np.stack(
        [
            np.stack([z, z, np.cos(b) * db], -1),
            np.stack([z, -np.sin(a) * da, -np.cos(a) * np.cos(b) * da + np.sin(a) * np.sin(b) * db], -1),
            np.stack([z, np.cos(a) * da, -np.sin(a) * np.cos(b) * da - np.cos(a) * np.sin(b) * db], -1),
        ],
        -2,
    )


def E_matrix(e: np.ndarray) -> np.ndarray:
    """(N, 4) Euler parameters -> (N, 3, 4) E(e), omega = 2 E e_dot."""
    e0, e1, e2, e3 = np.moveaxis(np.atleast_2d(e), -1, 0)
    return np.stack(
        [
            np.stack([-e1, e0, -e3, e2], -1),
            np.stack([-e2, e3, e0, -e1], -1),
            np.stack([-e3, -e2, e1, e0], -1),
        ],
        -2,
    )


def euler_angles_from_matrix(R: np.ndarray, times: np.ndarray | None = None) -> np.ndarray:
    """(N, 3, 3) -> (N, 3) XYZ Euler angles, beta in [-pi/2, pi/2]; gimbal lock is an error naming the sample."""
    R = np.asarray(R)
    cb = np.hypot(R[:, 0, 0], R[:, 0, 1])
    _check_gimbal(cb, times)
    alpha = np.arctan2(-R[:, 1, 2], R[:, 2, 2])
    beta = np.arctan2(R[:, 0, 2], cb)
    gamma = np.arctan2(-R[:, 0, 1], R[:, 0, 0])
    return np.stack([alpha, beta, gamma], -1)


def euler_parameters_from_matrix(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) -> (N, 4) Euler parameters, e0 >= 0 (Shepperd's method, robust for any rotation)."""
    R = np.asarray(R)
    tr = np.trace(R, axis1=1, axis2=2)
    diag = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], -1)
    k = np.argmax(diag, axis=1)
    e = np.empty((R.shape[0], 4))
    for case in range(4):  # four closed-form branches, each vectorised over its samples
        idx = k == case
        if not idx.any():
            continue
        r = R[idx]
        if case == 0:
            s = 2.0 * np.sqrt(1.0 + tr[idx])
            e[idx] = np.stack([s / 4, (r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s, (r[:, 1, 0] - r[:, 0, 1]) / s], -1)
        else:
            i, j, m = case - 1, case % 3, (case + 1) % 3
            s = 2.0 * np.sqrt(1.0 + r[:, i, i] - r[:, j, j] - r[:, m, m])
            out = np.empty((r.shape[0], 4))
            out[:, 0] = (r[:, m, j] - r[:, j, m]) / s
            out[:, 1 + i] = s / 4
            out[:, 1 + j] = (r[:, j, i] + r[:, i, j]) / s
            out[:, 1 + m] = (r[:, m, i] + r[:, i, m]) / s
            e[idx] = out
    e *= np.where(e[:, :1] < 0, -1.0, 1.0)
    return e


def _check_gimbal(cos_beta: np.ndarray, times: np.ndarray | None) -> None:
    bad = np.flatnonzero(np.abs(cos_beta) < GIMBAL_LOCK_TOLERANCE)
    if bad.size:
        i = int(bad[0])
        raise KinematicsError(
            f"gimbal lock of the XYZ Euler angles (cos(beta) = {cos_beta[i]:.3g}): the angle rates are undefined; "
            f"{bad.size} sample(s) affected",
            sample=i,
            time=None if times is None else float(times[i]),
        )


def euler_angles_to_parameters(angles, rates, accels):
    """Convert a motion from XYZ Euler angles to Euler parameters at position, velocity and acceleration level.

    All arrays (N, 3) -> e, e_dot, e_ddot (N, 4). Exact: through R, omega = R_omega a_dot and
    omega_dot = R_omega a_ddot + R_omega_dot a_dot; then e_dot = E^T omega / 2 and
    e_ddot = E^T omega_dot / 2 - abs(e_dot)^2 e (from e.e = 1 differentiated twice).
    """
    angles, rates, accels = (np.atleast_2d(x) for x in (angles, rates, accels))
    e = euler_parameters_from_matrix(matrix_from_euler_angles(angles))
    Rw = R_omega(angles)
    omega = np.einsum("nij,nj->ni", Rw, rates)
    omega_dot = np.einsum("nij,nj->ni", Rw, accels) + np.einsum("nij,nj->ni", R_omega_dot(angles, rates), rates)
    Et = np.swapaxes(E_matrix(e), 1, 2)
    e_dot = 0.5 * np.einsum("nij,nj->ni", Et, omega)
    e_ddot = 0.5 * np.einsum("nij,nj->ni", Et, omega_dot) - np.sum(e_dot**2, axis=1, keepdims=True) * e
    return e, e_dot, e_ddot


def euler_parameters_to_angles(e, e_dot, e_ddot, times=None):
    """Convert a motion from Euler parameters to XYZ Euler angles at all three levels (seed 001, Sect. 5.4).

    (N, 4) arrays -> angles, rates, accels (N, 3). Gimbal lock (cos(beta) = 0, R_omega singular) is an error
    naming the first sample where it occurs.
    """
    e, e_dot, e_ddot = (np.atleast_2d(x) for x in (e, e_dot, e_ddot))
    angles = euler_angles_from_matrix(matrix_from_euler_parameters(e), times)
    E = E_matrix(e)
    omega = 2 * np.einsum("nij,nj->ni", E, e_dot)
    omega_dot = 2 * np.einsum("nij,nj->ni", E, e_ddot)  # E_dot e_dot = 0 identically
    Rw = R_omega(angles)
    rates = np.linalg.solve(Rw, omega[..., None])[..., 0]
    accels = np.linalg.solve(Rw, (omega_dot - np.einsum("nij,nj->ni", R_omega_dot(angles, rates), rates))[..., None])[..., 0]
    return angles, rates, accels
