"""The folder of a texture test (``chewbot tpa``): tpa.json (Bourne's measures from the plant's force and from the
torques), task.csv (the test's point path, zero bite force: a task for ``chewbot simulate --food``), the simulation's
own files (results.csv with the food's columns, run.json, its figures and report.html),
the force-time and force-displacement figures and tpa.html, written whole through :func:`chewbot.files.atomic_folder`
and recognised later by tpa.json (key ``chewbot_tpa``). From a robot's log (``chewbot tpa --log``) the folder has
tpa.json, the two figures and tpa.html.
"""

from __future__ import annotations

import html
from pathlib import Path

from chewbot.files import Marker, atomic_folder, to_json
from chewbot.food.tpa import MEASURES
from chewbot.progress import SILENT, Progress

TPA_FOLDER = Marker("texture test folder", "tpa.json", "chewbot_tpa")
TPA_FILE = "tpa.json"
TASK_FILE = "task.csv"  # the test's point path, a task for chewbot simulate --food


def write_tpa(result, out: Path, force: bool = False, progress: Progress = SILENT) -> Path:
    """Write the folder of a simulated texture test (:class:`chewbot.simulation.texture.TpaResult`)."""
    from chewbot.outputs.simulation import write_into
    from chewbot.simulation.run import input_files
    from chewbot.task.csvio import task_table

    out = Path(out)
    c = result.curves
    curves = {"plant": (c["t"], c["gap_plant"], c["force_plant"]), "estimated": (c["t"], c["gap_estimated"], c["force_estimated"])}
    with atomic_folder(out, force, TPA_FOLDER, inputs=input_files(result.simulation.options)) as tmp:
        write_into(result.simulation, tmp, progress)
        task_table(result.simulation.task).to_csv(tmp / TASK_FILE)  # plain CSV: the folder's tpa.json is chewbot's marker
        record = result.record()
        _write_common(tmp, record, curves, result.food.height, result.food.name)
    return out


def write_tpa_log(record: dict, curve: dict, height: float | None, name: str, out: Path, force: bool = False, inputs=()) -> Path:
    """Write the folder of a logged texture test: tpa.json, the figures, tpa.html."""
    out = Path(out)
    with atomic_folder(out, force, TPA_FOLDER, inputs=inputs) as tmp:
        _write_common(tmp, record, {"estimated": (curve["t"], curve["gap"], curve["force"])}, height, name)
    return out


def _write_common(folder: Path, record: dict, curves: dict, height: float | None, name: str) -> None:
    from chewbot.report.tpa_figures import force_displacement, force_time

    force_time(curves, folder / "force_time.png", name)
    force_displacement(curves, folder / "force_displacement.png", height, name)
    (folder / TPA_FILE).write_text(to_json(record))
    (folder / "tpa.html").write_text(tpa_html(record), encoding="utf-8")


def tpa_html(record: dict) -> str:
    """A one-page report: the food, the protocol, the measures side by side, the two figures."""
    columns = [k for k in ("plant", "estimated") if record.get(k) is not None]
    rows = []
    for m in MEASURES:
        cells = []
        for k in columns:
            v = record[k].get(m)
            cells.append("null" if v is None else f"{v:.4g}")
        rows.append(f"<tr><th>{html.escape(m)}</th>{''.join(f'<td>{c}</td>' for c in cells)}</tr>")
    food = record.get("food", {})
    facts = {k: record[k] for k in ("protocol", "deepest_compression_mm", "tilt_at_deepest_deg", "largest_height_mm",
                                     "estimator") if k in record}
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Texture test: {html.escape(str(food.get('name', '')))}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}td,th{{padding:2px 10px;text-align:right}}
pre{{background:#f4f4f4;padding:8px;overflow:auto}}</style></head><body>
<h1>Texture profile analysis: {html.escape(str(food.get('name', '')))}</h1>
<p>Bourne's measures of the two-bite test (definitions: docs/food.md). Areas are works of the force over the probe's
travel.</p>
<table><tr><th>measure</th>{''.join(f'<th>{c}</th>' for c in columns)}</tr>{''.join(rows)}</table>
<h2>Force over time</h2><img src="force_time.png" alt="force over time" width="900">
<h2>Force over compression</h2><img src="force_displacement.png" alt="force over compression" width="700">
<h2>The food and the test</h2><pre>{html.escape(to_json({'food': food, **facts}))}</pre>
</body></html>
"""
