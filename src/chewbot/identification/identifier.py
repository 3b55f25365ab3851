"""Friction and inertia of a model from a robot log: the whole identification (docs/identification.md).

:func:`identify` takes a model and a :class:`~chewbot.identification.log.RobotLog`, recovers the mandible's motion
(:mod:`~chewbot.identification.motion`), fits the parameters (:mod:`~chewbot.identification.estimate`) and returns
an :class:`Identification`: estimates with standard errors, what could not be identified, the residuals before and
after, and the model file's new values.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from chewbot.errors import ChewbotError
from chewbot.identification import MAX_RELATIVE_SE, RCOND
from chewbot.identification.estimate import Fit, ReducedProblem, fit
from chewbot.identification.log import RobotLog
from chewbot.identification.motion import LogMotion, log_motion
from chewbot.identification.parameters import (CRANKS, DRIVE, GROUPS, HKP, INDEX, INERTIA, N_X, PARAMETERS, group_entries,
                                               x_of)
from chewbot.model import Model
from chewbot.progress import SILENT, Progress
from chewbot.task import smoothing
from chewbot.units import factor

# Reference magnitudes of the friction parameters where the start model has 0 (the built-in models' values).
TYPICAL_FRICTION = {"mu_H": 0.1, "c_H": 0.5, "R*mu_c": 2.5e-4, "c_A": 0.01}
STEPS = 4  # progress: motion, start, least squares, results


@dataclass
class Identification:
    """The result of :func:`identify`; arrays over the parameters of
    :data:`chewbot.identification.parameters.PARAMETERS` (SI).

    ``x0``, ``x``: start and estimate; ``se``: standard errors (0 where not estimated); ``status`` per parameter:
    ``estimated`` (``(at its bound)`` added where a bound holds it), ``held`` (not identifiable from the log: kept at
    the start; the reason in ``fit.reasons``), ``fixed`` (by ``--fix``), ``given`` (the model file's value, as the
    parameter's ``given`` says, unless ``--free``), ``not in the model`` (the 6RSS has no HKP; a model without a
    drive has no torque constant or efficiency), ``not in the log`` (the drive's numbers from a log of torques) or
    ``no arm`` (R = 0 in the file: R mu_c cannot be written back);
    ``held_directions``: the non-identifiable combinations, each {parameter name: coefficient in file units};
    ``identified``: the parameter-file keys that were estimated.
    """

    model: Model
    log: RobotLog
    motion: LogMotion
    fit: Fit
    x0: np.ndarray
    x: np.ndarray
    se: np.ndarray
    status: list[str]
    held_directions: list[dict[str, float]]
    identified: list[str]
    notes: list[str] = field(default_factory=list)

    def rms(self, which: str = "estimate") -> np.ndarray:
        """RMS of the torque residual per actuator (N*m) over the samples in the fit, at the start or the estimate."""
        r = (self.fit.start if which == "start" else self.fit.evaluation).r[self.fit.used]
        return np.sqrt(np.mean(r**2, axis=0))

    def rows(self) -> list[dict]:
        """The table of estimates in the file's units (one dict per parameter, keys of
        :data:`chewbot.identification.output.TABLE_COLUMNS`), with the derived actuator Coulomb coefficient."""
        def se(j, convert):  # empty where the parameter was not estimated
            return _g(convert(self.se[j])) if self.status[j].startswith("estimated") else ""

        rows = []
        for j, p in enumerate(PARAMETERS):
            rows.append({"parameter": p.name, "key": p.key, "unit": p.file_unit, "start": _g(p.in_file_units(self.x0[j])),
                         "estimate": _g(p.in_file_units(self.x[j])), "standard_error": se(j, p.in_file_units),
                         "status": self.status[j]})
        arm = self.model.friction.actuator_arm
        if arm > 0:
            j = NAMES_INDEX["R*mu_c"]
            rows.append({"parameter": "mu_c", "key": "friction.actuator_coulomb", "unit": "1",
                         "start": _g(self.x0[j] / arm), "estimate": _g(self.x[j] / arm), "standard_error": se(j, lambda v: v / arm),
                         "status": f"R*mu_c / R, R = {arm / factor('mm'):g} mm as in the file"})
        return rows

    def values(self) -> dict[str, object]:
        """The parameter-file keys of the estimated groups with their new values (file units)."""
        out: dict[str, object] = {}
        x = self.x
        for key in self.identified:
            if key == "mandible.mass_g":
                out[key] = float(PARAMETERS[0].in_file_units(x[0]))
            elif key == "mandible.inertia_g_mm2":
                xx, yy, zz, xy, xz, yz = (float(p.in_file_units(v)) for p, v in zip(PARAMETERS[INERTIA], x[INERTIA]))
                out[key] = [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
            elif key == "cranks.inertia_g_mm2":
                out[key] = [float(p.in_file_units(v)) for p, v in zip(PARAMETERS[CRANKS], x[CRANKS])]
            elif key == "friction.actuator_coulomb":
                out[key] = float(x[NAMES_INDEX["R*mu_c"]] / self.model.friction.actuator_arm)
            else:
                j = next(j for j, p in enumerate(PARAMETERS) if p.group == key)
                out[key] = float(PARAMETERS[j].in_file_units(x[j]))
        return out

    def uncertainty(self) -> dict[str, object]:
        """The model file's ``[uncertainty]`` section (file units): the estimated parameters' keys, standard errors
        and correlations, and the torque error the estimate leaves (:func:`torque_error`), its standard deviation
        per actuator and correlations. Empty where nothing was estimated."""
        est = [j for j in range(N_X) if self.status[j].startswith("estimated")]
        if not est:
            return {}
        arm = self.model.friction.actuator_arm
        scale = np.array([1 / arm if PARAMETERS[j].name == "R*mu_c" else PARAMETERS[j].in_file_units(1.0) for j in est])
        keys = ["friction.actuator_coulomb" if PARAMETERS[j].name == "R*mu_c" else PARAMETERS[j].key for j in est]
        cov = self.fit.cov[np.ix_(est, est)] * scale[:, None] * scale
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
        torque = torque_error(self.fit)
        tsd = np.sqrt(np.maximum(np.diag(torque), 0.0))
        return {"keys": keys, "standard_error": sd.tolist(), "correlation": _correlation(cov, sd).tolist(),
                "torque_error_Nm": tsd.tolist(), "torque_error_correlation": _correlation(torque, tsd).tolist()}

    def summary(self) -> list[str]:
        """Lines of the summary: log, motion, condition number, residuals, held combinations."""
        f, m = self.fit, self.motion
        smoothing_line = ("rates: " + ", ".join(f"{k} from the log" if v == "logged" else f"{k} by Savitzky-Golay "
                          f"(degree {smoothing.POLYORDER}, {m.window_samples} samples)" for k, v in m.rates.items()))
        lines = [f"log {self.log.source}: {self.log.n} samples, {self.log.t[-1] - self.log.t[0]:.4g} s; bite force "
                 f"{'logged' if self.log.force_given else 'not logged (zero)'}",
                 f"samples in the fit: {int(self.fit.used.sum())} (every crank turning faster than {m.min_speed:.3g} rad/s)",
                 f"poses from the crank angles: RMS angle residual {np.sqrt(np.mean(m.angle_residual**2)):.3g} rad; " + smoothing_line,
                 f"condition number of the Jacobian (unit-norm columns, the {int(f.free.sum())} free parameters): "
                 f"{f.condition_start:.4g} at the start, {f.condition:.4g} at the estimate",
                 "RMS torque residual tau1..6 [N*m]: start " + " ".join(f"{v:.4g}" for v in self.rms("start"))
                 + "; estimate " + " ".join(f"{v:.4g}" for v in self.rms()),
                 f"least squares: {f.evaluations} evaluations of the residual in all; the last solve: {f.solver.message if f.solver else 'nothing left to estimate'}"]
        for j, p in enumerate(PARAMETERS):
            if self.status[j].startswith("estimated") and (j not in range(N_X)[INERTIA] or j == INERTIA.start):
                what = p.combination if j not in range(N_X)[INERTIA] else p.combination + " (the six entries in the table)"
                lines.append(f"identified: {p.name} = {p.in_file_units(self.x[j]):.6g} +/- {p.in_file_units(self.se[j]):.3g} "
                             f"{p.file_unit} (standard error): {what}")
            elif self.status[j] == "given":
                lines.append(f"given, not estimated: {p.name} = {p.in_file_units(self.x[j]):.6g} {p.file_unit} ({p.given}; "
                             f"--free {p.group} estimates it)")
        for d in self.held_directions:
            lines.append("the torques do not change along: " + " ".join(f"{c:+.4g} {name}" for name, c in d.items())
                         + " (file units)")
        for j, reason in sorted(f.reasons.items()):
            lines.append(f"not identifiable from this log, held at the start: {PARAMETERS[j].name} ({reason})")
        return lines + [f"note: {n}" for n in self.notes]


NAMES_INDEX = INDEX


def _correlation(cov: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """The correlation matrix of ``cov`` with standard deviations ``sd`` (0 where a standard deviation is 0, 1 on
    the diagonal)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        R = np.where(np.outer(sd, sd) > 0, cov / np.outer(sd, sd), 0.0)
    R = np.clip((R + R.T) / 2, -1.0, 1.0)
    np.fill_diagonal(R, 1.0)
    return R


