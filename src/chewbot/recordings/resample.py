"""From fitted frames to a task: the coordinates resampled by a spline whose derivatives give the rates, and the
bite force interpolated to the task's times.

The spline is cubic and interpolating (``scipy.interpolate.CubicSpline``, not-a-knot ends) through the fitted
frames, with or without the low-pass filter: the noise is removed before the fit, on the marker paths, so the
task passes through exactly the poses whose errors the verdict reports. Its first and second derivatives are
the rates; the accelerations are continuous (piecewise linear between frames).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from chewbot.errors import RecordingError
from chewbot.recordings.formats import FORCES, read_table, require_complete


def output_times(t: np.ndarray, rate_hz: float | None) -> np.ndarray:
    """The task's times: the frames' own (``rate_hz`` None) or a uniform grid from the first frame to the last."""
    if rate_hz is None:
        return t.copy()
    count = int(np.floor((t[-1] - t[0]) * rate_hz * (1 + 1e-12))) + 1
    return t[0] + np.arange(count) / rate_hz


def spline_motion(t: np.ndarray, q: np.ndarray, t_out: np.ndarray, at_rest: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, dq, ddq (M, n) at ``t_out`` from the interpolating cubic spline through (t, q); at the frames
    themselves q is returned as given (no rounding by the spline). ``at_rest``: zero rates at both ends (clamped
    ends) instead of not-a-knot."""
    spline = CubicSpline(t, q, axis=0, bc_type="clamped" if at_rest else "not-a-knot")
    values = spline(t_out)
    same = np.searchsorted(t, t_out).clip(0, len(t) - 1)
    at_frame = t[same] == t_out
    values[at_frame] = q[same[at_frame]]
    return values, spline(t_out, 1), spline(t_out, 2)


def read_force_file(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """A bite force file: CSV ``t, Fx, Fy, Fz`` (force on the mandible in {S}), units in brackets (``t[ms]``,
    ``Fz[kN]``; seconds and newtons without). Returns t (N,) s and F (N, 3) N."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"{path}: no such force file")

    def kind_of(name: str):
        return ("time", 1.0) if name == "t" else ("force", 1.0) if name in FORCES else None

    names, data, lines = read_table(path, kind_of, "force file (t, Fx, Fy, Fz)")
    missing = [c for c in ("t",) + FORCES if c not in names]
    if missing:
        raise RecordingError(f"{path}: missing column(s) {', '.join(missing)} (a force file has t, Fx, Fy, Fz)")
    require_complete(path, names, data, lines, names)
    if len(lines) < 2:
        raise RecordingError(f"{path}: {len(lines)} data row(s); a force file needs at least 2")
    t = data[:, names.index("t")]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise RecordingError(f"{path}: line {lines[bad[0] + 1]}, column 't': time does not increase")
    return t, np.column_stack([data[:, names.index(f)] for f in FORCES])


def force_at(t_force: np.ndarray, force: np.ndarray, t_out: np.ndarray, source: str) -> np.ndarray:
    """The force (N, 3) linearly interpolated to ``t_out`` (shape-preserving: no overshoot of a burst's peak).
    The force's times must cover the task's."""
    slack = 1e-9 * max(1.0, abs(t_out[-1]))
    if t_force[0] > t_out[0] + slack or t_force[-1] < t_out[-1] - slack:
        raise RecordingError(f"{source}: the force covers t = {t_force[0]:.6g} to {t_force[-1]:.6g} s; the task runs from "
                             f"{t_out[0]:.6g} to {t_out[-1]:.6g} s")
    return np.column_stack([np.interp(t_out, t_force, force[:, j]) for j in range(3)])
