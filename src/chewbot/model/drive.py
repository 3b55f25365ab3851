"""The drive train's law: each crank driven by a DC motor through a gearhead, written once for NumPy and CasADi.

A crank's torque ``tau`` (N m, at the crank's shaft: the results' ``tau1..6``) and its motor's torque ``tau_m`` (N m,
at the motor: ``tau_motor1..6``, the current ``i = tau_m / k_t`` times the torque constant) are related by the
gearbox's ratio N and efficiency eta, which takes its loss from the power that flows through it, in either direction:

    tau = N tau_m eta^s,    s = tanh(P_m / P_0),    P_m = tau_m omega_m = N tau_m theta_dot (the motor's power).

Driving (the motor gives power, s -> +1), the crank gets eta N tau_m; back-driven (the load gives it, s -> -1), the
motor holds N tau_m / eta. ``tanh`` blends the two over motor powers of about P_0 = :data:`EFFICIENCY_BLEND_W`, so the
law is smooth (its derivatives exact, for the integrator and the estimator) where a crank stops or its torque
changes sign. The gearbox's loss P_m - tau theta_dot = P_m (1 - eta^s) is >= 0 in both directions. The rotor's inertia
J_r is lumped with the crank's, reflected through the gears loss-free as J_r N^2 (``Model.crank_total_inertia``), so
``tau`` includes its inertia torque J_r N^2 theta_ddot.

From the motor's torque the crank's follows explicitly; the motor's from the crank's by Newton's iteration
(:data:`NEWTON_ITERATIONS` steps from the loss law evaluated at the crank's power): for eta > 0.11 the crank's torque
grows monotonically with the motor's (d tau / d tau_m >= N eta^s (1 + 0.45 ln eta) > 0), so the root is unique.
Without a drive the parameters are neutral (N = 1, eta = 1, k_t = 1 N m/A, :data:`NEUTRAL`) and the law the identity.

The encoders count ``encoder_counts`` per motor revolution: the crank's angle is known on a grid of
2 pi / (counts N) rad (:func:`quantise`, rounding to the nearest count).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from chewbot.model.model import Drive
from chewbot.model.vector import BLOCKS

# The motor power (W) over which the loss law turns from driving to back-driven: small against a chewing motion's
# motor powers (0.1 to 10 W), large enough that the blend takes a few samples at 1 kHz where a crank turns around.
EFFICIENCY_BLEND_W = 0.01
# Newton steps from the motor torque to the crank torque's inverse: the first guess is within a factor eta^2 of the
# answer, and the iteration converges quadratically (to rounding in four to five steps; eight for margin).
NEWTON_ITERATIONS = 8
# The entries of p for a model without a drive (chewbot.model.vector's neutral values): the identity law.
NEUTRAL = Drive(**{b.name.removeprefix("drive."): b.absent for b in BLOCKS if b.name.startswith("drive.")})


def _xp(*values):
    return ca if any(isinstance(v, (ca.SX, ca.MX, ca.DM)) for v in values) else np


def of(model) -> Drive:
    """The drive of ``model`` (numeric), or :data:`NEUTRAL` where it has none."""
    return NEUTRAL if model.drive is None else model.drive


def crank_torque(drive, tau_motor, dtheta):
    """The crank's torque (N m) from its motor's ``tau_motor`` (N m) at crank rate ``dtheta`` (rad/s): the loss law.
    ``drive``: a :class:`~chewbot.model.Drive` or a symbolic model's ``drive`` (then CasADi expressions)."""
    xp = _xp(tau_motor, dtheta, drive.efficiency)
    ideal = drive.gear_ratio * tau_motor
    return ideal * drive.efficiency ** xp.tanh(ideal * dtheta / EFFICIENCY_BLEND_W)


def motor_torque(drive, tau, dtheta):
    """The motor's torque (N m) that gives the crank's ``tau`` (N m) at crank rate ``dtheta`` (rad/s): the loss law
    inverted by :data:`NEWTON_ITERATIONS` Newton steps (exact to rounding)."""
    xp = _xp(tau, dtheta, drive.efficiency)
    N, log_eta = drive.gear_ratio, xp.log(drive.efficiency)
    x = tau / (N * drive.efficiency ** xp.tanh(tau * dtheta / EFFICIENCY_BLEND_W))
    a = N * dtheta / EFFICIENCY_BLEND_W
    for _ in range(NEWTON_ITERATIONS):
        s = xp.tanh(a * x)
        gain = N * drive.efficiency**s
        x = x - (gain * x - tau) / (gain * (1 + x * log_eta * a * (1 - s * s)))
    return x


def current(drive, tau_motor):
    """The motor's current (A) for its torque ``tau_motor`` (N m)."""
    return tau_motor / drive.torque_constant


def torque_of_current(drive, i):
    """The motor's torque (N m) for its current ``i`` (A)."""
    return drive.torque_constant * i


def gearbox_loss(drive, tau_motor, dtheta):
    """The power the gearbox takes (W, >= 0): the motor's N tau_m theta_dot less the crank's tau theta_dot."""
    return (drive.gear_ratio * tau_motor - crank_torque(drive, tau_motor, dtheta)) * dtheta


def count_angle(drive) -> float:
    """The crank's angle of one encoder count (rad): 2 pi / (counts N), counted at the motor (a drive with an encoder)."""
    return 2 * np.pi / (drive.encoder_counts * drive.gear_ratio)


def quantise(drive, theta):
    """Crank angles (rad) as the motors' encoders read them: on the grid of :func:`count_angle`, the nearest count
    (NumPy; the angle unchanged without an encoder)."""
    if not drive.encoder_counts:
        return np.asarray(theta, float)
    step = count_angle(drive)
    return np.round(np.asarray(theta, float) / step) * step


def add_columns(table, drive, tau, dtheta) -> None:
    """Add the motors' torques ``tau_motor1..6`` (N m) and currents ``i1..6`` (A) of the crank torques ``tau`` (K, 6)
    at crank rates ``dtheta`` (K, 6) to ``table`` (a :class:`~chewbot.table.Table`)."""
    tau_m = motor_torque(drive, np.asarray(tau, float), np.asarray(dtheta, float))
    table.add_block([f"tau_motor{i + 1}" for i in range(6)], tau_m, "N*m",
                    "motor torque of crank i's drive (gear ratio and the gearbox's loss law, docs/models.md)")
    table.add_block([f"i{i + 1}" for i in range(6)], current(drive, tau_m), "A", "motor current of crank i's drive")
