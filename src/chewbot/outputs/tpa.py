"""The folder of a texture test (``chewbot tpa``): tpa.json (Bourne's measures from the plant's force and from the
torques), task.csv (the test's point path, zero bite force: a task for ``chewbot simulate --food``), the simulation's
own files (results.csv with the food's columns, run.json, its figures and report.html),
the force-time and force-displacement figures and tpa.html, written whole through :func:`chewbot.files.atomic_folder`
and recognised later by tpa.json (key ``chewbot_tpa``). From a robot's log (``chewbot tpa --log``) the folder has
tpa.json, the two figures and tpa.html.

The simulation's files depend on the simulation alone: :func:`tpa_folder` has a second process write them (forked
where a second core is free, as ``chewbot run``'s figures are drawn) while this one estimates the force from the
torques and measures the test, then writes the test's own files.
"""

from __future__ import annotations

import html
import os
from contextlib import contextmanager
from pathlib import Path

from chewbot.files import Marker, atomic_folder, forked, kill, reap, to_json
from chewbot.food.tpa import MEASURES
from chewbot.progress import SILENT, Progress

TPA_FOLDER = Marker("texture test folder", "tpa.json", "chewbot_tpa")
TPA_FILE = "tpa.json"
TASK_FILE = "task.csv"  # the test's point path, a task for chewbot simulate --food


def write_tpa(result, out: Path, force: bool = False, progress: Progress = SILENT) -> Path:
    """Write the folder of a simulated texture test (:class:`chewbot.simulation.texture.TpaResult`)."""
    from chewbot.simulation.run import input_files

    with tpa_folder(out, force, input_files(result.simulation.options), progress, parallel=False) as folder:
        folder.simulated(result.simulation)
        folder.finish(result)
    return Path(out)


def write_simulation_files(simulation, folder: Path, progress: Progress = SILENT) -> None:
    """The simulation's own files of a texture test (:class:`chewbot.simulation.run.SimulateResult`): those of
    ``chewbot simulate`` and task.csv."""
    from chewbot.outputs.simulation import write_into
    from chewbot.task.csvio import task_table

    write_into(simulation, folder, progress)
    task_table(simulation.task).to_csv(folder / TASK_FILE)  # plain CSV: the folder's tpa.json is chewbot's marker


class TpaFolder:
    """The temporary folder of a simulated texture test (:func:`tpa_folder`): :meth:`simulated` starts writing the
    simulation's files, :meth:`finish` writes the test's own once they are written."""

    def __init__(self, path: Path, progress: Progress, parallel: bool):
        self.path, self.progress, self.parallel = path, progress, parallel
        self.pid, self.report = None, None

    def simulated(self, simulation) -> None:
        """Write the simulation's files (:func:`write_simulation_files`): in a forked process where a second core is
        free, else here."""
        if not (self.parallel and hasattr(os, "fork") and len(os.sched_getaffinity(0)) > 1):
            write_simulation_files(simulation, self.path, self.progress)
            return
        self.progress("writing the simulation's files (results.csv, run.json, figures, report.html) beside the estimate")
        self.pid, self.report = forked(lambda: write_simulation_files(simulation, self.path))

    def wait(self) -> None:
        """Wait for the writing process; its failure raised here (RuntimeError with its traceback)."""
        if self.pid is None:
            return
        pid, report, self.pid, self.report = self.pid, self.report, None, None
        reap(pid, report, "writing the simulation's files failed in the writing process")

    def stop(self) -> None:
        """Stop the writing process at once (an error or a signal here)."""
        if self.pid is not None:
            kill(self.pid)
            self.pid = None
        if self.report is not None:
            os.close(self.report)
            self.report = None

    def finish(self, result) -> None:
        """The test's own files (tpa.json, the force-time and force-displacement figures, tpa.html), after the
        simulation's."""
        c = result.curves
        curves = {"plant": (c["t"], c["gap_plant"], c["force_plant"]),
                  "estimated": (c["t"], c["gap_estimated"], c["force_estimated"])}
        self.progress("drawing the force-time and force-displacement figures")
        _write_common(self.path, result.record(), curves, result.food.height, result.food.name, before_json=self.wait)


