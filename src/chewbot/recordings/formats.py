"""Reading marker recordings: CSV, ArtiSynth numeric probe text and C3D, into one :class:`Recording`.

Every reader returns marker positions in metres, in the tracker's frame, with NaN where a marker was not seen
(a dropped frame). Lengths without a unit in the file take the registration's ``units``. Errors are
:class:`~chewbot.errors.RecordingError` naming the file and the line, column or marker.

* CSV (``.csv``): one header row, then one row per frame, comma-separated; blank lines and lines starting with
  ``#`` are skipped. Columns: ``t`` (seconds unless it carries a unit: ``t[ms]``), ``NAME_x, NAME_y, NAME_z``
  for each marker NAME, and optionally the bite force ``Fx, Fy, Fz`` on the mandible in {S} (newtons unless
  ``Fx[kN]``); units in brackets as in task files (``M1_x[mm]``). An empty cell or ``NaN`` in a marker's column
  is a dropped frame.
* ArtiSynth numeric probe text (any other suffix, e.g. ``.txt``): ``start stop scale`` (times in seconds, or in
  nanoseconds when written as integers; ``scale`` stretches the probe's own time: t = start + scale * t_probe),
  then ``interpolation vsize timestep`` (knots at 0, timestep, 2 timestep, ...) or
  ``interpolation vsize explicit`` (each row starts with its knot time), then one row per frame of vsize values:
  x, y, z of markers M1, M2, ... in order. ``#`` starts a comment. Knots outside [start, stop] are not used
  (ArtiSynth does not apply them either). ``NaN`` is a dropped frame.
* C3D (``.c3d``), read with ezc3d: POINT:LABELS name the markers, POINT:UNITS gives the length unit,
  POINT:RATE the frame rate (t = 0 at the file's first frame); points ezc3d reports as invalid (negative
  residual) are dropped frames.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from chewbot.errors import RecordingError
from chewbot.units import HEADER_CELL, UNITS, unit_factor

FORCES = ("Fx", "Fy", "Fz")
AXES = ("x", "y", "z")
# Fewest frames a recording may have: the zero-phase filter pads each end with 9 frames.
MIN_FRAMES = 10
ARTISYNTH_INTERPOLATIONS = ("step", "linear", "parabolic", "cubic", "cubicstep", "sphericallinear", "sphericalcubic")
_INTEGER = re.compile(r"^[+-]?\d+$")
_MISSING = ("", "nan")


@dataclass(frozen=True, eq=False)
class Recording:
    """Marker paths over time, as read from a file (arrays frames first, SI).

    ``t`` (N,) s, strictly increasing; ``markers``: the names; ``positions`` (N, K, 3) m in the tracker's frame,
    NaN where a marker was not seen; ``force`` (N, 3) N in {S}, or None; ``lines``: each frame's line in a text
    file (None for C3D); ``meta``: what the reader found (format, units, dropped knots).
    """

    source: str
    format: str
    t: np.ndarray
    markers: tuple[str, ...]
    positions: np.ndarray
    force: np.ndarray | None = None
    lines: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    first_frame: int = 1  # the number of frame 0 in the file (frames count from 1)

    @property
    def n(self) -> int:
        return self.t.shape[0]

    def where(self, i: int) -> str:
        """``frame 12 (t = 0.11 s, line 14)``: frame ``i`` as a person finds it in the file."""
        line = "" if self.lines is None else f", line {self.lines[i]}"
        return f"frame {self.first_frame + i} (t = {self.t[i]:.6g} s{line})"

    def frames(self, start: int, stop: int) -> Recording:
        """Frames ``start`` to ``stop - 1`` of the recording."""
        cut = slice(start, stop)
        return replace(self, t=self.t[cut], positions=self.positions[cut], force=None if self.force is None else self.force[cut],
                       lines=None if self.lines is None else self.lines[cut], first_frame=self.first_frame + start)


def read_recording(path: str | Path, units: str) -> Recording:
    """Read a recording by its suffix (``.csv``, ``.c3d``, otherwise ArtiSynth probe text); ``units``: the length
    unit of values that carry none (the registration's)."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"{path}: no such recording")
    suffix = path.suffix.lower()
    reader = {".csv": read_csv, ".c3d": read_c3d}.get(suffix, read_artisynth)
    rec = reader(path, units)
    if rec.n < MIN_FRAMES:
        raise RecordingError(f"{path}: {rec.n} frame(s); a recording needs at least {MIN_FRAMES}")
    bad = np.flatnonzero(np.diff(rec.t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise RecordingError(f"{path}: {rec.where(i)}: time does not increase (previous frame at t = {rec.t[i - 1]:.9g} s)")
    return rec


def length_factor(unit: str, where: str) -> float:
    """Metres per ``unit`` (a length unit of task files); RecordingError naming ``where`` otherwise."""
    try:
        return unit_factor(unit, "length", 0)
    except ValueError as exc:
        raise RecordingError(f"{where}: {exc}") from None


def read_table(path: Path, kind_of, what: str):
    """A CSV of named columns with units: (names, SI values (N, k) with NaN for empty or NaN cells, line of each
    row). ``kind_of(name)`` is (kind, default factor) of a column, or None for an unknown one."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: cannot read the {what} ({exc})") from None
    reader = csv.reader(text.splitlines())
    rows = [(reader.line_num, cells) for cells in reader if any(c.strip() for c in cells) and not cells[0].lstrip().startswith("#")]
    if not rows:
        raise RecordingError(f"{path}: empty {what}")
    (header_line, header), body = rows[0], rows[1:]
    names, factors = [], []
    for j, cell in enumerate(header):
        m = HEADER_CELL.match(cell)
        known = kind_of(m.group(1)) if m else None
        if known is None:
            raise RecordingError(f"{path}: line {header_line}, column {j + 1}: {cell.strip()!r} is not a column of a {what}")
        if m.group(1) in names:
            raise RecordingError(f"{path}: line {header_line}: column {m.group(1)!r} appears twice")
        kind, default = known
        if m.group(2) is None:
            factors.append(default)
        else:
            try:
                factors.append(unit_factor(m.group(2), kind, 0))
            except ValueError as exc:
                raise RecordingError(f"{path}: line {header_line}, column {cell.strip()!r}: {exc}") from None
        names.append(m.group(1))
    for line, cells in body:
        if len(cells) != len(names):
            raise RecordingError(f"{path}: line {line}: {len(cells)} cells, the header has {len(names)} columns")
    try:  # all at once; cell by cell only to name a bad one
        data = np.array([[c if c.strip() else "nan" for c in cells] for _, cells in body], dtype=float).reshape(len(body), len(names))
    except ValueError:
        data = None
    for i, (line, cells) in enumerate(body if data is None or np.isinf(data).any() else ()):
        for j, cell in enumerate(cells):
            cell = cell.strip()
            try:
                value = np.nan if cell.lower() in _MISSING else float(cell)
            except ValueError:
                raise RecordingError(f"{path}: line {line}, column {names[j]!r}: {cell!r} is not a number") from None
            if np.isinf(value):
                raise RecordingError(f"{path}: line {line}, column {names[j]!r}: {cell!r} is not a finite number")
    return names, data * np.array(factors), np.array([line for line, _ in body], dtype=int)


def require_complete(path: Path, names, data, lines, columns) -> None:
    """Cells of ``columns`` (time, force) may not be empty: a RecordingError names the first empty one."""
    for name in columns:
        j = names.index(name)
        bad = np.flatnonzero(np.isnan(data[:, j]))
        if bad.size:
            raise RecordingError(f"{path}: line {lines[bad[0]]}, column {name!r}: empty or NaN (only marker columns may have gaps)")


def _csv_kind(length_default: float):
    def kind_of(name: str):
        if name == "t":
            return "time", 1.0
        if name in FORCES:
            return "force", 1.0
        stem, _, axis = name.rpartition("_")
        return ("length", length_default) if stem and axis in AXES else None

    return kind_of


def read_csv(path: Path, units: str) -> Recording:
    """A CSV recording (see the module docstring)."""
    names, data, lines = read_table(path, _csv_kind(length_factor(units, f"{path}: registration units")), "marker recording (t, NAME_x, NAME_y, NAME_z, ..., optional Fx, Fy, Fz)")
    if "t" not in names:
        raise RecordingError(f"{path}: no column 't' (time)")
    require_complete(path, names, data, lines, ["t"] + [f for f in FORCES if f in names])
    markers = list(dict.fromkeys(n.rpartition("_")[0] for n in names if n != "t" and n not in FORCES))
    if not markers:
        raise RecordingError(f"{path}: no marker columns (NAME_x, NAME_y, NAME_z)")
    for name in markers:
        missing = [f"{name}_{a}" for a in AXES if f"{name}_{a}" not in names]
        if missing:
            raise RecordingError(f"{path}: marker {name!r} lacks column(s) {', '.join(missing)}")
    positions = np.stack([np.column_stack([data[:, names.index(f"{m}_{a}")] for a in AXES]) for m in markers], axis=1)
    given = [f for f in FORCES if f in names]
    force = np.column_stack([data[:, names.index(f)] if f in given else np.zeros(len(lines)) for f in FORCES]) if given else None
    return Recording(str(path), "csv", data[:, names.index("t")], tuple(markers), positions, force, lines,
                     {"format": "csv", "columns": names})


def read_artisynth(path: Path, units: str) -> Recording:
    """An ArtiSynth numeric probe file (see the module docstring)."""
    factor = length_factor(units, f"{path}: registration units")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: cannot read the ArtiSynth probe file ({exc})") from None
    rows = [(i + 1, line.split("#", 1)[0].split()) for i, line in enumerate(text.splitlines())]
    rows = [(line, tokens) for line, tokens in rows if tokens]
    if len(rows) < 3:
        raise RecordingError(f"{path}: not an ArtiSynth probe file: expected a line 'start stop scale', a line "
                             "'interpolation vsize timestep|explicit' and one row per frame")
    (l1, head), (l2, kind), body = rows[0], rows[1], rows[2:]
    if len(head) != 3:
        raise RecordingError(f"{path}: line {l1}: expected 'start stop scale', found {len(head)} value(s)")
    start, stop = (_probe_time(path, l1, tok, name) for tok, name in zip(head[:2], ("start", "stop")))
    scale = _probe_number(path, l1, head[2], "scale")
    if not scale > 0 or not stop >= start:
        raise RecordingError(f"{path}: line {l1}: need stop >= start and scale > 0 (start {start:g} s, stop {stop:g} s, scale {head[2]})")
    if len(kind) != 3 or kind[0].lower() not in ARTISYNTH_INTERPOLATIONS:
        raise RecordingError(f"{path}: line {l2}: expected 'interpolation vsize timestep' or 'interpolation vsize explicit' "
                             f"with interpolation one of {', '.join(ARTISYNTH_INTERPOLATIONS)}, found {' '.join(kind)!r}")
    if not _INTEGER.match(kind[1]) or int(kind[1]) <= 0 or int(kind[1]) % 3:
        raise RecordingError(f"{path}: line {l2}: vsize {kind[1]!r} must be a positive multiple of 3 (x, y, z per marker)")
    vsize = int(kind[1])
    explicit = kind[2] == "explicit"
    step = None if explicit else _probe_number(path, l2, kind[2], "timestep")
    if step is not None and not step > 0:
        raise RecordingError(f"{path}: line {l2}: timestep {kind[2]} must be positive (or the keyword 'explicit')")
    width = vsize + explicit
    values = np.empty((len(body), width))
    for i, (line, tokens) in enumerate(body):
        if len(tokens) != width:
            raise RecordingError(f"{path}: line {line}: {len(tokens)} value(s), expected {width}"
                                 f"{' (the knot time, then vsize)' if explicit else ' (vsize)'}")
        for j, tok in enumerate(tokens):
            try:
                values[i, j] = float(tok)
            except ValueError:
                raise RecordingError(f"{path}: line {line}, column {j + 1}: {tok!r} is not a number") from None
            if np.isinf(values[i, j]) or (explicit and j == 0 and np.isnan(values[i, j])):
                raise RecordingError(f"{path}: line {line}, column {j + 1}: {tok!r} is not a finite number")
    t_probe = values[:, 0] if explicit else step * np.arange(len(body))
    t = start + scale * t_probe
    lines = np.array([line for line, _ in body], dtype=int)
    keep = (t >= start - 1e-12) & (t <= stop + 1e-9 * max(1.0, abs(stop)))
    data = values[:, int(explicit):] * factor
    markers = tuple(f"M{k + 1}" for k in range(vsize // 3))
    meta = {"format": "artisynth", "start_s": start, "stop_s": stop, "scale": scale, "interpolation": kind[0],
            "timestep_s": step, "knots_outside_start_stop": int((~keep).sum())}
    return Recording(str(path), "artisynth", t[keep], markers, data[keep].reshape(-1, vsize // 3, 3), None, lines[keep], meta)


def _probe_number(path: Path, line: int, token: str, what: str) -> float:
    try:
        value = float(token)
    except ValueError:
        raise RecordingError(f"{path}: line {line}: {what} {token!r} is not a number") from None
    if not np.isfinite(value):
        raise RecordingError(f"{path}: line {line}: {what} {token!r} is not a finite number")
    return value


def _probe_time(path: Path, line: int, token: str, what: str) -> float:
    """A probe's start or stop time: an integer is nanoseconds (ArtiSynth's older format), otherwise seconds."""
    return int(token) * 1e-9 if _INTEGER.match(token) else _probe_number(path, line, token, what)


def read_c3d(path: Path, units: str) -> Recording:
    """A C3D file through ezc3d (see the module docstring)."""
    import ezc3d

    try:
        c = ezc3d.c3d(str(path))
    except Exception as exc:  # ezc3d raises RuntimeError or ValueError with its own text for a file it cannot parse
        raise RecordingError(f"{path}: not a readable C3D file ({exc})") from None
    point = c["parameters"]["POINT"]
    labels = [str(s).strip() for s in point["LABELS"]["value"]]
    for extra in ("LABELS2", "LABELS3"):  # files with more than 255 markers continue the list
        labels += [str(s).strip() for s in point.get(extra, {}).get("value", [])]
    points = np.asarray(c["data"]["points"], dtype=float)  # (4, K, N), NaN where not seen
    if len(labels) < points.shape[1]:
        raise RecordingError(f"{path}: POINT:LABELS names {len(labels)} markers, the file has {points.shape[1]}")
    labels = labels[: points.shape[1]]
    if len(set(labels)) != len(labels):
        twice = sorted({s for s in labels if labels.count(s) > 1})
        raise RecordingError(f"{path}: POINT:LABELS repeats {', '.join(twice)}")
    unit = "".join(point.get("UNITS", {}).get("value", [""]) or [""]).strip() or units
    factor = length_factor(unit, f"{path}: POINT:UNITS")
    rate = float(np.ravel(point["RATE"]["value"])[0]) if "RATE" in point else float(c["header"]["points"]["frame_rate"])
    if not rate > 0:
        raise RecordingError(f"{path}: POINT:RATE is {rate}: the frame rate must be positive")
    positions = np.transpose(points[:3], (2, 1, 0)) * factor
    t = np.arange(positions.shape[0]) / rate
    return Recording(str(path), "c3d", t, tuple(labels), positions, None, None,
                     {"format": "c3d", "units": unit, "rate_hz": rate})


def known_length_units() -> tuple[str, ...]:
    """The length units files and registrations may use."""
    return tuple(UNITS["length"])
