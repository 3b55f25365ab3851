"""A run: model + task -> kinematics (-> dynamics, coupling ...) -> validity checks -> a results folder.

The folder is written in a temporary sibling and moved into place at the end (:func:`chewbot.outputs.atomic_folder`):
a failed or interrupted run leaves nothing behind, and an existing folder is replaced only when ``force`` is
given and chewbot wrote it. The folder is written whatever the checks say; the command decides the exit code.
"""

from __future__ import annotations

import hashlib
import platform
import time
from dataclasses import replace
from importlib import metadata
from pathlib import Path

import numpy as np

from chewbot.casadi_tools import prepare_kernels
from chewbot.command import pause_for_tests
from chewbot.errors import KinematicsError, TaskError
from chewbot.kinematics.motion import solve_kinematics
from chewbot.model import Model
from chewbot.model_vector import vector_digest
from chewbot.outputs import RESULTS_FOLDER, atomic_folder, to_json
from chewbot.params import load_model, split_overrides
from chewbot.report import dynamics_figures, figures
from chewbot.report.html import write_report
from chewbot.results import RESULTS_FORMAT, RunOptions, RunResult, kinematics_table
from chewbot.task.base import Task

__all__ = ["RunOptions", "RunResult", "compute", "input_files", "load_task", "run_json", "write"]


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


def compute(options: RunOptions, progress=None) -> RunResult:
    """Compute a run in memory (no files)."""
    step = progress or (lambda msg: None)
    model_overrides, task_overrides = split_overrides(options.overrides)
    model = load_model(options.model, model_overrides)
    step("task")
    task = load_task(options.task, model, options.side, task_overrides)
    options = replace(options, side=task.side)  # the side in effect, as run.json records it
    step("kinematics")
    t0 = time.perf_counter()
    prepare_kernels(run_kernels(model, options))
    try:
        kin = solve_kinematics(model, task, options.orientation)
    except KinematicsError as exc:  # name the task file's line of the sample
        if task.lines is None or exc.sample is None:
            raise
        raise exc.located(f"{task.source}: line {task.lines[exc.sample]}") from None
    timings = {"kinematics_s": time.perf_counter() - t0}
    table = kinematics_table(kin)
    result = RunResult(options=options, model=model, task=task, kinematics=kin, table=table, info={"timings": timings})
    _singularity_columns(result)
    if options.method:
        _dynamics_stage(result, step)
    _checks_stage(result, step)
    return result


def _singularity_columns(result: RunResult) -> None:
    """The transmission angles mu1..mu6 and kappa_J of the chains' Jacobian (docs/conventions.md)."""
    kin = result.kinematics
    result.table.add_block([f"mu{i + 1}" for i in range(6)], np.arcsin(np.clip(kin.transmission, 0.0, 1.0)), "rad",
                           "transmission angle of chain i (90 deg best, 0 at the dead point)")
    result.table.add("kappa_J", kin.kappa, "1",
                     "reciprocal condition number of the chains' Jacobian J_theta1, columns scaled (0: singular)")


def _checks_stage(result: RunResult, step) -> None:
    """The validity checks of every sample (chewbot.analysis.checks), on the whole run as one chunk."""
    from chewbot.analysis.checks import run_checks

    step("validity checks")
    t0 = time.perf_counter()
    result.checks = run_checks(result.model, result.table, result.info.get("dynamics"), result.options.contact)
    result.info["timings"]["checks_s"] = time.perf_counter() - t0
def run_kernels(model: Model, options: RunOptions) -> list:
    """The compiled kernels a run uses: the kinematics, the formulation's, and the inertia coupling's."""
    from chewbot.analysis.coupling import coupling_kernel
    from chewbot.dynamics import formulation_kernels
    from chewbot.kinematics.functions import kinematics_kernel

    kernels = [kinematics_kernel(model.mechanism, options.orientation)]
    if options.method:
        kernels += formulation_kernels(model.mechanism, options.orientation, options.method, goal=options.goal)
        kernels.append(coupling_kernel(model.mechanism))
    return kernels