@contextmanager
def tpa_folder(out: Path, force: bool, inputs=(), progress: Progress = SILENT, parallel: bool = True):
    """The folder of a simulated texture test, written whole (:func:`chewbot.files.atomic_folder`): yields a
    :class:`TpaFolder`, whose :meth:`~TpaFolder.simulated` is called with the simulation as soon as it is done (the
    writing process, with ``parallel``, then writes its files while the caller estimates the force) and
    :meth:`~TpaFolder.finish` with the test's result. On an error or a signal the writing process is stopped and
    nothing is left."""
    with atomic_folder(Path(out), force, TPA_FOLDER, inputs=inputs) as tmp:
        folder = TpaFolder(tmp, progress, parallel)
        try:
            yield folder
            folder.wait()
        finally:
            folder.stop()


def write_tpa_log(record: dict, curve: dict, height: float | None, name: str, out: Path, force: bool = False, inputs=()) -> Path:
    """Write the folder of a logged texture test: tpa.json, the figures, tpa.html."""
    out = Path(out)
    with atomic_folder(out, force, TPA_FOLDER, inputs=inputs) as tmp:
        _write_common(tmp, record, {"estimated": (curve["t"], curve["gap"], curve["force"])}, height, name)
    return out


def _write_common(folder: Path, record: dict, curves: dict, height: float | None, name: str, before_json=None) -> None:
    """The figures, tpa.json and tpa.html; ``before_json()`` is called before tpa.json, the folder's marker, is written
    (the simulation's files are complete by then)."""
    from chewbot.report.tpa_figures import force_displacement, force_time

    force_time(curves, record.get("anchors", {}), folder / "force_time.png", name)
    force_displacement(curves, folder / "force_displacement.png", height, name)
    if before_json is not None:
        before_json()
    (folder / TPA_FILE).write_text(to_json(record))
    (folder / "tpa.html").write_text(tpa_html(record), encoding="utf-8")


def _cell(v) -> str:
    if v is None:
        return "&ndash;"
    if isinstance(v, float):
        return f"{v:.4g}"
    return html.escape(str(v))


def _interval(bounds) -> str | None:
    """A measure's 95 % interval as a cell's text, ``low – high`` (None: no interval)."""
    return None if bounds is None else f"{bounds[0]:.4g} – {bounds[1]:.4g}"