def torque_error(fit: Fit) -> np.ndarray:
    """(6, 6) N^2 m^2: the covariance of the torque error the model leaves, from the residuals at the estimate over
    the samples in the fit: their second moment, times 6 / (6 - nN) for the nN directions per sample that the
    samples' own normal forces absorb (2 on the target: a residual has 4 degrees of freedom of 6), and times
    n / (n - k) for the k parameters fitted to the n residual rows."""
    r = fit.evaluation.r[fit.used]
    n, k = r.shape[0], int(np.sum(fit.free & ~fit.held))
    rows = 6 - fit.evaluation.N.shape[1]
    scale = 6 / rows * (rows * n) / max(rows * n - k, 1)
    return scale * (r.T @ r) / max(n, 1)


def _g(value: float) -> float:
    return float(f"{value:.6g}")


def references(model: Model, x0: np.ndarray) -> np.ndarray:
    """Reference magnitudes of the parameters (SI): the start value for the mass and friction (the built-in
    models' where the start is 0), a third of the inertia's trace for every inertia entry (off-diagonal entries
    are judged against the body's size, not their own near-zero values)."""
    ref = np.abs(x0).astype(float)
    ref[INERTIA] = np.trace(model.mandible_inertia) / 3
    ref[CRANKS] = np.abs(x0[CRANKS])
    for j, p in enumerate(PARAMETERS):
        if ref[j] == 0 and p.name in TYPICAL_FRICTION:
            ref[j] = TYPICAL_FRICTION[p.name]
    return ref


