"""A run: model + task -> kinematics (-> dynamics, coupling ...) -> validity checks -> a results folder.

A task is processed in chunks of consecutive samples (:data:`CHUNK_SAMPLES`): each chunk goes through every
stage, its rows are appended to results.csv, and what the run says about the whole task (the validity checks,
the formulation's indices and counts, the coupling means, the timings, the decimated view that the figures and
the report draw) is accumulated across the chunks. A task of any length therefore runs in constant memory and at
a constant cost per sample. Two things carry over from one chunk to the next: the crank angles' continuity
(theta continues from the previous chunk's last angle, as NumPy's unwrap of the whole task gives it) and the
formulation's :attr:`~chewbot.dynamics.base.Dynamics.carry` (the torque distribution's warm start from the
previous sample). A task in chunks gives the results of the whole task in one piece (tested: every column to
1e-12, the checks and run.json's numbers alike).

How the formulation's ``info`` combines across chunks is set per key in :data:`INFO_RULES` (sample indices are
shifted, counts added, means weighted by the chunk's samples); any other entry must be the same in every chunk.

The folder is written in a temporary sibling and moved into place at the end (:func:`chewbot.files.atomic_folder`):
a failed or interrupted run leaves nothing behind, and an existing folder is replaced only when ``force`` is
given and chewbot wrote it. The folder is written whatever the checks say; the command decides the exit code.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from chewbot.errors import KinematicsError, TaskError
from chewbot.model import Model
from chewbot.table import RunRecord, Table, kinematics_table, run_record
from chewbot.run.options import RunOptions, complete
from chewbot.kinematics.task import Task

if TYPE_CHECKING:
    from chewbot.analysis.checks import CheckResult
    from chewbot.kinematics.motion import Kinematics

__all__ = ["CHUNK_SAMPLES", "INFO_RULES", "RunOptions", "RunResult", "compute", "input_files", "load_task", "run",
           "run_json", "run_kernels", "write"]

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



# Samples per chunk. Large enough that the per-chunk overhead (a Python pass over the stages, the checks) is
# noise beside the compiled kernels' work; small enough that a chunk's arrays (the Newton-Euler data, about
# 250 numbers per sample, and every column) stay in the processor's caches' reach and a few tens of megabytes.
CHUNK_SAMPLES = 10_000


def load_task(spec: str, model: Model, side: str | None, overrides: dict[str, float] | None = None) -> Task:
    """``"default"`` (the synthetic chewing task, with ``overrides`` of its parameters) or the path of a CSV file;
    ``side`` None: left, or the side of the run whose results.csv the file is."""
    from chewbot.task.default import default_task, parameters_with

    if spec == "default":
        return default_task(model, side or "left", parameters_with(overrides) if overrides else None)
    if overrides:
        raise TaskError(f"{', '.join(f'--set task.{k}={v:g}' for k, v in overrides.items())}: the default task's "
                        f"parameters apply to --task default, not to {spec}")
    from chewbot.task.csvio import read_task_csv

    return read_task_csv(Path(spec), side=side, mechanism=model.mechanism)


def input_files(options: RunOptions) -> list[Path]:
    """The files a run reads (its task file, its parameter file), which its output must not contain."""
    from chewbot.model.params import BUILTIN_MODELS

    return [Path(p) for p in (options.task, options.model) if p not in ("default", *BUILTIN_MODELS)]


def run_kernels(model: Model, options: RunOptions) -> list:
    """The compiled kernels a run uses: the kinematics, the formulation's, and the inertia coupling's."""
    from chewbot.analysis.coupling import coupling_kernel
    from chewbot.dynamics.registry import formulation_kernels
    from chewbot.kinematics.functions import kinematics_kernel

    kernels = [kinematics_kernel(model.mechanism, options.orientation)]
    if options.method:
        kernels += formulation_kernels(model.mechanism, options.orientation, options.method, **options.formulation_options())
        kernels.append(coupling_kernel(model.mechanism))
    return kernels


def _inputs(options: RunOptions) -> tuple[RunOptions, Model, Task]:
    """The model and the task of a run, and its options complete (:func:`chewbot.run.options.complete`) with the side
    in effect (as run.json records them)."""
    from chewbot.model.params import load_model, split_overrides

    model_overrides, task_overrides = split_overrides(options.overrides)
    model = load_model(options.model, model_overrides)
    options = complete(options, model.has_hkp)
    task = load_task(options.task, model, options.side, task_overrides)
    return replace(options, side=task.side), model, task


# --- one chunk through the stages ------------------------------------------------------------------------


@dataclass
class Chunk:
    """Samples ``offset`` to ``offset + n - 1`` of the task through every stage: their kinematics, the results
    table's rows (``table``), the formulation's result and the coupling's means, and each stage's time."""

    offset: int
    kinematics: object  # Kinematics
    table: Table
    dynamics: object | None  # Dynamics
    coupling_means: dict | None
    timings: dict[str, float]

    @property
    def n(self) -> int:
        return self.table.n


def _kinematics(model: Model, task: Task, part: Task, offset: int, orientation: str, theta_before: np.ndarray | None):
    """The kinematics of the chunk ``part`` (samples from ``offset``), theta continued from ``theta_before`` (the
    previous chunk's last angles); an error names the task's sample (and the file's line)."""
    from chewbot.kinematics.motion import solve_kinematics

    try:
        kin = solve_kinematics(model, part, orientation)
    except KinematicsError as exc:
        sample = None if exc.sample is None else exc.sample + offset
        error = KinematicsError(exc.reason, sample, exc.chain, exc.time)
        if task.lines is not None and sample is not None:
            error = error.located(f"{task.source}: line {task.lines[sample]}")
        raise error from None
    theta = _continued(kin.theta, theta_before)
    return kin if theta is kin.theta else replace(kin, theta=theta)


def _continued(theta: np.ndarray, before: np.ndarray | None) -> np.ndarray:
    """Angles (n, 6) continuous within a chunk, the first in (-pi, pi] (as solve_kinematics gives them), continued
    from ``before``, the previous chunk's last angles: shifted by the whole turns that close the gap, as NumPy's
    unwrap of the whole task continues them."""
    if before is None:
        return theta
    turns = np.round((before - theta[0]) / (2 * np.pi))
    return theta + 2 * np.pi * turns if turns.any() else theta


def singularity_columns(table: Table, kin) -> None:
    """The transmission angles mu1..mu6 and kappa_J of the chains' Jacobian (docs/conventions.md)."""
    table.add_block([f"mu{i + 1}" for i in range(6)], np.arcsin(np.clip(kin.transmission, 0.0, 1.0)), "rad",
                    "transmission angle of chain i (90 deg best, 0 at the dead point)")
    table.add("kappa_J", kin.kappa, "1", "reciprocal condition number of the chains' Jacobian J_theta1, columns scaled (0: singular)")


def chunks(model: Model, task: Task, options: RunOptions, size: int | None = CHUNK_SAMPLES, progress=None,
           check: Callable[[], None] | None = None) -> Iterator[Chunk]:
    """The task through the stages, ``size`` samples at a time (None: in one piece), in order. ``progress(message,
    done=samples, stage=None)`` is told each stage (the first chunk's inverse dynamics as the stage ``dynamics``);
    ``check()`` is called inside the loops of the formulations where a library may swallow a signal, and raises to
    stop."""
    from chewbot.compiled.kernels import prepare_kernels

    step = _stepper(progress)
    size = task.n if size is None else int(size)
    if size < 1:
        raise ValueError(f"chunk size must be at least 1 sample, not {size}")
    prepare_kernels(run_kernels(model, options))
    o = options
    used = o.formulation_options()
    theta_end, carry = None, None
    for start in range(0, max(task.n, 1), size):
        timings: dict[str, float] = {}
        step("kinematics", done=start)
        t0 = time.perf_counter()
        kin = _kinematics(model, task, task.window(start, start + size), start, o.orientation, theta_end)
        theta_end = kin.theta[-1] if kin.n else theta_end
        table = kinematics_table(kin)
        singularity_columns(table, kin)
        timings["kinematics_s"] = time.perf_counter() - t0
        dyn = means = None
        if o.method:
            from chewbot.analysis.coupling import coupling
            from chewbot.dynamics.registry import inverse_dynamics

            step(f"inverse dynamics ({o.method})", done=start, stage="dynamics" if start == 0 else None)
            t0 = time.perf_counter()
            dyn = inverse_dynamics(model, kin, o.method, carry=carry, check=check, **used)
            carry = dyn.carry
            timings[f"dynamics_{o.method}_s"] = time.perf_counter() - t0
            table.add_block([f"tau{i + 1}" for i in range(6)], dyn.tau, "N*m", f"actuator torques ({o.method})")
            for name, values in dyn.table.columns.items():
                table.add(name, values, dyn.table.units[name], dyn.table.descriptions.get(name, ""))
            step("inertia coupling", done=start)
            t0 = time.perf_counter()
            c = coupling(model, kin)
            table.add_block([f"MCI{i + 1}" for i in range(6)], c.MCI, "1", "inertia coupling index of joint i (seed 000, Eq. 60)")
            means = c.means()
            timings["coupling_s"] = time.perf_counter() - t0
        yield Chunk(start, kin, table, dyn, means, timings)


# --- what the run says about the whole task -----------------------------------------------------------------


Parts = list[tuple[int, int, object]]  # (offset, samples, value) of each chunk


def _weighted_mean(parts: Parts):
    """Means over each chunk's samples (a number, a list, or a dict of either) as the mean over the whole task."""
    if len(parts) == 1:
        return parts[0][2]
    total = sum(n for _, n, _ in parts)
    first = parts[0][2]
    if isinstance(first, dict):
        return {key: _weighted_mean([(o, n, v[key]) for o, n, v in parts]) for key in first}
    if isinstance(first, (list, tuple)):
        return [_weighted_mean([(o, n, v[j]) for o, n, v in parts]) for j in range(len(first))]
    return float(sum(n * v for _, n, v in parts if n) / total) if total else float("nan")


def _shifted_samples(parts: Parts) -> list:
    """Sample indices (or entries with a "sample" key), each chunk's shifted by its offset, in order."""
    out = []
    for offset, _, entries in parts:
        for e in entries:
            out.append({**e, "sample": e["sample"] + offset} if isinstance(e, dict) else e + offset)
    return out


# How an entry of a formulation's info combines over the chunks (chewbot.dynamics: Dynamics.info).
INFO_RULES: dict[str, Callable[[Parts], object]] = {
    "indices": _weighted_mean,  # F1..F7: means over the samples
    "newton_iterations": lambda parts: max(v for _, _, v in parts),  # the samples converge independently
    "constrained_samples": lambda parts: sum(v for _, _, v in parts),
    "unconverged": _shifted_samples,
    "infeasible": _shifted_samples,
    "contact": lambda parts: merge_info(parts),  # the contact model, its entries by these rules
    "raised_samples": lambda parts: sum(v for _, _, v in parts),  # the unilateral fallback's raised N
}


def merge_info(parts: list[tuple[int, int, dict]]) -> dict:
    """One info from the chunks' infos (``(offset, samples, info)`` each) by :data:`INFO_RULES`; an entry without
    a rule must be equal in every chunk (a constant: the goal, the equations)."""
    if len(parts) == 1:
        return parts[0][2]
    merged = {}
    for key in parts[0][2]:
        values = [(o, n, info[key]) for o, n, info in parts]
        if key in INFO_RULES:
            merged[key] = INFO_RULES[key](values)
        elif all(v == values[0][2] for _, _, v in values):
            merged[key] = values[0][2]
        else:
            raise RuntimeError(f"the formulation's info {key!r} differs between chunks and chewbot.run.pipeline.INFO_RULES "
                               "has no rule to combine it")
    return merged


class Totals:
    """What a run reports about the whole task, accumulated chunk by chunk: the validity checks, the stages'
    times, the formulation's info and the coupling's means."""

    def __init__(self, model: Model, options: RunOptions):
        from chewbot.analysis.checks import RunChecks

        self.checks = RunChecks.for_model(model, options.contact)
        self.timings: dict[str, float] = {}
        self.dynamics: list[tuple[int, int, dict]] = []
        self.coupling: list[tuple[int, int, dict]] = []

    def add(self, chunk: Chunk) -> None:
        dyn = chunk.dynamics
        t0 = time.perf_counter()
        self.checks.update(chunk.offset, chunk.table.columns, dyn.info if dyn is not None else None)
        timings = {**chunk.timings, "checks_s": time.perf_counter() - t0}
        for key, value in timings.items():
            self.timings[key] = self.timings.get(key, 0.0) + value
        if dyn is not None and dyn.info:
            self.dynamics.append((chunk.offset, chunk.n, dyn.info))
        if chunk.coupling_means is not None:
            self.coupling.append((chunk.offset, chunk.n, chunk.coupling_means))

    def info(self) -> dict:
        """run.json's entries beside the checks: timings, the formulation's info, the coupling means."""
        out = {"timings": dict(self.timings)}
        if self.dynamics:
            out["dynamics"] = merge_info(self.dynamics)
        if self.coupling:
            out["coupling_means"] = _weighted_mean(self.coupling)
        return out


# --- a run in memory ---------------------------------------------------------------------------------------


def _joined(parts: list, cls):
    """Dataclass instances of consecutive chunks as one: arrays (and dicts of arrays) concatenated, the rest from
    the first."""
    if len(parts) == 1:
        return parts[0]
    values = {}
    for f in fields(cls):
        first = getattr(parts[0], f.name)
        if isinstance(first, np.ndarray):
            values[f.name] = np.concatenate([getattr(p, f.name) for p in parts])
        elif isinstance(first, dict) and first and all(isinstance(v, np.ndarray) for v in first.values()):
            values[f.name] = {k: np.concatenate([getattr(p, f.name)[k] for p in parts]) for k in first}
        else:
            values[f.name] = first
    return cls(**values)


def compute(options: RunOptions, progress=None, chunk: int | None = CHUNK_SAMPLES, check: Callable[[], None] | None = None) -> RunResult:
    """Compute a run in memory (no files), ``chunk`` samples at a time (None: the task in one piece; the results
    are the same)."""
    from chewbot.kinematics.motion import Kinematics

    step = _stepper(progress)
    step("task")
    options, model, task = _inputs(options)
    totals = Totals(model, options)
    parts = []
    for part in chunks(model, task, options, chunk, step, check):
        totals.add(part)
        parts.append(part)
    result = RunResult(options=options, model=model, task=task, kinematics=_joined([p.kinematics for p in parts], Kinematics),
                       table=Table.concat([p.table for p in parts]), info=totals.info())
    if options.method:
        from chewbot.dynamics.base import Dynamics

        dyn = [p.dynamics for p in parts]
        result.dynamics = replace(_joined(dyn, Dynamics), table=Table.concat([d.table for d in dyn]),
                                  info=result.info.get("dynamics", {}), carry=dyn[-1].carry)
    step("validity checks")
    result.checks = totals.checks.results()
    return result


def _stepper(progress):
    """The progress callback ``step(message, done=None, total=None)`` (samples done, of total), or one that does
    nothing."""
    return progress or (lambda msg, done=None, total=None, stage=None: None)


def run_json(result: RunResult) -> dict:
    """The run record (run.json) of a run computed in memory (:func:`chewbot.table.run_record`)."""
    return run_record(result.options, result.model, result.task, result.table, result.checks, result.info)


# --- writing a folder --------------------------------------------------------------------------------------


def _view_builder(model: Model, t: np.ndarray, contact: str):
    from chewbot.report.view import ViewBuilder, report_columns

    return ViewBuilder(t, derived=lambda columns: report_columns(model, columns, contact))


def _figures_and_report(record: Callable[[], dict], method: str | None, model: Model, view, folder: Path, figures: bool,
                        report: bool, step, beside: Path | None = None, contact: str = "") -> list[Path]:
    """Draw the figures and write report.html into ``folder`` (as asked); their paths. The figures are drawn beside
    the rest (:func:`chewbot.report.figures.drawn`): meanwhile ``record()`` gives the run's record as run.json has
    it (it may write what the figures do not need: the last rows, run.json), then the report is written from it
    (read back from JSON, NaN as null: a report drawn later from the folder is the same). The report links to
    results.csv, run.json, the figures drawn and those that ``beside`` (the folder these files will join) has."""
    from chewbot.report.figures import drawn, figure_jobs, figure_names
    from chewbot.report.html import write_report

    jobs = figure_jobs(view, method, folder, contact) if figures else []
    written = [folder / name for name, _ in jobs]
    with drawn(jobs, step):
        content = record()
        if report:
            step("writing report.html")
            linked = {name for name, _ in jobs} | {name for name in figure_names(view.columns, method)
                                                    if beside is not None and (beside / name).exists()}
            written.append(write_report(content, model, view, folder / "report.html",
                                        files=sorted(["results.csv", "run.json", *linked])))
    return written


def _write_record(record: dict, folder: Path) -> dict:
    """Write run.json into ``folder``; the record as it reads back."""
    from chewbot.files import to_json

    text = to_json(record)
    (folder / "run.json").write_text(text)
    return json.loads(text)


def write(result: RunResult, out: Path, force: bool = False, progress=None, figures: bool = True, report: bool = True) -> Path:
    """Write the results folder ``out`` (results.csv, run.json, figures, report.html) of a run computed in memory,
    atomically.

    Everything is written in a temporary sibling folder that replaces ``out`` only once complete: a failure or a
    signal at any step (a figure, the report) leaves ``out`` as it was. ``progress(message)`` is told each step.
    """
    from chewbot.files import RESULTS_FOLDER, atomic_folder

    step = _stepper(progress)
    out = Path(out)
    with atomic_folder(out, force, RESULTS_FOLDER, inputs=input_files(result.options)) as tmp:
        step("writing results.csv")
        result.table.to_csv(tmp / "results.csv")
        step("writing run.json", stage="writing")
        record = _write_record(run_json(result), tmp)
        view = _view_builder(result.model, result.task.t, result.options.contact)
        view.update(result.table)
        written = _figures_and_report(lambda: record, result.options.method, result.model, view.result(), tmp, figures, report, step,
                                      contact=result.options.contact)
    result.figures = [out / p.name for p in written if p.suffix == ".png"]
    return out


def run(options: RunOptions, out: Path, force: bool = False, progress=None, figures: bool = True, report: bool = True,
        chunk: int | None = CHUNK_SAMPLES, check: Callable[[], None] | None = None) -> RunRecord:
    """Compute a run chunk by chunk and write its folder ``out`` as it goes (what ``chewbot run`` does): each
    chunk's rows are appended to results.csv in the temporary folder, then run.json, the figures and report.html
    are written from what was accumulated. Atomic as :func:`write`. ``progress(message, done=samples, total=samples)``
    is told each stage."""
    from chewbot.files import RESULTS_FOLDER, atomic_folder
    from chewbot.table import CsvWriter

    step = _stepper(progress)
    step("task")
    options, model, task = _inputs(options)
    step("kinematics", done=0, total=task.n)
    out = Path(out)
    with atomic_folder(out, force, RESULTS_FOLDER, inputs=input_files(options)) as tmp:
        totals = Totals(model, options)
        view = _view_builder(model, task.t, options.contact)
        with CsvWriter(tmp / "results.csv") as csv:

            def rows(part: Chunk) -> None:
                step("writing results.csv", done=part.offset)
                t0 = time.perf_counter()
                csv.write(part.table)
                totals.timings["results_csv_s"] = totals.timings.get("results_csv_s", 0.0) + time.perf_counter() - t0

            last = None
            for part in chunks(model, task, options, chunk, step, check):
                totals.add(part)
                view.update(part.table)
                if last is not None:
                    rows(last)
                last = part
            checks = totals.checks.results()

            content = {}

            def record() -> dict:  # while the figures are drawn: the last chunk's rows, then run.json
                rows(last)
                csv.close()
                step("writing run.json", stage="writing")
                content.update(_write_record(run_record(options, model, task, last.table.rows(0, 0), checks, totals.info()), tmp))
                return content

            step("figures and report", done=task.n)
            written = _figures_and_report(record, options.method, model, view.result(), tmp, figures, report, step,
                                          contact=options.contact)
    return RunRecord(content, model, checks, view.result(), [out / "results.csv", out / "run.json", *(out / p.name for p in written)])



# --- figures and report of a results folder ----------------------------------------------------------------


def redraw(folder: Path, force: bool = False, figures: bool = True, report: bool = True, progress=None,
           chunk: int = CHUNK_SAMPLES) -> list[Path]:
    """Draw the figures and write report.html of the results folder ``folder`` from its run.json and results.csv
    (read ``chunk`` rows at a time: constant memory), as the run would have (``chewbot report DIR``).

    Only the figures and report.html are written (:func:`chewbot.files.atomic_members`: all or none, each under
    a temporary name until all are complete); results.csv and run.json are read, never written. An existing figure
    or report is replaced only with ``force``. The model is loaded from the parameter file run.json names, with
    the run's overrides, and must have the run's parameters (their SHA-256 in run.json)."""
    from chewbot.errors import ChewbotError
    from chewbot.model.vector import vector_digest
    from chewbot.files import RESULTS_FOLDER, atomic_members
    from chewbot.model.params import BUILTIN_MODELS, load_model, split_overrides
    from chewbot.report.figures import figure_names
    from chewbot.table import READABLE_FORMATS, read_csv_chunks

    step = _stepper(progress)
    folder = Path(folder)
    if not folder.is_dir():
        raise ChewbotError(f"{folder}: no such results folder")
    if not RESULTS_FOLDER.present(folder):
        raise _not_ours(folder)
    path = folder / "run.json"
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ChewbotError(f"{path}: cannot read it ({exc})") from None
    if record.get("chewbot_run") not in READABLE_FORMATS:
        raise ChewbotError(f"{path}: results format {record.get('chewbot_run')!r}; this chewbot reads "
                           f"{', '.join(map(str, READABLE_FORMATS))}")
    model_overrides, _ = split_overrides(record.get("overrides", {}))
    spec = record["model"]["file"]
    if not Path(spec).is_file() and record["model"]["name"] in BUILTIN_MODELS:
        spec = record["model"]["name"]  # a built-in model, from another installation
    model = load_model(spec, model_overrides)
    if record["model"].get("parameters_sha256") not in (None, vector_digest(model)):
        raise ChewbotError(f"{path}: the model {spec} (with the run's overrides) no longer has the run's parameters "
                           "(their SHA-256 differs): the figures and report would not show the run's robot")
    columns = record.get("columns", {})
    csv_path = folder / "results.csv"
    step("reading results.csv")
    t = np.array([float(line.partition(",")[0]) for line in _data_lines(csv_path)])
    if t.size != record["task"]["samples"]:
        raise ChewbotError(f"{csv_path}: {t.size} rows, run.json says {record['task']['samples']} samples")
    view = _view_builder(model, t, record["options"].get("contact", "bilateral"))
    units = {name: c.get("unit", "") for name, c in columns.items()}
    done = 0
    for part in read_csv_chunks(csv_path, units, chunk):
        step("reading results.csv", done=done, total=t.size)
        part.descriptions = {name: c["description"] for name, c in columns.items() if c.get("description") and name in part.columns}
        view.update(part)
        done += part.n
    view = view.result()
    method = record["options"].get("method")
    names = (figure_names(view.columns, method) if figures else []) + (["report.html"] if report else [])
    with atomic_members(folder, names, force) as tmp:
        _figures_and_report(lambda: record, method, model, view, tmp, figures, report, step, beside=folder,
                            contact=record["options"].get("contact", "bilateral"))
    return [folder / name for name in names]


def _data_lines(path: Path):
    """The lines of a CSV file after its header (comment and blank lines skipped)."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = (line for line in f if line.strip() and not line.lstrip().startswith("#"))
            next(lines, None)
            yield from lines
    except OSError as exc:
        from chewbot.errors import ChewbotError

        raise ChewbotError(f"{path}: cannot read it ({exc.strerror or exc})") from None


def _not_ours(folder: Path):
    from chewbot.files import RESULTS_FOLDER, OutputError

    return OutputError(f"{folder}: not a results folder written by chewbot (no {RESULTS_FOLDER.file} of chewbot's); "
                       "chewbot draws figures and reports into its own results folders only")
