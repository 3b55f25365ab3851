"""The figure of an imported recording (``chewbot import-motion``): the recorded and the reproduced incisor path
side by side, as SVG text (written with chewbot's marker, beside the task)."""

from __future__ import annotations

import io

import numpy as np

from chewbot.report.plotting import layout, subplots
from chewbot.units import factor


def incisor_paths_svg(t: np.ndarray, recorded: np.ndarray, reproduced: np.ndarray, title: str, tracker=None) -> str:
    """:func:`incisor_paths` as SVG text without its XML declaration."""
    return _svg(incisor_paths(t, recorded, reproduced, title, tracker), text_as_text=False)


def incisor_paths(t: np.ndarray, recorded: np.ndarray, reproduced: np.ndarray, title: str, tracker=None):
    """The incisor point's path, recorded (registered, scale 1) and reproduced by the robot (``recorded``,
    ``reproduced`` (N, 3) m in {S}): in the sagittal plane (x, z of {S}) and the frontal plane (y, z), and its
    distance from the first frame over time; with ``tracker`` (rotation (3, 3), origin (3,) m: p_S = rotation p_T
    + origin) a second row shows both paths side by side in the tracker's frame (its x, z and y, z planes), as the
    recording saw them. Returns the figure, laid out."""
    rows = 1 if tracker is None else 2
    fig, axes = subplots(rows, 3, figsize=(13.0, 4.0 * rows), squeeze=False)
    side, front, time = axes[0]
    rec, rep = recorded / factor("mm"), reproduced / factor("mm")
    frames = [(rec, rep, "{S}", "the robot's frame", axes[0][:2])]
    if tracker is not None:
        rotation, origin = tracker

        def seen(p):  # p_T = rotation^T (p_S - origin), mm
            return (p - origin) @ rotation / factor("mm")

        frames.append((seen(recorded), seen(reproduced), "the tracker's frame", "the tracker's frame", axes[1][:2]))
    for r, p, frame, where, pair in frames:
        for ax, (i, j), name in zip(pair, ((0, 2), (1, 2)), ("x, z", "y, z")):
            ax.plot(r[:, i], r[:, j], color="0.55", lw=2.2, label="recorded")
            ax.plot(p[:, i], p[:, j], color="C0", lw=1.0, label="reproduced")
            ax.set_xlabel(f"{'xyz'[i]} in {frame} [mm]")
            ax.set_ylabel(f"{'xyz'[j]} in {frame} [mm]")
            ax.set_title(f"incisor path in {where} ({name})", fontsize=9)
            ax.set_aspect("equal", adjustable="datalim")
    side.legend(loc="best", fontsize=8)
    if tracker is not None:
        axes[1][2].set_axis_off()
    time.plot(t, np.linalg.norm(rec - rec[0], axis=1), color="0.55", lw=2.2, label="recorded")
    time.plot(t, np.linalg.norm(rep - rep[0], axis=1), color="C0", lw=1.0, label="reproduced")
    time.set_xlabel("t [s]")
    time.set_ylabel("incisal excursion [mm]")
    time.set_title("distance from the first frame")
    fig.suptitle(title, fontsize=10)
    layout(fig)
    return fig


def errors_over_time(t: np.ndarray, incisor_mm: np.ndarray, mandible_mm: np.ndarray, rotation_deg: np.ndarray,
                     limiting_t: np.ndarray, tolerance_mm: float, title: str):
    """Two panels over time: the incisor's and the whole mandible's largest point error (mm), and the mandible's
    rotation error (deg), of the reproduced against the recorded motion (registered, scale 1); the position
    tolerance as a dashed line and the frames that limit the share as ticks. Returns the figure, laid out."""
    fig, (pos, rot) = subplots(2, 1, figsize=(9.0, 5.0), sharex=True)
    pos.plot(t, mandible_mm, color="0.55", lw=1.6, label="mandible (largest over incisor, molars, condyles)")
    pos.plot(t, incisor_mm, color="C0", lw=1.0, label="incisor")
    pos.axhline(tolerance_mm, color="C3", ls="--", lw=0.8, label="--max-residual (position)")
    pos.set_ylabel("error [mm]")
    pos.set_title("reproduced vs recorded (registered, scale 1)")
    rot.plot(t, rotation_deg, color="C1", lw=1.0, label="mandible rotation")
    rot.set_ylabel("rotation error [deg]")
    rot.set_xlabel("t [s]")
    for ax in (pos, rot):
        for tl in limiting_t:
            ax.axvline(tl, color="C3", lw=0.4, alpha=0.5)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.suptitle(title, fontsize=10)
    layout(fig)
    return fig


