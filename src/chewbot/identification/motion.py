"""The mandible's motion from a log's crank angles: poses by least squares on the angles, rates by smoothing.

Forward kinematics as the robot needs it: the target's six crank angles over-determine its four coordinates, and
measured angles carry noise, so the closure cannot hold exactly. The pose of each sample is the least-squares fit
of the model's angles theta(q) (closed-form inverse kinematics) to the measured ones, by Gauss-Newton on all
samples at once with the exact Jacobian d theta / d q of the compiled kinematics kernel. Its residual (2 degrees of
freedom per sample on the target, none on the 6RSS) measures the angles' noise and the geometry's error.

Rates: the fitted coordinates are differentiated by the Savitzky-Golay filter of :mod:`chewbot.task.smoothing`
(``window_s`` long, degree 5); where the log gives the crank rates, q_dot solves J q_dot = theta_dot by least
squares and q_ddot solves J q_ddot = theta_ddot - (theta_ddot at q_ddot = 0), or is the filter's derivative of
q_dot. The motion then goes through :func:`chewbot.kinematics.motion.solve_kinematics` like any task, so the
angles, rates and checks are the model's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chewbot.compiled.kernels import evaluate, native
from chewbot.dynamics.formulations.newton_euler import EPS_THETA_DOT
from chewbot.errors import KinematicsError, TaskError
from chewbot.identification.log import RobotLog
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.kinematics.motion import Kinematics, solve_kinematics
from chewbot.model import Model
from scipy.signal import savgol_coeffs
from chewbot.task import smoothing
from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task

# Gauss-Newton on the angles stops when the largest step is below this (m or rad).
STEP_TOL = 1e-13
MAX_ITERATIONS = 50
# Samples where a crank turns slower than the larger of these are left out of the fit (LogMotion.moving).
MIN_SPEED_NOISES = 5.0
MIN_SPEED_EPS = 10.0
# A sample whose angles the model cannot fit closer than this (rad, RMS over the six) is not a pose of this robot:
# a wrong model, a column in the wrong place or an angle offset, not noise (encoders resolve ~1e-4 rad).
MAX_ANGLE_RESIDUAL = 1e-2


@dataclass(frozen=True, eq=False)
class LogMotion:
    """The motion recovered from a log: ``kin`` (:class:`Kinematics`, Euler angles), the RMS residual of the angle
    fit per sample (rad), and how the rates were obtained (``rates``: ``"smoothed"`` or ``"logged"`` per order).
    ``tau`` (n, 6) N m: the torques that go with the motion (the log's; with ``held``, their average that matches
    the smoothed accelerations); ``rate_sd``, ``acceleration_sd`` (n, dof): the standard deviations of the
    coordinates' smoothed rates (:class:`chewbot.task.smoothing.LocalFits`; 0 where logged); ``cuts``: the samples
    the smoothing does not reach across."""

    kin: Kinematics
    angle_residual: np.ndarray
    rates: dict
    window_samples: int
    speed_noise: float  # rad/s: standard deviation of the crank rates' error (0 where the log gives the rates)
    tau: np.ndarray | None = None
    rate_sd: np.ndarray | None = None
    acceleration_sd: np.ndarray | None = None
    cuts: tuple[int, ...] = ()

    @property
    def min_speed(self) -> float:
        """rad/s: the larger of :data:`MIN_SPEED_NOISES` times the rates' noise and :data:`MIN_SPEED_EPS` times the
        regularisation of sgn(theta_dot)."""
        return max(MIN_SPEED_NOISES * self.speed_noise, MIN_SPEED_EPS * EPS_THETA_DOT)

    def moving(self) -> np.ndarray:
        """(N,) True where every crank turns faster than :attr:`min_speed`. Elsewhere the direction of the
        Coulomb friction is not known (at rest static friction is indeterminate, and a smoothed rate near zero has
        a random sign): those samples are left out of the fit."""
        return np.abs(self.kin.dtheta).min(axis=1) > self.min_speed


def fit_poses(model: Model, theta: np.ndarray, where=None) -> tuple[np.ndarray, np.ndarray]:
    """q_EE in Euler angles (N, 4 or 6) whose model angles fit ``theta`` (N, 6) best, and the residual (N, 6) rad.

    Gauss-Newton from the home pose on all samples at once, with backtracking; ``where(i)`` names sample i in errors. Raises
    :class:`KinematicsError` where it does not converge or leaves the workspace, :class:`TaskError` where the
    fit is worse than :data:`MAX_ANGLE_RESIDUAL`.
    """
    fn = native(kinematics_kernel(model.mechanism, "euler-angles"))
    p = model.vector()
    n, k = theta.shape[0], model.dof
    q = np.zeros((n, k))
    zeros = np.zeros(k)  # the rates, the same at every sample
    it_theta, it_J = KINEMATICS_OUTPUTS.index("theta"), KINEMATICS_OUTPUTS.index("J_theta1_angles")

    def residual(q, rows=slice(None)):
        out = evaluate(fn, q, zeros, zeros, p)
        return _wrap(theta[rows] - out[it_theta]), out[it_J]

    res, J = residual(q)
    trial, J_trial = np.empty_like(res), np.empty_like(J)
    for _ in range(MAX_ITERATIONS):
        step = _lstsq(J, res)
        # Backtracking per sample: far from home a full step can leave the workspace (no inverse kinematics) or
        # overshoot; it is halved until the angles' residual is finite and smaller (a halving evaluates the samples
        # still worse, alone).
        cost = np.sum(res**2, axis=1)
        alpha, rows = np.ones(n), np.arange(n)
        for _ in range(30):
            trial[rows], J_trial[rows] = residual(q[rows] + alpha[rows, None] * step[rows], rows)
            worse = ~(np.sum(trial[rows] ** 2, axis=1) <= cost[rows]) & np.isfinite(step[rows]).all(axis=1)
            if not worse.any():
                break
            rows = rows[worse]
            alpha[rows] /= 2
        if not (np.isfinite(step).all() and np.isfinite(trial).all()):
            bad = ~(np.isfinite(step).all(axis=1) & np.isfinite(trial).all(axis=1))
            i = int(np.flatnonzero(bad)[0])
            raise KinematicsError(f"{where(i) if where else f'sample {i}'}: the crank angles give no pose of the model "
                                  "(out of reach or singular)")
        q, res, J = q + alpha[:, None] * step, trial.copy(), J_trial.copy()
        if np.abs(alpha[:, None] * step).max() < STEP_TOL:
            break
    rms = np.sqrt(np.mean(res**2, axis=1))
    bad = np.flatnonzero(~(rms <= MAX_ANGLE_RESIDUAL))
    if bad.size:
        i = int(bad[0])
        column = f"theta{int(np.argmax(np.abs(res[i]))) + 1}"
        raise TaskError(f"{where(i) if where else f'sample {i}'}: the crank angles fit no pose of the model: RMS residual "
                        f"{np.degrees(rms[i]):.3g} deg > {np.degrees(MAX_ANGLE_RESIDUAL):.3g} deg, largest in column "
                        f"{column} ({bad.size} sample(s)); check the model, the order of the theta columns and their zero")
    return q, res


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _lstsq(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Least-squares solutions of J x = r, batched (J (N, 6, k) of full column rank away from singularities)."""
    Q, R = np.linalg.qr(J)
    return np.linalg.solve(R, np.einsum("nki,nk->ni", Q, r)[..., None])[..., 0]


