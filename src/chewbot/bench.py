"""Timing of every inverse-dynamics formulation and of the real-time kernels (``chewbot bench``).

Everything is measured in one process, one run, on the default task (5001 samples), so the medians and the
ratios compare like with like. A case is one entry of :data:`TASK_CASES`: a label, the mechanisms and the
orientation it runs on, and a callable ``(model, kinematics)`` that computes the whole task. Adding a
formulation to the benchmark is adding one entry. The kinematics are computed once per (mechanism,
orientation) and left out of the timings; the first call of a case (graph build, kernel compile or load) is
reported apart from the median of the further calls.

The plain references are the straightforward ways: the Newton–Euler torques in NumPy, vectorised
(:func:`chewbot.reference.frictionless_torques`), and the friction-aware distribution by SciPy's SLSQP, sample
by sample (:func:`chewbot.reference.slsqp_min_torque`, timed on a stretch of :data:`SLSQP_SAMPLES` samples
and scaled to the task).
"""

from __future__ import annotations

import os
import platform
import statistics
import subprocess
import tempfile
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np

from chewbot.casadi_tools import c_compiler, native
from chewbot.dynamics import inverse_dynamics
from chewbot.dynamics.core6rss import core_terms
from chewbot.kinematics.motion import solve_kinematics
from chewbot.params import load_model
from chewbot.reference import frictionless_torques, slsqp_min_torque
from chewbot.task.default import default_task

SLSQP_SAMPLES = 100  # consecutive samples from t = 2 s (inside a bite), SLSQP costs milliseconds each
BOTH = ("target", "6rss")
EA, EP = "euler-angles", "euler-parameters"


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
    start = int(np.searchsorted(kin.t, 2.0))
    return slsqp_min_torque(model, kin, np.arange(start, start + SLSQP_SAMPLES))


def _g1_kernel(model, kin):
    from chewbot.realtime import g1_distribution

    return g1_distribution(model, kin)


def _recording_fit(model, kin):
    """chewbot import-motion's fit to the robot, on the task's poses as if recorded (unconstrained, exact)."""
    from chewbot.recordings.fit import fit_to_robot
    from chewbot.rotation import matrix_from_euler_angles

    return fit_to_robot(model, kin.X[:, :3], matrix_from_euler_angles(kin.X[:, 3:]))


TASK_CASES: tuple[Case, ...] = (
    Case("hessian", partial(inverse_dynamics, method="hessian")),
    Case("liang", partial(inverse_dynamics, method="liang")),
    Case("lagrange", partial(inverse_dynamics, method="lagrange")),
    Case("6rss-core", partial(inverse_dynamics, method="6rss-core")),
    Case("6rss-core with M_f, C_f, G_f", core_terms),
    Case("reference: NumPy Newton-Euler", frictionless_torques),
    Case("newton-euler G1 (EA)", partial(inverse_dynamics, method="newton-euler", goal="min-torque")),
    Case("newton-euler G1 (EP)", partial(inverse_dynamics, method="newton-euler", goal="min-torque"), orientation=EP),
    Case("newton-euler G2 (EA)", partial(inverse_dynamics, method="newton-euler", goal="min-coupler-force"), ("target",)),
    Case("newton-euler G2 (EP)", partial(inverse_dynamics, method="newton-euler", goal="min-coupler-force"), ("target",), EP),
    Case("newton-euler G3 (EA)", partial(inverse_dynamics, method="newton-euler", goal="min-hkp-force"), ("target",)),
    Case("newton-euler G3 (EP)", partial(inverse_dynamics, method="newton-euler", goal="min-hkp-force"), ("target",), EP),
    Case("G1 kernel, friction (EP)", _g1_kernel, ("target",), EP),
    Case("import-motion: fit to the robot", _recording_fit),
    Case(f"reference: SciPy SLSQP G1 (timed on {SLSQP_SAMPLES} samples, scaled)", _slsqp, ("target",), EA, SLSQP_SAMPLES),
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
    ("G1 kernel, friction (EP)", f"reference: SciPy SLSQP G1 (timed on {SLSQP_SAMPLES} samples, scaled)"),
    ("newton-euler G1 (EA)", f"reference: SciPy SLSQP G1 (timed on {SLSQP_SAMPLES} samples, scaled)"),
)


@dataclass(frozen=True)
class Timing:
    """One case on one mechanism: ``first_s`` (graph build + kernel load or compile + run), ``median_s`` and
    ``min_s`` over ``repeats`` further runs, scaled to the ``samples`` of the whole task."""

    mechanism: str
    case: str
    samples: int
    first_s: float
    median_s: float
    min_s: float
    repeats: int

    @property
    def per_sample_us(self) -> float:
        return 1e6 * self.median_s / self.samples