def _svg(fig, text_as_text: bool = True) -> str:
    """A figure as SVG text without its XML declaration; ``text_as_text``: its text kept as text (searchable,
    smaller; shown in the reader's fonts) rather than drawn as paths."""
    from matplotlib import rc_context

    out = io.StringIO()
    with rc_context({"svg.fonttype": "none" if text_as_text else "path"}):
        fig.savefig(out, format="svg")
    text = out.getvalue()
    return text[text.index("?>") + 2:].lstrip() if text.startswith("<?xml") else text


def recording_report_html(title: str, t: np.ndarray, measures, share: float | None, limiting: str,
                          limiting_t: np.ndarray, tolerance_mm: float, lines: list[str], notes: list[str], tracker=None,
                          registration: list[tuple[str, str]] = ()) -> str:
    """A small self-contained HTML page (no script, the figures inline SVG) of what the robot reproduces of an
    imported recording: a table of what was recorded and how it was registered (``registration``: (what, value)
    rows: detected, prior, found, moved from the prior), a table of the measures (the share, what limits it, the
    shares of the recorded rotation and incisal excursion with their correlations r, the largest and RMS errors),
    the recorded and reproduced incisor path side by side in {S} and in the tracker's frame (``tracker``: its
    rotation and origin), and the errors over time. ``measures``: a :class:`~chewbot.recordings.measures.Measures`;
    ``lines``: the import's summary; ``notes``: what the preparation did. Without chewbot's marker line (the caller
    writes it first)."""
    from chewbot.recordings.measures import IN_STEP_R
    from chewbot.report.html import escape, html_table, number

    m = measures

    def peak(a):
        return float(np.nanmax(a))

    def rms(a):
        return float(np.sqrt(np.nanmean(np.asarray(a) ** 2)))

    def step(r):
        return "in step" if r >= IN_STEP_R else "NOT in step"

    shown = ", ".join(f"{v:.3f}" for v in limiting_t[:12]) + (" ..." if limiting_t.size > 12 else "")
    rows = [
        ["share (largest uniform scale &le; 1 at which every frame is reached within --max-residual)",
         "not searched" if share is None else number(share), ""],
        ["limited by", escape(limiting or "nothing (share 1)"), escape(f"{limiting_t.size} frame(s) at t = {shown} s") if limiting_t.size else ""],
        ["incisal excursion reproduced", f"{number(100 * m.excursion_share)} %", f"of {number(peak(m.recorded_excursion))} mm"],
        ["in step, excursion (Pearson r over time)", number(m.r_excursion), escape(f"{step(m.r_excursion)} (r >= {IN_STEP_R:g})")],
        ["rotation reproduced", f"{number(100 * m.rotation_share)} %", f"of {number(peak(m.recorded_angle))} deg"],
        ["in step, rotation (Pearson r over time)", number(m.r_rotation), escape(f"{step(m.r_rotation)} (r >= {IN_STEP_R:g})")],
        ["incisor error, largest / RMS", f"{number(peak(m.incisor_error))} / {number(rms(m.incisor_error))} mm", "at scale 1"],
        ["mandible error (incisor, molars, condyles), largest / RMS",
         f"{number(peak(m.mandible_error))} / {number(rms(m.mandible_error))} mm", "at scale 1"],
        ["mandible rotation error, largest / RMS",
         f"{number(peak(m.mandible_rotation_error))} / {number(rms(m.mandible_rotation_error))} deg", "at scale 1"],
    ]
    paths = _svg(incisor_paths(t, m.recorded_incisor, m.reproduced_incisor, "recorded (registered, scale 1) and reproduced incisor path",
                               tracker))
    registered = html_table(["registration", "value"], [[escape(a), escape(b)] for a, b in registration]) if registration else ""
    errors = _svg(errors_over_time(t, m.incisor_error, m.mandible_error, m.mandible_rotation_error, limiting_t, tolerance_mm,
                                   "errors per frame (ticks: the frames that limit the share)"))
    items = "".join(f"<li>{escape(line)}</li>" for line in lines)
    noted = "".join(f"<li>{escape(n)}</li>" for n in notes)
    style = ("body{font-family:sans-serif;max-width:1300px;margin:1em auto;padding:0 1em}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:3px 8px;text-align:left}svg{max-width:100%;height:auto}")
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{escape(title)}</title>"
            f"<style>{style}</style></head><body>\n<h1>{escape(title)}</h1>\n"
            + (f"<h2>What was recorded and how it was registered</h2>\n{registered}\n" if registered else "")
            + f"<h2>What the robot reproduces</h2>\n{html_table(['measure', 'value', ''], rows)}\n<ul>{items}</ul>\n"
            f"<h2>Incisor path</h2>\n{paths}\n<h2>Errors over time</h2>\n{errors}\n"
            + (f"<h2>Notes</h2>\n<ul>{noted}</ul>\n" if notes else "") + "</body></html>\n")
