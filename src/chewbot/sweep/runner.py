"""Running chunks of evaluations on a Dask cluster and writing each as it arrives.

:func:`dask_client` gives a ``distributed`` client: on a ``LocalCluster`` of worker processes (one per core,
one thread each: the kernels hold the GIL while NumPy works between them) or on an existing cluster at a
scheduler's address. :class:`ChunkRunner` splits a design (the parameter values of n evaluations) into chunks
of the SPEC's size, as Dask's documentation advises for tasks of milliseconds (one task per chunk, so the
scheduler's overhead of about a millisecond per task is spread over dozens of evaluations), keeps a bounded
number of chunks in flight (the memory of the client does not grow with the number of evaluations), and writes
every finished chunk to the sweep folder as one Parquet file as soon as it arrives (:mod:`chewbot.sweep.record`).
A chunk whose file exists (a resumed sweep) is read back instead of computed, after checking that it holds the
same evaluations.
"""

from __future__ import annotations

import itertools
import logging
import os
import signal
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from chewbot.errors import ChewbotError
from chewbot.files import atomic_member, shield
from chewbot.progress import SILENT, Progress
from chewbot.sweep.record import SweepFolder

# Chunks in flight per worker thread: enough that a worker never waits for the client, few enough that the
# client holds little (a chunk's result is a few kilobytes).
IN_FLIGHT_PER_THREAD = 3
CLOSE_TIMEOUT_S = 20


