"""The ``chewbot`` command line (typer + rich).

Every command follows the same rules (docs/cli.md): exit codes and signals (:mod:`chewbot.commands.common`), outputs
written whole and never over what chewbot did not write (:mod:`chewbot.files`). The helpers below are what a
command calls: :func:`errors_reported`, :func:`fail`, :func:`progress`, :func:`exit_after_checks`, and the
options :data:`FORCE_HELP`, :func:`flag`.
"""

from __future__ import annotations

from contextlib import contextmanager
from enum import Enum
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape

from chewbot.commands.common import (  # noqa: F401  (the exit codes, for the commands and their tests)
    EXIT_BAD_INPUT,
    EXIT_CHECK_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_TERMINATED,
    EXIT_UNREACHABLE,
    check_interrupted,
)
from chewbot.errors import ChewbotError
from chewbot.commands.identify import identify
from chewbot.commands.import_motion import import_motion
from chewbot.commands.simulate import simulate
from chewbot.commands.sweep import sweep

app = typer.Typer(
    name="chewbot",
    help="Kinematics, inverse dynamics and inertia coupling of the bio-inspired chewing robot and its 6RSS counterpart.\n\n"
         "Examples:\n\n"
         "  chewbot run --out runs/default\n\n"
         "  chewbot run --method newton-euler --goal min-hkp-force --out runs/g3\n\n"
         "  chewbot study seed000 --out runs/seed000\n\n"
         "  chewbot export-c --out kernels",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
    epilog="Exit codes: 0 success; 1 unexpected error (a bug); 2 bad input or usage; 3 unreachable or singular pose; "
           "4 results written, a validity check failed; 5 output exists (not written by chewbot, or no --force) or cannot be "
           "written; 130 interrupted (SIGINT); 143 terminated (SIGTERM). See docs/cli.md.",
)
console = Console(stderr=True, soft_wrap=True)  # progress, warnings, errors: standard error, paths unwrapped
stdout = Console(soft_wrap=True)  # results: standard output, for scripts

PROGRESS_DELAY_S = 1.0  # a run shows its progress bar once it has taken this long
FORCE_HELP = "Replace the output if it exists and chewbot wrote it (anything else is never replaced)."


def _flags_without_a_type() -> None:
    """Show boolean flags as flags in help (``--force``), not with the ``<bool>`` type that typer 0.2x prints
    beside them (a value they do not take). Older typer versions have no such type column: nothing to do."""
    from typer.core import TyperOption

    shown = getattr(TyperOption, "display_type_rich", None)
    if shown is not None:
        TyperOption.display_type_rich = lambda self, ctx: None if self.is_flag else shown(self, ctx)


_flags_without_a_type()


def flag(*names: str, help: str) -> bool:
    """A boolean option that is off unless given (``--force``)."""
    return typer.Option(False, *names, help=help)


def exit_code(exc: BaseException) -> int:
    """The exit code for an error chewbot raised on purpose (the table in docs/cli.md). Exit code 4 is not an
    error's: it follows a complete output whose validity checks failed (:func:`exit_after_checks`)."""
    from chewbot.errors import KinematicsError
    from chewbot.files import OutputError

    for kind, code in ((KinematicsError, EXIT_UNREACHABLE), (OutputError, EXIT_OUTPUT)):
        if isinstance(exc, kind):
            return code
    return EXIT_BAD_INPUT


def fail(exc: Exception, code: int | None = None) -> None:
    """Print the error (its message names the file, row, key or sample) and exit with its code."""
    console.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)  # unwrapped: paths stay whole
    raise typer.Exit(exit_code(exc) if code is None else code)




@contextmanager
def errors_reported():
    """Turn the errors chewbot raises on purpose into one line on standard error and their exit code."""
    try:
        yield
    except ChewbotError as exc:
        fail(exc)


