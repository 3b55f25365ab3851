"""The exported step's context as one table: every member of the header's three structs (``chewbot_ctrl_config``,
``chewbot_ctrl_outputs`` and the context ``chewbot_ctrl`` that holds them) with its C type, length, meaning and unit.

Both the typedefs of the header (:func:`c_typedefs`) and their ctypes mirror (:func:`structures`, through which
:class:`chewbot.export.controller.library.StepLibrary` reads and sets the context) are generated from it; the tests
hold the mirror's offsets and sizes against the C compiler's ``offsetof`` and ``sizeof``.

A length is a number or the name of one of the header's dimensions (``NQ`` is ``CHEWBOT_CTRL_NQ``), whose values
each export gives. The header's text is kept as exported since format 1: a member ``joined`` to the one before it
shares its declaration (``double fk_residual, fk_step, ...;``), and the header writes a line's meaning as its comment
only where the first member of the line is ``commented``.
"""

from __future__ import annotations

import ctypes
from collections.abc import Mapping
from dataclasses import dataclass
from string import Template

MACRO_PREFIX = "CHEWBOT_CTRL_"  # of the dimensions' macros


@dataclass(frozen=True)
class Field:
    """One member: ``name``, ``ctype`` (a key of :data:`CTYPES`, or a struct of :data:`STRUCTS` above its own),
    ``length`` (None: one value; a number; or a dimension's name), ``meaning`` (as the header's comment words it;
    ``$gains`` is the law's description, filled in per export), ``unit`` (SI, chewbot's unit names; ``1`` a ratio,
    empty for a count, a flag, a pointer or a struct)."""

    name: str
    ctype: str
    length: int | str | None
    meaning: str
    unit: str
    joined: bool = False
    commented: bool = True

    def declarator(self) -> str:
        if self.length is None:
            return self.name
        return f"{self.name}[{self.length if isinstance(self.length, int) else MACRO_PREFIX + self.length}]"


@dataclass(frozen=True)
class Struct:
    """A typedef of the header: its ``name``, the comment above it, the column where its members' comments start."""

    name: str
    doc: str
    column: int
    fields: tuple[Field, ...]


# The C types of the members and their ctypes.
CTYPES = {"double": ctypes.c_double, "long": ctypes.c_long, "long long": ctypes.c_longlong, "int": ctypes.c_int,
          "unsigned": ctypes.c_uint, "const double*": ctypes.POINTER(ctypes.c_double), "double*": ctypes.POINTER(ctypes.c_double)}

CONFIG = Struct("chewbot_ctrl_config", "Settings, set to their defaults by chewbot_ctrl_init; the caller may change them "
                "before the first step.", 34, (
    Field("gains", "double", "NG", "${gains}", "N*m/rad, N*m*s/rad (PD on the cranks); 1/s^2, 1/s (on the coordinates)"),
    Field("cutoff_hz", "double", None, "velocity filter: v = b v + (1 - b) dq/dt, b = exp(-2 pi cutoff dt)", "Hz"),
    Field("torque_limit", "double", None, "N m: |tau| saturates here", "N*m"),
    Field("torque_rate_limit", "double", None, "N m/s: |dtau/dt| limit; 0 switches it off", "N*m/s"),
    Field("watchdog_s", "double", None, "s: a step later than this after the previous one trips the (latched) watchdog", "s"),
    Field("fk_step_tolerance", "double", None, "m or rad: the last Gauss-Newton step of a converged estimate", "m, rad"),
    Field("fk_residual_tolerance", "double", None, "scaled closure residual (1) above which the angles are rejected", "1"),
    Field("conditioning_min", "double", None, "near-singular below this (direct kinematics)", "1"),
    Field("transmission_min", "double", None, "near-singular below this (sin of the smallest transmission angle)", "1"),
    Field("distribution_step_tolerance", "double", None, "N: Newton-Euler distribution's last step", "N"),
    Field("max_hold_ticks", "double", None, "ticks the last torques are held while the estimate is unusable, then zero", ""),
    Field("gear_ratio", "double", None, "drive: motor turns per crank turn (1 without a drive)", "1"),
    Field("gear_efficiency", "double", None, "drive: the gearbox's efficiency in its loss law (1 without a drive)", "1"),
    Field("torque_constant", "double", None, "drive: N m/A, the motor's torque per ampere (1 without a drive)", "N*m/A"),
    Field("encoder_counts", "double", None, "drive: encoder counts per motor turn (0: no encoder, step_counts refuses)", ""),
))

