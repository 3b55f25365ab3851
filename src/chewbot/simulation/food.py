"""The food in the plant: a sample on the lower molar whose force on the mandible depends on the plant's state.

:class:`FoodPlant` is the plant of :mod:`chewbot.simulation.plant` with a food (:class:`chewbot.food.law.Food`) at
the bite point of its side. The bite force in the equations of motion is no longer given: at every stage of the
integrator step it is the food's force at the stage's state (:func:`food_stage`): the compression delta from the bite
point's gap (:mod:`chewbot.food.geometry`), its rate, the lower tooth's tilt (the cylinder's law integrated over its
tilted face), the sliding velocity, and the food's own state, the
:class:`FoodState`: ``broken`` (0/1), the Maxwell branch's force F_m (integrated exactly over the step for a linear
change of b F_e, :func:`chewbot.food.law.maxwell_force`) and the deepest compression so far delta_max (with
``broken`` or the yield it sets the sample's permanent set, :func:`chewbot.food.law.permanent_set`). The derivatives the step's Newton iteration needs are
CasADi's, exact. The food's state at a step's start is part of the step's shared inputs, laid out by name
(:data:`STEP_STATE` in :data:`FOOD_SHARED`); the plant's own state (:class:`FoodSolved`) carries it from step to step.

Events. The law has kinks and one jump (:mod:`chewbot.food.law`, its guards :func:`chewbot.food.law.guards` in the
order of :data:`~chewbot.food.law.FOOD_EVENTS`): contact, the teeth meeting (delta = h0), the fracture ((delta + a sin theta) / h0 =
fracture_strain on the face's most compressed fibre, which switches ``broken``: :func:`chewbot.food.law.fracture_state`), the adhesion clamp
(F_d + F_m = -adhesion_N), the yield and the turn (where delta_max stops growing). Each is a guard function of the
state, evaluated with the food's state at a step's end inside the compiled step (:func:`food_ended`: one C call a
step); after every step the guards at its ends are compared, and where one changed sign the step is cut at the crossing: the crossing's step length is found by SciPy's ``brentq``
on the guard of the step's end as a function of the step length (each evaluation one compiled Radau IIA step from
the start), to :data:`EVENT_TOLERANCE`; the step is taken to just past it, the state switched (fracture), and the
interval continued. No step straddles a kink, so the method keeps its order, and the fracture happens at its strain,
not at the next tick. :attr:`FoodPlant.events` lists them.

The controllers are not told the food's force: a model-based controller gets the task's bite force, which must be
zero with a food (refused otherwise by the simulation's options), except for a controller whose row reads the task's
force as its force reference (:attr:`chewbot.simulation.controllers.table.ControllerRow.force_reference`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np
from scipy.optimize import brentq

from chewbot.compiled.cache import cached_graph, symbols
from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.formulations.newton_euler import n_unknowns
from chewbot.food.geometry import bite_point_function, gap, home_height
from chewbot.food.law import (CASADI, FOOD_EVENTS, N_FOOD, NUMPY, Food, fracture_state, guards, loaded_force,
                              maxwell_force, normal_force, permanent_set, tangential_force)
from chewbot.compiled.layout import Layout
from chewbot.simulation.forward import forward_kernel, n_coordinates, plant_outputs_kernel, residual_function
from chewbot.simulation.integrator import C, STAGES
from chewbot.simulation.interfaces import PLANT_INPUTS, Column, PlantCapabilities, PlantState
from chewbot.simulation.plant import MAX_STEP, PLANT_SHARED, Plant, Solved, Step, step_kernel

# Step lengths of the located events are found to this (s).
EVENT_TOLERANCE = 1e-10
EVENTS = FOOD_EVENTS
# The food's state at a step's start: broken (0/1), the Maxwell branch's force F_m and the elastic force b F_e (N), the
# deepest compression so far delta_max (m) and sin of the lower tooth's tilt there.
STEP_STATE = Layout.of(broken=1, F_m=1, bFe=1, delta_max=1, tilt_max=1)
# W of the food's step: the torques and each stage's time since the step's start (s); s: the plant's, the food's
# vector, its state at the step's start, and B_z at home (m).
FOOD_INPUTS = Layout.of(tau=6, elapsed=1)
FOOD_SHARED = PLANT_SHARED + Layout.of(food=N_FOOD) + STEP_STATE + Layout.of(z_home=1)
_ELAPSED = FOOD_INPUTS.slices()["elapsed"]
# The food's state at a step's end, an output of the compiled step (:func:`food_ended`): F_m and b F_e (N), the
# compression delta (m) and its rate (m/s), F_v and F_n (N), the deepest compression so far delta_max (m), sin of the
# tilt there (tilt_max) and sin of the lower tooth's tilt at the end (sin_tilt).
FOOD_END = Layout.of(F_m=1, bFe=1, delta=1, ddelta=1, F_v=1, F_n=1, delta_max=1, tilt_max=1, sin_tilt=1)


@dataclass(frozen=True)
class FoodState:
    """The food's state at one time: ``broken`` (0/1), ``F_m`` the Maxwell branch's force (N), ``delta_max`` the
    deepest compression so far (m; with ``broken`` it gives the permanent set, :func:`chewbot.food.law.permanent_set`),
    and what the state gives there: ``bFe`` the elastic force b F_e (N), ``delta`` the compression h0 - g (m; negative:
    apart), ``ddelta`` its rate (m/s), ``F_v`` the force before the clamp F_d + F_m (N), ``F_n`` the normal force
    (N), ``sin_tilt`` sin of the lower tooth's tilt, ``tilt_max`` sin of the tilt where the compression was deepest."""

    broken: int
    F_m: float
    bFe: float
    delta: float
    F_v: float
    F_n: float
    delta_max: float = 0.0
    ddelta: float = 0.0
    sin_tilt: float = 0.0
    tilt_max: float = 0.0


