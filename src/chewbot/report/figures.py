"""PNG figures of a run (matplotlib), the equivalents of the papers' figures, and how a run's figures are drawn
(:func:`figure_jobs`, :func:`drawn`). Every axis says its unit; the shared machinery is :mod:`chewbot.report.plotting`.
"""

from __future__ import annotations

import io
import os
import pickle
import struct
import sys
import tempfile
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np

from chewbot.files import forked, kill, reap
from chewbot.progress import SILENT, Progress
from chewbot.report.plotting import save, subplots
from chewbot.table import Table
from chewbot.units import factor

LEVELS = (("", "displacement"), ("d", "velocity"), ("dd", "acceleration"))


def task_space(table: Table, path: Path) -> Path:
    """Motion of the mandible: X, Y, Z and alpha, beta, gamma with rates (seed 000, Fig. 3)."""
    fig, axes = subplots(3, 2, figsize=(11, 8), sharex=True)
    t = table["t"]
    for row, (prefix, level) in enumerate(LEVELS):
        tr, rot = axes[row]
        for name in ("X", "Y", "Z"):
            tr.plot(t, table[prefix + name] / factor("mm"), label=prefix + name)
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
    return save(fig, path)


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
    return save(fig, path)


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
    return save(fig, path)


def figure_names(columns, method: str | None) -> list[str]:
    """The PNG files of a run with these columns: the motion and the bite force always, the torques and the coupling
    where the run computed them, the Newton-Euler figures where it has their forces and friction (``method`` is
    not needed: what was computed says it)."""
    names = ["task_space.png", "joint_space.png", "bite_force.png"]
    names += ["torques.png"] * ("tau1" in columns) + ["coupling.png"] * ("MCI1" in columns)
    if all(c in columns for c in ("tau_f1", "FS1_x", "MG1_x")):
        from chewbot.report.newton_euler_figures import FIGURES

        names += list(FIGURES)
    return names


def figure_jobs(series: Table, method: str | None, folder: Path, contact: str = "") -> list[tuple[str, Callable[[], Path]]]:
    """The figures of a run (:func:`figure_names`), each as (file name, a function that draws it from ``series``,
    the decimated series of the run's view, :class:`chewbot.report.view.RunView`, into ``folder``); ``contact``: the
    run's contact model, named on the torques figure."""
    from chewbot.report import dynamics_figures, newton_euler_figures

    draw = {"task_space.png": task_space, "joint_space.png": joint_space, "bite_force.png": bite_force,
            "torques.png": lambda table, path: dynamics_figures.torques(table, path, method or "", contact),
            "coupling.png": dynamics_figures.coupling_indices, **newton_euler_figures.FIGURES}
    return [(name, partial(draw[name], series, Path(folder) / name)) for name in figure_names(series.columns, method)]


@contextmanager
def drawing_process(enabled: bool = True):
    """A :class:`Drawer` forked now, where a second core can draw (None otherwise): created before the data is
    written, it loads matplotlib meanwhile. Stopped on the way out (at once, on an error or a signal)."""
    drawer = Drawer() if enabled and _cores() > 1 and hasattr(os, "fork") else None
    try:
        yield drawer
    finally:
        if drawer:
            drawer.stop()


# The quickest figures (one panel of three or six lines, about 0.1 s each), handed out last, so that two processes
# drawing a run's figures end at nearly the same time.
QUICK_FIGURES = ("bite_force.png", "coupling.png")
# Other figures still waiting when this process is done from which it loads matplotlib to draw some of them too:
# loading it costs about 0.6 to 0.8 s of CPU, such a figure 0.3 to 0.6 s (the one being drawn and the quick ones add
# to what is left), so with two or more left two processes finish first (measured on two free cores: a Hessian run's
# five figures about 0.2 s sooner, a Newton-Euler run's nine about 0.8 s).
HELP_FROM = 2


