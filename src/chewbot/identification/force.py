"""The bite force from a robot log or from crank angles and torques: the motion recovered as ``chewbot identify``
recovers it (:mod:`chewbot.identification.motion`: poses by least squares on the angles, rates by the
Savitzky-Golay filter of :mod:`chewbot.task.smoothing` unless given), then the estimator of
:mod:`chewbot.dynamics.bite_force`."""

from __future__ import annotations

import numpy as np

from chewbot.dynamics.bite_force import ForceEstimate, estimate
from chewbot.identification.log import RobotLog
from chewbot.identification.motion import log_motion
from chewbot.model import Model
from chewbot.task import WINDOW_S


def estimate_log(model: Model, log: RobotLog, *, side: str = "left", contact: str = "bilateral", friction: bool = True,
                 window_s: float = WINDOW_S, sigma: float | None = None) -> ForceEstimate:
    """F_B, N_L, N_R with standard errors at every sample of ``log`` (its t, crank angles, optional rates, torques or
    currents: :meth:`~chewbot.identification.log.RobotLog.crank_torques`; a logged bite force is not used). ``window_s``: the smoothing window of the rates the log does not give;
    the other options as :func:`chewbot.dynamics.bite_force.estimate`. ``info["rates"]`` says how the rates were
    obtained."""
    motion = log_motion(model, log, side, window_s)
    result = estimate(model, motion.kin, log.crank_torques(model, motion.kin.dtheta), side=side, contact=contact,
                      friction=friction, sigma=sigma)
    result.info.update({"reads": log.reads(model), "rates": motion.rates, "window_samples": motion.window_samples, "window_s": window_s,
                        "angle_residual_rms_rad": float(np.sqrt(np.mean(motion.angle_residual**2)))})
    return result


def estimate_angles(model: Model, t, theta, tau, *, side: str = "left", contact: str = "bilateral", friction: bool = True,
                    rates: tuple | None = None, window_s: float = WINDOW_S, sigma: float | None = None,
                    source: str = "angles") -> ForceEstimate:
    """:func:`estimate_log` on arrays: times ``t`` (n,) s, crank angles ``theta`` (n, 6) rad, measured torques ``tau``
    (n, 6) N m, optionally ``rates`` = (theta_dot, theta_ddot) (n, 6) each (else smoothed from the angles)."""
    t = np.asarray(t, float)
    dtheta, ddtheta = (None, None) if rates is None else (np.asarray(rates[0], float), np.asarray(rates[1], float))
    log = RobotLog(source, t, np.asarray(theta, float), dtheta, ddtheta, np.asarray(tau, float), np.zeros((t.size, 3)),
                   np.arange(t.size) + 2)
    return estimate_log(model, log, side=side, contact=contact, friction=friction, window_s=window_s, sigma=sigma)