def deepest_sx(delta_max0, tilt_max0, delta, sin_tilt):
    """(delta_max, tilt_max) at a stage: the deepest compression so far, the step's start's or the stage's, and sin of
    the tilt there (the ``turn`` and ``yield`` events keep a step from straddling the kinks where they stop growing)."""
    deeper = delta > delta_max0
    return ca.fmax(delta_max0, delta), ca.if_else(deeper, sin_tilt, tilt_max0)


def food_geometry_sx(mechanism: str, q, dq, B, p, f, broken, z_home, delta_max0=0.0, tilt_max0=0.0):
    """The food's kinematic quantities at a state (SX): delta (h0 - g at the face's centre), its rate, b F_e of the
    sample in its state over the lower tooth's tilted face (``delta_max0``, ``tilt_max0`` the state's deepest
    compression before and sin of the tilt there: :func:`deepest_sx`), the bite point's velocity, sin of the lower
    tooth's tilt."""
    point, velocity, _, sin_tilt = bite_point_function(mechanism)(q, dq, B, p)
    delta = f[0] - (z_home - point[2])  # h0 - g
    ddelta = velocity[2]
    delta_max, tilt_max = deepest_sx(delta_max0, tilt_max0, delta, sin_tilt)
    bFe = loaded_force(CASADI, f, delta, broken, delta_max, sin_tilt, tilt_max)
    return delta, ddelta, bFe, velocity, sin_tilt


def _force_sx(f, delta, ddelta, broken, F_m, delta_max, tilt_max, velocity, sin_tilt):
    F_n, F_v = normal_force(CASADI, f, delta, ddelta, broken, F_m, delta_max, sin_tilt, tilt_max)
    Fx, Fy = tangential_force(CASADI, f, F_n, velocity[0], velocity[1])
    return F_n, F_v, ca.vertcat(Fx, Fy, -F_n)


