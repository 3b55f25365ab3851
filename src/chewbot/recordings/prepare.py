"""Preparing marker paths for the fit: dropped frames at the ends, gaps, and a zero-phase low-pass filter.

In this order (:func:`chewbot.recordings.importer.import_motion`):

1. :func:`trim` drops the frames at the start and the end where a marker is missing: there is nothing on one
   side to interpolate from.
2. :func:`spikes` finds tracker artefacts (unless ``--keep-spikes``): frames where the markers stop being one
   rigid body (the largest distance of a marker from the rigid body fitted to all, an outlier: above
   :data:`SPIKE_MIN_MM` and the median plus :data:`SPIKE_MADS` robust standard deviations, 1.4826 x the median
   absolute deviation), and stretches of at most ``max_gap`` between two jumps of the markers' speed that are
   outliers the same way (above :data:`SPIKE_MIN_SPEED_MM_S` and the median plus :data:`SPEED_MADS` robust
   standard deviations), or of the rigid body's angular speed (above :data:`SPIKE_MIN_TURN_DEG_S`: a marker that
   jumps off the plane of three keeps their distances but turns their body), and cancel (a jump out and back: their sum below :data:`CANCEL` of the smaller; the steps
   of a fast stroke add up instead). Their frames are dropped and filled like gaps.
3. :func:`fill_gaps` fills each gap of each marker (frames where it was not seen) by a cubic spline through all
   the frames where that marker was seen (``scipy.interpolate.CubicSpline``, not-a-knot ends), if the gap lasts
   at most ``max_gap``; a longer gap is an error naming the marker and the times.
4. :func:`low_pass` filters every marker coordinate with a Butterworth low-pass of order 2 run forward and
   backward (``scipy.signal.sosfiltfilt``): zero phase, so the filtered path is not delayed against the bite
   force or the other markers, and an overall response of order 4. Order 2 twice is the usual choice for jaw
   and limb motion (Winter, Biomechanics and Motor Control of Human Movement): steep enough to remove tracker
   noise a few times above the chewing band, with little overshoot on fast closing strokes, which higher
   orders ring on. The design frequency is the cutoff divided by 0.802, so that the two passes together
   attenuate to 1/sqrt(2) (-3 dB) at the cutoff itself. Uniform sampling is required.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt

from chewbot.errors import RecordingError
from chewbot.recordings.formats import Recording
from chewbot.units import factor

FILTER_ORDER = 2
# (sqrt(2) - 1)^(1 / (2 n)) for n = FILTER_ORDER: the forward-backward response 1 / (1 + (f / f0)^(2n)) is
# 1/sqrt(2) at f = f0 times this.
TWO_PASS_CORRECTION = (np.sqrt(2) - 1) ** (1 / (2 * FILTER_ORDER))
# Time steps may differ from their median by this fraction and still count as uniform (files print times rounded).
UNIFORM_TOLERANCE = 1e-3
# Spikes: a frame breaks the rigid body by at least this (mm) and by this many robust standard deviations above
# the median; a jump of the speed is at least this (mm/s) and that many robust standard deviations above the
# median. The rigid-body error of a sound recording is the tracker's noise (0.05-0.2 mm); chewing moves markers
# at up to about 150 mm/s, a spike of a few millimetres in one frame at 50-100 Hz at hundreds of mm/s.
SPIKE_MIN_MM = 0.5
SPIKE_MADS = 10.0
SPIKE_MIN_SPEED_MM_S = 200.0
# The markers' rigid body turns in chewing at up to about 120 deg/s; a marker of a cluster 40 mm wide jumping 3 mm
# off its plane turns it by 4 deg within a frame, 200 deg/s at 50 Hz.
SPIKE_MIN_TURN_DEG_S = 150.0
SPEED_MADS = 5.0
# A jump out and a jump back: their sum is less than this share of the smaller (a fast stroke's steps add up).
CANCEL = 0.5


def missing(positions: np.ndarray) -> np.ndarray:
    """(N, K) True where a marker was not seen (any of its coordinates is NaN)."""
    return np.isnan(positions).any(axis=2)


def trim(rec: Recording) -> tuple[Recording, int, int]:
    """The recording without the frames at its start and end where a marker is missing, and how many went from
    each end. A marker never seen is an error."""
    gone = missing(rec.positions)
    never = [rec.markers[k] for k in np.flatnonzero(gone.all(axis=0))]
    if never:
        raise RecordingError(f"{rec.source}: marker(s) {', '.join(never)} never seen")
    complete = np.flatnonzero(~gone.any(axis=1))
    if complete.size == 0:
        raise RecordingError(f"{rec.source}: no frame sees every marker")
    first, last = int(complete[0]), int(complete[-1])
    return rec.frames(first, last + 1), first, rec.n - 1 - last


def _outliers(x: np.ndarray, floor: float, mads: float) -> np.ndarray:
    """x above ``floor`` and the median plus ``mads`` robust standard deviations (1.4826 MAD)."""
    med = np.nanmedian(x)
    sigma = 1.4826 * np.nanmedian(np.abs(x - med))
    return x > max(floor, med + mads * sigma)


def _jumps(step: np.ndarray, rate: np.ndarray, floor: float, t: np.ndarray, max_gap: float) -> np.ndarray:
    """(N,) the frames between two jumps of ``rate`` (N-1,), outliers above ``floor`` (:data:`SPEED_MADS`), that
    cancel (the sum of their ``step`` (N-1, 3) below :data:`CANCEL` of the smaller: a jump out and back; the steps
    of a fast stroke add up instead) within ``max_gap`` seconds."""
    bad = np.zeros(len(t), dtype=bool)
    with np.errstate(invalid="ignore"):
        jumps = np.flatnonzero(_outliers(rate, floor, SPEED_MADS))  # a jump between frame j and j + 1
    for a, b in zip(jumps[:-1], jumps[1:]):
        out, back = step[a], step[b]
        cancels = np.linalg.norm(out + back) < CANCEL * min(np.linalg.norm(out), np.linalg.norm(back))
        if cancels and t[b + 1] - t[a + 1] <= max_gap * (1 + 1e-9):
            bad[a + 1 : b + 1] = True
    return bad


def spikes(rec: Recording, body: np.ndarray | None, max_gap: float) -> tuple[Recording, list[tuple[int, int, str]]]:
    """The recording with the frames of tracker spikes dropped (NaN, to be filled like gaps) and the spikes:
    (first frame, last frame, why) each. ``body`` (K, 3) m: the markers in {M} (None: their first frame)."""
    from chewbot.recordings.rigid import rigid_fit

    from scipy.spatial.transform import Rotation

    P = rec.positions
    found: list[tuple[int, int, str]] = []
    bad = np.zeros(rec.n, dtype=bool)
    dt = np.diff(rec.t)
    turn = np.full(rec.n - 1, np.nan)
    if P.shape[1] >= 3:
        seen = ~missing(P).any(axis=1)  # gaps are not spikes: they are filled next
        d = np.full(rec.n, np.nan)
        fitted = rigid_fit(P[0] if body is None else body, P[seen], rec.markers)
        d[seen] = fitted.max_mm
        with np.errstate(invalid="ignore"):
            rigid = _outliers(d, SPIKE_MIN_MM, SPIKE_MADS)
        bad |= rigid
        # a marker that jumps off the plane of three barely breaks their rigid body: their fitted rotation jumps
        R = np.full((rec.n, 3, 3), np.nan)
        R[seen] = fitted.R
        both = seen[:-1] & seen[1:]
        steps = np.full((rec.n - 1, 3), np.nan)
        steps[both] = Rotation.from_matrix(np.einsum("nij,nkj->nik", R[1:][both], R[:-1][both])).as_rotvec()
        turn = np.degrees(np.linalg.norm(steps, axis=1)) / dt
        bad |= _jumps(steps, turn, SPIKE_MIN_TURN_DEG_S, rec.t, max_gap)
    step = np.diff(P, axis=0)
    speed = np.linalg.norm(step, axis=2).max(axis=1) / dt / factor("mm")  # mm/s, (n-1,)
    bad |= _jumps(step.sum(axis=1), speed, SPIKE_MIN_SPEED_MM_S, rec.t, max_gap)
    edges = np.diff(np.r_[0, bad.astype(int), 0])
    for i0, i1 in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1):
        if i0 == 0 or i1 == rec.n - 1:
            continue  # nothing to interpolate from on one side: left as it is
        why = []
        if P.shape[1] >= 3 and rigid[i0 : i1 + 1].any():
            why.append(f"the markers break the rigid body by up to {d[i0:i1 + 1].max():.3g} mm")
        if not why:
            around = slice(max(i0 - 1, 0), i1 + 1)
            why.append(f"the markers jump at up to {np.nanmax(speed[around]):.4g} mm/s and turn at up to "
                       f"{np.nanmax(np.r_[turn[around], 0.0]):.4g} deg/s")
        found.append((int(i0), int(i1), "; ".join(why)))
    if not found:
        return rec, found
    positions = P.copy()
    for i0, i1, _ in found:
        positions[i0 : i1 + 1] = np.nan
    return replace(rec, positions=positions), found


def gaps(rec: Recording) -> list[tuple[str, int, int, float]]:
    """Every gap inside the recording: (marker, first missing frame, last missing frame, duration in s). The
    duration runs from the first missing frame to the frame that sees the marker again (k missing frames at a
    rate f last k / f)."""
    out = []
    gone = missing(rec.positions)
    for k, name in enumerate(rec.markers):
        edges = np.diff(np.r_[0, gone[:, k].astype(int), 0])
        for i0, i1 in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1):
            out.append((name, int(i0), int(i1), float(rec.t[i1 + 1] - rec.t[i0])))
    return out


def fill_gaps(rec: Recording, max_gap: float) -> tuple[Recording, list[tuple[str, int, int, float]]]:
    """Fill every gap of at most ``max_gap`` seconds by a spline per marker (the recording must start and end
    with every marker seen: :func:`trim`). Returns the filled recording and the gaps; a longer gap raises
    :class:`RecordingError` naming the marker and its frames and times."""
    found = gaps(rec)
    long = [g for g in found if g[3] > max_gap * (1 + 1e-9)]
    if long:
        text = "; ".join(f"marker {name} missing from {rec.where(i0)} to {rec.where(i1)} ({d:.4g} s)" for name, i0, i1, d in long[:5])
        more = f"; and {len(long) - 5} more" if len(long) > 5 else ""
        raise RecordingError(f"{rec.source}: gap(s) longer than --max-gap {max_gap:g} s: {text}{more}")
    if not found:
        return rec, found
    positions = rec.positions.copy()
    gone = missing(positions)
    for k in sorted({rec.markers.index(g[0]) for g in found}):  # a loop over markers, each filled at once
        seen = ~gone[:, k]
        spline = CubicSpline(rec.t[seen], positions[seen, k, :], axis=0)
        positions[~seen, k, :] = spline(rec.t[~seen])
    return replace(rec, positions=positions), found


def check_uniform(rec: Recording, why: str) -> float:
    """The frame period (median time step), after checking that the times are uniform; RecordingError naming the
    first irregular frame otherwise (``why`` says what needs uniform times)."""
    dt = np.diff(rec.t)
    period = float(np.median(dt))
    bad = np.flatnonzero(np.abs(dt - period) > UNIFORM_TOLERANCE * period)
    if bad.size:
        i = int(bad[0]) + 1
        raise RecordingError(f"{rec.source}: {rec.where(i)}: time step {dt[i - 1]:.6g} s differs from the median "
                             f"{period:.6g} s; {why} needs uniform sampling")
    return period


def low_pass(rec: Recording, cutoff_hz: float) -> Recording:
    """Zero-phase Butterworth low-pass of every marker coordinate at ``cutoff_hz`` (-3 dB; see the module)."""
    period = check_uniform(rec, f"the low-pass filter (--cutoff {cutoff_hz:g}; or --cutoff none)")
    nyquist = 0.5 / period
    design = cutoff_hz / TWO_PASS_CORRECTION
    if not 0 < design < nyquist:
        raise RecordingError(f"{rec.source}: --cutoff {cutoff_hz:g} Hz is too high for a recording at {1 / period:.6g} Hz "
                             f"(it must stay below {nyquist * TWO_PASS_CORRECTION:.6g} Hz); lower it or use --cutoff none")
    sos = butter(FILTER_ORDER, design / nyquist, output="sos")
    return replace(rec, positions=sosfiltfilt(sos, rec.positions, axis=0))
