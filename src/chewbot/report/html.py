"""``report.html``: one self-contained page per run, readable offline.

The page inlines plotly.js from the installed plotly package (no network), draws the robot in 3D animated
along the task, summarises the run (ranges, transmission angles, peak and RMS torques, MCI, the indices
F1..F7) and plots every column of the results table, interactively and with its unit. It shows what the run
contains: a stage that did not run (no torques, no Newton-Euler indices) leaves its part out.

Sizes: plotly.js is about 4.8 MB; the plots keep at most :data:`MAX_PLOT_POINTS` samples per series and the
animation one frame per :data:`FRAME_STEP_S` (at most :data:`MAX_FRAMES`), so a 5 s task at 1 kHz gives a
page of about 5.5 MB. The summary and ``results.csv`` use every sample.
"""

from __future__ import annotations

import html
import json
import math
import os
from importlib import resources
from pathlib import Path
from string import Template
import numpy as np
import plotly.graph_objects as go
import plotly.io as pio
from plotly.offline import get_plotlyjs
from plotly.subplots import make_subplots
from scipy.spatial import ConvexHull

from chewbot.analysis.checks import NEAR_SINGULAR_DEG
from chewbot.analysis.indices import INDEX_UNITS
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.report.summary import (
    INDEX_NAMES,
    column_stats,
    contact_note,
    crank_tips,
    infeasible_samples,
    near_singular,
    normal_force_stats,
    numbered_columns,
    performance_indices,
    solver_notes,
)
from chewbot.results import POSE_NAMES, RunResult, Table
from chewbot.rotation import matrix_from_euler_angles

MAX_PLOT_POINTS = 1000
FRAME_STEP_S = 0.04  # 25 frames per second of task: the animation plays in real time
MAX_FRAMES = 250
FORCE_SCALE_MM_PER_N = 0.25  # bite-force arrow: 80 N is drawn 20 mm long
MANDIBLE_POINTS = ("T_L", "T_R", "I", "B_L", "B_R")
ARCH = ("T_R", "B_R", "I", "B_L", "T_L")  # drawn as one line: the U of the lower jaw
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")
# Columns plotted in the task-space and joint-space figures (everything else is plotted by groups).
LEVELS = (("", "displacement"), ("d", "velocity"), ("dd", "acceleration"))
THETA_NAMES = tuple(f"theta{i}" for i in range(1, 7))


def write_report(result: RunResult, path: Path, files: list[str] | None = None) -> Path:
    """Write ``report.html`` for a computed run; ``files`` names the other files of the run folder."""
    figures: dict[str, go.Figure] = {}
    body = [
        _robot_section(result, figures),
        _checks_section(result),
        _summary_section(result),
        _plots_section(result, figures),
        _run_section(result, files or []),
    ]
    o = result.options
    page = render_page(
        title=f"chewbot report: {result.model.name}, {result.task.name} ({o.side} side)",
        subtitle=f"{result.model.description} · {result.table.n} samples · {o.orientation} · {dynamics_label(result)}",
        nav=RUN_NAV, body="\n".join(body), figures=figures)
    Path(path).write_text(page, encoding="utf-8")
    return Path(path)


RUN_NAV = (("robot-section", "Robot"), ("checks", "Checks"), ("summary", "Summary"), ("plots", "Plots"),
           ("run", "Run details and files"))


def render_page(title: str, subtitle: str, nav, body: str, figures: dict[str, go.Figure]) -> str:
    """A self-contained page in chewbot's report template: ``nav`` (anchor, label) pairs in the header, ``body``
    (HTML sections), ``figures`` drawn into the elements of their ids (plotly.js inlined)."""
    template = Template(resources.files("chewbot.report").joinpath("template.html").read_text("utf-8"))
    return template.substitute(
        title=html.escape(title),
        subtitle=html.escape(subtitle),
        nav="".join(f'<a href="#{html.escape(a)}">{html.escape(label)}</a>' for a, label in nav),
        plotlyjs=get_plotlyjs(),
        body=body,
        # "<" only occurs inside JSON strings, where \u003c means the same: no "</script>" can end the block
        figures="{" + ",".join(f"{json.dumps(k)}:{pio.to_json(f, validate=False)}" for k, f in figures.items()).replace("<", "\\u003c") + "}",
    )


