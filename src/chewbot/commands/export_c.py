"""``chewbot export-c``: the real-time kernels as dependency-free C."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape

from chewbot.commands.common import FORCE_HELP, errors_reported, flag, progress, stdout
from chewbot.errors import ChewbotError


def export_c(
    out: Path = typer.Option(..., "--out", help="Folder to write the C kernels to."),
    target: str = typer.Option("target", "--target-model", help="The target robot's model (built-in name or TOML file)."),
    sixrss: str = typer.Option("6rss", "--6rss-model", help="The 6RSS counterpart's model (built-in name or TOML file)."),
    force: bool = flag("--force", help=FORCE_HELP),
) -> None:
    """Write the real-time kernels as dependency-free C for the robot's controller.

    The folder holds chewbot_kernels.c and .h (plain C99, <math.h> only), a README with each kernel's inputs and
    outputs and their units and the expected outputs on an example sample, example.c (evaluates each kernel on
    that sample; `./example 100000` also times them) and a Makefile. Kernels: minimum-norm torques of the target
    and torques of the 6RSS (lean, and with M_f, C_f, G_f), M_A with MCI, and the friction-aware G1 distribution.

    Example:

      chewbot export-c --out controller/chewbot && make -C controller/chewbot
    """
    from chewbot.export.c import export_c as write_c
    from chewbot.files import EXPORT_FOLDER, check_output
    from chewbot.model.params import load_model
    from chewbot.export.realtime import kernels

    with errors_reported():
        t, s = load_model(target), load_model(sixrss)
        for m, want in ((t, "target"), (s, "6rss")):
            if m.mechanism != want:
                raise ChewbotError(f"{m.source}: mechanism is {m.mechanism!r}, expected {want!r} here")
        inputs = [Path(m.source) for m in (t, s)]
        check_output(out, force, EXPORT_FOLDER, inputs)  # before the kernels are built, not after
        with progress(False, "generating C") as step:
            step("building kernels")
            ks = kernels(t, s)
            step("writing C")
            write_c(ks, out, model_name=f"{t.name} + {s.name}", force=force, inputs=inputs)
    stdout.print(f"wrote {escape(str(out))} ({len(ks)} kernels)", highlight=False)
