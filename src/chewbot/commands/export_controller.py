"""``chewbot export-controller``: the whole controller step as a self-contained C99 library."""

from __future__ import annotations

from pathlib import Path

import typer

from chewbot.commands.common import FORCE_HELP, flag
from chewbot.run.options import Switch
from chewbot.simulation.controllers import table as controllers

EXPORTABLE = [controllers.CONTROLLERS[name] for name in controllers.EXPORTABLE]


def export_controller(
    out: Path = typer.Option(..., "--out", help="Folder to write the library to (include/, src/, example/, Makefile, README.md)."),
    model: str = typer.Option("target", "--model", help="The controller's model: a built-in model or a TOML parameter file (its numbers are folded into the code)."),
    method: str | None = typer.Option(None, "--method", show_default=False, help="The inverse dynamics of a model-based controller: hessian, lagrange, liang, 6rss-core (minimum-norm torques) or newton-euler (the fixed-cost distribution of --goal). Default: the formulation table's for Euler angles (hessian)."),
    goal: str | None = typer.Option(None, "--goal", show_default=False, help="newton-euler on the target: min-torque (G1), min-coupler-force or min-hkp-force. Default: min-torque."),
    friction: Switch = typer.Option(Switch.off, "--friction", help="on|off: the model's HKP and actuator friction in newton-euler's inverse dynamics (and in the plant of the simulation that writes the example's log)."),
    controller: str = typer.Option(controllers.DEFAULT_CONTROLLER, "--controller", help=" or ".join(f"{r.name} ({r.help})" for r in EXPORTABLE) + ": the controllers the exported step runs; their gains in the units of the gains file's keys (docs/simulation.md)."),
    gains: Path | None = typer.Option(None, "--gains", help="TOML file of the gains (as chewbot simulate; default: the built-in gains). They are the defaults of the library's ctx->config.gains."),
    task: str = typer.Option("default", "--task", help="The reference compiled in as a table: 'default' (the synthetic chewing task) or a CSV file (a results.csv of an earlier run too)."),
    side: str | None = typer.Option(None, "--side", show_default=False, help="Molar where the bite force acts (left or right). Default: left, or the side of the run whose results.csv is the --task."),
    rate: float = typer.Option(1000.0, "--rate", min=1.0, help="Control rate (Hz): the log's ticks; the watchdog trips at 1.5 periods."),
    torque_rate: float = typer.Option(0.0, "--torque-rate-limit", min=0.0, help="Default torque-rate limit (N m/s) of ctx->config; 0: off (the caller may set it)."),
    log: bool = typer.Option(True, "--log/--no-log", help="Simulate the controller along the task (chewbot simulate --sensor measured) and write example/log.csv (t, crank angles, commanded torques) for example.c to check against."),
    force: bool = flag("--force", help=FORCE_HELP),
) -> None:
    """Write the controller step the robot runs as a self-contained C99 library.

    One call per tick, chewbot_ctrl_step(ctx, t, theta_measured[6], tau_out[6], &status): forward kinematics of the
    measured crank angles (Gauss-Newton from the last estimate, fixed iterations), the rates by the filtered
    difference, the reference at t (the task compiled in, or set by the caller), the control law with its torque
    distribution, saturation, a torque-rate limit, a watchdog, an emergency stop and a status word. libm only, no
    allocation, no global state, no I/O in the step; compiles with -std=c99 -Wall -Wextra -Werror -pedantic.
    example/example.c runs the step against example/log.csv (a simulation of this controller), checks the torques
    and prints the time per step (`make check`). README.md documents the API, the status bits and their safe
    behaviour.

    Examples:

      chewbot export-controller --controller computed-torque --out controller && make -C controller check

      chewbot export-controller --method newton-euler --friction on --out controller-g1
    """
    from rich.markup import escape

    from chewbot.commands.common import EXIT_BAD_INPUT, errors_reported, fail, progress, resolved, stdout
    from chewbot.errors import ChewbotError
    from chewbot.files import EXPORT_FOLDER, check_output

    if controller not in controllers.EXPORTABLE:
        fail(ChewbotError(f"--controller {controller!r}: the exported step runs {' or '.join(controllers.EXPORTABLE)}"), EXIT_BAD_INPUT)
    from chewbot.simulation.options import resolve
    from chewbot.simulation.run import build, input_files

    with resolved():
        options = resolve(controller, model, task, side, method, goal, friction, rate=rate,
                          gains_file=None if gains is None else str(gains), sensor="measured")
    with errors_reported():
        check_output(out, force, EXPORT_FOLDER, inputs=input_files(options))  # before the work, not after it
        from chewbot.export.controller import StepSpec, export_controller as write

        with progress(False, "export-controller") as step:
            step("models and task")
            parts = build(options)
            built_model = parts.model
            spec = StepSpec.of(parts.controller, rate, torque_rate)
            rows = None
            if log:
                from chewbot.export.controller import simulation_log
                from chewbot.simulation.run import compute

                step("simulating the controller for the example's log")
                simulated = compute(options)
                rows = simulation_log(simulated)
                stopped = simulated.metrics["stopped"]
                if stopped is not None:
                    raise ChewbotError(f"in simulation this controller leaves the workspace at t = {stopped['t']:.4g} s "
                                       f"({stopped['reason']}): the example's log would record a failing loop. Give gains that "
                                       "are stable on the measured state (--gains; docs/simulation.md gives slower PD gains for "
                                       "the estimator), or export without the log (--no-log)")
            step("generating C")
            write(spec, out, force=force, inputs=input_files(options), log=rows)
    uses = options.controller.needs.inverse_dynamics
    stdout.print(f"wrote {escape(str(out))} ({spec.kind}, {spec.method if uses else 'PD'}, model {escape(built_model.name)}, "
                 f"{len(spec.t)} task samples{'' if rows is None else f', a log of {len(rows)} ticks'}); build and check it with "
                 f"make -C {escape(str(out))} check", highlight=False)
