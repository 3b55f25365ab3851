"""``chewbot estimate-force``: a robot log in, the bite force and the condyles' normal forces out (FORCE.csv).

The command's options and file; the work is :func:`chewbot.identification.force.estimate_log` (the motion as
``chewbot identify`` recovers it, then :mod:`chewbot.dynamics.bite_force`). FORCE.csv is written whole through
:func:`chewbot.files.atomic_file`, beginning with chewbot's marker line; an existing file is replaced only with
``--force`` and only if chewbot wrote it.
"""

from __future__ import annotations

import shlex
from pathlib import Path

import typer

from chewbot.commands.common import FORCE_HELP, errors_reported, flag, progress, stdout
from chewbot.dynamics.options import Contact
from chewbot.kinematics.options import Side
from chewbot.run.options import Switch
from chewbot.task import WINDOW_S


def estimate_force(
    log: Path = typer.Argument(..., help="The robot log (CSV, as chewbot identify reads it): t, theta1..6 (optional dtheta1..6, ddtheta1..6), tau1..6; units in brackets (SI without)."),
    model: str = typer.Option("target", "--model", help="A built-in model or a TOML parameter file (e.g. the one chewbot identify wrote, with the friction it found)."),
    side: Side = typer.Option(Side.left, "--side", help="Molar where the food is (left or right): the point the estimated force acts at."),
    contact: Contact = typer.Option(Contact.bilateral, "--contact", help="bilateral: the normal forces N_L, N_R (N) of either sign; unilateral: N_L, N_R >= 0 N (bounded least squares)."),
    friction: Switch = typer.Option(Switch.on, "--friction", help="on|off: the model's HKP and actuator friction in the equations (off: the frictionless model)."),
    window: float = typer.Option(WINDOW_S, "--window", min=0.0, help="Length (s) of the longest Savitzky-Golay window that estimates the rates the log does not give (shorter where the motion needs it), e.g. --window 0.1 for a noisy log."),
    out: Path = typer.Option(..., "--out", help="The CSV to write: t [s], Fx, Fy, Fz, N_L, N_R [N], their standard errors sFx..sN_R [N], their 95 % intervals Fx_low95, Fx_high95 .. N_R_high95 [N], residual [N*m]."),
    force: bool = flag("--force", help=FORCE_HELP),
    quiet: bool = flag("--quiet", "-q", help="Print nothing but errors and warnings."),
) -> None:
    """Estimate the food's force on the mandible and the condyles' normal forces from a robot log's angles and torques.

    At every sample the six measured torques give five unknowns (Fx, Fy, Fz at the molar of --side, in {S}, and
    N_L, N_R) by least squares on the Newton-Euler model with its friction (Gauss-Newton on the sign pattern of the
    normal forces, docs/bite_force.md); the motion is the log's, its rates smoothed where not given. Writes
    FORCE.csv with one row per log sample, standard errors (the torque error, the smoothed rates' error and, for a
    calibrated model, its [uncertainty]), 95 % intervals and the residual; warns where the problem is
    ill-conditioned (naming the samples).

    Examples:

      chewbot estimate-force examples/robot_log.csv --model target --out force.csv

      chewbot estimate-force examples/robot_log.csv --model target --side right --contact unilateral --out force.csv
    """
    from chewbot.commands.common import console
    from chewbot.files import WRITTEN_FILE, atomic_file, check_output
    from chewbot.identification.force import estimate_log
    from chewbot.identification.log import read_log
    from chewbot.model.params import load_model

    with errors_reported():
        m = load_model(model)
        inputs = [log, Path(m.source)]
        check_output(out, force, WRITTEN_FILE, inputs)  # before the work, not after it
        with progress(quiet, "estimate-force", total=3) as step:
            step("reading the log")
            data = read_log(log)
            step("estimating", stage="fit")
            result = estimate_log(m, data, side=str(side), contact=str(contact), friction=friction == Switch.on,
                                  window_s=window)
            step("writing", stage="writing")
            args = [str(log), "--model", model, "--side", str(side), "--contact", str(contact), "--friction", str(friction),
                    "--window", f"{window:g}", "--out", str(out)]
            about = f"chewbot estimate-force {shlex.join(args)}; pooled sigma {result.sigma:.6g} N*m ({result.dof} dof)"
            with atomic_file(out, force, inputs, about={out: about}) as tmp:
                result.table().to_csv(tmp)  # plain CSV; chewbot's marker in the sidecar beside it
    for warning in result.warnings:
        console.print(f"[yellow]warning:[/] {warning}", highlight=False, markup=False)
    if not quiet:
        peak = int(abs(result.F_B[:, 2]).argmax()) if result.n else 0
        stdout.print(f"wrote {out} ({result.n} rows); largest |Fz| {abs(result.F_B[peak, 2]):.4g} N at t = {result.t[peak]:.4g} s "
                     f"(standard error {result.se[peak, 2]:.3g} N); pooled torque error sigma = {result.sigma:.3g} N*m; "
                     f"rates {result.info['rates']['first']}/{result.info['rates']['second']}; crank torques from the log's "
                     f"{result.info['reads']}", highlight=False, markup=False)
        parts = result.info.get("standard_error_rms_N", {})
        if parts:
            stdout.print("RMS standard error of Fz [N] from: " + ", ".join(f"{k} {v['Fz']:.3g}" for k, v in parts.items())
                         + (" (the model's [uncertainty])" if m.uncertainty is not None else " (the model has no [uncertainty])"),
                         highlight=False, markup=False)
        if result.info.get("events"):
            stdout.print("steps of the force (not smoothed across) at t = "
                         + ", ".join(f"{e['t_s']:.6g} s" for e in result.info["events"]), highlight=False, markup=False)
