"""``chewbot identify``: a robot log in, the model with its friction and inertia estimated out.

The command's options and files; the work is :func:`chewbot.identification.identifier.identify`. The model file and
the table beside it (``MODEL.identification.csv``) are written together through
:func:`chewbot.files.atomic_files` (all or none), each beginning with chewbot's marker line; an existing file is
replaced only with ``--force`` and only if chewbot wrote it.
"""

from __future__ import annotations

import shlex
from pathlib import Path

import typer

from chewbot.kinematics.options import Side

from chewbot.identification import MAX_RELATIVE_SE
from chewbot.task import WINDOW_S


def identify(
    log: Path = typer.Argument(..., help="The robot log (CSV): t, theta1..6 (optional dtheta1..6, ddtheta1..6), tau1..6 (N*m) or the motors' currents i1..6 (A; read through the model's drive, whose torque constant and efficiency are then estimated), optional Fx, Fy, Fz; units in brackets, e.g. i1[mA]."),
    model: str = typer.Option("target", "--model", help="The start model: a built-in model (target, 6rss, ...) or a TOML parameter file."),
    out: Path = typer.Option(..., "--out", help="The model file to write (TOML); the table of estimates goes beside it, *.identification.csv."),
    side: Side = typer.Option(Side.left, "--side", help="Molar where the logged bite force acts."),
    window: float = typer.Option(WINDOW_S, "--window", min=0.0, help="Length (s) of the Savitzky-Golay window that estimates the rates the log does not give."),
    fix: list[str] = typer.Option([], "--fix", metavar="KEY", help="Keep this key at the model's value (mandible.inertia_g_mm2, cranks.inertia_g_mm2, friction.hkp_coulomb, friction.hkp_viscous_Ns_per_m, friction.actuator_coulomb, friction.actuator_viscous_Nms_per_rad, drive.torque_constant_mNm_per_A, drive.gear_efficiency); repeatable."),
    free: list[str] = typer.Option([], "--free", metavar="KEY", help="Estimate this key too, which the model file gives by default: mandible.mass_g (the weighed mass, in g; a log of torques identifies it as long as no drive's torque constant is estimated with it); repeatable."),
    max_relative_se: float = typer.Option(MAX_RELATIVE_SE, "--max-relative-se", min=0.0, help="A parameter whose standard error exceeds this fraction of its magnitude is not identifiable from the log and is held at the start (the largest first, then the fit is repeated)."),
    force: bool = typer.Option(False, "--force", help="Replace the output files if chewbot wrote them."),
) -> None:
    """Estimate the friction, the crank inertias and the mandible's inertia from a robot log (crank angles and measured torques or motor currents).

    Recovers the mandible's motion from the crank angles, fits the HKP and actuator friction, each crank's total
    axial inertia and the mandible's inertia, and from a log of currents on a model with a drive its torque
    constant and gearbox efficiency, that the torques identify by bounded nonlinear least squares (the HKP
    normal forces of every sample eliminated; the mandible's mass is the model file's, the weighed one, unless
    --free), prints the identified combinations with standard errors, the condition number and what the log cannot
    identify, and writes the model with the estimates in place (listed under `identified`), their covariance and the
    torque error the model leaves in its [uncertainty] section, and the table beside it.

    Examples:

      chewbot identify robot_log.csv --model target --out identified.toml && chewbot check-model identified.toml

      chewbot identify runs/excited/results.csv --model target --out calibrated.toml   (a simulated excitation: chewbot excite, then chewbot simulate --task)

      chewbot identify log.csv --model my_robot.toml --out my_robot_identified.toml --fix cranks.inertia_g_mm2 --free mandible.mass_g
    """
    from chewbot.commands.common import check_interrupted, console, errors_reported, progress, stdout
    from chewbot.identification.identifier import STEPS, identify as run_identify
    from chewbot.identification.log import read_log
    from chewbot.identification.output import model_text, table_text
    from chewbot.files import WRITTEN_FILE, atomic_files, check_output, marker_line
    from chewbot.model.params import load_model

    table = out.with_name(out.stem + ".identification.csv")
    side = side.value
    with errors_reported():
        m = load_model(model)
        inputs = [log, Path(m.source)]
        for target in (out, table):  # before the work, not after it
            check_output(target, force, WRITTEN_FILE, inputs)
        data = read_log(log)
        with progress(False, "identify", total=STEPS) as step:
            result = run_identify(m, data, side=side, window_s=window, fix=tuple(fix), max_relative_se=max_relative_se,
                                  progress=step, check=check_interrupted, free=tuple(free))
        args = [str(log), "--model", model, "--out", str(out), "--side", side, "--window", f"{window:g}",
                *[a for key in fix for a in ("--fix", key)], *[a for key in free for a in ("--free", key)],
                "--max-relative-se", f"{max_relative_se:g}"]
        about = f"chewbot identify {shlex.join(args)}"
        summary = result.summary()
        comments = {key: f"identified: {_with_se(result, key)}" for key in result.identified}
        header = [marker_line("#", f"the model {m.source} with the values estimated by {about}"),
                  *[f"# {line}" for line in summary]]
        text = model_text(Path(m.source).read_text("utf-8"), result.values(), result.identified, header, comments,
                          result.uncertainty())
        with atomic_files([out, table], force, inputs, about={table: {"about": f"estimates of {about}", "summary": summary}}) as (tmp_model, tmp_table):
            tmp_model.write_text(text, encoding="utf-8")
            tmp_table.write_text(table_text(result.rows()), encoding="utf-8")
    _print_table(stdout, result)
    for line in summary:
        stdout.print(line, highlight=False, markup=False)
    if not result.identified:
        console.print("[yellow]warning:[/] the log identifies none of the parameters: the model is written unchanged",
                      highlight=False)
    stdout.print(f"wrote {out} and {table}; check it with: chewbot check-model {shlex.quote(str(out))}",
                 highlight=False, markup=False)


def _with_se(result, key: str) -> str:
    """``0.1502 +/- 0.0021`` for a scalar key, ``see the table`` for the inertia."""
    rows = [r for r in result.rows() if r["key"] == key]
    if len(rows) != 1:
        return "see the .identification.csv table beside this file"
    return f"{rows[0]['estimate']:g} +/- {rows[0]['standard_error']:g} (standard error)"


def _print_table(stdout, result) -> None:
    from rich import box
    from rich.markup import escape
    from rich.table import Table as RichTable

    table = RichTable(title="identified parameters (file units)", title_justify="left", box=box.SIMPLE_HEAD)
    for col, justify in (("parameter", "left"), ("estimate", "right"), ("standard error", "right"), ("start", "right"),
                         ("unit", "left"), ("status", "left")):
        table.add_column(col, justify=justify)
    for row in result.rows():
        se = f"{row['standard_error']:.3g}" if row["standard_error"] != "" else "-"
        table.add_row(escape(row["parameter"]), f"{row['estimate']:.6g}", se,
                      f"{row['start']:.6g}", escape(row["unit"]), escape(row["status"]))
    stdout.print(table)
