"""``report.html`` of a simulation (``chewbot simulate``) and of a comparison of controllers (``--compare``).

The page of :mod:`chewbot.report.html` with what a simulation adds: the simulated robot beside the reference one
(each animated in 3D on the plant's model), the tracking figures (RMS and peak error, peak torque, time in
saturation, where the robot was stopped), the validity checks of the simulated motion and every column of
results.csv. The comparison's page puts the controllers' figures in one table and their errors in one plot.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from chewbot.report.html import RUN_NAV, checks_section, escape, float32, number, plots_section, html_table, render_page, robot_figure
from chewbot.report.view import PLOT_POINTS, RunView, ViewBuilder, every_kth
from chewbot.table import Table
from chewbot.run.columns import kinematics_table
from chewbot.units import factor


def _page(title: str, subtitle: str, body: list[str], figures: dict, path: Path, nav=RUN_NAV) -> Path:
    Path(path).write_text(render_page(title, subtitle, nav, "\n".join(body), figures), encoding="utf-8")
    return Path(path)


def _view(table: Table) -> RunView:
    """The report's view of a whole table (decimated plots, the animation's frames)."""
    builder = ViewBuilder(table["t"])
    builder.update(table)
    return builder.result()


def controller_label(result) -> str:
    """The controller in words: its kind, its inverse dynamics, its rate."""
    o = result.options
    inverse = o.inverse
    model_based = "" if not o.controller.needs.inverse_dynamics else f", inverse dynamics {inverse.method}" + (
        f" (goal {inverse.goal})" if inverse.goal else "") + (", with friction" if inverse.friction else "")
    rate = "continuous (every integrator stage)" if o.rate is None else f"{o.rate:g} Hz, torques held"
    return f"{o.controller.name}{model_based}, {rate}"


def write_simulation_report(result, record: dict, view: RunView, path: Path, files: list[str] | None = None) -> Path:
    """Write ``report.html`` for a computed simulation from what its folder holds: run.json's ``record`` (as read
    back) and ``view``, the view of its results.csv; ``files`` names the other files of its folder."""
    figures: dict[str, dict] = {}
    o = result.options
    body = [_robots_section(result, view, figures), checks_section(record), _tracking_section({o.controller.name: result}),
            _food_section(result), plots_section(view, figures), _run_section(result, files or [])]
    return _page(f"chewbot simulation: {o.controller.name} on {result.plant_model.name}, {result.task.name} ({result.task.side} side)",
                 f"{controller_label(result)} · {result.table.n} rows · plant {o.engine.name}, friction {_switch(o.friction)}", body,
                 figures, path)


def _switch(on: bool) -> str:
    return "on" if on else "off"


def _robots_section(result, view: RunView, figures: dict) -> str:
    side = result.task.side
    food = result.info.get("food")
    figures["robot"] = robot_figure(result.plant_model, view, side, None if food is None else sample_diameter(food["food"]))
    figures["robot_reference"] = robot_figure(result.plant_model, _view(kinematics_table(result.reference_kinematics)), side)
    stopped = result.simulation.stopped
    note = (f' <span class="warn">The robot left the workspace at t = {stopped["t"]:.4g} s ({escape(stopped["reason"])}): the motion ends '
            "at the last pose inside.</span>" if stopped else "")
    return ('<section id="robot-section"><h2>The simulated robot beside the reference</h2>'
            '<p class="note">{S} coordinates in mm, both on the plant\'s model; left the simulated motion, right the reference '
            f"(the task), each with its own time slider.{_sample_note(food)}{note}</p>"
            '<div class="grid"><div><h3>simulated</h3><div id="robot" class="plot"></div></div>'
            '<div><h3>reference</h3><div id="robot_reference" class="plot" style="height: 720px"></div></div></div></section>')


def sample_diameter(food: dict) -> float:
    """The diameter (m) the food sample is drawn with: a cylinder's, or a sphere's (its height) drawn as a cylinder."""
    return food.get("diameter_mm", food["height_mm"]) * factor("mm")


def _sample_note(food: dict | None) -> str:
    if food is None:
        return ""
    sphere = "" if "diameter_mm" in food["food"] else " (a sphere, drawn as a cylinder as wide as it is tall)"
    return (f" The {escape(food['food']['name'])}{sphere} stands on the lower molar at the bite point, its bottom face on "
            "the lower tooth's, its fibres cut off at the upper tooth: compressed with the gap, green while intact, "
            "brown and crushed to its new unloaded height once broken (results.csv: food_height, food_broken).")


def metrics_rows(results: dict) -> list[list[str]]:
    """One row per controller: RMS and peak position and orientation error, peak torque, time in saturation,
    stopped (the comparison's table, printed and in the report)."""
    rows = []
    for label, r in results.items():
        m = r.metrics
        stopped = m["stopped"]
        rows.append([label, number(m["rms_position_mm"]), number(m["peak_position_mm"]), number(m["rms_orientation_deg"]),
                     number(m["peak_orientation_deg"]), number(m["peak_torque_Nm"]), number(m["saturated_s"]),
                     "" if stopped is None else f"at t = {stopped['t']:.4g} s: {stopped['reason']}"])
    return rows


METRICS_HEADER = ["controller", "RMS position [mm]", "peak position [mm]", "RMS orientation [deg]", "peak orientation [deg]",
                  "peak torque [N·m]", "saturated [s]", "left the workspace"]


def _tracking_section(results: dict) -> str:
    rows = [[escape(c) for c in row] for row in metrics_rows(results)]
    per = []
    for label, r in results.items():
        for name, v in r.metrics["per_coordinate"].items():
            per.append([escape(label), escape(name), number(v["rms"]), number(v["peak"]), v["unit"]])
    return ('<section id="summary"><h2>Tracking</h2>' + html_table(METRICS_HEADER, rows)
            + '<p class="note">Position: the norm of the translational errors (reference minus simulated), orientation: the norm '
            "of the errors of the Euler angles, over the rows; peak torque: the largest applied abs(τ<sub>i</sub>); saturated: "
            "how long a commanded torque was beyond the limit.</p><h3>Per coordinate</h3>"
            + html_table(["controller", "coordinate", "RMS", "peak", "unit"], per) + "</section>")


def _food_section(result) -> str:
    """With a food in the plant: the force tracking of a controller that follows the task's Fz, the sample, and the
    food's events (the law's kinks and its fracture, located between the ticks); empty without a food."""
    food = result.info.get("food")
    if food is None:
        return ""
    parts = ['<section id="food"><h2>The food</h2>']
    f = food["food"]
    parts.append(html_table(["sample", "height [mm]", "peak force [N]", "deepest compression [mm]", "tilt there [deg]"],
                            [[escape(f["name"]), number(f["height_mm"]), number(food["peak_force_N"]),
                              number(food["deepest_compression_m"] / factor("mm")), number(food["tilt_at_deepest_deg"])]]))
    tracking = result.metrics.get("force")
    if tracking is not None:
        parts.append("<h3>Force tracking</h3>")
        if tracking["samples"]:
            parts.append(html_table(["RMS error [N]", "RMS error [% of the reference's peak]", "peak error [N]", "reference's peak [N]"],
                                    [[number(tracking["rms_N"]), number(tracking["rms_percent"]), number(tracking["peak_N"]),
                                      number(tracking["reference_peak_N"])]]))
            parts.append('<p class="note">The plant\'s Fz minus the task\'s Fz where the reference is not zero; the check '
                         "<code>force-tracking</code> bounds the RMS.</p>")
        else:
            parts.append('<p class="note">The task\'s force reference is zero throughout.</p>')
    events = food["events"]
    parts.append(f"<h3>The food's events ({len(events)})</h3>")
    if events:
        parts.append(html_table(["t [s]", "event", "compression [mm]"],
                                [[number(e["t"], 6), escape(e["event"]), number(e["delta_m"] / factor("mm"))] for e in events]))
    parts.append(f'<p class="note">{escape(food["event_location"])}.</p></section>')
    return "".join(parts)


def _integrator_text(info: dict, sim) -> str:
    """The plant's integrator in words: chewbot's Radau IIA, or MuJoCo's solver settings (run.json's plant)."""
    if "integrator" in info:
        i = info["integrator"]
        return (f"{escape(i['method'])}; steps of at most {i['max_step_s'] / factor('ms'):g} ms, {i['split_steps']} split; largest "
                f"residual {number(i['largest_residual_Nm'], 3)} N·m")
    p = info["plant"]
    settings = ", ".join(f"{escape(k)} {escape(str(v))}" for k, v in p["solver"].items())
    return (f"MuJoCo {escape(p['mujoco_version'])} (robot.xml): {settings}; largest residual of chewbot's equations at MuJoCo's "
            f"accelerations {number(float(np.max(sim.residual)), 3)} N·m")


def _run_section(result, files: list[str]) -> str:
    o, sim = result.options, result.simulation
    info = result.info["simulation"]
    rows = [["controller", escape(controller_label(result)) + f" on the model {escape(result.model.name)} (<code>{escape(result.model.source)}</code>)"],
            ["plant", f"{escape(result.plant_model.name)} (<code>{escape(result.plant_model.source)}</code>), simulated by "
                      f"{escape(o.engine.name)}, friction {_switch(o.friction)}"
             + (f", --plant-set {escape(', '.join(f'{k}={v:g}' for k, v in o.plant_overrides.items()))}" if o.plant_overrides else "")],
            ["bite force", "hidden from the controller (--bite-unknown)" if o.bite_unknown else "known to the controller"],
            ["sensor", f"crank encoders with noise of {o.noise_rad:g} rad (seed {o.seed})" if o.noise_rad else "the plant's state"],
            ["integrator", _integrator_text(info, sim)],
            ["task", f"{escape(result.task.name)} from <code>{escape(result.task.source)}</code>, {sim.n} rows over {sim.t[-1] - sim.t[0]:.4g} s"],
            ["timings", ", ".join(f"{escape(k)} {v:.3g} s" for k, v in result.info.get("timings", {}).items())]]
    if files:
        rows.append(["files", ", ".join(f'<a href="{escape(f)}">{escape(f)}</a>' for f in files)])
    return f'<section id="run"><h2>Run</h2>{html_table(["", ""], rows).replace("<td>", "<td class=text>")}</section>'


def write_comparison_report(results: dict, path: Path, files: list[str] | None = None) -> Path:
    """The comparison's ``report.html``: the table of :func:`metrics_rows` and the controllers' errors and torques
    plotted together; each controller's own report is in its folder."""
    figures = {"errors": _comparison_figure(results)}
    first = next(iter(results.values()))
    links = ", ".join(f'<a href="{escape(c)}/report.html">{escape(c)}</a>' for c in results)
    body = [_tracking_section(results),
            '<section id="plots"><h2>Tracking error compared</h2><p class="note">The norm of the translational errors '
            f"(mm) against time, each simulation until it was stopped. Each simulation's report: {links}.</p>"
            '<div id="errors" class="plot" style="height: 420px"></div></section>']
    if files:
        listed = ", ".join(f'<a href="{escape(f)}">{escape(f)}</a>' for f in files)
        body.append(f'<section id="run"><h2>Files</h2><p>{listed}</p></section>')
    what = "controllers" if len({r.options.controller.name for r in results.values()}) > 1 else "plants' engines"
    return _page(f"chewbot simulation: {what} compared on {first.plant_model.name}, {first.task.name}",
                 f"plant friction {_switch(first.options.friction)} · {len(results)} {what}", body, figures, path,
                 nav=(("summary", "Tracking"), ("plots", "Errors"), ("run", "Files")))


def _comparison_figure(results: dict) -> dict:
    data = []
    for label, r in results.items():
        idx = every_kth(r.table.n, PLOT_POINTS)
        names = [n for n in r.table.columns if n.startswith("e_") and r.table.units[n] == "m"]
        err = np.linalg.norm(np.column_stack([r.table[n] for n in names]), axis=1)[idx] / factor("mm")
        data.append({"type": "scatter", "x": float32(r.table["t"][idx]), "y": float32(err), "mode": "lines", "name": label,
                     "hovertemplate": f"{label}: %{{y:.3g}} mm<extra></extra>"})
    return {"data": data, "layout": {"xaxis": {"title": {"text": "time t [s]"}}, "yaxis": {"title": {"text": "position error [mm]"}, "type": "log"},
                                     "margin": {"l": 60, "r": 20, "t": 10, "b": 40}}}
