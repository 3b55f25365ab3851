"""The bolus in the plant: a food that breaks into particles, whose particle bed is the food's force once it has
broken (docs/bolus.md, "The bolus in the plant").

:class:`BolusPlant` is the food plant of :mod:`chewbot.simulation.food` with the food's ``[comminution]`` table
(:mod:`chewbot.food.bolus`). The force on the teeth is

* the food's bulk law (:mod:`chewbot.food.law`) until its first fracture (the law's ``fracture`` event, located as in
  the food plant), then
* the particle bed's after it, damped while compressed: F = max(0, F_bed(g) (1 + 3/2 alpha r)),
  F_bed(g) = A E eps_c (e^(eps / eps_c) - 1), eps = max(0, 1 - g / h0), E the bolus's softened modulus
  (:func:`chewbot.food.bolus.bed`), r = -dg/dt the closing rate, alpha the bed's
  Hunt-Crossley damping (:func:`chewbot.food.bolus.bed_normal_force`), g the bite point's gap; its tangential friction
  the food's (``tooth_friction``). The switch is the food's ``broken`` state, so it happens at the fracture's strain,
  within the step.

The bed's parameters (:data:`~chewbot.food.bolus.BED_PARAMETERS`: h0, A, E, eps_c, alpha) are a block of the compiled step's
shared inputs (:data:`BOLUS_SHARED`), read from the plant's own state at each step's start: a chewing sequence
changes them without compiling anything. The bolus is part of that state (:class:`BolusSolved`): a **stroke** is a
contact of the teeth with the food (from the first step whose force is positive to the first where it is zero again);
at its end, if the food has broken, the bolus is broken down by the food layer's stroke
(:meth:`chewbot.food.bolus.Bolus.stroke`) with the stroke's closest gap (at the ends of the integrator's steps) and its
peak force, the bed's quasi-static force F_bed at that gap (where the closing stops; before the fracture, the bulk
law's force), and the bed's parameters are those of the new bolus (:meth:`~chewbot.food.bolus.Bolus.bed`). The bed's
contact (g = h0) is an event, as the bulk law's kinks are. Every state is a value: the trial steps of the event
location leave nothing behind.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from chewbot.compiled.cache import cached_graph, symbols
from chewbot.compiled.kernels import KernelSpec, evaluate
from chewbot.compiled.layout import Layout
from chewbot.food.bolus import BED_PARAMETERS, NUMPY, Bolus, bed_force, bed_normal_force, comminution_of
from chewbot.food.law import CASADI, FOOD_PARAMETERS, N_FOOD, maxwell_force, normal_force, tangential_force
from chewbot.simulation.food import EVENTS, FOOD_SHARED, FoodPlant, FoodSolved, food_ended, food_geometry_sx, stage_with_food
from chewbot.simulation.food import build as food_plant
from chewbot.simulation.forward import n_coordinates
from chewbot.simulation.interfaces import Column, PlantCapabilities, PlantState
from chewbot.simulation.plant import step_kernel

# The bolus plant's shared step inputs: the food plant's, then the particle bed's parameters (BED_PARAMETERS, SI).
BOLUS_SHARED = FOOD_SHARED + Layout.of(bed=len(BED_PARAMETERS))


def _bolus_force_sx(f, delta, ddelta, broken, F_m, velocity, bed):
    """(F_n, F_v, F): the bulk law's normal force until the fracture, the bed's after, and the force on the mandible."""
    bulk, F_v = normal_force(CASADI, f, delta, ddelta, broken, F_m)
    F_n = ca.if_else(broken > 0.5, bed_normal_force(CASADI, bed, f[0] - delta, ddelta), bulk)
    Fx, Fy = tangential_force(CASADI, f, F_n, velocity[0], velocity[1])
    return F_n, F_v, ca.vertcat(Fx, Fy, -F_n)


def bolus_stage(mechanism: str) -> ca.Function:
    """The stage residual of the plant with a bolus: (q, v, a, N, w, s), w laid out as
    :data:`~chewbot.simulation.food.FOOD_INPUTS` and s as :data:`BOLUS_SHARED`."""
    return stage_with_food(mechanism, "bolus_stage", BOLUS_SHARED,
                           lambda f, delta, ddelta, F_m, velocity, sin_tilt, shared: _bolus_force_sx(
                               f, delta, ddelta, shared["broken"], F_m, velocity, shared["bed"])[2])


def bolus_step_kernel(mechanism: str) -> KernelSpec:
    """The plant's step with a bolus (:func:`chewbot.simulation.plant.step_kernel` on :func:`bolus_stage`)."""
    from chewbot.model.symbolic import c_name

    return step_kernel(mechanism, f"bolus_step_{c_name(mechanism)}", lambda: bolus_stage(mechanism), ("bolus",), BOLUS_SHARED,
                       food_ended(mechanism))


