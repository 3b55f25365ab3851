"""``chewbot simulate``: a controller drives the simulated robot along a task; a results folder out.

The command's options; the work is :mod:`chewbot.simulation.run`. Exit codes, ``--force`` and signals as every
command (docs/cli.md).
"""

from __future__ import annotations

from pathlib import Path

import typer

from chewbot.simulation import CONTROLLERS

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
    if value not in CONTROLLERS:
        raise typer.BadParameter(f"{value!r} is not a controller; choose one of {', '.join(CONTROLLERS)}")
    return value


def simulate(
    controller: str = typer.Option("computed-torque", "--controller", callback=_controller, help="feedforward (the inverse dynamics of the reference, no feedback), pd (independent PD on the crank angles), computed-torque (inverse dynamics at the measured state with PD on the independent coordinates), impedance (springs and dampers in the molar point's x, y, z [N/m, N*s/m] and alpha [N*m/rad] around the reference, on top of the inverse dynamics) or hybrid (with --food: position control until the observed force passes hybrid.threshold_N, then force control along z following the task's Fz [N]; docs/bite_force.md)."),
    compare: bool = typer.Option(False, "--compare", help="Run feedforward, pd and computed-torque on the same task and plant, each into OUT/CONTROLLER/, and print one table (RMS and peak tracking error, peak torque, time in saturation)."),
    task: str = typer.Option("default", "--task", help="'default' (the synthetic chewing task) or a CSV file (a results.csv of an earlier run too)."),
    model: str = typer.Option("target", "--model", help="The controller's model: a built-in model or a TOML parameter file (also the plant's unless --plant)."),
    side: str | None = typer.Option(None, "--side", show_default=False, help="Molar where the bite force acts (left or right). Default: left, or the side of the run whose results.csv is the --task."),
    method: str = typer.Option("hessian", "--method", help="The controller's inverse dynamics: hessian, lagrange, liang, 6rss-core or newton-euler (as chewbot run; Euler angles)."),
    goal: str | None = typer.Option(None, "--goal", show_default=False, help="newton-euler on the target: the distribution of the redundant torques (min-torque, min-coupler-force, min-hkp-force). Default: min-torque."),
    friction: str = typer.Option("off", "--friction", help="on|off: HKP and actuator friction in the plant (the model's coefficients); the controller's model has it only with --method newton-euler."),
    contact: str = typer.Option("bilateral", "--contact", help="bilateral|unilateral: whether the contact-pull check (the plant's N_L, N_R < 0, or below contact.preload_N) fails the run (unilateral) or is reported (bilateral). The plant keeps both contacts closed either way."),
    rate: str = typer.Option("1000", "--rate", callback=_rate, help="Control rate in Hz (torques held between ticks), or 'continuous': the controller evaluated at every integrator stage, rows at the task's samples (for verification)."),
    noise: float = typer.Option(0.0, "--noise", min=0.0, help="Standard deviation (rad) of Gaussian noise on the measured crank angles; the controller then gets its state from an estimator (docs/simulation.md). 0: it sees the plant's state."),
    seed: int = typer.Option(0, "--seed", help="Seed of the sensor noise."),
    plant: str | None = typer.Option(None, "--plant", show_default=False, help="The simulated robot's model, if not the controller's (built-in name or TOML file)."),
    plant_set: list[str] = typer.Option([], "--plant-set", metavar="KEY=VALUE", help="Override one number of the plant's model only (as --set): the model error the controller does not know; repeatable."),
    set_: list[str] = typer.Option([], "--set", metavar="KEY=VALUE", help="Override one number of the controller's model (and of the plant's, unless --plant) or of the default task (task.NAME); repeatable."),
    bite_unknown: bool = typer.Option(False, "--bite-unknown", help="The bite force acts on the plant but the controller's inverse dynamics does not know it."),
    food: str | None = typer.Option(None, "--food", show_default=False, help="A food sample on the molar of the task's side: a built-in food (peanut, cheddar, gummy, bread, artisynth-bolus) or a TOML food file (docs/food.md). The bite force is then the food's force from the plant's state (results.csv: food_compression [m], food_force [N], food_broken [1]); the task must carry no bite force, except under --controller hybrid (its Fz is the force reference)."),
    gains: Path | None = typer.Option(None, "--gains", help="TOML file of the controllers' gains (default: the built-in gains, docs/simulation.md)."),
    gain: list[str] = typer.Option([], "--gain", metavar="KEY=VALUE", help="Override one gain: pd.kp_Nm_per_rad, pd.kd_Nms_per_rad, computed_torque.frequency_Hz, computed_torque.damping, estimator.cutoff_Hz, impedance.stiffness_N_per_m, impedance.damping_Ns_per_m, impedance.angle_stiffness_Nm_per_rad, impedance.angle_damping_Nms_per_rad, hybrid.frequency_Hz, hybrid.damping, hybrid.force_frequency_Hz, hybrid.force_damping, hybrid.threshold_N, hybrid.stiffness_min_N_per_m, hybrid.stiffness_max_N_per_m, hybrid.speed_limit_m_per_s, observer.cutoff_Hz (KEY[i] for the i-th entry; units in the key names); repeatable."),
    out: Path = typer.Option(Path("runs/simulation"), "--out", help="Results folder to write."),
    force: bool = typer.Option(False, "--force", help="Replace the output if it exists and chewbot wrote it (anything else is never replaced)."),
    allow_violations: bool = typer.Option(False, "--allow-violations", help="Exit 0 even when a validity check fails (the checks are still written and printed)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Simulate the robot driven by a controller along a task, and write a results folder.

    The plant (the Newton-Euler model, with friction if --friction on) is integrated by a compiled Radau IIA
    method in its independent coordinates; the controller runs at --rate with its own model (--model, --set),
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

      chewbot simulate --food cheddar --task closing.csv --out runs/cheddar

      chewbot simulate --controller hybrid --food cheddar --task bite.csv --out runs/hybrid
    """
    from chewbot.commands.common import (EXIT_BAD_INPUT, check_interrupted, errors_reported, exit_after_checks, fail, progress,
                                         resolved, set_overrides, stdout)
    from chewbot.errors import ChewbotError
    from chewbot.files import check_output
    from chewbot.outputs.simulation import SIMULATION_FOLDER
    from chewbot.simulation.run import SimulateOptions, input_files

    gain_overrides = set_overrides(gain)
    options = SimulateOptions(controller=controller, model=model, task=task, side=side, method=method, goal=goal, friction=friction,
                              contact=contact, rate=None if rate == "continuous" else float(rate), noise_rad=noise, seed=seed,
                              plant=plant, overrides=set_overrides(set_), plant_overrides=set_overrides(plant_set),
                              bite_unknown=bite_unknown, gains=None if gains is None else str(gains), gain_overrides=gain_overrides,
                              food=food)
    with resolved():
        options = options.resolved()
    if controller == "hybrid" and options.rate is None:
        fail(ChewbotError("--controller hybrid switches on the force observer's estimate at the ticks of a control rate: it needs a rate, not --rate continuous"), EXIT_BAD_INPUT)
    if noise > 0 and options.rate is None:
        fail(ChewbotError("--noise needs a control rate: the encoders are read at its ticks, not with --rate continuous"), EXIT_BAD_INPUT)
    with errors_reported():
        check_output(out, force, SIMULATION_FOLDER, inputs=input_files(options))  # before the work, not after it
        if compare:
            from chewbot.outputs.simulation import write_comparison
            from chewbot.simulation.run import compare as run_compare

            with progress(quiet, "simulate --compare", total=3 * SIMULATE_STEPS) as step:
                results = run_compare(options, progress=step, check=check_interrupted)
                write_comparison(results, out, force=force, progress=step)
        else:
            from chewbot.outputs.simulation import write
            from chewbot.simulation.run import compute

            with progress(quiet, "simulate", total=SIMULATE_STEPS) as step:
                results = {controller: compute(options, progress=step, check=check_interrupted)}
                write(results[controller], out, force=force, progress=step)
    if not quiet:
        _print_summary(stdout, results, out, compare)
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
        stopped = r.metrics["stopped"]
        if stopped is not None:
            stdout.print(f"{label}: the robot left the workspace at t = {stopped['t']:.4g} s ({escape(stopped['reason'])}); "
                         "its motion ends at the last pose inside", highlight=False)
        f = r.metrics.get("force")
        if f and f["samples"]:
            stdout.print(f"{label}: force tracking, the plant's Fz against the task's Fz where it is not zero: RMS {f['rms_N']:.4g} N "
                         f"({f['rms_percent']:.3g} % of its peak {f['reference_peak_N']:.4g} N), peak {f['peak_N']:.4g} N", highlight=False)
        passed = sum(c.passed and c.samples is not None for c in r.checks)
        stdout.print(f"{label}: validity checks {passed} passed, {sum(not c.passed for c in r.checks)} failed, "
                     f"{sum(c.samples is None for c in r.checks)} not evaluated; largest drift of the constraints "
                     f"{max(float(r.table[n].max()) for n in r.table.columns if n.startswith('drift_')):.3g} m", highlight=False)