# --- the robot in 3D ------------------------------------------------------------------------------------


def mandible_body_points(model: Model) -> tuple[tuple[str, ...], np.ndarray]:
    """Names and positions in {M} (m) of the points drawn on the mandible: M_1..M_6, T_L, T_R, I, B_L, B_R."""
    names = tuple(f"M{i}" for i in range(1, 7)) + MANDIBLE_POINTS
    pts = np.vstack([model.M, model.hkp.T_L, model.hkp.T_R, model.incisor, model.molar_left, model.molar_right])
    return names, pts


def robot_positions(model: Model, kin: Kinematics, samples: np.ndarray) -> dict[str, np.ndarray]:
    """Positions in {S} (m) at the given samples: ``S`` (n, 6, 3) crank tips from theta, ``body`` (n, 11, 3)
    the mandible points of :func:`mandible_body_points` from the pose (O_M and XYZ Euler angles)."""
    X = kin.X[samples]
    R = matrix_from_euler_angles(X[:, 3:6])
    _, body = mandible_body_points(model)
    return {
        "S": crank_tips(model, kin.theta[samples]),
        "body": X[:, None, :3] + np.einsum("nij,kj->nki", R, body),
    }


def frame_samples(t: np.ndarray) -> np.ndarray:
    """Sample indices of the animation's frames: one per FRAME_STEP_S, at most MAX_FRAMES, last included."""
    duration = float(t[-1] - t[0])
    step = max(FRAME_STEP_S, duration / (MAX_FRAMES - 1))
    wanted = t[0] + step * np.arange(int(duration / step) + 1)
    after = np.searchsorted(t, wanted).clip(1, len(t) - 1)
    # the nearest sample, so that 1.64 s is the frame "1.640" even though 41 * 0.04 is 1.6400000000000001
    idx = np.unique(np.where(wanted - t[after - 1] <= t[after] - wanted, after - 1, after))
    return idx if idx[-1] == len(t) - 1 else np.append(idx, len(t) - 1)


def _segments(a: np.ndarray, b: np.ndarray) -> list[list[float | None]]:
    """x, y, z lists (mm) of the segments a_k b_k, separated by gaps, for one scatter3d line trace."""
    out: list[list[float | None]] = [[], [], []]
    for p, q in zip(a * 1e3, b * 1e3):
        for c in range(3):
            out[c] += [round(float(p[c]), 3), round(float(q[c]), 3), None]
    return out


def _xyz(points: np.ndarray) -> dict[str, list[float]]:
    mm = np.round(points * 1e3, 3)
    return {"x": mm[:, 0].tolist(), "y": mm[:, 1].tolist(), "z": mm[:, 2].tolist()}


def _bite_point(kin: Kinematics) -> str:
    return "B_L" if kin.side == "left" else "B_R"


