"""Robot logs: crank angles and measured torques or motor currents over time, read from CSV.

One header row, then one row per sample, comma-separated; blank lines and lines starting with ``#`` are skipped
(chewbot's marker line among them). Columns (any order):

* ``t`` (strictly increasing; uniform steps where rates are estimated);
* ``theta1`` .. ``theta6``, the crank angles, and optionally their rates ``dtheta1..6`` and ``ddtheta1..6``
  (all six of a kind or none);
* ``tau1`` .. ``tau6``, the measured actuator torques at the cranks, or ``i1`` .. ``i6``, the motors' currents, or
  both (all six of a kind or none): :meth:`RobotLog.crank_torques` gives the cranks' torques for a model, from the
  currents through the model's drive (``[drive]``: torque constant, gear ratio, the gearbox's loss law at the crank
  rates) where the model has one and the log has currents (what a real robot measures), else the logged torques;
* optionally the bite force ``Fx, Fy, Fz`` on the mandible in {S} at the molar of ``--side`` (each one absent
  is zero).

Values are SI (s, rad, N*m, N) unless the name carries a unit in brackets, as in task files: ``theta1[deg]``,
``dtheta1[deg/s]``, ``tau1[N*mm]``, ``i1[mA]``, ``t[ms]``, ``Fz[kN]``. Errors are :class:`~chewbot.errors.TaskError`
naming the file and the line (1-based, as an editor shows it) and the column. The results.csv of a chewbot run or
simulation is a log too: the other columns that its run.json lists are skipped.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from chewbot.errors import TaskError
from chewbot.model import Drive
from chewbot.model import drive as drive_law
from chewbot.task.csvio import FORCES, columns_beside, read_signals

ANGLES = tuple(f"theta{i}" for i in range(1, 7))
TORQUES = tuple(f"tau{i}" for i in range(1, 7))
CURRENTS = tuple(f"i{i}" for i in range(1, 7))
COLUMNS = {"t": ("time", 0), **{f: ("force", 0) for f in FORCES}, **{c: ("torque", 0) for c in TORQUES},
           **{c: ("current", 0) for c in CURRENTS},
           **{prefix + c: ("angle", order) for c in ANGLES for order, prefix in enumerate(("", "d", "dd"))}}


@dataclass(frozen=True, eq=False)
class RobotLog:
    """A log of the robot (arrays samples first, SI).

    ``t`` (N,) s; ``theta`` (N, 6) rad; ``dtheta``, ``ddtheta`` (N, 6) or None where the file does not give them;
    ``tau`` (N, 6) N*m measured at the cranks, ``current`` (N, 6) A the motors' (either may be None, not both); ``force`` (N, 3) N, the bite force on the mandible in {S} (zero where not
    measured); ``lines``: each sample's line in the file.
    """

    source: str
    t: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray | None
    ddtheta: np.ndarray | None
    tau: np.ndarray
    force: np.ndarray
    lines: np.ndarray
    force_given: bool = False
    current: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.t.shape[0]

    def crank_torques(self, model, dtheta: np.ndarray) -> np.ndarray:
        """The cranks' torques (N, 6) N*m for ``model`` at the crank rates ``dtheta`` (N, 6) rad/s: from the currents
        through the model's drive where it has one and the log gives them, else the logged torques; a TaskError where
        the log has currents only and the model no drive to read them with."""
        if self.current is not None and (model.drive is not None or self.tau is None):
            if model.drive is None:
                raise TaskError(f"{self.source}: the log gives motor currents (i1..i6) and no torques, but the model "
                                f"{model.name} has no drive ([drive], docs/models.md) to turn them into crank torques")
            d = model.drive
            return drive_law.crank_torque(d, drive_law.torque_of_current(d, self.current), np.asarray(dtheta, float))
        return self.tau

    def current_torques(self, model, dtheta: np.ndarray, torque_constant: float, efficiency: float):
        """The cranks' torques (N, 6) N*m of the logged currents through ``model``'s drive with its torque constant
        and efficiency replaced by ``torque_constant`` (N m/A) and ``efficiency``, at the crank rates ``dtheta`` (N, 6)
        rad/s, and their exact derivatives with respect to the two, (N, 6, 2) (the loss law differentiated by CasADi)."""
        n = self.current.size
        out = _current_torque_function().map(n)(self.current.ravel(), np.asarray(dtheta, float).ravel(),
                                                model.drive.gear_ratio, torque_constant, efficiency)
        tau, d = (np.asarray(o) for o in out)
        return tau.reshape(self.current.shape), d.T.reshape(*self.current.shape, 2)

    def reads(self, model) -> str:
        """What :meth:`crank_torques` reads for ``model``: ``"currents"`` or ``"torques"``."""
        return "currents" if self.current is not None and (model.drive is not None or self.tau is None) else "torques"

    def where(self, i: int) -> str:
        """``line 12 (t = 0.011 s)``: sample ``i`` as a person finds it in the file."""
        return f"line {self.lines[i]} (t = {self.t[i]:.6g} s)"


@functools.cache
def _current_torque_function() -> ca.Function:
    """(i, dtheta, N, k_t, eta) -> tau, d tau / d (k_t, eta): one crank's torque of its motor's current through the
    loss law (:func:`chewbot.model.drive.crank_torque`), and its gradient."""
    i, w, ratio, k, eta = (ca.SX.sym(name) for name in ("i", "dtheta", "N", "k_t", "eta"))
    d = Drive(0.0, ratio, eta, k, 0.0)
    tau = drive_law.crank_torque(d, drive_law.torque_of_current(d, i), w)
    return ca.Function("current_torque", [i, w, ratio, k, eta], [tau, ca.jacobian(tau, ca.vertcat(k, eta))])


def read_log(path: str | Path) -> RobotLog:
    """Read a robot log (see the module docstring)."""
    path = Path(path)
    what = "a robot log (t, theta1..6, and tau1..6 or i1..6)"
    names, _, lines, col = read_signals(path, COLUMNS, ("t", *ANGLES), what, columns_beside(path))

    def block(names: tuple[str, ...], what: str):
        given = [c in col for c in names]
        if not any(given):
            return None
        if not all(given):
            missing = [c for c, g in zip(names, given) if not g]
            raise TaskError(f"{path}: the log gives some {what} columns but not {', '.join(missing)}: give all six or none")
        return np.column_stack([col[c] for c in names])

    tau, current = block(TORQUES, "torque"), block(CURRENTS, "current")
    if tau is None and current is None:
        raise TaskError(f"{path}: missing columns tau1..tau6 or i1..i6 ({what} needs the cranks' torques or the "
                        "motors' currents)")
    force = np.column_stack([col.get(f, np.zeros_like(col["t"])) for f in FORCES])
    return RobotLog(str(path), col["t"], block(ANGLES, "theta"), *(block(tuple(p + c for c in ANGLES), p + "theta") for p in ("d", "dd")),
                    tau, force, lines, any(f in col for f in FORCES), current)
