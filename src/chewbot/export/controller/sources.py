"""The library's files from the templates in ``templates/``: the header, the hand-written step, the task table, the
README (rendered), the Makefile and the example (copied), and the graphs as C (CasADi's code generator, post-processed
by :func:`strict_c`).

The templates are rendered with the standard library's :class:`string.Template` (``$name``): C and Markdown are full
of braces, which ``str.format`` would need doubled, while ``$`` occurs in neither the C sources nor the README (the
Makefile, whose ``$(CC)`` would, is copied as it is); :func:`render` refuses a placeholder left unfilled and a value
that fills nothing.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from string import Template

import casadi as ca
import numpy as np

from chewbot.export.controller.layout import c_typedefs
from chewbot.export.controller.step import (
    CONDITIONING_MIN, DISTRIBUTION_STEP_TOLERANCE, EXPORT_FORMAT, FK_RESIDUAL_TOLERANCE, FK_STEP_TOLERANCE, MAX_HOLD_TICKS, PREFIX,
    STATUS, STATUS_BITS, TRANSMISSION_MIN, WATCHDOG_PERIODS, StepSpec, drive_config, drive_function, fk_function, home_angles,
    law_function)
from chewbot.files import EXPORT_FOLDER, VERSION, atomic_folder, to_json
from chewbot.simulation.controllers.table import controller_row
from chewbot.simulation.reference import HERMITE_COEFFICIENTS as HERMITE
from chewbot.simulation.sensor import FK_ITERATIONS


def template(name: str) -> str:
    """The text of the template file ``name`` (package data in ``templates/``)."""
    return resources.files(__package__).joinpath("templates", name).read_text("utf-8")


def render(name: str, **values) -> str:
    """The template ``name`` with its placeholders filled in by ``values``: each placeholder given, each value used."""
    text = Template(template(name))
    unused = sorted(set(values) - set(text.get_identifiers()))
    if unused:
        raise ValueError(f"the template {name} has no placeholder for {', '.join(unused)}")
    return text.substitute(values)


# The flags the library must compile with, warning-free: the Makefile's CFLAGS (tested).
STRICT_FLAGS = tuple(re.search(r"^CFLAGS \?= (.*)$", template("Makefile"), re.M).group(1).split())

_FUNCTION = re.compile(r"^(?:[A-Za-z_][\w\s\*]*?)\b([A-Za-z_]\w*)\(([^()]*)\)\s*\{", re.M)


def strict_c(code: str) -> str:
    """CasADi's generated C made to compile with :data:`STRICT_FLAGS`: every parameter of every function is cast to
    void at its start (the generated functions leave some unused), and its one non-static helper made static."""
    def casts(match: re.Match) -> str:
        names = []
        for param in match.group(2).split(","):
            tokens = re.findall(r"[A-Za-z_]\w*", param)
            if tokens and tokens != ["void"]:
                names.append(tokens[-1])
        return match.group(0) + "".join(f" (void){name};" for name in names)

    code = _FUNCTION.sub(casts, code)
    return re.sub(r"^casadi_real casadi_(\w+)\(", r"static casadi_real casadi_\1(", code, flags=re.M)


def _array(values) -> str:
    return ", ".join(repr(float(v)) for v in np.ravel(values))


def coordinate_names(spec: StepSpec) -> list[str]:
    return ["X", "Y", "alpha", "beta"] if spec.model.has_hkp else ["X", "Y", "Z", "alpha", "beta", "gamma"]


def gain_description(spec: StepSpec) -> str:
    """The gains vector in words: its controller's gains section's (:mod:`chewbot.simulation.controllers`)."""
    return controller_row(spec.kind).module().Gains.VECTOR


def dimensions(spec: StepSpec, fk: ca.Function, law: ca.Function) -> dict[str, int]:
    """The header's dimensions (``CHEWBOT_CTRL_NQ``, ...) by name: the lengths of the context's arrays and the task's."""
    n, graphs = spec.n, (fk, law, drive_function())
    return {"NQ": n, "NN": max(spec.n_normal, 1), "NG": len(spec.gains), "TASK_ROWS": len(spec.t), "TASK_COLUMNS": 1 + 3 * n + 3,
            "WORK_ARG": max(g.sz_arg() for g in graphs), "WORK_RES": max(g.sz_res() for g in graphs),
            "WORK_IW": max(*(g.sz_iw() for g in graphs), 1), "WORK_W": max(*(g.sz_w() for g in graphs), 1)}


def filled(spec: StepSpec) -> Mapping[str, str]:
    """What fills the placeholders of the context table's meanings (:mod:`chewbot.export.controller.layout`)."""
    return {"gains": gain_description(spec)}


def header(spec: StepSpec, fk: ca.Function, law: ca.Function) -> str:
    return render("chewbot_ctrl.h", version=VERSION, model=spec.model.name, mechanism=spec.model.mechanism,
                  law=f"{spec.kind}{' with ' + spec.method if spec.uses_inverse_dynamics else ''}", coordinates=", ".join(coordinate_names(spec)),
                  status_bits="\n".join(f"#define CHEWBOT_CTRL_{name} 0x{value:04x}u" for name, value in STATUS_BITS.items()),
                  structs=c_typedefs(filled(spec)), **dimensions(spec, fk, law))