def _moving_traces(model: Model, kin: Kinematics, pos: dict[str, np.ndarray], f: int, k: int, hull) -> list:
    """The traces that move, at frame ``f`` (sample ``k``): cranks, couplers, mandible, its points, bite force."""
    names, _ = mandible_body_points(model)
    body = pos["body"][f]
    x, y, z = _segments(model.G, pos["S"][f])
    cranks = go.Scatter3d(x=x, y=y, z=z, mode="lines", line=dict(color="#d9822b", width=9), name="cranks G<sub>i</sub>S<sub>i</sub>", hoverinfo="skip")
    x, y, z = _segments(pos["S"][f], body[:6])
    couplers = go.Scatter3d(x=x, y=y, z=z, mode="lines+markers", line=dict(color="#4a5a6a", width=5), marker=dict(size=3, color="#4a5a6a"),
                            name="couplers S<sub>i</sub>M<sub>i</sub>", hoverinfo="skip")
    mandible = go.Mesh3d(**_xyz(body), i=hull[:, 0], j=hull[:, 1], k=hull[:, 2], color="#e8c9a0", opacity=0.3, flatshading=True,
                         name="mandible (hull of its points)", showlegend=True, hoverinfo="skip")
    arch = [names.index(n) for n in ARCH]
    points = go.Scatter3d(**_xyz(body[arch]), mode="lines+markers+text", text=list(ARCH), textposition="top center",
                          textfont=dict(size=11, color="#7a3b12"), line=dict(color="#a0522d", width=6), marker=dict(size=5, color="#7a3b12"),
                          name="condyles, molars, incisor", hovertemplate="%{text}: (%{x:.2f}, %{y:.2f}, %{z:.2f}) mm<extra></extra>")
    ends = go.Scatter3d(**_xyz(body[:6]), mode="markers+text", text=list(names[:6]), textposition="bottom center",
                        textfont=dict(size=9, color="#4a5a6a"), marker=dict(size=3, color="#4a5a6a"), name="coupler ends M<sub>i</sub>",
                        hovertemplate="%{text}: (%{x:.2f}, %{y:.2f}, %{z:.2f}) mm<extra></extra>")
    B = body[names.index(_bite_point(kin))]
    x, y, z = _segments(B[None], (B + kin.force[k] * FORCE_SCALE_MM_PER_N * 1e-3)[None])
    force = go.Scatter3d(x=x, y=y, z=z, mode="lines", line=dict(color="#c81e1e", width=8),
                         name=f"bite force F<sub>B</sub> ({1 / FORCE_SCALE_MM_PER_N:g} N per mm)",
                         hovertext=f"F_B = ({kin.force[k][0]:.1f}, {kin.force[k][1]:.1f}, {kin.force[k][2]:.1f}) N", hoverinfo="text")
    return [cranks, couplers, mandible, points, ends, force]


def _static_traces(model: Model, kin: Kinematics) -> list:
    """Base points, the sockets' planes (target only) and the paths of incisor and condyles over the task."""
    traces = [go.Scatter3d(**_xyz(model.G), mode="markers+text", text=[f"G{i}" for i in range(1, 7)], textposition="bottom center",
                           textfont=dict(size=10), marker=dict(size=6, color="#1f3a5a", symbol="square"), name="base points G<sub>i</sub>",
                           hovertemplate="%{text}: (%{x:.2f}, %{y:.2f}, %{z:.2f}) mm<extra></extra>")]
    if model.has_hkp:
        h = model.hkp
        corners = []
        for y_range in (h.y_left, h.y_right):
            for xs, ys in ((0, 0), (1, 0), (1, 1), (0, 1)):
                x, y = h.x_range[xs], y_range[ys]
                corners.append((x, y, -h.p1 * x - h.p2))  # on p1 x + z + p2 = 0
        c = np.array(corners)
        traces.append(go.Mesh3d(**_xyz(c), i=[0, 0, 4, 4], j=[1, 2, 5, 6], k=[2, 3, 6, 7], color="#5b9bd5", opacity=0.5,
                                name="sockets: planes p<sub>1</sub>x + z + p<sub>2</sub> = 0", showlegend=True, hoverinfo="name"))
    for label, keys in (("incisor path", ("I",)), ("condyle paths", ("T_L", "T_R"))):
        xyz = {"x": [], "y": [], "z": []}
        for key in keys:
            for axis, values in _xyz(kin.points[key][plot_samples(kin.n)]).items():
                xyz[axis] += values + [None]
        traces.append(go.Scatter3d(**xyz, mode="lines", line=dict(color="#9aa7b4", width=2), name=label, hoverinfo="skip"))
    return traces


