"""``chewbot fit-comminution``: measured sievings in, the food file with its selection and breakage fitted out.

The command's options and file; the work is :func:`chewbot.food.comminution_fit.fit_comminution`. The food file is
written whole through :func:`chewbot.files.atomic_file`, beginning with chewbot's marker line; an existing file is
replaced only with ``--force`` and only if chewbot wrote it. Exit codes and signals as every command (docs/cli.md):
4 where a validity check of the fit failed (the file is written all the same).
"""

from __future__ import annotations

import shlex
from pathlib import Path

import typer

from chewbot.commands.common import FORCE_HELP, check_interrupted, errors_reported, exit_after_checks, flag, progress, stdout
from chewbot.food import CLOSING_FORCE_N, MIN_GAP_MM


def fit_comminution(
    sieving: Path = typer.Argument(..., help="The measured distributions (CSV): chews [1], sieve [mm] (5.6, 4, 2.8, 2, 1.4, 1, 0.71, 0.5 and 0 for the pan), mass_fraction [1], optional subject; one row per sieve (docs/bolus.md)."),
    food: str = typer.Option(..., "--food", help="The food whose [comminution] table is fitted and whose other values are kept: a built-in food (peanut, carrot) or a TOML food file, e.g. --food peanut."),
    out: Path = typer.Option(..., "--out", help="The food file to write (TOML), e.g. --out peanut-fitted.toml: the food with the fitted values in place and their keys in comminution.fitted."),
    fit: list[str] = typer.Option([], "--fit", metavar="KEY", help="A [comminution] key to fit (placement, relief_mm, relief_exponent, strength_at_1mm_MPa, weibull_modulus, fragment_size, fragment_spread), e.g. --fit fragment_spread; repeatable. Default: placement, strength_at_1mm_MPa, fragment_size."),
    closing_force: float = typer.Option(CLOSING_FORCE_N, "--closing-force", min=0.0, help="The ideal stroke closes until the bed pushes back with this force (N), e.g. --closing-force 80 ..."),
    min_gap: float = typer.Option(MIN_GAP_MM, "--min-gap", min=0.0, help="... or until the teeth are this close (mm), e.g. --min-gap 0.2, whichever comes first."),
    force: bool = flag("--force", help=FORCE_HELP),
    allow_violations: bool = flag("--allow-violations", help="Exit 0 even when a validity check of the fit fails (the checks are still printed and written)."),
    quiet: bool = flag("--quiet", "-q", help="Print nothing but errors and the checks that fail."),
) -> None:
    """Fit a food's selection and breakage to sievings of boluses chewed a given number of times.

    The food's ideal chewing (strokes closing on the particle bed to --closing-force or --min-gap) predicts the mass
    fractions on the sieves after each measured number of chews; bounded least squares with the exact Jacobian
    adjust the keys of --fit. Prints each fitted key with its standard error, the measured and fitted X50 and b of
    every distribution and the validity checks (the fit converged; the fitted food conserves the bolus's mass and
    its X50 never rises; a key at the bound of its plausible range warns); writes the food file with the values in
    place.

    Examples:

      chewbot fit-comminution examples/peanut_sieving.csv --food peanut --out peanut-fitted.toml

      chewbot fit-comminution examples/peanut_sieving.csv --food peanut --fit placement --fit fragment_spread --out peanut-2.toml
    """
    from chewbot.files import WRITTEN_FILE, atomic_file, check_output, marker_line
    from chewbot.food.bolus import comminution_of
    from chewbot.food.comminution_fit import DEFAULT_KEYS, fit_checks, fit_comminution as run_fit, fitted_food_text, read_sieving
    from chewbot.food.law import load_food
    from chewbot.units import factor

    mm = factor("mm")

    with errors_reported():
        f = load_food(food)
        table = comminution_of(f)
        inputs = [sieving, Path(f.source)]
        check_output(out, force, WRITTEN_FILE, inputs)  # before the work, not after it
        data = read_sieving(sieving)
        keys = tuple(fit) or DEFAULT_KEYS
        with progress(quiet, "fit-comminution", total=3) as step:
            step("fitting", stage="fit")
            result = run_fit(table, data, keys, closing_force, min_gap * mm, progress=step, check=check_interrupted)
            step("checking")
            checks = fit_checks(result, max(data.counts), closing_force, min_gap * mm)
            step("writing", stage="writing")
        args = [str(sieving), "--food", food, "--out", str(out), *[a for key in keys for a in ("--fit", key)],
                "--closing-force", f"{closing_force:g}", "--min-gap", f"{min_gap:g}"]
        about = f"chewbot fit-comminution {shlex.join(args)}"
        header = [marker_line("#", f"the food {f.source} with [comminution] fitted by {about}"),
                  f"# residual RMS of the mass fractions {result.rms:.4g} ({result.dof} degrees of freedom)",
                  *[f"# check {c.name}: {'passed' if c.passed else 'FAILED'}: {c.message}" for c in checks]]
        text = fitted_food_text(Path(f.source).read_text("utf-8"), result, header)
        with atomic_file(out, force, inputs) as tmp:
            tmp.write_text(text, encoding="utf-8")
    if not quiet:
        _print(result, data)
        stdout.print(f"wrote {out}; residual RMS of the fractions {result.rms:.3g} ({result.dof} degrees of freedom)",
                     highlight=False, markup=False)
    exit_after_checks(checks, allow_violations, quiet)


def _print(result, data) -> None:
    from rich import box
    from rich.markup import escape
    from rich.table import Table as RichTable

    from chewbot.food.sieving import fit_rosin_rammler

    table = RichTable(title="fitted \\[comminution] keys (file units)", title_justify="left", box=box.SIMPLE_HEAD)
    for col, justify in (("key", "left"), ("estimate", "right"), ("standard error", "right"), ("start", "right"), ("unit", "left")):
        table.add_column(col, justify=justify)
    for row in result.rows():
        table.add_row(escape(row["key"]), f"{row['estimate']:.6g}", f"{row['standard_error']:.3g}", f"{row['start']:.6g}",
                      escape(row["unit"]))
    stdout.print(table)
    fits = RichTable(title="the distributions: measured and fitted Rosin-Rammler X50 and b", title_justify="left",
                     box=box.SIMPLE_HEAD)
    for col in ("subject", "chews", "X50 [mm] measured", "fitted", "b [1] measured", "fitted"):
        fits.add_column(col, justify="left" if col == "subject" else "right")
    for subject, n, measured, fitted in zip(data.subjects, data.chews, result.measured, result.fitted):
        a, b = fit_rosin_rammler(measured), fit_rosin_rammler(fitted)
        fits.add_row(escape(subject or "-"), str(int(n)), f"{a.x50_mm:.3g}", f"{b.x50_mm:.3g}", f"{a.b:.3g}", f"{b.b:.3g}")
    stdout.print(fits)
