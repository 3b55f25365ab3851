"""``chewbot track-incisor``: the motion that makes the incisor follow a path, as a task."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from chewbot.commands.common import FORCE_HELP, errors_reported, flag, progress, stdout
from chewbot.kinematics.options import Orientation, Side


def track_incisor(
    path: Path = typer.Argument(..., help="CSV of the incisor path: t, Ix, Iy, Iz (point I in {S}), optional rates dIx..ddIz and bite force Fx, Fy, Fz; units in brackets."),
    out: Path = typer.Option(..., "--out", help="Task CSV to write (read it back with chewbot run --task); the residuals go beside it, *.residuals.csv."),
    model: str = typer.Option("target", "--model", help="The target robot's model (built-in name or TOML file)."),
    pin: str = typer.Option("alpha", "--pin", help="The coordinate that resolves the redundancy (the incisor gives 3 equations for 4 DOF): X, Y, alpha or beta. It follows its column in the path file if there is one (e.g. alpha[deg]), else it is held at zero."),
    orientation: Orientation = typer.Option(Orientation.euler_angles, "--orientation", help="Parametrisation the optimisation works in."),
    side: Side = typer.Option(Side.left, "--side", help="Molar where the file's bite force acts."),
    force: bool = flag("--force", help=FORCE_HELP),
) -> None:
    """Find the mandible's motion that makes the incisor follow a path (seed 001, Sect. 5.1).

    Solves, sample after sample, the displacement, velocity and acceleration problems by SQP under the HKP
    constraints and the sockets' bounds; writes the task and the residuals f_D, f_V, f_A, and prints their maxima.

    Example:

      chewbot track-incisor incisor.csv --out task.csv --pin alpha && chewbot run --task task.csv --out runs/tracked
    """
    from chewbot.files import WRITTEN_FILE, atomic_files, check_output
    from chewbot.model.params import load_model
    from chewbot.task.csvio import read_incisor_csv
    from chewbot.task.incisor import track_incisor as track

    residuals = out.with_name(out.stem + ".residuals.csv")
    with errors_reported():
        m = load_model(model)
        inputs = [path, Path(m.source)]
        for target in (out, residuals):  # before the work, not after it
            check_output(target, force, WRITTEN_FILE, inputs)
        path_data = read_incisor_csv(path)
        with progress(False, "incisor tracking") as step:
            step("solving")
            result = track(m, path_data["t"], path_data["p"], path_data["v"], path_data["a"], orientation=orientation.value,
                           pin=pin, pinned=path_data["pinned"].get(pin), force=path_data["force"], side=side.value, name=out.stem)
        about = {out: f"a task, read it with chewbot run --task; from {path.name}",
                 residuals: f"residuals of chewbot track-incisor; from {path.name}"}
        with atomic_files((out, residuals), force, inputs, about=about) as temporaries:
            for table, tmp in zip(result.tables(), temporaries):
                table.to_csv(tmp)
    stdout.print(f"wrote {escape(str(out))} and {escape(str(residuals))}; max |f_D| = {abs(result.f_D).max():.3g} m, "
                 f"max |f_V| = {abs(result.f_V).max():.3g} m/s, max |f_A| = {abs(result.f_A).max():.3g} m/s^2")
