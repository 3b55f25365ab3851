"""The numbers a person checks first: derived quantities of a model, and the summary of a run.

Shared by ``chewbot check-model``, the end of ``chewbot run`` and the HTML report, so that the terminal and
the report always agree. Everything here reads what a run contains (columns of the results table, entries of
``Dynamics.info``) and leaves out what a stage that did not run would have produced.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Mapping

import numpy as np

from chewbot.config import read_text
from chewbot.table import Table

if TYPE_CHECKING:
    from chewbot.model import Model

# The near-singular check's threshold (chewbot.analysis.checks.NEAR_SINGULAR_DEG, equal by a test), here without
# importing the checks and the solvers behind them: a report is drawn without them.
NEAR_SINGULAR_DEG = 10.0

# Names of the performance indices of seed 001 (Sect. 5.3), as docs/conventions.md reads them.
INDEX_NAMES = {
    "F1": "actuator torques",
    "F2": "constraint forces at S_1..S_6",
    "F3": "HKP normal forces",
    "F4": "actuator friction torques",
    "F5": "constraint moments at G_1..G_6",
    "F6": "constraint forces at G_1..G_6",
    "F7": "HKP friction forces",
}


def home_pose(model: Model) -> dict[str, np.ndarray]:
    """The home (occlusal) pose, {M} = {S}: theta (6,) rad, the sin of each transmission angle (6,), the
    transmission angles mu (6,) in deg and kappa of the chains' Jacobian (chewbot.kinematics.conditioning).

    Raises :class:`~chewbot.errors.KinematicsError` when a chain cannot reach it.
    """
    from chewbot.kinematics.conditioning import jacobian_conditioning
    from chewbot.kinematics.ik import inverse_kinematics, transmission

    p, R = np.zeros((1, 3)), np.eye(3)[None]
    theta = inverse_kinematics(model, p, R)
    sin_mu = transmission(model, p, R)[0]
    return {"theta": theta[0], "transmission": sin_mu, "mu_deg": np.degrees(np.arcsin(np.clip(sin_mu, 0.0, 1.0))),
            "kappa": float(jacobian_conditioning(model, np.zeros((1, model.dof)))[0])}


def assumed_values(model: Model, keys: tuple[str, ...] | None = None) -> dict[str, object]:
    """The values of the keys the parameter file lists as assumed (or of ``keys``: ``model.identified``), as written
    in the file (papers' units).

    A model not read from a file (built from a dict) gives the keys with ``None``.
    """
    raw: dict = {}
    if Path(model.source).is_file():
        raw = read_text(model.source, "parameter file").data
    out = {}
    for key in model.assumed if keys is None else keys:
        value: object = raw
        for part in key.split("."):
            value = value.get(part) if isinstance(value, dict) else None
        out[key] = value
    return out


@dataclass(frozen=True)
class ColumnStats:
    """Peak (largest absolute value, with its sign and time), RMS, mean, minimum and maximum (with their times) of
    one column along the task."""

    name: str
    unit: str
    peak: float
    t_peak: float
    rms: float
    mean: float
    min: float = float("nan")
    t_min: float = float("nan")
    max: float = float("nan")
    t_max: float = float("nan")


class ColumnTotals:
    """Per column, over consecutive rows given in blocks: the minimum, maximum and peak (largest magnitude) with the
    time of their first occurrence, the sum and the sum of squares. A NaN is the extreme where it occurs (as
    NumPy's argmin and argmax take it): a column with a NaN shows it."""

    def __init__(self, k: int):
        self.extreme = np.full((3, k), np.nan)  # minimum, maximum, peak
        self.when = np.full((3, k), np.nan)  # their times
        self.sum = np.zeros(k)
        self.sumsq = np.zeros(k)
        self.n = 0

    def add(self, t: np.ndarray, y: np.ndarray) -> None:
        """Rows ``y`` (m, k) at times ``t`` (m,), after those added before."""
        if not y.shape[0]:
            return
        cols = np.arange(y.shape[1])
        for row, k in enumerate((np.argmin(y, axis=0), np.argmax(y, axis=0), np.argmax(np.abs(y), axis=0))):
            v, old = y[k, cols], self.extreme[row]
            size = (v, old) if row < 2 else (np.abs(v), np.abs(old))
            better = size[0] < size[1] if row == 0 else size[0] > size[1]
            better |= (np.isnan(v) & ~np.isnan(old)) if self.n else True
            self.extreme[row, better] = v[better]
            self.when[row, better] = t[k[better]]
        self.sum += y.sum(axis=0)
        self.sumsq += (y * y).sum(axis=0)
        self.n += y.shape[0]

    def stats(self, names: list[str], units: Mapping[str, str]) -> dict[str, ColumnStats]:
        """The statistics of each column (``names`` in the order of the columns given)."""
        (low, high, peak), (t_low, t_high, t_peak) = self.extreme, self.when
        return {name: ColumnStats(name, units[name], float(peak[j]), float(t_peak[j]), float(np.sqrt(self.sumsq[j] / self.n)),
                                  float(self.sum[j] / self.n), float(low[j]), float(t_low[j]), float(high[j]), float(t_high[j]))
                for j, name in enumerate(names)}


def column_stats(table: Table, names: list[str]) -> list[ColumnStats]:
    """Peak, time of the peak, RMS, mean, minimum and maximum of each named column of ``table`` (in its unit)."""
    totals = ColumnTotals(len(names))
    totals.add(table["t"], np.column_stack([table[name] for name in names]))
    stats = totals.stats(names, table.units)
    return [stats[name] for name in names]


def numbered_columns(table: Table, prefix: str) -> list[str]:
    """Columns named ``prefix`` followed by a chain number (``tau1`` ... ``tau6``), in the table's order."""
    pattern = re.compile(re.escape(prefix) + r"[1-6]")
    return [name for name in table.columns if pattern.fullmatch(name)]


@dataclass(frozen=True)
class Interval:
    """Consecutive samples of one chain below the near-singular threshold."""

    chain: int  # 1-based
    first: int  # sample index
    last: int
    t_first: float
    t_last: float
    min_deg: float  # smallest transmission angle in the interval
    t_min: float


class NearSingularRuns:
    """The runs of consecutive samples where a chain's transmission angle is below ``threshold_deg``, found in
    consecutive blocks of rows (``update``), a run that crosses a block's end continued in the next."""

    def __init__(self, threshold_deg: float = NEAR_SINGULAR_DEG):
        self.threshold = threshold_deg
        self._closed: list[Interval] = []
        self._open: dict[int, Interval] = {}  # chain -> the run that reaches the last sample seen

    def update(self, offset: int, t: np.ndarray, angle_deg: np.ndarray) -> None:
        """Samples ``offset`` to ``offset + m - 1`` at times ``t`` (m,), each chain's transmission angle (m, 6) in deg."""
        m = angle_deg.shape[0]
        for k in range(angle_deg.shape[1]):
            low = np.flatnonzero(angle_deg[:, k] < self.threshold)
            runs = np.split(low, np.flatnonzero(np.diff(low) > 1) + 1) if low.size else []
            going = self._open.pop(k + 1, None)
            for run in runs:
                j = run[np.argmin(angle_deg[run, k])]
                here = Interval(k + 1, offset + int(run[0]), offset + int(run[-1]), float(t[run[0]]), float(t[run[-1]]),
                                float(angle_deg[j, k]), float(t[j]))
                if going is not None and run[0] == 0:  # the run that reached the previous block's end goes on
                    lower = here.min_deg < going.min_deg
                    here = Interval(going.chain, going.first, here.last, going.t_first, here.t_last,
                                    here.min_deg if lower else going.min_deg, here.t_min if lower else going.t_min)
                elif going is not None:
                    self._closed.append(going)
                going = None
                if run[-1] == m - 1:
                    self._open[k + 1] = here
                else:
                    self._closed.append(here)
            if going is not None:
                self._closed.append(going)

    def result(self) -> list[Interval]:
        """Every run, chain by chain, in time order."""
        return sorted(self._closed + list(self._open.values()), key=lambda i: (i.chain, i.first))


def near_singular(t: np.ndarray, sin_transmission: np.ndarray, threshold_deg: float = NEAR_SINGULAR_DEG) -> list[Interval]:
    """Runs of samples where a chain's transmission angle is below ``threshold_deg``, chain by chain."""
    runs = NearSingularRuns(threshold_deg)
    runs.update(0, t, np.degrees(np.arcsin(np.clip(sin_transmission, 0.0, 1.0))))
    return runs.result()


def performance_indices(info: dict) -> dict[str, float]:
    """The indices F1..F7 found anywhere in a run's dynamics info (at its top level or in a nested dict); one that
    does not apply (NaN, or null as run.json writes it) is NaN."""
    found: dict[str, float] = {}

    def visit(d: dict) -> None:
        for key, value in d.items():
            if isinstance(value, dict):
                visit(value)
            elif re.fullmatch(r"F[1-7]", str(key)) and (value is None or isinstance(value, (int, float))):
                found[str(key)] = float("nan") if value is None else float(value)

    visit(info)
    return dict(sorted(found.items()))


def infeasible_samples(info: dict, t: np.ndarray, samples: np.ndarray | None = None) -> list[dict]:
    """Samples a formulation reports as infeasible (``info["infeasible"]``), each as {sample, t, limits}.

    Entries may be sample indices or dicts with ``sample`` (and ``t``, ``limits``), as the optimal
    distribution records them. An entry without its time takes it from ``t``: the times of every sample, or of
    ``samples`` only (then NaN for the others).
    """
    out = []
    for item in info.get("infeasible", []):
        entry = item if isinstance(item, dict) else {"sample": item}
        k = int(entry["sample"])
        if "t" in entry:
            when = float(entry["t"])
        elif samples is None:
            when = float(t[k])
        else:
            pos = int(np.searchsorted(samples, k))
            when = float(t[pos]) if pos < len(samples) and samples[pos] == k else float("nan")
        out.append({"sample": k, "t": when, "limits": list(entry.get("limits", []))})
    return out


def solver_notes(info: dict) -> dict[str, object]:
    """The plain entries (text, numbers, flags) of a formulation's info, for a key/value listing; a flag in words
    (``friction: on``, not Python's ``True``)."""
    return {k: ({True: "on" if k == "friction" else "yes", False: "off" if k == "friction" else "no"}[v] if isinstance(v, bool) else v)
            for k, v in info.items() if isinstance(v, (str, int, float, bool))}


@dataclass(frozen=True)
class NormalForceStats:
    """One condyle's normal force along the task: smallest and largest (N) with their times, and the share of the
    samples below ``bound`` (0, or the preload of a unilateral contact), percent."""

    name: str
    low: float
    t_low: float
    high: float
    t_high: float
    below: float


def below_columns(columns, bound: float = 0.0) -> dict[str, tuple[np.ndarray, str]]:
    """Per normal force N_L, N_R of ``columns`` (none for the 6RSS), 100 where it is below ``bound`` (0, or the
    preload of a unilateral contact; the ``contact-pull`` check's tolerance allowed) and 0 elsewhere: their mean
    over the task is the share of the samples below, percent (:func:`normal_force_stats`)."""
    from chewbot.analysis.checks import PULL_TOLERANCE_N

    return {f"{name}_below": (100.0 * (np.asarray(columns[name]) < bound - PULL_TOLERANCE_N), "%")
            for name in ("N_L", "N_R") if name in columns}


def normal_force_stats(stats: Mapping[str, ColumnStats]) -> list[NormalForceStats]:
    """:class:`NormalForceStats` of N_L and N_R from the statistics of the whole task's columns, those of
    :func:`below_columns` among them (none where the run has no normal forces: the 6RSS)."""
    return [NormalForceStats(name, stats[name].min, stats[name].t_min, stats[name].max, stats[name].t_max,
                             stats[f"{name}_below"].mean) for name in ("N_L", "N_R") if name in stats]


def contact_note(contact: str, preload: float, info: dict) -> str:
    """The contact model of a run in words, with how the formulation obtained N (its ``info["contact"]``)."""
    c = info.get("contact", {})
    how = c.get("distribution") or c.get("normal_forces") or ""
    if contact == "unilateral":
        head = f"unilateral (a ball pressed on a plane: N >= contact.preload_N = {preload:g} N)"
        raised = c.get("raised_samples")
        if raised is not None:
            how += f"; the bound raised N at {raised} sample(s)"
    else:
        head = "bilateral (a ball held in a slot: the plane may push or pull; a pull is reported, not a failure)"
    return f"{head}{'; ' + how if how else ''}"
