"""The numbers a person checks first: derived quantities of a model, and the summary of a run.

Shared by ``chewbot check-model``, the end of ``chewbot run`` and the HTML report, so that the terminal and
the report always agree. Everything here reads what a run contains (columns of the results table, entries of
``Dynamics.info``) and leaves out what a stage that did not run would have produced.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from chewbot.analysis.checks import NEAR_SINGULAR_DEG
from chewbot.kinematics.ik import inverse_kinematics, transmission
from chewbot.model import Model
from chewbot.results import Table

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


def crank_tips(model: Model, theta: np.ndarray) -> np.ndarray:
    """S_i = G_i + R_C0,i Rz(theta_i) [L_c,i, 0, 0] in {S}, (N, 6, 3) m, from theta (N, 6) rad."""
    u, v = model.R_C0[:, :, 0], model.R_C0[:, :, 1]
    arm = np.cos(theta)[..., None] * u + np.sin(theta)[..., None] * v
    return model.G + model.crank_length[:, None] * arm


def home_pose(model: Model) -> dict[str, np.ndarray]:
    """The home (occlusal) pose, {M} = {S}: theta (6,) rad, the sin of each transmission angle (6,), the
    transmission angles mu (6,) in deg and kappa of the chains' Jacobian (chewbot.kinematics.conditioning).

    Raises :class:`~chewbot.errors.KinematicsError` when a chain cannot reach it.
    """
    from chewbot.kinematics.conditioning import jacobian_conditioning

    p, R = np.zeros((1, 3)), np.eye(3)[None]
    theta = inverse_kinematics(model, p, R)
    sin_mu = transmission(model, p, R)[0]
    return {"theta": theta[0], "transmission": sin_mu, "mu_deg": np.degrees(np.arcsin(np.clip(sin_mu, 0.0, 1.0))),
            "kappa": float(jacobian_conditioning(model, np.zeros((1, model.dof)))[0])}


def assumed_values(model: Model) -> dict[str, object]:
    """The values of the keys the parameter file lists as assumed, as written in the file (papers' units).

    A model not read from a file (built from a dict) gives the keys with ``None``.
    """
    raw: dict = {}
    if Path(model.source).is_file():
        raw = tomllib.loads(Path(model.source).read_text("utf-8"))
    out = {}
    for key in model.assumed:
        value: object = raw
        for part in key.split("."):
            value = value.get(part) if isinstance(value, dict) else None
        out[key] = value
    return out


@dataclass(frozen=True)
class ColumnStats:
    """Peak (largest absolute value, with its sign and time) and RMS of one column along the task."""

    name: str
    unit: str
    peak: float
    t_peak: float
    rms: float
    mean: float


def column_stats(table: Table, names: list[str]) -> list[ColumnStats]:
    """Peak, time of the peak, RMS and mean of each named column of ``table`` (in the column's unit)."""
    t = table["t"]
    out = []
    for name in names:
        y = table[name]
        k = int(np.argmax(np.abs(y)))
        out.append(ColumnStats(name, table.units[name], float(y[k]), float(t[k]), float(np.sqrt(np.mean(y**2))), float(np.mean(y))))
    return out


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


def near_singular(t: np.ndarray, sin_transmission: np.ndarray, threshold_deg: float = NEAR_SINGULAR_DEG) -> list[Interval]:
    """Runs of samples where a chain's transmission angle is below ``threshold_deg``, chain by chain."""
    angle = np.degrees(np.arcsin(np.clip(sin_transmission, 0.0, 1.0)))
    out = []
    for k in range(angle.shape[1]):
        low = np.flatnonzero(angle[:, k] < threshold_deg)
        for run in np.split(low, np.flatnonzero(np.diff(low) > 1) + 1) if low.size else []:
            j = run[np.argmin(angle[run, k])]
            out.append(Interval(k + 1, int(run[0]), int(run[-1]), float(t[run[0]]), float(t[run[-1]]), float(angle[j, k]), float(t[j])))
    return out


def performance_indices(info: dict) -> dict[str, float]:
    """The indices F1..F7 found anywhere in a run's dynamics info (at its top level or in a nested dict)."""
    found: dict[str, float] = {}

    def visit(d: dict) -> None:
        for key, value in d.items():
            if isinstance(value, dict):
                visit(value)
            elif re.fullmatch(r"F[1-7]", str(key)) and isinstance(value, (int, float)):
                found[str(key)] = float(value)

    visit(info)
    return dict(sorted(found.items()))


def infeasible_samples(info: dict, t: np.ndarray) -> list[dict]:
    """Samples a formulation reports as infeasible (``info["infeasible"]``), each as {sample, t, limits}.

    Entries may be sample indices or dicts with ``sample`` (and ``t``, ``limits``), as the optimal
    distribution records them.
    """
    out = []
    for item in info.get("infeasible", []):
        entry = item if isinstance(item, dict) else {"sample": item}
        k = int(entry["sample"])
        out.append({"sample": k, "t": float(entry.get("t", t[k])), "limits": list(entry.get("limits", []))})
    return out


def solver_notes(info: dict) -> dict[str, object]:
    """The plain entries (text, numbers, flags) of a formulation's info, for a key/value listing."""
    return {k: v for k, v in info.items() if isinstance(v, (str, int, float, bool))}


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


def normal_force_stats(table: Table, bound: float = 0.0) -> list[NormalForceStats]:
    """:class:`NormalForceStats` of N_L and N_R (none where the run has no normal forces: the 6RSS)."""
    from chewbot.analysis.checks import PULL_TOLERANCE_N

    if "N_L" not in table:
        return []
    t = table["t"]
    out = []
    for name in ("N_L", "N_R"):
        y = table[name]
        lo, hi = int(np.argmin(y)), int(np.argmax(y))
        out.append(NormalForceStats(name, float(y[lo]), float(t[lo]), float(y[hi]), float(t[hi]),
                                    float(100 * np.mean(y < bound - PULL_TOLERANCE_N))))
    return out


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