def robot_figure(model: Model, kin: Kinematics) -> go.Figure:
    """The robot in 3D (mm, {S}), animated along the task with a time slider and play/pause buttons."""
    samples = frame_samples(kin.t)
    pos = robot_positions(model, kin, samples)
    _, body0 = mandible_body_points(model)
    hull = ConvexHull(body0).simplices  # the mandible is rigid: one triangulation serves every frame
    static = _static_traces(model, kin)
    moving = list(range(len(static), len(static) + 6))
    frames = [go.Frame(data=_moving_traces(model, kin, pos, f, int(k), hull), traces=moving, name=f"{kin.t[k]:.3f}")
              for f, k in enumerate(samples)]
    fig = go.Figure(data=static + list(frames[0].data), frames=frames)
    names, _ = mandible_body_points(model)
    arrows = pos["body"][:, names.index(_bite_point(kin))] * 1e3 + kin.force[samples] * FORCE_SCALE_MM_PER_N
    everything = np.vstack([model.G * 1e3, pos["S"].reshape(-1, 3) * 1e3, pos["body"].reshape(-1, 3) * 1e3, arrows.reshape(-1, 3)])
    lo, hi = everything.min(axis=0) - 8, everything.max(axis=0) + 8
    span = hi - lo
    axis = lambda name, j: dict(title=f"{name}<sub>S</sub> [mm]", range=[lo[j], hi[j]], backgroundcolor="#f7f9fb", gridcolor="#dde3ea")  # noqa: E731
    play = dict(frame=dict(duration=FRAME_STEP_S * 1000, redraw=True), fromcurrent=True, transition=dict(duration=0), mode="immediate")
    fig.update_layout(
        template="plotly_white",
        margin=dict(l=0, r=0, t=10, b=10),
        legend=dict(x=0.0, y=0.98, bgcolor="rgba(255,255,255,0.7)", font=dict(size=11)),
        scene=dict(domain=dict(y=[0.1, 1.0]), xaxis=axis("X", 0), yaxis=axis("Y", 1), zaxis=axis("Z", 2), aspectmode="manual",
                   aspectratio=dict(x=span[0] / span.max(), y=span[1] / span.max(), z=span[2] / span.max()),
                   camera=dict(eye=dict(x=1.05, y=-1.0, z=0.55), up=dict(x=0, y=0, z=1))),
        updatemenus=[dict(type="buttons", direction="left", x=0.02, y=0.02, xanchor="left", yanchor="bottom", showactive=False,
                          buttons=[dict(label="▶ play", method="animate", args=[None, play]),
                                   dict(label="❚❚ pause", method="animate", args=[[None], dict(frame=dict(duration=0, redraw=False), mode="immediate")])])],
        sliders=[dict(x=0.2, y=0.02, len=0.78, yanchor="bottom", pad=dict(t=0, b=0), currentvalue=dict(prefix="t = ", suffix=" s"),
                      steps=[dict(label=fr.name, method="animate", args=[[fr.name], dict(frame=dict(duration=0, redraw=True), mode="immediate")])
                             for fr in frames])],
    )
    return fig


# --- time plots -----------------------------------------------------------------------------------------

# Display units: lengths in mm and angles in degrees read better than m and rad at the robot's scale.
_DISPLAY = {"m": (1e3, "mm"), "rad": (180 / math.pi, "deg")}


def display_unit(unit: str) -> tuple[float, str]:
    """The factor and the label to show a column of ``unit`` (SI) with: m -> mm, rad -> deg, rates alike."""
    if unit == "1":
        return 1.0, "-"
    base, sep, rest = unit.partition("/")
    factor, shown = _DISPLAY.get(base, (1.0, base))
    label = shown + sep + rest
    return factor, label.replace("*", "·").replace("^2", "²").replace("^3", "³")


def plot_samples(n: int) -> np.ndarray:
    """Every k-th sample, k the smallest that keeps at most MAX_PLOT_POINTS (the last sample always kept)."""
    idx = np.arange(0, n, max(1, math.ceil(n / MAX_PLOT_POINTS)))
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def _add_series(fig: go.Figure, t: np.ndarray, table: Table, names, row=None, col=None, labels=None, groups=None, color0=0) -> str:
    """Add one line per column (display units, hover with the unit); returns the unit's label.

    ``groups``: legend groups, one per column: series of one group (X, dX, ddX) toggle together and show one
    legend entry, the group's name.
    """
    label = ""
    for j, name in enumerate(names):
        factor, label = display_unit(table.units[name])
        shown = (labels or names)[j]
        legend = dict(legendgroup=groups[j], name=groups[j], showlegend=row == 1) if groups else dict(name=shown)
        fig.add_trace(go.Scatter(x=t, y=(table[name][plot_samples(table.n)] * factor).astype(np.float32), mode="lines", **legend,
                                 line=dict(width=1.6, color=COLORS[(color0 + j) % len(COLORS)]),
                                 hovertemplate=f"{shown} = %{{y:.4g}} {label}<extra></extra>"), row=row, col=col)
    return label


