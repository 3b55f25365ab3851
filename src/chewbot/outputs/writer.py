"""The one writer of a results folder's data, and the folders written with it.

:class:`ResultsWriter` writes results.csv chunk after chunk and then run.json, and builds, from the rows it is given,
the view that the figures and report.html are drawn from (:mod:`chewbot.report.folder`): the figures are drawn from
the rows as they are written (the last chunk's rows are written while the figures of the whole are drawn), the report
from run.json as written, and a folder drawn later (``chewbot report DIR``, :func:`redraw`) is drawn from the same
inputs read back. It is the one place where the data of a run or a simulation are written: a new format of the rows
goes here.

:func:`write_run` computes a run chunk by chunk (:func:`chewbot.run.pipeline.chunks`) and writes its folder as it
goes (what ``chewbot run`` does), in constant memory; :func:`write` writes a run computed in memory. Either folder
is written in a temporary sibling and moved into place at the end (:func:`chewbot.files.atomic_folder`): a failed or
interrupted run leaves nothing behind, and an existing folder is replaced only when ``force`` is given and chewbot
wrote it. The folder is written whatever the checks say; the command decides the exit code.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable

import numpy as np

from chewbot.errors import ChewbotError
from chewbot.files import RESULTS_FOLDER, OutputError, atomic_folder, atomic_members, to_json
from chewbot.model import Model
from chewbot.outputs.record import RunRecord, copy_inputs, read_record, run_record, with_copies
from chewbot.progress import SILENT, Progress
from chewbot.report.figures import Drawer, drawing_process
from chewbot.report.folder import draw, drawing_names, figures_drawn, write_page
from chewbot.report.view import RunView, ViewBuilder, report_columns
from chewbot.run.options import RunOptions
from chewbot.run.pipeline import CHUNK_SAMPLES, RunResult, Totals, chunks, input_files, inputs
from chewbot.table import CsvWriter, Table, read_csv_chunks

RESULTS_FILE = "results.csv"
RECORD_FILE = "run.json"
# The formats of a results folder's rows: the file each writes. Parquet (pyarrow, columnar, float64 as computed, no
# text conversion, plain encoding, uncompressed) has the columns of results.csv, named as its header cells (`tau1 [N*m]`), each field's unit and
# description in the field's metadata and the table of units in the schema's metadata (key ``chewbot_units``).
RESULTS_FILES = {"csv": RESULTS_FILE, "parquet": "results.parquet"}
# rows per Parquet row group: large enough for columnar compression, small enough to read a run back in chunks
PARQUET_ROW_GROUP = 100_000


class ParquetWriter:
    """results.parquet, one chunk of rows after another (a pyarrow ``ParquetWriter``), float64 columns named
    ``name [unit]`` with units and descriptions in the schema."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self._writer = None

    def _schema(self, table: Table):
        import pyarrow as pa

        from chewbot.units import column_header

        fields = [pa.field(column_header(name, table.units[name]), pa.float64(),
                           metadata={"name": name, "unit": table.units[name], "description": table.descriptions.get(name, "")})
                  for name in table.columns]
        return pa.schema(fields, metadata={"chewbot_units": json.dumps(table.units), "chewbot_version": _version()})

    def write(self, table: Table) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        if self._writer is None:
            self._schema_ = self._schema(table)
            # float64 results are noise to a dictionary and barely compress: encoding them plainly writes a million
            # rows of 61 columns about 5 times faster than the defaults (dictionary, snappy) at ~the same size
            self._writer = pq.ParquetWriter(self.path, self._schema_, compression="none", use_dictionary=False)
        columns = [pa.array(v, type=pa.float64()) for v in table.columns.values()]  # strided views read as they are
        self._writer.write_table(pa.Table.from_arrays(columns, schema=self._schema_), row_group_size=PARQUET_ROW_GROUP)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None


def _version() -> str:
    from chewbot.files import VERSION

    return VERSION


