"""``chewbot models`` and ``chewbot check-model``: the built-in robots, and what follows from a parameter file."""

from __future__ import annotations

import typer
from rich.markup import escape

from chewbot.commands.common import SET_HELP, console, errors_reported, set_overrides, stdout
from chewbot.errors import ChewbotError


def models() -> None:
    """List the built-in models: name, mechanism, description and parameter file.

    Copy one of the files to describe your own robot, then check it with `chewbot check-model FILE`.

    Example: chewbot models
    """
    from rich.table import Table as RichTable

    from chewbot.model.params import BUILTIN_MODELS, builtin_model_path, load_model

    table = RichTable(title="built-in models")
    for col in ("name", "mechanism", "description"):
        table.add_column(col, overflow="fold")
    for name in BUILTIN_MODELS:
        m = load_model(name)
        table.add_row(name, f"{m.mechanism} ({m.dof} DOF)", m.description)
    stdout.print(table)
    stdout.print("files (copy one to describe your own robot):")
    for name in BUILTIN_MODELS:  # whole lines, so that a path can be copied as it is
        stdout.print(f"  {name}: {builtin_model_path(name)}", highlight=False, markup=False)



def check_model(
    model: str = typer.Argument(..., help="A TOML parameter file, or the name of a built-in model."),
    set_: list[str] = typer.Option([], "--set", metavar="KEY=VALUE", help=SET_HELP.replace(" or of the default task (task.force_z_N=-100)", "")),
    min_transmission: float = typer.Option(10.0, "--min-transmission", min=0.0, max=90.0, help="Smallest transmission angle (deg) of an admissible pose in the reachable ranges (as chewbot import-motion's option)."),
) -> None:
    """Validate a parameter file and print what follows from it.

    Prints the lengths and masses of the chains (couplers: density x area x length), the total moving mass,
    the home pose (theta_i and their largest absolute value, transmission angles), the condyles at home and
    whether they lie on their planes inside the sockets, what the robot can play from home (the range of each
    coordinate moved alone, the farthest the incisor point moves along each axis of {S}, each with the constraint
    that ends it; admissible: condyles in their sockets, every transmission angle >= --min-transmission), and the
    values the file marks as assumed; warns when the home pose is near a singularity (a transmission angle or kappa of the chains' Jacobian below its threshold).
    Exit code 2 names the file and the key of the first problem; 3 means the home pose is out of reach.

    Examples:

      chewbot check-model target

      chewbot check-model my_robot.toml

      chewbot check-model target --set chains.crank_length_mm[3]=12
    """
    from chewbot.analysis.checks import KAPPA_MIN, NEAR_SINGULAR_DEG
    from chewbot.model.params import load_model
    from chewbot.report.summary import home_pose

    overrides = set_overrides(set_)
    with errors_reported():
        if any(k.startswith("task.") for k in overrides):
            raise ChewbotError("--set task.NAME applies to chewbot run with --task default, not to a model")
        m = load_model(model, overrides)
        home = home_pose(m)
        stdout.print(_model_report(m, home))
        stdout.print(_reach_report(m, min_transmission))
    for i, mu in enumerate(home["mu_deg"]):
        if mu < NEAR_SINGULAR_DEG:
            console.print(f"[yellow]warning:[/] chain {i + 1} is near-singular at the home pose: transmission angle "
                          f"{mu:.2f} deg < {NEAR_SINGULAR_DEG:g} deg (docs/conventions.md)", highlight=False)
    if home["kappa"] < KAPPA_MIN:
        console.print(f"[yellow]warning:[/] the home pose is near a singularity: kappa of the chains' Jacobian "
                      f"{home['kappa']:.3g} < {KAPPA_MIN:g} (docs/conventions.md)", highlight=False)