def exit_after_checks(checks, allow_violations: bool, quiet: bool = False) -> None:
    """After the output is written: print a table of the failed checks (standard error) and exit 4 if one of them
    fails the run, unless ``allow_violations``. With ``quiet`` only the checks that make it exit 4 are printed
    (they are its error)."""
    from chewbot.analysis.checks import run_fails

    stops = run_fails(checks) and not allow_violations
    if quiet:
        failed = [c for c in checks if c.fails_run] if stops else []
    else:
        failed = [c for c in checks if not c.passed]
    if failed:
        from rich import box
        from rich.table import Table as RichTable

        table = RichTable(title="failed validity checks (details: run.json, \"checks\", and report.html)", title_justify="left",
                          box=box.SIMPLE_HEAD, pad_edge=False)
        for col, justify in (("check", "left"), ("counts as", "left"), ("samples", "right"), ("first at t [s]", "right"), ("worst", "right")):
            table.add_column(escape(col), justify=justify, no_wrap=True)
        for c in failed:
            worst = "" if c.worst is None else f"{c.worst['value']:.4g} {c.worst['unit']}"
            first = "" if c.first_sample is None else f"{c.first_sample['t']:.4g}"
            table.add_row(c.name, "failure" if c.fails_run else "warning", str(c.samples), first, escape(worst))
        console.print(table)
    if stops:
        raise typer.Exit(EXIT_CHECK_FAILED)
    if run_fails(checks) and not quiet:
        console.print("[yellow]warning:[/] a validity check failed; exit code 0 because of --allow-violations", highlight=False)


class Side(str, Enum):
    left = "left"
    right = "right"


class Orientation(str, Enum):
    euler_angles = "euler-angles"
    euler_parameters = "euler-parameters"


class Goal(str, Enum):
    """Optimal distribution of the target's redundant actuation (Newton-Euler, seed 001 Sect. 4.5)."""

    min_torque = "min-torque"
    min_coupler_force = "min-coupler-force"
    min_hkp_force = "min-hkp-force"


class Switch(str, Enum):
    on = "on"
    off = "off"


class Contact(str, Enum):
    """How the HKP planes hold the condyles (docs/contact.md)."""

    bilateral = "bilateral"
    unilateral = "unilateral"


def _version(value: bool) -> None:
    if value:
        from chewbot import __version__

        stdout.print(f"chewbot {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version and exit.")) -> None:
    """chewbot: run a chewing task on the robot model and write its results.

    Start with `chewbot run --out runs/default`; see `chewbot COMMAND --help` for each command.
    """


def _check_method(name: str | None) -> str | None:
    """Accept the name of a registered inverse-dynamics formulation (the registry is the list of choices)."""
    from chewbot.dynamics import METHODS

    if name is not None and name not in METHODS:
        raise typer.BadParameter(f"{name!r} is not a formulation; choose one of {', '.join(sorted(METHODS))}")
    return name


SET_HELP = ("Override one number of the model (a parameter-file key in the file's units, 1-based indices: "
            "friction.hkp_coulomb=0.2, chains.crank_length_mm[3]=12, chains.G_mm[2][1]=24) or of the default task "
            "(task.force_z_N=-100); repeatable. Values that follow from it stay consistent (docs/models.md).")


def _overrides(arguments: list[str]) -> dict[str, float]:
    """``--set KEY=VALUE`` arguments as a dict, in order (a key given twice: the last value); exit 2 on a bad one."""
    from chewbot.model.params import parse_override

    with errors_reported():
        return dict(parse_override(a) for a in arguments)


