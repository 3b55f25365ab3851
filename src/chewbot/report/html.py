"""``report.html``: one self-contained page per run, readable offline.

The page inlines plotly.js from the installed plotly package (no network), draws the robot in 3D animated
along the task, summarises the run (ranges, transmission angles, peak and RMS torques, MCI, the indices
F1..F7) and plots every column of the results table, interactively and with its unit. It shows what the run
contains: a stage that did not run (no torques, no Newton-Euler indices) leaves its part out.

It is drawn from the run's record (run.json's content), its model and the :class:`~chewbot.report.view.RunView`
of its table, so that a report is the same whether it is written by the run or later from the folder
(``chewbot report DIR``), and a run of any length gives a page of the same size: the plots have at most
:data:`~chewbot.report.view.PLOT_POINTS` points per series (beyond, each pair of points is the smallest and the
largest value of a bin of consecutive samples: no peak is lost), the animation one frame per
:data:`~chewbot.report.view.FRAME_STEP_S` (at most :data:`~chewbot.report.view.MAX_FRAMES`). The summary uses every
sample. The figures are written as plotly.js's JSON directly (arrays as typed binary data), with the template
"plotly_white" of the plotly package; plotly's Python figure objects would validate every property of every
frame, which takes longer than the rest of a run.
"""

from __future__ import annotations

import base64
import html
import importlib.util
import json
import math
import os
from functools import cache
from importlib import resources
from pathlib import Path
from string import Template

import numpy as np

from chewbot.dynamics.indices import INDEX_UNITS
from chewbot.model import Model
from chewbot.report.summary import INDEX_NAMES, NEAR_SINGULAR_DEG, contact_note, infeasible_samples, normal_force_stats, numbered_columns, performance_indices, solver_notes
from chewbot.report.view import FRAME_STEP_S, MAX_FRAMES, RunView
from chewbot.table import Table
from chewbot.run.columns import POSE_NAMES
from chewbot.rotation import matrix_from_euler_angles
from chewbot.units import factor, shown

FORCE_SCALE_MM_PER_N = 0.25  # bite-force arrow: 80 N is drawn 20 mm long
MM = factor("mm")  # the 3-D views are drawn in mm
MANDIBLE_POINTS = ("T_L", "T_R", "I", "B_L", "B_R")
ARCH = ("T_R", "B_R", "I", "B_L", "T_L")  # drawn as one line: the U of the lower jaw
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")
# Columns plotted in the task-space and joint-space figures (everything else is plotted by groups).
LEVELS = (("", "displacement"), ("d", "velocity"), ("dd", "acceleration"))
THETA_NAMES = tuple(f"theta{i}" for i in range(1, 7))


def write_report(record: dict, model: Model, view: RunView, path: Path, files: list[str] | None = None) -> Path:
    """Write ``report.html`` for a run: ``record`` is its run.json (a dict), ``view`` the view of its table;
    ``files`` names the files of the run folder the page links to."""
    figures: dict[str, dict] = {}
    o = record["options"]
    body = [
        _robot_section(model, view, o["side"], figures),
        checks_section(record),
        _summary_section(record, model, view),
        plots_section(view, figures),
        _run_section(record, model, view, files or []),
    ]
    page = render_page(
        title=f"chewbot report: {model.name}, {record['task']['name']} ({o['side']} side)",
        subtitle=f"{model.description} · {view.n} samples · {o['orientation']} · {dynamics_label(record, model)}",
        nav=RUN_NAV, body="\n".join(body), figures=figures)
    Path(path).write_text(page, encoding="utf-8")
    return Path(path)


RUN_NAV = (("robot-section", "Robot"), ("checks", "Checks"), ("summary", "Summary"), ("plots", "Plots"),
           ("run", "Run details and files"))


def render_page(title: str, subtitle: str, nav, body: str, figures: dict) -> str:
    """A self-contained page in chewbot's report template: ``nav`` (anchor, label) pairs in the header, ``body``
    (HTML sections), ``figures`` drawn into the elements of their ids (plotly.js inlined): each a figure as plotly.js's
    JSON (a dict, NumPy arrays allowed) or a plotly ``Figure``."""
    template = Template(resources.files("chewbot.report").joinpath("template.html").read_text("utf-8"))
    figures = {key: fig if isinstance(fig, dict) else _plotly_json(fig) for key, fig in figures.items()}
    return template.substitute(
        title=html.escape(title),
        subtitle=html.escape(subtitle),
        nav="".join(f'<a href="#{html.escape(a)}">{html.escape(label)}</a>' for a, label in nav),
        plotlyjs=_plotly_file("plotly.min.js"),
        body=body,
        # "<" only occurs inside JSON strings, where \u003c means the same: no "</script>" can end the block
        figures=json.dumps({"template": json.loads(_plotly_file("templates/plotly_white.json")), "figures": figures},
                           separators=(",", ":"), default=_json_value, allow_nan=False).replace("<", "\\u003c"),
    )


def _plotly_json(figure) -> dict:
    """A plotly ``Figure`` as plotly.js's JSON (NaN as null, as plotly writes it)."""
    import plotly.io as pio

    return json.loads(pio.to_json(figure, validate=False))


