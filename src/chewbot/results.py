"""The results table of a run: named columns with units, written so that every number reads back exactly."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from chewbot.kinematics.motion import Kinematics

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

    def to_csv(self, path: Path) -> None:
        """Write as CSV: a header of names, one row per sample, each float in its shortest round-trip form."""
        names = list(self.columns)
        data = np.column_stack([self.columns[n] for n in names])
        buf = io.StringIO()
        buf.write(",".join(names) + "\n")
        for row in data.tolist():  # Python floats: repr is the shortest string that reads back exactly
            buf.write(",".join(map(repr, row)) + "\n")
        Path(path).write_text(buf.getvalue())

    @classmethod
    def read_csv(cls, path: Path, units: dict[str, str] | None = None) -> Table:
        """Read a table written by :meth:`to_csv` (units from ``units``, e.g. run.json's, else empty)."""
        with open(path, newline="") as f:
            reader = csv.reader(f)
            names = next(reader)
            data = np.array([[float(x) for x in row] for row in reader])
        table = cls()
        for j, name in enumerate(names):
            table.add(name, data[:, j], (units or {}).get(name, ""))
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
