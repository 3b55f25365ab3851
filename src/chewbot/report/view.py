"""What the figures and the report draw of a run: its columns decimated, their statistics and a few whole rows.

A :class:`ViewBuilder` is given the results table chunk after chunk (``update(table)`` for each chunk of
consecutive rows, then ``result()``), so that a run of any length is drawn from a :class:`RunView` of bounded
size:

* ``series`` (the PNG figures): every sample, up to :data:`FULL_SERIES` samples; beyond, the min/max envelope of
  :data:`SERIES_BINS` bins of consecutive samples;
* ``plot`` (the report's interactive plots): every sample up to :data:`PLOT_POINTS`, beyond, the envelope of
  ``PLOT_POINTS / 2`` bins;
* ``rows``: whole rows at chosen samples (the report's animation frames, the 3D paths, the first sample);
* ``stats``: per column its minimum, maximum and peak (the largest magnitude, with its sign) with their times,
  its mean and RMS; ``first``: every column's value at the first sample; ``near_singular``: the runs of samples
  where a chain's transmission angle is below the threshold of the ``near-singular`` check.

The envelope keeps, per bin, the bin's smallest and largest value in the order they occur, drawn at the bin's
first and last time: no peak is lost however long the run (a peak is drawn at most one bin away from its time),
and a line through these points covers every sample's value.

The builder works on blocks of :data:`BLOCK` samples counted from the task's start, whatever the chunks it is
given: the same rows give the same view, to the last bit of the sums behind means and RMS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from chewbot.report.summary import ColumnStats, ColumnTotals, NearSingularRuns
from chewbot.table import Table

FULL_SERIES = 10_000  # samples drawn one by one in the PNG figures (about ten per pixel of an axis)
SERIES_BINS = 2_000  # bins of the PNG figures' envelope beyond that: 4000 points per line
PLOT_POINTS = 1_000  # points per line of the report's interactive plots
FRAME_STEP_S = 0.04  # the report's animation: one frame per 40 ms of task (25 per second: real time) ...
MAX_FRAMES = 250  # ... at most this many
PATH_POINTS = 1_000  # points of the incisor's and condyles' paths in the 3D figure
BLOCK = 8_192  # samples per block of the builder


def frame_samples(t: np.ndarray) -> np.ndarray:
    """Sample indices of the animation's frames: one per FRAME_STEP_S, at most MAX_FRAMES, last included."""
    duration = float(t[-1] - t[0])
    step = max(FRAME_STEP_S, duration / (MAX_FRAMES - 1))
    wanted = t[0] + step * np.arange(int(duration / step) + 1)
    after = np.searchsorted(t, wanted).clip(1, len(t) - 1)
    # the nearest sample, so that 1.64 s is the frame "1.640" even though 41 * 0.04 is 1.6400000000000001
    idx = np.unique(np.where(wanted - t[after - 1] <= t[after] - wanted, after - 1, after))
    return idx if idx[-1] == len(t) - 1 else np.append(idx, len(t) - 1)


def every_kth(n: int, points: int) -> np.ndarray:
    """Every k-th sample of n, k the smallest that keeps at most ``points`` (the last sample always kept)."""
    idx = np.arange(0, n, max(1, math.ceil(n / points)))
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