class ResultsWriter:
    """Writes the data of a results folder into ``folder``: :meth:`rows` for each chunk of rows in order
    (results.csv), then :meth:`record` (run.json), and keeps the view of the rows given (:meth:`view`).

    A chunk's rows go into the view at once and into the file when the next chunk comes or at :meth:`flush`, so that
    the view is whole before the last rows are written: a run draws its figures from it meanwhile.

    ``t``: the times of every row to come (the view chooses its animation's frames from them); ``derived``: further
    columns of a block of rows whose statistics the view keeps (:func:`chewbot.report.view.report_columns`);
    ``format``: the rows' file, csv (results.csv) or parquet (results.parquet), :data:`RESULTS_FILES`.
    ``seconds``: the time spent writing rows."""

    def __init__(self, folder: Path, t: np.ndarray, derived: Callable | None = None, format: str = "csv"):
        if format not in RESULTS_FILES:
            raise ValueError(f"results format must be one of {', '.join(RESULTS_FILES)}, not {format!r}")
        self.folder = Path(folder)
        self.format = format
        path = self.folder / RESULTS_FILES[format]
        self._csv = CsvWriter(path) if format == "csv" else ParquetWriter(path)
        self._view = ViewBuilder(t, derived=derived)
        self._pending: Table | None = None
        self.seconds = 0.0

    def rows(self, table: Table) -> None:
        """Append the rows of ``table`` (every chunk with the same columns): into the view now, into the file with
        the next chunk or at :meth:`flush`."""
        self._view.update(table)
        self.flush()
        self._pending = table

    def flush(self) -> None:
        """Write the rows given and not yet written."""
        if self._pending is not None:
            t0 = time.perf_counter()
            self._csv.write(self._pending)
            self.seconds += time.perf_counter() - t0
            self._pending = None

    def record(self, record: dict) -> dict:
        """Write the rows not yet written, close the rows' file and write run.json holding ``record`` and
        ``results_file``, the name of the rows' file; the record as it reads back (NaN as null), what the report is
        drawn from."""
        self.flush()
        self._csv.close()
        text = to_json({**record, "results_file": RESULTS_FILES[self.format]})
        (self.folder / RECORD_FILE).write_text(text)
        return json.loads(text)

    def view(self) -> RunView:
        """The view of the rows given (their decimated series and statistics, the animation's frames)."""
        return self._view.result()

    def close(self) -> None:
        self._csv.close()


def run_view_columns(model: Model, contact: str) -> Callable:
    """The derived columns of a run's view (the incisor, the bite force's magnitude, the normal forces below what the
    contact model admits)."""
    return lambda columns: report_columns(model, columns, contact)


def write_run(options: RunOptions, out: Path, force: bool = False, progress: Progress = SILENT, figures: bool = True,
              report: bool = True, chunk: int | None = CHUNK_SAMPLES, check: Callable[[], None] | None = None,
              format: str = "csv", drawer: Drawer | None = None) -> RunRecord:
    """Compute a run chunk by chunk and write its folder ``out`` as it goes (what ``chewbot run`` does): each chunk's
    rows go to results.csv (``format`` parquet: results.parquet) as they are computed; once the last chunk is
    computed, the figures are drawn from the view of every row (by a second process where there is a second core)
    while the last rows and run.json are written and report.html is drawn from run.json as written.
    ``progress(message, done=samples, total=samples, stage=None)`` is told each stage (run.json's writing as the stage
    ``writing``); ``check()``: see :func:`chewbot.run.pipeline.chunks`; ``drawer``: a drawing process forked before
    (:func:`chewbot.report.figures.drawing_process`; None: one is forked here)."""
    progress("task")
    options, model, task = inputs(options)
    progress("kinematics", done=0, total=task.n)
    out = Path(out)
    with atomic_folder(out, force, RESULTS_FOLDER, inputs=input_files(options)) as tmp, \
            drawing_process(figures and drawer is None) as forked:
        drawer = drawer or forked
        totals = Totals(model, options)
        writer = ResultsWriter(tmp, task.t, run_view_columns(model, options.contact), format)
        name = RESULTS_FILES[format]
        try:
            columns = None
            for part in chunks(model, task, options, chunk, progress, check):
                totals.add(part)
                progress(f"writing {name}", done=part.offset)
                writer.rows(part.table)
                columns = part.table.rows(0, 0)
            view = writer.view()
            progress("figures, the last rows and the report", done=task.n)
            with figures_drawn(tmp, view, options.method, options.contact, figures, progress, drawer) as pictures:
                writer.flush()
                totals.timings[f"results_{format}_s"] = writer.seconds
                checks = totals.checks.results()
                progress("writing run.json", done=task.n, stage="writing")
                copies = copy_inputs(tmp, {"model": model}, task)
                record = writer.record(with_copies(run_record(options, model, task, columns, checks, totals.info()), copies))
                page = [write_page(tmp, record, model, view, pictures, progress)] if report else []
        finally:
            writer.close()
    return RunRecord(record, model, checks, view, [out / name, out / RECORD_FILE, *(out / p.name for p in [*pictures, *page])])


