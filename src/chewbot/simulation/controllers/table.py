"""The controllers of ``chewbot simulate``, in one table: what each is called, what its law is and what it needs.

Every controller is a row of :data:`CONTROLLERS` (:class:`ControllerRow`): its name (the ``--controller`` value; this
module is the only one that spells it), its help line, the module of its law, its section of the gains file, what it
needs (:class:`Needs`), whether its law can run inside the integrator (``--rate continuous``), be exported as C
(``chewbot export-controller``) and take part in ``--compare``. The command line's choices and help, the gains file,
the option rules, the simulator, the export and the report read this table; adding a controller is adding its module
in this package and a row here.

The module of a law (``law``, loaded when first used: the command line reads the table without NumPy, CasADi or
pydantic) gives ``build(parts) -> controller`` (:class:`chewbot.simulation.controllers.law.ControllerParts`; the
controller follows :class:`chewbot.simulation.interfaces.Controller`) and ``Gains``, its gains section as a strict
model (:class:`chewbot.simulation.controllers.gains.Section`), or None where it has no gains.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType


@dataclass(frozen=True)
class Needs:
    """What a controller needs besides the state and the reference. ``inverse_dynamics``: its law evaluates the
    controller's inverse dynamics (``--method``, ``--goal``, friction in its model, the bite force it knows or not:
    ``--bite-unknown``); ``target``: its task coordinates are the target's (the molar point's x, y, z and alpha);
    ``observer``: the force observer's estimate at each tick (:attr:`chewbot.simulation.interfaces.State.force`), the
    only bite force it knows; ``food``: a food in the plant (``--food``) to press on."""

    inverse_dynamics: bool = False
    target: bool = False
    observer: bool = False
    food: bool = False


@dataclass(frozen=True)
class ControllerRow:
    """One controller: ``name`` (``--controller``), ``help`` (its line of the help), ``law`` (the module of its law in
    this package), ``gains`` (its section of the gains file, None: no gains), ``needs``; ``continuous``: its law is one
    CasADi function of the state, evaluated at every integrator stage with ``--rate continuous``; ``exportable``: the
    exported C step runs it; ``compared``: one of ``--compare``'s; ``force_reference``: with a food it reads the task's
    bite force as its force reference (a task that carries one is then accepted); ``extends``: the row whose compiled
    law it evaluates with its own state added (None: its own law)."""

    name: str
    help: str
    law: str
    gains: str | None = None
    needs: Needs = Needs()
    continuous: bool = True
    exportable: bool = False
    compared: bool = False
    force_reference: bool = False
    extends: str | None = None

    def module(self) -> ModuleType:
        """The module of its law: ``build(parts)`` and ``Gains``."""
        return importlib.import_module(f"{__package__}.{self.law}")


CONTROLLERS: dict[str, ControllerRow] = {row.name: row for row in (
    ControllerRow("feedforward", "the inverse dynamics of the reference, no feedback", "feedforward",
                  needs=Needs(inverse_dynamics=True), compared=True),
    ControllerRow("pd", "independent PD on the crank angles", "pd", gains="pd", exportable=True, compared=True),
    ControllerRow("computed-torque", "inverse dynamics at the measured state with PD on the independent coordinates",
                  "computed_torque", gains="computed_torque", needs=Needs(inverse_dynamics=True), exportable=True, compared=True),
    ControllerRow("impedance", "springs and dampers in the molar point's x, y, z [N/m, N*s/m] and alpha [N*m/rad] around "
                  "the reference, on top of the inverse dynamics", "impedance", gains="impedance",
                  needs=Needs(inverse_dynamics=True, target=True)),
    ControllerRow("hybrid", "with --food: position control until the observed force passes hybrid.threshold_N, then force "
                  "control along z following the task's Fz [N]; docs/bite_force.md", "hybrid", gains="hybrid",
                  needs=Needs(inverse_dynamics=True, target=True, observer=True, food=True), continuous=False,
                  force_reference=True),
    ControllerRow("crosshead", "computed torque with integral action on the independent coordinates: a texture analyser's "
                  "crosshead that holds its path under a load, the observed force fed forward (chewbot tpa's)", "crosshead",
                  gains="crosshead", needs=Needs(inverse_dynamics=True, observer=True), continuous=False, extends="computed-torque"),
)}
NAMES = tuple(CONTROLLERS)
COMPARED = tuple(r.name for r in CONTROLLERS.values() if r.compared)
EXPORTABLE = tuple(r.name for r in CONTROLLERS.values() if r.exportable)
# The controller of chewbot simulate (and of the Python API's simulate) where none is named.
DEFAULT_CONTROLLER = "computed-torque"
# The position loop of chewbot tpa, a texture analyser's crosshead.
TEXTURE_CONTROLLER = "crosshead"


def controller_row(name: str) -> ControllerRow:
    """The row of ``name``; ValueError names the controllers there are."""
    if name not in CONTROLLERS:
        raise ValueError(f"{name!r} is not a controller; choose one of {', '.join(NAMES)}")
    return CONTROLLERS[name]


def help_text() -> str:
    """The ``--controller`` help: each controller with its line."""
    return "; ".join(f"{r.name} ({r.help})" for r in CONTROLLERS.values()) + "."