def bolus_function(mechanism: str) -> ca.Function:
    """The food's force at states with the bed: (q, dq, B, p, food, broken, F_m, z_home, bed) -> F_n (N, pushing the
    teeth apart), F (3, on the mandible in {S}, N)."""
    m = symbols(mechanism)

    def build():
        n = n_coordinates(mechanism)
        q, dq, B, f = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("B", 3), ca.SX.sym("food", N_FOOD)
        broken, F_m, z_home, bed = ca.SX.sym("broken"), ca.SX.sym("F_m"), ca.SX.sym("z_home"), ca.SX.sym("bed", len(BED_PARAMETERS))
        delta, ddelta, _, velocity, _ = food_geometry_sx(mechanism, q, dq, B, m.p, f, broken, z_home)
        F_n, _, F = _bolus_force_sx(f, delta, ddelta, broken, F_m, velocity, bed)
        return ca.Function("bolus", [q, dq, B, m.p, f, broken, F_m, z_home, bed], [F_n, F],
                           ["q", "dq", "B", "p", "food", "broken", "F_m", "z_home", "bed"], ["F_n", "F"], {"cse": True})

    return cached_graph(m, ("bolus-quantities",), build)


@dataclass(frozen=True)
class Stroke:
    """A stroke the plant applied to the bolus: its end ``t`` (s), closest ``gap`` (m), ``peak_force`` (N), and the
    mass ``caught`` and ``broken`` in it (kg)."""

    t: float
    gap: float
    peak_force: float
    caught: float
    broken: float


@dataclass(frozen=True)
class BolusSolved(FoodSolved):
    """The bolus plant's own state: the food plant's, the ``bolus``, its ``bed`` (:data:`BED_PARAMETERS`), the
    current contact's closest gap ``closest`` (m; inf: no contact) and peak force ``peak`` (N), and the ``strokes``
    applied so far."""

    bolus: Bolus = None
    bed: np.ndarray = None
    closest: float = np.inf
    peak: float = 0.0
    strokes: tuple[Stroke, ...] = ()

    def at(self, z: np.ndarray) -> BolusSolved:
        return replace(self, z=z)


