"""``chewbot run``: a task through the kinematics, the inverse dynamics and the checks into a results folder."""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer
from rich.markup import escape

from chewbot.commands.common import (FORCE_HELP, PROGRESS_DELAY_S, SET_HELP, check_interrupted, errors_reported,
                                     exit_after_checks, flag, progress, resolved, set_overrides, stdout)
from chewbot.dynamics.options import Contact, Goal
from chewbot.kinematics.options import Orientation, Side
from chewbot.run.options import Switch


class ResultsFormat(str, Enum):
    csv = "csv"
    parquet = "parquet"


def run(
    model: str = typer.Option("target", "--model", help="Built-in model (target, 6rss, target-as-printed, 6rss-as-printed) or a TOML parameter file."),
    task: str = typer.Option("default", "--task", help="'default' (the synthetic chewing task) or a CSV file (a results.csv of an earlier run too)."),
    side: Side | None = typer.Option(None, "--side", show_default=False, help="Molar where the bite force acts, and side of the default task. Default: left, or the side of the run whose results.csv is the --task."),
    orientation: Orientation = typer.Option(Orientation.euler_angles, "--orientation", help="Parametrisation of the mandible's orientation."),
    method: str | None = typer.Option(None, "--method", show_default=False, help="Inverse-dynamics formulation: hessian, lagrange, liang, 6rss-core (Euler angles) or newton-euler (either orientation). Default: hessian with Euler angles, newton-euler with Euler parameters."),
    goal: Goal | None = typer.Option(None, "--goal", show_default=False, help="newton-euler on the target: what the redundant torques minimise (torques, forces at S_i, HKP normal forces). Default: min-torque."),
    friction: Switch | None = typer.Option(None, "--friction", show_default=False, help="newton-euler: friction at the HKPs and the actuators. Default: on."),
    contact: Contact = typer.Option(Contact.bilateral, "--contact", help="Target: how the planes hold the condyles. bilateral: a ball in a slot, the plane may push or pull (the papers' reading); unilateral: a ball pressed on a plane, N_L, N_R >= contact.preload_N, kept by the redundant actuation where the limits allow (docs/contact.md)."),
    out: Path = typer.Option(Path("runs/default"), "--out", help="Results folder to write."),
    force: bool = flag("--force", help=FORCE_HELP),
    allow_violations: bool = flag("--allow-violations", help="Exit 0 even when a validity check fails (the checks are still written and printed)."),
    quiet: bool = flag("--quiet", "-q", help="Print nothing but errors."),
    set_: list[str] = typer.Option([], "--set", metavar="KEY=VALUE", help=SET_HELP),
    no_figures: bool = flag("--no-figures", help="Write no PNG figures (chewbot report DIR draws them later)."),
    no_report: bool = flag("--no-report", help="Write no report.html (chewbot report DIR writes it later)."),
    format_: ResultsFormat = typer.Option(ResultsFormat.csv, "--format", help="The rows' file: csv (results.csv, units in the header) or parquet (results.parquet: the same columns as float64, named 'name [unit]', units and descriptions in the schema's metadata; faster for long tasks)."),
) -> None:
    """Compute the kinematics and inverse dynamics of a task, check every sample, and write a results folder.

    Writes results.csv (or results.parquet with --format parquet; one row per sample, SI units in the header; torques tau1..tau6 and inertia coupling
    MCI1..MCI6 included), run.json (model, options, versions, units, the validity checks), figures and report.html.
    The folder is always written in full; the exit code is then 4 if a validity check failed (torque, power or
    bearing limits, crank range, speed, an infeasible distribution, and under --contact unilateral a normal force
    below contact.preload_N), unless --allow-violations. A long task is processed in chunks, in constant memory;
    --no-figures and --no-report leave out the drawings (chewbot report draws them later).

    Examples:

      chewbot run --out runs/left

      chewbot run --model 6rss --side right --out runs/6rss-right

      chewbot run --task my_chewing.csv --orientation euler-parameters --out runs/mine

      chewbot run --method newton-euler --goal min-hkp-force --friction on --out runs/ne-g3

      chewbot run --method newton-euler --contact unilateral --set contact.preload_N=2 --out runs/pressed

      chewbot run --task runs/left/results.csv --method liang --out runs/left-liang

      chewbot run --set chains.crank_length_mm[3]=12 --set task.force_z_N=-100 --out runs/longer-crank

      chewbot run --task long_recording.csv --no-figures --no-report --out runs/batch

      chewbot run --task long_recording.csv --format parquet --no-figures --out runs/batch-parquet
    """
    from chewbot.report.figures import drawing_process
    from chewbot.run.options import resolve

    overrides = set_overrides(set_)
    with resolved():
        options = resolve(model=model, task=task, side=side, orientation=orientation, method=method, goal=goal,
                          friction=friction, contact=contact, overrides=overrides)
    # the drawing process loads matplotlib while this one loads the rest of chewbot and computes
    with drawing_process(not no_figures) as drawer, errors_reported():
        from chewbot.files import RESULTS_FOLDER, check_output
        from chewbot.outputs.writer import write_run
        from chewbot.run.pipeline import input_files

        check_output(out, force, RESULTS_FOLDER, inputs=input_files(options))  # before the work, not after it
        with progress(quiet, "run", delay=PROGRESS_DELAY_S) as step:
            done = write_run(options, out, force=force, progress=step, figures=not no_figures, report=not no_report,
                             check=check_interrupted, format=format_.value, drawer=drawer)
    if not quiet:
        _print_run_summary(done, out)
    exit_after_checks(done.checks, allow_violations, quiet)



def _print_run_summary(done, out: Path) -> None:
    """The lines a person wants after a run: where the report is and the peak torque (the checks follow)."""
    from chewbot.commands.common import options_line
    from chewbot.report.summary import contact_note, normal_force_stats, numbered_columns

    view = done.view
    report = out / "report.html"
    where = f"open {escape(str(report))}" if any(p.name == "report.html" for p in done.files) else f"chewbot report {escape(str(out))} draws the report"
    stdout.print(f"wrote [bold]{escape(str(out))}[/] ({view.n} samples, {len(view.columns)} columns); {where}", highlight=False)
    stdout.print(escape(options_line(done.record["options"])), highlight=False)
    taus = numbered_columns(view.rows, "tau")
    if taus:
        top = max((view.stats[name] for name in taus), key=lambda s: abs(s.peak))
        stdout.print(f"largest torque: {top.name} = {top.peak:.4g} N·m at t = {top.t_peak:.3f} s", highlight=False)
    contact = done.record["options"].get("contact", "bilateral")
    preload = done.model.contact.preload if contact == "unilateral" else 0.0
    forces = normal_force_stats(view.stats)
    if forces:
        stdout.print(f"contact model: {contact_note(contact, preload, done.record.get('dynamics', {}))}", highlight=False)
        stdout.print("normal forces: " + ", ".join(f"{f.name} from {f.low:.4g} to {f.high:.4g} N ({f.below:.3g} % of the samples "
                                                    f"below {preload:g} N)" for f in forces), highlight=False)
    checks = done.checks
    passed = sum(c.passed is True for c in checks)
    stdout.print(f"validity checks: {passed} passed, {sum(c.passed is False for c in checks)} failed, "
                 f"{sum(c.samples is None for c in checks)} not evaluated (run.json, \"checks\")", highlight=False)