@app.command()
def run(
    model: str = typer.Option("target", "--model", help="Built-in model (target, 6rss, target-as-printed, 6rss-as-printed) or a TOML parameter file."),
    task: str = typer.Option("default", "--task", help="'default' (the synthetic chewing task) or a CSV file (a results.csv of an earlier run too)."),
    side: Side | None = typer.Option(None, "--side", show_default=False, help="Molar where the bite force acts, and side of the default task. Default: left, or the side of the run whose results.csv is the --task."),
    orientation: Orientation = typer.Option(Orientation.euler_angles, "--orientation", help="Parametrisation of the mandible's orientation."),
    method: str | None = typer.Option(None, "--method", callback=_check_method, show_default=False, help="Inverse-dynamics formulation: hessian, lagrange, liang, 6rss-core (Euler angles) or newton-euler (either orientation). Default: hessian with Euler angles, newton-euler with Euler parameters."),
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
) -> None:
    """Compute the kinematics and inverse dynamics of a task, check every sample, and write a results folder.

    Writes results.csv (one row per sample, SI units in the header; torques tau1..tau6 and inertia coupling
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
    """
    from chewbot.files import RESULTS_FOLDER, check_output
    from chewbot.run.pipeline import RunOptions, input_files
    from chewbot.run.pipeline import run as run_to_folder

    overrides = _overrides(set_)
    if method is None:
        method = "hessian" if orientation is Orientation.euler_angles else "newton-euler"
    if method != "newton-euler" and (goal is not None or friction is not None):
        fail(ChewbotError(f"--goal and --friction apply to --method newton-euler, not {method} (frictionless, minimum-norm torques)"), EXIT_BAD_INPUT)
    sixrss = False
    if method == "newton-euler" or contact is Contact.unilateral:  # options that only the target takes
        from chewbot.model.params import load_model

        with errors_reported():
            sixrss = not load_model(model).has_hkp
    if sixrss and contact is Contact.unilateral:
        fail(ChewbotError("--contact unilateral applies to the target robot: the 6RSS has no HKP contacts"), EXIT_BAD_INPUT)
    if method == "newton-euler":  # what newton-euler uses; the other formulations take neither
        if sixrss and goal is not None:
            fail(ChewbotError("--goal applies to the target robot: the 6RSS has no redundant actuation to distribute"), EXIT_BAD_INPUT)
        goal, friction = None if sixrss else goal or Goal.min_torque, friction or Switch.on
    options = RunOptions(model=model, task=task, side=side and side.value, orientation=orientation.value, method=method,
                         goal=goal and goal.value, friction=friction and friction.value, contact=contact.value, overrides=overrides)
    with errors_reported():
        check_output(out, force, RESULTS_FOLDER, inputs=input_files(options))  # before the work, not after it
        with progress(quiet, "run", delay=PROGRESS_DELAY_S) as step:
            done = run_to_folder(options, out, force=force, progress=step, figures=not no_figures, report=not no_report)
    if not quiet:
        _print_run_summary(done, out)
    exit_after_checks(done.checks, allow_violations, quiet)


@contextmanager
def progress(quiet: bool, label: str, total: int | None = None, delay: float = 0.0):
    """A progress bar that names the current step (nothing with --quiet, nor where standard error is not a
    terminal: a log gets no bar). The yielded callback ``step(message, done=None, total=None)`` starts a step:
    with ``done`` the bar shows that many units of ``total`` done (samples of a run), else it advances by one
    step of ``total`` (the number of steps, if known; otherwise it pulses). ``delay``: the bar appears only once
    the command has run that many seconds (a short run shows none). Each step also stops the command if a signal
    arrived that a library swallowed (:func:`chewbot.commands.common.check_interrupted`)."""
    if quiet or not console.is_terminal:
        yield lambda msg, done=None, total=None: check_interrupted()
        return
    import time

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    bar = Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                   console=console, transient=True)
    task = bar.add_task(label, total=total)
    start, shown, started = time.monotonic(), False, False

    def step(msg: str, done: int | None = None, total: int | None = None) -> None:
        nonlocal shown, started
        check_interrupted()
        if total is not None:
            bar.update(task, total=total)
        if done is not None:
            bar.update(task, description=f"{label}: {msg}", completed=done)
        else:
            bar.update(task, description=f"{label}: {msg}", advance=1 if started else 0)
        started = True
        if not shown and time.monotonic() - start >= delay:
            bar.start()
            shown = True

    try:
        yield step
    finally:
        bar.stop()