@cache
def _plotly_file(name: str) -> str:
    """A file of the installed plotly package's data (plotly.js, a template), found without importing plotly."""
    spec = importlib.util.find_spec("plotly")
    return (Path(spec.submodule_search_locations[0]) / "package_data" / name).read_text("utf-8")


def _json_value(value):
    """NumPy arrays as plotly.js's typed arrays (binary, base64), NumPy scalars as numbers."""
    if isinstance(value, np.ndarray):
        kind = {"f": "f4", "i": "i4"}.get(value.dtype.kind, "f8")
        if value.dtype == np.float64:
            kind = "f8"
        return {"dtype": kind, "bdata": base64.b64encode(np.ascontiguousarray(value, dtype="<" + kind).tobytes()).decode()}
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON")


def float32(values) -> np.ndarray:
    """A series as 32-bit floats: plenty for a plot, half the bytes."""
    return np.asarray(values, dtype=np.float32)


# --- the robot in 3D ------------------------------------------------------------------------------------


def mandible_body_points(model: Model) -> tuple[tuple[str, ...], np.ndarray]:
    """Names and positions in {M} (m) of the points drawn on the mandible: M_1..M_6, T_L, T_R, I, B_L, B_R."""
    names = tuple(f"M{i}" for i in range(1, 7)) + MANDIBLE_POINTS
    pts = np.vstack([model.M, model.hkp.T_L, model.hkp.T_R, model.incisor, model.molar_left, model.molar_right])
    return names, pts


def robot_positions(model: Model, rows: Table) -> dict[str, np.ndarray]:
    """Positions in {S} (m) at the samples of ``rows`` (columns X..gamma, theta1..6): ``S`` (n, 6, 3) crank tips
    from theta, ``body`` (n, 11, 3) the mandible points of :func:`mandible_body_points` from the pose (O_M and XYZ
    Euler angles)."""
    from chewbot.model.chains import crank_tips

    X = np.column_stack([rows[name] for name in POSE_NAMES])
    theta = np.column_stack([rows[name] for name in THETA_NAMES])
    R = matrix_from_euler_angles(X[:, 3:6])
    _, body = mandible_body_points(model)
    return {"S": crank_tips(model, theta), "body": X[:, None, :3] + np.einsum("nij,kj->nki", R, body)}


def _segments(a: np.ndarray, b: np.ndarray) -> list[list[float | None]]:
    """x, y, z lists (mm) of the segments a_k b_k, separated by gaps, for one scatter3d line trace."""
    out: list[list[float | None]] = [[], [], []]
    for p, q in zip(np.round(a / MM, 3).tolist(), np.round(b / MM, 3).tolist()):
        for c in range(3):
            out[c] += [p[c], q[c], None]
    return out


def _xyz(points: np.ndarray) -> dict[str, list[float]]:
    mm = np.round(points / MM, 3)
    return {"x": mm[:, 0].tolist(), "y": mm[:, 1].tolist(), "z": mm[:, 2].tolist()}


def _bite_point(side: str) -> str:
    return "B_L" if side == "left" else "B_R"


POINT_HOVER = "%{text}: (%{x:.2f}, %{y:.2f}, %{z:.2f}) mm<extra></extra>"


def _moving_traces(model: Model, side: str, body: np.ndarray, S: np.ndarray, F: np.ndarray) -> list[dict]:
    """The traces that move, at one frame: cranks, couplers, mandible, its points, bite force."""
    names, _ = mandible_body_points(model)
    x, y, z = _segments(model.G, S)
    cranks = {"type": "scatter3d", "x": x, "y": y, "z": z, "mode": "lines", "line": {"color": "#d9822b", "width": 9},
              "name": "cranks G<sub>i</sub>S<sub>i</sub>", "hoverinfo": "skip"}
    x, y, z = _segments(S, body[:6])
    couplers = {"type": "scatter3d", "x": x, "y": y, "z": z, "mode": "lines+markers", "line": {"color": "#4a5a6a", "width": 5},
                "marker": {"size": 3, "color": "#4a5a6a"}, "name": "couplers S<sub>i</sub>M<sub>i</sub>", "hoverinfo": "skip"}
    # the hull of the mandible's points, computed by plotly.js (alphahull 0: the convex hull)
    mandible = {"type": "mesh3d", **_xyz(body), "alphahull": 0, "color": "#e8c9a0", "opacity": 0.3, "flatshading": True,
                "name": "mandible (hull of its points)", "showlegend": True, "hoverinfo": "skip"}
    arch = [names.index(n) for n in ARCH]
    points = {"type": "scatter3d", **_xyz(body[arch]), "mode": "lines+markers+text", "text": list(ARCH), "textposition": "top center",
              "textfont": {"size": 11, "color": "#7a3b12"}, "line": {"color": "#a0522d", "width": 6}, "marker": {"size": 5, "color": "#7a3b12"},
              "name": "condyles, molars, incisor", "hovertemplate": POINT_HOVER}
    ends = {"type": "scatter3d", **_xyz(body[:6]), "mode": "markers+text", "text": list(names[:6]), "textposition": "bottom center",
            "textfont": {"size": 9, "color": "#4a5a6a"}, "marker": {"size": 3, "color": "#4a5a6a"}, "name": "coupler ends M<sub>i</sub>",
            "hovertemplate": POINT_HOVER}
    B = body[names.index(_bite_point(side))]
    x, y, z = _segments(B[None], (B + F * FORCE_SCALE_MM_PER_N * MM)[None])
    force = {"type": "scatter3d", "x": x, "y": y, "z": z, "mode": "lines", "line": {"color": "#c81e1e", "width": 8},
             "name": f"bite force F<sub>B</sub> ({1 / FORCE_SCALE_MM_PER_N:g} N per mm)",
             "hovertext": f"F_B = ({F[0]:.1f}, {F[1]:.1f}, {F[2]:.1f}) N", "hoverinfo": "text"}
    return [cranks, couplers, mandible, points, ends, force]


