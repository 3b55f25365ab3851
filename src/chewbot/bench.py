"""Timing of the inverse-dynamics formulations on the default task (``chewbot bench``).

Each case is one entry of :data:`CASES`: a label and a callable ``(model, kinematics) -> anything`` that computes
the torques of the whole task. Adding a formulation (Newton-Euler, a 6RSS-core formulation, a compiled kernel) to
the benchmark is adding one entry. Every case runs on every mechanism of :data:`MECHANISMS` in one process, so the
medians and ratios printed are measured under the same conditions.

The first call of a case builds its CasADi graph and loads (or, with an empty kernel cache, compiles) its C code:
it is reported apart from the steady-state median.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from functools import partial
from typing import Callable

from chewbot.dynamics import inverse_dynamics
from chewbot.kinematics.motion import solve_kinematics
from chewbot.params import load_model
from chewbot.task.default import default_task

CASES: dict[str, Callable] = {
    "hessian": partial(inverse_dynamics, method="hessian"),
    "liang": partial(inverse_dynamics, method="liang"),
    "lagrange": partial(inverse_dynamics, method="lagrange"),
}
MECHANISMS = ("target", "6rss")
# Ratios printed: (numerator case, denominator case) on each mechanism.
CASE_RATIOS = (("hessian", "liang"), ("lagrange", "liang"))


@dataclass(frozen=True)
class Timing:
    """One case on one mechanism: ``first_s`` (graph build + kernel load or compile + run), ``median_s`` and
    ``min_s`` over ``repeats`` further runs, for ``samples`` samples of the task."""

    mechanism: str
    case: str
    samples: int
    first_s: float
    median_s: float
    min_s: float
    repeats: int


def _time(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def bench(repeats: int = 11, cases: dict[str, Callable] | None = None, mechanisms=MECHANISMS, side: str = "left") -> list[Timing]:
    """Time every case on every mechanism on the default task; the models are loaded fresh, so the first call of
    a case includes building its graph."""
    out = []
    for name in mechanisms:
        model = load_model(name)
        kin = solve_kinematics(model, default_task(model, side))
        for label, case in (cases or CASES).items():
            run = partial(case, model, kin)
            first = _time(run)
            times = [_time(run) for _ in range(repeats)]
            out.append(Timing(name, label, kin.n, first, statistics.median(times), min(times), repeats))
    return out


def ratios(timings: list[Timing]) -> dict[str, float]:
    """Median ratios: each pair of :data:`CASE_RATIOS` per mechanism, and target over 6RSS per case."""
    med = {(t.mechanism, t.case): t.median_s for t in timings}
    out = {}
    for mech in dict.fromkeys(t.mechanism for t in timings):
        for a, b in CASE_RATIOS:
            if (mech, a) in med and (mech, b) in med:
                out[f"{mech}: {a} / {b}"] = med[mech, a] / med[mech, b]
    for case in dict.fromkeys(t.case for t in timings):
        if ("target", case) in med and ("6rss", case) in med:
            out[f"{case}: target / 6rss"] = med["target", case] / med["6rss", case]
    return out