@dataclass
class BolusPlant(FoodPlant):
    """The food plant with the food's bolus (module docstring). ``bolus``: the bolus it starts from (None: the intact
    portion, :meth:`chewbot.food.bolus.Bolus.portion`)."""

    bolus: Bolus | None = None
    applied: tuple[Stroke, ...] = field(default=(), init=False)  # the strokes of the last simulation's rows
    capabilities: PlantCapabilities = field(default=PlantCapabilities(food=True, bolus=True), init=False)

    def __post_init__(self):
        super().__post_init__()
        # the bulk law at the face's centre, as its stage integrates it: a face of radius 0 takes no tilt
        self._f[FOOD_PARAMETERS.index("radius")] = 0.0
        self.table = comminution_of(self.food)
        if self.bolus is None:
            self.bolus = Bolus.portion(self.table)

    def step_kernel(self) -> KernelSpec:
        return bolus_step_kernel(self.mechanism)

    def shared(self) -> np.ndarray:
        return BOLUS_SHARED.pack(**FOOD_SHARED.unpack(super().shared()), bed=0.0)

    def shared_at(self, s0: np.ndarray, state: PlantState) -> np.ndarray:
        s = super().shared_at(s0, state)
        BOLUS_SHARED.split(s)["bed"][:] = state.internal.bed
        return s

    def initial(self, t: float, q, dq) -> PlantState:
        state = super().initial(t, q, dq)
        internal = state.internal
        return replace(state, internal=BolusSolved(internal.z, internal.food, internal.guards, self.bolus, self.bolus.bed(self.table)))

    def gap_and_force(self, internal: BolusSolved) -> tuple[float, float]:
        """The gap (m) and the food's normal force (N) at a state: the bulk law's, or once broken the bed's quasi-static
        force (positive exactly where the bed is in contact)."""
        food = internal.food
        g = self.food.height - food.delta
        return g, (float(bed_force(NUMPY, internal.bed, g)) if food.broken else food.F_n)

    def ended(self, start: PlantState, end: PlantState, h: float, outputs: dict) -> PlantState:
        """The food plant's end of a step, and the stroke: tracked while the force is positive, applied to the bolus
        where it falls to zero on a broken food."""
        end = super().ended(start, end, h, outputs)
        s = end.internal
        g, force = self.gap_and_force(s)
        if force > 0:
            return replace(end, internal=replace(s, closest=min(s.closest, g), peak=max(s.peak, force)))
        if not np.isfinite(s.closest):
            return end
        if not s.food.broken:  # a contact that did not break the food: the portion is intact
            return replace(end, internal=replace(s, closest=np.inf, peak=0.0))
        bolus, record = s.bolus.stroke(self.table, max(s.closest, 0.0), s.peak)
        stroke = Stroke(end.t, record.gap, record.force, record.caught, record.broken)
        return replace(end, internal=replace(s, bolus=bolus, bed=bolus.bed(self.table), closest=np.inf, peak=0.0,
                                             strokes=s.strokes + (stroke,)))

    def guards_at(self, internal: BolusSolved) -> np.ndarray:
        """The bulk law's guards until the fracture; then the bed's contact (h0 - g) alone."""
        if not internal.food.broken:
            return super().guards_at(internal)
        g, _ = self.gap_and_force(internal)
        return np.array([internal.bed[0] - g, *([np.nan] * (len(EVENTS) - 1))])

    def outputs(self, t, q, dq, force, internal) -> tuple[np.ndarray, dict]:
        """The food plant's quantities with the bed's force once broken, ``h0_bed`` (m) and ``strokes`` (the count
        applied by each row)."""
        F, quantities = super().outputs(t, q, dq, force, internal)
        if not len(t):
            return F, quantities
        bed = np.array([s.bed for s in internal])
        F_n, F = evaluate(bolus_function(self.mechanism), q, dq, self._B, self._p, self._f, quantities["broken"],
                          quantities["F_m"], np.full(len(t), self._z_home), bed)
        quantities.update(force=F_n[:, 0], h0_bed=bed[:, 0], strokes=np.array([len(s.strokes) for s in internal], float))
        self.applied = internal[-1].strokes
        return F, quantities

    def columns(self, quantities: dict) -> list[Column]:
        return super().columns(quantities) + [
            Column("bed_height", quantities["h0_bed"], "m", "the particle bed's loose height h0 (the food's force once it has "
                   "broken: docs/bolus.md)"),
            Column("strokes", quantities["strokes"], "1", "strokes applied to the bolus so far")]

    def info(self, sim) -> dict:
        """The food plant's entries, and under ``bolus`` the law, the portion and the strokes applied."""
        out = super().info(sim)
        out["bolus"] = {"law": "the food's bulk law until its first fracture, then the particle bed's "
                               "F = A E eps_c (exp(eps/eps_c) - 1), eps = max(0, 1 - g/h0), E = E0 (1 - f)^n softened "
                               "by the bolus's paste fraction f (docs/bolus.md)",
                        "stroke": "a contact (force > 0); at its end the bolus breaks by chewbot.food.bolus.stroke with its "
                                  "closest gap and peak force",
                        "portion_g": self.bolus.total * 1e3,
                        "strokes": [{"t_s": k.t, "gap_m": k.gap, "peak_force_N": k.peak_force, "caught_kg": k.caught,
                                     "broken_kg": k.broken} for k in self.applied]}
        return out


def build(model, friction: bool, side: str, food=None, write_mjcf=None, bolus: bool = False):
    """chewbot's engine (the engine table's builder): its plant (:func:`chewbot.simulation.food.build`: without a food,
    or with one), or with ``bolus`` the plant whose food breaks into a bolus, :class:`BolusPlant`."""
    if bolus:
        return BolusPlant(model, friction=friction, side=side, food=food)
    return food_plant(model, friction, side, food)


__all__ = ["BOLUS_SHARED", "BolusPlant", "BolusSolved", "Stroke", "bolus_function", "bolus_stage", "bolus_step_kernel"]
