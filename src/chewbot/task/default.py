"""The default synthetic chewing task (docs/conventions.md; assumed: the papers' measured data are not public).

A rest period, then ``cycles`` chewing cycles. In each cycle every coordinate follows a smooth bump
b(s) = K s^a (1 - s)^c of the cycle phase s in [0, 1] (a, c >= 3: position, velocity and acceleration are
zero at both ends, so cycles join with C^2 continuity), with its peak at s = a / (a + c):
beta (mouth opening) and X (protrusion) peak early, Y and alpha (the swing to the working side) peak late,
as in human chewing. The bite force is one burst per cycle in the closing phase.
Everything is analytic: the rates are exact derivatives of the bumps.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

import numpy as np
from numpy.polynomial import Polynomial

from chewbot.config import unknown_key
from chewbot.errors import TaskError
from chewbot.model import Model
from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task
from chewbot.units import factor


@dataclass(frozen=True)
class ChewingParameters:
    """Parameters of the synthetic chewing task; units in the names (s, Hz, mm, deg, N)."""

    cycles: int = 5
    period_s: float = 0.8
    rest_s: float = 1.0
    rate_hz: float = 1000.0
    X_mm: float = 4.0  # protrusion of O_M
    Y_mm: float = 2.0  # lateral swing toward the working side
    alpha_deg: float = 2.0  # roll toward the working side
    beta_deg: float = 10.0  # mouth opening
    peak_open: float = 0.4  # phase of the beta and X peaks
    peak_swing: float = 0.7  # phase of the Y and alpha peaks (later: the jaw swings while closing)
    force_z_N: float = -80.0  # vertical bite force at the peak of a burst (down on the mandible)
    force_x_N: float = -15.0
    force_y_N: float = 5.0  # lateral component swings between +/- this value during a burst
    burst_s: float = 0.25  # duration of one bite-force burst
    burst_centre: float = 0.8  # phase of the burst's centre (closing phase)

    def validate(self) -> None:
        if self.cycles < 0 or int(self.cycles) != self.cycles:
            raise TaskError(f"default task: cycles must be a non-negative integer, not {self.cycles}")
        for name in ("period_s", "rate_hz", "burst_s"):
            if not getattr(self, name) > 0:
                raise TaskError(f"default task: {name} must be positive, not {getattr(self, name)}")
        if self.rest_s < 0:
            raise TaskError(f"default task: rest_s must be >= 0, not {self.rest_s}")
        for name in ("peak_open", "peak_swing"):
            if not 0.3 <= getattr(self, name) <= 0.7:
                raise TaskError(f"default task: {name} must lie in [0.3, 0.7], not {getattr(self, name)}")
        half = self.burst_s / (2 * self.period_s)
        if not (half <= self.burst_centre <= 1 - half):
            raise TaskError(f"default task: a burst of {self.burst_s} s centred at phase {self.burst_centre} does not fit in a cycle of {self.period_s} s")


def parameters_with(overrides: dict[str, float], base: ChewingParameters | None = None) -> ChewingParameters:
    """``base`` (default: the defaults) with the fields named in ``overrides`` (``{"force_z_N": -100.0}``, as
    ``chewbot run --set task.force_z_N=-100`` gives them) replaced, then validated; errors name the argument."""
    types = {f.name: f.type for f in fields(ChewingParameters)}
    values = {}
    for name, value in overrides.items():
        argument = f"--set task.{name}={value:g}"
        if name not in types:
            reason = unknown_key(name, types, prefix="task.", value=value).removeprefix("unknown key")
            raise TaskError(f"{argument}: the default task has no parameter {name!r}{reason}")
        if types[name] in ("int", int):
            if float(value) != int(value):
                raise TaskError(f"{argument}: task.{name} must be a whole number")
            value = int(value)
        values[name] = float(value) if types[name] in ("float", float) else value
    params = replace(base or ChewingParameters(), **values)
    try:
        params.validate()
    except TaskError as exc:
        raise TaskError(f"{', '.join(f'--set task.{k}={v:g}' for k, v in overrides.items())}: {exc}") from None
    return params


def _bump(peak: float, order: int = 10) -> tuple[Polynomial, Polynomial, Polynomial]:
    """s^a (1-s)^c scaled to a maximum of 1 at s = peak (a + c = order, a, c >= 3), with its derivatives."""
    a = int(round(peak * order))
    a = min(max(a, 3), order - 3)
    c = order - a
    p = Polynomial([0, 1]) ** a * Polynomial([1, -1]) ** c
    s_max = a / order
    p = p / p(s_max)
    return p, p.deriv(1), p.deriv(2)


def default_task(model: Model | None = None, side: str = "left", params: ChewingParameters | None = None) -> Task:
    """The default chewing task on the ``side`` molar (right: Y, alpha and F_y mirrored).

    With a 6RSS ``model`` the task carries all six coordinates of X_EE, Z and gamma being the parasitic
    motions of the target's HKPs (the model's ``hkp`` geometry): both robots run the same motion.
    """
    params = params or ChewingParameters()
    params.validate()
    if side not in ("left", "right"):
        raise TaskError(f"side must be 'left' or 'right', not {side!r}")
    n = int(round((params.rest_s + params.cycles * params.period_s) * params.rate_hz)) + 1
    t = np.arange(n) / params.rate_hz
    tc = t - params.rest_s
    active = (tc >= 0) & (tc < params.cycles * params.period_s)
    s = np.where(active, (tc % params.period_s) / params.period_s, 0.0)
    T = params.period_s
    sign = 1.0 if side == "left" else -1.0
    amplitudes = {
        "X": (params.X_mm * factor("mm"), params.peak_open),
        "Y": (sign * params.Y_mm * factor("mm"), params.peak_swing),
        "alpha": (sign * np.radians(params.alpha_deg), params.peak_swing),
        "beta": (np.radians(params.beta_deg), params.peak_open),
    }
    q, dq, ddq = (np.zeros((n, 4)) for _ in range(3))
    for j, name in enumerate(TARGET_COORDS):
        amp, peak = amplitudes[name]
        b, db, ddb = _bump(peak)
        q[:, j] = np.where(active, amp * b(s), 0.0)
        dq[:, j] = np.where(active, amp * db(s) / T, 0.0)
        ddq[:, j] = np.where(active, amp * ddb(s) / T**2, 0.0)

    # bite force: a sin^2 burst of burst_s seconds centred at phase burst_centre of each cycle
    u = (s - params.burst_centre) * T / params.burst_s + 0.5  # 0..1 over the burst
    inside = active & (u >= 0) & (u <= 1)
    envelope = np.where(inside, np.sin(np.pi * u) ** 2, 0.0)
    force = np.stack(
        [
            params.force_x_N * envelope,
            sign * params.force_y_N * np.where(inside, np.sin(2 * np.pi * u), 0.0),
            params.force_z_N * envelope,
        ],
        axis=1,
    )
    meta = {"generator": "default", "parameters": asdict(params)}
    task = Task(name=f"default-{side}", t=t, coords=TARGET_COORDS, q=q, dq=dq, ddq=ddq, force=force, side=side, meta=meta)
    if model is not None and not model.has_hkp:
        return lift_to_full(model, task)
    return task


def lift_to_full(model: Model, task: Task) -> Task:
    """The same task with all six coordinates (Z and gamma from the model's sockets)."""
    from chewbot.compiled.kernels import evaluate
    from chewbot.compiled.cache import folded
    from chewbot.kinematics.functions import parasitic_function

    X, dX, ddX = evaluate(parasitic_function(folded(model)), task.q, task.dq, task.ddq)
    return Task(name=task.name, t=task.t, coords=FULL_COORDS, q=X, dq=dX, ddq=ddX, force=task.force, lines=task.lines,
                side=task.side, source=task.source, meta=task.meta)
