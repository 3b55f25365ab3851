"""``chewbot chew``: the robot chews a food's portion for a number of cycles, the bolus broken in the plant; the bolus
measured after each cycle (cycles.csv, psd.csv), the motion's results folder, figures and a report.

The command's options; the work is :mod:`chewbot.simulation.chewing` (the cycle and the sequence) and
:mod:`chewbot.outputs.chewing` (the folder). Exit codes, ``--force`` and signals as every command (docs/cli.md).
"""

from __future__ import annotations

from pathlib import Path

import typer

from chewbot.commands.common import FORCE_HELP, flag
from chewbot.kinematics.options import Side
from chewbot.simulation.controllers import table as controllers

CHEW_STEPS = 10  # models and task, simulation, kinematics, checks, results.csv, run.json, figures, report, bolus figures
# The controller that closes onto the food under force control: the one whose row reads the task's force as its reference.
DEFAULT_CONTROLLER = next(r.name for r in controllers.CONTROLLERS.values() if r.force_reference)
DEFAULT_CYCLES = 25


def _controller(value: str) -> str:
    if value not in controllers.CONTROLLERS:
        raise typer.BadParameter(f"{value!r} is not a controller; choose one of {', '.join(controllers.NAMES)}")
    return value


def _shares(value: str | None) -> str | None:
    """A typer callback: comma-separated shares of the cycles in % (0-100)."""
    if value is None:
        return value
    try:
        shares = [float(v) for v in value.split(",")]
    except ValueError:
        raise typer.BadParameter(f"{value!r}: give shares of the cycles in %, separated by commas (25,50,75,100)") from None
    if not all(0 <= s <= 100 for s in shares):
        raise typer.BadParameter(f"{value!r}: every share is between 0 and 100 %")
    return value