def food_stage(mechanism: str) -> ca.Function:
    """The stage residual of the plant with a food: (q, v, a, N, w, s) -> r with w laid out as :data:`FOOD_INPUTS` and
    s as :data:`FOOD_SHARED`."""
    return stage_with_food(mechanism, "food_stage_face", FOOD_SHARED,
                           lambda f, delta, ddelta, F_m, velocity, sin_tilt, shared: _force_sx(
                               f, delta, ddelta, shared["broken"], F_m,
                               *deepest_sx(shared["delta_max"], shared["tilt_max"], delta, sin_tilt), velocity, sin_tilt)[2])


def stage_with_food(mechanism: str, name: str, shared: Layout, force) -> ca.Function:
    """A stage residual of the plant with a food: (q, v, a, N, w, s) -> r, w laid out as :data:`FOOD_INPUTS` and s as
    ``shared`` (:data:`FOOD_SHARED` and what ``force`` reads beyond it); ``force(f, delta, ddelta, F_m, velocity,
    sin_tilt, blocks)`` the food's force on the mandible (3,) from the food's vector, the compression and its rate, the
    Maxwell branch's force over the stage, the bite point's velocity, sin of the lower tooth's tilt and the blocks of
    s."""
    m = symbols(mechanism)

    def build():
        n, nN = n_coordinates(mechanism), n_unknowns(mechanism)
        q, v, a, N = ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("a", n), ca.SX.sym("N", nN)
        w, stage = FOOD_INPUTS.symbols("w", ca.SX.sym)
        s, blocks = shared.symbols("s", ca.SX.sym)
        B, p, f = blocks["B"], blocks["p"], blocks["food"]
        delta, ddelta, bFe, velocity, sin_tilt = food_geometry_sx(mechanism, q, v, B, p, f, blocks["broken"],
                                                                  blocks["z_home"], blocks["delta_max"], blocks["tilt_max"])
        F_m = maxwell_force(CASADI, f, blocks["F_m"], blocks["bFe"], bFe, stage["elapsed"])
        F = force(f, delta, ddelta, F_m, velocity, sin_tilt, blocks)
        r = residual_function(m)(q, v, a, N, stage["tau"], B, F, blocks["friction"], p)
        return ca.Function(name, [q, v, a, N, w, s], [r])

    return cached_graph(m, (name,), build)


def food_ended(mechanism: str):
    """The food's state at the end of a step as outputs of the compiled step (``ended`` of
    :func:`chewbot.simulation.plant.step_kernel`): ``food_end`` laid out as :data:`FOOD_END` and the ``guards`` there
    (:func:`chewbot.food.law.guards`), from the state at the step's start (the blocks of s, :data:`FOOD_SHARED`): b F_e
    at the end, the Maxwell branch's force integrated exactly over the step for a linear change of b F_e
    (:func:`chewbot.food.law.maxwell_force`), the food's quantities there (:func:`food_function`)."""

    def ended(q1, v1, blocks, h):
        fn = food_function(mechanism)
        state = (q1, v1, blocks["B"], blocks["p"], blocks["food"], blocks["broken"])
        before = (blocks["delta_max"], blocks["tilt_max"], blocks["z_home"])
        bFe = fn(*state, 0.0, *before)[4]
        F_m = maxwell_force(CASADI, blocks["food"], blocks["F_m"], blocks["bFe"], bFe, h)
        delta, ddelta, delta_max, tilt_max, bFe, F_v, F_n, _, _, sin_tilt, g = fn(*state, F_m, *before)
        end = dict(F_m=F_m, bFe=bFe, delta=delta, ddelta=ddelta, F_v=F_v, F_n=F_n, delta_max=delta_max, tilt_max=tilt_max,
                   sin_tilt=sin_tilt)
        return {"food_end": ca.vertcat(*(end[name] for name in FOOD_END.names)), "guards": g}

    return ended


