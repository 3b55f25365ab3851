"""Tables of named columns with units, samples first (:class:`Table`), written to CSV so that every number reads
back exactly (:class:`CsvWriter`, one chunk of rows after another) and read back in chunks (:func:`read_csv_chunks`).

The header holds each column's unit, ``name [unit]`` (:mod:`chewbot.units`); results, tasks and the tables beside
them are written this way.
"""

from __future__ import annotations

import csv
import itertools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from chewbot.errors import ChewbotError
from chewbot.units import HEADER_CELL, column_header

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
            self._file.write(",".join(column_header(n, table.units[n]) for n in names) + "\n")
        elif names != self._names:
            raise ValueError(f"{self.path}: a chunk with columns {names} after {self._names}")
        if not table.n:
            return
        data = np.column_stack([table.columns[n] for n in names]) + 0.0  # + 0.0 turns -0.0 into 0.0
        # Python floats: repr is the shortest string that reads back exactly (mapped rather than a comprehension: a
        # tenth faster, the formatting being most of a run's writing)
        self._file.write("\n".join(map(",".join, map(lambda row: map(repr, row), data.tolist()))) + "\n")

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
