"""``chewbot tpa``: the robot as a texture analyser. A two-bite compression of a food simulated with the food in the
plant, or a robot's logged test; Bourne's measures out (tpa.json), with the figures and a report.

The command's options; the work is :mod:`chewbot.simulation.texture` (the test) and :mod:`chewbot.outputs.tpa` (the
folder). Exit codes, ``--force`` and signals as every command (docs/cli.md).
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from chewbot.commands.common import (EXIT_BAD_INPUT, FORCE_HELP, check_interrupted, errors_reported, fail, flag, progress,
                                     set_overrides, stdout)
from chewbot.kinematics.options import Side

TPA_STEPS = 8


def tpa(
    food: str | None = typer.Option(None, "--food", show_default=False, help="The sample: a built-in food (peanut, cheddar, gummy, bread, artisynth-bolus) or a TOML food file (docs/food.md). Required without --log; with --log it only gives h0 for the force-displacement figure."),
    compression: float = typer.Option(50.0, "--compression", help="How far each bite compresses the sample: a fraction of its height h0, in % (50: to h0/2)."),
    speed: float = typer.Option(2.0, "--speed", help="Speed of the molar point along z during the strokes (mm/s)."),
    pause: float = typer.Option(2.0, "--pause", help="Pause between the two bites (s), at the start gap h0 + 1 mm."),
    side: Side = typer.Option(Side.left, "--side", help="The molar the sample sits on (left or right)."),
    model: str = typer.Option("target", "--model", help="The robot's model (built-in name or TOML file): the controller's and the plant's, and the estimator's."),
    gain: list[str] = typer.Option([], "--gain", metavar="KEY=VALUE", help="Override one gain of the position control (computed torque; default here computed_torque.frequency_Hz=100, a stiff texture analyser; keys as chewbot simulate --gain); repeatable."),
    log: Path | None = typer.Option(None, "--log", show_default=False, help="A robot's logged two-bite test (chewbot identify's log: t, theta1..6, tau1..6; units in brackets): the measures from its angles and torques through the bite-force estimator, no simulation."),
    out: Path = typer.Option(..., "--out", help="Folder to write: tpa.json, task.csv and results.csv (simulated), force_time.png, force_displacement.png, tpa.html."),
    force: bool = flag("--force", help=FORCE_HELP),
    quiet: bool = flag("--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Run texture profile analysis with the robot: two bites of a food sample, Bourne's measures.

    The molar point of --side moves along z at --speed from a gap of h0 + 1 mm to --compression % of h0 and back,
    pauses, and bites again, alpha pinned at 0; the robot follows it under computed-torque position control with the
    food in the plant (its force unknown to the controller). tpa.json holds hardness_N, fracturability_N (null if
    nothing broke), cohesiveness, springiness, resilience, adhesiveness_mJ, gumminess_N and chewiness_N twice:
    "plant" (the food's force in the simulation) and "estimated" (from the crank angles and torques through the
    bite-force estimator, as on the real robot). The largest sample height is 15.08 mm at either side of the
    default model (the bite point opens 16.08 mm along z with alpha = 0); a taller sample is an error.

    Examples:

      chewbot tpa --food cheddar --out runs/tpa-cheddar

      chewbot tpa --food peanut --compression 60 --speed 1 --out runs/tpa-peanut

      chewbot tpa --log runs/tpa-cheddar/results.csv --food cheddar --out runs/tpa-logged   (a logged test: here the simulated one)
    """
    from chewbot.errors import ChewbotError
    from chewbot.files import check_output
    from chewbot.outputs.tpa import TPA_FOLDER

    gains = set_overrides(gain)
    with errors_reported():
        inputs = [Path(p) for p in (food, model, log) if p is not None and Path(p).suffix.lower() in (".toml", ".csv")]
        check_output(out, force, TPA_FOLDER, inputs=inputs)
        if log is not None:
            if gains:
                fail(ChewbotError("--gain: a logged test is not simulated; the gains do not apply to --log"), EXIT_BAD_INPUT)
            record = _from_log(log, food, model, side.value, out, force, inputs)
        else:
            if food is None:
                fail(ChewbotError("--food: required (the sample to test), unless --log gives a robot's logged test"), EXIT_BAD_INPUT)
            from chewbot.outputs.tpa import write_tpa
            from chewbot.simulation.texture import TpaOptions, run_tpa

            options = TpaOptions(food=food, compression=compression, speed=speed, pause=pause, side=side.value, model=model,
                                 gain_overrides=gains)
            with progress(quiet, "tpa", total=TPA_STEPS) as step:
                result = run_tpa(options, progress=step, check=check_interrupted)
                write_tpa(result, out, force=force, progress=step)
            record = result.record()
    if not quiet:
        _print(record, out)


def _from_log(log: Path, food: str | None, model: str, side: str, out: Path, force: bool, inputs) -> dict:
    from chewbot.food.law import load_food
    from chewbot.outputs.tpa import write_tpa_log
    from chewbot.simulation.texture import tpa_from_log

    sample = load_food(food) if food is not None else None
    measures, curve, estimator = tpa_from_log(log, model, side)
    record = {"chewbot_tpa": 1, "options": {"log": str(log), "model": model, "side": side, "food": food},
              "food": None if sample is None else sample.as_dict(), "plant": None, "estimated": measures,
              "estimator": estimator, "definitions": "docs/food.md#texture-profile-analysis"}
    write_tpa_log(record, curve, None if sample is None else sample.height, "logged" if sample is None else sample.name,
                  out, force, inputs)
    return record


def _print(record: dict, out: Path) -> None:
    from chewbot.food.tpa import MEASURES

    stdout.print(f"wrote [bold]{escape(str(out))}[/]; open {escape(str(out / 'tpa.html'))}", highlight=False)
    columns = [k for k in ("plant", "estimated") if record.get(k) is not None]
    stdout.print("measure".ljust(18) + "".join(c.rjust(12) for c in columns), highlight=False, markup=False)
    for m in MEASURES:
        cells = ["null" if record[c][m] is None else f"{record[c][m]:.4g}" for c in columns]
        stdout.print(m.ljust(18) + "".join(c.rjust(12) for c in cells), highlight=False, markup=False)
