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

from dataclasses import dataclass
from math import comb

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
    fits = local_fits(t, np.asarray(y, dtype=float).reshape(len(t), -1), window_s, polyorder=polyorder, adaptive=False)
    shape = np.shape(y)
    return fits.rate.reshape(shape), fits.acceleration.reshape(shape)


# local_fits takes the half window where its acceleration differs from the full window's by more than this many
# standard deviations of their difference's noise.
ADAPT_SCALES = 3.0
# ... down to windows of this many times the fewest samples a polynomial of the degree needs (7 for degree 5): the
# shortest windows are all but interpolations, and average the held torques' noise over too few samples.
MIN_WINDOW_FACTOR = 1.5
# The differences that estimate a signal's noise (noise_level): of this order, so that a smooth motion sampled at
# 1 kHz contributes far less than any sensor's noise (dt^6 times its sixth derivative).
NOISE_DIFFERENCES = 6


@dataclass(frozen=True, eq=False)
class LocalFits:
    """The local polynomial fits of :func:`local_fits` (arrays samples first): ``value``, ``rate``, ``acceleration``
    (n, k); ``held`` (n, m), the average of a held signal (each sample's value holds until the next: a digital
    controller's torques) that matches the fitted acceleration, or None; ``rate_sd``, ``acceleration_sd`` (n, k), the
    estimates' standard deviations (the signal's noise through the filter, and the smoothing error where the fit
    with half the window differs from it by more than the noise explains); ``noise`` (k,) the signal's noise;
    ``window`` the samples of a full window; ``cuts`` the samples the fits do not reach across; ``shorter`` (n,)
    where the half window was taken (None for :func:`derivatives`' plain fits)."""

    value: np.ndarray
    rate: np.ndarray
    acceleration: np.ndarray
    held: np.ndarray | None
    rate_sd: np.ndarray
    acceleration_sd: np.ndarray
    noise: np.ndarray
    window: int
    cuts: tuple[int, ...]
    shorter: np.ndarray | None = None


def noise_level(y: np.ndarray) -> np.ndarray:
    """(k,): the standard deviation of white noise on the columns of ``y`` (n, k), from the median absolute
    deviation of their :data:`NOISE_DIFFERENCES`-th differences (robust against the few large ones of an event)."""
    d = np.diff(y, n=NOISE_DIFFERENCES, axis=0)
    if not d.shape[0]:
        return np.zeros(y.shape[1])
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    return 1.4826 * mad / np.sqrt(comb(2 * NOISE_DIFFERENCES, NOISE_DIFFERENCES))


def held_weights(acceleration: np.ndarray, dt: float) -> np.ndarray:
    """The weights of a held signal's samples that match a fit's acceleration ``acceleration`` (its coefficients on
    the window's samples): the acceleration estimate is the integral of the true acceleration against the kernel
    K(s) = sum_i c_i (t_i - s)_+, so a signal held on [t_j, t_j+1) enters the same average with weight
    w_j = integral of K over that step = dt^2 sum_(i > j) c_i (i - j - 1/2). The weights sum to 1."""
    c = acceleration
    w = c.size
    i = np.arange(w)
    return dt**2 * np.array([np.sum(c[j + 1:] * (i[j + 1:] - j - 0.5)) for j in range(w)])


ANCHORS = ("centre", "left", "right")


