"""Texture profile analysis: the two-bite compression and Bourne's measures of its force curve.

The protocol (Friedman, Whitney and Szczesniak 1963; Bourne 1978, "Texture profile analysis", Food Technology 32(7)
62-66, 72): the probe, here the bite point of the molar, starts at a gap of h0 + 1 mm, moves along z at a constant
speed to a compression of c % of h0, back to the start, pauses, and does it again. The speed's changes are smoothed
over :data:`BLEND` seconds (quintic smoothstep in the speed: the task is C^2, as the controllers need), placed so that
the deepest gap is exactly h0 (1 - c / 100) and the strokes are at the given speed everywhere else.

The measures (:func:`tpa_measures`), from the force the sample exerts (N, positive pushing the teeth apart) and the
gap g along the test. An "area" is the work of the force over the probe's travel, sum of F |dg| (mJ when reported):
at a texture analyser's constant crosshead speed it is Bourne's area under the force-time chart times the speed, and
it does not depend on how the speed is blended at the turns.

* bites: the two deepest points of g (the turns); the first bite ends, and the second begins, in the middle of the
  pause between them;
* hardness_N: the largest force of the first bite;
* fracturability_N: the force at the first significant break of the first compression stroke: the running maximum of
  the force where the force first falls :data:`BREAK_DROP` below it (null if it never does);
* cohesiveness: A2 / A1, the positive areas of the second and of the first bite (compression and withdrawal);
* springiness: D2 / D1, D_i the travel from the i-th bite's contact (the force first above :data:`CONTACT_FRACTION` of
  the hardness) to its deepest point: how much of its height the sample recovered in the pause (Bourne's distance,
  as a ratio of the first bite's);
* resilience: the positive area of the first bite's withdrawal over that of its compression, split at its deepest
  point (a later measure of the texture analysers, not Bourne's; with an instantaneous turn the peak force is there,
  with a blended turn the damping's share of the force fades before it, and a split at the peak force would move that
  part of the compression's area to the withdrawal);
* adhesiveness_mJ: the negative area of the first bite, the work of pulling the teeth off the sample;
* gumminess_N = hardness x cohesiveness; chewiness_N = gumminess x springiness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chewbot.errors import ChewbotError
from chewbot.units import factor

BLEND = 0.05  # s: each change of speed is spread over this
HOLD = 0.2  # s at rest before the first and after the second bite
BREAK_DROP = 0.05  # a break: the force falls 5 % below its running maximum while compressing
CONTACT_FRACTION = 0.01  # contact: the force above 1 % of the hardness
MEASURES = ("hardness_N", "fracturability_N", "cohesiveness", "springiness", "resilience", "adhesiveness_mJ", "gumminess_N",
            "chewiness_N")

# P(x) = int_0^x S, S(u) = 6u^5 - 15u^4 + 10u^3 the quintic smoothstep; P(1) = 1/2, P(1/2) = 5/64
_P_HALF = 5 / 64


class TpaError(ChewbotError):
    """A texture test that cannot be built or analysed (names the option or the log and why)."""


@dataclass(frozen=True)
class Protocol:
    """The two-bite test: ``height`` h0 (m), ``compression`` (fraction of h0), ``speed`` (m/s), ``pause`` (s).
    ``switches`` the times (s) the speed changes at (the middle of each blend) and ``changes`` by how much (m/s)."""

    height: float
    compression: float
    speed: float
    pause: float
    rate: float = 1000.0

    @property
    def start_gap(self) -> float:
        return self.height + 1e-3

    @property
    def deepest_gap(self) -> float:
        return self.height * (1 - self.compression)

    @property
    def stroke_time(self) -> float:
        """Time of one stroke at speed between the middles of its blends (s): the corner of the ideal path lowered by
        what the reversal's blend leaves above it, so that the smooth path turns exactly at the deepest gap."""
        ideal = self.deepest_gap - 2 * self.speed * BLEND * _P_HALF
        return (self.start_gap - ideal) / self.speed

    def schedule(self) -> tuple[np.ndarray, np.ndarray]:
        """(switch times, speed changes): down, reverse, stop; pause; down, reverse, stop."""
        T, v, t0 = self.stroke_time, self.speed, HOLD + BLEND / 2
        t = [t0, t0 + T, t0 + 2 * T]
        t2 = t[2] + BLEND + self.pause
        t += [t2, t2 + T, t2 + 2 * T]
        return np.array(t), np.array([-v, 2 * v, -v, -v, 2 * v, -v])

    @property
    def duration(self) -> float:
        return float(self.schedule()[0][-1] + BLEND / 2 + HOLD)

    def path(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The gap g (m), dg/dt, d2g/dt2 at times ``t``."""
        t = np.asarray(t, float)
        switches, changes = self.schedule()
        x = (t[:, None] - (switches[None, :] - BLEND / 2)) / BLEND
        xc = np.clip(x, 0.0, 1.0)
        P = np.where(x > 1, x - 0.5, xc**6 - 3 * xc**5 + 2.5 * xc**4)
        S = 6 * xc**5 - 15 * xc**4 + 10 * xc**3
        dS = np.where((x > 0) & (x < 1), 30 * xc**4 - 60 * xc**3 + 30 * xc**2, 0.0) / BLEND
        return (self.start_gap + BLEND * P @ changes, S @ changes, dS @ changes)

    def times(self) -> np.ndarray:
        count = int(np.floor(self.duration * self.rate + 1e-9)) + 1
        return np.arange(count) / self.rate


def protocol(height: float, compression_percent: float = 50.0, speed_mm_s: float = 2.0, pause_s: float = 2.0) -> Protocol:
    """The protocol from the command line's units, checked."""
    if not 0 < compression_percent < 100:
        raise TpaError(f"--compression {compression_percent:g}: a percentage of h0 between 0 and 100 (exclusive)")
    if not speed_mm_s > 0 or not np.isfinite(speed_mm_s):
        raise TpaError(f"--speed {speed_mm_s:g}: the probe's speed must be a positive number of mm/s")
    if not pause_s >= 0 or not np.isfinite(pause_s):
        raise TpaError(f"--pause {pause_s:g}: the pause must be a non-negative number of seconds")
    p = Protocol(height, compression_percent / 100, speed_mm_s * factor("mm/s"), pause_s)
    if p.stroke_time <= BLEND:
        raise TpaError(f"--speed {speed_mm_s:g}: a stroke of {(p.start_gap - p.deepest_gap) / factor('mm'):.3g} mm takes less than "
                       f"the {BLEND:g} s over which the speed is blended; lower the speed")
    return p


def _work(F, g, mask) -> float:
    """sum of F |dg| over the intervals whose both ends are in ``mask`` (trapezoids)."""
    seg = mask[:-1] & mask[1:]
    return float(np.sum(0.5 * (F[:-1] + F[1:])[seg] * np.abs(np.diff(g))[seg]))


def bites(t, g) -> tuple[slice, slice, int, int]:
    """The two bites of a test from its gap: their samples and the indices of their deepest points."""
    from scipy.signal import find_peaks

    g = np.asarray(g, float)
    span = float(np.ptp(g)) if g.size else 0.0
    if not span > 0:
        raise TpaError("the gap does not change: this is not a compression test")
    troughs, _ = find_peaks(-g, prominence=0.5 * span)
    if troughs.size != 2:
        raise TpaError(f"a two-bite test has two deepest points of the gap; this one has {troughs.size}")
    m1, m2 = int(troughs[0]), int(troughs[1])
    between = g[m1:m2 + 1]
    top = np.flatnonzero(between >= between.max() - 1e-3 * span) + m1
    split = int((top[0] + top[-1]) // 2)
    return slice(0, split + 1), slice(split, g.size), m1, m2


def tpa_measures(t, g, F) -> dict:
    """Bourne's measures (module docstring) of a two-bite test: times ``t`` (s), the gap ``g`` (m) and the sample's
    force ``F`` (N, positive pushing the teeth apart)."""
    t, g, F = (np.asarray(x, float) for x in (t, g, F))
    one, two, m1, m2 = bites(t, g)
    first = np.zeros(t.size, bool)
    first[one] = True
    second = np.zeros(t.size, bool)
    second[two] = True
    pos, neg = np.maximum(F, 0.0), np.maximum(-F, 0.0)
    idx1 = np.arange(t.size)[one]
    peak = int(idx1[np.argmax(F[one])])
    hardness = float(F[peak])
    if not hardness > 0:
        raise TpaError("the sample was never compressed: no positive force in the first bite")
    A1, A2 = _work(pos, g, first), _work(pos, g, second)
    before = first & (np.arange(t.size) <= m1)
    after = first & (np.arange(t.size) >= m1)
    compressing = F[:m1 + 1]
    running = np.maximum.accumulate(compressing)
    threshold = CONTACT_FRACTION * hardness
    breaks = np.flatnonzero((compressing < (1 - BREAK_DROP) * running) & (running > threshold))
    fracturability = float(running[breaks[0]]) if breaks.size else None

    def travel(lo: int, m: int) -> float:
        above = np.flatnonzero(F[lo:m + 1] > threshold)
        return float(g[lo + above[0]] - g[m]) if above.size else 0.0

    D1, D2 = travel(0, m1), travel(two.start, m2)
    cohesiveness = A2 / A1
    springiness = D2 / D1 if D1 > 0 else float("nan")
    gumminess = hardness * cohesiveness
    return {"hardness_N": hardness, "fracturability_N": fracturability, "cohesiveness": cohesiveness,
            "springiness": springiness, "resilience": _work(pos, g, after) / _work(pos, g, before),
            "adhesiveness_mJ": _work(neg, g, first) / factor("mJ"), "gumminess_N": gumminess, "chewiness_N": gumminess * springiness,
            "areas_mJ": {"first_bite": A1 / factor("mJ"), "second_bite": A2 / factor("mJ")},
            "deepest_gap_m": [float(g[m1]), float(g[m2])], "peak_time_s": float(t[peak]),
            "fracture_time_s": None if not breaks.size else float(t[int(np.argmax(compressing[:breaks[0] + 1]))])}


__all__ = ["BLEND", "BREAK_DROP", "CONTACT_FRACTION", "HOLD", "MEASURES", "Protocol", "TpaError", "bites", "protocol",
           "tpa_measures"]
