"""Inverse and forward kinematics of poses, one call each: the crank angles of the mandible's coordinates and back.

``q`` is the mechanism's independent coordinates (docs/conventions.md): in Euler angles X, Y, alpha, beta on the
target (Z and gamma follow from its sockets) and X, Y, Z, alpha, beta, gamma on the 6RSS, in m and rad; in Euler
parameters X, Y, e0, e1, e2 on the target and X, Y, Z, e0, e1, e2, e3 on the 6RSS. ``theta`` the six crank angles
in rad. One sample or many (:mod:`chewbot.api.samples`); the samples are independent poses, not a trajectory.
"""

from __future__ import annotations

import numpy as np

from chewbot.api.samples import Argument, batch, coordinates, kinematics
from chewbot.errors import KinematicsError
from chewbot.kinematics import ik
from chewbot.kinematics.options import Orientation, Side
from chewbot.model import Model

# Forward kinematics answers a pose whose crank angles, solved back on the working branch, differ from the given ones
# by at most this (rad): Newton's closure residual is below 1e-9 of L_r^2 there, about 1e-9 rad of crank angle.
BRANCH_TOLERANCE = 1e-6


def wrapped(theta: np.ndarray) -> np.ndarray:
    """Angles in (-pi, pi]."""
    return np.pi - np.remainder(np.pi - theta, 2 * np.pi)


def inverse_kinematics(model: Model, q, *, orientation: str = Orientation.euler_angles.value) -> np.ndarray:
    """The crank angles theta (..., 6) in rad, each in (-pi, pi], of the poses ``q`` ((n,) or (N, n), the
    mechanism's coordinates in ``orientation``), on the working branch of every chain
    (:mod:`chewbot.kinematics.ik`).

    The poses are checked as a run checks its task (the condyles in their sockets, every chain within reach and
    away from its singular configuration, no parallel singularity): :class:`~chewbot.errors.KinematicsError` names
    the first bad sample (and chain)."""
    b = batch(coordinates(model, orientation, "q", q))
    q = b.arrays[0]
    zero = np.zeros_like(q)
    kin = kinematics(model, orientation, q, zero, zero, np.zeros((b.n, 3)), Side.left.value)
    return b.out(wrapped(kin.theta))


def forward_kinematics(model: Model, theta, *, orientation: str = Orientation.euler_angles.value, q0=None) -> np.ndarray:
    """The pose q (..., n) (the mechanism's coordinates in ``orientation``) whose crank angles are ``theta``
    ((6,) or (N, 6), rad), by Newton's method on the closure equations from ``q0`` (default: the home pose;
    :func:`chewbot.kinematics.ik.forward_kinematics`).

    The answer is checked: its inverse kinematics on the working branch must give ``theta`` back (within
    :data:`BRANCH_TOLERANCE` rad) and it must pass :func:`inverse_kinematics`'s checks. Crank angles that no pose
    closes (the target's four coordinates cannot satisfy all six chains), or that Newton's method closes on another
    branch or assembly, are a :class:`~chewbot.errors.KinematicsError` naming the sample."""
    arguments = [Argument("theta", theta, 6, "the crank angles theta1..theta6 in rad")]
    if q0 is not None:
        arguments.append(coordinates(model, orientation, "q0", q0))
    b = batch(*arguments)
    q = ik.forward_kinematics(model, b.arrays[0], orientation, None if q0 is None else b.arrays[1])
    back = inverse_kinematics(model, q, orientation=orientation)
    off = np.abs(wrapped(back - b.arrays[0])).max(axis=1)
    bad = np.flatnonzero(~(off <= BRANCH_TOLERANCE))
    if bad.size:
        k = int(bad[0])
        raise KinematicsError(f"forward kinematics closed the chains on another branch or assembly: the pose's crank "
                              f"angles on the working branch differ from theta by {off[k]:.3g} rad (give q0 near the "
                              f"pose); {bad.size} sample(s) affected", sample=k)
    return b.out(q)
