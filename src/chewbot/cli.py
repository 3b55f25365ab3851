"""The ``chewbot`` command line: the typer app, assembled from the commands of :mod:`chewbot.commands`.

Every command follows the same rules (docs/cli.md): exit codes, signals, errors and progress
(:mod:`chewbot.commands.common`), outputs written whole and never over what chewbot did not write
(:mod:`chewbot.files`). A command is a function in a module of its own under :mod:`chewbot.commands`; this module
only names it.
"""

from __future__ import annotations

import typer

from chewbot.commands import bench, cache, chew, estimate_force, excite, export_c, export_controller, export_model, fit_comminution, identify, import_motion, models, report, run, simulate, study, sweep, tpa, track_incisor
from chewbot.commands.common import stdout

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


def _flags_without_a_type() -> None:
    """Show boolean flags as flags in help (``--force``), not with the ``<bool>`` type that typer 0.2x prints
    beside them (a value they do not take). Older typer versions have no such type column: nothing to do."""
    from typer.core import TyperOption

    shown = getattr(TyperOption, "display_type_rich", None)
    if shown is not None:
        TyperOption.display_type_rich = lambda self, ctx: None if self.is_flag else shown(self, ctx)


_flags_without_a_type()


def _version(value: bool) -> None:
    if value:
        from chewbot.files import VERSION

        stdout.print(f"chewbot {VERSION}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version and exit.")) -> None:
    """chewbot: run a chewing task on the robot model and write its results.

    Start with `chewbot run --out runs/default`; see `chewbot COMMAND --help` for each command.
    """


app.command("run")(run.run)
app.command("report")(report.report_command)
app.command("bench")(bench.bench)
app.command("export-c")(export_c.export_c)
app.command("export-controller")(export_controller.export_controller)
app.command("export-model")(export_model.export_model)
app.command("study")(study.study)
app.command("track-incisor")(track_incisor.track_incisor)
app.command("import-motion")(import_motion.import_motion)
app.command("excite")(excite.excite)
app.command("identify")(identify.identify)
app.command("estimate-force")(estimate_force.estimate_force)
app.command("tpa")(tpa.tpa)
app.command("fit-comminution")(fit_comminution.fit_comminution)
app.command("chew")(chew.chew)
app.command("simulate")(simulate.simulate)
app.command("sweep")(sweep.sweep)
app.command("models")(models.models)
app.command("check-model")(models.check_model)
app.add_typer(cache.cache_app, name="cache")
