"""``chewbot report``: the figures and report.html of a results folder, from what it holds."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from chewbot.commands.common import EXIT_BAD_INPUT, PROGRESS_DELAY_S, errors_reported, fail, flag, progress, stdout
from chewbot.errors import ChewbotError


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
    from chewbot.outputs.writer import redraw

    if no_figures and no_report:
        fail(ChewbotError("--no-figures and --no-report together leave nothing to write"), EXIT_BAD_INPUT)
    with errors_reported():
        with progress(quiet, "report", delay=PROGRESS_DELAY_S) as step:
            written = redraw(folder, force=force, figures=not no_figures, report=not no_report, progress=step)
    if not quiet:
        stdout.print(f"wrote {', '.join(p.name for p in written)} in [bold]{escape(str(folder))}[/]", highlight=False)