def _print_run_summary(done, out: Path) -> None:
    """The lines a person wants after a run: where the report is and the peak torque (the checks follow)."""
    from chewbot.report.summary import contact_note, normal_force_stats, numbered_columns

    view = done.view
    report = out / "report.html"
    where = f"open {escape(str(report))}" if any(p.name == "report.html" for p in done.files) else f"chewbot report {escape(str(out))} draws the report"
    stdout.print(f"wrote [bold]{escape(str(out))}[/] ({view.n} samples, {len(view.columns)} columns); {where}", highlight=False)
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
    passed = sum(c.passed and c.samples is not None for c in checks)
    stdout.print(f"validity checks: {passed} passed, {sum(not c.passed for c in checks)} failed, "
                 f"{sum(c.samples is None for c in checks)} not evaluated (run.json, \"checks\")", highlight=False)


@app.command("report")
def report_command(
    folder: Path = typer.Argument(..., help="A results folder written by chewbot run."),
    force: bool = flag("--force", help="Replace the folder's figures and report.html if they exist (results.csv and run.json are never written)."),
    no_figures: bool = flag("--no-figures", help="Write report.html only."),
    no_report: bool = flag("--no-report", help="Draw the figures only."),
    quiet: bool = flag("--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Draw the figures and write report.html of a results folder from its results.csv and run.json.

    What chewbot run writes at its end, later: after a run with --no-figures or --no-report, or to draw a run again.
    Only the figures and report.html are written into the folder (all or none, each complete before it replaces
    an older one; an existing one only with --force); results.csv and run.json are only read. The model is read
    from the parameter file run.json names and must still have the run's parameters.

    Examples:

      chewbot run --no-figures --no-report --out runs/batch && chewbot report runs/batch

      chewbot report runs/default --force
    """
    from chewbot.run.pipeline import redraw

    if no_figures and no_report:
        fail(ChewbotError("--no-figures and --no-report together leave nothing to write"), EXIT_BAD_INPUT)
    with errors_reported():
        with progress(quiet, "report", delay=PROGRESS_DELAY_S) as step:
            written = redraw(folder, force=force, figures=not no_figures, report=not no_report, progress=step)
    if not quiet:
        stdout.print(f"wrote {', '.join(p.name for p in written)} in [bold]{escape(str(folder))}[/]", highlight=False)


@app.command()
def bench(
    repeats: int = typer.Option(11, "--repeats", min=3, help="Timed runs per case after the first, interleaved (median and spread reported)."),
    calls: int = typer.Option(20000, "--calls", min=100, help="Calls per in-loop kernel for the one-sample timings."),
    long: bool = flag("--long", help="Also run tasks of 10,000 to 1,000,000 samples with every method: time per "
                      "sample and peak memory (about half an hour)."),
    sweep: int = typer.Option(0, "--sweep", metavar="N", min=0, help="Also time the sweep's scale study (the built-in "
                              "SPEC sobol-scale) with N base samples, a power of 2 (10 N evaluations), in this process and "
                              "on local clusters of 1 and 2 workers, and project the whole study (1,024 base samples)."),
    out: Path | None = typer.Option(None, "--out", help="Also write the tables as Markdown to this file (replaces a "
                                    "file written by chewbot bench with --force)."),
    force: bool = flag("--force", help=FORCE_HELP),
) -> None:
    """Time what a user waits for: chewbot run and --help, every formulation on the default task (5001 samples),
    both mechanisms, the in-loop kernels and the exported C.

    Every timing is repeated, and the variants a table compares run interleaved: medians with the interquartile
    range of the runs; a ratio whose two spreads overlap is printed as "within noise". The machine and its load
    average are written above the tables. Timings are not tests: pin to one core for single-core figures.

    Examples:

      chewbot bench --out docs/benchmark.md --force

      taskset -c 0 chewbot bench --long --out bench.md

      chewbot bench --sweep 32 --out bench.md
    """
    from chewbot.bench.benchmark import bench_sweep, benchmark, sweep_markdown
    from chewbot.files import WRITTEN_FILE, atomic_file, check_output, marker_line

    if sweep & (sweep - 1):
        fail(ChewbotError(f"--sweep {sweep}: the base samples of a Sobol' study must be a power of 2 (8, 16, 32, ...)"), EXIT_BAD_INPUT)
    with errors_reported():
        if out is not None:
            check_output(out, force, WRITTEN_FILE)  # before the timings, not after them
        with progress(False, "timing") as step:
            text = benchmark(repeats=repeats, calls=calls, long=long, progress=step)
            if sweep:
                text += sweep_markdown(*bench_sweep(sweep, progress=step))
        stdout.print(text, markup=False, highlight=False)
        if out is not None:
            with atomic_file(out, force) as tmp:
                tmp.write_text(marker_line("<!--", "chewbot bench") + "\n" + text)


@app.command("export-c")
def export_c(
    out: Path = typer.Option(..., "--out", help="Folder to write the C kernels to."),
    target: str = typer.Option("target", "--target-model", help="The target robot's model (built-in name or TOML file)."),
    sixrss: str = typer.Option("6rss", "--6rss-model", help="The 6RSS counterpart's model (built-in name or TOML file)."),
    force: bool = flag("--force", help=FORCE_HELP),
) -> None:
    """Write the real-time kernels as dependency-free C for the robot's controller.

    The folder holds chewbot_kernels.c and .h (plain C99, <math.h> only), a README with each kernel's inputs and
    outputs and their units and the expected outputs on an example sample, example.c (evaluates each kernel on
    that sample; `./example 100000` also times them) and a Makefile. Kernels: minimum-norm torques of the target
    and torques of the 6RSS (lean, and with M_f, C_f, G_f), M_A with MCI, and the friction-aware G1 distribution.

    Example:

      chewbot export-c --out controller/chewbot && make -C controller/chewbot
    """
    from chewbot.export.c import export_c as write_c
    from chewbot.files import EXPORT_FOLDER, check_output
    from chewbot.model.params import load_model
    from chewbot.export.realtime import kernels

    with errors_reported():
        t, s = load_model(target), load_model(sixrss)
        for m, want in ((t, "target"), (s, "6rss")):
            if m.mechanism != want:
                raise ChewbotError(f"{m.source}: mechanism is {m.mechanism!r}, expected {want!r} here")
        inputs = [Path(m.source) for m in (t, s)]
        check_output(out, force, EXPORT_FOLDER, inputs)  # before the kernels are built, not after
        with progress(False, "generating C") as step:
            step("building kernels")
            ks = kernels(t, s)
            step("writing C")
            write_c(ks, out, model_name=f"{t.name} + {s.name}", force=force, inputs=inputs)
    stdout.print(f"wrote {escape(str(out))} ({len(ks)} kernels)", highlight=False)


@app.command()
def study(
    name: str = typer.Argument(..., help="The study to run: seed000 (inverse dynamics and inertia coupling, seed 000) "
                               "or seed001 (Newton-Euler with friction, optimal distribution, Euler parameters, seed 001)."),
    out: Path | None = typer.Option(None, "--out", help="Folder to write the table and figures to (default runs/NAME)."),
    force: bool = flag("--force", help=FORCE_HELP),
) -> None:
    """Reproduce a paper's findings on the default models, write a table of claims and figures, and print the table.

    Examples:

      chewbot study seed000 --out runs/seed000

      chewbot study seed001 --out runs/seed001
    """
    from chewbot.study import STUDIES
    from chewbot.study.claims import claims_table

    if name not in STUDIES:
        fail(ValueError(f"unknown study {name!r}; available: {', '.join(sorted(STUDIES))}"), EXIT_BAD_INPUT)
    with errors_reported():
        out = out or Path("runs") / name
        with progress(False, f"study {name}") as step:  # each study refuses an existing folder before its work
            written = STUDIES[name](out, force=force, progress=step)
        stdout.print(claims_table(written))
    stdout.print(f"wrote [bold]{escape(str(written))}[/]", highlight=False)


@app.command("track-incisor")
def track_incisor(
    path: Path = typer.Argument(..., help="CSV of the incisor path: t, Ix, Iy, Iz (point I in {S}), optional rates dIx..ddIz and bite force Fx, Fy, Fz; units in brackets."),
    out: Path = typer.Option(..., "--out", help="Task CSV to write (read it back with chewbot run --task); the residuals go beside it, *.residuals.csv."),
    model: str = typer.Option("target", "--model", help="The target robot's model (built-in name or TOML file)."),
    pin: str = typer.Option("alpha", "--pin", help="The coordinate that resolves the redundancy (the incisor gives 3 equations for 4 DOF): X, Y, alpha or beta. It follows its column in the path file if there is one (e.g. alpha[deg]), else it is held at zero."),
    orientation: Orientation = typer.Option(Orientation.euler_angles, "--orientation", help="Parametrisation the optimisation works in."),
    side: Side = typer.Option(Side.left, "--side", help="Molar where the file's bite force acts."),
    force: bool = flag("--force", help=FORCE_HELP),
) -> None:
    """Find the mandible's motion that makes the incisor follow a path (seed 001, Sect. 5.1).

    Solves, sample after sample, the displacement, velocity and acceleration problems by SQP under the HKP
    constraints and the sockets' bounds; writes the task and the residuals f_D, f_V, f_A, and prints their maxima.

    Example:

      chewbot track-incisor incisor.csv --out task.csv --pin alpha && chewbot run --task task.csv --out runs/tracked
    """
    from chewbot.files import WRITTEN_FILE, atomic_files, check_output, marker_line
    from chewbot.model.params import load_model
    from chewbot.task.csvio import read_incisor_csv
    from chewbot.task.incisor import track_incisor as track

    residuals = out.with_name(out.stem + ".residuals.csv")
    with errors_reported():
        m = load_model(model)
        inputs = [path, Path(m.source)]
        for target in (out, residuals):  # before the work, not after it
            check_output(target, force, WRITTEN_FILE, inputs)
        path_data = read_incisor_csv(path)
        with progress(False, "incisor tracking") as step:
            step("solving")
            result = track(m, path_data["t"], path_data["p"], path_data["v"], path_data["a"], orientation=orientation.value,
                           pin=pin, pinned=path_data["pinned"].get(pin), force=path_data["force"], side=side.value, name=out.stem)
        with atomic_files((out, residuals), force, inputs) as temporaries:
            for table, tmp, what in zip(result.tables(), temporaries, ("a task, read it with chewbot run --task",
                                                                       "residuals of chewbot track-incisor")):
                table.to_csv(tmp, first_line=marker_line("#", f"{what}; from {path.name}"))
    stdout.print(f"wrote {escape(str(out))} and {escape(str(residuals))}; max |f_D| = {abs(result.f_D).max():.3g} m, "
                 f"max |f_V| = {abs(result.f_V).max():.3g} m/s, max |f_A| = {abs(result.f_A).max():.3g} m/s^2")


app.command("import-motion")(import_motion)
app.command("identify")(identify)
app.command("simulate")(simulate)
app.command()(sweep)


@app.command()
def models() -> None:
    """List the built-in models: name, mechanism, description and parameter file.

    Copy one of the files to describe your own robot, then check it with `chewbot check-model FILE`.

    Example: chewbot models
    """
    from rich.table import Table as RichTable

    from chewbot.model.params import BUILTIN_MODELS, builtin_model_path, load_model

    table = RichTable(title="built-in models")
    for col in ("name", "mechanism", "description"):
        table.add_column(col, overflow="fold")
    for name in BUILTIN_MODELS:
        m = load_model(name)
        table.add_row(name, f"{m.mechanism} ({m.dof} DOF)", m.description)
    stdout.print(table)
    stdout.print("files (copy one to describe your own robot):")
    for name in BUILTIN_MODELS:  # whole lines, so that a path can be copied as it is
        stdout.print(f"  {name}: {builtin_model_path(name)}", highlight=False, markup=False)


@app.command("check-model")
def check_model(
    model: str = typer.Argument(..., help="A TOML parameter file, or the name of a built-in model."),
    set_: list[str] = typer.Option([], "--set", metavar="KEY=VALUE", help=SET_HELP.replace(" or of the default task (task.force_z_N=-100)", "")),
) -> None:
    """Validate a parameter file and print what follows from it.

    Prints the lengths and masses of the chains (couplers: density x area x length), the total moving mass,
    the home pose (theta_i and their largest absolute value, transmission angles), the condyles at home and
    whether they lie on their planes inside the sockets, and the values the file marks as assumed; warns when the
    home pose is near a singularity (a transmission angle or kappa of the chains' Jacobian below its threshold).
    Exit code 2 names the file and the key of the first problem; 3 means the home pose is out of reach.

    Examples:

      chewbot check-model target

      chewbot check-model my_robot.toml

      chewbot check-model target --set chains.crank_length_mm[3]=12
    """
    from chewbot.analysis.checks import KAPPA_MIN, NEAR_SINGULAR_DEG
    from chewbot.model.params import load_model
    from chewbot.report.summary import home_pose

    overrides = _overrides(set_)
    with errors_reported():
        if any(k.startswith("task.") for k in overrides):
            raise ChewbotError("--set task.NAME applies to chewbot run with --task default, not to a model")
        m = load_model(model, overrides)
        home = home_pose(m)
        stdout.print(_model_report(m, home))
    for i, mu in enumerate(home["mu_deg"]):
        if mu < NEAR_SINGULAR_DEG:
            console.print(f"[yellow]warning:[/] chain {i + 1} is near-singular at the home pose: transmission angle "
                          f"{mu:.2f} deg < {NEAR_SINGULAR_DEG:g} deg (docs/conventions.md)", highlight=False)
    if home["kappa"] < KAPPA_MIN:
        console.print(f"[yellow]warning:[/] the home pose is near a singularity: kappa of the chains' Jacobian "
                      f"{home['kappa']:.3g} < {KAPPA_MIN:g} (docs/conventions.md)", highlight=False)


def _model_report(m, home: dict):
    """Tables of a model's derived quantities (SI inside, printed in mm, g and degrees, each with its unit)."""
    import numpy as np
    from rich.console import Group
    from rich.table import Table as RichTable

    from chewbot.report.summary import assumed_values

    theta = np.degrees(home["theta"])
    chains = RichTable(title=escape(f"{m.name}: {m.mechanism}, {m.dof} DOF, {m.source}"), title_justify="left")
    for col in ("chain", "crank [mm]", "coupler [mm]", "coupler mass [g]", "crank mass [g]", "crank inertia [g·mm²]",
                "θ home [deg]", "μ home [deg]"):
        chains.add_column(escape(col), justify="right")  # escaped: rich would take "[mm]" for markup
    for i in range(6):
        chains.add_row(str(i + 1), f"{m.crank_length[i] * 1e3:.4g}", f"{m.coupler_length[i] * 1e3:.4g}", f"{m.coupler_mass[i] * 1e3:.4g}",
                       f"{m.crank_mass[i] * 1e3:.5g}", f"{m.crank_inertia[i] * 1e9:.6g}", f"{theta[i]:.4f}", f"{home['mu_deg'][i]:.2f}")
    couplers, cranks = m.coupler_mass.sum() * 1e3, m.crank_mass.sum() * 1e3
    facts = RichTable(show_header=False, box=None)
    facts.add_column(style="bold")
    facts.add_column()
    facts.add_row("masses", f"couplers {couplers:.4g} g, cranks {cranks:.5g} g, mandible {m.mandible_mass * 1e3:.5g} g; "
                            f"total moving {couplers + cranks + m.mandible_mass * 1e3:.5g} g")
    facts.add_row("home pose", f"max |theta_i| = {np.abs(theta).max():.4f} deg (0 where the printed geometry closes exactly at home); "
                               f"μ_i: transmission angles (90 deg best, 0 at the dead point); kappa of the chains' Jacobian "
                               f"{home['kappa']:.3g} [-] (1 best, 0 singular)")
    h = m.hkp
    for label, T, y_range in (("left condyle T_L", h.T_L, h.y_left), ("right condyle T_R", h.T_R, h.y_right)):
        text = f"({', '.join(f'{v * 1e3:.4g}' for v in T)}) mm in {{S}} at home"
        if m.has_hkp:
            inside = h.x_range[0] <= T[0] <= h.x_range[1] and y_range[0] <= T[1] <= y_range[1]
            text += (f"; plane residual p1 x + z + p2 = {(h.p1 * T[0] + T[2] + h.p2) * 1e3:.3g} mm; "
                     f"{'inside' if inside else 'OUTSIDE'} its socket")
        facts.add_row(label, text)
    for label, p in (("incisor I", m.incisor), ("molars B_L, B_R", np.hstack([m.molar_left, m.molar_right]))):
        facts.add_row(label, ", ".join(f"({', '.join(f'{v * 1e3:.4g}' for v in q)}) mm" for q in p.reshape(-1, 3)) + " in {M}")
    assumed = assumed_values(m)
    facts.add_row("assumed", escape("\n".join(f"{k} = {v}" for k, v in assumed.items())) or "none")
    if m.identified:
        facts.add_row("identified", escape("\n".join(f"{k} = {v}" for k, v in assumed_values(m, m.identified).items())))
    if m.overrides:
        facts.add_row("overrides", escape("\n".join(f"{k} = {v:g}" for k, v in m.overrides.items())))
    return Group(chains, facts, f"[green]valid:[/] {escape(m.source)}")


cache_app = typer.Typer(help="The kernel cache: where the compiled kernels are kept.", no_args_is_help=False,
                        add_completion=False, pretty_exceptions_enable=False)
app.add_typer(cache_app, name="cache")


@cache_app.callback(invoke_without_command=True)
def cache(context: typer.Context) -> None:
    """Print the kernel cache's location, its number of libraries and their size; `chewbot cache clear` empties it.

    The cache is $CHEWBOT_CACHE, else $XDG_CACHE_HOME/chewbot, else ~/.cache/chewbot; its size is capped at
    $CHEWBOT_CACHE_MAX_MB megabytes (default 200), the least recently used libraries removed first.

    Examples:

      chewbot cache

      chewbot cache clear
    """
    if context.invoked_subcommand is not None:
        return
    from chewbot.compiled.kernels import cache_info

    try:
        info = cache_info()
    except (OSError, ValueError) as exc:
        fail(ChewbotError(f"the kernel cache cannot be read: {exc}"), EXIT_OUTPUT)
    stdout.print(f"location: {info['location']}\nlibraries: {info['libraries']}\n"
                 f"size: {info['bytes'] / 1e6:.1f} MB (cap {info['max_bytes'] / 1e6:.0f} MB)", highlight=False, markup=False)


@cache_app.command("clear")
def cache_clear() -> None:
    """Remove chewbot's compiled kernels from the cache (nothing else in the folder); they are compiled again when
    next needed.

    Example:

      chewbot cache clear
    """
    from chewbot.compiled.kernels import cache_root, clear_cache

    try:
        count, size = clear_cache()
    except OSError as exc:
        fail(ChewbotError(f"{cache_root()}: cannot clear the kernel cache ({exc.strerror or exc})"), EXIT_OUTPUT)
    stdout.print(f"removed {count} libraries ({size / 1e6:.1f} MB) from {cache_root()}", highlight=False, markup=False)

