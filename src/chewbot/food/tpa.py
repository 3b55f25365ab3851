"""Texture profile analysis: a texture analyser's two-bite protocol, the displacement profile it implies, an ideal
texture analyser that drives a food's law through it, and Bourne's measures of a force curve in both readings.

**The protocol** (:class:`Protocol`, Friedman, Whitney and Szczesniak 1963; Bourne 1978, "Texture profile
analysis", Food Technology 32(7) 62-66, 72; the settings of a texture analyser's TPA mode): the probe (here the bite
point of the molar) starts at rest a gap ``approach`` above the sample and moves at the pre-test speed until the force
reaches the trigger force; the gap there is the sample's height h_t. From the trigger it compresses at the test speed
by ``compression`` of h_t (or by ``distance``), withdraws at the post-test speed to h_t, pauses, compresses again to
the same deepest gap at the test speed and withdraws at the post-test speed to where it started. Every change of
speed is a quintic smoothstep over ``blend`` seconds (the path is C^2, as a robot's controller needs): the first
starts at the trigger, which cannot be anticipated; the others end exactly where the probe stops. :class:`Profile` is
this path once the trigger's time is known.

**The ideal texture analyser** (:func:`ideal_test`): a food's law (:mod:`chewbot.food.law`) driven through the
profile exactly: the crosshead's motion imposed, the trigger found on the law's force, the food's state (broken, the
Maxwell branch's force, the deepest compression so far) carried from sample to sample, the fracture placed at its
exact strain. It gives the reference measures of a food under a protocol; the built-in foods are calibrated with it.

**The measures** (:func:`analyse`), from the sample's force F (N, positive pushing the teeth apart) and the gap g
(m) at the bite point. An area is the work of the force over the probe's travel, the sum of F |dg| (trapezoids): at
a held speed its ratios equal those of Bourne's force-time areas. :data:`DEFINITIONS` says each in words; the keys
are :data:`MEASURES`. The energy readings (cohesiveness, springiness, resilience) of a passive sample lie in [0, 1];
outside, by more than the numerical tolerance, their check fails. The texture analyser macro's anchors at the first
peak force (``springiness_at_peak``, ``resilience_at_peak``) can exceed 1 on a fracturing food and are not checked.
:func:`protocol_checks` says whether a test held its protocol (the compression reached, the test speed held).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from chewbot.errors import ChewbotError
from chewbot.food.law import (FOOD_PARAMETERS, NUMPY, fracture_state, loaded_force, maxwell_force,
                              normal_force)
from chewbot.units import factor

BLEND = 0.05  # s: each change of speed is spread over this
HOLD = 0.2  # s at rest before the approach and after the return
APPROACH = 1e-3  # m: the probe starts this far above the sample's unloaded top
TRIGGER_FORCE = 0.049  # N: a texture analyser's default trigger, 5 g
BREAK_DROP = 0.05  # a break: the force falls 5 % below its running maximum while compressing ...
AT_SPEED = 0.95  # ... at 95 % of the stroke's speed or more (the turn's slowing fades a viscous force: no break)
CONTACT_FRACTION = 0.01  # contact where no trigger force is given: the force above 1 % of the hardness
# The energy readings of a passive sample are in [0, 1] within this: the trapezoids at 1 kHz leave less than 1e-4 on
# the closed-form curves of the tests, an estimated curve's noise about 1e-3 (an elastic bolus read 0.999
# from the torques); 0.5 % keeps both inside and puts the impossible values (1.011, 1.176) outside.
RATIO_TOLERANCE = 0.005
# The protocol is held where the deepest compression is within 1 % of its target and the 2nd-98th percentiles of the
# probe's speed within 1 % of the test (post-test) speed, BLEND after the trigger and around each turn left out.
PROTOCOL_TOLERANCE = 0.01
SPEED_PERCENTILES = (2.0, 98.0)
MEASURES = ("hardness_N", "fracturability_N", "cohesiveness", "springiness", "resilience", "adhesiveness_mJ", "gumminess_N",
            "chewiness_N", "springiness_at_peak", "resilience_at_peak")
CHECKED = ("cohesiveness", "springiness", "resilience")  # in [0, 1] for a passive sample
DEFINITIONS = {
    "hardness_N": "the first bite's peak force (N)",
    "fracturability_N": "the force at the first significant break before the peak: the running maximum of the force "
                        "where, compressing at 95 % of the stroke's speed or more, it first falls 5 % below it (N; null "
                        "if it never does)",
    "cohesiveness": "the positive work of the second bite over that of the first, both strokes of each (A2 / A1)",
    "springiness": "Bourne's height recovered: the travel from contact to the deepest point in the second bite over "
                   "that in the first",
    "resilience": "the work returned on the first withdrawal (deepest point back to zero force) over the work of the "
                  "first compression (contact to the deepest point)",
    "adhesiveness_mJ": "the negative work of the first bite: the work of pulling the teeth off the sample (mJ)",
    "gumminess_N": "hardness x cohesiveness (N)",
    "chewiness_N": "gumminess x springiness (N)",
    "springiness_at_peak": "the texture analyser macro's reading: the travel from contact to the peak force in the "
                           "second bite over that in the first (not checked: above 1 where the first peak is a fracture)",
    "resilience_at_peak": "the texture analyser macro's reading: the positive work of the first bite after its peak force "
                          "over that before it (not checked: above 1 where the first peak is a fracture)",
}

# P(x) = int_0^x S, S(u) = 6u^5 - 15u^4 + 10u^3 the quintic smoothstep: P(1) = 1/2


class TpaError(ChewbotError):
    """A texture test that cannot be built or analysed (names the option or the log and why)."""


# ------------------------------------------------------------------------------------------- the protocol


@dataclass(frozen=True)
class Protocol:
    """A texture analyser's two-bite test (SI): ``pre_test_speed``, ``test_speed`` and ``post_test_speed`` (m/s),
    ``trigger_force`` (N), ``compression`` (a fraction of the height at the trigger) or ``distance`` (m, then
    ``compression`` is None), ``pause`` between the bites (s), ``approach`` (m above the sample's top where the probe
    starts), ``blend`` (s over which each change of speed is spread)."""

    pre_test_speed: float = 1e-3
    test_speed: float = 2e-3
    post_test_speed: float = 2e-3
    trigger_force: float = TRIGGER_FORCE
    compression: float | None = 0.5
    distance: float | None = None
    pause: float = 5.0
    approach: float = APPROACH
    blend: float = BLEND

    def target_gap(self, trigger_gap: float) -> float:
        """The deepest gap (m) for a sample whose height at the trigger is ``trigger_gap``."""
        return trigger_gap * (1 - self.compression) if self.distance is None else trigger_gap - self.distance

    def profile(self, start_gap: float, trigger_time: float, rate: float = 1000.0) -> "Profile":
        """The displacement profile of a test that starts at ``start_gap`` (m) and triggers at ``trigger_time`` (s),
        sampled at ``rate`` (Hz)."""
        return Profile(self, start_gap, trigger_time, rate)

    def approach_path(self, start_gap: float, t):
        """The gap (m), its rate and acceleration of the approach (from rest at ``start_gap``, at the pre-test speed)
        at times ``t``, as if no trigger came."""
        return _path(np.asarray(t, float), start_gap, [(HOLD, -self.pre_test_speed)], self.blend)

    def record(self) -> dict:
        """The settings as tpa.json's ``"protocol"`` gives them (the command line's units)."""
        mm, mm_s = factor("mm"), factor("mm/s")
        out = {"pre_test_speed_mm_s": self.pre_test_speed / mm_s, "test_speed_mm_s": self.test_speed / mm_s,
               "post_test_speed_mm_s": self.post_test_speed / mm_s, "trigger_force_N": self.trigger_force}
        if self.distance is None:
            out["compression_percent"] = self.compression * 100
        else:
            out["distance_mm"] = self.distance / mm
        out.update(pause_s=self.pause, approach_mm=self.approach / mm, blend_s=self.blend)
        return out


def settings(compression_percent: float | None = 50.0, test_speed_mm_s: float = 2.0, pause_s: float = 5.0, *,
             pre_test_speed_mm_s: float = 1.0, post_test_speed_mm_s: float | None = None,
             trigger_force_N: float = TRIGGER_FORCE, distance_mm: float | None = None) -> Protocol:
    """The protocol from the command line's units (mm/s, N, %, mm, s), checked: errors name the option. The post-test
    speed is the test speed unless given (a texture analyser's advice for TPA: the areas of both strokes at one
    speed). ``distance_mm`` replaces ``compression_percent`` (give one)."""
    speeds = {"--pre-test-speed": pre_test_speed_mm_s, "--speed": test_speed_mm_s,
              "--post-test-speed": test_speed_mm_s if post_test_speed_mm_s is None else post_test_speed_mm_s}
    for option, value in speeds.items():
        if not (np.isfinite(value) and value > 0):
            raise TpaError(f"{option} {value:g}: the probe's speed must be a positive number of mm/s")
    if not (np.isfinite(trigger_force_N) and trigger_force_N > 0):
        raise TpaError(f"--trigger-force {trigger_force_N:g}: the force that finds the sample must be a positive number of "
                       f"N (a texture analyser's default: {TRIGGER_FORCE:g} N = 5 g)")
    if not (np.isfinite(pause_s) and pause_s >= 0):
        raise TpaError(f"--pause {pause_s:g}: the pause must be a non-negative number of seconds")
    if distance_mm is not None:
        if compression_percent is not None:
            raise TpaError("--distance and --compression: give one (a distance in mm or a percentage of the height at the "
                           "trigger)")
        if not (np.isfinite(distance_mm) and distance_mm > 0):
            raise TpaError(f"--distance {distance_mm:g}: the compression's distance must be a positive number of mm")
        compression, distance = None, distance_mm * factor("mm")
    else:
        c = compression_percent
        if c is None:
            raise TpaError("--compression or --distance: give one (how far each bite compresses the sample)")
        if not np.isfinite(c) or c <= 0 or c >= 100:
            raise TpaError(f"--compression {c:g}: a percentage of the height at the trigger between 0 and 100 (exclusive)")
        if c < 1:
            raise TpaError(f"--compression {c:g}: a percentage of the height at the trigger, not a fraction (did you mean "
                           f"{c * 100:g} %?)")
        compression, distance = c / 100, None
    mm_s = factor("mm/s")
    return Protocol(pre_test_speed=speeds["--pre-test-speed"] * mm_s, test_speed=speeds["--speed"] * mm_s,
                    post_test_speed=speeds["--post-test-speed"] * mm_s, trigger_force=trigger_force_N,
                    compression=compression, distance=distance, pause=pause_s)


def _path(t, start: float, changes, blend: float):
    """g, dg/dt, d2g/dt2 at times t of a path from rest at ``start`` whose speed changes by dv over ``blend`` seconds
    from each time t_i of ``changes`` [(t_i, dv), ...] (quintic smoothstep)."""
    if not changes:
        n = np.shape(t)
        return np.full(n, start), np.zeros(n), np.zeros(n)
    starts, dv = (np.array(c, float) for c in zip(*changes))
    x = (t[..., None] - starts) / blend
    xc = np.clip(x, 0.0, 1.0)
    xc2 = xc * xc
    P = np.where(x > 1, x - 0.5, xc2 * xc2 * (2.5 + xc * (xc - 3)))
    S = xc2 * xc * (10 + xc * (6 * xc - 15))
    dS = 30 * xc2 * (1 - xc) ** 2 / blend
    return start + blend * P @ dv, S @ dv, dS @ dv


@dataclass(frozen=True)
class Profile:
    """The displacement profile of a test (:class:`Protocol`) that started at ``start_gap`` (m) and triggered at
    ``trigger_time`` (s), sampled at ``rate`` (Hz): the path (:meth:`path`), its stops and turns (:attr:`changes`)."""

    protocol: Protocol
    start_gap: float
    trigger_time: float
    rate: float = 1000.0
    changes: tuple = field(init=False, repr=False)  # ((t_i, dv_i), ...): the path's changes of speed
    stops: tuple = field(init=False, repr=False)  # the times the probe stops: deepest, h_t, deepest, start

    def __post_init__(self):
        p, b = self.protocol, self.protocol.blend
        t_tr = self.trigger_time
        if t_tr < HOLD + b:
            raise TpaError(f"the trigger came at t = {t_tr:.4g} s, before the approach reached its pre-test speed: start "
                           "further above the sample")
        h_t = self.trigger_gap
        deepest = p.target_gap(h_t)
        if not 0 < deepest < h_t:
            raise TpaError(f"--distance {p.distance / factor('mm'):g} mm: more than the sample's height at the trigger, "
                           f"{h_t / factor('mm'):.4g} mm")
        changes, stops = [(HOLD, -p.pre_test_speed)], []

        def move(t0: float, v0: float, g0: float, target: float, v1: float) -> float:
            """From speed v0 at t0 (gap g0) to speed v1 and then to rest exactly at ``target``; the stop's time."""
            travel = target - g0  # signed; v1 has its sign
            cruise = travel / v1 - b * (v0 + v1) / (2 * v1) - b / 2
            if cruise < 0:
                raise TpaError(f"a stroke of {abs(travel) / factor('mm'):.3g} mm at {abs(v1) / factor('mm/s'):g} mm/s is shorter than its "
                               f"changes of speed ({b:g} s each); lower the speed")
            changes.extend([(t0, v1 - v0), (t0 + b + cruise, -v1)])
            stops.append(t0 + 2 * b + cruise)
            return stops[-1]

        t = move(t_tr, -p.pre_test_speed, h_t, deepest, -p.test_speed)
        t = move(t, 0.0, deepest, h_t, p.post_test_speed)
        t = move(t + p.pause, 0.0, h_t, deepest, -p.test_speed)
        move(t, 0.0, deepest, self.start_gap, p.post_test_speed)
        object.__setattr__(self, "changes", tuple(changes))
        object.__setattr__(self, "stops", tuple(stops))

    @property
    def trigger_gap(self) -> float:
        """h_t (m): the gap at the trigger, the sample's height as the analyser measures it."""
        return float(self.protocol.approach_path(self.start_gap, np.array([self.trigger_time]))[0][0])

    @property
    def deepest_gap(self) -> float:
        return self.protocol.target_gap(self.trigger_gap)

    @property
    def speed(self) -> float:
        """The test speed (m/s)."""
        return self.protocol.test_speed

    @property
    def pause(self) -> float:
        return self.protocol.pause

    @property
    def duration(self) -> float:
        return float(self.stops[-1] + HOLD)

    def path(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The gap g (m), dg/dt, d2g/dt2 at times ``t``."""
        return _path(np.asarray(t, float), self.start_gap, self.changes, self.protocol.blend)

    def times(self) -> np.ndarray:
        count = int(np.floor(self.duration * self.rate + 1e-9)) + 1
        return np.arange(count) / self.rate

    def held(self) -> list[tuple[float, float, float]]:
        """The spans at a held speed: (from, to, speed in m/s, signed), the test's four strokes from the end of one
        change of speed to the start of the next."""
        b = self.protocol.blend
        starts = [c[0] for c in self.changes[1:]]  # the trigger's change, then stop/go pairs
        spans = []
        for i, (stop_start, speed) in enumerate(zip(starts[1::2], (-self.protocol.test_speed, self.protocol.post_test_speed,
                                                                   -self.protocol.test_speed, self.protocol.post_test_speed))):
            spans.append((starts[2 * i] + b, stop_start, speed))
        return spans

    def record(self) -> dict:
        """The protocol as run (tpa.json): the settings, where it started, the trigger and the deepest gap (mm, s)."""
        mm = factor("mm")
        return {**self.protocol.record(), "start_gap_mm": self.start_gap / mm, "trigger_time_s": self.trigger_time,
                "height_at_trigger_mm": self.trigger_gap / mm, "deepest_gap_mm": self.deepest_gap / mm,
                "turns_s": [self.stops[0], self.stops[2]], "duration_s": self.duration, "rate_Hz": self.rate}


def protocol(height: float, compression_percent: float = 50.0, speed_mm_s: float = 2.0, pause_s: float = 2.0) -> Profile:
    """The profile of a test that does not look at the force: every stroke at ``speed_mm_s``, the trigger where the
    approach reaches the sample's unloaded top ``height`` (m), from ``APPROACH`` above it."""
    p = settings(compression_percent, speed_mm_s, pause_s, pre_test_speed_mm_s=speed_mm_s)
    start = height + p.approach
    # from rest at HOLD, the approach has covered v (t - HOLD - blend / 2) once at speed
    return p.profile(start, HOLD + p.blend / 2 + p.approach / p.pre_test_speed)


# ------------------------------------------------------------------------------------------- the measures


@dataclass(frozen=True)
class TpaAnalysis:
    """The measures of a two-bite test (:data:`MEASURES`, plain numbers or None), their definitions in words (with
    the contact force used), the checks of the energy readings (:class:`chewbot.analysis.checks.CheckResult`), the
    anchors a texture analyser's software marks (samples, times, gaps, forces, areas) and, for an estimated force
    with an error bar, each measure's 95 % interval ``[low, high]`` (``intervals``; None where there is none)."""

    measures: dict
    definitions: dict
    checks: list
    anchors: dict
    intervals: dict | None = None

    def as_dict(self) -> dict:
        """tpa.json's pieces: the measures, the definitions, the checks as run.json has them, the anchors."""
        return {"measures": self.measures, "definitions": self.definitions, "checks": [c.as_dict() for c in self.checks],
                "anchors": self.anchors}


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
    # the two most prominent troughs of the gap; a third as prominent as half the second is a third bite
    troughs, props = find_peaks(-g, prominence=1e-6 * span)
    order = np.argsort(props["prominences"])[::-1]
    prominent = props["prominences"][order]
    if troughs.size < 2 or (troughs.size > 2 and prominent[2] > 0.5 * prominent[1]):
        count = int(np.sum(prominent > 0.5 * prominent[0])) if troughs.size else 0
        raise TpaError(f"a two-bite test has two deepest points of the gap; this one has {count}")
    m1, m2 = sorted(int(k) for k in troughs[order[:2]])
    between = g[m1:m2 + 1]
    top = np.flatnonzero(between >= between.max() - 1e-3 * span) + m1
    split = int((top[0] + top[-1]) // 2)
    return slice(0, split + 1), slice(split, g.size), m1, m2


def _contact(F, g, lo: int, m: int, threshold: float, hold: int = 1) -> tuple[int, float] | None:
    """The first sample from ``lo`` to ``m`` where F reaches ``threshold`` and stays there for ``hold`` samples (or to
    ``m``), and the gap there interpolated between it and the sample before; None if it never does."""
    above = (F[lo:m + 1] >= threshold).astype(int)
    if hold > 1:
        held = np.convolve(above, np.ones(hold, int), "full")[hold - 1:]  # samples above from each one on, up to hold
        above = above * (held >= np.minimum(hold, above.size - np.arange(above.size)))
    above = np.flatnonzero(above)
    if not above.size:
        return None
    k = lo + int(above[0])
    if k == lo or F[k] == F[k - 1]:
        return k, float(g[k])
    w = (threshold - F[k - 1]) / (F[k] - F[k - 1])
    return k, float(g[k - 1] + w * (g[k] - g[k - 1]))


def _at_speed(t, g) -> np.ndarray:
    """Samples where the probe closes at :data:`AT_SPEED` of its top closing speed or faster (the larger of the speeds
    of the intervals on either side; intervals of no time, as at a fracture's two samples, count as the one before)."""
    dt, dg = np.diff(t), np.diff(g)
    speed = np.divide(-dg, dt, out=np.full(dg.size, np.nan), where=dt > 0)
    speed = np.where(np.isnan(speed), np.fmax.accumulate(np.nan_to_num(speed, nan=-np.inf)), speed) if speed.size else speed
    both = np.fmax(np.concatenate([[-np.inf], speed]), np.concatenate([speed, [-np.inf]]))
    return both >= AT_SPEED * np.max(speed, initial=0.0)


def analyse(t, g, F, contact_force: float | None = None, tolerance: float = RATIO_TOLERANCE,
            label: str = "", contact_hold: float = 0.0) -> TpaAnalysis:
    """Bourne's measures of a two-bite test in both readings (module docstring): times ``t`` (s), the gap ``g`` (m) at
    the bite point and the sample's force ``F`` (N, positive pushing the teeth apart). Contact is where the force
    reaches ``contact_force`` (N; the protocol's trigger force; None: :data:`CONTACT_FRACTION` of the hardness). The
    checks hold cohesiveness, springiness and resilience in [0, 1] within ``tolerance``; ``label`` (e.g. "plant")
    prefixes their names. ``contact_hold`` (s): contact is where the force reaches the
    contact force and stays there that long (an estimated force's brief excursions are not contact)."""
    from chewbot.analysis.checks import CheckResult

    t, g, F = (np.asarray(x, float) for x in (t, g, F))
    one, two, m1, m2 = bites(t, g)
    index = np.arange(t.size)
    first = (index >= one.start) & (index < one.stop)
    second = (index >= two.start) & (index < two.stop)
    pos, neg = np.maximum(F, 0.0), np.maximum(-F, 0.0)
    peak1 = int(one.start + np.argmax(F[one]))
    peak2 = int(two.start + np.argmax(F[two]))
    hardness = float(F[peak1])
    if not hardness > 0:
        raise TpaError("the sample was never compressed: no positive force in the first bite")
    threshold = CONTACT_FRACTION * hardness if contact_force is None else float(contact_force)
    A1, A2 = _work(pos, g, first), _work(pos, g, second)
    compressing = F[:m1 + 1]
    running = np.maximum.accumulate(compressing)
    breaks = np.flatnonzero((compressing < (1 - BREAK_DROP) * running) & (running > threshold)
                            & _at_speed(t[:m1 + 1], g[:m1 + 1]))
    fracture = int(np.argmax(compressing[:breaks[0] + 1])) if breaks.size else None
    hold = max(1, int(round(contact_hold / np.median(np.diff(t))))) if contact_hold > 0 else 1
    c1, c2 = _contact(F, g, 0, m1, threshold, hold), _contact(F, g, two.start, m2, threshold, hold)
    D1 = c1[1] - g[m1] if c1 else 0.0
    D2 = c2[1] - g[m2] if c2 else 0.0
    P1 = c1[1] - g[peak1] if c1 else 0.0
    P2 = c2[1] - g[peak2] if c2 else 0.0
    springiness = float(D2 / D1) if D1 > 0 else None
    cohesiveness = A2 / A1
    gumminess = hardness * cohesiveness
    after, before = first & (index >= m1), first & (index <= m1)
    resilience = _work(pos, g, after) / _work(pos, g, before)
    at_peak = _work(pos, g, first & (index <= peak1))
    mJ = factor("mJ")
    measures = {"hardness_N": hardness, "fracturability_N": None if fracture is None else float(F[fracture]),
                "cohesiveness": cohesiveness, "springiness": springiness, "resilience": resilience,
                "adhesiveness_mJ": _work(neg, g, first) / mJ, "gumminess_N": gumminess,
                "chewiness_N": None if springiness is None else gumminess * springiness,
                "springiness_at_peak": float(P2 / P1) if P1 > 0 else None,
                "resilience_at_peak": _work(pos, g, first & (index >= peak1)) / at_peak if at_peak > 0 else None}
    contact = (f"the force first reaching {threshold:.4g} N" + (" (the trigger force)" if contact_force is not None
                                                               else f" ({CONTACT_FRACTION:.0%} of the hardness)"))
    definitions = {k: DEFINITIONS[k] + (f"; contact is {contact}" if "contact" in DEFINITIONS[k] else "")
                   for k in MEASURES}
    definitions["areas"] = "every area is a work, the sum of F |dg| over the gap g at the bite point (trapezoids)"

    def anchor(k: int | None, gap: float | None = None) -> dict | None:
        return None if k is None else {"index": int(k), "t_s": float(t[k]), "gap_mm": float(g[k] if gap is None else gap) / factor("mm"),
                                       "force_N": float(F[k])}

    anchors = {"contact_1": anchor(*c1) if c1 else None, "fracture": anchor(fracture), "peak_1": anchor(peak1),
               "deepest_1": anchor(m1), "split": anchor(one.stop - 1), "contact_2": anchor(*c2) if c2 else None,
               "peak_2": anchor(peak2), "deepest_2": anchor(m2),
               "areas_mJ": {"first_bite": A1 / mJ, "second_bite": A2 / mJ,
                            "first_compression": _work(pos, g, before) / mJ, "first_withdrawal": _work(pos, g, after) / mJ,
                            "before_peak_1": at_peak / mJ, "adhesion": _work(neg, g, first) / mJ}}
    where = {"cohesiveness": m2, "springiness": m2, "resilience": m1}
    checks = []
    for key in CHECKED:
        name = f"{label}-{key}-range" if label else f"{key}-range"
        value = measures[key]
        if value is None:
            checks.append(CheckResult(name, None, None, None, None, f"not evaluated: no contact in the first bite "
                                      f"(the force never reached {threshold:.4g} N)", "failure"))
            continue
        ok = bool(-tolerance <= value <= 1 + tolerance)
        bound = f"[0, 1] within {tolerance:g}"
        message = (f"{key} = {value:.4g}, within {bound}" if ok else
                   f"{key} = {value:.4g} outside {bound}: a passive sample cannot give back more than it took; the test "
                   "did not measure what it claims (compression, speed or the force read)")
        checks.append(CheckResult(name, ok, 0 if ok else 1, None if ok else {"index": int(where[key]), "t": float(t[where[key]])},
                                  {"value": float(value), "unit": "1"}, message, "failure"))
    return TpaAnalysis(measures, definitions, checks, anchors)


def tpa_measures(t, g, F, contact_force: float | None = None) -> dict:
    """The measures alone (:func:`analyse`)."""
    return analyse(t, g, F, contact_force).measures


def protocol_checks(t, g, F, profile: Profile, rate=None, label: str = "") -> list:
    """Whether a test held its protocol (:class:`chewbot.analysis.checks.CheckResult`, failures): ``compression-
    reached``, each bite's deepest gap within :data:`PROTOCOL_TOLERANCE` of the target (for 50 %: 49.5-50.5 % of the
    height at the trigger), and ``speed-held``, the 2nd-98th percentiles of the probe's speed (``rate``, dg/dt in m/s;
    central differences of ``g`` if not given) within :data:`PROTOCOL_TOLERANCE` of the test speed on each
    compression and of the post-test speed on each withdrawal until the force is back to zero, the changes of speed
    (:attr:`Protocol.blend` after the trigger and around each turn) left out. ``t``, ``g`` (m), ``F`` (N) as measured."""
    from chewbot.analysis.checks import CheckResult

    t, g, F = (np.asarray(x, float) for x in (t, g, F))
    v = np.gradient(g, t) if rate is None else np.asarray(rate, float)
    _, _, m1, m2 = bites(t, g)
    h_t, target = profile.trigger_gap, profile.deepest_gap
    wanted = h_t - target
    checks = []
    name = (lambda n: f"{label}-{n}" if label else n)
    reached = [(h_t - g[m]) / wanted for m in (m1, m2)]
    worst = int(np.argmax(np.abs(np.array(reached) - 1)))
    off = abs(reached[worst] - 1)
    ok = bool(off <= PROTOCOL_TOLERANCE)
    how = (f"{profile.protocol.compression * 100:g} % of the height at the trigger" if profile.protocol.distance is None
           else f"{profile.protocol.distance / factor('mm'):g} mm")
    checks.append(CheckResult(name("compression-reached"), ok, 0 if ok else int(sum(abs(r - 1) > PROTOCOL_TOLERANCE for r in reached)),
                              None if ok else {"index": int((m1, m2)[worst]), "t": float(t[(m1, m2)[worst]])},
                              {"value": float(reached[worst] * 100), "unit": "% of the target"},
                              f"the bites reached {reached[0]:.2%} and {reached[1]:.2%} of the target compression ({how}, "
                              f"{wanted / factor('mm'):.4g} mm from {h_t / factor('mm'):.4g} mm); within {PROTOCOL_TOLERANCE:.0%}: {'yes' if ok else 'no'}",
                              "failure"))
    # the spans at a held speed, the withdrawals cut where the force is back to zero
    bad_spans, worst_span = [], (0.0, None, None)
    for k, (a, b, speed) in enumerate(profile.held()):
        inside = (t >= a) & (t <= b)
        if speed > 0:  # withdrawal: until the force is back to zero
            ends = np.flatnonzero(inside & (F <= 0))
            if ends.size:
                inside &= t <= t[ends[0]]
        if inside.sum() < 3:
            continue
        low, high = np.percentile(v[inside], SPEED_PERCENTILES)
        dev = float(max(abs(low / speed - 1), abs(high / speed - 1)))
        if dev > worst_span[0]:
            worst_span = (dev, k, int(np.flatnonzero(inside)[0]))
        if dev > PROTOCOL_TOLERANCE:
            bad_spans.append(k)
    strokes = ("first compression", "first withdrawal", "second compression", "second withdrawal")
    dev, k, first = worst_span
    ok = not bad_spans
    checks.append(CheckResult(name("speed-held"), ok, len(bad_spans),
                              None if ok else {"index": first, "t": float(t[first])},
                              {"value": dev * 100, "unit": "% off the stroke's speed"},
                              f"the probe's speed (percentiles {SPEED_PERCENTILES[0]:g}-{SPEED_PERCENTILES[1]:g}) off its stroke's "
                              f"speed by at most {dev:.2%}" + ("" if k is None else f" ({strokes[k]})")
                              + f"; allowed {PROTOCOL_TOLERANCE:.0%}" + ("" if ok else f"; failed: {', '.join(strokes[i] for i in bad_spans)}"),
                              "failure"))
    return checks


# ------------------------------------------------------------------------------------------- the ideal analyser


@dataclass(frozen=True)
class TextureTest:
    """A test run by the ideal texture analyser: the times (s), the gap (m), the force (N), the food's state along it
    (``state``: broken, F_m (N), delta_max (m), as :data:`chewbot.food.law.FOOD_STATE`), the profile as run, the
    events (``{"t", "event", "delta_m"}``) and the analysis."""

    t: np.ndarray
    gap: np.ndarray
    force: np.ndarray
    state: dict
    profile: Profile
    events: list
    analysis: TpaAnalysis

    @property
    def measures(self) -> dict:
        return self.analysis.measures


def _decaying_sum(t, u, inv_tau: float, y0: float) -> np.ndarray:
    """y_k = e^(-inv_tau (t_k - t_k-1)) y_k-1 + u_k, y_0 = y0 + u_0, on whole arrays: y_k = e^(-inv_tau t_k) (y0 +
    sum_j<=k u_j e^(inv_tau t_j)), the exponentials taken in blocks short enough not to overflow."""
    if inv_tau == 0:
        return y0 + np.cumsum(u)
    out = np.empty_like(u)
    start, carry = 0, y0
    while start < t.size:
        stop = start + int(np.searchsorted(t[start:], t[start] + 500.0 / inv_tau, side="right"))
        s = t[start:stop] - t[start]
        acc = np.cumsum(u[start:stop] * np.exp(inv_tau * s))
        out[start:stop] = np.exp(-inv_tau * s) * (carry + acc)
        carry = out[stop - 1] * np.exp(-inv_tau * (t[stop] - t[stop - 1])) if stop < t.size else 0.0
        start = stop
    return out


def _states(f, t, delta, ddelta, broken, sin_tilt, F_m0=0.0):
    """The food's state and force along a compression imposed at times t (the fracture already placed in
    ``broken``): delta_max, b F_e, F_m (the exact step of the Maxwell branch between samples, the jump at the
    fracture), F_n."""
    delta_max = np.maximum.accumulate(np.maximum(delta, 0.0))  # at a constant tilt, tilt_max is sin_tilt
    bFe = loaded_force(NUMPY, f, delta, broken, delta_max, sin_tilt, sin_tilt)
    inv_tau = float(f[FOOD_PARAMETERS.index("inv_tau")])
    h = np.diff(t)
    # increments of the step formula: F_m(t+h) = F_m(t) e^(-h/tau) + rho (bFe(t+h) - bFe(t)) phi(h/tau)
    u = np.concatenate([[0.0], maxwell_force(NUMPY, f, 0.0, bFe[:-1], bFe[1:], h)])
    jump = np.flatnonzero(np.diff(broken) > 0)
    if jump.size:  # the fracture: two samples at one time, before and after; F_m jumps by the ratio of b F_e
        k = int(jump[0]) + 1
        F_m = np.empty_like(delta)
        F_m[:k] = _decaying_sum(t[:k], u[:k], inv_tau, F_m0)
        _, after, _ = fracture_state(NUMPY, f, delta[k], F_m[k - 1], delta_max[k], sin_tilt, sin_tilt)
        u[k] = 0.0
        F_m[k:] = _decaying_sum(t[k:], u[k:], inv_tau, float(after))
    else:
        F_m = _decaying_sum(t, u, inv_tau, F_m0)
    F_n, _ = normal_force(NUMPY, f, delta, ddelta, broken, F_m, delta_max, sin_tilt, sin_tilt)
    return delta_max, F_m, F_n


def ideal_test(food, protocol: Protocol = Protocol(), rate: float = 1000.0, tilt: float = 0.0) -> TextureTest:
    """The ideal texture analyser (module docstring): ``food`` (:class:`chewbot.food.law.Food`) driven through
    ``protocol`` sampled at ``rate`` (Hz), the faces at a constant ``tilt`` (rad; 0: parallel platens). The fracture is
    placed at its exact strain (two samples at its time, before and after), the trigger at its exact time."""
    from scipy.optimize import brentq

    f = food.vector()
    h0 = food.height
    sin_tilt = np.sin(tilt)
    start = h0 + protocol.approach
    # the approach, as if no trigger came, until the teeth would meet: the trigger is the first time F_n reaches it
    t_a = np.arange(int(np.ceil((HOLD + protocol.blend + start / protocol.pre_test_speed) * rate)) + 1) / rate
    g_a, dg_a, _ = protocol.approach_path(start, t_a)
    reach = g_a > 0
    t_a, g_a, dg_a = t_a[reach], g_a[reach], dg_a[reach]
    zero = np.zeros(t_a.size)
    _, F_m_a, F_a = _states(f, t_a, h0 - g_a, -dg_a, zero, sin_tilt)
    hits = np.flatnonzero(F_a >= protocol.trigger_force)
    if not hits.size:
        raise TpaError(f"the {food.name} never pushed back {protocol.trigger_force:g} N (the trigger force) before the teeth "
                       "met: lower --trigger-force")
    k = int(hits[0])
    if k == 0:
        raise TpaError(f"the {food.name} pushes back {F_a[0]:.3g} N at the start, above the trigger force")
    bFe_k = float(loaded_force(NUMPY, f, h0 - g_a[k - 1], 0.0, max(h0 - g_a[k - 1], 0.0), sin_tilt))

    def force_at(tt: float) -> float:
        g, dg, _ = protocol.approach_path(start, np.array([tt]))
        d = h0 - g[0]
        bFe = float(loaded_force(NUMPY, f, d, 0.0, max(d, 0.0), sin_tilt))
        F_m = float(maxwell_force(NUMPY, f, F_m_a[k - 1], bFe_k, bFe, tt - t_a[k - 1]))
        return float(normal_force(NUMPY, f, d, -dg[0], 0.0, F_m, max(d, 0.0), sin_tilt)[0]) - protocol.trigger_force

    t_trigger = brentq(force_at, t_a[k - 1], t_a[k], xtol=1e-12, rtol=4 * np.finfo(float).eps)
    profile = protocol.profile(start, t_trigger, rate)
    t = np.union1d(profile.times(), [t_trigger])
    g, dg, _ = profile.path(t)
    delta = h0 - g
    events = []
    broken = np.zeros(t.size)
    if food.fracture_strain is not None:  # on the face's most compressed fibre (chewbot.food.law.guards)
        edge = (food.diameter or 0.0) / 2 * sin_tilt
        strain = (delta + edge) / h0 - food.fracture_strain
        over = np.flatnonzero(strain >= 0)
        if over.size:
            j = int(over[0])
            t_f = t[j] if strain[j] == 0 or j == 0 else brentq(
                lambda tt: (h0 - profile.path(np.array([tt]))[0][0] + edge) / h0 - food.fracture_strain, t[j - 1], t[j],
                xtol=1e-13, rtol=4 * np.finfo(float).eps)
            _, dg_f, _ = profile.path(np.array([t_f]))
            t = np.concatenate([t[:j], [t_f, t_f], t[j:]])
            g = np.concatenate([g[:j], [h0 * (1 - food.fracture_strain) + edge] * 2, g[j:]])
            dg = np.concatenate([dg[:j], [dg_f[0]] * 2, dg[j:]])
            delta = h0 - g
            broken = (np.arange(t.size) > j).astype(float)
            events.append({"t": float(t_f), "event": "fracture", "delta_m": float(delta[j])})
    delta_max, F_m, F_n = _states(f, t, delta, -dg, broken, sin_tilt)
    events.insert(0, {"t": float(t_trigger), "event": "trigger", "delta_m": float(h0 - profile.trigger_gap)})
    analysis = analyse(t, g, F_n, protocol.trigger_force)
    state = {"broken": broken, "F_m": F_m, "delta_max": delta_max}
    return TextureTest(t, g, F_n, state, profile, events, analysis)


__all__ = ["APPROACH", "BLEND", "BREAK_DROP", "CHECKED", "CONTACT_FRACTION", "DEFINITIONS", "HOLD", "MEASURES",
           "PROTOCOL_TOLERANCE", "AT_SPEED", "Profile", "Protocol", "RATIO_TOLERANCE", "TRIGGER_FORCE", "TextureTest", "TpaAnalysis",
           "TpaError", "analyse", "bites", "ideal_test", "protocol", "protocol_checks", "settings", "tpa_measures"]