class Envelope:
    """The min/max envelope of columns over bins of ``size`` consecutive samples, built from consecutive rows."""

    def __init__(self, size: int):
        self.size = size
        self.t: list[np.ndarray] = []
        self.y: list[np.ndarray] = []
        self._pending: tuple[np.ndarray, np.ndarray] | None = None  # the rows of the bin not yet complete

    def add(self, t: np.ndarray, y: np.ndarray) -> None:
        """Rows ``t`` (m,) and ``y`` (m, k) that follow the ones added before."""
        if self.size == 1:
            self.t.append(t)
            self.y.append(y)
            return
        if self._pending is not None:
            t, y = np.concatenate([self._pending[0], t]), np.concatenate([self._pending[1], y])
        full = t.shape[0] // self.size * self.size
        self._bins(t[:full], y[:full])
        self._pending = (t[full:], y[full:]) if full < t.shape[0] else None

    def _bins(self, t: np.ndarray, y: np.ndarray) -> None:
        if not t.shape[0]:
            return
        m = t.shape[0] // self.size if t.shape[0] % self.size == 0 else 1
        size = t.shape[0] // m
        yb = y.reshape(m, size, y.shape[1])
        # NaN is neither the smallest nor the largest value; a bin of NaN alone gives NaN
        low = np.argmin(np.where(np.isnan(yb), np.inf, yb), axis=1)
        high = np.argmax(np.where(np.isnan(yb), -np.inf, yb), axis=1)
        first, second = np.minimum(low, high), np.maximum(low, high)
        pair = np.stack([np.take_along_axis(yb, first[:, None, :], 1)[:, 0], np.take_along_axis(yb, second[:, None, :], 1)[:, 0]], axis=1)
        tb = t.reshape(m, size)
        self.t.append(np.stack([tb[:, 0], tb[:, -1]], axis=1).reshape(-1))
        self.y.append(pair.reshape(2 * m, y.shape[1]))

    def result(self, names: list[str], like: Table) -> Table:
        """The envelope as a table of ``names`` (units and descriptions from ``like``), its times as ``t``."""
        if self._pending is not None:
            self._bins(*self._pending)
            self._pending = None
        t = np.concatenate(self.t) if self.t else np.zeros(0)
        y = np.concatenate(self.y) if self.y else np.zeros((0, len(names)))
        table = Table()
        for j, name in enumerate(names):
            table.add(name, t if name == "t" else y[:, j], like.units[name], like.descriptions.get(name, ""))
        return table


@dataclass(frozen=True, eq=False)
class RunView:
    """The view of a run's table (see the module docstring). ``rows`` holds every column at the samples
    ``row_samples`` (sorted); ``frames`` and ``paths`` are the samples of the animation and of the 3D paths;
    ``plot_bin``: samples per bin of ``plot`` (1: every sample)."""

    n: int
    series: Table
    plot: Table
    plot_bin: int
    rows: Table
    row_samples: np.ndarray
    frames: np.ndarray
    paths: np.ndarray
    stats: dict[str, ColumnStats]
    first: dict[str, float]
    near_singular: list

    def at(self, samples: np.ndarray) -> Table:
        """Every column at ``samples`` (among ``row_samples``)."""
        pos = np.searchsorted(self.row_samples, samples)
        if not np.array_equal(self.row_samples[pos.clip(0, len(self.row_samples) - 1)], samples):
            raise ValueError("the view keeps whole rows only at its frames, paths and first sample")
        out = Table(units=dict(self.rows.units), descriptions=dict(self.rows.descriptions))
        out.columns = {name: values[pos] for name, values in self.rows.columns.items()}
        return out

    @property
    def columns(self) -> list[str]:
        return list(self.rows.columns)


