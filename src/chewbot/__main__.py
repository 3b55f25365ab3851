"""The ``chewbot`` program (``python -m chewbot`` and the installed ``chewbot`` script): the signal handlers
first, then the command line (:mod:`chewbot.cli`)."""

from __future__ import annotations

import sys

from chewbot.commands.common import EXIT_BAD_INPUT, EXIT_OK, install_signal_handlers, interrupted_message, pause_for_tests, received_signal


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
        if received_signal() is None:
            raise
        code = EXIT_OK
    signum = received_signal()
    if signum is not None:  # whatever the exception became on its way out (or a library swallowed it)
        sys.stderr.write(interrupted_message(signum) + "\n")
        return 128 + signum
    return code


if __name__ == "__main__":
    sys.exit(main())
