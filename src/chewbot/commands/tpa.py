"""``chewbot tpa``: the robot as a texture analyser. A two-bite compression of a food held by the robot with the food
in the plant, or a robot's logged test; Bourne's measures out (tpa.json), with the checks, the figures and a report.

The command's options, resolved once by :func:`chewbot.simulation.texture.resolve_tpa`; the work is
:mod:`chewbot.simulation.texture` (the test) and :mod:`chewbot.outputs.tpa` (the folder). Exit codes, ``--force`` and
signals as every command (docs/cli.md): 4 where a check of the test failed, unless ``--allow-violations``.
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from chewbot.commands.common import (EXIT_BAD_INPUT, FORCE_HELP, check_interrupted, errors_reported, exit_after_checks, fail,
                                     flag, progress, resolved, set_overrides, stdout)
from chewbot.kinematics.options import Side
from chewbot.run.options import Switch

TPA_STEPS = 12


def _foods() -> str:
    """The built-in foods, read from the food layer."""
    from chewbot.food.law import builtin_foods

    return ", ".join(builtin_foods())


def tpa(
    food: str | None = typer.Option(None, "--food", show_default=False, help=f"The sample: a built-in food ({_foods()}) or a TOML food file (docs/food.md). Required without --log; with --log it only gives h0 for the force-displacement figure."),
    compression: float | None = typer.Option(None, "--compression", show_default=False, help="How far each bite compresses the sample: the fraction of its height at the trigger, in % (default 50: to half of it; 1-99, e.g. 50, not 0.5). Exclusive with --distance."),
    distance: float | None = typer.Option(None, "--distance", show_default=False, help="How far each bite compresses the sample from the trigger, in mm (e.g. 5), instead of --compression."),
    speed: float = typer.Option(2.0, "--speed", help="Test speed: the molar point's speed along z while it compresses (mm/s, e.g. 2)."),
    pre_test_speed: float = typer.Option(1.0, "--pre-test-speed", help="Speed of the approach until the trigger (mm/s, e.g. 1)."),
    post_test_speed: float | None = typer.Option(None, "--post-test-speed", show_default=False, help="Speed of the withdrawals (mm/s, e.g. 2; default: the test speed)."),
    trigger_force: float = typer.Option(0.049, "--trigger-force", help="The force that finds the sample (N; 0.049 N = 5 g, a texture analyser's default): read on the plant's food force, the analyser's load cell; with --log on the estimate, raised to 5 times the estimate's noise where that is larger (tpa.json: estimator.contact_force_N)."),
    pause: float = typer.Option(5.0, "--pause", help="Pause between the two bites at the height of the trigger (s, e.g. 5)."),
    slide: float | None = typer.Option(None, "--slide", show_default=False, help="Bound on the bite point's horizontal slide on the upper tooth from the sample's top (mm, default 1, e.g. 0.5): the path keeps the lower tooth's face parallel to the upper one as long as the slide stays within it, and tilts it no more than the gap needs beyond (tpa.json: face)."),
    side: Side = typer.Option(Side.left, "--side", help="The molar the sample sits on (left or right)."),
    model: str = typer.Option("target", "--model", help="The robot's model (built-in name or TOML file): the controller's and the estimator's, and the plant's unless --plant."),
    plant: str | None = typer.Option(None, "--plant", show_default=False, help="The simulated robot's model, if not --model (built-in name or TOML file, e.g. target or robot.toml)."),
    plant_set: list[str] = typer.Option([], "--plant-set", metavar="KEY=VALUE", help="Override one number of the plant's model only (as chewbot simulate --plant-set, e.g. mandible.mass_g=408): the model error the controller and the estimator do not know; repeatable."),
    friction: Switch = typer.Option(Switch.on, "--friction", help="on|off: the robot's HKP and actuator friction (the model's coefficients), in the plant, in the controller's Newton-Euler model and in the estimator (as chewbot estimate-force --friction)."),
    gain: list[str] = typer.Option([], "--gain", metavar="KEY=VALUE", help="Override one gain of the test's position loop, the crosshead controller (keys crosshead.frequency_Hz (Hz, default 100), crosshead.damping (1), crosshead.integral_Hz (Hz, 20)), or of its force observer (observer.cutoff_Hz (Hz, 200): the low-pass of the force fed forward); e.g. crosshead.integral_Hz=10; repeatable."),
    log: Path | None = typer.Option(None, "--log", show_default=False, help="A robot's logged two-bite test (chewbot identify's log: t, theta1..6, tau1..6; units in brackets): the measures from its angles and torques through the bite-force estimator, no simulation."),
    out: Path = typer.Option(..., "--out", help="Folder to write: tpa.json, task.csv and results.csv (simulated), force_time.png, force_displacement.png, tpa.html."),
    force: bool = flag("--force", help=FORCE_HELP),
    allow_violations: bool = flag("--allow-violations", help="Exit 0 even when a check of the test fails (the checks are still written and printed)."),
    quiet: bool = flag("--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Run texture profile analysis with the robot: two bites of a food sample, Bourne's measures.

    As a texture analyser: the molar point of --side approaches the sample from 1 mm above its highest point at --pre-test-speed until
    the food's force reaches --trigger-force (the sample's height h_t is the gap there), compresses it by
    --compression % of h_t (or --distance mm) at --speed, withdraws at --post-test-speed to h_t, pauses --pause s, and
    bites again, its face kept as parallel to the upper tooth as a horizontal slide within --slide mm allows. The robot,
    with its friction (--friction), holds the path under the crosshead controller (computed torque with integral
    action, the force observer's estimate of the sample's force fed forward, its redundant torques keeping both
    condyles pressed on their planes). tpa.json holds
    Bourne's measures twice, "plant" (the food's force in the simulation) and "estimated" (from the crank angles and
    torques through the bite-force estimator, as on the real robot), their definitions, the protocol as run and the
    checks: compression reached and speed held within 1 %, teeth met, a condyle lifted, the energy readings in [0, 1].
    Exit 4 where one fails, unless --allow-violations.

    Examples:

      chewbot tpa --food cheddar --out runs/tpa-cheddar

      chewbot tpa --food peanut --compression 60 --speed 1 --out runs/tpa-peanut

      chewbot tpa --food carrot --distance 3 --speed 1 --pause 2 --out runs/tpa-carrot

      chewbot tpa --log runs/tpa-cheddar/results.csv --food cheddar --out runs/tpa-logged   (a logged test: here the simulated one)
    """
    from chewbot.files import check_output
    from chewbot.food.tpa import TpaError
    from chewbot.outputs.tpa import TPA_FOLDER
    from chewbot.simulation.texture import resolve_tpa

    gains, plant_overrides = set_overrides(gain, "--gain"), set_overrides(plant_set, "--plant-set")
    with resolved():
        try:
            options = resolve_tpa(food, compression=compression,
                                  distance=distance, speed=speed, pre_test_speed=pre_test_speed, post_test_speed=post_test_speed,
                                  trigger_force=trigger_force, pause=pause, side=side.value, model=model, plant_file=plant,
                                  plant_overrides=plant_overrides, friction=friction.value, gain_overrides=gains,
                                  log=None if log is None else str(log), slide=slide)
        except TpaError as exc:
            fail(exc, EXIT_BAD_INPUT)
    with errors_reported():
        inputs = [Path(p) for p in (food, model, plant, log) if p is not None and Path(p).suffix.lower() in (".toml", ".csv")]
        check_output(out, force, TPA_FOLDER, inputs=inputs)
        if log is not None:
            record = _from_log(options, out, force, inputs)
        else:
            from chewbot.outputs.tpa import tpa_folder
            from chewbot.simulation.run import input_files
            from chewbot.simulation.texture import run_tpa

            with progress(quiet, "tpa", total=TPA_STEPS) as step:
                # the simulation's files are written by a second process while this one estimates the force
                with tpa_folder(out, force, input_files(options.simulation), step) as folder:
                    result = run_tpa(options, progress=step, check=check_interrupted, simulated=folder.simulated)
                    folder.finish(result)
            record = result.record()
    if not quiet:
        _print(record, out)
    from chewbot.analysis.checks import CheckResult

    exit_after_checks([CheckResult(**c) for c in record["checks"]], allow_violations, quiet)