def default_status(model: Model, fix: tuple[str, ...] = (), free: tuple[str, ...] = (), currents: bool = False) -> list[str]:
    """The status of each parameter before the fit: "" (to estimate), ``fixed`` (a key of ``fix``), ``given`` (the
    file's value by default, unless its key is in ``free``), ``not in the model`` (the 6RSS has no HKP, a model
    without a drive no torque constant or efficiency), ``not in the log`` (the drive's numbers, unless ``currents``:
    the torques are read from the log's currents through the model's drive) or ``no arm`` (R = 0 in the file: R mu_c
    cannot be written back)."""
    status = ["" for _ in PARAMETERS]
    for j, p in enumerate(PARAMETERS):
        if p.drive and model.drive is None:
            status[j] = "not in the model"
        elif p.drive and not currents:
            status[j] = "not in the log"
        elif p.group in fix:
            status[j] = "fixed"
        elif p.given and p.group not in free:
            status[j] = "given"
        elif j in HKP and not model.has_hkp:
            status[j] = "not in the model"
    if model.friction.actuator_arm == 0 and "friction.actuator_coulomb" not in fix:
        status[NAMES_INDEX["R*mu_c"]] = "no arm"
    return status


def estimated_by_default(model: Model) -> np.ndarray:
    """(N_X,) True for the parameters ``chewbot identify`` estimates from a log of torques without --fix or --free
    (what an excitation is designed for: the drive's numbers from currents come on top)."""
    return np.array([s == "" for s in default_status(model)])