def write_table(folder: Path, table: Table, record: dict, derived: Callable | None = None,
                progress: Progress = SILENT) -> tuple[dict, RunView]:
    """results.csv of a table computed whole and run.json of its ``record``, by :class:`ResultsWriter`; the record as
    it reads back and the view of the rows written, what the figures and report are drawn from."""
    writer = ResultsWriter(folder, table["t"], derived)
    try:
        progress("writing results.csv")
        writer.rows(table)
        writer.flush()
        progress("writing run.json", stage="writing")
        written = writer.record(record)
    finally:
        writer.close()
    return written, writer.view()


def write(result: RunResult, out: Path, force: bool = False, progress: Progress = SILENT, figures: bool = True,
          report: bool = True) -> Path:
    """Write the results folder ``out`` (results.csv, run.json, figures, report.html) of a run computed in memory
    (:func:`chewbot.run.pipeline.compute`), atomically as :func:`write_run`."""
    out = Path(out)
    with atomic_folder(out, force, RESULTS_FOLDER, inputs=input_files(result.options)) as tmp, drawing_process(figures) as drawer:
        copies = copy_inputs(tmp, {"model": result.model}, result.task)
        record, view = write_table(tmp, result.table, with_copies(run_json(result), copies),
                                   run_view_columns(result.model, result.options.contact), progress)
        draw(tmp, record, result.model, view, figures, report, progress, drawer=drawer)
    return out


def run_json(result: RunResult) -> dict:
    """The run record (run.json) of a run computed in memory (:func:`chewbot.outputs.record.run_record`)."""
    return run_record(result.options, result.model, result.task, result.table, result.checks, result.info)


# --- figures and report of a results folder ----------------------------------------------------------------