# The food sample's cylinder is drawn with this many sides; intact and crushed in these colours.
SAMPLE_SIDES = 32
SAMPLE_COLOURS = {False: "#5a9e3a", True: "#8b5a2b"}


def sample_vertices(model: Model, side: str, rows: Table, diameter: float) -> np.ndarray:
    """The food sample's cylinder at the samples of ``rows`` (n, 2 + 2 SAMPLE_SIDES, 3; m, {S}): the centres of its
    bottom and top faces, then its bottom and top rims. It stands on the lower tooth at the bite point of ``side``, its
    bottom face in the tooth's plane (tilted with the mandible), its axis along the tooth's normal, ``diameter`` (m)
    across and ``food_height`` (its unloaded height, crushed once broken) tall; each of its fibres is cut off at the
    upper tooth, the plane z = B_z at home ({M} = {S} there): compressed by the gap, as the food's law has it."""
    X = np.column_stack([rows[name] for name in POSE_NAMES])
    R = matrix_from_euler_angles(X[:, 3:6])
    B = X[:, :3] + R @ np.asarray(model.molar(side), float)
    angle = 2 * np.pi * np.arange(SAMPLE_SIDES) / SAMPLE_SIDES
    rim = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(SAMPLE_SIDES)]) * diameter / 2
    bottom = np.concatenate([B[:, None], B[:, None] + np.einsum("nij,kj->nki", R, rim)], axis=1)
    top = bottom + rows["food_height"][:, None, None] * R[:, None, :, 2]
    top[..., 2] = np.minimum(top[..., 2], float(np.asarray(model.molar(side), float)[2]))
    return np.concatenate([bottom[:, :1], top[:, :1], bottom[:, 1:], top[:, 1:]], axis=1)


def _sample_trace(vertices: np.ndarray, broken: bool) -> dict:
    """The food sample at one frame (:func:`sample_vertices`): its caps and its side as one mesh."""
    n = SAMPLE_SIDES
    k = np.arange(n)
    nxt = (k + 1) % n
    b, t = 2 + k, 2 + n + k
    i = np.concatenate([np.zeros(n, int), np.ones(n, int), b, 2 + nxt])
    j = np.concatenate([b, t, 2 + nxt, 2 + n + nxt])
    kk = np.concatenate([2 + nxt, 2 + n + nxt, t, t])
    return {"type": "mesh3d", **_xyz(vertices), "i": i.tolist(), "j": j.tolist(), "k": kk.tolist(),
            "color": SAMPLE_COLOURS[bool(broken)], "opacity": 0.85, "flatshading": True,
            "name": "food sample (green intact, brown crushed)", "showlegend": True, "hoverinfo": "name"}


def _static_traces(model: Model, paths: Table) -> list[dict]:
    """Base points, the sockets' planes (target only) and the paths of incisor and condyles over the task."""
    traces = [{"type": "scatter3d", **_xyz(model.G), "mode": "markers+text", "text": [f"G{i}" for i in range(1, 7)],
               "textposition": "bottom center", "textfont": {"size": 10}, "marker": {"size": 6, "color": "#1f3a5a", "symbol": "square"},
               "name": "base points G<sub>i</sub>", "hovertemplate": POINT_HOVER}]
    if model.has_hkp:
        h = model.hkp
        corners = []
        for y_range in (h.y_left, h.y_right):
            for xs, ys in ((0, 0), (1, 0), (1, 1), (0, 1)):
                x, y = h.x_range[xs], y_range[ys]
                corners.append((x, y, -h.p1 * x - h.p2))  # on p1 x + z + p2 = 0
        traces.append({"type": "mesh3d", **_xyz(np.array(corners)), "i": [0, 0, 4, 4], "j": [1, 2, 5, 6], "k": [2, 3, 6, 7],
                       "color": "#5b9bd5", "opacity": 0.5, "name": "sockets: planes p<sub>1</sub>x + z + p<sub>2</sub> = 0",
                       "showlegend": True, "hoverinfo": "name"})
    body = robot_positions(model, paths)["body"]
    names, _ = mandible_body_points(model)
    for label, keys in (("incisor path", ("I",)), ("condyle paths", ("T_L", "T_R"))):
        xyz = {"x": [], "y": [], "z": []}
        for key in keys:
            for axis, values in _xyz(body[:, names.index(key)]).items():
                xyz[axis] += values + [None]
        traces.append({"type": "scatter3d", **xyz, "mode": "lines", "line": {"color": "#9aa7b4", "width": 2}, "name": label,
                       "hoverinfo": "skip"})
    return traces