OUTPUTS = Struct("chewbot_ctrl_outputs", "What the last step computed (all doubles).", 36, (
    Field("q", "double", "NQ", "estimated pose, independent coordinates (m, rad)", "m, rad"),
    Field("dq", "double", "NQ", "estimated rates (filtered difference)", "m/s, rad/s"),
    Field("pose", "double", 6, "X_EE = X, Y, Z (m), alpha, beta, gamma (rad) of the estimate", "m, rad"),
    Field("q_ref", "double", "NQ", "the reference used", "m, rad"),
    Field("dq_ref", "double", "NQ", "the reference's rates", "m/s, rad/s", commented=False),
    Field("ddq_ref", "double", "NQ", "the reference's accelerations", "m/s^2, rad/s^2", commented=False),
    Field("force", "double", 3, "bite force the law used (N, in S)", "N"),
    Field("error", "double", "NQ", "tracking error q_ref - q", "m, rad"),
    Field("normal", "double", "NN", "HKP normal forces N_L, N_R (N)", "N"),
    Field("tau_cmd", "double", 6, "the control law's torques before saturation and rate limit (N m)", "N*m"),
    Field("tau", "double", 6, "the torques output (N m)", "N*m"),
    Field("dtheta", "double", 6, "crank rates, the filtered difference of the angles (rad/s)", "rad/s"),
    Field("tau_motor", "double", 6, "the motors' torques that give tau through the drive (N m)", "N*m"),
    Field("current", "double", 6, "the motors' currents commanded, tau_motor / torque_constant (A)", "A"),
    Field("fk_residual", "double", None, "the estimate's scaled closure residual", "1", commented=False),
    Field("fk_step", "double", None, "the estimate's last Gauss-Newton step", "m, rad", joined=True),
    Field("conditioning", "double", None, "the estimate's conditioning, det(J'J)^(1/n) / (trace(J'J)/n)", "1", joined=True),
    Field("transmission", "double", None, "the smallest sin of the chains' transmission angles at the estimate", "1", joined=True),
    Field("pose_margin", "double", None, "> 0: the estimated pose inside the workspace (ratios and distances)", "1, m",
          joined=True),
    Field("ref_margin", "double", None, "> 0: the reference asked for inside the workspace", "1, m", joined=True),
    Field("dist_step", "double", None, "Newton-Euler distribution's last Newton step (0 without it)", "N", joined=True),
    Field("limit_excess", "double", None, "largest |limit value| / bound - 1 of the distribution's actuator limits "
          "(-1 without it)", "1", joined=True),
    Field("dt", "double", None, "time since the previous step", "s", joined=True),
))

