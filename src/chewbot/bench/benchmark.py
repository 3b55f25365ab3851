"""Timing of every inverse-dynamics formulation, of a whole run and of the real-time kernels (``chewbot bench``).

Every timing is repeated, and the variants a table compares are run interleaved (one run of each in turn, then
again), so that a change of the machine's load meets them all alike; each is given as the median of its runs
with their interquartile range (the spread), and a ratio is given as the ratio of the medians with the range of
the ratios of the runs paired by their turn. Where the spreads of two timings overlap, the ratio says nothing
the noise could not have said: it is printed as "within noise" (:func:`compare`). The studies judge their timing
claims by the same rule.

Tables (:func:`benchmark`): the formulations on the whole default task (5001 samples, the kinematics computed
once and left out, the first call apart), with the plain references: the Newton–Euler torques in vectorised
NumPy (:func:`chewbot.bench.reference.frictionless_torques`) and the friction-aware G1 distribution by SciPy's SLSQP
with exact gradients, warm-started sample after sample (:func:`chewbot.bench.reference.slsqp_min_torque`, timed on a
stretch of :data:`SLSQP_SAMPLES` samples inside a bite and scaled to the task); ``chewbot run`` and ``chewbot
--help`` as a user waits for them (separate processes, warm kernel cache); the in-loop kernels
(:func:`chewbot.export.realtime.loop_kernel`) and the exported C (its example program, built with the flags of its
Makefile). With ``long``: runs of 10,000 to 1,000,000 samples, their time per sample and peak memory.
"""

from __future__ import annotations

import os
import re
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np

from chewbot.progress import SILENT, Progress

SLSQP_SAMPLES = 50  # consecutive samples from t = 2 s (inside a bite); SLSQP costs milliseconds each
BOTH = ("target", "6rss")
EA, EP = "euler-angles", "euler-parameters"
RUN_CASES = {"run, hessian": ["run"], "run, newton-euler G1 with friction": ["run", "--method", "newton-euler"],
             "chew, peanut, 25 cycles": ["chew", "--food", "peanut", "--cycles", "25"],
             "tpa, cheddar": ["tpa", "--food", "cheddar"]}
LONG_SAMPLES = (10_000, 100_000, 1_000_000)


# --- repeated, interleaved, paired --------------------------------------------------------------------------


@dataclass(frozen=True)
class Timing:
    """Repeated runs of one case: ``first_s`` (the first call: graph build, kernel load or compile), ``times`` (the
    further runs, in seconds, in their turn's order), ``samples`` it stands for (a per-sample time divides by it)."""

    label: str
    times: tuple[float, ...]
    first_s: float = float("nan")
    samples: int = 1

    @property
    def median(self) -> float:
        return statistics.median(self.times)

    @property
    def spread(self) -> tuple[float, float]:
        """The interquartile range of the runs (their middle half)."""
        q1, _, q3 = np.percentile(self.times, [25, 50, 75])
        return float(q1), float(q3)

    def per_sample(self, unit: float = 1e6) -> str:
        q1, q3 = self.spread
        return f"{self.median / self.samples * unit:.3g} ({q1 / self.samples * unit:.3g}–{q3 / self.samples * unit:.3g})"


def interleaved(runs: dict[str, Callable[[], object]], repeats: int, samples: dict[str, int] | None = None,
                scale: dict[str, float] | None = None, progress: Progress = SILENT) -> dict[str, Timing]:
    """Time each of ``runs`` once (its first call), then ``repeats`` times in turn: one run of each, in an order
    rotated from turn to turn, so that the runs of one turn are paired. ``scale``: a factor on a case's times (a
    part of the task timed for the whole); ``samples``: what each case computes."""
    first, times = {}, {label: [] for label in runs}
    for label, fn in runs.items():
        progress(f"{label}: first call")
        first[label] = _seconds(fn) * (scale or {}).get(label, 1.0)
    labels = list(runs)
    for turn in range(repeats):
        progress(f"turn {turn + 1} of {repeats}")
        for label in labels[turn % len(labels):] + labels[:turn % len(labels)]:
            times[label].append(_seconds(runs[label]) * (scale or {}).get(label, 1.0))
    return {label: Timing(label, tuple(times[label]), first[label], (samples or {}).get(label, 1)) for label in labels}