def robot_figure(model: Model, view: RunView, side: str, sample_diameter: float | None = None) -> dict:
    """The robot in 3D (mm, {S}), animated along the task with a time slider and play/pause buttons; with
    ``sample_diameter`` (m) the food sample too (:func:`sample_vertices`, from the rows' ``food_height`` and
    ``food_broken``)."""
    rows = view.at(view.frames)
    pos = robot_positions(model, rows)
    force = np.column_stack([rows[name] for name in ("Fx", "Fy", "Fz")])
    static = _static_traces(model, view.at(view.paths))
    sample = None if sample_diameter is None else sample_vertices(model, side, rows, sample_diameter)
    moving = list(range(len(static), len(static) + 6 + (sample is not None)))
    t = rows["t"]
    frames = [{"name": f"{t[f]:.3f}", "data": _moving_traces(model, side, pos["body"][f], pos["S"][f], force[f])
               + ([] if sample is None else [_sample_trace(sample[f], rows["food_broken"][f] > 0)]), "traces": moving}
              for f in range(len(t))]
    names, _ = mandible_body_points(model)
    arrows = pos["body"][:, names.index(_bite_point(side))] / MM + force * FORCE_SCALE_MM_PER_N
    everything = np.vstack([model.G / MM, pos["S"].reshape(-1, 3) / MM, pos["body"].reshape(-1, 3) / MM, arrows.reshape(-1, 3)]
                           + ([] if sample is None else [sample.reshape(-1, 3) / MM]))
    lo, hi = everything.min(axis=0) - 8, everything.max(axis=0) + 8
    span = hi - lo
    axis = lambda name, j: {"title": {"text": f"{name}<sub>S</sub> [mm]"}, "range": [lo[j], hi[j]],  # noqa: E731
                            "backgroundcolor": "#f7f9fb", "gridcolor": "#dde3ea"}
    play = {"frame": {"duration": FRAME_STEP_S / factor("ms"), "redraw": True}, "fromcurrent": True, "transition": {"duration": 0}, "mode": "immediate"}
    pause = {"frame": {"duration": 0, "redraw": False}, "mode": "immediate"}
    layout = {
        "margin": {"l": 0, "r": 0, "t": 10, "b": 10},
        "legend": {"x": 0.0, "y": 0.98, "bgcolor": "rgba(255,255,255,0.7)", "font": {"size": 11}},
        "scene": {"domain": {"y": [0.1, 1.0]}, "xaxis": axis("X", 0), "yaxis": axis("Y", 1), "zaxis": axis("Z", 2), "aspectmode": "manual",
                  "aspectratio": {"x": span[0] / span.max(), "y": span[1] / span.max(), "z": span[2] / span.max()},
                  # the eye far enough that the axes and their titles stay inside the scene at every frame
                  "camera": {"eye": {"x": 1.3, "y": -1.25, "z": 0.7}, "up": {"x": 0, "y": 0, "z": 1}}},
        "updatemenus": [{"type": "buttons", "direction": "left", "x": 0.02, "y": 0.02, "xanchor": "left", "yanchor": "bottom", "showactive": False,
                         "buttons": [{"label": "▶ play", "method": "animate", "args": [None, play]},
                                     {"label": "❚❚ pause", "method": "animate", "args": [[None], pause]}]}],
        "sliders": [{"x": 0.2, "y": 0.02, "len": 0.78, "yanchor": "bottom", "pad": {"t": 0, "b": 0},
                     "currentvalue": {"prefix": "t = ", "suffix": " s"},
                     "steps": [{"label": fr["name"], "method": "animate",
                                "args": [[fr["name"]], {"frame": {"duration": 0, "redraw": True}, "mode": "immediate"}]} for fr in frames]}],
    }
    return {"data": static + frames[0]["data"], "layout": layout, "frames": frames}


# --- time plots -----------------------------------------------------------------------------------------

# Display units: lengths in mm and angles in degrees read better than m and rad at the robot's scale.
def display_unit(unit: str) -> tuple[float, str]:
    """The factor and the label to show a column of ``unit`` (SI) with: m -> mm, rad -> deg, rates alike
    (:func:`chewbot.units.shown`)."""
    if unit == "1":
        return 1.0, "-"
    factor, label = shown(unit)
    return factor, label.replace("*", "·").replace("^2", "²").replace("^3", "³")


