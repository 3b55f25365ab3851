"""Tasks from CSV files: a motion of the mandible in XYZ Euler angles and, optionally, its rates and the bite force.

One header row of column names, then one row per sample, comma-separated. Columns (any order):

* ``t`` (time, strictly increasing) and the coordinates: ``X, Y, alpha, beta`` for the target, plus ``Z, gamma``
  for the 6RSS. A target file may carry ``Z`` and ``gamma`` too (both): they are kept and checked against the
  sockets when the kinematics are solved.
* optional rates ``dX, dY, ..., ddX, ddY, ...`` of any coordinate present: used as given; the missing ones are
  estimated from the positions (:mod:`chewbot.task.smoothing`, uniform sampling only).
* optional bite force ``Fx, Fy, Fz`` on the mandible in {S} (each one absent is zero).

Values are SI (s, m, rad, N and their rates) unless the name carries a unit in brackets: ``X[mm]``,
``alpha [deg]``, ``dX[mm/s]``, ``ddbeta[deg/s^2]``, ``t[ms]``, ``Fz[kN]`` (see :data:`chewbot.units.UNITS`). Blank lines and
lines starting with ``#`` are skipped. Every error is a :class:`~chewbot.errors.TaskError` naming the file and
the line (1-based, as an editor shows it) or the column.

A run's ``results.csv`` is a task too: with chewbot's run.json beside it, the columns that run.json lists and a
task does not take (theta1, tau1, MCI1, ...) are skipped, and the bite force's side is the run's unless given.
"""

from __future__ import annotations

import csv
import itertools
import json
from pathlib import Path

import numpy as np

from chewbot.errors import TaskError
from chewbot.units import HEADER_CELL, unit_factor
from chewbot.task import smoothing
from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task

KIND = {"X": "length", "Y": "length", "Z": "length", "alpha": "angle", "beta": "angle", "gamma": "angle"}
FORCES = ("Fx", "Fy", "Fz")
# Fewest samples a task file may have: enough for the derivative estimate's local polynomial.
MIN_ROWS = smoothing.POLYORDER + 2



def _columns(kinds: dict[str, str]) -> dict[str, tuple[str, int]]:
    """Every known column name -> (kind, order of the time derivative), for signals of ``kinds``."""
    known = {"t": ("time", 0), **{f: ("force", 0) for f in FORCES}}
    for name, kind in kinds.items():
        for order, prefix in enumerate(("", "d", "dd")):
            known[prefix + name] = (kind, order)
    return known


COLUMNS = _columns(KIND)
INCISOR = ("Ix", "Iy", "Iz")  # the incisor point I in {S}
# An incisor path may also give the trajectory of the coordinate pinned to resolve the redundancy.
INCISOR_COLUMNS = _columns({**{c: "length" for c in INCISOR}, **{c: KIND[c] for c in TARGET_COORDS}})


def _parse_header(path: Path, line: int, cells: list[str], columns: dict = COLUMNS,
                  outputs: frozenset[str] = frozenset()) -> tuple[list[str], np.ndarray, list[int]]:
    """Names, factors to SI and the indices of the cells that are read; cells named in ``outputs`` (the output
    columns of the run that wrote the file) and not in ``columns`` are skipped."""
    names, factors, kept = [], [], []
    for j, cell in enumerate(cells):
        m = HEADER_CELL.match(cell)
        if m is None:
            raise TaskError(f"{path}: line {line}, column {j + 1}: cannot read the column name {cell!r} (expected NAME or NAME[unit])")
        name, unit = m.group(1), m.group(2)
        if name in outputs and name not in columns:
            continue
        if name not in columns:
            raise TaskError(f"{path}: line {line}: unknown column {name!r} (known: {', '.join(columns)}; a run's results.csv "
                            "is read with the run.json beside it, which names its other columns)")
        if name in names:
            raise TaskError(f"{path}: line {line}: column {name!r} appears twice")
        kind, order = columns[name]
        try:
            factors.append(1.0 if unit is None else unit_factor(unit, kind, order))
        except ValueError as exc:
            raise TaskError(f"{path}: line {line}: column {cell.strip()!r}: {exc}") from None
        names.append(name)
        kept.append(j)
    return names, np.array(factors), kept


# Rows parsed at a time: a block's cells are Python strings (about 60 bytes each), the file's numbers are kept as
# floats only, so a long recording (an hour at 1 kHz) is read in the memory of its numbers.
BLOCK_ROWS = 65_536


def _rows(path: Path, f):
    """(line, cells) of each row of an open CSV file, skipping blank and comment lines; a malformed file (bad
    quoting, a NUL byte) is named with its line."""
    reader = csv.reader(f)
    try:
        for cells in reader:
            if cells and any(c.strip() for c in cells) and not cells[0].lstrip().startswith("#"):
                yield reader.line_num, cells
    except csv.Error as exc:
        raise TaskError(f"{path}: line {reader.line_num}: {exc}") from None
    except UnicodeDecodeError as exc:
        raise TaskError(f"{path}: cannot read the task file ({exc})") from None


