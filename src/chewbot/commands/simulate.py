"""``chewbot simulate``: a controller drives the simulated robot along a task; a results folder out.

The command's options; the work is :mod:`chewbot.simulation.run`. Exit codes, ``--force`` and signals as every
command (docs/cli.md).
"""

from __future__ import annotations

from pathlib import Path

import typer

from chewbot.dynamics.options import Contact
from chewbot.kinematics.options import Side
from chewbot.run.options import Switch
from chewbot.simulation.controllers import table as controllers
from chewbot.simulation import engines
from chewbot.simulation.options import Sensor

SIMULATE_STEPS = 8  # models and task, simulation, kinematics, checks, results.csv, figures, report (and the compile)


def _rate(value: str) -> str:
    """A typer callback: a positive number (Hz) or 'continuous'."""
    if value == "continuous":
        return value
    try:
        number = float(value)
    except ValueError:
        raise typer.BadParameter(f"{value!r} is neither a rate in Hz nor 'continuous'") from None
    if not number > 0 or number != number or number == float("inf"):
        raise typer.BadParameter(f"the control rate must be a positive number of Hz, not {value}")
    return value


def _controller(value: str) -> str:
    if value not in controllers.CONTROLLERS:
        raise typer.BadParameter(f"{value!r} is not a controller; choose one of {', '.join(controllers.NAMES)}")
    return value


def _engine(value: str) -> str:
    if value not in engines.ENGINES:
        raise typer.BadParameter(f"{value!r} is not a plant engine; choose one of {', '.join(engines.NAMES)}")
    return value