def food_step_kernel(mechanism: str) -> KernelSpec:
    """The plant's step with a food (:func:`chewbot.simulation.plant.step_kernel` on :func:`food_stage`), the food's
    state and guards at its end among its outputs (:func:`food_ended`)."""
    from chewbot.model.symbolic import c_name

    return step_kernel(mechanism, f"food_step_{c_name(mechanism)}", lambda: food_stage(mechanism), ("food",), FOOD_SHARED,
                       food_ended(mechanism))


def food_function(mechanism: str) -> ca.Function:
    """The food at states: (q, dq, B, p, food, broken, F_m, delta_max, tilt_max, z_home) -> delta (m), ddelta (m/s),
    delta_max (m, with the state's) and tilt_max, bFe, F_v, F_n (N), F (3, the force on the mandible in {S}, N),
    cos_tilt, sin_tilt, guards (the law's guards there over the tilted face, :func:`chewbot.food.law.guards`, in the
    order of :data:`EVENTS`; NaN: not armed)."""
    m = symbols(mechanism)

    def build():
        n = n_coordinates(mechanism)
        q, dq, B, f = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("B", 3), ca.SX.sym("food", N_FOOD)
        broken, F_m, z_home = ca.SX.sym("broken"), ca.SX.sym("F_m"), ca.SX.sym("z_home")
        delta_max0, tilt_max0 = ca.SX.sym("delta_max"), ca.SX.sym("tilt_max")
        delta, ddelta, bFe, velocity, sin_tilt = food_geometry_sx(mechanism, q, dq, B, m.p, f, broken, z_home, delta_max0,
                                                                  tilt_max0)
        cos_tilt = bite_point_function(mechanism)(q, dq, B, m.p)[2]
        delta_max, tilt_max = deepest_sx(delta_max0, tilt_max0, delta, sin_tilt)
        F_n, F_v, F = _force_sx(f, delta, ddelta, broken, F_m, delta_max, tilt_max, velocity, sin_tilt)
        g = ca.vertcat(*guards(CASADI, f, delta, ddelta, broken, F_m, delta_max, sin_tilt, tilt_max))
        return ca.Function("food", [q, dq, B, m.p, f, broken, F_m, delta_max0, tilt_max0, z_home],
                           [delta, ddelta, delta_max, tilt_max, bFe, F_v, F_n, F, cos_tilt, sin_tilt, g],
                           ["q", "dq", "B", "p", "food", "broken", "F_m", "delta_max_before", "tilt_max_before", "z_home"],
                           ["delta", "ddelta", "delta_max", "tilt_max", "bFe", "F_v", "F_n", "F", "cos_tilt", "sin_tilt",
                            "guards"], {"cse": True})

    return cached_graph(m, ("food-quantities-face-guards",), build)


def food_quantities_kernel(mechanism: str) -> KernelSpec:
    """:func:`food_function` compiled: the food's state at each step's end is one call of it."""
    from chewbot.model.symbolic import c_name

    name = f"food_quantities_face_{c_name(mechanism)}"

    def build(params):
        fn = food_function(mechanism)
        inputs = fn.sx_in()
        return ca.Function(name, inputs, fn.call(inputs), fn.name_in(), fn.name_out())

    return KernelSpec(name, build, (mechanism, "food-quantities-face-guards"), mechanism)


@dataclass(frozen=True)
class FoodSolved(Solved):
    """The food plant's own state: the plant's (``z``), the food's (``food``) and the law's guards there (``guards``,
    in the order of :data:`EVENTS`)."""

    food: FoodState = None
    guards: np.ndarray = None

    def at(self, z: np.ndarray) -> FoodSolved:
        return FoodSolved(z, self.food, self.guards)


