"""The two kinds of part the simulator connects, declared: plants and controllers, with what each can do as data.

As in Drake (a ``Simulator`` advancing a diagram whose systems declare their ports) and MuJoCo (``mj_step`` between
the user's control callbacks), the simulator (:func:`chewbot.simulation.simulator.simulate`) knows a plant and a
controller only by these protocols: it calls what they declare, reads what they can do from their capabilities
(:class:`PlantCapabilities`, :class:`ControllerCapabilities`), and never asks a part for its type.

The state of a plant that every plant reports is :class:`PlantState` (time, independent coordinates and rates, crank
angles and rates, workspace margin); what a plant keeps beyond it (the integrator's last accelerations and normal
forces, a food's state, MuJoCo's full state) is its own :attr:`PlantState.internal`, of a type the plant declares,
opaque to the simulator, which keeps it per row and hands it back (:meth:`Plant.outputs`). What a controller is given
at a tick is :class:`State`.

A plant's input at the stages of an integrator step is :data:`StageInputs`: ``inputs(t0, dt)`` gives W, whose rows
are laid out as :data:`PLANT_INPUTS` (the torques and the bite force) and whose columns are the step's stage times
t0 + c_k dt (:data:`chewbot.simulation.integrator.C`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, NamedTuple, Protocol

import numpy as np

from chewbot.compiled.layout import Layout

# The rows of a plant's stage inputs W: the six torques (N m) and the bite force on the mandible in {S} (N).
PLANT_INPUTS = Layout.of(tau=6, F_B=3)
StageInputs = Callable[[float, float], np.ndarray]


@dataclass(frozen=True)
class State:
    """What a controller is given at a tick: ``q`` (n,) the independent coordinates (Euler angles; m, rad) and ``dq``
    their rates; ``theta`` (6,) the crank angles the encoders read (rad), from which the estimate was made (None: not
    given); ``force`` (3,) the force observer's bite force on the mandible (N, {S}), None where no observer runs."""

    q: np.ndarray
    dq: np.ndarray
    theta: np.ndarray | None = None
    force: np.ndarray | None = None


@dataclass(frozen=True)
class PlantState:
    """A plant's state at time ``t`` (s): ``q``, ``dq`` the independent coordinates (Euler angles; m, rad) and their
    rates, ``theta``, ``dtheta`` the crank angles and rates (rad, rad/s), ``margin`` the workspace margin (> 0 inside,
    :func:`chewbot.simulation.forward.workspace_margin_sx`), and ``internal``: the plant's own state beyond these, of
    the type the plant declares (the next step needs it; the simulator only keeps it)."""

    t: float
    q: np.ndarray
    dq: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray
    margin: float
    internal: Any = None


class Column(NamedTuple):
    """A column a part adds to results.csv: ``name``, ``values`` (one per row), ``unit``, ``description``."""

    name: str
    values: np.ndarray
    unit: str
    description: str


@dataclass(frozen=True)
class PlantCapabilities:
    """What a plant can do. ``closes_loop``: it integrates a controller's law (a CasADi function) at every stage of
    its integrator's steps (``--rate continuous``; :class:`LoopPlant`); ``food``: its bite force is a food's, from
    its own state (the task's bite force is not applied); ``bolus``: its food breaks into a bolus of particles, whose
    bed is the food's force once it has broken (:class:`chewbot.simulation.bolus.BolusPlant`)."""

    closes_loop: bool = False
    food: bool = False
    bolus: bool = False


@dataclass(frozen=True)
class ControllerCapabilities:
    """What a controller can do. ``continuous``: its law is a CasADi function of the state, which a plant that closes
    the loop evaluates at every integrator stage (:class:`LawController`)."""

    continuous: bool = False


class Plant(Protocol):
    """A simulated robot: its ``model`` (the plant's numbers), ``side`` (the molar where the bite force acts),
    ``friction`` (HKP and actuator friction on or off), ``capabilities``, and ``splits`` (steps split so far, a
    diagnostic)."""

    model: Any
    side: str
    friction: bool
    capabilities: PlantCapabilities
    splits: int

    @property
    def mechanism(self) -> str: ...

    def kernels(self) -> list:
        """The compiled kernels it uses (:class:`~chewbot.compiled.kernels.KernelSpec`), compiled before the loop."""

    def initial(self, t: float, q, dq) -> PlantState:
        """Its state at ``t``, at rest on (q, dq)."""

    def advance(self, state: PlantState, h: float, inputs: StageInputs) -> PlantState:
        """The state ``h`` seconds after ``state`` (the last one it returned) under ``inputs``."""

    def outputs(self, t: np.ndarray, q: np.ndarray, dq: np.ndarray, force: np.ndarray,
                internal: list) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The bite force on the plant at the rows (``force``: the task's) and its own quantities per row by name (a
        food's compression, force, ...; empty where it has none), from the rows' states and their
        :attr:`PlantState.internal`."""

    def columns(self, quantities: dict[str, np.ndarray]) -> list[Column]:
        """Its own columns of results.csv, from the quantities of :meth:`outputs`."""

    def forward(self, q, dq, tau, force):
        """The accelerations, normal forces and residual (:class:`~chewbot.simulation.forward.Forward`) at states."""

    def drift(self, kinematics, rows: int) -> dict[str, np.ndarray]:
        """How far the first ``rows`` states are from the mechanism's constraints (m), by column name, given the
        kinematics of the simulated motion."""

    def info(self, sim) -> dict:
        """What run.json says about the plant after the simulation ``sim``, by run.json's top-level key: under
        ``"simulation"`` its engine and settings, and sections of its own (a food's)."""

    def files(self) -> dict[str, str]:
        """Files of the results folder that describe it, by name (MuJoCo's robot.xml)."""


class Controller(Protocol):
    """A controller: ``__call__(t, state)`` returns the six torques it commands (N m) at a tick; the simulator
    saturates them at the actuators' limit and holds them until the next tick."""

    capabilities: ControllerCapabilities

    def kernels(self) -> list:
        """The compiled kernels it uses, compiled before the loop."""

    def __call__(self, t: float, state: State) -> np.ndarray: ...

    def columns(self, t: np.ndarray) -> list[Column]:
        """Its own columns of results.csv at the rows' times ``t`` (an internal state it logged at its ticks)."""

    def info(self) -> dict:
        """What run.json adds about it under ``simulation`` (beyond the options)."""


class LawController(Controller, Protocol):
    """A controller whose law is one CasADi function (``capabilities.continuous``)."""

    def function(self):
        """The law: a CasADi function of :data:`chewbot.simulation.controllers.law.CONTROL_INPUTS` -> tau."""

    def shared(self) -> dict[str, np.ndarray]:
        """The law's inputs that do not change during a simulation: gains, B, p."""

    def known_force(self, force: np.ndarray) -> np.ndarray:
        """The bite force the law uses, given the task's."""

    def commands(self, t: np.ndarray, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """The law's torques (K, 6) at the rows' times and states, all at once."""


class Loop(Protocol):
    """A plant with a controller's law inside its steps (``rate=None``)."""

    def kernels(self) -> list: ...

    def advance(self, state: PlantState, h: float) -> PlantState: ...


class LoopPlant(Plant, Protocol):
    """A plant that closes the loop (``capabilities.closes_loop``)."""

    def closed_loop(self, controller: LawController, reference, limit: float) -> Loop:
        """This plant with ``controller``'s law at every integrator stage, following ``reference``, the torques
        saturated at ``limit`` (N m)."""
