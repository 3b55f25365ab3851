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

import codecs
import csv
import json
import mmap
import os
import re
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


# A cell that is a number as pyarrow's CSV reader reads one (the error path names a cell that is not).
NUMBER = re.compile(r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)", re.IGNORECASE)
LONE_CR = re.compile(rb"\r(?!\n)")
# After a line end, what may begin a blank line or a comment: where none follows, every line of the rows is a row.
SKIPPED_START = re.compile(rb"\n[\n\r \t,#]")


def _source(path: Path, what: str):
    """The file's bytes (memory-mapped: a long log is not copied into memory) and where they begin (after a UTF-8
    byte-order mark); old Mac line ends (a lone CR) are read as line ends."""
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            data = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
    except FileNotFoundError:
        raise TaskError(f"{path}: no such file (expected {what})") from None
    except OSError as exc:
        raise TaskError(f"{path}: cannot read it as {what} ({exc.strerror or exc})") from None
    begin = len(codecs.BOM_UTF8) if data[:3] == codecs.BOM_UTF8 else 0
    if data.find(b"\r", begin) >= 0 and LONE_CR.search(data, begin):
        data, begin = data[begin:].replace(b"\r\n", b"\n").replace(b"\r", b"\n"), 0
    return data, begin


def _skipped(text: bytes) -> bool:
    """A blank line (nothing but spaces and commas) or a comment (its first cell begins with ``#``)."""
    return not text.strip(b", \t\r") or text.lstrip(b" \t").startswith(b"#")


def _header(path: Path, data, pos: int, what: str, required: tuple[str, ...]) -> tuple[int, list[str], int]:
    """The header's line (1-based), its cells, and where the rows after it start: the first line from ``pos`` that is
    neither blank nor a comment."""
    line = 1
    while pos < len(data):
        end = data.find(b"\n", pos)
        end = len(data) if end < 0 else end
        text = data[pos:end]
        if not _skipped(text):
            try:
                return line, next(csv.reader([text.decode("utf-8").rstrip("\r")])), end + 1
            except UnicodeDecodeError as exc:
                raise TaskError(f"{path}: line {line}: cannot read the column names ({exc})") from None
        line, pos = line + 1, end + 1
    raise TaskError(f"{path}: empty file (expected {what}: a header such as '{','.join(required[:5])}{',...' if len(required) > 5 else ''}' "
                    "and one row per sample)")


def _without_skipped(data, pos: int) -> tuple[bytes, np.ndarray]:
    """The lines from ``pos`` on without the blank and comment lines, and the 0-based line (counted from ``pos``) of
    each line kept: every line classified at once, NumPy over its bytes."""
    a = np.frombuffer(data, dtype=np.uint8, offset=pos)
    ends = np.flatnonzero(a == ord("\n"))
    if a[-1] != ord("\n"):
        ends = np.append(ends, a.size)
    starts = np.concatenate(([0], ends[:-1] + 1))
    space = np.isin(a, np.frombuffer(b" \t\r\n", dtype=np.uint8))
    filled = np.append(np.flatnonzero(~space & (a != ord(","))), a.size)  # neither a space nor a comma; a sentinel
    visible = np.append(np.flatnonzero(~space), a.size)
    blank = filled[np.searchsorted(filled, starts)] >= ends
    first = visible[np.searchsorted(visible, starts)]
    comment = ~blank & (a[np.minimum(first, a.size - 1)] == ord("#"))
    keep = ~(blank | comment)
    within = np.repeat(keep, ends - starts + 1)[:a.size]  # each line with its line end
    return a[within].tobytes(), np.flatnonzero(keep).astype(np.int64)


def _first_refused(path: Path, rows, line: int, within: np.ndarray | None, width: int, names: list[str], kept: list[int],
                   reason: str) -> TaskError:
    """The error of the first row that pyarrow refused, named by its line and column: a row with another number of
    cells than the header, or a cell that is not a number. ``line``: the first row's line; ``within``: each row's line
    from there (None: one after the other)."""
    text = [row.rstrip("\r") for row in bytes(rows).decode("utf-8", errors="replace").removesuffix("\n").split("\n")]
    for k, cells in enumerate(csv.reader(text)):
        number = line + (k if within is None else int(within[k]))
        if len(cells) != width:
            return TaskError(f"{path}: line {number}: {len(cells)} cells, the header has {width} columns")
        for name, j in zip(names, kept):
            if not NUMBER.fullmatch(cells[j].strip()):
                return TaskError(f"{path}: line {number}, column {name!r}: {cells[j].strip()!r} is not a number")
    return TaskError(f"{path}: cannot read the rows ({reason})")