def cores() -> int:
    """The cores this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


@contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, processes: bool = True):
    """A ``distributed.Client``: connected to ``scheduler`` (``tcp://HOST:PORT``), or to a new LocalCluster of
    ``workers`` processes (default: the cores) with one thread each. Closed (and the local cluster shut down)
    when the block ends, also on an error or a signal.

    The local workers are started with SIGINT and SIGTERM ignored: Ctrl-C on a terminal reaches the whole
    process group, and it is the client that stops them, cleanly, on its way out.
    """
    from distributed import Client, LocalCluster

    for name in ("distributed", "tornado", "bokeh"):
        logging.getLogger(name).setLevel(logging.ERROR)
    cluster = client = None
    try:
        if scheduler is not None:
            try:
                client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise ChewbotError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler there ({exc})") from None
        else:
            import dask

            handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
            # Dask sets MALLOC_TRIM_THRESHOLD_ = 64 KiB in its workers (memory back to the system early); an
            # evaluation allocates and frees arrays of the whole task, and the trimming made it about 15 % slower.
            # glibc's own threshold (dynamic, up to 32 MiB) still returns freed memory; one SPEC's evaluations do
            # not grow it. One thread per BLAS, as Dask sets.
            environ = {k: v for k, v in dask.config.get("distributed.nanny.pre-spawn-environ").items()
                       if k != "MALLOC_TRIM_THRESHOLD_"}
            try:
                for s in handlers:  # inherited by the worker processes as "ignored"
                    signal.signal(s, signal.SIG_IGN)
                with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
                    cluster = LocalCluster(n_workers=workers or cores(), threads_per_worker=1, processes=processes,
                                           dashboard_address=None, silence_logs=logging.ERROR,
                                           # no dashboard; the scheduler's small HTTP server on a free port, not on
                                           # 8787 (where another cluster on this machine may be)
                                           scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"})
            finally:
                for s, h in handlers.items():
                    signal.signal(s, h)
            client = Client(cluster)
        yield client
    finally:
        with shield():
            if client is not None:
                client.close(timeout=CLOSE_TIMEOUT_S)
            if cluster is not None:
                cluster.close(timeout=CLOSE_TIMEOUT_S)


def cluster_description(client) -> dict:
    """The workers and threads the client sees, and the scheduler's address."""
    threads = client.nthreads()
    return {"scheduler": client.scheduler.address, "workers": len(threads), "threads": int(sum(threads.values()))}


@dataclass
class Design:
    """The parameter values of ``n`` evaluations: ``rows(a, b)`` gives rows a..b-1 (n_keys columns), computed on
    demand so that a design of millions of evaluations need not be held at once. ``first``: the sample index of
    row 0 (the optimiser's generations follow one another)."""

    keys: tuple[str, ...]
    n: int
    rows: Callable[[int, int], np.ndarray]
    first: int = 0

    @classmethod
    def of(cls, keys, values: np.ndarray, first: int = 0) -> Design:
        values = np.asarray(values, dtype=float).reshape(-1, len(keys))
        return cls(tuple(keys), values.shape[0], lambda a, b: values[a:b], first)


class ChunkRunner:
    """Evaluates designs on the cluster in chunks, writing each finished chunk to the sweep folder.

    ``task(spec_payload, values) -> {column: (n,) array, "error": [str | None]}`` is the function mapped over the
    chunks (:func:`chewbot.sweep.evaluate.evaluate_chunk` for chewbot's model); ``units`` gives the unit of each
    output column (Parquet field metadata). ``progress("evaluations", done, total, stage=None)`` is told the
    evaluations done (after a chunk written to the folder, as the stage ``chunk``); ``check()`` is called as each chunk arrives, and raises
    to stop (a signal that Dask's machinery may swallow).
    """

    def __init__(self, client, folder: SweepFolder, task: Callable, payload, chunk: int, units: dict[str, str],
                 progress: Progress = SILENT, check: Callable[[], None] | None = None):
        self.client, self.folder, self.task, self.payload, self.chunk = client, folder, task, payload, chunk
        self.units = units
        self.progress = progress
        self.check = check or (lambda: None)
        self.reused = self.computed = 0  # chunks read back from an interrupted run, and chunks evaluated
        self.evaluations = 0
        self.compute_s = 0.0  # wall time spent evaluating (not reading chunks back)
        self.done = 0
        self.total = 0

    def run(self, design: Design, keep: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
        """Evaluate every row of ``design`` (or read its chunk back); returns the ``keep`` columns for all rows
        (``"error"`` as a boolean: the evaluation failed), nothing else stays in memory."""
        from distributed import as_completed

        kept = {name: np.full(design.n, np.nan) if name != "error" else np.zeros(design.n, bool) for name in keep}
        bounds = [(a, min(a + self.chunk, design.n)) for a in range(0, design.n, self.chunk)]
        self.total = max(self.total, self.done + design.n)
        pending = []
        for a, b in bounds:
            path = self.folder.chunk_path(design.first + a)
            if path.exists():
                self._keep(kept, a, self._read_back(path, design, a, b))
                self.reused += 1
                self._advance(b - a)
            else:
                pending.append((a, b))
        if not pending:
            return kept
        window = max(1, IN_FLIGHT_PER_THREAD * sum(self.client.nthreads().values()))
        started = time.perf_counter()
        queue = iter(pending)
        futures = {}
        flow = as_completed()
        try:
            for a, b in itertools.islice(queue, window):
                f = self._submit(design, a, b)
                futures[f] = (a, b)
                flow.add(f)
            for future in flow:
                self.check()
                a, b = futures.pop(future)
                columns = future.result()
                future.release()
                table = self._table(design, a, b, columns)
                with atomic_member(self.folder.chunk_path(design.first + a)) as tmp:
                    pq.write_table(table, tmp)
                self._keep(kept, a, table)
                self.computed += 1
                self.evaluations += b - a
                self._advance(b - a, stage="chunk")
                nxt = next(queue, None)
                if nxt is not None:
                    f = self._submit(design, *nxt)
                    futures[f] = nxt
                    flow.add(f)
        finally:
            if futures:
                with shield():
                    self.client.cancel(list(futures))
            self.compute_s += time.perf_counter() - started
        return kept

    def _submit(self, design: Design, a: int, b: int):
        return self.client.submit(self.task, self.payload, design.rows(a, b), pure=False)

    def _advance(self, n: int, stage: str | None = None) -> None:
        self.done += n
        self.progress("evaluations", done=self.done, total=self.total, stage=stage)

    def _table(self, design: Design, a: int, b: int, columns: dict) -> pa.Table:
        """A chunk's rows: ``sample``, the parameters (keys), the outputs (with their units), ``error``."""
        values = design.rows(a, b)
        fields, arrays = [pa.field("sample", pa.int64())], [pa.array(np.arange(design.first + a, design.first + b))]
        for j, key in enumerate(design.keys):
            fields.append(pa.field(key, pa.float64(), metadata={"unit": "the parameter file's (the key's suffix)"}))
            arrays.append(pa.array(values[:, j]))
        for name, col in columns.items():
            if name == "error":
                continue
            fields.append(pa.field(name, pa.float64(), metadata={"unit": self.units.get(name, "")}))
            arrays.append(pa.array(np.asarray(col, dtype=float)))
        fields.append(pa.field("error", pa.string()))
        arrays.append(pa.array(columns["error"], type=pa.string()))
        return pa.Table.from_arrays(arrays, schema=pa.schema(fields))

    def _read_back(self, path: Path, design: Design, a: int, b: int) -> pa.Table:
        """A chunk of an interrupted run, checked to hold the evaluations this design asks for."""
        try:
            table = pq.read_table(path)
        except (OSError, pa.ArrowException) as exc:
            raise ChewbotError(f"{path}: cannot read this chunk of the interrupted sweep ({exc}); remove it to compute it again") from None
        values = design.rows(a, b)
        same = (table.num_rows == b - a and all(k in table.column_names for k in design.keys)
                and all(np.array_equal(table.column(k).to_numpy(), values[:, j]) for j, k in enumerate(design.keys)))
        if not same:
            raise ChewbotError(f"{path}: this chunk holds other evaluations than the sweep asks for now (another version of "
                               "chewbot, NumPy, SciPy or SALib draws other samples?); start the sweep over with --force")
        return table

    @staticmethod
    def _keep(kept: dict, a: int, table: pa.Table) -> None:
        for name, arr in kept.items():
            col = table.column(name)
            if name == "error":
                arr[a:a + table.num_rows] = col.is_valid().to_numpy(zero_copy_only=False)
            else:
                arr[a:a + table.num_rows] = col.to_numpy(zero_copy_only=False)


def merge_chunks(folder: SweepFolder, path: Path) -> int:
    """Stream the chunk files, in the order of their samples, into one Parquet file (whole, by rename); returns
    the number of rows. One chunk is in memory at a time."""
    files = folder.chunk_files()
    rows = 0
    with atomic_member(path) as tmp:
        writer = None
        try:
            for f in files:
                table = pq.read_table(f)
                if writer is None:
                    writer = pq.ParquetWriter(tmp, table.schema)
                writer.write_table(table)
                rows += table.num_rows
        finally:
            if writer is not None:
                writer.close()
    return rows