def _figure_layout(fig: go.Figure, height: int) -> None:
    fig.update_layout(template="plotly_white", height=height, margin=dict(l=70, r=20, t=30, b=50), hovermode="x unified",
                      legend=dict(orientation="h", y=1.0, yanchor="bottom", x=0, font=dict(size=12)))
    fig.update_xaxes(showspikes=True, spikemode="across", spikethickness=1)


def task_space_figure(table: Table) -> go.Figure:
    """X, Y, Z and alpha, beta, gamma of the mandible with their rates (seed 000, Fig. 3), 3 x 2 panels."""
    t = table["t"][plot_samples(table.n)]
    fig = make_subplots(rows=3, cols=2, shared_xaxes=True, vertical_spacing=0.06, horizontal_spacing=0.08)
    for r, (prefix, level) in enumerate(LEVELS, start=1):
        for c, names in enumerate((POSE_NAMES[:3], POSE_NAMES[3:]), start=1):
            unit = _add_series(fig, t, table, [prefix + n for n in names], r, c, groups=list(names), color0=3 * (c - 1))
            fig.update_yaxes(title_text=f"{level} [{unit}]", row=r, col=c)
    fig.update_xaxes(title_text="time t [s]", row=3)
    _figure_layout(fig, 760)
    return fig


def joint_space_figure(table: Table) -> go.Figure:
    """The six actuator angles with their rates (seed 000, Fig. 4), three panels."""
    t = table["t"][plot_samples(table.n)]
    fig = make_subplots(rows=3, cols=1, shared_xaxes=True, vertical_spacing=0.05)
    for r, (prefix, level) in enumerate(LEVELS, start=1):
        unit = _add_series(fig, t, table, [prefix + n for n in THETA_NAMES], r, 1, labels=[f"{prefix}θ{i}" for i in range(1, 7)],
                           groups=[f"θ{i}" for i in range(1, 7)])
        fig.update_yaxes(title_text=f"actuator {level} [{unit}]", row=r, col=1)
    fig.update_xaxes(title_text="time t [s]", row=3)
    _figure_layout(fig, 760)
    return fig


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


def group_figure(table: Table, names: list[str]) -> go.Figure:
    """One panel with the columns ``names`` against time; the y axis is named by the names' common stem."""
    fig = go.Figure()
    unit = _add_series(fig, table["t"][plot_samples(table.n)], table, names)
    stem = os.path.commonprefix(names).rstrip("_") or names[0]
    fig.update_layout(xaxis_title="time t [s]", yaxis_title=f"{stem} [{unit}]")
    _figure_layout(fig, 330)
    return fig


def transmission_figure(kin: Kinematics) -> go.Figure:
    """Transmission angle of each chain (deg) with the near-singular threshold."""
    idx = plot_samples(kin.n)
    fig = go.Figure()
    for k in range(6):
        fig.add_trace(go.Scatter(x=kin.t[idx], y=np.degrees(np.arcsin(np.clip(kin.transmission[idx, k], 0, 1))).astype(np.float32),
                                 mode="lines", name=f"chain {k + 1}", line=dict(width=1.6, color=COLORS[k]),
                                 hovertemplate=f"chain {k + 1}: %{{y:.2f}} deg<extra></extra>"))
    fig.add_hline(y=NEAR_SINGULAR_DEG, line=dict(color="#b4461a", dash="dash"), annotation_text=f"near-singular below {NEAR_SINGULAR_DEG:g} deg")
    fig.update_layout(xaxis_title="time t [s]", yaxis_title="transmission angle [deg]", yaxis_range=[0, 90])
    _figure_layout(fig, 330)
    return fig


