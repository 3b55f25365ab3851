"""``chewbot export-model``: the robot as a model file for another engine (MuJoCo's MJCF)."""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer
from rich.markup import escape

from chewbot.commands.common import FORCE_HELP, errors_reported, flag, stdout
from chewbot.run.options import Switch


class ModelFormat(str, Enum):
    mjcf = "mjcf"


def export_model(
    format_: ModelFormat = typer.Option(ModelFormat.mjcf, "--format", help="The file's format: mjcf (MuJoCo's XML model; SI units: m, kg, s, N, N*m)."),
    model: str = typer.Option("target", "--model", help="Built-in model (target, 6rss, target-as-printed, 6rss-as-printed) or a TOML parameter file."),
    friction: Switch = typer.Option(Switch.on, "--friction", help="on: Coulomb friction (coefficient hkp.coulomb) at the condyles' contacts and viscous damping (N*m*s/rad) at the cranks' hinges; off: frictionless contacts, undamped hinges."),
    out: Path = typer.Option(Path("robot.xml"), "--out", help="The model file to write."),
    force: bool = flag("--force", help=FORCE_HELP),
) -> None:
    """Write the robot as a MuJoCo model (MJCF) for an independent engine.

    The mandible (a free body), the six cranks (hinges, motors crank1..crank6: torque in N*m, gear 1) and
    couplers (universal joint at the crank tip) with the model's masses and inertias, the six loops closed by
    connect equality constraints at M_i, the condyles as spheres pressed on their socket planes (unilateral
    contacts), a site O_M at the mandible's origin; gravity -g along z, SI units. The solver settings make the
    constraints stiff (docs/mujoco.md says which and what the file leaves out: the sockets' x, y bounds, the HKP
    viscous friction, the load-dependent actuator friction). `chewbot simulate --plant-engine mujoco` runs the
    controllers against MuJoCo's simulation of the same model.

    Examples:

      chewbot export-model --format mjcf --model target --out robot.xml

      chewbot export-model --model 6rss --friction off --out sixrss.xml

      python -m mujoco.viewer --mjcf=robot.xml
    """
    from chewbot.export.mjcf import write_mjcf
    from chewbot.model.params import load_model

    with errors_reported():
        m = load_model(model)
        write_mjcf(m, out, friction=friction == Switch.on, force=force, inputs=[Path(m.source)])
    stdout.print(f"wrote {escape(str(out))} ({format_.value}, the {escape(m.name)} model, friction {friction.value})", highlight=False)
