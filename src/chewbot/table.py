"""What a run produces: the results table (named columns with units, written so that every number reads back
exactly), the run's options and result in memory, and reading a results folder back.

This module sits below both the pipeline that computes a run and the report that shows it.
"""

from __future__ import annotations

import csv
import hashlib
import itertools
import json
import platform
import re
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from chewbot.errors import ChewbotError

if TYPE_CHECKING:
    from chewbot.analysis.checks import CheckResult
    from chewbot.kinematics.motion import Kinematics
    from chewbot.model import Model
    from chewbot.report.view import RunView
    from chewbot.kinematics.task import Task

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

    def rows(self, start: int, stop: int) -> Table:
        """Samples ``start`` to ``stop - 1`` (views of the columns, no copy)."""
        part = Table(units=dict(self.units), descriptions=dict(self.descriptions))
        part.columns = {name: values[start:stop] for name, values in self.columns.items()}
        return part

    @classmethod
    def concat(cls, parts: list[Table]) -> Table:
        """The tables one after the other (equal columns in equal order): a task's chunks as one table."""
        first = parts[0]
        for part in parts[1:]:
            if list(part.columns) != list(first.columns):
                raise ValueError("tables with different columns cannot be concatenated")
        whole = cls(units=dict(first.units), descriptions=dict(first.descriptions))
        whole.columns = {name: np.concatenate([p.columns[name] for p in parts]) for name in first.columns}
        return whole

    def to_csv(self, path: Path, first_line: str | None = None) -> None:
        """Write as CSV (:class:`CsvWriter`): a header of ``name [unit]``, one row per sample, each float in its
        shortest form that reads back exactly (and 0.0 for -0.0). ``first_line``: a comment line above the header
        (e.g. chewbot's marker, :func:`chewbot.files.marker_line`)."""
        with CsvWriter(path, first_line) as writer:
            writer.write(self)

    @classmethod
    def read_csv(cls, path: Path, units: dict[str, str] | None = None) -> Table:
        """Read a table written by :meth:`to_csv`: units from the header (``name [unit]``), else from ``units``
        (e.g. the ``columns`` of a version-1 run.json), else empty. Lines starting with ``#`` are skipped."""
        parts = list(read_csv_chunks(path, units))
        return cls.concat(parts) if len(parts) > 1 else parts[0]


class CsvWriter:
    """A results table written chunk after chunk (:meth:`write` per chunk of rows, in order), in the format of
    :meth:`Table.to_csv`; the header comes from the first chunk, and every chunk must have the same columns."""

    def __init__(self, path: Path, first_line: str | None = None):
        self.path = Path(path)
        self._file = open(self.path, "w", encoding="utf-8", newline="")
        self._names: list[str] | None = None
        if first_line:
            self._file.write(first_line + "\n")

    def write(self, table: Table) -> None:
        names = list(table.columns)
        if self._names is None:
            self._names = names
            self._file.write(",".join(f"{n} [{table.units[n]}]" if table.units[n] else n for n in names) + "\n")
        elif names != self._names:
            raise ValueError(f"{self.path}: a chunk with columns {names} after {self._names}")
        if not table.n:
            return
        data = np.column_stack([table.columns[n] for n in names]) + 0.0  # + 0.0 turns -0.0 into 0.0
        # Python floats: repr is the shortest string that reads back exactly
        self._file.write("\n".join([",".join(map(repr, row)) for row in data.tolist()]) + "\n")

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> CsvWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_csv_chunks(path: Path, units: dict[str, str] | None = None, rows: int = 10_000):
    """A table written by :meth:`Table.to_csv` read ``rows`` rows at a time (a generator of :class:`Table`), in
    constant memory; units as :meth:`Table.read_csv` takes them. A table without rows gives one empty chunk.
    Lines starting with ``#`` and blank lines are skipped; a row that is not a number per column is named by its
    line."""
    path = Path(path)
    try:
        f = open(path, newline="", encoding="utf-8")
    except OSError as exc:
        raise ChewbotError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    with f:
        numbered = ((k, text) for k, text in enumerate(f, start=1) if text.strip() and not text.lstrip().startswith("#"))
        first = next(numbered, None)
        if first is None:
            raise ChewbotError(f"{path}: no header line (an empty results table)")
        header = next(csv.reader([first[1]]))
        cells = [HEADER_CELL.match(c) for c in header]
        if not all(cells):
            bad = next(c for c, m in zip(header, cells) if m is None)
            raise ChewbotError(f"{path}: cannot read the column name {bad!r} (expected NAME or NAME [unit])")
        names = [m.group(1) for m in cells]
        unit_of = {m.group(1): m.group(2) if m.group(2) is not None else (units or {}).get(m.group(1), "") for m in cells}
        yielded = False
        while True:
            block = list(itertools.islice(numbered, rows))
            if not block and yielded:
                return
            data = _numbers(path, block, len(names))
            table = Table()
            for j, name in enumerate(names):
                table.add(name, data[:, j], unit_of[name])
            yielded = True
            yield table
            if len(block) < rows:
                return