def time_figures(result: RunResult) -> list[tuple[str, go.Figure]]:
    """Every plot of the run, titled: the kinematics first, then each further group of columns."""
    table = result.table
    known = ({"t", "Fx", "Fy", "Fz"} | {p + n for p, _ in LEVELS for n in POSE_NAMES + THETA_NAMES}
             | {f"mu{i}" for i in range(1, 7)})  # the transmission angles have their figure
    out = [("Motion of the mandible (task space)", task_space_figure(table)),
           ("Motion of the actuators (joint space)", joint_space_figure(table)),
           ("Bite force F_B on the mandible at the molar, in {S}", group_figure(table, ["Fx", "Fy", "Fz"])),
           ("Transmission angles (90 deg best, 0 at a singularity)", transmission_figure(result.kinematics))]
    for names in column_groups(table, known):
        title = table.descriptions.get(names[0]) or ", ".join(names)
        out.append((f"{title[0].upper()}{title[1:]} ({', '.join(names)})", group_figure(table, names)))
    return out


# --- HTML sections --------------------------------------------------------------------------------------


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{h}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _e(x) -> str:
    return html.escape(str(x))


def _run_section(result: RunResult, files: list[str]) -> str:
    m, task, o = result.model, result.task, result.options
    t = result.table["t"]
    rows = [
        ["model", f"{_e(m.name)} ({_e(m.mechanism)}, {m.dof} DOF): {_e(m.description)}"],
        ["parameter file", f"<code>{_e(m.source)}</code> (sha256 {_e(m.sha256[:12])}…)"],
        ["task", f"{_e(task.name)} from <code>{_e(task.source)}</code>: {task.n} samples, "
                 f"{t[-1] - t[0]:.3f} s, {(task.n - 1) / (t[-1] - t[0]):.4g} Hz" if task.n > 1 else _e(task.name)],
        ["options", f"bite side {_e(o.side)}, orientation {_e(o.orientation)}, {_e(dynamics_label(result))}, "
                    f"contact model {_e(o.contact)}"],
        ["timings", ", ".join(f"{_e(k)} {v:.3g} s" for k, v in result.info.get("timings", {}).items()) or "-"],
        ["assumed values", ", ".join(f"<code>{_e(k)}</code>" for k in m.assumed) + " (not in the papers; <code>chewbot check-model</code> lists their values)"],
    ]
    if files:
        rows.append(["files", ", ".join(f'<a href="{_e(f)}">{_e(f)}</a>' for f in files)])
    return f'<section id="run"><h2>Run</h2>{_table(["", ""], [[r[0], r[1]] for r in rows]).replace("<td>", "<td class=text>")}</section>'


def dynamics_label(result: RunResult) -> str:
    """The inverse dynamics as run, in words: the method with the goal and friction in effect."""
    o = result.options
    if not o.method:
        return "inverse dynamics not run"
    if o.method != "newton-euler":
        fallback = (", N_L, N_R >= contact.preload_N: the unilateral fallback"
                    if o.contact == "unilateral" and result.model.has_hkp else "")
        return f"inverse dynamics: {o.method} (minimum-norm torques{fallback}, no friction)"
    goal = o.goal if result.model.has_hkp and o.goal else "no redundancy to distribute (6RSS)"
    return f"inverse dynamics: newton-euler (goal {goal}, friction {o.friction or 'on'})"


def _checks_section(result: RunResult) -> str:
    """The validity checks of the run (chewbot.analysis.checks), failed ones marked."""
    if not result.checks:
        return '<section id="checks"><h2>Validity checks</h2><p class="note">No validity checks were run.</p></section>'
    rows = []
    for c in result.checks:
        verdict = ("not evaluated" if c.samples is None else "passed" if c.passed
                   else f'<span class="warn">{"FAILED" if c.fails_run else "warning"}</span>')
        worst = "" if c.worst is None else f"{_fmt(c.worst['value'])} {_e(c.worst['unit'])}"
        first = "" if c.first_sample is None else f"{c.first_sample['t']:.3f}"
        rows.append([_e(c.name), verdict, _e(c.severity), "" if c.samples is None else str(c.samples), first, worst, _e(c.message)])
    failing = [c.name for c in result.checks if c.fails_run]
    verdict = (f'<p class="warn">Failed: {_e(", ".join(failing))} (the run exits with code 4).</p>' if failing
               else '<p class="ok">No check that counts as a failure failed.</p>')
    return ('<section id="checks"><h2>Validity checks</h2>' + verdict
            + _table(["check", "verdict", "counts as", "samples", "first at t [s]", "worst", "message"], rows).replace("<td>", "<td class=text>")
            + f'<p class="note">Contact model: {_e(result.options.contact)}. Every sample is checked; docs/cli.md lists the checks and '
            "their bounds. A failure makes the run exit with code 4 (unless --allow-violations); a warning is reported only.</p></section>")


