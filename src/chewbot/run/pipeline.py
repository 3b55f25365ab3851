"""One run: a model, a task and resolved options (:mod:`chewbot.run.options`) in, chunks of results with their checks
out. Every command that computes what a run computes goes through here or through the kernels beneath it:
``chewbot run`` writes the chunks as they come (:mod:`chewbot.outputs.writer`), a sweep evaluates one chunk per
parameter set (:mod:`chewbot.sweep.evaluate`), a simulation runs the kinematics of its motion and its reference
(:mod:`chewbot.simulation.run`).

A task is processed in chunks of consecutive samples (:data:`CHUNK_SAMPLES`): each :class:`Chunk` goes through the
stages (kinematics and the transmission angles; the formulation's inverse dynamics; the inertia coupling), each
stage computed when first asked, so a caller that needs only the kinematics pays for nothing else. What the run says
about the whole task (the validity checks, the formulation's indices and counts, the coupling means, the timings) is
accumulated across the chunks (:class:`Totals`). A task of any length therefore runs in constant memory and at a
constant cost per sample. Two things carry over from one chunk to the next: the crank angles' continuity (theta
continues from the previous chunk's last angle, as NumPy's unwrap of the whole task gives it) and the formulation's
:attr:`~chewbot.dynamics.base.Dynamics.carry` (the torque distribution's warm start from the previous sample), where
the formulation carries state (:attr:`chewbot.dynamics.registry.Formulation.carries`). A task in chunks gives the
results of the whole task in one piece (tested: every column to 1e-12, the checks and run.json's numbers alike).

How the formulation's ``info`` combines across chunks is set per key in :data:`INFO_RULES` (sample indices are
shifted, counts added, means weighted by the chunk's samples); any other entry must be the same in every chunk.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from chewbot.errors import KinematicsError, TaskError
from chewbot.kinematics.task import Task
from chewbot.model import Model
from chewbot.progress import SILENT, Progress
from chewbot.run.columns import kinematics_table, singularity_columns
from chewbot.run.options import RunOptions, complete
from chewbot.table import Table

if TYPE_CHECKING:
    from chewbot.analysis.checks import CheckResult
    from chewbot.analysis.coupling import Coupling
    from chewbot.dynamics.base import Dynamics
    from chewbot.kinematics.motion import Kinematics

# Samples per chunk. Large enough that the per-chunk overhead (a Python pass over the stages, the checks) is
# noise beside the compiled kernels' work; small enough that a chunk's arrays (the Newton-Euler data, about
# 250 numbers per sample, and every column) stay in the processor's caches' reach and a few tens of megabytes.
CHUNK_SAMPLES = 10_000


@dataclass
class RunResult:
    """What a run computed, in memory (its folder holds the same): the options in effect, the model and the task,
    the kinematics, the results table, ``info`` (run.json's timings, the formulation's info, the coupling means),
    the formulation's result and the validity checks."""

    options: RunOptions
    model: Model
    task: Task
    kinematics: Kinematics
    table: Table
    info: dict = field(default_factory=dict)
    dynamics: Dynamics | None = None
    checks: list[CheckResult] = field(default_factory=list)


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


def inputs(options: RunOptions, task: Task | None = None) -> tuple[RunOptions, Model, Task]:
    """The model and the task of a run, and its options complete (:func:`chewbot.run.options.complete`) with the side
    in effect (as run.json records them). ``task``: a task built in memory instead of ``options.task``."""
    from chewbot.model.params import load_model, split_overrides

    model_overrides, task_overrides = split_overrides(options.overrides)
    model = load_model(options.model, model_overrides)
    options = complete(options, model.has_hkp)
    if task is None:
        task = load_task(options.task, model, options.side, task_overrides)
    return replace(options, side=task.side), model, task


# --- one chunk through the stages ------------------------------------------------------------------------


