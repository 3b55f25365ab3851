"""Robot logs: crank angles and measured torques over time, read from CSV.

One header row, then one row per sample, comma-separated; blank lines and lines starting with ``#`` are skipped
(chewbot's marker line among them). Columns (any order):

* ``t`` (strictly increasing; uniform steps where rates are estimated);
* ``theta1`` .. ``theta6``, the crank angles, and optionally their rates ``dtheta1..6`` and ``ddtheta1..6``
  (all six of a kind or none);
* ``tau1`` .. ``tau6``, the measured actuator torques;
* optionally the bite force ``Fx, Fy, Fz`` on the mandible in {S} at the molar of ``--side`` (each one absent
  is zero).

Values are SI (s, rad, N*m, N) unless the name carries a unit in brackets, as in task files: ``theta1[deg]``,
``dtheta1[deg/s]``, ``tau1[N*mm]``, ``t[ms]``, ``Fz[kN]``. Errors are :class:`~chewbot.errors.TaskError`
naming the file and the line (1-based, as an editor shows it) and the column. The results.csv of a chewbot run or
simulation is a log too: the other columns that its run.json lists are skipped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from chewbot.errors import TaskError
from chewbot.task.csvio import FORCES, columns_beside, read_signals

ANGLES = tuple(f"theta{i}" for i in range(1, 7))
TORQUES = tuple(f"tau{i}" for i in range(1, 7))
COLUMNS = {"t": ("time", 0), **{f: ("force", 0) for f in FORCES}, **{c: ("torque", 0) for c in TORQUES},
           **{prefix + c: ("angle", order) for c in ANGLES for order, prefix in enumerate(("", "d", "dd"))}}


@dataclass(frozen=True, eq=False)
class RobotLog:
    """A log of the robot (arrays samples first, SI).

    ``t`` (N,) s; ``theta`` (N, 6) rad; ``dtheta``, ``ddtheta`` (N, 6) or None where the file does not give them;
    ``tau`` (N, 6) N*m measured; ``force`` (N, 3) N, the bite force on the mandible in {S} (zero where not
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

    @property
    def n(self) -> int:
        return self.t.shape[0]

    def where(self, i: int) -> str:
        """``line 12 (t = 0.011 s)``: sample ``i`` as a person finds it in the file."""
        return f"line {self.lines[i]} (t = {self.t[i]:.6g} s)"


def read_log(path: str | Path) -> RobotLog:
    """Read a robot log (see the module docstring)."""
    path = Path(path)
    what = "a robot log (t, theta1..6, tau1..6)"
    names, _, lines, col = read_signals(path, COLUMNS, ("t", *ANGLES, *TORQUES), what, columns_beside(path))

    def block(prefix: str):
        given = [prefix + c in col for c in ANGLES]
        if not any(given):
            return None
        if not all(given):
            missing = [prefix + c for c, g in zip(ANGLES, given) if not g]
            raise TaskError(f"{path}: the log gives some {prefix}theta columns but not {', '.join(missing)}: give all six or none")
        return np.column_stack([col[prefix + c] for c in ANGLES])

    force = np.column_stack([col.get(f, np.zeros_like(col["t"])) for f in FORCES])
    return RobotLog(str(path), col["t"], block(""), block("d"), block("dd"), np.column_stack([col[c] for c in TORQUES]),
                    force, lines, any(f in col for f in FORCES))