def redraw(folder: Path, force: bool = False, figures: bool = True, report: bool = True, progress: Progress = SILENT,
           chunk: int = CHUNK_SAMPLES) -> list[Path]:
    """Draw the figures and write report.html of the results folder ``folder`` from its run.json and results.csv
    (read ``chunk`` rows at a time: constant memory), as the run did (``chewbot report DIR``).

    Only the figures and report.html are written (:func:`chewbot.files.atomic_members`: all or none, each under
    a temporary name until all are complete); results.csv and run.json are read, never written. An existing figure
    or report is replaced only with ``force``. The model is loaded from the folder's copy of its parameter file
    (run.json's ``model.copy``; a folder written before the copies: the file run.json names), with the run's
    overrides, and must have the run's parameters (their SHA-256 in run.json)."""
    from chewbot.model.params import BUILTIN_MODELS, load_model, split_overrides
    from chewbot.model.vector import vector_digest

    folder = Path(folder)
    if not folder.is_dir():
        raise ChewbotError(f"{folder}: no such results folder")
    if not RESULTS_FOLDER.present(folder):
        raise OutputError(f"{folder}: not a results folder written by chewbot (no {RESULTS_FOLDER.file} of chewbot's); "
                          "chewbot draws figures and reports into its own results folders only")
    path = folder / RECORD_FILE
    record = read_record(folder)
    model_overrides, _ = split_overrides(record.get("overrides", {}))
    spec = str(folder / record["model"]["copy"]) if record["model"].get("copy") else record["model"]["file"]
    if not Path(spec).is_file() and record["model"]["name"] in BUILTIN_MODELS:
        spec = record["model"]["name"]  # a built-in model, from another installation
    model = load_model(spec, model_overrides)
    if record["model"].get("parameters_sha256") not in (None, vector_digest(model)):
        raise ChewbotError(f"{path}: the model {spec} (with the run's overrides) no longer has the run's parameters "
                           "(their SHA-256 differs): the figures and report would not show the run's robot")
    with drawing_process(figures) as drawer:  # loads matplotlib while results.csv is read
        columns = record.get("columns", {})
        name = record.get("results_file", RESULTS_FILE)
        rows_path = folder / name
        progress(f"reading {name}")
        units = {name: c.get("unit", "") for name, c in columns.items()}
        if name == RESULTS_FILES["parquet"]:
            t = read_parquet_column(rows_path, "t")
            parts = read_parquet_chunks(rows_path, units, chunk)
        else:
            t = np.array([float(line.partition(",")[0]) for line in _data_lines(rows_path)])
            parts = read_csv_chunks(rows_path, units, chunk)
        if t.size != record["task"]["samples"]:
            raise ChewbotError(f"{rows_path}: {t.size} rows, run.json says {record['task']['samples']} samples")
        view = ViewBuilder(t, derived=run_view_columns(model, record["options"].get("contact", "bilateral")))
        done = 0
        for part in parts:
            progress(f"reading {name}", done=done, total=t.size)
            part.descriptions = {name: c["description"] for name, c in columns.items() if c.get("description") and name in part.columns}
            view.update(part)
            done += part.n
        view = view.result()
        names = drawing_names(record, view, figures, report)
        with atomic_members(folder, names, force) as tmp:
            draw(tmp, record, model, view, figures, report, progress, beside=folder, drawer=drawer)
        return [folder / name for name in names]


def _parquet(path: Path):
    import pyarrow.parquet as pq

    try:
        return pq.ParquetFile(path)
    except (OSError, ValueError) as exc:
        raise ChewbotError(f"{path}: cannot read it as Parquet ({exc})") from None


def read_parquet_column(path: Path, name: str) -> np.ndarray:
    """One column of results.parquet by its name (without the unit), as float64."""
    f = _parquet(path)
    for i, field in enumerate(f.schema_arrow):
        if (field.metadata or {}).get(b"name", b"").decode() == name:
            return f.read(columns=[field.name]).column(0).to_numpy()
    raise ChewbotError(f"{path}: no column {name!r}")


def read_parquet_chunks(path: Path, units: dict[str, str] | None = None, chunk: int = CHUNK_SAMPLES):
    """results.parquet as :class:`Table` chunks of ``chunk`` rows, the columns named and united by the fields' metadata;
    ``units``: those run.json gives, which the file's must equal."""
    f = _parquet(path)
    fields = [(field.name, (field.metadata or {}).get(b"name", b"").decode(), (field.metadata or {}).get(b"unit", b"").decode())
              for field in f.schema_arrow]
    for header, name, unit in fields:
        if not name:
            raise ChewbotError(f"{path}: column {header!r} has no chewbot metadata (name, unit)")
        if units and name in units and units[name] != unit:
            raise ChewbotError(f"{path}: column {name!r} is in {unit!r}, run.json says {units[name]!r}")
    for batch in f.iter_batches(batch_size=chunk):
        part = Table()
        for j, (_, name, unit) in enumerate(fields):
            part.add(name, batch.column(j).to_numpy(), unit)
        yield part


def _data_lines(path: Path):
    """The lines of a CSV file after its header (comment and blank lines skipped)."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = (line for line in f if line.strip() and not line.lstrip().startswith("#"))
            next(lines, None)
            yield from lines
    except OSError as exc:
        raise ChewbotError(f"{path}: cannot read it ({exc.strerror or exc})") from None