class ViewBuilder:
    """Builds the :class:`RunView` of a run's table from its chunks of consecutive rows (in order).

    ``t``: the task's times, all of them (the frames are chosen from them); ``derived``: a function of a block's
    columns giving further columns (name -> (values, unit)) whose statistics the view keeps (not drawn).
    """

    def __init__(self, t: np.ndarray, derived: Callable[[Mapping[str, np.ndarray]], dict] | None = None):
        self.n = len(t)
        self.frames = frame_samples(t) if self.n > 1 else np.arange(self.n)
        self.paths = every_kth(self.n, PATH_POINTS) if self.n else np.zeros(0, dtype=int)
        self.row_samples = np.union1d(np.union1d(self.frames, self.paths), [0] if self.n else []).astype(np.int64)
        self.series = Envelope(1 if self.n <= FULL_SERIES else math.ceil(self.n / SERIES_BINS))
        self.plot_bin = 1 if self.n <= PLOT_POINTS else math.ceil(self.n / (PLOT_POINTS // 2))
        self.plot = Envelope(self.plot_bin)
        self.derived = derived
        self._like: Table | None = None
        self._extra: Table | None = None
        self._totals: ColumnTotals | None = None
        self._near = NearSingularRuns()
        self._rows: list[np.ndarray] = []
        self._pending: list[Table] = []
        self._buffered = 0
        self._done = 0
        self._view: RunView | None = None
        self._first: dict[str, float] = {}

    def update(self, table: Table) -> None:
        """The next rows of the table (a Table, or a mapping of columns: then without units)."""
        if not isinstance(table, Table):
            table = Table(columns=dict(table), units={k: "" for k in table})
        if self._like is None:
            self._like = table.rows(0, 0)
        elif list(table.columns) != list(self._like.columns):
            raise ValueError("a chunk with other columns than the first")
        if table.n:
            self._pending.append(table)
            self._buffered += table.n
        while self._buffered >= BLOCK:
            self._flush(BLOCK)

    def _flush(self, rows: int) -> None:
        whole = Table.concat(self._pending) if len(self._pending) > 1 else self._pending[0]
        self._block(whole.rows(0, rows))
        rest = whole.rows(rows, whole.n)
        self._pending = [rest] if rest.n else []
        self._buffered = rest.n

    def _block(self, table: Table) -> None:
        start, m = self._done, table.n
        names = list(table.columns)
        y = np.column_stack([table.columns[n] for n in names]) + 0.0  # -0.0 as 0.0, as results.csv has it
        columns = dict(zip(names, y.T))
        extra = self.derived(columns) if self.derived else {}
        if self._extra is None:
            self._extra = Table()
            for name, (values, unit) in extra.items():
                self._extra.add(name, values[:0], unit)
            self._totals = ColumnTotals(len(names) + len(extra))
        t = columns["t"]
        every = np.column_stack([y] + [values for values, _ in extra.values()]) if extra else y
        self._totals.add(t, every)
        if start == 0:
            self._first = dict(zip(names + list(extra), every[0].tolist()))
        self.series.add(t, y)
        self.plot.add(t, y)
        picked = self.row_samples[(self.row_samples >= start) & (self.row_samples < start + m)] - start
        self._rows.append(y[picked])
        mu = [f"mu{i}" for i in range(1, 7)]
        if all(name in columns for name in mu):
            self._near.update(start, t, np.degrees(np.column_stack([columns[name] for name in mu])))
        self._done += m

    def result(self) -> RunView:
        if self._view is not None:
            return self._view
        if self._buffered:
            self._flush(self._buffered)
        like = self._like if self._like is not None else Table()
        names = list(like.columns)
        rows = np.concatenate(self._rows) if self._rows else np.zeros((0, len(names)))
        row_table = Table(units=dict(like.units), descriptions=dict(like.descriptions))
        row_table.columns = {name: rows[:, j] for j, name in enumerate(names)}
        stats = {}
        if self._totals is not None and self._totals.n:
            extra = self._extra
            stats = self._totals.stats(names + list(extra.columns), {**like.units, **extra.units})
        self._view = RunView(self.n, self.series.result(names, like), self.plot.result(names, like), self.plot_bin, row_table,
                             self.row_samples, self.frames, self.paths, stats, self._first, self._near.result())
        return self._view


def report_columns(model, columns: Mapping[str, np.ndarray], contact: str = "bilateral") -> dict[str, tuple[np.ndarray, str]]:
    """The further columns whose statistics the report shows: the incisor point I in {S} (from the pose), the
    bite force's magnitude, and where the run has normal forces, whether each is below what ``contact`` admits
    (:func:`chewbot.report.summary.below_columns`)."""
    from chewbot.report.summary import below_columns
    from chewbot.rotation import matrix_from_euler_angles

    R = matrix_from_euler_angles(np.column_stack([columns[name] for name in ("alpha", "beta", "gamma")]))
    incisor = np.column_stack([columns[name] for name in ("X", "Y", "Z")]) + R @ model.incisor
    force = np.sqrt(sum(np.asarray(columns[name]) ** 2 for name in ("Fx", "Fy", "Fz")))
    bound = model.contact.preload if contact == "unilateral" else 0.0
    return {**{f"incisor_{a}": (incisor[:, j], "m") for j, a in enumerate("xyz")}, "bite_force": (force, "N"),
            **below_columns(columns, bound)}