def _seconds(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


@dataclass(frozen=True)
class Comparison:
    """``a`` against ``b``: the ratio of the medians, the range of the ratios of the paired runs, and whether the
    two spreads overlap (then the difference is within the noise of the runs)."""

    a: Timing
    b: Timing

    @property
    def ratio(self) -> float:
        return self.a.median / self.b.median

    @property
    def within_noise(self) -> bool:
        (a1, a3), (b1, b3) = self.a.spread, self.b.spread
        return a1 <= b3 and b1 <= a3

    @property
    def paired(self) -> tuple[float, float]:
        ratios = np.array(self.a.times) / np.array(self.b.times)
        return float(np.percentile(ratios, 25)), float(np.percentile(ratios, 75))

    def text(self) -> str:
        lo, hi = self.paired
        value = "within noise" if self.within_noise else f"{self.ratio:.3g}"
        return f"{value} (medians {self.ratio:.3g}, paired runs {lo:.3g}–{hi:.3g})"


def compare(a: Timing, b: Timing) -> Comparison:
    """The rule by which chewbot judges a timing claim: ``a`` is faster or slower than ``b`` only where their
    spreads (interquartile ranges of the interleaved runs) do not overlap; else "within noise"."""
    if len(a.times) != len(b.times):
        raise ValueError("compared timings must come from the same interleaved runs")
    return Comparison(a, b)


# --- the formulations on the whole task --------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """A whole-task benchmark case: ``run(model, kin)`` on each of ``mechanisms`` in ``orientation``;
    ``samples``: the samples it computes when not all (then the times are scaled to the whole task)."""

    label: str
    run: Callable
    mechanisms: tuple[str, ...] = BOTH
    orientation: str = EA
    samples: int | None = None


def _slsqp(model, kin):
    from chewbot.bench.reference import slsqp_min_torque

    start = int(np.searchsorted(kin.t, 2.0))
    return slsqp_min_torque(model, kin, np.arange(start, start + SLSQP_SAMPLES))


def _g1_kernel(model, kin):
    from chewbot.dynamics.g1 import g1_distribution

    return g1_distribution(model, kin)


def _recording_fit(model, kin):
    """chewbot import-motion's fit to the robot, on the task's poses as if recorded (unconstrained, exact)."""
    from chewbot.recordings.fit import fit_to_robot
    from chewbot.rotation import matrix_from_euler_angles

    return fit_to_robot(model, kin.X[:, :3], matrix_from_euler_angles(kin.X[:, 3:]))


def _dynamics(method: str, **options):
    from chewbot.dynamics.registry import inverse_dynamics

    return partial(inverse_dynamics, method=method, **options)


def _core_terms(model, kin):
    from chewbot.dynamics.formulations.core6rss import core_terms

    return core_terms(model, kin)


def _numpy_reference(model, kin):
    from chewbot.bench.reference import frictionless_torques

    return frictionless_torques(model, kin)


SLSQP_LABEL = f"reference: SciPy SLSQP G1, exact gradients, warm start (timed on {SLSQP_SAMPLES} samples, scaled)"


def _simulate(model, kin):
    """chewbot simulate's loop: computed torque (Hessian, exact model) at 1 kHz along the task, plant without friction."""
    from chewbot.simulation.controllers.law import make_controller
    from chewbot.simulation.controllers.table import DEFAULT_CONTROLLER, controller_row
    from chewbot.simulation.plant import Plant
    from chewbot.simulation.reference import Reference
    from chewbot.simulation.simulator import simulate

    reference = Reference(kin.t, *kin.euler_angle_state(), kin.force, kin.side)
    controller = make_controller(controller_row(DEFAULT_CONTROLLER), model, reference)
    return simulate(Plant(model), controller, reference, rate=1000.0)


TASK_CASES: tuple[Case, ...] = (
    Case("hessian", _dynamics("hessian")),
    Case("liang", _dynamics("liang")),
    Case("lagrange", _dynamics("lagrange")),
    Case("6rss-core", _dynamics("6rss-core")),
    Case("6rss-core with M_f, C_f, G_f", _core_terms),
    Case("reference: NumPy Newton-Euler", _numpy_reference),
    Case("newton-euler G1 (EA)", _dynamics("newton-euler", goal="min-torque")),
    Case("newton-euler G1 (EP)", _dynamics("newton-euler", goal="min-torque"), orientation=EP),
    Case("newton-euler G2 (EA)", _dynamics("newton-euler", goal="min-coupler-force"), ("target",)),
    Case("newton-euler G2 (EP)", _dynamics("newton-euler", goal="min-coupler-force"), ("target",), EP),
    Case("newton-euler G3 (EA)", _dynamics("newton-euler", goal="min-hkp-force"), ("target",)),
    Case("newton-euler G3 (EP)", _dynamics("newton-euler", goal="min-hkp-force"), ("target",), EP),
    Case("G1 kernel, friction (EP)", _g1_kernel, ("target",), EP),
    Case("import-motion: fit to the robot", _recording_fit),
    Case("simulate: computed torque at 1 kHz", _simulate),
    Case(SLSQP_LABEL, _slsqp, ("target",), EA, SLSQP_SAMPLES),
)

# (numerator, denominator) of the ratios printed, per mechanism where both ran.
RATIOS = (
    ("hessian", "liang"),
    ("lagrange", "liang"),
    ("6rss-core", "hessian"),
    ("newton-euler G1 (EP)", "newton-euler G1 (EA)"),
    ("newton-euler G2 (EP)", "newton-euler G2 (EA)"),
    ("newton-euler G3 (EP)", "newton-euler G3 (EA)"),
    ("hessian", "reference: NumPy Newton-Euler"),
    ("6rss-core", "reference: NumPy Newton-Euler"),
    ("6rss-core with M_f, C_f, G_f", "reference: NumPy Newton-Euler"),
    ("G1 kernel, friction (EP)", SLSQP_LABEL),
    ("newton-euler G1 (EA)", SLSQP_LABEL),
)


def bench_task(repeats: int = 11, cases: tuple[Case, ...] = TASK_CASES, side: str = "left", progress: Progress = SILENT) -> dict[str, Timing]:
    """Time every case on its mechanisms on the default task, interleaved (:func:`interleaved`); keys
    ``"MECHANISM: LABEL"``. Models are loaded fresh, so the first call of a case includes building its graph and
    loading (or compiling) its kernel."""
    from chewbot.kinematics.motion import solve_kinematics
    from chewbot.model.params import load_model
    from chewbot.task.default import default_task

    models = {name: load_model(name) for name in BOTH}
    kins: dict[tuple[str, str], object] = {}
    runs, samples, scale = {}, {}, {}
    for case in cases:
        for name in case.mechanisms:
            key = (name, case.orientation)
            if key not in kins:
                kins[key] = solve_kinematics(models[name], default_task(models[name], side), case.orientation)
            label = f"{name}: {case.label}"
            runs[label] = partial(case.run, models[name], kins[key])
            samples[label] = kins[key].n
            scale[label] = kins[key].n / (case.samples or kins[key].n)
    return interleaved(runs, repeats, samples, scale, progress)


def ratios(timings: dict[str, Timing]) -> dict[str, Comparison]:
    """The comparisons of :data:`RATIOS` per mechanism, and target against 6RSS per case."""
    out = {}
    for mech in BOTH:
        for a, b in RATIOS:
            if f"{mech}: {a}" in timings and f"{mech}: {b}" in timings:
                out[f"{mech}: {a} / {b}"] = compare(timings[f"{mech}: {a}"], timings[f"{mech}: {b}"])
    for case in dict.fromkeys(label.split(": ", 1)[1] for label in timings):
        if f"target: {case}" in timings and f"6rss: {case}" in timings:
            out[f"{case}: target / 6rss"] = compare(timings[f"target: {case}"], timings[f"6rss: {case}"])
    return out


# --- what a user waits for: chewbot run, chewbot --help ------------------------------------------------------


def _chewbot(*args: str) -> list[str]:
    """The command line of ``chewbot ARGS`` as a user runs it: the installed script beside this Python, else
    ``python -m chewbot``."""
    script = Path(sys.executable).with_name("chewbot")
    return [str(script), *args] if script.is_file() else [sys.executable, "-m", "chewbot", *args]


def bench_commands(repeats: int = 7, progress: Progress = SILENT) -> dict[str, Timing]:
    """Wall time of ``chewbot run`` on the default task (Hessian; Newton–Euler G1 with friction), of ``chewbot chew``
    (the peanut, 25 cycles), of ``chewbot tpa`` (the cheddar, the default protocol: two simulations, the estimate,
    the folder), all outputs, warm kernel cache, and of ``chewbot --help``: separate processes, interleaved."""
    with tempfile.TemporaryDirectory() as tmp:
        runs = {label: partial(_quiet, _chewbot(*args, "--out", str(Path(tmp) / f"run{k}"), "--force", "-q"))
                for k, (label, args) in enumerate(RUN_CASES.items())}
        runs["chewbot --help"] = partial(_quiet, _chewbot("--help"))
        return interleaved(runs, repeats, progress=progress)


def _quiet(command: list[str]) -> None:
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


# --- reading inputs: a long task file, a long robot log -----------------------------------------------------

CSV_ROWS = 400_000  # an hour's log at 1 kHz is 3.6 million rows; a task this long a minute's chewing at ~7 kHz


def bench_csv(rows: int = CSV_ROWS, repeats: int = 7, progress: Progress = SILENT) -> dict[str, Timing]:
    """Wall time of reading a task CSV (:func:`chewbot.task.csvio.read_task_csv`: the default task with more cycles,
    its rates and bite force as ``track-incisor`` writes a task, 16 columns) and a robot log
    (:func:`chewbot.identification.log.read_log`: t, theta1..6, tau1..6) of about ``rows`` rows each, every number
    written in its shortest exact form (17 significant digits at most), interleaved."""
    from chewbot.identification.log import ANGLES, TORQUES, read_log
    from chewbot.model.params import load_model
    from chewbot.table import Table
    from chewbot.task.csvio import read_task_csv, task_table
    from chewbot.task.default import default_task, parameters_with

    with tempfile.TemporaryDirectory() as tmp:
        progress(f"writing a task and a robot log of {rows:,} rows")
        task = default_task(load_model("target"), "left", parameters_with({"cycles": long_cycles(rows)}))
        task_path, log_path = Path(tmp) / "task.csv", Path(tmp) / "log.csv"
        task_table(task).to_csv(task_path)
        log = Table()
        log.add("t", task.t, "s")
        log.add_block(ANGLES, np.column_stack([task.q, task.dq[:, :2]]), "rad")  # numbers of a log's magnitudes
        log.add_block(TORQUES, np.column_stack([task.dq, task.ddq[:, :2]]) * 1e-2, "N*m")
        log.to_csv(log_path)
        runs = {f"task CSV, {task.n:,} rows x 16 columns": partial(read_task_csv, task_path),
                f"robot log CSV, {task.n:,} rows x 13 columns": partial(read_log, log_path)}
        return interleaved(runs, repeats, {label: task.n for label in runs}, progress=progress)


def csv_markdown(timings: dict[str, Timing]) -> str:
    """The table of :func:`bench_csv`."""
    lines = ["Reading inputs (pyarrow's CSV reader: columnar, memory-mapped, correctly rounded; every check of the file "
             "included):", "", "| file | wall time (s) | per row (us) | runs |", "|---|---|---|---|"]
    for t in timings.values():
        q1, q3 = t.spread
        lines.append(f"| {t.label} | {t.median:.3f} ({q1:.3f}–{q3:.3f}) | {t.per_sample()} | {len(t.times)} |")
    return "\n".join(lines) + "\n"


# --- one sample: the in-loop kernels and the exported C -----------------------------------------------------


def bench_loop(calls: int = 20000, repeats: int = 11) -> dict[str, Timing]:
    """One call of each in-loop kernel (:func:`chewbot.export.realtime.loop_kernel`) of the target on a sample inside a
    bite, per call over ``calls // repeats`` calls per turn; beside it a :class:`~chewbot.compiled.kernels.NativeFunction`
    call of the same compiled kernel (inputs given as arrays and copied in, outputs copied out), interleaved."""
    from chewbot.compiled.kernels import native
    from chewbot.model.params import load_model
    from chewbot.export.realtime import LOOP_FLAGS, example_inputs, loop_kernel, loop_spec

    target = load_model("target")
    ex = example_inputs(target, load_model("6rss"))
    per_turn = max(calls // repeats, 1)
    runs, samples = {}, {}
    for kind, sample in (("tau", ex["tau_target"]), ("dynamics", ex["tau_target"]), ("g1", ex["g1_target"])):
        k = loop_kernel(target, kind)
        for name, value in sample.items():
            k.inputs[name][:] = np.ravel(value, order="F")
        fn = native(loop_spec(target, kind), LOOP_FLAGS)
        args = [sample[name] for name in k.inputs]
        runs[f"in-loop {kind}"] = partial(_repeat, k, per_turn)
        runs[f"NativeFunction call {kind}"] = partial(_repeat, partial(fn, *args), per_turn)
        samples[f"in-loop {kind}"] = samples[f"NativeFunction call {kind}"] = per_turn
    return interleaved(runs, repeats, samples)


def _repeat(fn, n: int) -> None:
    for _ in range(n):
        fn()


def bench_export(calls: int = 200000, repeats: int = 7) -> tuple[str, list[Timing]]:
    """The exported C (:func:`chewbot.export.c.export_c`) built by its own Makefile and its example program run
    ``repeats`` times with ``calls`` calls of each kernel, pinned to one core: (the compiler and flags, a timing per
    kernel, in ns per call, with the median, p99 and maximum of single calls)."""
    from chewbot.compiled.kernels import c_compiler
    from chewbot.export.c import export_c
    from chewbot.model.params import load_model
    from chewbot.export.realtime import kernels

    cc = c_compiler()
    if cc is None:
        return "no C compiler", []
    with tempfile.TemporaryDirectory() as tmp:
        folder = export_c(kernels(load_model("target"), load_model("6rss")), Path(tmp) / "kernels")
        subprocess.run(["make", "-s", "-C", str(folder), "example"], check=True, capture_output=True, env={**os.environ, "CC": cc})
        flags = (folder / "Makefile").read_text().split("CFLAGS ?= ", 1)[1].splitlines()[0]
        runs: dict[str, list[float]] = {}
        singles: dict[str, list[tuple[float, float, float]]] = {}
        for _ in range(repeats):
            out = subprocess.run([str(folder / "example"), str(calls)], check=True, capture_output=True, text=True,
                                 preexec_fn=_pin_to_one_core).stdout
            for line in out.splitlines():
                if line.startswith("time "):
                    # time NAME MEAN ns/call median MEDIAN p99 P99 max MAX
                    words = line.split()
                    runs.setdefault(words[1], []).append(float(words[2]))
                    singles.setdefault(words[1], []).append((float(words[5]), float(words[7]), float(words[9])))
    version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    return f"{version}, {flags}", [ExportTiming(name, tuple(values), single=single_calls(singles[name])) for name, values in runs.items()]


def _pin_to_one_core() -> None:
    """Run the example program on one core, the last this process may use (no migration between cores)."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {max(os.sched_getaffinity(0))})


@dataclass(frozen=True)
class ExportTiming(Timing):
    """A kernel of the exported C: the mean time per call of each run (ns, :class:`Timing`) and ``single``, the
    median, 99th percentile and maximum of its single calls (ns): the median over the runs of each run's median
    and 99th percentile, the largest of the maxima."""

    single: tuple[float, float, float] = (np.nan, np.nan, np.nan)


def single_calls(per_run: list[tuple[float, float, float]]) -> tuple[float, float, float]:
    """Median, p99, maximum over runs of the single calls' (median, p99, max) of each run."""
    a = np.array(per_run)
    return float(np.median(a[:, 0])), float(np.median(a[:, 1])), float(a[:, 2].max())


# --- the exported controller step --------------------------------------------------------------------------

# The exported step's cases: label, chewbot simulate options (the controller exported), and its budget (us): the share
# of a 1 kHz tick the step may take beside the rest of a robot's loop.
STEP_CASES = (("computed torque, Hessian (minimum-norm)", {"method": "hessian"}, 25.0),
              ("computed torque, Newton-Euler G1 with friction", {"method": "newton-euler", "friction": "on"}, 60.0))


@dataclass(frozen=True)
class StepTiming:
    """The exported controller step timed by its example program over ``steps`` calls pinned to ``core``: median, 99th
    percentile and maximum time per step (us)."""

    label: str
    median_us: float
    p99_us: float
    max_us: float
    steps: int
    core: int
    budget_us: float


def bench_controller(passes: int = 20, core: int | None = None, progress: Progress = SILENT) -> tuple[str, list[StepTiming]]:
    """Export each of :data:`STEP_CASES` (``chewbot export-controller``, default task, its log from a simulation), build
    it with its Makefile (-std=c99 ... -O2) and run its example over the log ``passes`` times in a process pinned to
    one core (``os.sched_setaffinity``; ``core`` None: the last this process may use): (the compiler and flags, the
    timings)."""
    from chewbot.compiled.kernels import c_compiler
    from chewbot.export.controller import StepSpec, export_controller, simulation_log
    from chewbot.simulation.options import resolve
    from chewbot.simulation.run import build, compute

    cc = c_compiler()
    if cc is None:
        return "no C compiler", []
    core = max(os.sched_getaffinity(0)) if core is None else core
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, options, budget in STEP_CASES:
            progress(f"exporting the controller step: {label}")
            opts = resolve(sensor="measured", **options)
            controller = build(opts).controller
            folder = export_controller(StepSpec.of(controller, 1000.0), Path(tmp) / options["method"],
                                       log=simulation_log(compute(opts)))
            subprocess.run(["make", "-s", "-C", str(folder), "example/example"], check=True, capture_output=True, env={**os.environ, "CC": cc})
            done = subprocess.run([str(folder / "example" / "example"), str(folder / "example" / "log.csv"), str(passes)], check=True,
                                  capture_output=True, text=True, preexec_fn=lambda: os.sched_setaffinity(0, {core}))
            found = re.search(r"over (\d+) steps: median ([\d.]+) us, p99 ([\d.]+) us, max ([\d.]+) us", done.stdout)
            out.append(StepTiming(label, float(found[2]), float(found[3]), float(found[4]), int(found[1]), core, budget))
        flags = (folder / "Makefile").read_text().split("CFLAGS ?= ", 1)[1].splitlines()[0]
    version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    return f"{version}, {flags}", out


def step_markdown(compiler: str, timings: list[StepTiming]) -> str:
    if not timings:
        return f"The exported controller step: not timed ({compiler}).\n"
    lines = [f"The exported controller step (`chewbot export-controller`, default task; its example program over its log, "
             f"pinned to core {timings[0].core}, {compiler}):", "",
             "| controller | median (us) | p99 (us) | max (us) | steps | budget of p99 (us) |", "|---|---|---|---|---|---|"]
    lines += [f"| {t.label} | {t.median_us:.2f} | {t.p99_us:.2f} | {t.max_us:.1f} | {t.steps} | {t.budget_us:g} |" for t in timings]
    return "\n".join(lines) + "\n"


# --- long runs -----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LongRun:
    """``chewbot run`` of a task of ``samples`` samples: its wall time, the time of its stages over the samples
    (run.json's timings: kinematics, dynamics, coupling, checks, results.csv; the part that grows with the task),
    and the peak memory (maximum resident set) of its processes."""

    method: str
    samples: int
    wall_s: float
    stages_s: float
    peak_mb: float

    @property
    def per_sample_us(self) -> float:
        return 1e6 * self.stages_s / self.samples


def long_cycles(samples: int) -> int:
    """Chewing cycles of the default task (1 s of rest, 0.8 s per cycle at 1 kHz) that give about ``samples``."""
    return max(1, round((samples - 1001) / 800))


LONG_PARQUET = "hessian, --format parquet --no-figures --no-report"


def bench_long(sizes=LONG_SAMPLES, methods=None, progress: Progress = SILENT) -> list[LongRun]:
    """Each method (default: every formulation) on default tasks of ``sizes`` samples (more chewing cycles), figures
    and report included; and the Hessian method as a batch run (:data:`LONG_PARQUET`)."""
    import json

    from chewbot.dynamics.registry import METHODS

    methods = METHODS if methods is None else methods
    out = []
    # each method with all outputs, and the Hessian method as a batch run writes it: results.parquet, no drawings
    cases = [(method, method, ()) for method in methods] + [
        (LONG_PARQUET, "hessian", ("--format", "parquet", "--no-figures", "--no-report"))]
    with tempfile.TemporaryDirectory() as tmp:
        for samples in sizes:
            for label, method, extra in cases:
                progress(f"{label}, {samples} samples")
                folder = Path(tmp) / "run"
                command = _chewbot("run", "--method", method, "--set", f"task.cycles={long_cycles(samples)}", "--out", str(folder),
                                   "--force", "-q", "--allow-violations", *extra)
                t0 = time.perf_counter()
                process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                _, status, usage = os.wait4(process.pid, 0)
                wall = time.perf_counter() - t0
                process.returncode = os.waitstatus_to_exitcode(status)
                if process.returncode != 0:
                    raise RuntimeError(f"{' '.join(command)} ended with {process.returncode}")
                record = json.loads((folder / "run.json").read_text())
                stages = sum(v for k, v in record["timings"].items())
                out.append(LongRun(label, record["task"]["samples"], wall, stages, usage.ru_maxrss / 1024))
    return out


SCALE_SPEC = "sobol-scale"  # the built-in SPEC of the scale study (its budget: 10,240 evaluations in 10 minutes)


@dataclass(frozen=True)
class SweepTiming:
    """The scale study's evaluations on ``workers`` worker processes (``workers = 0``: in this process, without
    Dask, the evaluations one after the other): ``evaluations`` computed in ``evaluating_s``, wall time from the first
    chunk sent to the last one written, the workers warm (their kernels loaded and the task built, as after a
    sweep's first chunks); ``startup_s``: starting the cluster and warming its workers; ``single_ms``: in this
    process only (each evaluation then timed on its own), the median, 99th percentile and maximum of one
    evaluation's time (ms)."""

    workers: int
    evaluations: int
    evaluating_s: float
    startup_s: float
    task_samples: int  # samples of the task per evaluation
    single_ms: tuple[float, float, float] | None = None

    @property
    def per_sample_us(self) -> float:
        """Wall time per task sample on one core (us)."""
        return 1e6 / self.per_s_per_core / self.task_samples

    @property
    def per_s(self) -> float:
        return self.evaluations / self.evaluating_s

    @property
    def per_s_per_core(self) -> float:
        return self.per_s / max(self.workers, 1)


def bench_sweep(base_samples: int = 32, workers: tuple[int, ...] = (1, 2), chunk: int = 8,
                progress: Progress = SILENT) -> tuple[list[SweepTiming], int]:
    """Throughput of the scale study (:data:`SCALE_SPEC`: a Sobol' study of 8 parameters on the default task,
    Hessian method, peak torque and mean MCI) with ``base_samples`` base samples instead of 1,024 (N (D + 2)
    evaluations) in chunks of ``chunk``: in this process without Dask, then by the sweep's chunk runner on a local
    cluster of each number of ``workers``, writing each chunk as ``chewbot sweep`` does. Returns the timings and the
    evaluations of the whole study."""
    from chewbot.sweep.evaluate import evaluate_chunk
    from chewbot.sweep.record import SweepFolder
    from chewbot.outputs.sweep import prepare
    from chewbot.sweep.evaluate import output_units
    from chewbot.sweep.runner import ChunkRunner, dask_client
    from chewbot.sweep.samplers import sobol_design
    from chewbot.sweep.spec import read_spec
    from chewbot.task.default import default_task

    full = read_spec(SCALE_SPEC)
    spec = replace(full, samples=base_samples, chunk=chunk)
    design = sobol_design(spec)
    prepare(spec)
    progress(f"{SCALE_SPEC}, {design.n} evaluations, in this process")
    t0 = time.perf_counter()
    evaluate_chunk(spec, design.rows(0, 1))  # the kernels loaded, the task built
    warm = time.perf_counter() - t0
    single = []  # each evaluation timed on its own, one after the other
    for a in range(design.n):
        t0 = time.perf_counter()
        evaluate_chunk(spec, design.rows(a, a + 1))
        single.append(time.perf_counter() - t0)
    samples = default_task(None, spec.side or "left").t.size
    single_ms = tuple(float(x) * 1e3 for x in (np.median(single), np.percentile(single, 99), np.max(single)))
    out = [SweepTiming(0, design.n, float(np.sum(single)), warm, samples, single_ms)]
    for w in workers:
        progress(f"{SCALE_SPEC}, {design.n} evaluations, {w} worker(s)")
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            with dask_client(workers=w) as client:
                client.run(evaluate_chunk, spec, design.rows(0, 1))  # every worker warm
                startup = time.perf_counter() - t0
                runner = ChunkRunner(client, SweepFolder.start(Path(tmp) / "sweep", {}, b""), evaluate_chunk, spec, chunk,
                                     output_units(spec))
                runner.run(design)
            out.append(SweepTiming(w, runner.evaluations, runner.compute_s, startup, samples))
    return out, full.samples * (len(full.keys) + 2)


def sweep_markdown(timings: list[SweepTiming], total: int) -> str:
    """The scale study's throughput, its scaling over the workers and the projected time of the whole study."""
    serial = timings[0]
    lines = ["", f"Sweep throughput: the scale study (chewbot sweep sobol-scale: Sobol', 8 parameters, default task, Hessian "
             f"method, peak_tau_Nm and mean_MCI), {serial.evaluations} evaluations, warm workers:", "",
             "| workers | evaluations/s | per core (evaluations/s) | per task sample and core (us) | speed-up | "
             f"evaluating (s) | cluster start and warm-up (s) | the whole study, {total:,} evaluations (min) | "
             "one evaluation: median, p99, max (ms) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for t in timings:
        who = "in this process, no Dask" if t.workers == 0 else str(t.workers)
        single = "—" if t.single_ms is None else ", ".join(f"{x:.1f}" for x in t.single_ms)
        lines.append(f"| {who} | {t.per_s:.2f} | {t.per_s_per_core:.2f} | {t.per_sample_us:.1f} | {t.per_s / serial.per_s:.2f} | "
                     f"{t.evaluating_s:.1f} | {t.startup_s:.1f} | {total / t.per_s / 60:.1f} | {single} |")
    return "\n".join(lines) + "\n"
# --- the page ------------------------------------------------------------------------------------------------


def machine() -> str:
    """The CPU model, the cores this process may use, Python, and the load average when asked."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{model}, {cores} core(s) available, Python {platform.python_version()}"


def load() -> str:
    try:
        return ", ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def benchmark(repeats: int = 11, calls: int = 20000, long: bool = False, progress: Progress = SILENT) -> str:
    """Run every table of the benchmark and return them as Markdown, with the machine and its load."""
    started = load()
    t0 = time.perf_counter()
    progress("chewbot run, chew and --help")
    commands = bench_commands(max(3, repeats // 2), progress)
    progress("the formulations on the whole task")
    task = bench_task(repeats, progress=progress)
    progress("reading a long task and a long robot log")
    inputs = bench_csv(repeats=max(3, repeats // 2), progress=progress)
    progress("the in-loop kernels")
    loop = bench_loop(calls, repeats)
    progress("the exported C")
    compiler, c_timings = bench_export()
    progress("the exported controller step")
    step_compiler, step_timings = bench_controller(progress=progress)
    runs = bench_long(progress=progress) if long else []
    minutes = (time.perf_counter() - t0) / 60
    lines = [f"Machine: {machine()}; load average (1, 5, 15 min) {started} at the start, {load()} at the end "
             f"({minutes:.1f} min). Medians with the interquartile range of the runs in brackets; the variants of a "
             "table ran interleaved; a ratio whose two spreads overlap is printed as \"within noise\".", ""]
    lines += _commands_table(commands) + _task_table(task) + _ratio_lines(ratios(task)) + [csv_markdown(inputs)] + _loop_table(loop)
    lines += _export_table(compiler, c_timings)
    lines += [step_markdown(step_compiler, step_timings)]
    if runs:
        lines += _long_table(runs)
    return "\n".join(lines) + "\n"


def _commands_table(timings: dict[str, Timing]) -> list[str]:
    lines = ["What a user waits for (separate processes, warm kernel cache, default task, all outputs):", "",
             "| command | wall time (s) | runs |", "|---|---|---|"]
    lines += [f"| `chewbot {' '.join(RUN_CASES.get(t.label, ['--help']))}` | {t.per_sample(1)} | {len(t.times)} |" for t in timings.values()]
    lines += ["", f"- `chewbot tpa` / `chewbot run` (Hessian): {compare(timings['tpa, cheddar'], timings['run, hessian']).text()}"]
    return lines + [""]


def _task_table(timings: dict[str, Timing]) -> list[str]:
    some = next(iter(timings.values()))
    lines = [f"Whole default task ({some.samples} samples), kinematics left out:", "",
             "| mechanism | case | first call (s) | median (ms) | per sample (us) |", "|---|---|---|---|---|"]
    for label, t in timings.items():
        mech, case = label.split(": ", 1)
        q1, q3 = t.spread
        lines.append(f"| {mech} | {case} | {t.first_s:.3f} | {t.median * 1e3:.2f} ({q1 * 1e3:.2f}–{q3 * 1e3:.2f}) | {t.per_sample()} |")
    return lines + [""]


def _ratio_lines(comparisons: dict[str, Comparison]) -> list[str]:
    return ["Ratios (time of the first over the second):", ""] + [f"- {name}: {c.text()}" for name, c in comparisons.items()] + [""]


def _loop_table(timings: dict[str, Timing]) -> list[str]:
    lines = ["One sample from Python, target (`chewbot.export.realtime.loop_kernel`: preallocated arrays, no copy; a "
             "`NativeFunction` call: inputs given as arrays, outputs returned as new ones):", "",
             "| kernel | in-loop call (us) | NativeFunction call (us) |", "|---|---|---|"]
    for kind in ("tau", "dynamics", "g1"):
        lines.append(f"| {kind} | {timings[f'in-loop {kind}'].per_sample()} | {timings[f'NativeFunction call {kind}'].per_sample()} |")
    return lines + [""]


def _export_table(compiler: str, timings: list[Timing]) -> list[str]:
    lines = [f"Exported C, one call (its example program, {compiler}; single calls timed one by one, each with a clock "
             "reading):", "", "| kernel | ns per call (mean of a loop) | single call: median (ns) | p99 (ns) | max (ns) |",
             "|---|---|---|---|---|"]
    for t in timings:
        q1, q3 = t.spread
        med, p99, top = t.single
        lines.append(f"| {t.label} | {t.median:.0f} ({q1:.0f}–{q3:.0f}) | {med:.0f} | {p99:.0f} | {top:.0f} |")
    return lines + [""]


def _long_table(runs: list[LongRun]) -> list[str]:
    lines = ["Long tasks (`chewbot run --set task.cycles=N`, figures and report included unless the method says otherwise): the time per sample of the "
             "stages that grow with the task (run.json's timings), the whole wall time, the peak memory:", "",
             "| method | samples | per sample (us) | wall (s) | peak memory (MB) |", "|---|---|---|---|---|"]
    lines += [f"| {r.method} | {r.samples} | {r.per_sample_us:.3g} | {r.wall_s:.1f} | {r.peak_mb:.0f} |" for r in runs]
    return lines + [""]

