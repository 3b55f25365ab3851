"""The ``chewbot`` command line (typer + rich)."""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer
from rich.console import Console

from chewbot.errors import ChewbotError

app = typer.Typer(
    name="chewbot",
    help="Kinematics, inverse dynamics and inertia coupling of the bio-inspired chewing robot and its 6RSS counterpart.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console(stderr=True)

EXIT_BAD_INPUT = 2  # typer's own usage errors use 2 as well
EXIT_UNREACHABLE = 3


class Side(str, Enum):
    left = "left"
    right = "right"


class Orientation(str, Enum):
    euler_angles = "euler-angles"
    euler_parameters = "euler-parameters"


@app.callback()
def _root() -> None:
    """chewbot: run a chewing task on the robot model and write its results.

    Start with `chewbot run --out runs/default`; see `chewbot COMMAND --help` for each command.
    """


def _fail(exc: Exception, code: int) -> None:
    console.print(f"[bold red]error:[/] {exc}", highlight=False)
    raise typer.Exit(code)


@app.command()
def run(
    model: str = typer.Option("target", "--model", help="Built-in model (target, 6rss, target-as-printed, 6rss-as-printed) or a TOML parameter file."),
    task: str = typer.Option("default", "--task", help="'default' (the synthetic chewing task) or a CSV file."),
    side: Side = typer.Option(Side.left, "--side", help="Molar where the bite force acts, and side of the default task."),
    orientation: Orientation = typer.Option(Orientation.euler_angles, "--orientation", help="Parametrisation of the mandible's orientation."),
    out: Path = typer.Option(Path("runs/default"), "--out", help="Results folder to write."),
    force: bool = typer.Option(False, "--force", help="Replace the results folder if it exists."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Compute the kinematics of a task and write a results folder.

    Writes results.csv (one row per sample, SI units), run.json (model, options, versions, units) and figures.

    Examples:

      chewbot run --out runs/left

      chewbot run --model 6rss --side right --out runs/6rss-right

      chewbot run --task my_chewing.csv --orientation euler-parameters --out runs/mine
    """
    from chewbot.errors import KinematicsError
    from chewbot.pipeline import RunOptions, check_output, compute, write

    options = RunOptions(model=model, task=task, side=side.value, orientation=orientation.value)
    try:
        check_output(out, force)
        with console.status("computing", spinner="dots") if not quiet else _Null() as status:
            result = compute(options, progress=(lambda msg: status.update(msg)) if not quiet else None)
            write(result, out, force=force)
    except KinematicsError as exc:
        _fail(exc, EXIT_UNREACHABLE)
    except ChewbotError as exc:
        _fail(exc, EXIT_BAD_INPUT)
    if not quiet:
        console.print(f"wrote [bold]{out}[/] ({result.table.n} samples, {len(result.table.columns)} columns)")


class _Null:
    def __enter__(self):
        return self

    def __exit__(self, *a):
        return False


def main() -> None:  # pragma: no cover
    app()
