"""Velocities and accelerations of sampled signals, for task files that give positions only.

Method: a Savitzky-Golay filter (:func:`scipy.signal.savgol_filter`): at every sample a polynomial of degree
``polyorder`` is fitted by least squares to the samples in a window centred on it, and its derivatives at the
centre are the estimates; near the ends the polynomial fitted to the first (last) window is used
(``mode="interp"``), so no boundary condition is imposed on the motion.
Why this filter: it is exact for polynomials up to its degree, its error on smooth signals is controlled by one
window length that has a physical meaning (a low-pass cut-off), it treats the ends without assuming rest, and
all columns are filtered at once. It needs uniform sampling: a file with irregular time steps must give its
derivative columns or be resampled (:class:`IrregularSampling` says where the steps differ).
A cubic smoothing spline with generalised cross-validation was rejected: on noise-free samples its criterion
degenerates (it chooses a near-straight line) and its natural end conditions force the acceleration to zero at
both ends.

The measured error on an analytic signal, with and without noise, is printed by
``python -m chewbot.task.smoothing`` (see docs/tasks.md).
"""

from __future__ import annotations

import numpy as np

from chewbot.errors import TaskError
from chewbot.task import WINDOW_S

# Degree of the local polynomial: exact for quintics, so the acceleration keeps a cubic's worth of detail.
POLYORDER = 5
# Time steps may differ from their median by this fraction (rounding of the printed times), no more.
UNIFORM_RTOL = 1e-3


class IrregularSampling(TaskError):
    """The time steps are not uniform; ``sample`` is the 0-based index where the step first changes."""

    def __init__(self, message: str, sample: int):
        super().__init__(message)
        self.sample = sample


def uniform_step(t: np.ndarray) -> float:
    """The time step of uniformly sampled times ``t`` (s); raises :class:`IrregularSampling` otherwise."""
    steps = np.diff(np.asarray(t, dtype=float))
    dt = float(np.median(steps))
    bad = np.flatnonzero(np.abs(steps - dt) > UNIFORM_RTOL * dt)
    if bad.size:
        i = int(bad[0])
        raise IrregularSampling(
            f"time step {steps[i]:.6g} s after sample {i} differs from the median step {dt:.6g} s: the derivatives "
            f"are estimated only for uniform sampling; give the derivative columns or resample the file", sample=i + 1)
    return dt


def window_samples(n: int, dt: float, window_s: float = WINDOW_S, polyorder: int = POLYORDER) -> int:
    """The odd number of samples in the filter window: ``window_s`` long, at least ``polyorder + 2``, at most ``n``."""
    w = max(int(round(window_s / dt)) | 1, polyorder + 2 | 1)
    if w > n:
        w = n if n % 2 else n - 1
    if w <= polyorder:
        raise TaskError(f"{n} samples are too few to estimate derivatives with a polynomial of degree {polyorder}: "
                        f"give at least {polyorder + 2} samples or the derivative columns")
    return w


def derivatives(t: np.ndarray, y: np.ndarray, window_s: float = WINDOW_S, polyorder: int = POLYORDER) -> tuple[np.ndarray, np.ndarray]:
    """First and second time derivatives of uniformly sampled ``y`` ((N,) or (N, k), samples first) at times ``t``."""
    from scipy.signal import savgol_filter  # scipy.signal takes 0.7 s to import: only where derivatives are estimated

    y = np.asarray(y, dtype=float)
    dt = uniform_step(t)
    w = window_samples(y.shape[0], dt, window_s, polyorder)
    d1, d2 = (savgol_filter(y, w, polyorder, deriv=k, delta=dt, axis=0, mode="interp") for k in (1, 2))
    return d1, d2


def _measure() -> None:
    """Print the error of :func:`derivatives` on y = A sin^2(2 pi f t) (docs/tasks.md quotes this table)."""
    rate, A, f = 1000.0, np.radians(10.0), 1.25  # 10 deg, a 0.8 s cycle: the default task's beta
    t = np.arange(0, 2 * rate + 1) / rate
    w = 2 * np.pi * f
    exact = (A * np.sin(w * t) ** 2, A * w * np.sin(2 * w * t), 2 * A * w**2 * np.cos(2 * w * t))
    rng = np.random.default_rng(0)
    print(f"y = A sin^2(2 pi f t), A = 10 deg, f = {f} Hz, {t.size} samples at {rate:g} Hz, window {WINDOW_S} s, degree {POLYORDER}")
    print("noise std (rad) | max error velocity / peak | max error acceleration / peak | same, 50 samples from the ends")
    for noise in (0.0, 1e-5, 1e-4):
        d1, d2 = derivatives(t, exact[0] + noise * rng.standard_normal(t.size))
        e1, e2 = np.abs(d1 - exact[1]) / A / w, np.abs(d2 - exact[2]) / (2 * A * w**2)
        print(f"{noise:g} | {e1.max():.2e} | {e2.max():.2e} | {e1[50:-50].max():.2e}, {e2[50:-50].max():.2e}")


if __name__ == "__main__":
    _measure()
