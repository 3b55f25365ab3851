"""A run: model + task -> kinematics (-> dynamics, coupling ...) -> a results folder.

The folder is written in a temporary sibling and moved into place at the end: a failed run leaves nothing
behind, and an existing folder is replaced only when ``force`` is given.
"""

from __future__ import annotations

import hashlib
import platform
import time
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

from chewbot.casadi_tools import prepare_kernels
from chewbot.errors import KinematicsError, TaskError
from chewbot.kinematics.motion import Kinematics, solve_kinematics
from chewbot.model import Model
from chewbot.model_vector import vector_digest
from chewbot.params import load_model, split_overrides
from chewbot.report import dynamics_figures, figures
from chewbot.report.html import write_report
from chewbot.results import Table, kinematics_table
from chewbot.task.base import Task
from chewbot.outputs import atomic_folder, to_json


@dataclass
class RunOptions:
    """Everything that defines a run (recorded in run.json)."""

    model: str = "target"
    task: str = "default"
    side: str = "left"
    orientation: str = "euler-angles"
    method: str | None = None
    goal: str | None = "min-torque"  # newton-euler on the target only
    friction: str | None = "on"  # newton-euler only
    overrides: dict[str, float] = field(default_factory=dict)  # --set KEY=VALUE: model keys and task.NAME


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


def load_task(spec: str, model: Model, side: str, overrides: dict[str, float] | None = None) -> Task:
    """``"default"`` (the synthetic chewing task, with ``overrides`` of its parameters) or the path of a CSV file."""
    from chewbot.task.default import default_task, parameters_with

    if spec == "default":
        return default_task(model, side, parameters_with(overrides) if overrides else None)
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
    if options.method:
        _dynamics_stage(result, step)
    return result


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
    t0 = time.perf_counter()
    used = {**({"goal": o.goal} if o.goal else {}), **({"friction": o.friction == "on"} if o.friction else {})}
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


def run_json(result: RunResult) -> dict:
    """The run record (run.json): options, model and task identity, versions, platform, column units, info."""
    m, task = result.model, result.task
    return {
        "chewbot_run": 1,
        "options": vars(result.options),
        "model": {"name": m.name, "mechanism": m.mechanism, "file": m.source, "sha256": m.sha256, "assumed": list(m.assumed),
                  "parameters_sha256": vector_digest(m)},
        "overrides": dict(result.options.overrides),
        "task": {"name": task.name, "source": task.source, **({"sha256": _sha256(task.source)} if Path(task.source).is_file() else {}),
                 "samples": task.n, "side": task.side, **({"meta": task.meta} if task.meta else {})},
        "versions": _versions(),
        "platform": platform.platform(),
        "columns": {name: {"unit": result.table.units[name], **({"description": d} if (d := result.table.descriptions.get(name)) else {})} for name in result.table.columns},
        **result.info,
    }


def write(result: RunResult, out: Path, force: bool = False, progress=None) -> Path:
    """Write the results folder ``out`` (results.csv, run.json, figures, report.html) atomically.

    Everything is written in a temporary sibling folder that replaces ``out`` only once complete: a failure
    at any step (a figure, the report) leaves ``out`` as it was. ``progress(message)`` is told each step.
    """
    step = progress or (lambda msg: None)
    out = Path(out)
    with atomic_folder(out, force) as tmp:
        step("writing results.csv")
        result.table.to_csv(tmp / "results.csv")
        step("drawing figures")
        result.figures = [
            figures.task_space(result.table, tmp / "task_space.png"),
            figures.joint_space(result.table, tmp / "joint_space.png"),
            figures.bite_force(result.table, tmp / "bite_force.png"),
        ]
        if result.dynamics is not None:
            result.figures += [
                dynamics_figures.torques(result.table, tmp / "torques.png", result.options.method),
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
