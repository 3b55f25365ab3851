"""What every chewbot command shares: the exit codes, the handling of SIGINT and SIGTERM, the consoles, errors
and progress display, ``--set`` parsing and the test pause hook.

This module imports nothing but the standard library at its top (rich, typer and chewbot's modules inside the
functions that use them), so that the entry point (:func:`chewbot.__main__.main`) can take over the signals before
anything heavy is imported. Writing a new command: docs/cli.md ("Writing a new command").

Signals. :func:`chewbot.__main__.main` turns SIGINT (Ctrl-C) and SIGTERM into :class:`Interrupted`, an exception that unwinds
the stack like KeyboardInterrupt: every ``finally`` runs, so :mod:`chewbot.files` removes its temporary
folders and files; then the entry point prints one line and exits with 128 + the signal's number (130, 143).
Code that must not be cut in half (renaming an output into place, removing a temporary folder) runs inside
:func:`chewbot.files.shield`, which holds a signal back until the block ends. Libraries that catch the exception and turn it
into their own (CasADi's solvers raise a RuntimeError saying "KeyboardInterrupt") still end the same way:
the entry point looks at whether a signal arrived, not at the exception's type. Where a library swallows it
altogether, :func:`check_interrupted` (called by each step of the progress display, and passed down as ``check``
to the loops that call such libraries) stops the command there.
"""

from __future__ import annotations

import os
import signal
import time
from contextlib import contextmanager

# Exit codes (docs/cli.md), the same for every command. 1 is left to Python: a bug, printed with its traceback.
EXIT_OK = 0
EXIT_BAD_INPUT = 2  # bad parameter file, task, option or missing file; the command line's own usage errors too
EXIT_UNREACHABLE = 3  # a pose of the task is out of reach, outside the sockets or singular
EXIT_CHECK_FAILED = 4  # results written; a validity check failed (chewbot.analysis.checks)
EXIT_OUTPUT = 5  # the output exists (and --force was not given, or chewbot did not write it) or cannot be written
EXIT_INTERRUPTED = 128 + signal.SIGINT  # 130
EXIT_TERMINATED = 128 + signal.SIGTERM  # 143

# Test hook: CHEWBOT_TEST_PAUSE=STAGE:FILE makes the command create FILE and wait when it reaches STAGE
# (see pause_for_tests), so that a test can send a signal at a known point.
TEST_PAUSE_VARIABLE = "CHEWBOT_TEST_PAUSE"
TEST_PAUSE_S = 60.0


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived. A BaseException, like KeyboardInterrupt: no ``except Exception`` stops it."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


_received: int | None = None  # the first signal that arrived


def _on_signal(signum: int, frame) -> None:
    global _received
    if _received is None:
        _received = signum
    raise Interrupted(signum)


def install_signal_handlers() -> None:
    """SIGINT and SIGTERM raise :class:`Interrupted` from now on (main thread only, as Python requires)."""
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)


def received_signal() -> int | None:
    """The number of the first SIGINT or SIGTERM this process received, or None."""
    return _received


def check_interrupted() -> None:
    """Raise :class:`Interrupted` if a signal arrived, even one a library caught and turned into something else.

    The loops of the lower layers are given this function (their ``check`` argument) where a library may swallow a
    signal: they know nothing of the command line."""
    if _received is not None:
        raise Interrupted(_received)


def pause_for_tests(stage: str) -> None:
    """Test hook. Where ``$CHEWBOT_TEST_PAUSE`` is ``STAGE:FILE`` and ``stage`` is STAGE, create FILE (holding the
    process id) and wait up to a minute, so that a test can send a signal at this point. Does nothing otherwise.

    Stages: ``import`` (between the entry point and the command's imports), ``dynamics`` (a run's inverse
    dynamics is about to start), ``writing`` (a run's results.csv is written in the temporary folder), ``fit``
    (``identify``'s least squares are about to start), ``chunk`` (a sweep has written a chunk of evaluations to its
    folder), ``simulation`` (a simulation's loop is about to start). The lower layers name a stage in their progress
    callback (``step(message, stage="dynamics")``), which calls this.
    """
    spec = os.environ.get(TEST_PAUSE_VARIABLE, "")
    name, _, flag = spec.partition(":")
    if name != stage or not flag:
        return
    with open(flag, "w") as f:
        f.write(str(os.getpid()))
    deadline = time.monotonic() + TEST_PAUSE_S
    while time.monotonic() < deadline:
        time.sleep(0.02)


