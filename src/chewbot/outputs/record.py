"""The record of a results folder (run.json): what defines the run and what it computed besides its rows, and reading
a results folder back.

run.json holds the results format's version (``"chewbot_run"``, the folder's marker), the options, the model's and
the task's identity, the versions and platform, every column's unit and description, the validity checks and what
the run says about the whole task (timings, the formulation's info, the coupling means).
"""

from __future__ import annotations

import hashlib
import json
import platform
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING

from chewbot.errors import ChewbotError
from chewbot.table import Table

if TYPE_CHECKING:
    from chewbot.analysis.checks import CheckResult
    from chewbot.kinematics.task import Task
    from chewbot.model import Model
    from chewbot.report.view import RunView

# Version of the results folder's format, the value of run.json's "chewbot_run" (CHANGELOG.md): 2 puts each
# column's unit in the header of results.csv (`tau1 [N*m]`) and adds the transmission angles, kappa_J and the
# validity checks. Version 1 (names alone, units in run.json) is still read.
RESULTS_FORMAT = 2
READABLE_FORMATS = (1, 2)


@dataclass
class RunRecord:
    """A run as its folder holds it, without its rows: ``record`` (run.json's content), the model, the validity
    checks, ``view`` (the decimated columns and their statistics, :class:`chewbot.report.view.RunView`) and the
    files written. What ``chewbot run`` returns for a task written chunk by chunk."""

    record: dict
    model: Model
    checks: list[CheckResult]
    view: RunView
    files: list[Path] = field(default_factory=list)


def versions(*extra: str) -> dict[str, str]:
    """The versions of Python, chewbot and the libraries its results depend on, and of the packages ``extra``."""
    out = {"python": platform.python_version()}
    for pkg in ("chewbot", "numpy", "scipy", "casadi", "pydantic", "matplotlib", "plotly", *extra):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def model_record(model: Model) -> dict:
    """A model's identity in run.json: name, mechanism, file and its hash, assumed keys, the parameters' hash."""
    from chewbot.model.vector import vector_digest

    return {"name": model.name, "mechanism": model.mechanism, "file": model.source, "sha256": model.sha256,
            "assumed": list(model.assumed), "parameters_sha256": vector_digest(model)}


def task_record(task: Task) -> dict:
    """A task's identity in run.json: name, source (and its hash), samples, side, what the generator recorded."""
    source = Path(task.source)
    return {"name": task.name, "source": task.source,
            **({"sha256": hashlib.sha256(source.read_bytes()).hexdigest()} if source.is_file() else {}),
            "samples": task.n, "side": task.side, **({"meta": task.meta} if task.meta else {})}


def environment_record(*extra: str) -> dict:
    """The versions of chewbot and its libraries (and of the packages ``extra``), and the platform."""
    return {"versions": versions(*extra), "platform": platform.platform()}


def columns_record(columns: Table) -> dict:
    """Each column's unit and description (``columns``: any chunk of the results table)."""
    return {name: {"unit": columns.units[name], **({"description": d} if (d := columns.descriptions.get(name)) else {})}
            for name in columns.columns}


def run_record(options, model: Model, task: Task, columns: Table, checks: list[CheckResult], info: dict) -> dict:
    """The run record (run.json): format, options, model and task identity, versions, platform, the unit and
    description of every column of ``columns`` (any chunk of the results table), the validity checks, ``info``
    (timings, the formulation's info, the coupling means)."""
    return {
        "chewbot_run": RESULTS_FORMAT,
        "options": vars(options),
        "model": model_record(model),
        "overrides": dict(options.overrides),
        "task": task_record(task),
        **environment_record(),
        "columns": columns_record(columns),
        "checks": [c.as_dict() for c in checks],
        **info,
    }


def read_record(folder: Path) -> dict:
    """run.json of a results folder, of a format this chewbot reads (:data:`READABLE_FORMATS`); a
    :class:`ChewbotError` names the file otherwise."""
    folder = Path(folder)
    path = folder / "run.json"
    try:
        run = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ChewbotError(f"{folder}: not a results folder (no run.json)") from None
    except (OSError, ValueError) as exc:
        raise ChewbotError(f"{path}: cannot read it ({exc})") from None
    version = run.get("chewbot_run") if isinstance(run, dict) else None
    if version not in READABLE_FORMATS:
        raise ChewbotError(f"{path}: results format {version!r}; this chewbot reads {', '.join(map(str, READABLE_FORMATS))}")
    return run


def read_results(folder: Path) -> tuple[dict, Table]:
    """A results folder read back: run.json (as a dict, :func:`read_record`) and its rows (results.csv, or
    results.parquet where run.json's ``results_file`` names it) as a :class:`Table` with its units."""
    run = read_record(folder)
    units = {name: c.get("unit", "") for name, c in run.get("columns", {}).items()}
    name = run.get("results_file", "results.csv")
    if name == "results.parquet":
        import pyarrow.parquet as pq

        path = Path(folder) / name
        try:
            data = pq.read_table(path)
        except (OSError, ValueError) as exc:
            raise ChewbotError(f"{path}: cannot read it as Parquet ({exc})") from None
        table = Table()
        for field, column in zip(data.schema, data.columns):
            meta = field.metadata or {}
            table.add(meta.get(b"name", field.name.encode()).decode(), column.to_numpy(), meta.get(b"unit", b"").decode())
        return run, table
    return run, Table.read_csv(Path(folder) / name, units)