def _grid(rows: int, cols: int, vertical: float, horizontal: float = 0.0) -> dict:
    """The axes of a grid of panels (as plotly's make_subplots lays them out), x shared within each column: the
    bottom panel's axis carries the tick labels."""
    layout = {}
    width, height = (1 - horizontal * (cols - 1)) / cols, (1 - vertical * (rows - 1)) / rows
    for r in range(rows):
        for c in range(cols):
            k = r * cols + c + 1
            bottom = (rows - 1) * cols + c + 1
            x0, y1 = c * (width + horizontal), 1 - r * (height + vertical)
            xaxis = {"anchor": f"y{k}", "domain": [x0, x0 + width]}
            if k != bottom:
                xaxis.update(matches=f"x{bottom}", showticklabels=False)
            layout[_axis("xaxis", k)] = xaxis
            layout[_axis("yaxis", k)] = {"anchor": f"x{k}", "domain": [max(y1 - height, 0.0), y1]}
    return layout


def _axis(kind: str, k: int) -> str:
    return kind if k == 1 else f"{kind}{k}"


def _series(t: np.ndarray, table: Table, names, panel: int = 1, labels=None, groups=None, color0: int = 0, first_row: bool = True) -> tuple[list[dict], str]:
    """One line per column (display units, hover with the unit) in panel ``panel``; and the unit's label.

    ``groups``: legend groups, one per column: series of one group (X, dX, ddX) toggle together and show one
    legend entry, the group's name.
    """
    label, traces = "", []
    for j, name in enumerate(names):
        factor, label = display_unit(table.units[name])
        shown = (labels or names)[j]
        legend = {"legendgroup": groups[j], "name": groups[j], "showlegend": first_row} if groups else {"name": shown}
        traces.append({"type": "scatter", "x": t, "y": float32(table[name] * factor), "mode": "lines", **legend,
                       "line": {"width": 1.6, "color": COLORS[(color0 + j) % len(COLORS)]},
                       "hovertemplate": f"{shown} = %{{y:.4g}} {label}<extra></extra>",
                       **({} if panel == 1 else {"xaxis": f"x{panel}", "yaxis": f"y{panel}"})})
    return traces, label


def figure_layout(figure, height: int) -> None:
    """The layout of the report's time plots on a plotly ``Figure`` (as :func:`_figure` gives the JSON ones)."""
    figure.update_layout(height=height, margin=dict(l=70, r=20, t=30, b=50), hovermode="x unified",
                         legend=dict(orientation="h", y=1.0, yanchor="bottom", x=0, font=dict(size=12)))
    figure.update_xaxes(showspikes=True, spikemode="across", spikethickness=1)


def _figure(data: list[dict], layout: dict, height: int) -> dict:
    for key, axis in layout.items():
        if key.startswith("xaxis"):
            axis.update(showspikes=True, spikemode="across", spikethickness=1)
    return {"data": data, "layout": {**layout, "height": height, "margin": {"l": 70, "r": 20, "t": 30, "b": 50}, "hovermode": "x unified",
                                     "legend": {"orientation": "h", "y": 1.0, "yanchor": "bottom", "x": 0, "font": {"size": 12}}}}


def _titled(layout: dict, key: str, text: str) -> None:
    layout[key]["title"] = {"text": text}


def task_space_figure(table: Table) -> dict:
    """X, Y, Z and alpha, beta, gamma of the mandible with their rates (seed 000, Fig. 3), 3 x 2 panels."""
    layout, data = _grid(3, 2, 0.06, 0.08), []
    for r, (prefix, level) in enumerate(LEVELS):
        for c, names in enumerate((POSE_NAMES[:3], POSE_NAMES[3:])):
            k = 2 * r + c + 1
            traces, unit = _series(table["t"], table, [prefix + n for n in names], k, groups=list(names), color0=3 * c, first_row=r == 0)
            data += traces
            _titled(layout, _axis("yaxis", k), f"{level} [{unit}]")
    for k in (5, 6):
        _titled(layout, _axis("xaxis", k), "time t [s]")
    return _figure(data, layout, 760)


def joint_space_figure(table: Table) -> dict:
    """The six actuator angles with their rates (seed 000, Fig. 4), three panels."""
    layout, data = _grid(3, 1, 0.05), []
    for r, (prefix, level) in enumerate(LEVELS):
        traces, unit = _series(table["t"], table, [prefix + n for n in THETA_NAMES], r + 1, labels=[f"{prefix}θ{i}" for i in range(1, 7)],
                               groups=[f"θ{i}" for i in range(1, 7)], first_row=r == 0)
        data += traces
        _titled(layout, _axis("yaxis", r + 1), f"actuator {level} [{unit}]")
    _titled(layout, "xaxis3", "time t [s]")
    return _figure(data, layout, 760)


def column_groups(table: Table, skip: set[str]) -> list[list[str]]:
    """Runs of consecutive columns with the same unit and description (a block such as tau1..tau6)."""
    groups: list[list[str]] = []
    key = None
    for name in table.columns:
        if name in skip:
            key = None
            continue
        k = (table.units[name], table.descriptions.get(name, ""))
        if groups and k == key:
            groups[-1].append(name)
        else:
            groups.append([name])
        key = k
    return groups