def _from_log(options, out: Path, force: bool, inputs) -> dict:
    from chewbot.food.law import load_food
    from chewbot.outputs.tpa import write_tpa_log
    from chewbot.simulation.texture import tpa_from_log

    sample = load_food(options.food) if options.food is not None else None
    analysis, curve, estimator = tpa_from_log(options)
    record = {"chewbot_tpa": 2, "options": options.record(), "protocol": options.protocol.record(),
              "food": None if sample is None else sample.as_dict(), "plant": None, "estimated": analysis.measures,
              "estimated_ci95": analysis.intervals,
              "definitions": analysis.definitions, "anchors": {"estimated": analysis.anchors}, "estimator": estimator,
              "checks": [c.as_dict() for c in analysis.checks]}
    write_tpa_log(record, curve, None if sample is None else sample.height, "logged" if sample is None else sample.name,
                  out, force, inputs)
    return record


def _print(record: dict, out: Path) -> None:
    from chewbot.food.tpa import MEASURES

    stdout.print(f"wrote [bold]{escape(str(out))}[/]; open {escape(str(out / 'tpa.html'))}", highlight=False)
    p = record["protocol"]
    if "height_at_trigger_mm" in p:
        how = (f"{p['compression_percent']:g} %" if "compression_percent" in p else f"{p['distance_mm']:g} mm")
        stdout.print(f"trigger {p['trigger_force_N']:g} N at t = {p['trigger_time_s']:.4g} s, height there "
                     f"{p['height_at_trigger_mm']:.4g} mm; compression {how} to a gap of {p['deepest_gap_mm']:.4g} mm at "
                     f"{p['test_speed_mm_s']:g} mm/s; friction {record['options']['friction']}", highlight=False, markup=False)
    face = record.get("face")
    if face:
        stdout.print(f"faces at the deepest point: tilt {face['tilt_deg']:.3g} deg, gap spread across the sample "
                     f"{face['spread_mm']:.3g} mm, slide {face['slide_mm']:.3g} mm (bound {face['slide_bound_mm']:g} mm)",
                     highlight=False, markup=False)
    columns = [k for k in ("plant", "estimated") if record.get(k) is not None]
    intervals = record.get("estimated_ci95") or {}
    stdout.print("measure".ljust(20) + "".join(c.rjust(12) for c in columns) + ("  estimated 95 %" if intervals else ""),
                 highlight=False, markup=False)
    for m in MEASURES:
        cells = ["null" if record[c][m] is None else f"{record[c][m]:.4g}" for c in columns]
        bounds = intervals.get(m)
        ci = "" if bounds is None else f"  [{bounds[0]:.4g}, {bounds[1]:.4g}]"
        stdout.print(m.ljust(20) + "".join(c.rjust(12) for c in cells) + ci, highlight=False, markup=False)
    checks = record["checks"]
    stdout.print(f"checks: {sum(c['passed'] is True for c in checks)} passed, {sum(c['passed'] is False for c in checks)} "
                 f"failed, {sum(c['passed'] is None for c in checks)} not evaluated (tpa.json \"checks\")", highlight=False,
                 markup=False)
