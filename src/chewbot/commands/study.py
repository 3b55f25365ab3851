"""``chewbot study``: a paper's findings reproduced on the default models."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from chewbot.commands.common import EXIT_BAD_INPUT, FORCE_HELP, errors_reported, fail, flag, progress, stdout


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