def _to_float(path: Path, names: list[str], lines: list[int], cells: list[list[str]]) -> np.ndarray:
    """The block's cells as numbers (rows, columns); a cell that is not a number is named by line and column."""
    try:
        return np.array(cells, dtype=float).reshape(len(cells), len(names))
    except ValueError:
        for i, row in enumerate(cells):
            for j, cell in enumerate(row):
                try:
                    float(cell)
                except ValueError:
                    raise TaskError(f"{path}: line {lines[i]}, column {names[j]!r}: {cell.strip()!r} is not a number") from None
        raise


def read_signals(path: Path, columns: dict, required: tuple[str, ...], what: str, outputs: frozenset[str] = frozenset()):
    """Parse, check and convert to SI a file of signals over time: (names, header, lines, col) with col the
    columns by name (SI, (N,) each), header the cells of the columns read. Columns in ``outputs`` that are not in
    ``columns`` are skipped. Every defect is a TaskError naming the file and the line or column. The file is read
    in blocks of :data:`BLOCK_ROWS` rows, keeping only the numbers."""
    try:
        f = open(path, encoding="utf-8-sig", newline="")
    except FileNotFoundError:
        raise TaskError(f"{path}: no such task file") from None
    except OSError as exc:
        raise TaskError(f"{path}: cannot read the task file ({exc})") from None
    with f:
        rows = _rows(path, f)
        first = next(rows, None)
        if first is None:
            raise TaskError(f"{path}: empty task file (expected a header such as 't,X,Y,alpha,beta' and one row per sample)")
        header_line, header = first
        names, factors, kept = _parse_header(path, header_line, header, columns, outputs)
        missing = [c for c in required if c not in names]
        if missing:
            raise TaskError(f"{path}: missing column(s) {', '.join(missing)} ({what} needs {', '.join(required)})")
        for n in names:
            kind, order = columns[n]
            if order and n[order:] not in names:
                raise TaskError(f"{path}: column {n!r} is a rate of {n[order:]!r}, which the file does not give")
        blocks, lines = [], []
        while block := list(itertools.islice(rows, BLOCK_ROWS)):
            numbers = [line for line, _ in block]
            for line, cells in block:
                if len(cells) != len(header):
                    raise TaskError(f"{path}: line {line}: {len(cells)} cells, the header has {len(header)} columns")
            blocks.append(_to_float(path, names, numbers, [[cells[j] for j in kept] for _, cells in block]))
            lines.append(np.array(numbers, dtype=np.int64))
    n = sum(b.shape[0] for b in blocks)
    if n < MIN_ROWS:
        raise TaskError(f"{path}: {n} data row(s); {what} needs at least {MIN_ROWS}")
    data = np.concatenate(blocks) if len(blocks) > 1 else blocks[0]
    del blocks
    lines = np.concatenate(lines)
    bad = np.argwhere(~np.isfinite(data))
    if bad.size:
        i, j = bad[0]
        raise TaskError(f"{path}: line {lines[i]}, column {names[j]!r}: {data[i, j]} is not a finite number")
    data *= factors
    col = {n: data[:, j] for j, n in enumerate(names)}
    t = col["t"]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise TaskError(f"{path}: line {lines[i]}, column 't': time {t[i]:.9g} s does not increase (previous row {t[i - 1]:.9g} s)")
    return names, [header[j] for j in kept], lines, col


def _with_rates(path: Path, lines, col: dict, signals: tuple[str, ...]):
    """The signals (N, k) and their first and second rates: from the file where given, else estimated
    (:mod:`chewbot.task.smoothing`); and the list of the estimated columns."""
    t = col["t"]
    q = np.column_stack([col[c] for c in signals])
    estimated = [prefix + c for prefix in ("d", "dd") for c in signals if prefix + c not in col]
    if estimated:
        try:
            smooth = smoothing.derivatives(t, q)
        except smoothing.IrregularSampling as exc:
            raise TaskError(f"{path}: line {lines[exc.sample]}: {exc} (missing: {', '.join(estimated)})") from None
        except TaskError as exc:
            raise TaskError(f"{path}: {exc}") from None
    rates = [np.column_stack([col[prefix + c] if prefix + c in col else smooth[order - 1][:, j] for j, c in enumerate(signals)])
             for order, prefix in ((1, "d"), (2, "dd"))]
    return q, rates[0], rates[1], estimated


def _meta(path: Path, names, header, estimated) -> dict:
    units = {n: (h.split("[", 1)[1].rstrip("] ") if "[" in h else "SI") for n, h in zip(names, header)}
    return {"file": str(path), "units": units, "derivatives_estimated": estimated,
            **({"smoothing": {"method": "savgol", "polyorder": smoothing.POLYORDER, "window_s": smoothing.WINDOW_S}} if estimated else {})}


