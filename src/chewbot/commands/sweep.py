"""``chewbot sweep``: the command's options, progress bar and summary; the work is :func:`chewbot.outputs.sweep.run_sweep`."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import typer


def sweep(
    spec: str = typer.Argument(..., help="The SPEC: a TOML file (docs/sweeps.md) or the name of a built-in SPEC "
                               "(finding5, finding5-search, sobol-scale, workspace)."),
    out: Path = typer.Option(..., "--out", help="Sweep folder to write: run.json, chunks/ while it runs, samples.parquet, "
                             "the indices or the optimum (CSV), report.html."),
    scheduler: str | None = typer.Option(None, "--scheduler", metavar="ADDRESS", help="An existing Dask scheduler, "
                                          "tcp://HOST:PORT, to run on (default: a local cluster of this machine's cores)."),
    workers: int | None = typer.Option(None, "--workers", min=1, show_default=False, help="Worker processes of the local "
                                       "cluster (default: one per core)."),
    resume: bool = typer.Option(False, "--resume", help="Continue the interrupted sweep in --out: its finished chunks are "
                                "read back, not computed again (the SPEC must be the same)."),
    force: bool = typer.Option(False, "--force", help="Replace --out if it is a sweep folder chewbot wrote (anything else "
                               "is never replaced)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Evaluate the model many times on Dask: Monte Carlo, Sobol' sensitivity, grids (maps of the workspace,
    singularities and force capability) and design optimisation.

    The SPEC names the kind, the model, task and method, the parameters that vary (keys as in chewbot run --set)
    and the outputs (peak_tau_Nm, mean_MCI, feasible, ...). Work is sent to the cluster in chunks; each finished
    chunk is written to --out/chunks/ as it arrives, and run.json says the sweep is incomplete until it ends, so an
    interrupted sweep keeps its finished chunks and --resume continues it. A failed evaluation is a row of NaN
    outputs with its reason in the error column; the command still exits 0.

    Examples:

      chewbot sweep my_study.toml --out runs/study

      chewbot sweep finding5 --out runs/finding5 --workers 2

      chewbot sweep my_study.toml --out runs/study --resume

      chewbot sweep my_study.toml --out runs/study --scheduler tcp://10.0.0.5:8786
    """
    import shlex

    from chewbot.commands.common import EXIT_BAD_INPUT, check_interrupted, errors_reported, fail, keep_on_interrupt, progress, stdout
    from chewbot.errors import ChewbotError
    from chewbot.outputs.sweep import run_sweep

    if resume and force:
        fail(ChewbotError("--resume continues a sweep, --force starts it over: give one of them"), EXIT_BAD_INPUT)
    if scheduler is not None and workers is not None:
        fail(ChewbotError("--workers sizes the local cluster; with --scheduler the cluster has its own workers"), EXIT_BAD_INPUT)
    again = ["chewbot", "sweep", str(spec), "--out", str(out), "--resume"] + (["--scheduler", scheduler] if scheduler else [])
    keep_on_interrupt(f"the chunks finished so far are kept in {out} (nothing half-written): {shlex.join(again)} continues")
    with errors_reported():
        with progress(quiet, "sweep") as step, _evaluations(quiet, step) as told:
            result = run_sweep(spec, out, scheduler=scheduler, workers=workers, resume=resume, force=force,
                               progress=told, check=check_interrupted)
    if not quiet:
        _print_summary(stdout, result)


@contextmanager
def _evaluations(quiet: bool, step):
    """The sweep's progress: its stages as ``step`` (the command's progress display) shows them, and on a terminal the
    evaluations done (``done`` given) on a bar of their own with the rate and the time left."""
    from chewbot.commands.common import check_interrupted, console, pause_for_tests

    if quiet or not console.is_terminal:
        yield step
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    rate = TextColumn("{task.fields[rate]}")
    with Progress(TextColumn("evaluations"), BarColumn(), MofNCompleteColumn(), TaskProgressColumn(), rate,
                  TimeElapsedColumn(), TimeRemainingColumn(), console=console, transient=True) as p:
        task = p.add_task("evaluations", total=None, rate="")

        def told(message: str, done: int | None = None, total: int | None = None, stage: str | None = None) -> None:
            if done is None:
                step(message, total=total, stage=stage)
                return
            check_interrupted()
            if stage:
                pause_for_tests(stage)
            speed = p.tasks[0].speed
            p.update(task, completed=done, total=total, rate=f"{speed:.1f}/s" if speed else "")

        yield told


def _print_summary(stdout, result) -> None:
    from rich.markup import escape

    from chewbot.sweep.record import REPORT_FILE

    spec = result.spec
    rate = f", {result.computed / result.elapsed_s:.1f} evaluations/s" if result.computed and result.elapsed_s else ""
    stdout.print(f"wrote [bold]{escape(str(result.folder))}[/]: {result.evaluations} evaluations, {result.failed} failed "
                 f"(reasons in the error column); {result.computed} computed in {result.elapsed_s:.1f} s{rate}"
                 + (f", {result.reused_chunks} chunk(s) read back" if result.reused_chunks else "")
                 + f"; open {escape(str(result.folder / REPORT_FILE))}", highlight=False)
    for name, ind in result.indices.items():
        order = sorted(range(len(spec.keys)), key=lambda j: -(ind["ST"][j] if ind["ST"][j] == ind["ST"][j] else -1))
        parts = ", ".join(f"{spec.keys[j]} {ind['ST'][j]:.2f}±{ind['ST_conf'][j]:.2f}" for j in order[:4])
        stdout.print(escape(f"{name}: total Sobol' indices {parts}"), highlight=False)
    if result.optimum is not None:
        o = result.optimum
        values = ", ".join(f"{k} = {v:.5g}" for k, v in o["parameters"].items())
        stdout.print(escape(f"optimum: {spec.minimize} = {o['outputs'][spec.minimize]:.5g} at {values} "
                            f"({'constraints met' if o['constraints_met'] else 'constraints NOT met'}; sample {o['sample']})"), highlight=False)
