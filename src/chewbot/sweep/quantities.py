"""The outputs a sweep can compute per evaluation: one number each, with its unit (docs/sweeps.md lists them).

An output is a function of an :class:`~chewbot.sweep.evaluate.Evaluation`, which computes the stages of a run
lazily: an output that needs only the kinematics (``min_mu_deg``) costs no inverse dynamics, one that needs the
inertia coupling (``mean_MCI``) no torques, and only the ratios evaluate the counterpart mechanism. Every
number is computed from the same arrays as ``chewbot run`` computes them (its results.csv and checks).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from chewbot.dynamics.indices import INDEX_UNITS

NAN = float("nan")


@dataclass(frozen=True)
class Output:
    """One output: ``name`` (its column), ``unit``, ``description``, ``value(evaluation) -> float``;
    ``target_only``: NaN on the 6RSS (no HKPs); ``whole``: it reads more of the inverse dynamics than the torques
    (the formulation's columns or info, or the run's checks), so an evaluation runs the whole formulation
    rather than its torques alone."""

    name: str
    unit: str
    description: str
    value: Callable
    target_only: bool = False
    whole: bool = False


def _max_abs(a: np.ndarray) -> float:
    return float(np.abs(a).max())


def _column(name: str, reduce):
    """An output read from a column of the formulation's own table (N_L, N_R): NaN where the run has none."""

    def value(ev) -> float:
        table = ev.dynamics.table
        return float(reduce(table[name])) if name in table else NAN

    return value


def _share(check: str):
    """The failing samples of a validity check over the task's samples; NaN where the run cannot evaluate it."""

    def value(ev) -> float:
        samples = ev.check(check).samples
        return NAN if samples is None else samples / ev.kinematics.n

    return value


def _index(name: str):
    def value(ev) -> float:
        return float(ev.dynamics.info.get("indices", {}).get(name, NAN))

    return value


def _ratio(i: int | None, reduce=None):
    def value(ev) -> float:
        r = ev.mean_mci / ev.counterpart_mean_mci
        return float(r[i] if i is not None else reduce(r))

    return value


def _outputs() -> dict[str, Output]:
    out = [
        Output("peak_tau_Nm", "N*m", "largest abs(tau_i) over the samples and joints", lambda ev: _max_abs(ev.tau)),
        *[Output(f"peak_tau{i + 1}_Nm", "N*m", f"largest abs(tau_{i + 1}) over the samples",
                 lambda ev, i=i: _max_abs(ev.tau[:, i])) for i in range(6)],
        Output("rms_tau_Nm", "N*m", "root mean square of tau over the samples and joints",
               lambda ev: float(np.sqrt(np.mean(ev.tau ** 2)))),
        Output("peak_power_W", "W", "largest abs(tau_i theta_dot_i) over the samples and joints",
               lambda ev: _max_abs(ev.tau * ev.kinematics.dtheta)),
        Output("peak_speed_rad_per_s", "rad/s", "largest abs(theta_dot_i) over the samples and joints",
               lambda ev: _max_abs(ev.kinematics.dtheta)),
        Output("min_mu_deg", "deg", "smallest transmission angle over the samples and chains (docs/conventions.md)",
               lambda ev: float(np.degrees(ev.mu.min()))),
        Output("min_kappa_J", "1", "smallest kappa of the chains' Jacobian over the samples (1 best, 0 singular)",
               lambda ev: float(ev.kinematics.kappa.min())),
        Output("mean_MCI", "1", "MCI (seed 000, Eq. 60) averaged over the samples and the six joints",
               lambda ev: float(ev.mean_mci.mean())),
        *[Output(f"mean_MCI{i + 1}", "1", f"MCI_{i + 1} averaged over the samples",
                 lambda ev, i=i: float(ev.mean_mci[i])) for i in range(6)],
        Output("max_MCI", "1", "largest MCI_i over the samples and joints", lambda ev: float(ev.mci.max())),
        *[Output(f"ratio_MCI{i + 1}", "1", f"mean_MCI{i + 1} over the counterpart's mean_MCI{i + 1} (the same motion and "
                 "values on the other mechanism: seed 000's target/6RSS comparison)", _ratio(i)) for i in range(6)],
        Output("min_ratio_MCI", "1", "smallest of ratio_MCI1..6", _ratio(None, np.min)),
        Output("max_ratio_MCI", "1", "largest of ratio_MCI1..6", _ratio(None, np.max)),
        Output("peak_N_L", "N", "largest normal force of the left plane on its condyle (NaN where the formulation "
               "gives no N_L, and on the 6RSS)", _column("N_L", np.max), target_only=True, whole=True),
        Output("peak_N_R", "N", "largest normal force of the right plane on its condyle", _column("N_R", np.max), target_only=True, whole=True),
        Output("min_N_L", "N", "smallest normal force of the left plane (negative: the plane pulls)", _column("N_L", np.min), target_only=True, whole=True),
        Output("min_N_R", "N", "smallest normal force of the right plane", _column("N_R", np.min), target_only=True, whole=True),
        Output("contact_pull_share", "1", "share of the task's samples where a plane pulls its condyle: the contact-pull "
               "check's failing samples (N below 0, or below contact.preload_N under the unilateral contact model)",
               _share("contact-pull"), target_only=True, whole=True),
        Output("feasible", "1", "1 where no validity check that makes chewbot run exit 4 fails, else 0",
               lambda ev: float(not ev.fails), whole=True),
        Output("failed_checks", "1", "number of validity checks that fail the run", lambda ev: float(len(ev.failed_checks)), whole=True),
        Output("violation_share", "1", "sum over the failed checks of their failing samples over the task's samples "
               "(0 where feasible; the optimiser's measure of how far a design is from feasible)",
               lambda ev: float(sum(c.samples or 0 for c in ev.failed_checks) / ev.kinematics.n), whole=True),
        *[Output(name, unit, f"performance index {name} (seed 001, Sect. 5.3; newton-euler only, else NaN)", _index(name),
                 target_only=name in ("F3", "F7"), whole=True) for name, unit in INDEX_UNITS.items()],
    ]
    return {o.name: o for o in out}


OUTPUTS: dict[str, Output] = _outputs()


def needs_counterpart(name: str) -> bool:
    """True for the outputs that compare with the counterpart mechanism."""
    return "ratio_MCI" in name