def _floats(column) -> np.ndarray:
    """A float64 column of pyarrow's (no nulls: the reader takes no null values) as one array, from its chunks'
    buffers (``to_numpy`` would load pandas first, half a second on a first call)."""
    return np.concatenate([np.frombuffer(c.buffers()[1], dtype=np.float64, count=len(c), offset=8 * c.offset) for c in column.chunks])


def read_signals(path: Path, columns: dict, required: tuple[str, ...], what: str, outputs: frozenset[str] = frozenset()):
    """Parse, check and convert to SI a file of signals over time: (names, header, lines, col) with col the
    columns by name (SI, (N,) each), header the cells of the columns read, lines each row's line in the file. Columns in
    ``outputs`` that are not in ``columns`` are skipped. Every defect is a TaskError naming the file and the line or
    column.

    The rows are read by pyarrow's CSV reader (columnar, in parallel blocks, each number correctly rounded: the float
    nearest to its decimal text, as Python's ``float``), from the file memory-mapped, only the columns used converted;
    blank lines and comments among the rows are left out first."""
    import pyarrow as pa
    import pyarrow.csv as pc

    data, begin = _source(path, what)
    header_line, header, pos = _header(path, data, begin, what, required)
    names, factors, kept = _parse_header(path, header_line, header, columns, outputs)
    missing = [c for c in required if c not in names]
    if missing:
        raise TaskError(f"{path}: missing column(s) {', '.join(missing)} ({what} needs {', '.join(required)})")
    for n in names:
        kind, order = columns[n]
        if order and n[order:] not in names:
            raise TaskError(f"{path}: column {n!r} is a rate of {n[order:]!r}, which the file does not give")
    body = pos < len(data)
    if body and SKIPPED_START.search(data, pos - 1):
        rows, within = _without_skipped(data, pos)
    else:
        rows, within = (pa.py_buffer(data)[pos:] if body else b""), None
    cells = [f"c{j}" for j in range(len(header))]
    try:
        table = pc.read_csv(pa.BufferReader(rows), read_options=pc.ReadOptions(column_names=cells),
                            convert_options=pc.ConvertOptions(include_columns=[cells[j] for j in kept],
                                                              column_types={cells[j]: pa.float64() for j in kept},
                                                              null_values=[], strings_can_be_null=False,
                                                              quoted_strings_can_be_null=False))
    except pa.ArrowInvalid as exc:
        raise _first_refused(path, rows, header_line + 1, within, len(header), names, kept, str(exc)) from None
    n = table.num_rows
    lines = header_line + 1 + (within if within is not None else np.arange(n, dtype=np.int64))
    if n < MIN_ROWS:
        raise TaskError(f"{path}: {n} data row(s); {what} needs at least {MIN_ROWS}")
    values = [_floats(table.column(j)) for j in range(len(names))]
    bad = [(int(np.argmin(finite)), j) for j, finite in enumerate(np.isfinite(v) for v in values) if not finite.all()]
    if bad:
        i, j = min(bad)
        raise TaskError(f"{path}: line {lines[i]}, column {names[j]!r}: {values[j][i]} is not a finite number")
    col = {name: v * f if f != 1.0 else v for name, v, f in zip(names, values, factors)}
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
    """The task as :func:`read_task_csv` reads it back: t, the coordinates, their rates and accelerations, the bite
    force; SI units in the header (what ``track-incisor`` and ``import-motion`` write, a run folder's task.csv)."""
    from chewbot.table import Table

    table = Table()
    table.add("t", task.t, "s")
    units = {"X": "m", "Y": "m", "Z": "m", "alpha": "rad", "beta": "rad", "gamma": "rad"}
    for prefix, values, per in (("", task.q, ""), ("d", task.dq, "/s"), ("dd", task.ddq, "/s^2")):
        for j, c in enumerate(task.coords):
            table.add(prefix + c, values[:, j], units[c] + per)
    table.add_block(list(FORCES), task.force, "N")
    return table
