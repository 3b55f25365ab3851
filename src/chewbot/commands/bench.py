"""``chewbot bench``: the timings a user waits for, as Markdown tables."""

from __future__ import annotations

from pathlib import Path

import typer

from chewbot.commands.common import EXIT_BAD_INPUT, FORCE_HELP, errors_reported, fail, flag, progress, stdout
from chewbot.errors import ChewbotError


def bench(
    repeats: int = typer.Option(11, "--repeats", min=3, help="Timed runs per case after the first, interleaved (median and spread reported)."),
    calls: int = typer.Option(20000, "--calls", min=100, help="Calls per in-loop kernel for the one-sample timings."),
    long: bool = flag("--long", help="Also run tasks of 10,000 to 1,000,000 samples with every method: time per "
                      "sample and peak memory (about half an hour)."),
    sweep: int = typer.Option(0, "--sweep", metavar="N", min=0, help="Also time the sweep's scale study (the built-in "
                              "SPEC sobol-scale) with N base samples, a power of 2 (10 N evaluations), in this process and "
                              "on local clusters of 1 and 2 workers, and project the whole study (1,024 base samples)."),
    step_only: bool = flag("--step-only", help="Time only the exported controller step (chewbot export-controller: "
                           "computed torque with minimum-norm and with G1 and friction): median, p99 and maximum per step "
                           "over --passes runs of its log, pinned to one core."),
    passes: int = typer.Option(20, "--passes", min=1, help="Runs of the exported step's log (5001 steps each) for its timing."),
    csv_only: bool = flag("--csv-only", help="Time only reading a task CSV and a robot log of 400,000 rows each "
                          "(seconds per file, microseconds per row), --repeats runs interleaved."),
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

      chewbot bench --step-only --passes 50

      chewbot bench --csv-only --repeats 7
    """
    from chewbot.bench.benchmark import bench_sweep, benchmark, sweep_markdown
    from chewbot.files import WRITTEN_FILE, atomic_file, check_output, marker_line

    if sweep & (sweep - 1):
        fail(ChewbotError(f"--sweep {sweep}: the base samples of a Sobol' study must be a power of 2 (8, 16, 32, ...)"), EXIT_BAD_INPUT)
    with errors_reported():
        if out is not None:
            check_output(out, force, WRITTEN_FILE)  # before the timings, not after them
        with progress(False, "timing") as step:
            if step_only or csv_only:
                from chewbot.bench.benchmark import bench_controller, bench_csv, csv_markdown, load, machine, step_markdown

                started = load()
                table = step_markdown(*bench_controller(passes, progress=step)) if step_only else ""
                table += csv_markdown(bench_csv(repeats=repeats, progress=step)) if csv_only else ""
                text = f"Machine: {machine()}; load average (1, 5, 15 min) {started} at the start, {load()} at the end.\n\n" + table
            else:
                text = benchmark(repeats=repeats, calls=calls, long=long, progress=step)
            if sweep:
                text += sweep_markdown(*bench_sweep(sweep, progress=step))
        stdout.print(text, markup=False, highlight=False)
        if out is not None:
            with atomic_file(out, force) as tmp:
                tmp.write_text(marker_line("<!--", "chewbot bench") + "\n" + text)
