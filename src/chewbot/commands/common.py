"""What every chewbot command shares: the exit codes, the handling of SIGINT and SIGTERM, and the entry point.

This module imports nothing but the standard library, so that :func:`main` can take over the signals before
anything heavy is imported. Writing a new command: docs/cli.md ("Writing a new command").

Signals. :func:`main` turns SIGINT (Ctrl-C) and SIGTERM into :class:`Interrupted`, an exception that unwinds
the stack like KeyboardInterrupt: every ``finally`` runs, so :mod:`chewbot.files` removes its temporary
folders and files; then :func:`main` prints one line and exits with 128 + the signal's number (130, 143).
Code that must not be cut in half (renaming an output into place, removing a temporary folder) runs inside
:func:`shield`, which holds a signal back until the block ends. Libraries that catch the exception and turn it
into their own (CasADi's solvers raise a RuntimeError saying "KeyboardInterrupt") still end the same way:
:func:`main` looks at whether a signal arrived, not at the exception's type. Where a library swallows it
altogether, :func:`check_interrupted` (called by each step of the progress display) stops the command at the
next step.
"""

from __future__ import annotations

import os
import signal
import sys
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
_shielded = 0  # depth of shield() blocks
_held = False  # a signal arrived inside a shield() block


def _on_signal(signum: int, frame) -> None:
    global _received, _held
    if _received is None:
        _received = signum
    if _shielded:
        _held = True
        return
    raise Interrupted(signum)


def install_signal_handlers() -> None:
    """SIGINT and SIGTERM raise :class:`Interrupted` from now on (main thread only, as Python requires)."""
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)


def received_signal() -> int | None:
    """The number of the first SIGINT or SIGTERM this process received, or None."""
    return _received


def check_interrupted() -> None:
    """Raise :class:`Interrupted` if a signal arrived, even one a library caught and turned into something else."""
    if _received is not None and not _shielded:
        raise Interrupted(_received)


@contextmanager
def shield():
    """Hold SIGINT and SIGTERM back while the block runs; a signal that arrived meanwhile is raised at its end.

    For the short steps that must not be cut in half: renaming an output into place, removing temporary files.
    """
    global _shielded, _held
    _shielded += 1
    try:
        yield
    finally:
        _shielded -= 1
    if _held and not _shielded:
        _held = False
        raise Interrupted(_received)


def pause_for_tests(stage: str) -> None:
    """Test hook. Where ``$CHEWBOT_TEST_PAUSE`` is ``STAGE:FILE`` and ``stage`` is STAGE, create FILE (holding the
    process id) and wait up to a minute, so that a test can send a signal at this point. Does nothing otherwise.

    Stages: ``import`` (between the entry point and the command's imports), ``dynamics`` (a run's inverse
    dynamics is about to start), ``writing`` (a run's results.csv is written in the temporary folder), ``fit``
    (``identify``'s least squares are about to start), ``chunk`` (a sweep has written a chunk of evaluations to its
    folder).
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


def interrupted_message(signum: int) -> str:
    """The one line printed when a signal ends a command."""
    what = "Ctrl-C" if signum == signal.SIGINT else "a request to terminate"
    return f"interrupted: {signal.Signals(signum).name} ({what}); stopped, no partial output left"


def main(argv: list[str] | None = None) -> int:
    """The ``chewbot`` program: the signal handlers first, then the command line (:mod:`chewbot.cli`).

    Returns the exit code. A signal ends the program with one line on standard error and 128 + its number;
    any other unexpected exception propagates (Python prints its traceback, exit code 1).
    """
    install_signal_handlers()
    try:
        pause_for_tests("import")
        from chewbot.cli import app

        app(args=argv, prog_name="chewbot")  # standalone: ends with SystemExit
        code = EXIT_OK
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (EXIT_OK if exc.code is None else EXIT_BAD_INPUT)
    except BaseException:
        if _received is None:
            raise
        code = EXIT_OK
    if _received is not None:  # whatever the exception became on its way out (or a library swallowed it)
        sys.stderr.write(interrupted_message(_received) + "\n")
        return 128 + _received
    return code