def _robot_section(result: RunResult, figures: dict) -> str:
    figures["robot"] = robot_figure(result.model, result.kinematics)
    planes = " the two sockets' planes (their x and y ranges) in blue;" if result.model.has_hkp else ""
    return ('<section id="robot-section"><h2>The robot along the task</h2>'
            f'<p class="note">{{S}} coordinates in mm. Base points G<sub>i</sub>, cranks G<sub>i</sub>S<sub>i</sub> (orange), couplers '
            f"S<sub>i</sub>M<sub>i</sub> (grey), the mandible (the hull of M<sub>i</sub>, condyles T<sub>L</sub>, T<sub>R</sub>, incisor I and "
            f"molars B<sub>L</sub>, B<sub>R</sub>);{planes} the bite force at B<sub>{'L' if result.kinematics.side == 'left' else 'R'}</sub> in red "
            f"({1 / FORCE_SCALE_MM_PER_N:g} N per mm). One frame every {FRAME_STEP_S * 1000:g} ms of the task (at most {MAX_FRAMES}); "
            "drag to rotate, scroll to zoom, click a legend entry to hide it.</p>"
            '<div id="robot" class="plot"></div></section>')


def _fmt(x: float, digits: int = 4) -> str:
    # Rounding noise (1e-12 mm) reads as 0; + 0.0 turns -0.0 into 0.0.
    return f"{round(float(x), 9) + 0.0:.{digits}g}"


def _range_rows(table: Table, names) -> list[list[str]]:
    rows = []
    for name in names:
        factor, unit = display_unit(table.units[name])
        y = table[name] * factor
        rows.append([name, _fmt(y.min()), _fmt(y.max()), unit])
    return rows


def _summary_section(result: RunResult) -> str:
    table, kin = result.table, result.kinematics
    parts = ['<section id="summary"><h2>Summary</h2><div class="grid">']
    parts.append("<div><h3>Range of motion</h3>" + _table(["", "min", "max", "unit"], _range_rows(table, POSE_NAMES + THETA_NAMES)) + "</div>")

    incisor = (kin.points["I"] - kin.points["I"][0]) * 1e3
    force = np.linalg.norm(kin.force, axis=1)
    k = int(np.argmax(force))
    rows = [[f"incisor {a}, from its start", _fmt(incisor[:, j].min()), _fmt(incisor[:, j].max()), "mm"] for j, a in enumerate("xyz")]
    incisor_block = ("<div><h3>Incisor and bite force</h3>" + _table(["", "min", "max", "unit"], rows)
                     + f'<p class="note">Largest bite force |F<sub>B</sub>| = {force[k]:.4g} N at t = {kin.t[k]:.3f} s.</p></div>')

    angle = np.degrees(np.arcsin(np.clip(kin.transmission, 0, 1)))
    rows = [[f"chain {c + 1}", _fmt(angle[:, c].min()), f"{kin.t[int(np.argmin(angle[:, c]))]:.3f}"] for c in range(6)]
    intervals = near_singular(kin.t, kin.transmission)
    if intervals:
        verdict = f'<p class="warn">Near-singular (transmission angle below {NEAR_SINGULAR_DEG:g} deg):</p>' + _table(
            ["chain", "from t [s]", "to t [s]", "samples", "smallest [deg]", "at t [s]"],
            [[str(i.chain), f"{i.t_first:.3f}", f"{i.t_last:.3f}", str(i.last - i.first + 1), _fmt(i.min_deg), f"{i.t_min:.3f}"] for i in intervals])
    else:
        verdict = f'<p class="ok">No near-singular sample: every transmission angle stays above {NEAR_SINGULAR_DEG:g} deg.</p>'
    parts.append("<div><h3>Transmission angles</h3>" + _table(["", "smallest [deg]", "at t [s]"], rows) + verdict + "</div>")
    parts.append(incisor_block + "</div>")

    parts.append(_dynamics_summary(result))
    return "\n".join(parts) + "</section>"