def local_fits(t: np.ndarray, y: np.ndarray, window_s: float = WINDOW_S, cuts: tuple[int, ...] = (),
               held: np.ndarray | None = None, polyorder: int = POLYORDER, anchor: str = "centre",
               adaptive: bool = True) -> LocalFits:
    """Savitzky-Golay fits of uniformly sampled ``y`` (n, k) that do not reach across ``cuts``.

    The samples are split before each index of ``cuts`` (an event: the motion's acceleration jumps there); in each
    piece every sample gets the polynomial of degree ``polyorder`` fitted by least squares to the window of
    ``window_s`` centred on it (``anchor`` "left": the window that ends at it, the past only; "right": the one that
    starts at it), or near the piece's ends the first or last window of the piece (as :func:`derivatives`, which is
    this without cuts and not ``adaptive``). ``adaptive``: a sample takes the half window where its fit differs from
    the full window's by more than :data:`ADAPT_SCALES` times the noise of that difference, and within half a window
    of a cut. A piece shorter than a window gets a window of its length;
    one shorter than ``polyorder`` + 2 samples is an error. ``held`` (n, m): a signal held between samples (the
    torques), averaged with each fit's :func:`held_weights`. The standard deviations: the noise
    (:func:`noise_level`) through the fit's coefficients, and the smoothing error, estimated where the fit on half
    the window (a less smoothed, noisier estimate) differs from the fit by more than their noise
    (Var(half - full) = Var(half) - Var(full) for nested least squares)."""
    from numpy.lib.stride_tricks import sliding_window_view
    from scipy.signal import savgol_coeffs

    y = np.asarray(y, dtype=float)
    n = y.shape[0]
    dt = uniform_step(t)
    w = window_samples(n, dt, window_s, polyorder)
    bounds = [0, *sorted(c for c in set(cuts) if 0 < c < n), n]
    noise = noise_level(y)

    def fits(width: int):
        """value, rate, acceleration (n, k), held (n, m) and the coefficients' norms (n, 3) with windows of
        ``width`` samples (shorter in a shorter piece)."""
        out = [np.empty_like(y) for _ in range(3)]
        avg = None if held is None else np.empty((n, held.shape[1]))
        norms = np.empty((n, 3))
        for a, b in zip(bounds[:-1], bounds[1:]):
            size = b - a
            wp = min(width, size if size % 2 else size - 1)
            if wp <= polyorder:
                raise TaskError(f"samples {a} to {b - 1}: {size} samples between events are too few for a polynomial of "
                                f"degree {polyorder}")
            k = np.arange(a, b)
            offset = {"centre": wp // 2, "left": wp - 1, "right": 0}[anchor]
            start = np.clip(k - offset, a, b - wp)  # the window of each sample: as anchored, or the piece's first or last
            pos = k - start
            coeffs = np.stack([np.stack([savgol_coeffs(wp, polyorder, deriv=d, delta=dt, pos=p, use="dot")
                                         for d in range(3)]) for p in range(wp)])  # (pos, deriv, wp)
            windows = sliding_window_view(y, wp, axis=0)[start]  # (size, k, wp)
            for d in range(3):
                out[d][a:b] = np.einsum("skw,sw->sk", windows, coeffs[pos, d])
            norms[a:b] = np.linalg.norm(coeffs[pos], axis=2)
            if held is not None:
                weights = np.stack([held_weights(coeffs[p, 2], dt) for p in range(wp)])
                avg[a:b] = np.einsum("smw,sw->sm", sliding_window_view(held, wp, axis=0)[start], weights[pos])
        return out, avg, norms

    full, avg, norms = fits(w)
    if not adaptive:
        return LocalFits(*full, avg, noise * norms[:, 1:2], noise * norms[:, 2:3], noise, w, tuple(bounds[1:-1]))
    # The scales: the window, then halved down to the shortest a polynomial of the degree allows. A sample keeps the
    # longest window whose acceleration the next shorter one confirms (they differ by less than ADAPT_SCALES times
    # the noise of their difference, Var(short - long) = Var(short) - Var(long) for nested least squares): where the
    # long window smooths over something (a friction reversal, an event), a shorter one takes over, for all of the
    # sample's coordinates so that the held average matches every acceleration. Within half a window of a cut the
    # half window is taken: the samples next to an event are fitted from one side, where a shorter window is
    # nearly an interpolation of the motion's transient.
    widths = [w]
    while widths[-1] // 2 | 1 >= MIN_WINDOW_FACTOR * (polyorder + 2 | 1) and widths[-1] // 2 | 1 < widths[-1]:
        widths.append(widths[-1] // 2 | 1)
    scales = [(full, avg, norms)] + [fits(width) for width in widths[1:]]
    if len(scales) == 1:
        return LocalFits(*full, avg, noise * norms[:, 1:2], noise * norms[:, 2:3], noise, w, tuple(bounds[1:-1]))
    chosen = np.full(n, len(scales) - 1)
    undecided = np.ones(n, dtype=bool)
    near = np.zeros(n, dtype=bool)
    for c in bounds[1:-1]:
        near[max(c - w // 2, 0):c + w // 2] = True
    for i in range(len(scales) - 1):
        (long, _, n_long), (short, _, n_short) = scales[i], scales[i + 1]
        spread = noise * np.sqrt(np.maximum(n_short[:, 2:3] ** 2 - n_long[:, 2:3] ** 2, 0.0))
        agree = np.all(np.abs(long[2] - short[2]) <= ADAPT_SCALES * spread, axis=1)
        take = undecided & agree & ~(near & (i == 0))
        chosen[take], undecided[take] = i, False
    chosen[near] = np.maximum(chosen[near], 1)
    rows = np.arange(n)

    def pick(values):
        return np.stack(values)[chosen, rows]

    value, rate, acc = (pick([sc[0][d] for sc in scales]) for d in range(3))
    if held is not None:
        avg = pick([sc[1] for sc in scales])
    sd = []
    for d in (1, 2):
        # a window the next shorter one confirms: its noise and the smoothing error their difference shows beyond
        # the noise; the shortest: its noise and its whole difference from the next longer as its smoothing error
        parts = []
        for i, (est, _, nrm) in enumerate(scales):
            j = i + 1 if i + 1 < len(scales) else i - 1
            other, n_other = scales[j][0][d], scales[j][2]
            diff2 = (est[d] - other) ** 2
            own = (noise * nrm[:, d:d + 1]) ** 2
            if j > i:
                parts.append(np.sqrt(own + np.maximum(diff2 - noise**2 * np.maximum(n_other[:, d:d + 1] ** 2 - nrm[:, d:d + 1] ** 2, 0.0), 0.0)))
            else:
                parts.append(np.sqrt(own + diff2))
        sd.append(pick(parts))
    shorter = chosen > 0
    return LocalFits(value, rate, acc, avg, sd[0], sd[1], noise, w, tuple(bounds[1:-1]), shorter)


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