_kept: str | None = None  # what a command keeps when a signal stops it (a sweep's chunks), set by the command


def keep_on_interrupt(note: str) -> None:
    """Say what an interruption leaves behind on purpose from now on (a sweep's finished chunks, for --resume): the
    interrupted message names it instead of "no partial output left"."""
    global _kept
    _kept = note


def interrupted_message(signum: int) -> str:
    """The one line printed when a signal ends a command."""
    what = "Ctrl-C" if signum == signal.SIGINT else "a request to terminate"
    return f"interrupted: {signal.Signals(signum).name} ({what}); stopped, {_kept or 'no partial output left'}"


# --- what a command prints and how it ends ----------------------------------------------------------------------

PROGRESS_DELAY_S = 1.0  # a run shows its progress bar once it has taken this long
PROGRESS_LINE_S = 10.0  # in a log, a stage that goes on this long gets a line with its latest detail
FORCE_HELP = "Replace the output if it exists and chewbot wrote it (anything else is never replaced)."
SET_HELP = ("Override one number of the model (a parameter-file key in the file's units, 1-based indices: "
            "friction.hkp_coulomb=0.2, chains.crank_length_mm[3]=12, chains.G_mm[2][1]=24) or of the default task "
            "(task.force_z_N=-100); repeatable. Values that follow from it stay consistent (docs/models.md).")

_CONSOLES: dict = {}


def _console(name: str = "console"):
    if name not in _CONSOLES:
        from rich.console import Console

        _CONSOLES[name] = Console(stderr=name == "console", soft_wrap=True)  # paths unwrapped
    return _CONSOLES[name]


def __getattr__(name: str):
    """``console`` (standard error: progress, warnings, errors) and ``stdout`` (results, for scripts): rich consoles,
    made on first use so that the entry point imports nothing heavy before it takes over the signals."""
    if name in ("console", "stdout"):
        return _console(name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def flag(*names: str, help: str) -> bool:
    """A boolean option that is off unless given (``--force``)."""
    import typer

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
    import typer
    from rich.markup import escape

    _console().print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)  # unwrapped: paths stay whole
    raise typer.Exit(exit_code(exc) if code is None else code)


@contextmanager
def errors_reported():
    """Turn the errors chewbot raises on purpose into one line on standard error and their exit code."""
    from chewbot.errors import ChewbotError

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
        failed = [c for c in checks if c.passed is False]
    if failed:
        from rich import box
        from rich.markup import escape
        from rich.table import Table as RichTable

        table = RichTable(title="failed validity checks (details: run.json, \"checks\", and report.html)", title_justify="left",
                          box=box.SIMPLE_HEAD, pad_edge=False)
        for col, justify in (("check", "left"), ("counts as", "left"), ("samples", "right"), ("first at t [s]", "right"), ("worst", "right")):
            table.add_column(escape(col), justify=justify, no_wrap=True)
        for c in failed:
            worst = "" if c.worst is None else f"{c.worst['value']:.4g} {c.worst['unit']}"
            first = "" if c.first_sample is None else f"{c.first_sample['t']:.4g}"
            table.add_row(c.name, "failure" if c.fails_run else "warning", str(c.samples), first, escape(worst))
        _console().print(table)
    if stops:
        import typer

        raise typer.Exit(EXIT_CHECK_FAILED)
    if run_fails(checks) and not quiet:
        _console().print("[yellow]warning:[/] a validity check failed; exit code 0 because of --allow-violations", highlight=False)


def options_line(options: dict) -> str:
    """The options a computation actually used, from its run.json's ``"options"``: method (and the orientation it is
    computed in), goal, friction, contact; a default that another option switched (the method of
    ``--orientation euler-parameters``) is visible in every run's console summary."""
    parts = [f"method {options.get('method') or 'none (kinematics only)'}"]
    if options.get("orientation"):
        parts[0] += f" ({options['orientation']})"
    parts.append(f"goal {options.get('goal') or 'none (minimum-norm torques)'}")
    parts.append(f"friction {options.get('friction') or 'none (frictionless formulation)'}")
    parts.append(f"contact {options.get('contact', 'bilateral')}")
    return "used: " + ", ".join(parts)