@dataclass
class FoodPlant(Plant):
    """The plant with ``food`` on the molar of its side. :attr:`events` lists the located events
    (``{"t", "event", "delta_m"}``)."""

    food: Food | None = None
    capabilities: PlantCapabilities = field(default=PlantCapabilities(food=True), init=False)
    events: list = field(default_factory=list, init=False)
    _fn: object = field(default=None, init=False, repr=False)

    def __post_init__(self):
        if self.food is None:
            raise ValueError("FoodPlant needs a food")
        self._f = self.food.vector()
        self._B = np.asarray(self.model.molar(self.side), float)
        self._z_home = home_height(self.model, self.side)
        self._p = self.model.vector()

    def kernels(self) -> list[KernelSpec]:
        return [self.step_kernel(), food_quantities_kernel(self.mechanism), forward_kernel(self.mechanism),
                plant_outputs_kernel(self.mechanism)]

    def step_kernel(self) -> KernelSpec:
        """The compiled step it advances by (:func:`food_step_kernel`)."""
        return food_step_kernel(self.mechanism)

    def shared(self) -> np.ndarray:
        """s of :func:`food_step_kernel` with the food's state at zero (:meth:`step_shared` sets it)."""
        return FOOD_SHARED.pack(**PLANT_SHARED.unpack(super().shared()), food=self._f, broken=0.0, F_m=0.0, bFe=0.0,
                                delta_max=0.0, tilt_max=0.0, z_home=self._z_home)

    def shared_at(self, s0: np.ndarray, state: PlantState) -> np.ndarray:
        """s of a step from ``state``: ``s0`` (:meth:`shared`) with the food's state at the step's start."""
        s = s0.copy()
        blocks, food = FOOD_SHARED.split(s), state.internal.food
        blocks["broken"][:], blocks["F_m"][:], blocks["bFe"][:] = food.broken, food.F_m, food.bFe
        blocks["delta_max"][:], blocks["tilt_max"][:] = food.delta_max, food.tilt_max
        return s

    def quantities(self, q, dq, broken: float, F_m: float, delta_max: float, tilt_max: float) -> tuple[FoodState, np.ndarray]:
        """The food's state at one plant state, ``delta_max`` the deepest compression before it and ``tilt_max`` sin of
        the tilt there, and the law's guards there."""
        if self._fn is None:
            self._fn = native(food_quantities_kernel(self.mechanism))
        delta, ddelta, deepest, tilt, bFe, F_v, F_n, _, _, sin_tilt, g = self._fn(q, dq, self._B, self._p, self._f, broken, F_m,
                                                                                  delta_max, tilt_max, self._z_home)
        return (FoodState(int(broken), float(F_m), float(bFe[0]), float(delta[0]), float(F_v[0]), float(F_n[0]),
                          float(deepest[0]), float(ddelta[0]), float(sin_tilt[0]), float(tilt[0])), np.ravel(g))

    def initial(self, t: float, q, dq) -> PlantState:
        state = super().initial(t, q, dq)
        return replace(state, internal=FoodSolved(state.internal.z, *self.quantities(q, dq, 0, 0.0, 0.0, 0.0)))

    def ended(self, start: PlantState, end: PlantState, h: float, outputs: dict) -> PlantState:
        """The food's state at the step's end, as the compiled step gave it (:func:`food_ended`)."""
        F_m, bFe, delta, ddelta, F_v, F_n, delta_max, tilt_max, sin_tilt = outputs["food_end"].tolist()
        food = FoodState(start.internal.food.broken, F_m, bFe, delta, F_v, F_n, delta_max, ddelta, sin_tilt, tilt_max)
        return replace(end, internal=replace(end.internal, food=food, guards=outputs["guards"]))

    # ---------------------------------------------------------------------------------------------- events

    def guards_at(self, internal: FoodSolved) -> np.ndarray:
        """The guard functions at the plant's own state, in the order of :data:`EVENTS` (NaN: not armed): the law's
        (:func:`chewbot.food.law.guards`, over the tilted face), evaluated where the state was."""
        return internal.guards

    def advance(self, state: PlantState, h: float, inputs) -> PlantState:
        """The state after h seconds under the torques of ``inputs``, held over the interval (their bite forces are not
        used: the food's force replaces them), with the food's events located (module docstring)."""
        if self._step is None:
            s0 = self.shared()
            kernel = native(self.step_kernel())
            self._step = Step(kernel, lambda state: self.shared_at(s0, state), tuple(kernel.name_out()))

        # the torques are held over the interval (the simulator's zero-order hold): read once, at the interval's own
        # step, whose inputs the simulator has ready (the bite forces of other steps' stages are not needed here)
        W = FOOD_INPUTS.pack(columns=STAGES, tau=PLANT_INPUTS.unpack(inputs(state.t, h))["tau"], elapsed=0.0)

        def stage(t0: float, dt: float) -> np.ndarray:  # the step copies W in: one array for the interval's steps
            W[_ELAPSED] = C * dt
            return W

        n_steps = max(1, int(np.ceil(h / MAX_STEP - 1e-9)))
        end = state.t + h
        for j in range(n_steps):
            stop = state.t + (end - state.t) / (n_steps - j)
            while stop - state.t > EVENT_TOLERANCE:
                state = self._until_event(state, stop - state.t, stage)
        return state

    def _until_event(self, state: PlantState, h: float, stage) -> PlantState:
        """One step of h seconds from ``state``, or to just past the first event within it (then switched)."""
        step = self._step
        trial = self.interval(step, stage, state, h, 0)
        g0, g1 = self.guards_at(state.internal), self.guards_at(trial.internal)
        crossed = np.flatnonzero(np.sign(g0) * np.sign(g1) < 0)
        if not crossed.size or not trial.margin > 0:
            return trial
        first, root = None, h
        for i in crossed:
            def guard(dt, i=i):
                return self.guards_at(self.interval(step, stage, state, dt, 0).internal)[i] if dt > 0 else g0[i]

            r = brentq(guard, 0.0, h, xtol=EVENT_TOLERANCE, rtol=4 * np.finfo(float).eps)
            if r < root or first is None:
                first, root = int(i), r
        # just past the crossing: the step whose end has the guard's new sign
        past = min(h, root + EVENT_TOLERANCE)
        after = self.interval(step, stage, state, past, 0)
        while np.sign(self.guards_at(after.internal)[first]) == np.sign(g0[first]) and past < h:
            past = min(h, past + EVENT_TOLERANCE * 10)
            after = self.interval(step, stage, state, past, 0)
        self.events.append({"t": float(after.t), "event": EVENTS[first], "delta_m": after.internal.food.delta})
        if EVENTS[first] == "fracture":
            now = after.internal.food
            broken, F_m, delta_max = fracture_state(NUMPY, self._f, now.delta, now.F_m, now.delta_max, now.sin_tilt,
                                                    now.tilt_max)
            food, g = self.quantities(after.q, after.dq, broken, float(F_m), float(delta_max), now.tilt_max)
            after = replace(after, internal=replace(after.internal, food=food, guards=g))
        return after

    # ---------------------------------------------------------------------------------------------- rows

    def outputs(self, t, q, dq, force, internal) -> tuple[np.ndarray, dict]:
        """The food's force on the mandible at the rows, and the food's quantities: ``compression`` (m, max(0, delta)),
        ``force`` (N, F_n), ``broken``, ``delta`` (m, h0 - g), ``tilt`` (rad), ``F_m`` (N), ``delta_max`` (m) and
        ``height`` (m, the sample's unloaded height h0 - s, s its permanent set)."""
        broken = np.array([s.food.broken for s in internal], float)
        F_m = np.array([s.food.F_m for s in internal], float)
        delta_max = np.array([s.food.delta_max for s in internal], float)
        tilt_max = np.array([s.food.tilt_max for s in internal], float)
        delta, _, _, _, _, _, F_n, F, cos_tilt, sin_tilt, _ = evaluate(native(food_quantities_kernel(self.mechanism)), q, dq,
                                                                       self._B, self._p, self._f, broken, F_m, delta_max,
                                                                       tilt_max, np.full(len(t), self._z_home))
        quantities = {"compression": np.maximum(delta[:, 0], 0.0), "force": F_n[:, 0], "broken": broken, "delta": delta[:, 0],
                      "tilt": np.arctan2(sin_tilt[:, 0], cos_tilt[:, 0]), "F_m": F_m, "delta_max": delta_max,
                      "height": self.food.height - permanent_set(NUMPY, self._f, broken, delta_max)}
        return F, quantities

    def columns(self, quantities: dict) -> list[Column]:
        return [Column("food_compression", quantities["compression"], "m", "the food's compression max(0, h0 - g), g the bite "
                       "point's gap along {S}'s z"),
                Column("food_force", quantities["force"], "N", "the food's normal force on the teeth (positive pushing them apart; "
                       "Fz = -food_force)"),
                Column("food_broken", quantities["broken"], "1", "1 once the food has broken (its fracture strain reached)"),
                Column("food_height", quantities["height"], "m", "the sample's unloaded height h0 - s, s its permanent set "
                       "(crushed once broken, plastic past its yield strain)")]

    def info(self, sim) -> dict:
        """The plant's entries, and what run.json says about the food: the food, the events, the deepest compression and
        the lower tooth's tilt there."""
        q = sim.quantities
        k = int(np.argmax(q["delta"])) if len(q["delta"]) else 0
        return {**super().info(sim),
                "food": {"food": self.food.as_dict(), "side": self.side, "events": self.events,
                         "event_location": f"guards checked after every step; crossings by scipy.optimize.brentq on the step "
                                           f"length to {EVENT_TOLERANCE:g} s",
                         "deepest_compression_m": float(q["compression"][k]) if len(q["delta"]) else 0.0,
                         "tilt_at_deepest_deg": float(np.degrees(q["tilt"][k])) if len(q["delta"]) else 0.0,
                         "peak_force_N": float(np.max(q["force"])) if len(q["force"]) else 0.0}}