def _dynamics_summary(result: RunResult) -> str:
    """Torques, MCI, indices and infeasible samples, each only when the run produced them."""
    table, model = result.table, result.model
    info = result.info.get("dynamics", {})
    out = []
    taus = numbered_columns(table, "tau")
    if taus:
        rows = []
        for s in column_stats(table, taus):
            over = abs(s.peak) > model.limits.torque
            cell = f'<span class="warn">{_fmt(s.peak)}</span>' if over else _fmt(s.peak)
            rows.append([s.name, cell, f"{s.t_peak:.3f}", _fmt(s.rms)])
        out.append("<h3>Actuator torques</h3>" + _table(["", "peak [N·m]", "at t [s]", "RMS [N·m]"], rows)
                   + f'<p class="note">Peak: the largest |τ| with its sign; values beyond the actuator limit of '
                   f"{model.limits.torque:g} N·m are marked.</p>")
    else:
        out.append('<p class="note">Inverse dynamics did not run (<code>chewbot run --method ...</code> computes the torques).</p>')
    contact = result.options.contact
    preload = model.contact.preload if contact == "unilateral" else 0.0
    forces = normal_force_stats(table, preload)
    if forces:
        rows = [[f.name, _fmt(f.low), f"{f.t_low:.3f}", _fmt(f.high), f"{f.t_high:.3f}", _fmt(f.below, 3)] for f in forces]
        out.append("<h3>HKP normal forces</h3>" + _table(["", "min [N]", "at t [s]", "max [N]", "at t [s]", f"below {preload:g} N [%]"], rows)
                   + f'<p class="note">N &gt; 0: the plane pushes the condyle, along n = (p<sub>1</sub>, 0, 1)/|n|. '
                   f"Contact model: {_e(contact_note(contact, preload, info))}.</p>")
    mcis = numbered_columns(table, "MCI")
    if mcis:
        stats = column_stats(table, mcis)
        rows = [[s.name, _fmt(s.mean), _fmt(table[s.name].min()), _fmt(table[s.name].max())] for s in stats]
        out.append("<h3>Inertia coupling (MCI)</h3>" + _table(["", "mean", "min", "max"], rows))
    indices = performance_indices(info)
    if indices:
        rows = [[k, _e(INDEX_NAMES[k]), "n/a" if math.isnan(v) else _fmt(v), display_unit(INDEX_UNITS[k])[1]] for k, v in indices.items()]
        out.append("<h3>Performance indices</h3>" + _table(["", "mean norm of", "value", "unit"], rows)
                   + '<p class="note">Seed 001, Sect. 5.3: the mean over the samples of the Euclidean norm of the stacked vector.</p>')
    bad = infeasible_samples(info, table["t"])
    if bad:
        shown = ", ".join(f"{b['sample']} (t = {b['t']:.3f} s{': ' if b['limits'] else ''}{_e(', '.join(b['limits']))})" for b in bad[:20])
        out.append(f'<h3>Infeasible samples</h3><p class="warn">{len(bad)} sample(s) without an admissible torque distribution: '
                   f"{shown}{' …' if len(bad) > 20 else ''}</p>")
    notes = solver_notes(info)
    if notes:
        out.append("<h3>Formulation</h3>" + _table(["", ""], [[_e(k), _e(v)] for k, v in notes.items()]).replace("<td>", "<td class=text>"))
    return '<div class="grid"><div>' + "</div><div>".join(out) + "</div></div>"


def _plots_section(result: RunResult, figures: dict) -> str:
    parts = ['<section id="plots"><h2>Plots</h2>',
             f'<p class="note">Every column of results.csv against time (one point every '
             f"{math.ceil(result.table.n / MAX_PLOT_POINTS)} sample(s); the file has them all). Hover for values with their units, "
             "drag to zoom (double-click to reset), click a legend entry to hide the series.</p>"]
    for j, (title, fig) in enumerate(time_figures(result)):
        figures[f"plot{j}"] = fig
        parts.append(f'<h3>{_e(title)}</h3><div id="plot{j}" class="plot"></div>')
    return "\n".join(parts) + "</section>"