def group_figure(table: Table, names: list[str]) -> dict:
    """One panel with the columns ``names`` against time; the y axis is named by the names' common stem."""
    data, unit = _series(table["t"], table, names)
    stem = os.path.commonprefix(names).rstrip("_") or names[0]
    return _figure(data, {"xaxis": {"title": {"text": "time t [s]"}}, "yaxis": {"title": {"text": f"{stem} [{unit}]"}}}, 330)


def transmission_figure(table: Table) -> dict:
    """Transmission angle of each chain (deg, from the columns mu1..mu6) with the near-singular threshold."""
    data = [{"type": "scatter", "x": table["t"], "y": float32(np.degrees(table[f"mu{k + 1}"])), "mode": "lines", "name": f"chain {k + 1}",
             "line": {"width": 1.6, "color": COLORS[k]}, "hovertemplate": f"chain {k + 1}: %{{y:.2f}} deg<extra></extra>"} for k in range(6)]
    layout = {"xaxis": {"title": {"text": "time t [s]"}}, "yaxis": {"title": {"text": "transmission angle [deg]"}, "range": [0, 90]},
              "shapes": [{"type": "line", "xref": "x domain", "x0": 0, "x1": 1, "yref": "y", "y0": NEAR_SINGULAR_DEG, "y1": NEAR_SINGULAR_DEG,
                          "line": {"color": "#b4461a", "dash": "dash"}}],
              "annotations": [{"showarrow": False, "text": f"near-singular below {NEAR_SINGULAR_DEG:g} deg", "x": 1, "xanchor": "right",
                               "xref": "x domain", "y": NEAR_SINGULAR_DEG, "yanchor": "bottom", "yref": "y"}]}
    return _figure(data, layout, 330)


def time_figures(table: Table) -> list[tuple[str, dict]]:
    """Every plot of a run's (decimated) table, titled: the kinematics first, then each further group of columns."""
    known = ({"t", "Fx", "Fy", "Fz"} | {p + n for p, _ in LEVELS for n in POSE_NAMES + THETA_NAMES}
             | {f"mu{i}" for i in range(1, 7)})  # the transmission angles have their figure
    out = [("Motion of the mandible (task space)", task_space_figure(table)),
           ("Motion of the actuators (joint space)", joint_space_figure(table)),
           ("Bite force F_B on the mandible at the molar, in {S}", group_figure(table, ["Fx", "Fy", "Fz"])),
           ("Transmission angles (90 deg best, 0 at a singularity)", transmission_figure(table))]
    for names in column_groups(table, known):
        title = table.descriptions.get(names[0]) or ", ".join(names)
        out.append((f"{title[0].upper()}{title[1:]} ({', '.join(names)})", group_figure(table, names)))
    return out


# --- HTML sections --------------------------------------------------------------------------------------