@contextmanager
def drawn(series: Table, method: str | None, folder: Path, contact: str = "", progress: Progress = SILENT, drawer: Drawer | None = None):
    """Draw the figures of a run (:func:`figure_jobs`) while the block runs; their paths are yielded. A drawing
    process (``drawer``, or one forked here) takes them one by one as soon as the block starts; when the block ends,
    this process takes those still waiting if it has matplotlib loaded already or :data:`HELP_FROM` or more of them
    are not quick ones (:data:`QUICK_FIGURES`), then waits for the other to finish.

    A failure in the drawing process is raised here (RuntimeError with its traceback); an error or a signal in
    the block stops the drawing process at once. ``progress(message)`` is told each figure drawn here.
    """
    jobs = figure_jobs(series, method, folder, contact)
    with drawing_process(drawer is None and len(jobs) > 1) as forked:
        child = drawer or forked
        order = sorted(range(len(jobs)), key=lambda k: jobs[k][0] in QUICK_FIGURES)
        if child:
            child.start(series, method, folder, contact, order)
        yield [path for path in (Path(folder) / name for name, _ in jobs)]
        left = order[len(order) - child.waiting():] if child else []
        if child is None or "matplotlib.figure" in sys.modules or sum(jobs[k][0] not in QUICK_FIGURES for k in left) >= HELP_FROM:
            if child is not None and "matplotlib.figure" not in sys.modules:
                _warm_up()  # before a figure is taken from the other process, which meanwhile draws
            for name, draw in (child.remaining(jobs) if child else jobs):
                progress(f"drawing {name}")
                draw()
        if child:
            child.wait()


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _warm_up() -> None:
    """Load what drawing a figure loads (matplotlib, its fonts, the Agg renderer, the PNG writer)."""
    from chewbot.report import dynamics_figures, newton_euler_figures  # noqa: F401  (imported to be loaded)

    fig, ax = subplots(figsize=(2, 1))
    ax.plot([0, 1], [0, 1], label="x")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title("warm-up")
    fig.savefig(io.BytesIO(), format="png", pil_kwargs={"compress_level": 1})


class Drawer:
    """A process forked to draw a run's figures before they can be drawn: meanwhile it loads matplotlib
    (:func:`_warm_up`). :meth:`start` hands it the figures (the series to draw from, through a file both processes
    hold, and one byte per figure in a pipe); each process reads the next byte (a read of one byte is atomic) and
    draws that figure; an empty pipe means done. Closing the start pipe without starting ends it."""

    def __init__(self):
        self.data = tempfile.TemporaryFile()
        self.tokens, self.fill = os.pipe()
        self.go_read, self.go = os.pipe()
        self.pid, self.report = forked(self._draw, close=(self.fill, self.go))
        os.close(self.go_read)

    def _draw(self) -> None:
        """The drawing process: matplotlib loaded, then the figures drawn as they are taken, once started."""
        _warm_up()
        if os.read(self.go_read, 1):
            self.data.seek(0)
            jobs = figure_jobs(*pickle.load(self.data))
            for _, draw in self.remaining(jobs):
                draw()

    def start(self, series: Table, method: str | None, folder: Path, contact: str, order: list[int]) -> None:
        """Hand the figures of :func:`figure_jobs` with these arguments to both processes, in ``order`` (their
        indices)."""
        pickle.dump((series, method, Path(folder), contact), self.data, protocol=pickle.HIGHEST_PROTOCOL)
        self.data.flush()
        os.write(self.fill, bytes(order))
        os.close(self.fill)
        self.fill = None
        os.write(self.go, b"1")

    def waiting(self) -> int:
        """How many jobs are not yet taken (the bytes left in the pipe)."""
        import fcntl  # POSIX, as the fork the drawing process is
        import termios

        return struct.unpack("i", fcntl.ioctl(self.tokens, termios.FIONREAD, b"\0\0\0\0"))[0]

    def remaining(self, jobs):
        """The jobs not yet taken, each taken as it is yielded."""
        while token := os.read(self.tokens, 1):
            yield jobs[token[0]]

    def wait(self) -> None:
        os.close(self.go)
        self.go = None
        pid, report, self.pid, self.report = self.pid, self.report, None, None
        reap(pid, report, "drawing the figures failed in the drawing process")

    def stop(self) -> None:
        if self.pid is not None:
            kill(self.pid)
            self.pid = None
        for fd in (self.tokens, self.fill, self.go, self.report):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.data.close()