class Chunk:
    """Samples ``offset`` to ``offset + n - 1`` of ``task`` through the stages of a run, each computed when first
    asked (in the run's order: a later stage asks for the earlier ones).

    ``kinematics`` (with theta continued from ``theta_before``, the previous chunk's last angles), ``columns`` (the
    kinematics' columns, the transmission angles and kappa_J, and with a formulation its torques and own columns:
    what the validity checks read), ``dynamics`` (the formulation's result, started from ``carry``, the previous
    chunk's :attr:`~chewbot.dynamics.base.Dynamics.carry`; None without inverse dynamics), ``coupling`` (the inertia
    coupling, with a formulation), ``table`` (the results table's rows: ``columns`` and MCI1..MCI6) and ``timings``
    (each stage's time). ``progress(message, done=samples, stage=None)`` is told each stage; ``check()`` is given to
    the formulation's loops that may swallow a signal."""

    def __init__(self, model: Model, task: Task, options: RunOptions, offset: int = 0, size: int | None = None,
                 theta_before: np.ndarray | None = None, carry: dict | None = None, progress: Progress = SILENT,
                 check: Callable[[], None] | None = None):
        self.model, self.task, self.options, self.offset = model, task, options, offset
        self.part = task if offset == 0 and (size is None or size >= task.n) else task.window(offset, offset + size)
        self.theta_before, self.carry, self.check = theta_before, carry, check
        self.progress = progress
        self.timings: dict[str, float] = {}

    @property
    def n(self) -> int:
        return self.part.n

    @cached_property
    def kinematics(self) -> Kinematics:
        self.progress("kinematics", done=self.offset)
        t0 = time.perf_counter()
        kin = _kinematics(self.model, self.task, self.part, self.offset, self.options.orientation, self.theta_before)
        self.timings["kinematics_s"] = time.perf_counter() - t0
        return kin

    @cached_property
    def dynamics(self) -> Dynamics | None:
        o = self.options
        if not o.method:
            return None
        from chewbot.dynamics.registry import inverse_dynamics

        kin = self.kinematics
        self.progress(f"inverse dynamics ({o.method})", done=self.offset, stage="dynamics" if self.offset == 0 else None)
        t0 = time.perf_counter()
        dyn = inverse_dynamics(self.model, kin, o.method, carry=self.carry, check=self.check, **o.formulation_options())
        self.timings[f"dynamics_{o.method}_s"] = time.perf_counter() - t0
        return dyn

    @cached_property
    def kinematic_columns(self) -> Table:
        """The kinematics' columns of results.csv with the transmission angles and kappa_J (no inverse dynamics);
        built when first asked (a sweep whose outputs need only the torques or the coupling never builds it), its
        time counted in the kinematics stage's."""
        kin = self.kinematics
        t0 = time.perf_counter()
        table = kinematics_table(kin)
        singularity_columns(table, kin)
        self.timings["kinematics_s"] += time.perf_counter() - t0
        return table

    @cached_property
    def columns(self) -> Table:
        base = self.kinematic_columns
        table = Table(columns=dict(base.columns), units=dict(base.units), descriptions=dict(base.descriptions))
        dyn = self.dynamics
        if dyn is not None:
            table.add_block([f"tau{i + 1}" for i in range(6)], dyn.tau, "N*m", f"actuator torques ({self.options.method})")
            for name, values in dyn.table.columns.items():
                table.add(name, values, dyn.table.units[name], dyn.table.descriptions.get(name, ""))
        return table

    @cached_property
    def coupling(self) -> Coupling | None:
        if not self.options.method:
            return None
        from chewbot.analysis.coupling import coupling

        kin = self.kinematics
        self.progress("inertia coupling", done=self.offset)
        t0 = time.perf_counter()
        c = coupling(self.model, kin)
        self.timings["coupling_s"] = time.perf_counter() - t0
        return c

    @cached_property
    def table(self) -> Table:
        columns = self.columns
        table = Table(columns=dict(columns.columns), units=dict(columns.units), descriptions=dict(columns.descriptions))
        if self.coupling is not None:
            table.add_block([f"MCI{i + 1}" for i in range(6)], self.coupling.MCI, "1", "inertia coupling index of joint i (seed 000, Eq. 60)")
        return table


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


def chunks(model: Model, task: Task, options: RunOptions, size: int | None = CHUNK_SAMPLES, progress: Progress = SILENT,
           check: Callable[[], None] | None = None) -> Iterator[Chunk]:
    """The task through every stage, ``size`` samples at a time (None: in one piece), in order: each chunk's
    ``table`` computed. ``progress(message, done=samples, stage=None)`` is told each stage (the first chunk's inverse
    dynamics as the stage ``dynamics``); ``check()`` is called inside the loops of the formulations where a library
    may swallow a signal, and raises to stop."""
    from chewbot.compiled.kernels import prepare_kernels

    size = task.n if size is None else int(size)
    if size < 1:
        raise ValueError(f"chunk size must be at least 1 sample, not {size}")
    prepare_kernels(run_kernels(model, options), progress=progress)
    theta_end, carry = None, None
    for start in range(0, max(task.n, 1), size):
        part = Chunk(model, task, options, start, size, theta_end, carry, progress, check)
        theta_end = part.kinematics.theta[-1] if part.table.n else theta_end
        carry = part.dynamics.carry if part.dynamics is not None else None
        yield part


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
        if chunk.coupling is not None:
            self.coupling.append((chunk.offset, chunk.n, chunk.coupling.means()))

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


def compute(options: RunOptions, progress: Progress = SILENT, chunk: int | None = CHUNK_SAMPLES,
            check: Callable[[], None] | None = None, task: Task | None = None) -> RunResult:
    """Compute a run in memory (no files), ``chunk`` samples at a time (None: the task in one piece; the results
    are the same). ``task``: a task built in memory instead of ``options.task``."""
    from chewbot.kinematics.motion import Kinematics

    progress("task")
    options, model, task = inputs(options, task)
    totals = Totals(model, options)
    parts = []
    for part in chunks(model, task, options, chunk, progress, check):
        totals.add(part)
        parts.append(part)
    result = RunResult(options=options, model=model, task=task, kinematics=_joined([p.kinematics for p in parts], Kinematics),
                       table=Table.concat([p.table for p in parts]), info=totals.info())
    if options.method:
        from chewbot.dynamics.base import Dynamics

        dyn = [p.dynamics for p in parts]
        result.dynamics = replace(_joined(dyn, Dynamics), table=Table.concat([d.table for d in dyn]),
                                  info=result.info.get("dynamics", {}), carry=dyn[-1].carry)
    progress("validity checks")
    result.checks = totals.checks.results()
    return result
