"""The folder of a simulation (``chewbot simulate``): results.csv, run.json, the figures and report.html, written
whole through :func:`chewbot.files.atomic_folder` and recognised later by its run.json (key ``chewbot_simulation``);
``--compare`` writes one such folder per controller inside one comparison folder, with the comparison's own
run.json, table and report.
"""

from __future__ import annotations

import json
from pathlib import Path


from chewbot.files import Marker, atomic_folder, to_json
from chewbot.simulation.run import SimulateResult, comparison_table, input_files

SIMULATION_FORMAT = 1
SIMULATION_FOLDER = Marker("simulation folder", "run.json", "chewbot_simulation")


def simulation_json(result: SimulateResult) -> dict:
    """run.json of a simulation: format, options, both models, task, versions, columns, checks, tracking, info."""
    from chewbot.table import columns_record, environment_record, model_record, task_record

    return {
        "chewbot_simulation": SIMULATION_FORMAT,
        "options": vars(result.options),
        "model": model_record(result.model),
        "plant": model_record(result.plant),
        "task": task_record(result.task),
        **environment_record(),
        "columns": columns_record(result.table),
        "checks": [c.as_dict() for c in result.checks],
        **result.info,
    }


def write_into(result: SimulateResult, folder: Path, progress=None) -> None:
    """Write the files of a simulation into an existing (temporary) folder."""
    from chewbot.report import dynamics_figures, figures, simulation_figures
    from chewbot.report.simulation_html import controller_label, write_simulation_report

    step = progress or (lambda msg, stage=None: None)
    step("writing results.csv")
    result.table.to_csv(folder / "results.csv")
    step("writing run.json", stage="writing")
    text = to_json(simulation_json(result))
    (folder / "run.json").write_text(text)
    step("drawing figures")
    result.figures = [
        simulation_figures.tracking_error(result.table, folder / "tracking_error.png", controller_label(result)),
        dynamics_figures.torques(result.table, folder / "torques.png", f"applied, {result.options.controller}", result.options.contact),
        simulation_figures.saturation(result.table, folder / "saturation.png", result.plant.limits.torque),
        figures.task_space(result.table, folder / "task_space.png"),
        figures.joint_space(result.table, folder / "joint_space.png"),
    ]
    step("writing report.html")
    write_simulation_report(result, json.loads(text), folder / "report.html", files=sorted(p.name for p in folder.iterdir()))


def write(result: SimulateResult, out: Path, force: bool = False, progress=None) -> Path:
    """Write the results folder ``out`` atomically (see :func:`chewbot.run.pipeline.write`)."""
    out = Path(out)
    with atomic_folder(out, force, SIMULATION_FOLDER, inputs=input_files(result.options)) as tmp:
        write_into(result, tmp, progress)
    result.figures = [out / p.name for p in result.figures]
    return out




def write_comparison(results: dict[str, SimulateResult], out: Path, force: bool = False, progress=None) -> Path:
    """The comparison folder: one simulation folder per controller, comparison.csv, the figure, run.json and the report."""
    from chewbot.report.simulation_figures import comparison
    from chewbot.report.simulation_html import write_comparison_report

    out = Path(out)
    first = next(iter(results.values()))
    with atomic_folder(out, force, SIMULATION_FOLDER, inputs=input_files(first.options)) as tmp:
        for kind, result in results.items():
            (tmp / kind).mkdir()
            write_into(result, tmp / kind, progress)
        comparison_table(results).to_csv(tmp / "comparison.csv")
        comparison({k: r.table for k, r in results.items()}, tmp / "comparison.png")
        record = {"chewbot_simulation": SIMULATION_FORMAT, "comparison": {k: r.metrics for k, r in results.items()},
                  "options": {k: v for k, v in vars(first.options).items() if k != "controller"},
                  "folders": {k: k for k in results}}
        (tmp / "run.json").write_text(to_json(record))
        write_comparison_report(results, tmp / "report.html", files=sorted(p.name for p in tmp.iterdir()))
    return out