@contextmanager
def resolved():
    """Report the run options that do not apply (:class:`chewbot.run.options.OptionError`) as the command line's
    options (``--goal and --friction apply to ...``), exit 2; other errors as :func:`errors_reported`."""
    from chewbot.errors import ChewbotError
    from chewbot.run.options import OptionError

    with errors_reported():
        try:
            yield
        except OptionError as exc:
            fail(ChewbotError(exc.worded(lambda option: f"--{option}")), EXIT_BAD_INPUT)


def set_overrides(arguments: list[str], option: str = "--set") -> dict[str, float]:
    """``--set KEY=VALUE`` arguments (or those of ``option``) as a dict, in order (a key given twice: the last
    value); exit 2 on a bad one (not a number, NaN, infinite)."""
    from chewbot.model.params import parse_override

    with errors_reported():
        return dict(parse_override(a, option) for a in arguments)


def _checked(stage: str | None) -> None:
    """What every step of a progress display does first: stop if a signal arrived, pause at a named stage for tests."""
    check_interrupted()
    if stage:
        pause_for_tests(stage)


@contextmanager
def progress(quiet: bool, label: str, total: int | None = None, delay: float = 0.0):
    """The command's progress display, a :class:`chewbot.progress.Progress`: on a terminal a bar that names the
    current step; where standard error is not a terminal (a pipe, a log) one line per stage, ``LABEL: message (12.3
    s)``, the seconds since the command started (and, in a stage that goes on, its latest detail every
    :data:`PROGRESS_LINE_S` at most); nothing with --quiet.

    The yielded callback ``step(message, done=None, total=None, stage=None)`` starts a step: with ``done`` the bar
    shows that many units of ``total`` done (samples of a run; from then on a step without ``done``, such as the
    kernels compiled or the report, leaves the count as it is), else it advances by one step of ``total`` (the number
    of steps, if known; otherwise it pulses), except where the message begins with the same words before its first
    colon as the one before (``least squares: evaluation 12, cost ...`` after ``least squares: 11 parameters``): that
    updates the step's description, the step goes on, and no new line is printed. ``delay``: the bar (or the first
    line) appears only once the command has run that many seconds (a short run shows none). Each step also stops the
    command if a signal arrived that a library swallowed (:func:`check_interrupted`), and a step that names its
    ``stage`` is where the test hook may pause (:func:`pause_for_tests`)."""
    import time

    start, shown, started, previous, printed, counting = time.monotonic(), False, False, None, 0.0, False
    if quiet:
        def quiet_step(msg: str, done: int | None = None, total: int | None = None, stage: str | None = None) -> None:
            _checked(stage)

        yield quiet_step
        return
    if not _console().is_terminal:
        def line_step(msg: str, done: int | None = None, total: int | None = None, stage: str | None = None) -> None:
            nonlocal shown, previous, printed
            _checked(stage)
            head, elapsed = msg.split(":", 1)[0], time.monotonic() - start
            if elapsed >= delay and (head != previous or not shown or (elapsed - printed >= PROGRESS_LINE_S and head != msg)):
                _console().print(f"{label}: {msg} ({elapsed:.1f} s)", markup=False, highlight=False)
                shown, printed = True, elapsed
            previous = head

        yield line_step
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    bar = Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                   console=_console(), transient=True)
    task = bar.add_task(label, total=total)

    def step(msg: str, done: int | None = None, total: int | None = None, stage: str | None = None) -> None:
        nonlocal shown, started, previous, counting
        _checked(stage)
        if total is not None:
            bar.update(task, total=total)
        head = msg.split(":", 1)[0]
        counting = counting or done is not None
        if done is not None:
            bar.update(task, description=f"{label}: {msg}", completed=done)
        else:
            bar.update(task, description=f"{label}: {msg}", advance=1 if started and head != previous and not counting else 0)
        started, previous = True, head
        if not shown and time.monotonic() - start >= delay:
            bar.start()
            shown = True

    try:
        yield step
    finally:
        bar.stop()

