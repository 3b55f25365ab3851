"""PNG figures of a run (matplotlib), the equivalents of the papers' figures. Every axis says its unit.

Each figure is drawn once: its margins are set from what surrounds its axes (:func:`_layout`: labels, titles,
the legends beside the axes) rather than measured by matplotlib's tight layout, which lays the whole figure out
once more before it is drawn (as long as the drawing). The figures are made without pyplot (no figure manager),
and the PNG is compressed at zlib's fastest level (files about 10 % larger, written in a fifth of the time).
"""

from __future__ import annotations

import os
import signal
import traceback
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np

from chewbot.table import Table

LEVELS = (("", "displacement"), ("d", "velocity"), ("dd", "acceleration"))
DPI = 110
PNG_COMPRESSION = 1  # zlib level: 1 fastest, 9 smallest


def subplots(nrows: int = 1, ncols: int = 1, figsize=None, **kwargs):
    """A new figure and its axes, as ``matplotlib.pyplot.subplots`` gives them (without pyplot). matplotlib is
    imported here, on first use: a process that draws nothing does not load it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig, fig.subplots(nrows, ncols, **kwargs)


# Text sizes for the margins (inches), for the default font (DejaVu Sans) at the sizes the figures use.
_CHAR_IN = {7: 0.058, 8: 0.066, 10: 0.083, 12: 0.1}


def _layout(fig) -> None:
    """Margins and gaps (in inches, converted to the figure's fractions) that leave room for the tick labels and
    the y labels on the left of each column of axes, the legends placed beside the axes on their right, the
    titles above, the x labels below."""
    width, height = fig.get_size_inches()
    axes = fig.axes
    rows, cols = axes[0].get_subplotspec().get_gridspec().get_geometry()
    legend = 0.0
    for ax in axes:
        leg = ax.get_legend()
        if leg is not None and leg.get_bbox_to_anchor().x0 > ax.bbox.x1:  # anchored beside the axes
            size = _CHAR_IN.get(round(leg.get_texts()[0].get_fontsize()), 0.066)
            legend = max(legend, 0.45 + size * max(len(t.get_text()) for t in leg.get_texts()))
    titled = any(ax.get_title() for ax in axes)
    top = 0.2 + 0.35 * bool(fig.get_suptitle()) + 0.25 * titled
    bottom = 0.55 if any(ax.get_xlabel() for ax in axes) else 0.35
    left, right = 0.95, 0.2 + legend
    wspace = left + right
    hspace = 0.15 + (0.3 if titled and rows > 1 else 0.0) + (0.3 if not axes[0].get_shared_x_axes().joined(axes[0], axes[-1]) else 0.0)
    axis_w = (width - left - right - (cols - 1) * wspace) / cols
    axis_h = (height - top - bottom - (rows - 1) * hspace) / rows
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height, top=1 - top / height,
                        wspace=wspace / axis_w, hspace=hspace / axis_h)


def _save(fig, path: Path) -> Path:
    """Lay out and save a figure (every figure has a title: its own or one of its panels')."""
    if not fig.get_suptitle() and not any(ax.get_title() for ax in fig.axes):
        raise ValueError(f"{path.name}: a figure without a title")
    _layout(fig)
    fig.savefig(path, dpi=DPI, pil_kwargs={"compress_level": PNG_COMPRESSION})
    return path


def task_space(table: Table, path: Path) -> Path:
    """Motion of the mandible: X, Y, Z and alpha, beta, gamma with rates (seed 000, Fig. 3)."""
    fig, axes = subplots(3, 2, figsize=(11, 8), sharex=True)
    t = table["t"]
    for row, (prefix, level) in enumerate(LEVELS):
        tr, rot = axes[row]
        for name in ("X", "Y", "Z"):
            tr.plot(t, table[prefix + name] * 1e3, label=prefix + name)
        for name in ("alpha", "beta", "gamma"):
            rot.plot(t, np.degrees(table[prefix + name]), label=prefix + name)
        unit = ["", "/s", "/s²"][row]
        tr.set_ylabel(f"translation {level} [mm{unit}]")
        rot.set_ylabel(f"rotation {level} [deg{unit}]")
        for ax in (tr, rot):
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
            ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time t [s]")
    fig.suptitle("Motion of the mandible (task space)")
    return _save(fig, path)


def joint_space(table: Table, path: Path) -> Path:
    """Motion of the six actuators: theta, theta_dot, theta_ddot (seed 000, Fig. 4)."""
    fig, axes = subplots(3, 1, figsize=(11, 8), sharex=True)
    t = table["t"]
    for ax, (prefix, level), unit in zip(axes, LEVELS, ("deg", "deg/s", "deg/s²")):
        for i in range(1, 7):
            ax.plot(t, np.degrees(table[f"{prefix}theta{i}"]), label=f"{prefix}θ{i}")
        ax.set_ylabel(f"actuator {level} [{unit}]")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time t [s]")
    fig.suptitle("Motion of the actuators (joint space)")
    return _save(fig, path)


def bite_force(table: Table, path: Path) -> Path:
    """Bite force on the mandible in {S} (seed 000, Fig. 5)."""
    fig, ax = subplots(figsize=(11, 3.5))
    for name in ("Fx", "Fy", "Fz"):
        ax.plot(table["t"], table[name], label=name)
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("bite force F_B [N]")
    ax.set_title("Bite force F_B on the mandible at the molar, in {S}")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)


def figure_names(columns, method: str | None) -> list[str]:
    """The PNG files of a run with these columns and method: the motion and the bite force always, the torques and
    the coupling where the run computed them, the Newton-Euler figures for that method."""
    names = ["task_space.png", "joint_space.png", "bite_force.png"]
    names += ["torques.png"] * ("tau1" in columns) + ["coupling.png"] * ("MCI1" in columns)
    if method == "newton-euler":
        from chewbot.report.newton_euler_figures import FIGURES

        names += list(FIGURES)
    return names


def figure_jobs(view, method: str | None, folder: Path, contact: str = "") -> list[tuple[str, Callable[[], Path]]]:
    """The figures of a run (:func:`figure_names`), each as (file name, a function that draws it from the
    ``series`` of the run's view, :class:`chewbot.report.view.RunView`, into ``folder``); ``contact``: the run's
    contact model, named on the torques figure."""
    from chewbot.report import dynamics_figures, newton_euler_figures

    draw = {"task_space.png": task_space, "joint_space.png": joint_space, "bite_force.png": bite_force,
            "torques.png": lambda table, path: dynamics_figures.torques(table, path, method or "", contact),
            "coupling.png": dynamics_figures.coupling_indices, **newton_euler_figures.FIGURES}
    return [(name, partial(draw[name], view.series, Path(folder) / name)) for name in figure_names(view.series.columns, method)]


def write_figures(view, method: str | None, folder: Path, contact: str = "") -> list[Path]:
    """Draw the figures of a run (:func:`figure_jobs`) into ``folder``; their paths."""
    jobs = figure_jobs(view, method, folder, contact)
    with drawn(jobs):
        pass
    return [Path(folder) / name for name, _ in jobs]


@contextmanager
def drawn(jobs: list[tuple[str, Callable[[], Path]]], progress=None):
    """Draw ``jobs`` (name, function) while the block runs: a forked process takes them one by one as soon as the
    block starts (where a second core is available); when the block ends, this process takes those still
    waiting, then waits for the other to finish its current one. The drawing process inherits the data (no
    copy) and imports matplotlib itself, so a run's figures cost it little beyond its own work.

    A failure in the drawing process is raised here (RuntimeError with its traceback); an error or a signal in
    the block stops the drawing process at once. ``progress(message)`` is told each figure drawn here.
    """
    step = progress or (lambda msg: None)
    child = _Drawer(jobs) if len(jobs) > 1 and _cores() > 1 and hasattr(os, "fork") else None
    try:
        yield
        for name, draw in (child.remaining() if child else jobs):
            step(f"drawing {name}")
            draw()
        if child:
            child.wait()
    finally:
        if child:
            child.stop()


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


class _Drawer:
    """A forked process drawing jobs. The jobs are handed out through a pipe holding one byte per job: each
    process reads the next byte (a read of one byte is atomic) and draws that job; an empty pipe means done."""

    def __init__(self, jobs):
        self.jobs = jobs
        tokens, fill = os.pipe()
        os.write(fill, bytes(range(len(jobs))))
        os.close(fill)
        self.tokens = tokens
        self.report, report = os.pipe()
        self.pid = os.fork()
        if self.pid == 0:  # the drawing process: never returns into the caller's frames
            code = 0
            try:
                signal.signal(signal.SIGINT, signal.SIG_DFL)  # Ctrl-C reaches the process group: just stop
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                os.close(self.report)
                for _, draw in self.remaining():
                    draw()
            except BaseException:
                code = 1
                os.write(report, traceback.format_exc().encode()[-20000:])
            finally:
                os._exit(code)
        os.close(report)

    def remaining(self):
        """The jobs not yet taken, each taken as it is yielded."""
        while token := os.read(self.tokens, 1):
            yield self.jobs[token[0]]

    def wait(self) -> None:
        _, status = os.waitpid(self.pid, 0)
        self.pid = None
        message = b""
        while chunk := os.read(self.report, 65536):
            message += chunk
        if status != 0:
            raise RuntimeError("drawing the figures failed in the drawing process:\n" + message.decode(errors="replace"))

    def stop(self) -> None:
        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGKILL)
                os.waitpid(self.pid, 0)
            except (ProcessLookupError, ChildProcessError):
                pass
            self.pid = None
        for fd in (self.tokens, self.report):
            try:
                os.close(fd)
            except OSError:
                pass
