"""What a run produces: the results table (named columns with units, written so that every number reads back
exactly), the run's options and result in memory, and reading a results folder back.

This module sits below both the pipeline that computes a run and the report that shows it.
"""

from __future__ import annotations

import csv
import io
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from chewbot.errors import ChewbotError
from chewbot.kinematics.motion import Kinematics

if TYPE_CHECKING:
    from chewbot.analysis.checks import CheckResult
    from chewbot.model import Model
    from chewbot.task.base import Task

# Version of the results folder's format, the value of run.json's "chewbot_run" (CHANGELOG.md): 2 puts each
# column's unit in the header of results.csv (`tau1 [N*m]`) and adds the transmission angles, kappa_J and the
# validity checks. Version 1 (names alone, units in run.json) is still read.
RESULTS_FORMAT = 2
READABLE_FORMATS = (1, 2)
# A header cell: NAME or NAME [unit].
HEADER_CELL = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?:\[\s*([^\]]*?)\s*\])?\s*$")

POSE_NAMES = ("X", "Y", "Z", "alpha", "beta", "gamma")
POSE_UNITS = ("m", "m", "m", "rad", "rad", "rad")


_LEVEL = ("", "rate of the ", "second rate of the ")


def _rate_unit(unit: str, order: int) -> str:
    return unit if order == 0 else f"{unit}/s" if order == 1 else f"{unit}/s^2"


@dataclass
class Table:
    """Columns of equal length (samples first), each with a unit. Insertion order is the column order."""

    columns: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    descriptions: dict[str, str] = field(default_factory=dict)

    def add(self, name: str, values, unit: str, description: str = "") -> None:
        values = np.asarray(values, dtype=float)
        if values.ndim != 1:
            raise ValueError(f"column {name!r} must be one-dimensional, got shape {values.shape}")
        if self.columns and values.shape[0] != self.n:
            raise ValueError(f"column {name!r} has {values.shape[0]} rows, the table has {self.n}")
        if name in self.columns:
            raise ValueError(f"column {name!r} already in the table")
        self.columns[name] = values
        self.units[name] = unit
        if description:
            self.descriptions[name] = description

    def add_block(self, names, values: np.ndarray, unit: str, description: str = "") -> None:
        """Add the columns of a (N, k) array under k names."""
        values = np.asarray(values, dtype=float)
        for j, name in enumerate(names):
            self.add(name, values[:, j], unit, description)

    @property
    def n(self) -> int:
        return next(iter(self.columns.values())).shape[0] if self.columns else 0

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def to_csv(self, path: Path, first_line: str | None = None) -> None:
        """Write as CSV: a header of ``name [unit]``, one row per sample, each float in its shortest form that
        reads back exactly (and 0.0 for -0.0). ``first_line``: a comment line above the header (e.g. chewbot's
        marker, :func:`chewbot.outputs.marker_line`)."""
        names = list(self.columns)
        data = np.column_stack([self.columns[n] for n in names]) + 0.0  # + 0.0 turns -0.0 into 0.0
        buf = io.StringIO()
        if first_line:
            buf.write(first_line + "\n")
        buf.write(",".join(f"{n} [{self.units[n]}]" if self.units[n] else n for n in names) + "\n")
        for row in data.tolist():  # Python floats: repr is the shortest string that reads back exactly
            buf.write(",".join(map(repr, row)) + "\n")
        Path(path).write_text(buf.getvalue())

    @classmethod
    def read_csv(cls, path: Path, units: dict[str, str] | None = None) -> Table:
        """Read a table written by :meth:`to_csv`: units from the header (``name [unit]``), else from ``units``
        (e.g. the ``columns`` of a version-1 run.json), else empty. Lines starting with ``#`` are skipped."""
        with open(path, newline="") as f:
            rows = [row for row in csv.reader(f) if row and not row[0].startswith("#")]
        cells = [HEADER_CELL.match(c) for c in rows[0]]
        if not all(cells):
            bad = next(c for c, m in zip(rows[0], cells) if m is None)
            raise ChewbotError(f"{path}: cannot read the column name {bad!r} (expected NAME or NAME [unit])")
        data = np.array([[float(x) for x in row] for row in rows[1:]]).reshape(len(rows) - 1, len(cells))
        table = cls()
        for j, m in enumerate(cells):
            name = m.group(1)
            table.add(name, data[:, j], m.group(2) if m.group(2) is not None else (units or {}).get(name, ""))
        return table


