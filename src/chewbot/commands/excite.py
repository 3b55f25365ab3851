"""``chewbot excite``: an excitation task for identification (a periodic Fourier series in the task coordinates,
D-optimal for ``chewbot identify``'s regressor within the robot's limits) out, as a task CSV that ``run`` and
``simulate`` read.

The command's options and file; the design is :func:`chewbot.identification.excitation.design`, the task's checks a
run's (:func:`chewbot.run.pipeline.compute`, Newton-Euler with friction). The task is written whole through
:func:`chewbot.files.atomic_file`, its sidecar saying what it is (the design, the condition number, the checks);
exit codes, ``--force`` and signals as every command (docs/cli.md): exit 4 if a validity check of the task fails,
unless --allow-violations.
"""

from __future__ import annotations

import shlex
from pathlib import Path

import typer

from chewbot.commands.common import FORCE_HELP, errors_reported, exit_after_checks, flag, progress, stdout
from chewbot.kinematics.options import Side

EXCITE_STEPS = 5  # model, design, task and condition number, checks, writing
DURATION_S = 10.0
RATE_HZ = 1000.0


def excite(
    model: str = typer.Option("target", "--model", help="The robot to excite: a built-in model (target, 6rss, ...) or a TOML parameter file; its limits.speed_rad_per_s, limits.acceleration_rad_per_s2 and limits.torque_Nm bound the motion."),
    duration: float = typer.Option(DURATION_S, "--duration", min=0.0, help="Length of the task in s, rounded to whole periods of the series (2 s each; at least one): e.g. --duration 20 for ten periods."),
    side: Side = typer.Option(Side.left, "--side", help="left, or right for the mirror image of the same design (Y and alpha change sign); recorded as the task's side."),
    seed: int = typer.Option(0, "--seed", help="Seed of the random start of the design (the optimisation is local: another seed, another excitation), e.g. --seed 3."),
    out: Path = typer.Option(..., "--out", help="The task CSV to write: t [s], X, Y [m], alpha, beta [rad] (the 6RSS: all six coordinates), their rates and accelerations, Fx, Fy, Fz [N] (zero); the design in its sidecar OUT.chewbot.json."),
    force: bool = flag("--force", help=FORCE_HELP),
    allow_violations: bool = flag("--allow-violations", help="Exit 0 even when a validity check of the task fails (the checks are still written and printed)."),
    quiet: bool = flag("--quiet", "-q", help="Print nothing but errors and failed checks."),
) -> None:
    """Design an excitation task for chewbot identify: a Fourier series in the task coordinates, starting and ending at rest at home, within the robot's limits, whose identification regressor is well conditioned.

    Each coordinate is a sum of 5 harmonics of a 2 s period (Swevers et al. 1997); the coefficients maximise the
    log-determinant of the information of the parameters chewbot identify estimates (friction, crank inertias, the
    mandible's inertia) under the crank speed, acceleration and torque limits (80 % of each), the sockets and the
    chains' reach and transmission, by SciPy's SLSQP with exact gradients (CasADi). Prints the condition number of
    the identification's Jacobian on the task (as chewbot identify prints it) and writes it in the sidecar with the
    design; the task's validity checks are a run's (Newton-Euler with friction): exit code 4 if one fails.

    Examples:

      chewbot excite --model target --out excitation.csv

      chewbot excite --model target --duration 4 --seed 1 --out exc.csv && chewbot simulate --task exc.csv --friction on --out runs/excited
    """
    from chewbot.commands.common import check_interrupted
    from chewbot.files import WRITTEN_FILE, atomic_file, check_output
    from chewbot.identification.excitation import design, identification_condition, periods_of
    from chewbot.model.params import load_model
    from chewbot.run.options import RunOptions
    from chewbot.run.pipeline import compute
    from chewbot.task.csvio import task_table

    with errors_reported():
        m = load_model(model)
        inputs = [Path(m.source)]
        check_output(out, force, WRITTEN_FILE, inputs)  # before the work, not after it
        with progress(quiet, "excite", total=EXCITE_STEPS) as step:
            step("model and kernels")
            result = design(m, seed=seed, side=side.value, progress=step, check=check_interrupted)
            step("the task and its condition number")
            task = result.task(m, duration, RATE_HZ, name=out.stem)
            result.condition = identification_condition(m, task)
            step("validity checks (newton-euler with friction)")
            run = compute(RunOptions(model=model, method="newton-euler", side=side.value), check=check_interrupted, task=task)
            step("writing", stage="writing")
            args = ["--model", model, "--duration", f"{duration:g}", "--side", side.value, "--seed", str(seed), "--out", str(out)]
            about = f"an excitation task, read it with chewbot run --task or chewbot simulate --task; from chewbot excite {shlex.join(args)}"
            record = {"about": about, "excitation": result.record(), "duration_s": float(task.t[-1]),
                      "periods": periods_of(duration, result.series.period), "rate_Hz": RATE_HZ,
                      "checks": [c.as_dict() for c in run.checks]}
            with atomic_file(out, force, inputs, about={out: record}) as tmp:
                task_table(task).to_csv(tmp)
    if not quiet:
        b = result.binding
        used = ", ".join(f"{name} {b[name]['limit_used'] * 100:.0f} %" for name in ("dtheta", "ddtheta", "tau") if name in b)
        stdout.print(f"wrote {out} ({task.n} samples, {task.t[-1]:g} s: {periods_of(duration, result.series.period)} periods "
                     f"of {result.series.period:g} s); condition number of the identification's Jacobian (unit-norm "
                     f"columns, {len(result.parameters)} parameters): {result.condition:.4g}", highlight=False, markup=False)
        stdout.print(f"largest share of the limits: {used}; log det of the information {result.log_det_start:.5g} at the "
                     f"start, {result.log_det:.5g} designed ({result.solver['iterations']} SLSQP iterations: "
                     f"{result.solver['message']})", highlight=False, markup=False)
    exit_after_checks(run.checks, allow_violations, quiet)