def _reach_report(m, min_transmission: float):
    """The reachable ranges from home (:func:`chewbot.recordings.reach.reach`) as a table."""
    from rich.table import Table as RichTable

    from chewbot.recordings.reach import reach

    r = reach(m, min_transmission)
    table = RichTable(title=escape(f"reachable from home (condyles in their sockets, transmission angles >= {min_transmission:g} deg)"),
                      title_justify="left")
    for col in ("coordinate or incisor direction", "low", "high", "limited by (low | high)"):
        table.add_column(escape(col))
    for name, (lo, hi) in r.coordinates.items():
        u = r.units[name]
        table.add_row(escape(f"{name} [{u}] (alone)"), f"{lo:.3f}", f"{hi:.3f}", f"{r.limiting[name + ' low']} | {r.limiting[name + ' high']}")
    for label, distance in r.incisor.items():
        table.add_row(escape(f"incisor I {label} [mm]"), "", f"{distance:.2f}", r.limiting[f"incisor {label}"])
    return table


def _model_report(m, home: dict):
    """Tables of a model's derived quantities (SI inside, printed in mm, g and degrees, each with its unit)."""
    import numpy as np
    from rich.console import Group
    from rich.table import Table as RichTable

    from chewbot.report.summary import assumed_values
    from chewbot.units import factor

    mm, g, g_mm2 = factor("mm"), factor("g"), factor("g*mm^2")
    theta = np.degrees(home["theta"])
    chains = RichTable(title=escape(f"{m.name}: {m.mechanism}, {m.dof} DOF, {m.source}"), title_justify="left")
    for col in ("chain", "crank [mm]", "coupler [mm]", "coupler mass [g]", "crank mass [g]", "crank inertia [g·mm²]",
                "θ home [deg]", "μ home [deg]"):
        chains.add_column(escape(col), justify="right")  # escaped: rich would take "[mm]" for markup
    for i in range(6):
        chains.add_row(str(i + 1), f"{m.crank_length[i] / mm:.4g}", f"{m.coupler_length[i] / mm:.4g}", f"{m.coupler_mass[i] / g:.4g}",
                       f"{m.crank_mass[i] / g:.5g}", f"{m.crank_inertia[i] / g_mm2:.6g}", f"{theta[i]:.4f}", f"{home['mu_deg'][i]:.2f}")
    couplers, cranks = m.coupler_mass.sum() / g, m.crank_mass.sum() / g
    facts = RichTable(show_header=False, box=None)
    facts.add_column(style="bold")
    facts.add_column()
    facts.add_row("masses", f"couplers {couplers:.4g} g, cranks {cranks:.5g} g, mandible {m.mandible_mass / g:.5g} g; "
                            f"total moving {couplers + cranks + m.mandible_mass / g:.5g} g")
    facts.add_row("home pose", f"max |theta_i| = {np.abs(theta).max():.4f} deg (0 where the printed geometry closes exactly at home); "
                               f"μ_i: transmission angles (90 deg best, 0 at the dead point); kappa of the chains' Jacobian "
                               f"{home['kappa']:.3g} [-] (1 best, 0 singular)")
    h = m.hkp
    for label, T, y_range in (("left condyle T_L", h.T_L, h.y_left), ("right condyle T_R", h.T_R, h.y_right)):
        text = f"({', '.join(f'{v / mm:.4g}' for v in T)}) mm in {{S}} at home"
        if m.has_hkp:
            inside = h.x_range[0] <= T[0] <= h.x_range[1] and y_range[0] <= T[1] <= y_range[1]
            text += (f"; plane residual p1 x + z + p2 = {(h.p1 * T[0] + T[2] + h.p2) / mm:.3g} mm; "
                     f"{'inside' if inside else 'OUTSIDE'} its socket")
        facts.add_row(label, text)
    for label, p in (("incisor I", m.incisor), ("molars B_L, B_R", np.hstack([m.molar_left, m.molar_right]))):
        facts.add_row(label, ", ".join(f"({', '.join(f'{v / mm:.4g}' for v in q)}) mm" for q in p.reshape(-1, 3)) + " in {M}")
    assumed = assumed_values(m)
    facts.add_row("assumed", escape("\n".join(f"{k} = {v}" for k, v in assumed.items())) or "none")
    if m.identified:
        facts.add_row("identified", escape("\n".join(f"{k} = {v}" for k, v in assumed_values(m, m.identified).items())))
    if m.overrides:
        facts.add_row("overrides", escape("\n".join(f"{k} = {v:g}" for k, v in m.overrides.items())))
    return Group(chains, facts, f"[green]valid:[/] {escape(m.source)}")