def _numbers(path: Path, block: list[tuple[int, str]], width: int) -> np.ndarray:
    """The rows of ``block`` (line number, text) as an (n, width) array; a bad row is named by its line."""
    if not block:
        return np.zeros((0, width))
    try:
        data = np.loadtxt([text for _, text in block], delimiter=",", dtype=float, ndmin=2)
        if data.shape[1] == width:
            return data
    except ValueError:
        pass
    for line, text in block:
        row = text.rstrip("\r\n").split(",")
        if len(row) != width:
            raise ChewbotError(f"{path}: line {line}: {len(row)} cells, the header has {width} columns")
        for cell in row:
            try:
                float(cell)
            except ValueError:
                raise ChewbotError(f"{path}: line {line}: {cell.strip()!r} is not a number") from None
    raise ChewbotError(f"{path}: the rows from line {block[0][0]} cannot be read")


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
class RunRecord:
    """A run as its folder holds it, without its rows: ``record`` (run.json's content), the model, the validity
    checks, ``view`` (the decimated columns and their statistics, :class:`chewbot.report.view.RunView`) and the
    files written. What ``chewbot run`` returns for a task written chunk by chunk."""

    record: dict
    model: Model
    checks: list[CheckResult]
    view: RunView
    files: list[Path] = field(default_factory=list)


def versions(*extra: str) -> dict[str, str]:
    """The versions of Python, chewbot and the libraries its results depend on, and of the packages ``extra``."""
    out = {"python": platform.python_version()}
    for pkg in ("chewbot", "numpy", "scipy", "casadi", "pydantic", "matplotlib", "plotly", *extra):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def model_record(model: Model) -> dict:
    """A model's identity in run.json: name, mechanism, file and its hash, assumed keys, the parameters' hash."""
    from chewbot.model.vector import vector_digest

    return {"name": model.name, "mechanism": model.mechanism, "file": model.source, "sha256": model.sha256,
            "assumed": list(model.assumed), "parameters_sha256": vector_digest(model)}


def task_record(task: Task) -> dict:
    """A task's identity in run.json: name, source (and its hash), samples, side, what the generator recorded."""
    source = Path(task.source)
    return {"name": task.name, "source": task.source,
            **({"sha256": hashlib.sha256(source.read_bytes()).hexdigest()} if source.is_file() else {}),
            "samples": task.n, "side": task.side, **({"meta": task.meta} if task.meta else {})}


def environment_record(*extra: str) -> dict:
    """The versions of chewbot and its libraries (and of the packages ``extra``), and the platform."""
    return {"versions": versions(*extra), "platform": platform.platform()}


def columns_record(columns: Table) -> dict:
    """Each column's unit and description (``columns``: any chunk of the results table)."""
    return {name: {"unit": columns.units[name], **({"description": d} if (d := columns.descriptions.get(name)) else {})}
            for name in columns.columns}


def run_record(options, model: Model, task: Task, columns: Table, checks: list[CheckResult], info: dict) -> dict:
    """The run record (run.json): format, options, model and task identity, versions, platform, the unit and
    description of every column of ``columns`` (any chunk of the results table), the validity checks, ``info``
    (timings, the formulation's info, the coupling means)."""
    return {
        "chewbot_run": RESULTS_FORMAT,
        "options": vars(options),
        "model": model_record(model),
        "overrides": dict(options.overrides),
        "task": task_record(task),
        **environment_record(),
        "columns": columns_record(columns),
        "checks": [c.as_dict() for c in checks],
        **info,
    }


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