def simulate(
    controller: str = typer.Option(controllers.DEFAULT_CONTROLLER, "--controller", callback=_controller, help=controllers.help_text()),
    compare: bool = typer.Option(False, "--compare", help=f"Run {', '.join(controllers.COMPARED)} on the same task and plant, each into OUT/CONTROLLER/, and print one table (RMS and peak tracking error, peak torque, time in saturation)."),
    task: str = typer.Option("default", "--task", help="'default' (the synthetic chewing task) or a CSV file (a results.csv of an earlier run too)."),
    model: str = typer.Option("target", "--model", help="The controller's model: a built-in model or a TOML parameter file (also the plant's unless --plant)."),
    side: Side | None = typer.Option(None, "--side", show_default=False, help="Molar where the bite force acts. Default: left, or the side of the run whose results.csv is the --task."),
    method: str | None = typer.Option(None, "--method", show_default=False, help="The inverse dynamics of the model-based controllers: hessian, lagrange, liang, 6rss-core or newton-euler (as chewbot run; Euler angles). Default: the formulation table's for Euler angles (hessian)."),
    goal: str | None = typer.Option(None, "--goal", show_default=False, help="newton-euler on the target: the distribution of the redundant torques (min-torque, min-coupler-force, min-hkp-force). Default: min-torque."),
    friction: Switch = typer.Option(Switch.off, "--friction", help="on|off: HKP and actuator friction in the plant (the model's coefficients); the controller's model has it only with --method newton-euler."),
    contact: Contact = typer.Option(Contact.bilateral, "--contact", help="bilateral|unilateral: whether the contact-pull check (the plant's N_L, N_R < 0, or below contact.preload_N) fails the run (unilateral) or is reported (bilateral). chewbot's plant keeps both contacts closed either way; MuJoCo's (--plant-engine mujoco) are unilateral."),
    rate: str = typer.Option("1000", "--rate", callback=_rate, help="Control rate in Hz (torques held between ticks), or 'continuous': the controller evaluated at every integrator stage, rows at the task's samples (for verification)."),
    noise: float = typer.Option(0.0, "--noise", min=0.0, help="Standard deviation (rad) of Gaussian noise on the measured crank angles; the controller then gets its state from an estimator (docs/simulation.md). 0: it sees the plant's state."),
    seed: int = typer.Option(0, "--seed", help="Seed of the sensor noise."),
    sensor: Sensor | None = typer.Option(None, "--sensor", show_default=False, help="What the controller is given: exact (the plant's state) or measured (its estimate from the six crank angles: Gauss-Newton forward kinematics and the filtered difference, cut-off estimator.cutoff_Hz, as the exported C step does). Default: measured with --noise or --exported, else exact."),
    exported: bool = typer.Option(False, "--exported", help="Run the controller as the exported C step (chewbot export-controller), compiled and called through ctypes at each tick (pd or computed-torque, --sensor measured); run.json records how far its torques are from the Python controller's on the same ticks (N m)."),
    plant: str | None = typer.Option(None, "--plant", show_default=False, help="The simulated robot's model, if not the controller's (built-in name or TOML file)."),
    plant_engine: str = typer.Option(engines.DEFAULT_ENGINE, "--plant-engine", callback=_engine, help="What simulates the plant's model: " + " or ".join(f"{e.name} ({e.help})" for e in engines.ENGINES.values()) + ". Only an engine whose plant closes the loop takes --rate continuous (chewbot's)."),
    compare_engines: bool = typer.Option(False, "--compare-engines", help=f"Simulate the controller on every engine ({', '.join(engines.NAMES)}), each into OUT/ENGINE/, and print one table; the comparison's report.html shows them side by side."),
    plant_set: list[str] = typer.Option([], "--plant-set", metavar="KEY=VALUE", help="Override one number of the plant's model only (as --set): the model error the controller does not know; repeatable."),
    set_: list[str] = typer.Option([], "--set", metavar="KEY=VALUE", help="Override one number of the controller's model (and of the plant's, unless --plant) or of the default task (task.NAME); repeatable."),
    bite_unknown: bool = typer.Option(False, "--bite-unknown", help="The bite force acts on the plant but the controller's inverse dynamics does not know it."),
    food: str | None = typer.Option(None, "--food", show_default=False, help="A food sample on the molar of the task's side: a built-in food (peanut, cheddar, gummy, bread, artisynth-bolus) or a TOML food file (docs/food.md). The bite force is then the food's force from the plant's state (results.csv: food_compression [m], food_force [N], food_broken [1], food_height [m]); the task must carry no bite force, except under --controller hybrid (its Fz is the force reference)."),
    gains: Path | None = typer.Option(None, "--gains", help="TOML file of the controllers' gains (default: the built-in gains, docs/simulation.md)."),
    gain: list[str] = typer.Option([], "--gain", metavar="KEY=VALUE", help="Override one gain of the gains file, SECTION.KEY=VALUE: a section per controller and the estimator's and observer's (docs/simulation.md lists the keys; units in the key names: pd.kp_Nm_per_rad=3 [N*m/rad], computed_torque.frequency_Hz=40 [Hz], observer.cutoff_Hz=150 [Hz]; KEY[i] for the i-th entry); repeatable."),
    out: Path = typer.Option(Path("runs/simulation"), "--out", help="Results folder to write."),
    force: bool = typer.Option(False, "--force", help="Replace the output if it exists and chewbot wrote it (anything else is never replaced)."),
    allow_violations: bool = typer.Option(False, "--allow-violations", help="Exit 0 even when a validity check fails (the checks are still written and printed)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Simulate the robot driven by a controller along a task, and write a results folder.

    The plant (the Newton-Euler model, with friction if --friction on) is integrated by a compiled Radau IIA
    method in its independent coordinates, or simulated by MuJoCo (--plant-engine mujoco); the controller runs at --rate with its own model (--model, --set),
    which may differ from the plant's (--plant, --plant-set). Torques are saturated at limits.torque_Nm. Writes
    results.csv (the simulated motion, applied and commanded torques, reference, tracking error, N_L, N_R,
    constraint drift; units in the header), run.json (options, both models, checks, tracking), figures and
    report.html. A robot that leaves the workspace is stopped there: a result, reported with its time. Exit code
    4 if a validity check failed, unless --allow-violations.

    Examples:

      chewbot simulate --controller computed-torque --out runs/ct

      chewbot simulate --compare --plant-set mandible.mass_g=408 --out runs/compare

      chewbot simulate --controller pd --friction on --noise 1e-4 --out runs/pd-noisy

      chewbot simulate --method newton-euler --friction on --bite-unknown --out runs/ne-blind

      chewbot simulate --food gummy --task runs/tpa-gummy/task.csv --out runs/gummy   (the task chewbot tpa wrote)

      chewbot simulate --controller hybrid --food cheddar --task examples/bite.csv --out runs/hybrid

      chewbot simulate --controller computed-torque --exported --out runs/ct-c

      chewbot simulate --plant-engine mujoco --contact unilateral --out runs/ct-mujoco

      chewbot simulate --compare-engines --contact unilateral --out runs/engines
    """
    from chewbot.commands.common import (check_interrupted, errors_reported, exit_after_checks, progress, resolved, set_overrides,
                                         stdout)
    from chewbot.files import check_output
    from chewbot.outputs.simulation import SIMULATION_FOLDER
    from chewbot.simulation.options import resolve
    from chewbot.simulation.run import input_files

    gain_overrides = set_overrides(gain, "--gain")
    with resolved():
        options = resolve(controller, model, task, side, method, goal, friction, contact, rate, noise, seed, plant,
                          set_overrides(set_), set_overrides(plant_set, "--plant-set"), bite_unknown,
                          None if gains is None else str(gains), gain_overrides, food, sensor, exported, plant_engine, compare,
                          compare_engines)
    from chewbot.export.mjcf import mjcf

    with errors_reported():
        check_output(out, force, SIMULATION_FOLDER, inputs=input_files(options))  # before the work, not after it
        if compare or compare_engines:
            from chewbot.outputs.simulation import write_comparison
            from chewbot.simulation.run import compare as run_compare

            label = "simulate --compare-engines" if compare_engines else "simulate --compare"
            with progress(quiet, label, total=len(options.runs()) * SIMULATE_STEPS) as step:
                results = run_compare(options, progress=step, check=check_interrupted, write_mjcf=mjcf)
                write_comparison(results, out, force=force, progress=step)
        else:
            from chewbot.outputs.simulation import write
            from chewbot.simulation.run import compute

            exported_step = None
            if exported:
                from chewbot.export.controller import ExportedController as exported_step
            with progress(quiet, "simulate", total=SIMULATE_STEPS + exported) as step:
                results = {controller: compute(options, progress=step, check=check_interrupted, exported=exported_step,
                                               write_mjcf=mjcf)}
                write(results[controller], out, force=force, progress=step)
    if not quiet:
        _print_summary(stdout, results, out, compare or compare_engines)
    exit_after_checks([c for r in results.values() for c in r.checks], allow_violations, quiet)


def _print_summary(stdout, results: dict, out: Path, compare: bool) -> None:
    """Where the report is, the tracking table, where a robot was stopped, the checks."""
    from rich.markup import escape

    from chewbot.report.simulation_html import METRICS_HEADER, metrics_rows

    rows = sum(r.table.n for r in results.values())
    stdout.print(f"wrote [bold]{escape(str(out))}[/] ({rows} rows); open {escape(str(out / 'report.html'))}", highlight=False)
    # a plain aligned table: whole on any terminal width, and easy to read from a script
    lines = [METRICS_HEADER[:-1]] + [row[:-1] for row in metrics_rows(results)]
    widths = [max(len(line[j]) for line in lines) for j in range(len(lines[0]))]
    for line in lines:
        stdout.print("  ".join(c.ljust(w) if j == 0 else c.rjust(w) for j, (c, w) in enumerate(zip(line, widths))),
                     highlight=False, markup=False)
    for label, r in results.items():
        o = r.options
        inverse = o.inverse
        dynamics = ("no inverse dynamics" if not o.controller.needs.inverse_dynamics else
                    f"inverse dynamics {inverse.method} (goal {inverse.goal or 'none: minimum-norm torques'}, friction in its model "
                    f"{'on' if inverse.friction else 'off'}, bite force {'unknown' if o.bite_unknown else 'known'})")
        stdout.print(f"{label}: used: controller {o.controller.name} at {'every integrator stage' if o.rate is None else f'{o.rate:g} Hz'} "
                     f"({dynamics}), plant friction {'on' if o.friction else 'off'}, contact {o.contact}, sensor noise {o.noise_rad:g} rad",
                     highlight=False, markup=False)
        stopped = r.metrics["stopped"]
        if stopped is not None:
            stdout.print(f"{label}: the robot left the workspace at t = {stopped['t']:.4g} s ({escape(stopped['reason'])}); "
                         "its motion ends at the last pose inside", highlight=False)
        f = r.metrics.get("force")
        if f and f["samples"]:
            stdout.print(f"{label}: force tracking, the plant's Fz against the task's Fz where it is not zero: RMS {f['rms_N']:.4g} N "
                         f"({f['rms_percent']:.3g} % of its peak {f['reference_peak_N']:.4g} N), peak {f['peak_N']:.4g} N", highlight=False)
        passed = sum(c.passed is True for c in r.checks)
        stdout.print(f"{label}: validity checks {passed} passed, {sum(c.passed is False for c in r.checks)} failed, "
                     f"{sum(c.samples is None for c in r.checks)} not evaluated; largest drift of the constraints "
                     f"{max(float(r.table[n].max()) for n in r.table.columns if n.startswith('drift_')):.3g} m", highlight=False)