def _table(header: list[str], rows: list[list]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{_cell(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _unit_rows(entries: dict) -> list[list]:
    """Rows (name, value, unit) of tpa.json's protocol or food entries, the unit read from the end of the key (a
    speed's ``_mm_s`` is mm/s there)."""
    from chewbot.units import key_unit

    rows = []
    for key, value in entries.items():
        if isinstance(value, (dict, list)):
            continue
        name, unit = key_unit(key)
        rows.append([name.replace("_", " "), value, (unit or "").replace("mm*s", "mm/s")])
    return rows


def _named(key: str) -> str:
    """A measure's key as a header: its name and its unit in brackets (``hardness_N``: hardness [N])."""
    from chewbot.units import key_unit

    name, unit = key_unit(key)
    return name.replace("_", " ") + (f" [{unit}]" if unit else "")


def _face(face: dict | None) -> str:
    """The faces' section: the path, the lower tooth's tilt, the spread of the gap across the sample's face and the
    bite point's slide (a logged test has none)."""
    if not face:
        return ""
    return ("<h2>The teeth's faces</h2>\n<p>The robot cannot move its lower tooth straight down with its face parallel "
            "to the upper one: its condyles' planes make the bite point slide as the face stays parallel, or tilt the "
            f"face where the bite point is held. {html.escape(face.get('path', '').capitalize())}. The spread is the "
            "difference of the gap across the sample's face (its diameter x sin tilt), seen by the food's law.</p>\n"
            + _table(["", "value", "unit"], [r for r in _unit_rows(face) if r[0] != "path"]))


def tpa_html(record: dict) -> str:
    """A food scientist's report: the measures of both readings side by side with their definitions, the checks, the
    protocol as run, the sample, and the force-time (anchors and areas shaded) and force-displacement figures."""
    columns = [k for k in ("plant", "estimated") if record.get(k) is not None]
    definitions = record.get("definitions", {})
    intervals = record.get("estimated_ci95")
    header = ["measure", *columns, *(["estimated: 95 % interval"] if intervals else []), "definition"]
    measures = [[_named(m), *(record[c].get(m) for c in columns), *([_interval(intervals.get(m))] if intervals else []),
                 definitions.get(m, "")] for m in MEASURES]
    checks = [[c["name"], {True: "passed", False: "FAILED" if c["severity"] == "failure" else "warning", None: "not evaluated"}[c["passed"]],
               c["message"]] for c in record.get("checks", [])]
    failed = [c for c in record.get("checks", []) if c["passed"] is False and c["severity"] == "failure"]
    warned = [c for c in record.get("checks", []) if c["passed"] is False and c["severity"] != "failure"]
    food = record.get("food") or {}
    verdict = (f'<p class="bad">{len(failed)} check(s) failed: {html.escape(", ".join(c["name"] for c in failed))}. '
               "The measures below are not those of the protocol asked for.</p>" if failed else
               '<p class="good">No check failed: the protocol was held and the measures are in their ranges'
               + (f' ({len(warned)} warning(s): {html.escape(", ".join(c["name"] for c in warned))}).</p>' if warned else '.</p>'))
    estimator = record.get("estimator") or {}
    est_rows = [[k.replace("_", " "), v] for k, v in estimator.items() if not isinstance(v, (list, dict))]
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Texture test: {html.escape(str(food.get('name', 'logged')))}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}td,th{{padding:2px 10px;text-align:left;
vertical-align:top}}table{{border-collapse:collapse;margin-bottom:1em}}tr:nth-child(even){{background:#f4f4f4}}
.bad{{color:#a00;font-weight:bold}}.good{{color:#070}}</style></head><body>
<h1>Texture profile analysis: {html.escape(str(food.get('name', 'logged test')))}</h1>
{verdict}
<h2>Measures</h2>
<p>Bourne's measures of the two-bite test; "plant" is the sample's force in the simulation (the load cell), "estimated"
the force the robot estimates from its crank angles and torques, with each measure's 95 % interval: the range of the
measure over the estimated curve and the two bounds of its 95 % interval (the estimate &plusmn; 1.96 standard errors:
the torques', the smoothed rates' and the model's errors). Areas are works of the force over the probe's travel.</p>
{_table(header, measures)}
<h2>Force over time</h2>
<p>The anchors a texture analyser's software marks (contact, fracture, peaks, deepest points) and the areas: the first
compression (A1 up to the deepest point), the first withdrawal (its returned work, resilience's numerator), the second
bite (A2). The plant's force is the solid line, the estimate the dashed one over it.</p>
<img src="force_time.png" alt="force over time" width="1000">
<h2>Force over compression</h2><img src="force_displacement.png" alt="force over compression" width="700">
<h2>Checks</h2>
{_table(["check", "verdict", "what was found"], checks)}
<h2>The protocol as run</h2>
{_table(["setting", "value", "unit"], _unit_rows(record.get("protocol") or {}))}
{_face(record.get("face"))}
<h2>The sample</h2>
{_table(["property", "value", "unit"], _unit_rows(food))}
<h2>The force estimate</h2>
{_table(["", "value"], est_rows)}
</body></html>
"""