def chew(
    food: str = typer.Option(..., "--food", help="The food to chew: a built-in food with a [comminution] table (peanut, carrot) or a TOML food file with one (docs/bolus.md)."),
    cycles: int | None = typer.Option(None, "--cycles", min=1, max=100, show_default=False, help=f"Chewing cycles (1-100). Default: {DEFAULT_CYCLES}, unless --until-x50-mm. Example: --cycles 25."),
    until_x50_mm: float | None = typer.Option(None, "--until-x50-mm", min=0.0, show_default=False, help="Chew until the bolus's X50 is at most this (mm), instead of --cycles; exit 4 if it is not reached within the cycles the ideal strokes need and a half more (docs/bolus.md). Example: --until-x50-mm 1.2."),
    task: Path | None = typer.Option(None, "--task", show_default=False, help="One chewing cycle as a task CSV (e.g. written by chewbot import-motion; the target's X, Y, alpha, beta, ending where it starts), repeated. Default: the human-like cycle (docs/bolus.md)."),
    controller: str = typer.Option(DEFAULT_CONTROLLER, "--controller", callback=_controller, help="The controller (chewbot simulate's). hybrid closes under force control until the closing force; the others follow the motion to its closest gap (the task's force is then not used). Example: --controller computed-torque."),
    side: Side = typer.Option(Side.left, "--side", help="The molar the bolus is on (left or right)."),
    opening_mm: float = typer.Option(18.0, "--opening-mm", min=5.0, max=25.0, help="The default cycle's incisal opening (mm): how far the incisor point drops from occlusion; humans 15-20 mm."),
    frequency_hz: float = typer.Option(1.3, "--frequency-hz", min=0.5, max=3.0, help="The chewing frequency (Hz, cycles per second); humans 1.2-1.4 Hz."),
    closing_force_n: float = typer.Option(100.0, "--closing-force-n", min=1.0, max=500.0, help="The closing force (N): the force reference the hybrid controller closes to (a task CSV without Fz gets it too)."),
    min_gap_mm: float = typer.Option(0.1, "--min-gap-mm", min=0.0, help="The default cycle's closest gap at the bite point (mm): where the motion closes to where nothing resists."),
    tpa_at: str | None = typer.Option(None, "--tpa-at", callback=_shares, show_default=False, help="Texture tests of the bolus after these shares of the cycles (%, comma-separated; 0: the intact food), on the particle bed's law: bolus_tpa.csv. Example: --tpa-at 25,50,75,100."),
    model: str = typer.Option("target", "--model", help="The robot's model (built-in name or TOML file): the controller's and the plant's."),
    gain: list[str] = typer.Option([], "--gain", metavar="KEY=VALUE", help="Override one gain (keys as chewbot simulate --gain; units in the key). Example: --gain hybrid.force_frequency_Hz=10. Repeatable."),
    out: Path = typer.Option(..., "--out", help="Folder to write: cycles.csv, psd.csv, results.csv, run.json, figures, chew.html and report.html."),
    force: bool = flag("--force", help=FORCE_HELP),
    allow_violations: bool = flag("--allow-violations", help="Exit 0 even where a check fails (the sequence stopped, mass not conserved, X50 rising); they are still reported."),
    quiet: bool = flag("--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Chew a food with the robot: cycles of closing onto the bolus, the bolus broken stroke by stroke in the plant.

    By default a human-like cycle (18 mm incisal opening, 1.3 Hz) under the hybrid controller: the molar closes from
    above the portion onto the bolus until the food pushes back with the closing force (or to the closest gap where
    nothing resists) and reopens. The food's bulk law resists until it breaks, the particle bed's after; each stroke's
    closest gap and peak force break the bolus (docs/bolus.md). cycles.csv holds X50, b, the peak force, the work, the
    particles and the mass after each cycle (cycle 0: the intact portion); psd.csv the mass on each sieve. Exit 4 (the
    folder written) where the sequence could not complete its cycles (the robot left its workspace) or a check of the
    bolus failed.

    Examples:

      chewbot chew --food peanut --cycles 3 --out runs/chew-peanut

      chewbot chew --food peanut --until-x50-mm 6 --out runs/chew-until

      chewbot chew --food peanut --cycles 4 --tpa-at 0,50,100 --out runs/chew-tpa
    """
    from chewbot.commands.common import (EXIT_BAD_INPUT, check_interrupted, errors_reported, exit_after_checks, fail, progress,
                                         resolved, set_overrides)
    from chewbot.errors import ChewbotError
    from chewbot.files import check_output
    from chewbot.outputs.chewing import CHEW_FOLDER
    from chewbot.simulation.options import resolve
    from chewbot.simulation.run import input_files

    gains = set_overrides(gain, "--gain")
    if cycles is not None and until_x50_mm is not None:
        with errors_reported():
            fail(ChewbotError("--cycles and --until-x50-mm exclude each other: a number of cycles, or chewing until an X50"),
                 EXIT_BAD_INPUT)
    with resolved():
        options = resolve(controller, model, "chewing cycle" if task is None else str(task), side.value, gain_overrides=gains,
                          food=food, bolus=True)
    with errors_reported():
        check_output(out, force, CHEW_FOLDER, inputs=input_files(options))
        from chewbot.food.law import load_food
        from chewbot.model.params import load_model
        from chewbot.outputs.chewing import write
        from chewbot.simulation.chewing import ChewingCycle, bolus_tpa, chew as chew_sequence, cycles_for, sequence_task

        sample = load_food(food)
        cycle = ChewingCycle(opening_mm, frequency_hz, closing_force_n, min_gap_mm)
        count = cycles_for(sample, until_x50_mm, cycle) if until_x50_mm is not None else (cycles or DEFAULT_CYCLES)
        sequence, period = sequence_task(load_model(model), sample, side.value, count, cycle, task, options.controller)
        with progress(quiet, "chew", total=CHEW_STEPS) as step:
            chewing = chew_sequence(options, sequence, period, progress=step, check=check_interrupted, target_x50_mm=until_x50_mm)
            if tpa_at is not None:
                step("texture tests of the bolus")
                chewing.tpa = bolus_tpa(chewing, [float(v) for v in tpa_at.split(",")])
            write(chewing, out, force=force, progress=step)
    if not quiet:
        _print_summary(chewing, out)
    exit_after_checks(chewing.checks, allow_violations, quiet)


def _print_summary(chewing, out: Path) -> None:
    from rich.markup import escape

    from chewbot.commands.common import stdout

    stdout.print(f"wrote [bold]{escape(str(out))}[/]; open {escape(str(out / 'chew.html'))}", highlight=False)
    stdout.print(f"{'cycle':>5}  {'X50 [mm]':>9}  {'b [1]':>6}  {'peak_force [N]':>14}  {'work [mJ]':>9}", highlight=False, markup=False)
    for r in chewing.records:
        flag = " (extrapolated)" if r.fit.extrapolated else ""
        stdout.print(f"{r.cycle:>5}  {r.fit.x50_mm:>9.4g}  {r.fit.b:>6.3g}  {r.peak_force:>14.4g}  {1e3 * r.work:>9.4g}{flag}",
                     highlight=False, markup=False)
    for t in chewing.tpa:
        stdout.print(f"bolus TPA after {t['share_percent']:g} % (cycle {t['cycle']}): hardness {t['measures']['hardness_N']:.4g} N",
                     highlight=False, markup=False)
    stopped = chewing.result.simulation.stopped
    if stopped is not None:
        stdout.print(f"the sequence stopped at t = {stopped['t']:.4g} s: the robot left its workspace ({escape(stopped['reason'])})",
                     highlight=False)
