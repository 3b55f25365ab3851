"""The bite force from a robot log or from crank angles and torques: the motion recovered as ``chewbot identify``
recovers it (:mod:`chewbot.identification.motion`: poses by least squares on the angles, rates by the local
polynomial fits of :mod:`chewbot.task.smoothing` unless given), then the estimator of
:mod:`chewbot.dynamics.bite_force`, with the model's uncertainty where it has one.

Where the rates are smoothed, two things keep the force's steps (a brittle food's fracture) out of the smoothing:

* **Held torques.** The log's torques are held between samples (a digital controller's command; chewbot's
  simulated logs). The smoothed acceleration at a sample is a weighted average of the true acceleration over the
  window; the torques enter the same average (:func:`chewbot.task.smoothing.held_weights`), so the equations are
  those of the averaged motion and the estimate is the same average of the force. Without it the torques of
  the instant would meet the accelerations of the window: a controller's reaction to a fracture, a few ticks of
  large torque changes, then puts a spike of the size of the force's step into the estimate.
* **Events.** Where the force jumps (:func:`force_events`), the motion's acceleration jumps with it: no window
  reaches across the event (:func:`chewbot.task.smoothing.local_fits` with cuts), so the estimate steps where
  the force steps, with no ringing or spike either side.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from chewbot.dynamics.bite_force import ForceEstimate, estimate
from chewbot.identification.log import RobotLog
from chewbot.identification.motion import LogMotion, log_motion
from chewbot.model import Model
from chewbot.task import WINDOW_S

# The event detector: one-sided fits this long (s) before and after each sample, of this degree; a step of the
# force between two samples larger than EVENT_FRACTION of the largest force and EVENT_SCALES times the steps'
# robust spread, which the force keeps for EVENT_WINDOW_S on either side (half of it at least: a fracture, not the
# one-sided fits' disagreement at a friction reversal), is an event.
EVENT_WINDOW_S = 0.01
EVENT_POLYORDER = 2
EVENT_FRACTION = 0.05
EVENT_SCALES = 20.0


def estimate_log(model: Model, log: RobotLog, *, side: str = "left", contact: str = "bilateral", friction: bool = True,
                 window_s: float = WINDOW_S, sigma: float | None = None, events: bool = True) -> ForceEstimate:
    """F_B, N_L, N_R with standard errors at every sample of ``log`` (its t, crank angles, optional rates, torques or
    currents: :meth:`~chewbot.identification.log.RobotLog.crank_torques`; a logged bite force is not used).
    ``window_s``: the smoothing window of the rates the log does not give; ``events``: find the force's steps and
    keep the smoothing from reaching across them (module docstring); the other options as
    :func:`chewbot.dynamics.bite_force.estimate`. A log read by its currents has them turned into crank torques
    through the model's drive at the smoothed crank rates first, then is estimated as a log of those torques.
    ``info["rates"]`` says how the rates were obtained, ``info["events"]`` where the force steps."""
    return estimate_log_motion(model, log, side=side, contact=contact, friction=friction, window_s=window_s,
                               sigma=sigma, events=events)[0]


def estimate_log_motion(model: Model, log: RobotLog, *, side: str = "left", contact: str = "bilateral",
                        friction: bool = True, window_s: float = WINDOW_S, sigma: float | None = None,
                        events: bool = True) -> tuple[ForceEstimate, LogMotion]:
    """:func:`estimate_log` and the motion it was estimated along (the poses, the smoothed rates, the held torques'
    average: :class:`~chewbot.identification.motion.LogMotion`), for a caller that needs the mandible's motion too
    (the texture test's gap)."""
    reads = log.reads(model)
    if reads == "currents":
        log = replace(log, tau=log.crank_torques(model, log_motion(model, log, side, window_s).kin.dtheta), current=None)
    smoothed = log.dtheta is None or log.ddtheta is None
    cuts = force_events(model, log, side, contact, window_s, friction) if smoothed and events else ()
    motion = log_motion(model, log, side, window_s, cuts=cuts, held=True)
    result = estimate(model, motion.kin, motion.tau, side=side, contact=contact, friction=friction, sigma=sigma,
                      rate_sd=motion.rate_sd if smoothed else None,
                      acceleration_sd=motion.acceleration_sd if smoothed else None)
    result.info.update({"reads": reads, "rates": motion.rates, "window_samples": motion.window_samples, "window_s": window_s,
                        "angle_residual_rms_rad": float(np.sqrt(np.mean(motion.angle_residual**2))),
                        "torques": "held between samples: averaged with the smoothed accelerations' weights" if smoothed
                        else "as logged", "events": [{"sample": int(k), "t_s": float(log.t[k])} for k in cuts]})
    return result, motion


def force_events(model: Model, log: RobotLog, side: str, contact: str, window_s: float = WINDOW_S,
                 friction: bool = True) -> tuple[int, ...]:
    """The samples where the bite force steps (each the first sample after the step), from the log alone.

    The force is estimated twice with short one-sided fits (:data:`EVENT_WINDOW_S`, degree :data:`EVENT_POLYORDER`;
    with the model's friction where the estimate has it, else its reversals would look like steps), from the
    samples up to k (F_L) and from k on
    (F_R): a step between k and k + 1 shows as D_k = F_R(k + 1) - F_L(k), and nowhere else does F_R(k + 1) differ
    from F_L(k) by more than the fits' errors. An event is a local largest abs(D_k) above :data:`EVENT_FRACTION` of
    the largest force and :data:`EVENT_SCALES` robust spreads of abs(D) (1.4826 median absolute deviations), that
    the force keeps: the medians of F_R from w to 4 w samples after and of F_L as far before differ by at least half
    of it. The first sample after the step is the sample nearest to k + 1 whose pose departs from the motion before
    it (:func:`_first_deviations`), else k + 1: not the first such sample of the w before k, which, where the force
    steps at a turn of the motion (a fracture at the deepest point), can be the turn's own departure, w samples early. Events closer than a smoothing window to each other or to an end of the
    log are left out (no window would fit between them)."""
    from chewbot.dynamics.bite_force import solve_states
    from chewbot.identification.motion import fit_poses
    from chewbot.kinematics.motion import solve_kinematics
    from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task
    from chewbot.task.smoothing import local_fits, uniform_step, window_samples

    q, _ = fit_poses(model, log.theta, lambda i: f"{log.source}: {log.where(i)}")
    dt = uniform_step(log.t)
    w = window_samples(log.n, dt, EVENT_WINDOW_S, EVENT_POLYORDER)
    F = {}
    for anchor in ("left", "right"):
        fits = local_fits(log.t, q, EVENT_WINDOW_S, held=log.tau, polyorder=EVENT_POLYORDER, anchor=anchor)
        task = Task(name=log.source, t=log.t, coords=TARGET_COORDS if model.has_hkp else FULL_COORDS, q=q, dq=fits.rate,
                    ddq=fits.acceleration, force=np.zeros((log.n, 3)), side=side)
        kin = solve_kinematics(model, task, "euler-angles")
        F[anchor] = solve_states(model, kin.theta, q, fits.rate, fits.acceleration, fits.held, side=side, contact=contact,
                                 friction=friction)[0][:, :3]
    D = np.linalg.norm(F["right"][1:] - F["left"][:-1], axis=1)
    if not D.size:
        return ()
    spread = 1.4826 * np.median(np.abs(D - np.median(D)))
    peak = max(np.abs(F["left"]).max(), np.abs(F["right"]).max())
    threshold = max(EVENT_FRACTION * peak, EVENT_SCALES * spread)
    first = _first_deviations(q, w)
    cuts: list[int] = []
    big = np.flatnonzero(D > threshold)
    for k in big[np.argsort(-D[big])]:
        if D[max(k - w, 0):k + w + 1].max() > D[k] or any(abs(k + 1 - c) < 2 * w for c in cuts):
            continue  # not the largest nearby, or the same event
        before = np.median(F["left"][max(k - 4 * w, 0):max(k - w, 1)], axis=0)
        after = np.median(F["right"][k + w:k + 4 * w], axis=0)
        if np.linalg.norm(after - before) < 0.5 * D[k]:
            continue  # the force does not keep the step: a disagreement of the fits (a friction reversal), not an event
        near = [c for c in first if k - w < c <= k + 3]
        cuts.append(min(near, key=lambda c: abs(c - (k + 1))) if near else k + 1)
    full = window_samples(log.n, dt, window_s)
    kept = []
    for c in sorted(cuts):
        if c >= full and c <= log.n - full and all(c - k >= full for k in kept):
            kept.append(c)
    return tuple(kept)


def _first_deviations(q: np.ndarray, w: int) -> np.ndarray:
    """The samples whose poses leave the polynomial of degree :data:`EVENT_POLYORDER` through the w samples before
    them by more than :data:`EVENT_SCALES` times the typical departure of the 2 w samples before those (each
    coordinate against its own): the first sample after a step of the acceleration is the first that departs from
    the motion before it."""
    from numpy.lib.stride_tricks import sliding_window_view

    V = np.vander(np.arange(w, dtype=float), EVENT_POLYORDER + 1)
    extrapolate = (np.vander(np.array([float(w)]), EVENT_POLYORDER + 1) @ np.linalg.pinv(V))[0]
    e = np.abs(q[w:] - np.einsum("nkw,w->nk", sliding_window_view(q[:-1], w, axis=0), extrapolate))  # sample j + w
    typical = np.median(sliding_window_view(e[:-w], 2 * w, axis=0), axis=2)  # departures of samples j - 2w .. j - 1
    z = np.max(e[3 * w - w:][: typical.shape[0]] / np.maximum(typical, 1e-300), axis=1)
    return np.flatnonzero(z > EVENT_SCALES) + 3 * w


def estimate_angles(model: Model, t, theta, tau, *, side: str = "left", contact: str = "bilateral", friction: bool = True,
                    rates: tuple | None = None, window_s: float = WINDOW_S, sigma: float | None = None,
                    source: str = "angles", events: bool = True) -> ForceEstimate:
    """:func:`estimate_log` on arrays: times ``t`` (n,) s, crank angles ``theta`` (n, 6) rad, measured torques ``tau``
    (n, 6) N m, optionally ``rates`` = (theta_dot, theta_ddot) (n, 6) each (else smoothed from the angles)."""
    t = np.asarray(t, float)
    dtheta, ddtheta = (None, None) if rates is None else (np.asarray(rates[0], float), np.asarray(rates[1], float))
    log = RobotLog(source, t, np.asarray(theta, float), dtheta, ddtheta, np.asarray(tau, float), np.zeros((t.size, 3)),
                   np.arange(t.size) + 2)
    return estimate_log(model, log, side=side, contact=contact, friction=friction, window_s=window_s, sigma=sigma,
                        events=events)