def _dynamics_stage(result: RunResult, step) -> None:
    """Inverse dynamics by the chosen formulation: tau1..tau6 and the formulation's own columns."""
    from chewbot.dynamics import inverse_dynamics

    o = result.options
    step(f"inverse dynamics ({o.method})")
    pause_for_tests("dynamics")
    t0 = time.perf_counter()
    used = {**({"goal": o.goal} if o.goal else {}), **({"friction": o.friction == "on"} if o.friction else {}), "contact": o.contact}
    dyn = inverse_dynamics(result.model, result.kinematics, o.method, **used)
    result.info["timings"][f"dynamics_{o.method}_s"] = time.perf_counter() - t0
    result.dynamics = dyn
    result.table.add_block([f"tau{i + 1}" for i in range(6)], dyn.tau, "N*m", f"actuator torques ({o.method})")
    for name, values in dyn.table.columns.items():
        result.table.add(name, values, dyn.table.units[name], dyn.table.descriptions.get(name, ""))
    if dyn.info:
        result.info["dynamics"] = dyn.info
    _coupling_stage(result, step)


def _coupling_stage(result: RunResult, step) -> None:
    """Inertia coupling MCI1..MCI6 (seed 000, Eq. 60) and the means of the related indices."""
    from chewbot.analysis.coupling import coupling

    step("inertia coupling")
    t0 = time.perf_counter()
    c = coupling(result.model, result.kinematics)
    result.info["timings"]["coupling_s"] = time.perf_counter() - t0
    result.table.add_block([f"MCI{i + 1}" for i in range(6)], c.MCI, "1", "inertia coupling index of joint i (seed 000, Eq. 60)")
    result.info["coupling_means"] = c.means()


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in ("chewbot", "numpy", "scipy", "casadi", "pydantic", "matplotlib", "plotly"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def _sha256(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def input_files(options: RunOptions) -> list[Path]:
    """The files a run reads (its task file, its parameter file), which its output must not contain."""
    from chewbot.params import BUILTIN_MODELS

    return [Path(p) for p in (options.task, options.model) if p not in ("default", *BUILTIN_MODELS)]


def run_json(result: RunResult) -> dict:
    """The run record (run.json): format, options, model and task identity, versions, platform, column units,
    the validity checks, info."""
    m, task = result.model, result.task
    return {
        "chewbot_run": RESULTS_FORMAT,
        "options": vars(result.options),
        "model": {"name": m.name, "mechanism": m.mechanism, "file": m.source, "sha256": m.sha256, "assumed": list(m.assumed),
                  "parameters_sha256": vector_digest(m)},
        "overrides": dict(result.options.overrides),
        "task": {"name": task.name, "source": task.source, **({"sha256": _sha256(task.source)} if Path(task.source).is_file() else {}),
                 "samples": task.n, "side": task.side, **({"meta": task.meta} if task.meta else {})},
        "versions": _versions(),
        "platform": platform.platform(),
        "columns": {name: {"unit": result.table.units[name], **({"description": d} if (d := result.table.descriptions.get(name)) else {})} for name in result.table.columns},
        "checks": [c.as_dict() for c in result.checks],
        **result.info,
    }


def write(result: RunResult, out: Path, force: bool = False, progress=None) -> Path:
    """Write the results folder ``out`` (results.csv, run.json, figures, report.html) atomically.

    Everything is written in a temporary sibling folder that replaces ``out`` only once complete: a failure or a
    signal at any step (a figure, the report) leaves ``out`` as it was. ``progress(message)`` is told each step.
    """
    step = progress or (lambda msg: None)
    out = Path(out)
    with atomic_folder(out, force, RESULTS_FOLDER, inputs=input_files(result.options)) as tmp:
        step("writing results.csv")
        result.table.to_csv(tmp / "results.csv")
        pause_for_tests("writing")
        step("drawing figures")
        result.figures = [
            figures.task_space(result.table, tmp / "task_space.png"),
            figures.joint_space(result.table, tmp / "joint_space.png"),
            figures.bite_force(result.table, tmp / "bite_force.png"),
        ]
        if result.dynamics is not None:
            result.figures += [
                dynamics_figures.torques(result.table, tmp / "torques.png", result.options.method, result.options.contact),
                dynamics_figures.coupling_indices(result.table, tmp / "coupling.png"),
            ]
            if result.options.method == "newton-euler":
                from chewbot.report.newton_euler_figures import run_figures

                result.figures += run_figures(result.table, tmp)
        (tmp / "run.json").write_text(to_json(run_json(result)))
        step("writing report.html")
        write_report(result, tmp / "report.html", files=sorted(p.name for p in tmp.iterdir()))
    result.figures = [out / p.name for p in result.figures]
    return out