def read_incisor_csv(path: str | Path) -> dict:
    """Read a path of the incisor point I in {S}: columns ``t, Ix, Iy, Iz``, optional rates ``dIx ... ddIz``,
    bite force ``Fx, Fy, Fz`` and the trajectory of a coordinate to pin (``X``, ``Y``, ``alpha`` or ``beta``,
    optionally with rates), units in brackets as for tasks. Returns t (N,), p, v, a, force (N, 3) and
    ``pinned``: {coordinate: (values, rates, accelerations)}, SI."""
    path = Path(path)
    names, header, lines, col = read_signals(path, INCISOR_COLUMNS, ("t",) + INCISOR, "an incisor path")
    p, v, a, _ = _with_rates(path, lines, col, INCISOR)
    force = np.column_stack([col.get(f, np.zeros_like(col["t"])) for f in FORCES])
    pinned = {}
    for c in TARGET_COORDS:
        if c in col:
            q, dq, ddq, _ = _with_rates(path, lines, col, (c,))
            pinned[c] = (q[:, 0], dq[:, 0], ddq[:, 0])
    return {"t": col["t"], "p": p, "v": v, "a": a, "force": force, "pinned": pinned}


def run_beside(path: Path) -> dict | None:
    """The run.json of the chewbot run whose results.csv ``path`` is (in the same folder), or None."""
    from chewbot.files import RESULTS_FOLDER

    if not RESULTS_FOLDER.present(path.parent):
        return None
    run = json.loads((path.parent / RESULTS_FOLDER.file).read_text(encoding="utf-8"))
    if path.name != "results.csv" or not isinstance(run.get("columns"), dict):
        return None
    return run


def columns_beside(path: Path) -> frozenset[str]:
    """The columns that the run.json beside a chewbot results.csv lists (a run's or a simulation's), or none: the
    output columns a reader of that file may skip."""
    path = Path(path)
    record = path.parent / "run.json"
    if path.name != "results.csv" or not record.is_file():
        return frozenset()
    try:
        run = json.loads(record.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return frozenset()
    if not (isinstance(run, dict) and any(k in run for k in ("chewbot_run", "chewbot_simulation"))
            and isinstance(run.get("columns"), dict)):
        return frozenset()
    return frozenset(run["columns"])


def read_task_csv(path: str | Path, side: str | None = None, mechanism: str = "target", name: str | None = None) -> Task:
    """Read a task file (see the module docstring) for a ``mechanism`` ("target" or "6rss"), bite force at
    ``side``: left or right; None takes the side of the run whose results.csv the file is, else left."""
    path = Path(path)
    if mechanism not in ("target", "6rss"):
        raise TaskError(f"mechanism must be 'target' or '6rss', not {mechanism!r}")
    run = run_beside(path)
    outputs = frozenset(run["columns"]) if run else frozenset()
    if side is None:
        side = (run or {}).get("task", {}).get("side") or "left"
    required = ("t",) + (TARGET_COORDS if mechanism == "target" else FULL_COORDS)
    names, header, lines, col = read_signals(path, COLUMNS, required, f"a {mechanism} task", outputs)
    has_full = "Z" in names or "gamma" in names
    if has_full and not ("Z" in names and "gamma" in names):
        raise TaskError(f"{path}: columns Z and gamma come together (the target computes both from its sockets when neither is given)")
    coords = FULL_COORDS if has_full else TARGET_COORDS
    q, dq, ddq, estimated = _with_rates(path, lines, col, coords)
    force = np.column_stack([col.get(f, np.zeros_like(col["t"])) for f in FORCES])
    meta = _meta(path, names, header, estimated)
    if run:
        meta["results_of_run"] = {"options": run.get("options", {}), "skipped_columns": len(outputs - set(names))}
    for a in (col["t"], q, dq, ddq, force):  # the task keeps them without a copy (a long file's numbers, once)
        a.setflags(write=False)
    return Task(name=name or path.stem, t=col["t"], coords=coords, q=q, dq=dq, ddq=ddq, force=force,
                side=side, source=str(path), meta=meta, lines=lines)


def task_table(task: Task):
    """The task as ``chewbot run --task`` reads it: t, coordinates, their rates, the bite force; SI units named."""
    from chewbot.table import Table

    table = Table()
    table.add("t", task.t, "s")
    units = {"X": "m", "Y": "m", "Z": "m", "alpha": "rad", "beta": "rad", "gamma": "rad"}
    for prefix, values, per in (("", task.q, ""), ("d", task.dq, "/s"), ("dd", task.ddq, "/s^2")):
        for j, c in enumerate(task.coords):
            table.add(prefix + c, values[:, j], units[c] + per)
    table.add_block(["Fx", "Fy", "Fz"], task.force, "N")
    return table