def identify(model: Model, log: RobotLog, side: str = "left", window_s: float = smoothing.WINDOW_S,
             fix: tuple[str, ...] = (), rcond: float = RCOND, max_relative_se: float = MAX_RELATIVE_SE,
             progress: Progress = SILENT, check=None, free: tuple[str, ...] = ()) -> Identification:
    """Estimate the friction, the crank inertias and the mandible's inertia of ``model`` from ``log`` (see the
    module docstring), and where the log gives currents and the model has a drive, its torque constant and efficiency
    (the cranks' torques of the currents through the drive with the two estimated).

    ``fix``: parameter-file keys (:data:`chewbot.identification.parameters.GROUPS`) kept at the model's values;
    ``free``: keys of the parameters given by the file by default (the weighed mass) to estimate too;
    ``window_s``: the smoothing window of the rates; ``rcond``, ``max_relative_se``: the identifiability
    thresholds (:mod:`chewbot.identification.estimate`); ``progress(message, stage=None)`` is told each stage (the
    least squares as the stage ``fit``); ``check()`` is called at each evaluation of the residual and raises to stop.
    """
    for key in fix:
        if key not in GROUPS:
            raise ChewbotError(f"--fix {key}: not an identified key; choose among {', '.join(GROUPS)}")
    givens = [g for g in GROUPS if any(PARAMETERS[j].given for j in group_entries(g))]
    for key in free:
        if key not in givens:
            raise ChewbotError(f"--free {key}: not a key the model file gives (only {', '.join(givens)} is held at the "
                               "file's value by default; the others are estimated unless --fix)")
        if key in fix:
            raise ChewbotError(f"--free {key} and --fix {key}: choose one")
    progress("motion from the crank angles")
    motion = log_motion(model, log, side, window_s)
    x0 = x_of(model)
    currents = model.drive is not None and log.reads(model) == "currents"
    status = default_status(model, fix, free, currents)
    notes = []
    if status[NAMES_INDEX["R*mu_c"]] == "no arm":
        notes.append("friction.actuator_arm_mm is 0: the actuators' Coulomb friction R mu_c cannot be written back as "
                     "mu_c; it is not estimated")
    if currents:
        notes.append(f"the cranks' torques are the log's currents through the model's drive (gear ratio "
                     f"{model.drive.gear_ratio:g} given; its torque constant and efficiency estimated unless --fix): the "
                     "currents' scale is fixed by gravity on the given mandible mass, the efficiency by the samples "
                     "where the cranks back-drive their motors")
    free = np.array([s == "" for s in status])
    used = motion.moving()
    if used.sum() < 10 * free.sum():
        raise ChewbotError(f"{log.source}: only {int(used.sum())} of {log.n} samples have every crank turning (faster than "
                           f"{motion.min_speed:.3g} rad/s): too "
                           "little motion to identify friction; log a longer or livelier motion")
    dtheta = motion.kin.dtheta
    if currents and any(status[j] == "" for j in DRIVE):
        measured = lambda x: log.current_torques(model, dtheta, x[DRIVE[0]], x[DRIVE[1]])  # noqa: E731
    else:  # the drive's numbers, if any, at the model's
        measured = log.crank_torques(model, dtheta)
    problem = ReducedProblem(model, motion.kin, measured, used, check)
    progress("the start model")
    result = fit(problem, x0, free, references(model, x0), motion.window_samples, rcond, max_relative_se, progress)
    progress("results")
    for j in np.flatnonzero(free):
        status[j] = "held" if result.held[j] else "estimated"
    for j in np.flatnonzero(result.at_bound):
        status[j] += " (at its bound)"
    held_directions = [{PARAMETERS[j].name: float(PARAMETERS[j].in_file_units(c)) for j, c in enumerate(d)
                        if abs(c) > 1e-3 * result.ref[j]} for d in result.null]
    identified = [g for g in GROUPS if any(status[j].startswith("estimated") for j, p in enumerate(PARAMETERS)
                                           if p.group == g)]
    se = np.sqrt(np.maximum(np.diag(result.cov), 0.0))
    return Identification(model, log, motion, result, x0, result.x, se, status, held_directions, identified, notes)