def _time(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def bench_task(repeats: int = 11, cases: tuple[Case, ...] = TASK_CASES, side: str = "left", progress=None) -> list[Timing]:
    """Time every case on its mechanisms on the default task; models are loaded fresh, so the first call of a
    case includes building its graph and loading (or compiling) its kernel."""
    models = {name: load_model(name) for name in BOTH}
    kins: dict[tuple[str, str], object] = {}
    out = []
    for case in cases:
        for name in case.mechanisms:
            if progress:
                progress(f"{case.label} ({name})")
            model = models[name]
            key = (name, case.orientation)
            if key not in kins:
                kins[key] = solve_kinematics(model, default_task(model, side), case.orientation)
            kin = kins[key]
            run = partial(case.run, model, kin)
            scale = kin.n / (case.samples or kin.n)
            first = _time(run)
            times = [scale * _time(run) for _ in range(repeats if case.samples is None else max(1, repeats // 5))]
            out.append(Timing(name, case.label, kin.n, first, statistics.median(times), min(times), len(times)))
    return out


def ratios(timings: list[Timing]) -> dict[str, float]:
    """Median ratios: each pair of :data:`RATIOS` per mechanism, and target over 6RSS per case."""
    med = {(t.mechanism, t.case): t.median_s for t in timings}
    out = {}
    for mech in BOTH:
        for a, b in RATIOS:
            if (mech, a) in med and (mech, b) in med:
                out[f"{mech}: {a} / {b}"] = med[mech, a] / med[mech, b]
    for case in dict.fromkeys(t.case for t in timings):
        if ("target", case) in med and ("6rss", case) in med:
            out[f"{case}: target / 6rss"] = med["target", case] / med["6rss", case]
    return out


@dataclass(frozen=True)
class KernelTiming:
    """One per-sample kernel: a call from Python (ctypes, median over ``calls``) and, where a C compiler is
    found, a call from C (mean over ``calls`` in the exported example program)."""

    name: str
    python_us: float
    c_ns: float | None
    calls: int


def bench_kernels(calls: int = 20000) -> list[KernelTiming]:
    """Time the exported kernels (:func:`chewbot.realtime.kernels`) for one sample, from Python and from C."""
    from chewbot.export import export_c
    from chewbot.realtime import kernels

    target, sixrss = load_model("target"), load_model("6rss")
    ks = kernels(target, sixrss)
    c_times: dict[str, float] = {}
    if c_compiler():
        with tempfile.TemporaryDirectory() as tmp:
            folder = export_c(ks, Path(tmp) / "kernels")
            exe = folder / "example"
            subprocess.run([c_compiler(), "-O3", "-std=c99", "-o", str(exe), str(folder / "example.c"),
                            str(folder / "chewbot_kernels.c"), "-lm"], check=True, capture_output=True)
            lines = subprocess.run([str(exe), str(calls)], check=True, capture_output=True, text=True).stdout.splitlines()
            for line in lines:
                if line.startswith("time "):
                    _, name, ns, _ = line.split()
                    c_times[name] = float(ns)
    out = []
    for k in ks:
        fn = native(k.function)
        args = [k.example[k.function.name_in(i)] for i in range(k.function.n_in())]
        for _ in range(200):
            fn(*args)
        ts = []
        for _ in range(calls // 4):
            t0 = time.perf_counter()
            fn(*args)
            ts.append(time.perf_counter() - t0)
        out.append(KernelTiming(k.name, 1e6 * statistics.median(ts), c_times.get(k.name), calls))
    return out


SCALE_SPEC = "sobol-scale"  # the built-in SPEC of the scale study (issue: 10,240 evaluations in 10 minutes)


@dataclass(frozen=True)
class SweepTiming:
    """The scale study's evaluations on ``workers`` worker processes (``workers = 0``: in this process, without
    Dask, the chunks one after the other): ``evaluations`` computed in ``evaluating_s``, wall time from the first
    chunk sent to the last one written, the workers warm (their kernels loaded and the task built, as after a
    sweep's first chunks); ``startup_s``: starting the cluster and warming its workers."""

    workers: int
    evaluations: int
    evaluating_s: float
    startup_s: float
    task_samples: int  # samples of the task per evaluation

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
                progress=None) -> tuple[list[SweepTiming], int]:
    """Throughput of the scale study (:data:`SCALE_SPEC`: a Sobol' study of 8 parameters on the default task,
    Hessian method, peak torque and mean MCI) with ``base_samples`` base samples instead of 1,024 (N (D + 2)
    evaluations) in chunks of ``chunk``: in this process without Dask, then by the sweep's chunk runner on a local
    cluster of each number of ``workers``, writing each chunk as ``chewbot sweep`` does. Returns the timings and the
    evaluations of the whole study."""
    from chewbot.sweep.evaluate import evaluate_chunk
    from chewbot.sweep.record import SweepFolder
    from chewbot.sweep.run import output_units, prepare
    from chewbot.sweep.runner import ChunkRunner, dask_client
    from chewbot.sweep.samplers import sobol_design
    from chewbot.sweep.spec import read_spec

    step = progress or (lambda msg: None)
    full = read_spec(SCALE_SPEC)
    spec = replace(full, samples=base_samples, chunk=chunk)
    design = sobol_design(spec)
    prepare(spec)
    step(f"{SCALE_SPEC}, {design.n} evaluations, in this process")
    t0 = time.perf_counter()
    evaluate_chunk(spec, design.rows(0, 1))  # the kernels loaded, the task built
    warm = time.perf_counter() - t0
    t0 = time.perf_counter()
    for a in range(0, design.n, chunk):
        evaluate_chunk(spec, design.rows(a, min(a + chunk, design.n)))
    samples = default_task(None, spec.side or "left").t.size
    out = [SweepTiming(0, design.n, time.perf_counter() - t0, warm, samples)]
    for w in workers:
        step(f"{SCALE_SPEC}, {design.n} evaluations, {w} worker(s)")
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


def machine() -> str:
    """The CPU model and the cores this process may use."""
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