def kinematics_table(kin: Kinematics) -> Table:
    """The kinematic columns of ``results.csv`` (names fixed: later stages and scripts rely on them)."""
    table = Table()
    table.add("t", kin.t, "s", "time")
    for order, (arr, prefix) in enumerate(((kin.X, ""), (kin.dX, "d"), (kin.ddX, "dd"))):
        for j, name in enumerate(POSE_NAMES):
            table.add(prefix + name, arr[:, j], _rate_unit(POSE_UNITS[j], order),
                      _LEVEL[order] + "pose of the mandible: O_M in {S}, XYZ Euler angles")
    for order, (arr, prefix) in enumerate(((kin.theta, ""), (kin.dtheta, "d"), (kin.ddtheta, "dd"))):
        table.add_block([f"{prefix}theta{i + 1}" for i in range(6)], arr, _rate_unit("rad", order), _LEVEL[order] + "actuator angle")
    if kin.orientation == "euler-parameters":
        for order, (arr, prefix) in enumerate(((kin.e, ""), (kin.de, "d"), (kin.dde, "dd"))):
            table.add_block([f"{prefix}e{i}" for i in range(4)], arr, "1" if order == 0 else _rate_unit("1", order),
                            _LEVEL[order] + "Euler parameters of the mandible (e0 scalar)")
    table.add_block(["Fx", "Fy", "Fz"], kin.force, "N", "bite force on the mandible at the molar, in {S}")
    return table


@dataclass
class RunOptions:
    """Everything that defines a run (recorded in run.json)."""

    model: str = "target"
    task: str = "default"
    side: str | None = None  # None: left, or the side of the run whose results.csv is the task
    orientation: str = "euler-angles"
    method: str | None = None
    goal: str | None = "min-torque"  # newton-euler on the target only
    friction: str | None = "on"  # newton-euler only
    contact: str = "bilateral"  # contact model of the HKPs: whether contact-pull fails a run (chewbot.analysis.checks)
    overrides: dict[str, float] = field(default_factory=dict)  # --set KEY=VALUE: model keys and task.NAME


@dataclass
class RunResult:
    """What a run computed, in memory (the folder holds the same)."""

    options: RunOptions
    model: Model
    task: Task
    kinematics: Kinematics
    table: Table
    figures: list[Path] = field(default_factory=list)
    info: dict = field(default_factory=dict)
    dynamics: object | None = None
    checks: list[CheckResult] = field(default_factory=list)


def read_results(folder: Path) -> tuple[dict, Table]:
    """A results folder read back: run.json (as a dict) and results.csv as a :class:`Table` with its units.

    Reads the formats listed in :data:`READABLE_FORMATS`; anything else is a :class:`ChewbotError` naming the file.
    """
    folder = Path(folder)
    path = folder / "run.json"
    try:
        run = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ChewbotError(f"{folder}: not a results folder (no run.json)") from None
    except (OSError, ValueError) as exc:
        raise ChewbotError(f"{path}: cannot read it ({exc})") from None
    version = run.get("chewbot_run") if isinstance(run, dict) else None
    if version not in READABLE_FORMATS:
        raise ChewbotError(f"{path}: results format {version!r}; this chewbot reads {', '.join(map(str, READABLE_FORMATS))}")
    units = {name: c.get("unit", "") for name, c in run.get("columns", {}).items()}
    return run, Table.read_csv(folder / "results.csv", units)
