"""The folder of a simulation (``chewbot simulate``): results.csv, run.json, the figures and report.html, written
whole through :func:`chewbot.files.atomic_folder` and recognised later by its run.json (key ``chewbot_simulation``);
``--compare`` writes one such folder per controller inside one comparison folder, with the comparison's own
run.json, table and report.
"""

from __future__ import annotations

from pathlib import Path

from chewbot.files import Marker, atomic_folder, to_json
from chewbot.outputs.writer import RECORD_FILE, RESULTS_FILE, write_table
from chewbot.progress import SILENT, Progress
from chewbot.simulation.run import SimulateResult, comparison_table, input_files

SIMULATION_FORMAT = 1
SIMULATION_FOLDER = Marker("simulation folder", "run.json", "chewbot_simulation")


def simulation_json(result: SimulateResult) -> dict:
    """run.json of a simulation: format, options, both models, task, versions, columns, checks, tracking, info."""
    from chewbot.outputs.record import columns_record, environment_record, model_record, task_record

    return {
        "chewbot_simulation": SIMULATION_FORMAT,
        "options": result.record,
        "model": model_record(result.model),
        "plant": model_record(result.plant_model),
        "task": task_record(result.task),
        **environment_record(),
        "columns": columns_record(result.table),
        "checks": [c.as_dict() for c in result.checks],
        **result.info,
    }


def write_into(result: SimulateResult, folder: Path, progress: Progress = SILENT) -> list[Path]:
    """Write the files of a simulation into an existing (temporary) folder: results.csv and run.json by the writer
    of every results folder (:class:`chewbot.outputs.writer.ResultsWriter`), then the figures and report.html drawn
    from what it wrote; the files written."""
    from chewbot.report import dynamics_figures, figures, simulation_figures
    from chewbot.report.simulation_html import controller_label, write_simulation_report

    from chewbot.outputs.record import copy_inputs, with_copies

    copies = copy_inputs(folder, {"model": result.model, "plant": result.plant_model}, result.task)
    record, view = write_table(folder, result.table, with_copies(simulation_json(result), copies), progress=progress)
    for name, text in result.files.items():  # the MuJoCo plant's model file
        (folder / name).write_text(text, encoding="utf-8")
    series = view.series
    progress("drawing figures")
    drawn = [
        simulation_figures.tracking_error(series, folder / "tracking_error.png", controller_label(result)),
        dynamics_figures.torques(series, folder / "torques.png", f"applied, {result.options.controller.name}", result.options.contact),
        simulation_figures.saturation(series, folder / "saturation.png", result.plant_model.limits.torque),
        figures.task_space(series, folder / "task_space.png"),
        figures.joint_space(series, folder / "joint_space.png"),
    ]
    progress("writing report.html")
    report = write_simulation_report(result, record, view, folder / "report.html", files=sorted(p.name for p in folder.iterdir()))
    return [folder / RESULTS_FILE, folder / RECORD_FILE, *(folder / n for n in result.files), *drawn, report]


def write(result: SimulateResult, out: Path, force: bool = False, progress: Progress = SILENT) -> Path:
    """Write the results folder ``out`` atomically (see :func:`chewbot.outputs.writer.write`)."""
    out = Path(out)
    with atomic_folder(out, force, SIMULATION_FOLDER, inputs=input_files(result.options)) as tmp:
        write_into(result, tmp, progress)
    return out




def write_comparison(results: dict[str, SimulateResult], out: Path, force: bool = False, progress: Progress = SILENT) -> Path:
    """The comparison folder: one simulation folder per controller (or per engine), comparison.csv, the figure, run.json
    and the report."""
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
        records = [r.record for r in results.values()]
        record = {"chewbot_simulation": SIMULATION_FORMAT, "comparison": {k: r.metrics for k, r in results.items()},
                  "options": {k: v for k, v in first.record.items() if k not in ("controller", "engine") or
                              len({rec[k] for rec in records}) == 1},
                  "folders": {k: k for k in results}}
        (tmp / "run.json").write_text(to_json(record))
        write_comparison_report(results, tmp / "report.html", files=sorted(p.name for p in tmp.iterdir()))
    return out