CONTEXT = Struct("chewbot_ctrl", "The context: the caller owns it (static, stack or its own memory); one per controller.", 36, (
    Field("config", CONFIG.name, None, "the settings", "", commented=False),
    Field("out", OUTPUTS.name, None, "what the last step computed", "", commented=False),
    Field("offsets", "double", 6, "encoder offsets: theta = theta_measured - offsets", "rad"),
    Field("q", "double", "NQ", "the estimator's state", "m, rad"),
    Field("dq", "double", "NQ", "the estimator's filtered rates", "m/s, rad/s", joined=True),
    Field("t_estimate", "double", None, "the time of the estimate", "s", joined=True),
    Field("theta_last", "double", 6, "the angles of the last step (less the offsets)", "rad"),
    Field("dtheta", "double", 6, "the crank rates' filter state", "rad/s", joined=True),
    Field("tau_last", "double", 6, "the torques output by the last step", "N*m", commented=False),
    Field("t_last", "double", None, "the time of the last step", "s", joined=True),
    Field("held_q_ref", "double", "NQ", "the last reference inside the workspace", "m, rad"),
    Field("user_q_ref", "double", "NQ", "the caller's reference (chewbot_ctrl_set_reference)", "m, rad", commented=False),
    Field("user_dq_ref", "double", "NQ", "the caller's reference rates", "m/s, rad/s", joined=True),
    Field("user_ddq_ref", "double", "NQ", "the caller's reference accelerations", "m/s^2, rad/s^2", joined=True),
    Field("user_force", "double", 3, "the caller's bite force", "N", joined=True),
    Field("row", "long", None, "the task table's row of the last reference (where the next search starts)", "", commented=False),
    Field("ticks", "long", None, "steps taken since chewbot_ctrl_init", "", joined=True),
    Field("hold_ticks", "long", None, "steps in a row the torques have been held", "", joined=True),
    Field("user_reference", "int", None, "1: the caller's reference, 0: the task table", "", commented=False),
    Field("estop", "int", None, "1: the emergency stop is on", "", joined=True),
    Field("started", "int", None, "1: a step has been taken", "", joined=True),
    Field("angles_known", "int", None, "1: theta_last holds measured angles", "", joined=True),
    Field("latched", "unsigned", None, "the latched status bits (the watchdog)", "", commented=False),
    Field("arg", "const double*", "WORK_ARG", "the graphs' argument pointers", "", commented=False),
    Field("res", "double*", "WORK_RES", "the graphs' result pointers", "", commented=False),
    Field("iw", "long long", "WORK_IW", "the graphs' integer work (casadi_int)", "", commented=False),
    Field("w", "double", "WORK_W", "the graphs' real work", "", commented=False),
))

# In the header's order: a struct only holds those before it.
STRUCTS = (CONFIG, OUTPUTS, CONTEXT)


def _lines(struct: Struct) -> list[list[Field]]:
    """The members grouped by declaration: a line's first member and those joined to it (one C type)."""
    lines: list[list[Field]] = []
    for f in struct.fields:
        if f.joined:
            assert lines and lines[-1][0].ctype == f.ctype and not f.ctype.endswith("*"), f.name  # one declarator list
            lines[-1].append(f)
        else:
            lines.append([f])
    return lines


def c_typedefs(filled: Mapping[str, str]) -> str:
    """The header's typedefs of :data:`STRUCTS`, one after the other; ``filled`` gives the meanings' placeholders."""
    blocks = []
    for struct in STRUCTS:
        rows = [f"/* {struct.doc} */", "typedef struct {"]
        for line in _lines(struct):
            first = line[0]
            code = f"  {first.ctype} {', '.join(f.declarator() for f in line)};"
            if first.commented:
                code = f"{code.ljust(struct.column - 1)} /* {Template(first.meaning).substitute(filled)} */"
            rows.append(code)
        rows.append(f"}} {struct.name};")
        blocks.append("\n".join(rows))
    return "\n\n".join(blocks)


def structures(dimensions: Mapping[str, int], filled: Mapping[str, str]) -> dict[str, type[ctypes.Structure]]:
    """The ctypes mirror of :data:`STRUCTS` for an export's ``dimensions`` (their values by name: ``NQ``, ``WORK_W``,
    ...), by struct name; each documents its members (meaning [unit]), ``filled`` giving the meanings' placeholders."""
    made: dict[str, type[ctypes.Structure]] = {}
    for struct in STRUCTS:
        members, doc = [], [f"{struct.doc} (the ctypes mirror of {struct.name})", ""]
        for f in struct.fields:
            base = made[f.ctype] if f.ctype in made else CTYPES[f.ctype]
            length = dimensions[f.length] if isinstance(f.length, str) else f.length
            members.append((f.name, base if length is None else base * length))
            doc.append(f"{f.declarator()}: {Template(f.meaning).substitute(filled)}" + (f" [{f.unit}]" if f.unit else ""))
        made[struct.name] = type(struct.name, (ctypes.Structure,), {"_fields_": members, "__doc__": "\n".join(doc)})
    return made