def log_motion(model: Model, log: RobotLog, side: str = "left", window_s: float = smoothing.WINDOW_S,
               cuts: tuple[int, ...] = (), held: bool = False) -> LogMotion:
    """The mandible's motion along a log (see the module docstring), as :class:`LogMotion`. ``cuts``: samples the
    rates' smoothing does not reach across (events: the force jumps there); ``held``: the log's torques are held
    between samples (a digital controller's), and are averaged to match the smoothed accelerations
    (:func:`chewbot.task.smoothing.held_weights`)."""
    q, res = fit_poses(model, log.theta, lambda i: f"{log.source}: {log.where(i)}")
    coords = TARGET_COORDS if model.has_hkp else FULL_COORDS
    needs_filter = log.dtheta is None or log.ddtheta is None
    window = 0
    if needs_filter:
        try:
            dt = smoothing.uniform_step(log.t)
            window = smoothing.window_samples(log.n, dt, window_s)
        except smoothing.IrregularSampling as exc:
            raise TaskError(f"{log.source}: {log.where(exc.sample)}: {exc}") from None
        except TaskError as exc:
            raise TaskError(f"{log.source}: {exc}") from None
    fn = native(kinematics_kernel(model.mechanism, "euler-angles"))
    p = model.vector()
    zeros = np.zeros_like(q)
    out = dict(zip(KINEMATICS_OUTPUTS, evaluate(fn, q, zeros, zeros, p)))
    J = out["J_theta1_angles"]
    tau, rate_sd, acc_sd = log.tau, zeros, zeros
    if log.dtheta is None:
        fits = smoothing.local_fits(log.t, q, window_s, cuts, log.tau if held else None)
        dq, ddq, rate_sd, acc_sd = fits.rate, fits.acceleration, fits.rate_sd, fits.acceleration_sd
    else:
        dq = _lstsq(J, log.dtheta)
        if log.ddtheta is None:
            fits = smoothing.local_fits(log.t, dq, window_s, cuts, log.tau if held else None)
            ddq, acc_sd = fits.rate, fits.rate_sd
    if log.ddtheta is not None:
        bias = dict(zip(KINEMATICS_OUTPUTS, evaluate(fn, q, dq, zeros, p)))["ddtheta"]  # theta_ddot at q_ddot = 0
        ddq = _lstsq(J, log.ddtheta - bias)
    elif held:
        tau = fits.held
    task = Task(name=log.source, t=log.t, coords=coords, q=q, dq=dq, ddq=ddq, force=log.force, side=side,
                source=log.source, lines=log.lines)
    try:
        kin = solve_kinematics(model, task, "euler-angles")
    except KinematicsError as exc:
        raise exc.located(f"{log.source}: {log.where(exc.sample)}" if exc.sample is not None else log.source) from None
    rates = {"first": "logged" if log.dtheta is not None else "smoothed",
             "second": "logged" if log.ddtheta is not None else "smoothed"}
    speed_noise = 0.0
    if log.dtheta is None:
        # the angles' noise from the fit's residual (6 - dof degrees of freedom of 6 per sample), times the filter's
        # gain on white noise for the first derivative
        dof = 6 - model.dof
        sigma = np.sqrt(np.mean(res**2) * 6 / dof) if dof else 0.0
        gain = np.linalg.norm(savgol_coeffs(window, smoothing.POLYORDER, deriv=1, delta=smoothing.uniform_step(log.t)))
        speed_noise = float(sigma * gain)
    return LogMotion(kin, np.sqrt(np.mean(res**2, axis=1)), rates, window, speed_noise, tau, rate_sd, acc_sd,
                     tuple(cuts) if needs_filter else ())