def food_checks(sim, info: dict) -> list:
    """The food simulation's check (a failure): ``teeth-met``, the compression reached the sample's height (the teeth
    pressed on each other through it, the tooth contact's stiff spring instead of the food's law). The food's events
    themselves are run.json's ``food.events`` and the report's section."""
    from chewbot.analysis.checks import CheckResult

    delta, h0 = sim.quantities["delta"], info["food"]["height_mm"] * 1e-3
    met = np.flatnonzero(delta >= h0)
    teeth = [e for e in info["events"] if e["event"] == "teeth"]
    k = int(met[0]) if met.size else None
    ok = k is None and not teeth
    first = None if ok else ({"index": k, "t": float(sim.t[k])} if k is not None else {"index": None, "t": teeth[0]["t"]})
    worst = float(np.max(delta) * 1e3) if delta.size else 0.0
    checks = [CheckResult("teeth-met", ok, 0 if ok else max(int(met.size), 1), first, {"value": worst, "unit": "mm of compression"},
                          f"the deepest compression was {worst:.4g} mm of the sample's {h0 * 1e3:.4g} mm"
                          + ("" if ok else f": the teeth met through the sample (peak force {np.max(sim.quantities['force']):.4g} N)"),
                          "failure")]
    return checks


def build(model, friction: bool, side: str, food: Food | None = None) -> Plant:
    """chewbot's :class:`~chewbot.simulation.plant.Plant`, or with ``food`` a :class:`FoodPlant`."""
    if food is None:
        return Plant(model, friction=friction, side=side)
    return FoodPlant(model, friction=friction, side=side, food=food)


def start_gap(plant_model, side: str, q0, dq0) -> float:
    """The gap (m) at a task's first sample."""
    return float(gap(plant_model, side, q0, dq0)["gap"][0])


__all__ = ["EVENTS", "EVENT_TOLERANCE", "FOOD_INPUTS", "FOOD_SHARED", "STEP_STATE", "FoodPlant", "FoodState", "deepest_sx", "food_checks", "food_function", "food_geometry_sx", "food_quantities_kernel",
           "food_stage", "food_step_kernel", "stage_with_food", "start_gap"]
