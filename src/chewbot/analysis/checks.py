"""Validity checks of a run: does what the run computed stay within what the robot and its model allow?

Every run checks every sample and records the verdicts in run.json under ``"checks"`` (docs/cli.md):

| check | a sample fails where | needs the columns | failure or warning |
|---|---|---|---|
| ``torque-limit`` | abs(tau_i) > ``limits.torque_Nm`` | tau1..6 | failure |
| ``power-limit`` | abs(tau_i theta_dot_i) > ``limits.power_W`` | tau1..6, dtheta1..6 | failure |
| ``bearing-load`` | abs(axial) or radial force at a crank bearing G_i over ``limits.axial_load_N``, ``limits.radial_load_N`` | FG1_axial .. FG6_radial (newton-euler) | failure |
| ``crank-range`` | theta_i outside ``limits.theta_range_deg`` (no key: not checked) | theta1..6 | failure |
| ``speed-limit`` | abs(theta_dot_i) > ``limits.speed_rad_per_s`` (no key: not checked) | dtheta1..6 | failure of a planned motion, warning of a simulated one |
| ``acceleration-limit`` | abs(theta_ddot_i) > ``limits.acceleration_rad_per_s2`` (no key: not checked) | ddtheta1..6 | failure of a planned motion, warning of a simulated one |
| ``distribution-infeasible`` | the distribution found no torques within the limits (and, unilateral, N >= the preload) | the formulation's ``info["infeasible"]`` | failure |
| ``contact-pull`` | N_L or N_R < 0: the plane pulls the condyle (unilateral: below ``contact.preload_N``) | N_L, N_R | failure only under the unilateral contact model |
| ``near-singular`` | a transmission angle below :data:`NEAR_SINGULAR_DEG` or the chains' Jacobian's kappa below :data:`KAPPA_MIN` | mu1..6, kappa_J | warning |
| ``bite-force`` | abs(F_B) > :data:`BITE_FORCE_BOUND_N` | Fx, Fy, Fz | warning |

The crank speed and acceleration limits bound what a motion may ask of the motors: a task (``chewbot run``, an
imported recording) that exceeds them fails. A simulated plant's motion is not asked for: it follows from the
torques, which the simulation already saturates at ``limits.torque_Nm``, and its transients (PD's first
milliseconds, a plant driven out of its workspace) are reported there as warnings (``planned=False``).

A check whose columns the run does not have (bearing loads with the Hessian method, the crank range of a model
without one) is not evaluated: ``samples`` is null and the message says why.

Each check is a reducer, so that a long task can be checked chunk by chunk: ``update(offset, columns, info)``
for each chunk (``offset`` the index of the chunk's first sample in the task, ``columns`` a mapping of the
chunk's columns by name, ``info`` the formulation's info for the chunk, its sample indices counted from the
chunk's start), then ``result()``. A whole run is one update (:func:`run_checks`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Callable, Mapping

import numpy as np

from chewbot.dynamics.options import CONTACT_MODELS, check_contact
from chewbot.dynamics.distribution import LIMIT_RTOL
from chewbot.model import Limits, Model

# A chain's transmission angle below this is near-singular (docs/conventions.md, "Transmission angle"): its
# crank rate is then more than 1/sin(10 deg) = 5.8 times the speed of M_i along the coupler divided by the
# crank length. Chains 3 and 4 of the built-in robots work at 17.96 deg at home and reach 13.98 deg on the
# default task; a few more degrees toward the dead point is where the task would pass it.
NEAR_SINGULAR_DEG = 10.0
# kappa of the chains' Jacobian (chewbot.kinematics.conditioning) below this is near-singular: crank-angle
# errors, and the torques that hold a load, are then 100 times larger in the worst direction of motion than in
# the best. The default task keeps kappa in 0.34-0.41 on the target and 0.030-0.16 on the 6RSS.
KAPPA_MIN = 0.01
# Largest plausible bite force: above the maximal voluntary molar bite force of healthy adults, roughly
# 300-900 N (e.g. 847 N in men and 597 N in women, Waltimo and Könönen 1993, Scand. J. Dent. Res. 101:171;
# review: Bakke 2006, Semin. Orthod. 12:120). Chewing takes about 70-150 N; the default task's bursts are 80 N.
BITE_FORCE_BOUND_N = 1000.0
# N_L, N_R below -this count as a pull: the distribution's G3 leaves normal forces of about 1e-12 N of
# either sign where it drives them to zero, which is no pull.
PULL_TOLERANCE_N = 1e-6


@dataclass(frozen=True)
class CheckResult:
    """The verdict of one check, as run.json records it (docs/cli.md)."""

    name: str
    passed: bool | None  # None: not evaluated (run.json: null)
    samples: int | None  # how many samples fail; None: not evaluated (the run has no such quantity)
    first_sample: dict | None  # {"index": k, "t": t} of the first failing sample
    worst: dict | None  # {"value": v, "unit": u}: the worst value over all samples, failing or not
    message: str
    severity: str  # "failure": a failed check makes the run exit 4; "warning": reported only

    @property
    def fails_run(self) -> bool:
        """True if this result makes the run fail (exit code 4): failed, and a failure under the contact model."""
        return self.passed is False and self.severity == "failure"

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class CheckContext:
    """What the checks know beyond the columns: the model's limits, the mechanism, the contact model, the
    smallest normal force it admits (``contact.preload_N``, unilateral only) and whether the motion was planned
    (a task) or simulated (the speed and acceleration limits then warn)."""

    limits: Limits
    has_hkp: bool
    contact: str = "bilateral"
    preload: float = 0.0
    planned: bool = True  # the motion is a task asked of the robot (False: a simulated plant's response)

    def __post_init__(self):
        check_contact(self.contact)


@dataclass(frozen=True)
class Measure:
    """What a check sees in one chunk: per sample a ``score`` (larger is worse), whether the sample fails, the
    ``value`` reported for the worst sample (in the check's unit), and ``where(k)`` naming what in sample k is
    worst (a joint, a bearing)."""

    score: np.ndarray
    bad: np.ndarray
    value: np.ndarray
    where: Callable[[int], str]


class Check:
    """A reducer over chunks of samples (see the module docstring). Subclasses define :meth:`measure`."""

    name = ""
    unit = ""
    what = ""  # the measured quantity, for messages
    failure = True  # severity under the bilateral contact model

    def __init__(self, ctx: CheckContext):
        self.ctx = ctx
        self.evaluated: bool | None = None
        self.samples = 0
        self.first: tuple[int, float] | None = None
        self.worst: tuple[float, float, str, int, float] | None = None  # score, value, where, index, t
        self.reason = ""

    def measure(self, columns: Mapping, info: Mapping) -> Measure | None:
        """The chunk's :class:`Measure`, or None (setting ``self.reason``) where the run cannot give it."""
        raise NotImplementedError

    def bound(self) -> str:
        """The bound, as the messages state it."""
        raise NotImplementedError

    def update(self, offset: int, columns: Mapping, info: Mapping | None = None) -> None:
        m = self.measure(columns, info or {})
        if m is None:
            self.evaluated = False if self.evaluated is None else self.evaluated
            return
        self.evaluated = True
        t = np.asarray(columns["t"])
        bad = np.flatnonzero(m.bad)
        if bad.size:
            self.samples += int(bad.size)
            if self.first is None:
                self.first = (offset + int(bad[0]), float(t[bad[0]]))
        if m.score.size:
            k = int(np.nanargmax(m.score)) if np.isfinite(m.score).any() else 0
            if self.worst is None or m.score[k] > self.worst[0]:
                self.worst = (float(m.score[k]), float(m.value[k]), m.where(k), offset + k, float(t[k]))

    def severity(self) -> str:
        return "failure" if self.failure else "warning"

    def result(self) -> CheckResult:
        severity = self.severity()
        if not self.evaluated:
            return CheckResult(self.name, None, None, None, None, f"not evaluated: {self.reason}", severity)
        if self.worst is None:  # evaluated on chunks without a sample
            return CheckResult(self.name, True, 0, None, None, "no samples to check", severity)
        first = None if self.first is None else {"index": self.first[0], "t": self.first[1]}
        worst = {"value": self.worst[1], "unit": self.unit} if self.unit else None
        return CheckResult(self.name, self.samples == 0, self.samples, first, worst, self.message(), severity)

    def message(self) -> str:
        _, value, where, _, t = self.worst
        peak = f"{where} = {value:.4g} {self.unit} at t = {t:.4g} s"
        if not self.samples:
            return f"{self.what} within {self.bound()}: worst {peak}"
        return (f"{self.samples} sample(s) with {self.what} beyond {self.bound()}, the first at t = {self.first[1]:.4g} s "
                f"(sample {self.first[0]}); worst {peak}")


def _columns(columns: Mapping, names: list[str]) -> np.ndarray | None:
    """The named columns side by side (n, k), or None if one is missing."""
    if not all(name in columns for name in names):
        return None
    return np.column_stack([np.asarray(columns[name], dtype=float) for name in names])


def _per_joint(values: np.ndarray, label: str) -> tuple[np.ndarray, Callable[[int], str]]:
    """Per sample the largest of ``values`` (n, 6) and a namer of its joint (``label`` + number)."""
    j = np.argmax(values, axis=1)
    return values[np.arange(values.shape[0]), j], lambda k: f"{label}{j[k] + 1}"


def _over(x: np.ndarray, bound: float) -> np.ndarray:
    return x > bound * (1 + LIMIT_RTOL)  # the distribution's own tolerance: its solutions sit on the bound


def _missing(check: Check, what: str) -> None:
    check.reason = what
    return None


class JointLimit(Check):
    """abs(a per-joint quantity: the product of the columns ``PREFIX1..PREFIX6`` of ``prefixes``) against a limit
    of the model (``Limits.<field>``, ``key`` in the parameter file); a model without the limit is not checked."""

    prefixes: tuple[str, ...] = ()
    label = ""  # names the joint in messages, followed by its number
    field = ""
    key = ""

    def limit(self) -> float | None:
        """The model's limit; None where it sets none (an optional key left out is infinite: unbounded)."""
        value = getattr(self.ctx.limits, self.field)
        return value if np.isfinite(value) else None

    def bound(self):
        return f"the limit of {self.limit():g} {self.unit} ({self.key})"

    def measure(self, columns, info):
        if self.limit() is None:
            return _missing(self, f"the model sets no limit ({self.key})")
        parts = [_columns(columns, [f"{p}{i}" for i in range(1, 7)]) for p in self.prefixes]
        if any(part is None for part in parts):
            return _missing(self, "the run has no " + " and ".join(f"{p}1..{p}6" for p in self.prefixes)
                            + (" (no inverse dynamics)" if "tau" in self.prefixes else ""))
        peak, where = _per_joint(np.abs(np.prod(parts, axis=0)), self.label)
        return Measure(peak, _over(peak, self.limit()), peak, where)


class TorqueLimit(JointLimit):
    name, unit, what = "torque-limit", "N*m", "abs(tau_i)"
    prefixes, label, field, key = ("tau",), "tau", "torque", "limits.torque_Nm"


class PowerLimit(JointLimit):
    name, unit, what = "power-limit", "W", "abs(tau_i theta_dot_i)"
    prefixes, label, field, key = ("tau", "dtheta"), "power of actuator ", "power", "limits.power_W"


class MotionLimit(JointLimit):
    """A limit on the cranks' motion: a failure of a planned motion, a warning of a simulated one."""

    def severity(self):
        return "failure" if self.ctx.planned else "warning"


class SpeedLimit(MotionLimit):
    name, unit, what = "speed-limit", "rad/s", "abs(theta_dot_i)"
    prefixes, label, field, key = ("dtheta",), "dtheta", "speed", "limits.speed_rad_per_s"


class AccelerationLimit(MotionLimit):
    name, unit, what = "acceleration-limit", "rad/s^2", "abs(theta_ddot_i)"
    prefixes, label, field, key = ("ddtheta",), "ddtheta", "acceleration", "limits.acceleration_rad_per_s2"


class BearingLoad(Check):
    name, unit, what = "bearing-load", "N", "the load at a crank bearing G_i"

    def bound(self):
        lim = self.ctx.limits
        return f"the limits of {lim.axial_load:g} N axial (limits.axial_load_N) and {lim.radial_load:g} N radial (limits.radial_load_N)"

    def measure(self, columns, info):
        axial = _columns(columns, [f"FG{i}_axial" for i in range(1, 7)])
        radial = _columns(columns, [f"FG{i}_radial" for i in range(1, 7)])
        if axial is None or radial is None:
            return _missing(self, "the formulation gives no bearing forces (newton-euler does)")
        lim = self.ctx.limits
        load = np.concatenate([np.abs(axial), radial], axis=1)  # (n, 12)
        use = load / np.repeat([lim.axial_load, lim.radial_load], 6)  # share of each load's limit
        j = np.argmax(use, axis=1)
        rows = np.arange(load.shape[0])
        bad = use[rows, j] > 1 + LIMIT_RTOL
        return Measure(use[rows, j], bad, load[rows, j],
                       lambda k: f"{'axial' if j[k] < 6 else 'radial'} load at G{j[k] % 6 + 1}")


class CrankRange(Check):
    name, unit, what = "crank-range", "deg", "theta_i"

    def bound(self):
        lo, hi = np.degrees(self.ctx.limits.theta_range)
        return f"the range [{lo:g}, {hi:g}] deg (limits.theta_range_deg)"

    def measure(self, columns, info):
        if not np.isfinite(self.ctx.limits.theta_range).any():
            return _missing(self, "the model sets no crank range (limits.theta_range_deg)")
        theta = _columns(columns, [f"theta{i}" for i in range(1, 7)])
        if theta is None:
            return _missing(self, "the run has no crank angles theta1..theta6")
        lo, hi = self.ctx.limits.theta_range
        beyond = np.maximum(lo - theta, theta - hi)  # rad outside the range; negative inside
        j = np.argmax(beyond, axis=1)
        rows = np.arange(theta.shape[0])
        bad = beyond[rows, j] > 1e-12  # rad: rounding of theta, not a motion
        return Measure(beyond[rows, j], bad, np.degrees(theta[rows, j]), lambda k: f"theta{j[k] + 1}")


class DistributionInfeasible(Check):
    name, unit, what = "distribution-infeasible", "", ""

    def __init__(self, ctx):
        super().__init__(ctx)
        self.first_limits = ""

    def measure(self, columns, info):
        if not self.ctx.has_hkp or "infeasible" not in info:
            return _missing(self, "no redundant torques were distributed (newton-euler on the target distributes them, "
                            "the other formulations under --contact unilateral)"
                            if self.ctx.has_hkp else "the 6RSS has no redundant actuation to distribute")
        n = len(columns["t"])
        bad = np.zeros(n, dtype=bool)
        for entry in info["infeasible"]:
            k = int(entry["sample"] if isinstance(entry, Mapping) else entry)
            bad[k] = True
            if not self.first_limits and isinstance(entry, Mapping):
                self.first_limits = f"{', '.join(entry.get('limits', []))}; solver: {entry.get('solver', '?')}"
        return Measure(bad.astype(float), bad, np.full(n, np.nan), lambda k: "")

    def _constraints(self) -> str:
        bounds = f" and N_L, N_R >= {self.ctx.preload:g} N (unilateral contact)" if self.ctx.contact == "unilateral" else ""
        return f" (within the actuator limits where the formulation has them{bounds})"

    def message(self):
        if not self.samples:
            return f"the distribution found admissible torques at every sample{self._constraints()}"
        return (f"{self.samples} sample(s) without admissible torques{self._constraints()}, the first at t = {self.first[1]:.4g} s "
                f"(sample {self.first[0]}: {self.first_limits})")


class ContactPull(Check):
    name, unit, what = "contact-pull", "N", "the normal force of a plane on its condyle"

    def severity(self):
        return "failure" if self.ctx.contact == "unilateral" else "warning"

    def lowest(self) -> float:
        """The smallest admissible normal force: the preload under the unilateral contact model, else 0."""
        return self.ctx.preload if self.ctx.contact == "unilateral" else 0.0

    def bound(self):
        return (f"{self.lowest():g} N (contact.preload_N: the plane can only push, unilateral contact)" if self.ctx.contact == "unilateral"
                else "0 (reported only: under the bilateral contact model the plane may hold the condyle)")

    def measure(self, columns, info):
        if not self.ctx.has_hkp:
            return _missing(self, "the 6RSS has no HKP contacts")
        N = _columns(columns, ["N_L", "N_R"])
        if N is None:
            return _missing(self, "the run has no normal forces N_L, N_R")
        j = np.argmin(N, axis=1)
        low = N[np.arange(N.shape[0]), j]
        return Measure(-low, low < self.lowest() - PULL_TOLERANCE_N, low, lambda k: "N_" + "LR"[j[k]])

    def message(self):
        _, value, where, _, t = self.worst
        below = "N < 0" if not self.lowest() else f"N < the preload {self.lowest():g} N"
        if not self.samples:
            return (f"both planes push their condyles at every sample{f' with at least {self.lowest():g} N' if self.lowest() else ''}: "
                    f"smallest {where} = {value:.4g} N at t = {t:.4g} s")
        return (f"{self.samples} sample(s) where a plane pulls its condyle ({below}), the first at t = {self.first[1]:.4g} s "
                f"(sample {self.first[0]}); most negative {where} = {value:.4g} N at t = {t:.4g} s"
                + ("" if self.ctx.contact == "unilateral" else "; bilateral contact model: reported, not a failure"))


class NearSingular(Check):
    """Two measures: the smallest transmission angle (reported as the worst value) and kappa of the chains'
    Jacobian (in the message)."""

    name, unit, what = "near-singular", "deg", "the transmission angle"
    failure = False

    def __init__(self, ctx):
        super().__init__(ctx)
        self.kappa = Kappa(ctx)

    def measure(self, columns, info):
        mu = _columns(columns, [f"mu{i}" for i in range(1, 7)])
        if mu is None or "kappa_J" not in columns:
            return _missing(self, "the run has no transmission angles mu1..mu6 and kappa_J")
        deg = np.degrees(mu)
        j = np.argmin(deg, axis=1)
        low = deg[np.arange(deg.shape[0]), j]
        bad = (low < NEAR_SINGULAR_DEG) | (np.asarray(columns["kappa_J"]) < KAPPA_MIN)
        return Measure(-low, bad, low, lambda k: f"mu{j[k] + 1}")

    def update(self, offset, columns, info=None):
        super().update(offset, columns, info)
        if self.evaluated:
            self.kappa.update(offset, columns, info)

    def message(self):
        _, value, where, _, t = self.worst
        _, kappa, _, _, t_kappa = self.kappa.worst
        both = (f"smallest transmission angle {where} = {value:.4g} deg at t = {t:.4g} s (threshold {NEAR_SINGULAR_DEG:g} deg), "
                f"smallest kappa of the chains' Jacobian {kappa:.3g} at t = {t_kappa:.4g} s (threshold {KAPPA_MIN:g})")
        if not self.samples:
            return f"no near-singular sample: {both}"
        return f"{self.samples} near-singular sample(s), the first at t = {self.first[1]:.4g} s (sample {self.first[0]}); {both}"


class Kappa(Check):
    """kappa_J alone: the second measure of :class:`NearSingular` (not a check of its own)."""

    def measure(self, columns, info):
        kappa = np.asarray(columns["kappa_J"], dtype=float)
        return Measure(-kappa, kappa < KAPPA_MIN, kappa, lambda k: "kappa_J")


class BiteForce(Check):
    name, unit, what = "bite-force", "N", "abs(F_B)"
    failure = False

    def bound(self):
        return f"the plausible bound of {BITE_FORCE_BOUND_N:g} N (the largest human molar bite forces)"

    def measure(self, columns, info):
        F = _columns(columns, ["Fx", "Fy", "Fz"])
        if F is None:
            return _missing(self, "the run has no bite force columns")
        size = np.linalg.norm(F, axis=1)
        return Measure(size, size > BITE_FORCE_BOUND_N, size, lambda k: "abs(F_B)")


CHECKS = (TorqueLimit, PowerLimit, BearingLoad, CrankRange, SpeedLimit, AccelerationLimit, DistributionInfeasible, ContactPull, NearSingular, BiteForce)


class RunChecks:
    """All the checks of a run, updated chunk by chunk: ``update(offset, columns, info)`` then ``results()``."""

    def __init__(self, limits: Limits, has_hkp: bool, contact: str = "bilateral", preload: float = 0.0, planned: bool = True):
        ctx = CheckContext(limits, has_hkp, contact, preload, planned)
        self.checks = [cls(ctx) for cls in CHECKS]

    @classmethod
    def for_model(cls, model: Model, contact: str = "bilateral", planned: bool = True) -> RunChecks:
        return cls(model.limits, model.has_hkp, contact, model.contact.preload, planned)

    def update(self, offset: int, columns: Mapping, info: Mapping | None = None) -> None:
        """Add the chunk starting at sample ``offset``: ``columns`` by name (with ``t``), ``info`` the formulation's."""
        for check in self.checks:
            check.update(offset, columns, info)

    def results(self) -> list[CheckResult]:
        return [check.result() for check in self.checks]


def run_checks(model: Model, columns: Mapping, info: Mapping | None = None, contact: str = "bilateral",
               planned: bool = True) -> list[CheckResult]:
    """Every check on a whole run at once: one chunk (``planned`` False: a simulated plant's motion)."""
    checks = RunChecks.for_model(model, contact, planned)
    checks.update(0, columns, info)
    return checks.results()


def run_fails(results: list[CheckResult]) -> bool:
    """True if any result makes the run fail (exit code 4)."""
    return any(r.fails_run for r in results)


def results_from_json(entries: list[dict]) -> list[CheckResult]:
    """The check results of a run.json's ``"checks"``."""
    return [CheckResult(**{k: e.get(k) for k in CheckResult.__dataclass_fields__}) for e in entries]


__all__ = ["BITE_FORCE_BOUND_N", "CHECKS", "CONTACT_MODELS", "KAPPA_MIN", "NEAR_SINGULAR_DEG", "PULL_TOLERANCE_N",
           "Check", "CheckContext", "CheckResult", "Measure", "RunChecks", "run_checks", "run_fails", "results_from_json"]