def step_source(spec: StepSpec) -> str:
    model = spec.model
    drive = {f"DRIVE_{name.upper()}": repr(float(value)) for name, value in drive_config(model).items()}
    return render("chewbot_ctrl.c", **drive, HOME=_array(home_angles(model)), HERMITE=", ".join("{" + _array(row) + "}" for row in HERMITE),
                  GAINS=_array(spec.gains), CUTOFF=repr(float(spec.cutoff)), TORQUE_LIMIT=repr(float(model.limits.torque)),
                  RATE_LIMIT=repr(float(spec.torque_rate_limit)), WATCHDOG=repr(WATCHDOG_PERIODS / spec.rate),
                  FK_STEP=repr(FK_STEP_TOLERANCE), FK_RESIDUAL=repr(FK_RESIDUAL_TOLERANCE), CONDITIONING=repr(CONDITIONING_MIN),
                  TRANSMISSION=repr(TRANSMISSION_MIN), DIST_STEP=repr(DISTRIBUTION_STEP_TOLERANCE), MAX_HOLD=repr(float(MAX_HOLD_TICKS)))


def task_source(spec: StepSpec) -> str:
    rows = np.column_stack([spec.t, spec.q, spec.dq, spec.ddq, spec.force])
    return render("chewbot_ctrl_task.c", rows=str(rows.shape[0]), table="\n".join("  " + _array(row) + "," for row in rows))


def readme(spec: StepSpec, fk: ca.Function, law: ca.Function, log_rows: int) -> str:
    return render(
        "README.md",
        model=spec.model.name, mechanism=spec.model.mechanism, kind=spec.kind,
        method=spec.method if spec.uses_inverse_dynamics else "(none: PD on the crank angles)", goal=spec.goal or "-",
        friction="with" if spec.friction else "without", n=str(spec.n), coords=", ".join(coordinate_names(spec)),
        gains=gain_description(spec), rows=str(len(spec.t)), t0=f"{spec.t[0]:g}", t1=f"{spec.t[-1]:g}", cutoff=f"{spec.cutoff:g}",
        rate=f"{spec.rate:g}", limit=f"{spec.model.limits.torque:g}", rate_limit=f"{spec.torque_rate_limit:g}",
        watchdog=f"{WATCHDOG_PERIODS / spec.rate:g}", fk_iterations=str(FK_ITERATIONS), fk_step=f"{FK_STEP_TOLERANCE:g}",
        fk_residual=f"{FK_RESIDUAL_TOLERANCE:g}", conditioning=f"{CONDITIONING_MIN:g}", transmission=f"{TRANSMISSION_MIN:g}",
        dist_step=f"{DISTRIBUTION_STEP_TOLERANCE:g}", max_hold=str(MAX_HOLD_TICKS), log_rows=str(log_rows),
        **{name: f"{value:g}" for name, value in drive_config(spec.model).items()}, period_ms=f"{1e3 / spec.rate:g}", work_w=str(max(fk.sz_w(), law.sz_w())), version=VERSION,
        bits="\n".join(f"| `CHEWBOT_CTRL_{bit.name}` | 0x{STATUS_BITS[bit.name]:04x} | {bit.behaviour} |" for bit in STATUS))


def write_sources(spec: StepSpec, folder: Path, fk: ca.Function | None = None, law: ca.Function | None = None) -> list[Path]:
    """The library's header and sources into ``folder`` (include/ and src/); returns the C files."""
    fk = fk if fk is not None else fk_function(spec.model)
    law = law if law is not None else law_function(spec)
    (folder / "include").mkdir(parents=True, exist_ok=True)
    (folder / "src").mkdir(parents=True, exist_ok=True)
    (folder / "include" / f"{PREFIX}.h").write_text(header(spec, fk, law))
    cg = ca.CodeGenerator(f"{PREFIX}_kernels.c", {"with_header": True})
    cg.add(fk)
    cg.add(law)
    cg.add(drive_function())
    cg.generate(f"{folder / 'src'}/")
    kernels = folder / "src" / f"{PREFIX}_kernels.c"
    kernels.write_text(strict_c(kernels.read_text()))
    (folder / "src" / f"{PREFIX}.c").write_text(step_source(spec))
    (folder / "src" / f"{PREFIX}_task.c").write_text(task_source(spec))
    return sorted((folder / "src").glob("*.c"))


def export_controller(spec: StepSpec, out: Path, force: bool = False, inputs=(), log: np.ndarray | None = None) -> Path:
    """Write the library for ``spec`` into the folder ``out`` (written whole, replaced only with ``force`` and only if
    chewbot exported it): include/chewbot_ctrl.h, src/ (the step, the generated graphs, the task table), Makefile,
    README.md, example/example.c and, with ``log`` (rows t, theta1..6, tau_cmd1..6), example/log.csv."""
    fk, law = fk_function(spec.model), law_function(spec)
    with atomic_folder(Path(out), force, EXPORT_FOLDER, inputs) as tmp:
        write_sources(spec, tmp, fk, law)
        (tmp / "Makefile").write_text(template("Makefile"))
        (tmp / "example").mkdir()
        (tmp / "example" / "example.c").write_text(template("example.c"))
        if log is not None:
            header_line = "t [s]," + ",".join(f"theta{i} [rad]" for i in range(1, 7)) + "," + ",".join(f"tau_cmd{i} [N*m]" for i in range(1, 7))
            body = "\n".join(",".join(repr(float(v)) for v in row) for row in log)
            (tmp / "example" / "log.csv").write_text(header_line + "\n" + body + "\n")
        (tmp / "README.md").write_text(readme(spec, fk, law, 0 if log is None else len(log)))
        (tmp / EXPORT_FOLDER.file).write_text(to_json({EXPORT_FOLDER.key: EXPORT_FORMAT, "chewbot": VERSION, "model": spec.model.name,
                                                       "prefix": PREFIX, "kind": "controller", "controller": spec.kind,
                                                       "method": spec.method, "goal": spec.goal, "friction": spec.friction}))
    return Path(out)