def html_table(header: list[str], rows: list[list[str]]) -> str:
    """An HTML table of ``header`` and ``rows`` (cells are HTML already: escape text with :func:`escape`)."""
    head = "".join(f"<th>{h}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def escape(x) -> str:
    """``x`` as text safe in HTML."""
    return html.escape(str(x))


def _run_section(record: dict, m: Model, view: RunView, files: list[str]) -> str:
    task, o = record["task"], record["options"]
    t = view.stats["t"]
    rows = [
        ["model", f"{escape(m.name)} ({escape(m.mechanism)}, {m.dof} DOF): {escape(m.description)}"],
        ["parameter file", f"<code>{escape(record['model'].get('file', m.source))}</code> "
                           f"(sha256 {escape(record['model'].get('sha256', m.sha256)[:12])}…)"
                           + (f"; its copy in this folder: <code>{escape(record['model']['copy'])}</code>" if record["model"].get("copy") else "")],
        ["task", f"{escape(task['name'])} from <code>{escape(task['source'])}</code>: {view.n} samples, "
                 f"{t.max - t.min:.3f} s, {(view.n - 1) / (t.max - t.min):.4g} Hz" if view.n > 1 else escape(task["name"])],
        ["options", f"bite side {escape(o['side'])}, orientation {escape(o['orientation'])}, {escape(dynamics_label(record, m))}, "
                    f"contact model {escape(o.get('contact', 'bilateral'))}"],
        ["timings", ", ".join(f"{escape(k)} {v:.3g} s" for k, v in record.get("timings", {}).items()) or "-"],
        ["assumed values", ", ".join(f"<code>{escape(k)}</code>" for k in m.assumed) + " (not in the papers; <code>chewbot check-model</code> lists their values)"],
    ]
    if files:
        rows.append(["files", ", ".join(f'<a href="{escape(f)}">{escape(f)}</a>' for f in files)])
    return f'<section id="run"><h2>Run</h2>{html_table(["", ""], [[r[0], r[1]] for r in rows]).replace("<td>", "<td class=text>")}</section>'


def dynamics_label(record: dict, model: Model) -> str:
    """The inverse dynamics as run, in words: the method with the goal and friction in effect."""
    o = record["options"]
    if not o.get("method"):
        return "inverse dynamics not run"
    if not o.get("friction"):  # recorded for the formulations with friction only
        fallback = (", N_L, N_R >= contact.preload_N: the unilateral fallback"
                    if o.get("contact") == "unilateral" and model.has_hkp else "")
        return f"inverse dynamics: {o['method']} (minimum-norm torques{fallback}, no friction)"
    goal = o["goal"] if model.has_hkp and o.get("goal") else "no redundancy to distribute (6RSS)"
    return f"inverse dynamics: newton-euler (goal {goal}, friction {o.get('friction') or 'on'})"


def checks_section(record: dict) -> str:
    """The validity checks of the run (chewbot.analysis.checks, as run.json has them), failed ones marked."""
    checks = record.get("checks", [])
    if not checks:
        return '<section id="checks"><h2>Validity checks</h2><p class="note">No validity checks were run.</p></section>'
    rows, failing = [], []
    for c in checks:
        fails_run = c["passed"] is False and c["severity"] == "failure"
        if fails_run:
            failing.append(c["name"])
        verdict = ("not evaluated" if c["samples"] is None else "passed" if c["passed"]
                   else f'<span class="warn">{"FAILED" if fails_run else "warning"}</span>')
        worst = "" if c["worst"] is None else f"{number(c['worst']['value'])} {escape(c['worst']['unit'])}"
        first = "" if c["first_sample"] is None else f"{c['first_sample']['t']:.3f}"
        rows.append([escape(c["name"]), verdict, escape(c["severity"]), "" if c["samples"] is None else str(c["samples"]), first, worst, escape(c["message"])])
    verdict = (f'<p class="warn">Failed: {escape(", ".join(failing))} (the run exits with code 4).</p>' if failing
               else '<p class="ok">No check that counts as a failure failed.</p>')
    return ('<section id="checks"><h2>Validity checks</h2>' + verdict
            + html_table(["check", "verdict", "counts as", "samples", "first at t [s]", "worst", "message"], rows).replace("<td>", "<td class=text>")
            + f'<p class="note">Contact model: {escape(record["options"].get("contact", "bilateral"))}. Every sample is checked; docs/cli.md '
            "lists the checks and their bounds. A failure makes the run exit with code 4 (unless --allow-violations); a warning is "
            "reported only.</p></section>")


def _robot_section(model: Model, view: RunView, side: str, figures: dict) -> str:
    figures["robot"] = robot_figure(model, view, side)
    planes = " the two sockets' planes (their x and y ranges) in blue;" if model.has_hkp else ""
    return ('<section id="robot-section"><h2>The robot along the task</h2>'
            f'<p class="note">{{S}} coordinates in mm. Base points G<sub>i</sub>, cranks G<sub>i</sub>S<sub>i</sub> (orange), couplers '
            f"S<sub>i</sub>M<sub>i</sub> (grey), the mandible (the hull of M<sub>i</sub>, condyles T<sub>L</sub>, T<sub>R</sub>, incisor I and "
            f"molars B<sub>L</sub>, B<sub>R</sub>);{planes} the bite force at B<sub>{'L' if side == 'left' else 'R'}</sub> in red "
            f"({1 / FORCE_SCALE_MM_PER_N:g} N per mm). One frame every {FRAME_STEP_S / factor('ms'):g} ms of the task (at most {MAX_FRAMES}); "
            "drag to rotate, scroll to zoom, click a legend entry to hide it.</p>"
            '<div id="robot" class="plot"></div></section>')


def number(x: float, digits: int = 4) -> str:
    """``x`` with ``digits`` significant digits, as the report prints numbers."""
    # Rounding noise (1e-12 mm) reads as 0; + 0.0 turns -0.0 into 0.0.
    return f"{round(float(x), 9) + 0.0:.{digits}g}"


def _range_rows(view: RunView, names) -> list[list[str]]:
    rows = []
    for name in names:
        s = view.stats[name]
        factor, unit = display_unit(s.unit)
        rows.append([name, number(s.min * factor), number(s.max * factor), unit])
    return rows


def _summary_section(record: dict, model: Model, view: RunView) -> str:
    stats = view.stats
    parts = ['<section id="summary"><h2>Summary</h2><div class="grid">']
    parts.append("<div><h3>Range of motion</h3>" + html_table(["", "min", "max", "unit"], _range_rows(view, POSE_NAMES + THETA_NAMES)) + "</div>")

    rows = []
    for a in "xyz":
        s, start = stats[f"incisor_{a}"], view.first[f"incisor_{a}"]
        rows.append([f"incisor {a}, from its start", number((s.min - start) / MM), number((s.max - start) / MM), "mm"])
    force = stats["bite_force"]
    incisor_block = ("<div><h3>Incisor and bite force</h3>" + html_table(["", "min", "max", "unit"], rows)
                     + f'<p class="note">Largest bite force |F<sub>B</sub>| = {force.max:.4g} N at t = {force.t_max:.3f} s.</p></div>')

    rows = [[f"chain {c}", number(np.degrees(stats[f"mu{c}"].min)), f"{stats[f'mu{c}'].t_min:.3f}"] for c in range(1, 7)]
    intervals = view.near_singular
    if intervals:
        verdict = f'<p class="warn">Near-singular (transmission angle below {NEAR_SINGULAR_DEG:g} deg):</p>' + html_table(
            ["chain", "from t [s]", "to t [s]", "samples", "smallest [deg]", "at t [s]"],
            [[str(i.chain), f"{i.t_first:.3f}", f"{i.t_last:.3f}", str(i.last - i.first + 1), number(i.min_deg), f"{i.t_min:.3f}"] for i in intervals])
    else:
        verdict = f'<p class="ok">No near-singular sample: every transmission angle stays above {NEAR_SINGULAR_DEG:g} deg.</p>'
    parts.append("<div><h3>Transmission angles</h3>" + html_table(["", "smallest [deg]", "at t [s]"], rows) + verdict + "</div>")
    parts.append(incisor_block + "</div>")

    parts.append(_dynamics_summary(record, model, view))
    return "\n".join(parts) + "</section>"


def _dynamics_summary(record: dict, model: Model, view: RunView) -> str:
    """Torques, MCI, indices and infeasible samples, each only when the run produced them."""
    info = record.get("dynamics", {})
    stats, out = view.stats, []
    taus = numbered_columns(view.plot, "tau")
    if taus:
        rows = []
        for s in (stats[name] for name in taus):
            over = abs(s.peak) > model.limits.torque
            cell = f'<span class="warn">{number(s.peak)}</span>' if over else number(s.peak)
            rows.append([s.name, cell, f"{s.t_peak:.3f}", number(s.rms)])
        out.append("<h3>Actuator torques</h3>" + html_table(["", "peak [N·m]", "at t [s]", "RMS [N·m]"], rows)
                   + f'<p class="note">Peak: the largest |τ| with its sign; values beyond the actuator limit of '
                   f"{model.limits.torque:g} N·m are marked.</p>")
    else:
        out.append('<p class="note">Inverse dynamics did not run (<code>chewbot run --method ...</code> computes the torques).</p>')
    contact = record["options"].get("contact", "bilateral")
    preload = model.contact.preload if contact == "unilateral" else 0.0
    forces = normal_force_stats(stats)
    if forces:
        rows = [[f.name, number(f.low), f"{f.t_low:.3f}", number(f.high), f"{f.t_high:.3f}", number(f.below, 3)] for f in forces]
        out.append("<h3>HKP normal forces</h3>" + html_table(["", "min [N]", "at t [s]", "max [N]", "at t [s]", f"below {preload:g} N [%]"], rows)
                   + f'<p class="note">N &gt; 0: the plane pushes the condyle, along n = (p<sub>1</sub>, 0, 1)/|n|. '
                   f"Contact model: {escape(contact_note(contact, preload, info))}.</p>")
    mcis = numbered_columns(view.plot, "MCI")
    if mcis:
        rows = [[name, number(stats[name].mean), number(stats[name].min), number(stats[name].max)] for name in mcis]
        out.append("<h3>Inertia coupling (MCI)</h3>" + html_table(["", "mean", "min", "max"], rows))
    indices = performance_indices(info)
    if indices:
        rows = [[k, escape(INDEX_NAMES[k]), "n/a" if math.isnan(v) else number(v), display_unit(INDEX_UNITS[k])[1]]
                for k, v in indices.items()]
        out.append("<h3>Performance indices</h3>" + html_table(["", "mean norm of", "value", "unit"], rows)
                   + '<p class="note">Seed 001, Sect. 5.3: the mean over the samples of the Euclidean norm of the stacked vector.</p>')
    bad = infeasible_samples(info, view.rows["t"], view.row_samples)
    if bad:
        shown = ", ".join(f"{b['sample']} (t = {b['t']:.3f} s{': ' if b['limits'] else ''}{escape(', '.join(b['limits']))})" for b in bad[:20])
        out.append(f'<h3>Infeasible samples</h3><p class="warn">{len(bad)} sample(s) without an admissible torque distribution: '
                   f"{shown}{' …' if len(bad) > 20 else ''}</p>")
    notes = solver_notes(info)
    if notes:
        out.append("<h3>Formulation</h3>" + html_table(["", ""], [[escape(k), escape(v)] for k, v in notes.items()]).replace("<td>", "<td class=text>"))
    return '<div class="grid"><div>' + "</div><div>".join(out) + "</div></div>"


def plots_section(view: RunView, figures: dict) -> str:
    how = ("every sample" if view.plot_bin == 1 else
           f"the smallest and the largest value of every {view.plot_bin} consecutive samples, so that no peak is lost")
    parts = ['<section id="plots"><h2>Plots</h2>',
             f'<p class="note">Every column of results.csv against time ({how}; the file has every sample). Hover for values with '
             "their units, drag to zoom (double-click to reset), click a legend entry to hide the series.</p>"]
    for j, (title, fig) in enumerate(time_figures(view.plot)):
        figures[f"plot{j}"] = fig
        parts.append(f'<h3>{escape(title)}</h3><div id="plot{j}" class="plot"></div>')
    return "\n".join(parts) + "</section>"
