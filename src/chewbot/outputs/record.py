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


MODEL_COPY = "model.toml"
TASK_COPY = "task.csv"


def copy_inputs(folder: Path, models: dict, task: Task | None = None) -> dict[str, str]:
    """Copy into ``folder`` the parameter file of each model of ``models`` (``{"model": model, "plant": plant}``;
    named model.toml, plant.toml, ...) and, where the task came from a file, the task (task.csv): the folder
    carries its inputs, so that ``chewbot report``, a colleague on another machine or a later chewbot read it as
    it is. The copies are the files' bytes (their SHA-256 is checked against the one the run read: a file changed
    meanwhile is an error); a task that is a run's results.csv is copied as the task it read (its motion and bite
    force, :func:`chewbot.task.csvio.task_table`), which reads back exactly. Returns ``{role: file name}``."""
    import shutil

    from chewbot.files import file_sha256

    copies: dict[str, str] = {}
    sources: dict[str, str] = {}
    for role, model in models.items():
        name = MODEL_COPY if role == "model" else f"{role}.toml"
        if model.source in sources:  # the same file: one copy
            copies[role] = sources[model.source]
            continue
        target = folder / name
        shutil.copyfile(model.source, target)
        if model.sha256 and file_sha256(target) != model.sha256:
            raise ChewbotError(f"{model.source}: changed while the run read it (its SHA-256 is not the one loaded); run again")
        copies[role] = sources[model.source] = name
    if task is not None and Path(task.source).is_file():
        from chewbot.task.csvio import run_beside, task_table

        source, target = Path(task.source), folder / TASK_COPY
        if run_beside(source) is not None:
            task_table(task).to_csv(target)
        else:
            shutil.copyfile(source, target)
        copies["task"] = TASK_COPY
    return copies


def with_copies(record: dict, copies: dict[str, str]) -> dict:
    """``record`` (run.json) with the name of each input's copy in the folder under its entry (``"model": {...,
    "copy": "model.toml"}``, ``"task": {..., "copy": "task.csv"}``)."""
    for role, name in copies.items():
        record[role] = {**record[role], "copy": name}
    return record


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


def _run_json(folder: Path):
    """The content of ``folder``'s run.json; a :class:`ChewbotError` names the folder without one or the file."""
    path = folder / "run.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ChewbotError(f"{folder}: not a results folder (no run.json)") from None
    except (OSError, ValueError) as exc:
        raise ChewbotError(f"{path}: cannot read it ({exc})") from None


def read_record(folder: Path) -> dict:
    """run.json of a results folder, of a format this chewbot reads (:data:`READABLE_FORMATS`); a
    :class:`ChewbotError` names the file otherwise."""
    path = Path(folder) / "run.json"
    run = _run_json(Path(folder))
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


RESULTS_RECORDS = ("chewbot_run", "chewbot_simulation")  # the folders with a results.csv: a run's, a simulation's


def read_frame(folder: Path):
    """The results.csv of a run's or a simulation's folder (``folder``, or the path of its results.csv) as a pandas
    DataFrame: plain column names (``tau1``), each column's unit in ``frame.attrs["units"]`` (``"N*m"``, SI) and
    its description in ``frame.attrs["descriptions"]``, the folder's run.json in ``frame.attrs["record"]``.
    A :class:`ChewbotError` names the folder that is not such a folder."""
    import pandas as pd

    folder = Path(folder)
    if folder.name == "results.csv":
        folder = folder.parent
    path = folder / "run.json"
    record = _run_json(folder)
    if not isinstance(record, dict) or not any(key in record for key in RESULTS_RECORDS):
        raise ChewbotError(f"{path}: not the record of a run or a simulation (no key {' or '.join(RESULTS_RECORDS)}); "
                           "chewbot.read_results reads the folders of chewbot run and chewbot simulate")
    name = record.get("results_file", "results.csv")
    try:
        frame = pd.read_parquet(folder / name) if name.endswith(".parquet") else pd.read_csv(folder / name)
    except FileNotFoundError:
        raise ChewbotError(f"{folder}: no {name}") from None
    from chewbot.units import HEADER_CELL

    columns = record.get("columns", {})
    cells = [HEADER_CELL.match(c) for c in frame.columns]
    names = [m.group(1) if m else c for m, c in zip(cells, frame.columns)]
    frame.attrs["units"] = {n: columns.get(n, {}).get("unit", (m.group(2) or "") if m else "") for n, m in zip(names, cells)}
    frame.columns = names
    frame.attrs["descriptions"] = {n: columns.get(n, {}).get("description", "") for n in names}
    frame.attrs["record"] = record
    return frame

