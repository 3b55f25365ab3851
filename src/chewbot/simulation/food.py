"""The food in the plant: a sample on the lower molar whose force on the mandible depends on the plant's state.

:class:`FoodPlant` is the plant of :mod:`chewbot.simulation.plant` with a food (:class:`chewbot.food.law.Food`) at
the bite point of its side. The bite force in the equations of motion is no longer given: at every stage of the
integrator step it is the food's force at the stage's state (:func:`food_stage`): the compression delta from the bite
point's gap (:mod:`chewbot.food.geometry`), its rate, the sliding velocity, and the food's own state, the
:class:`FoodState`: ``broken`` (0/1), the Maxwell branch's force F_m (integrated exactly over the step for a linear
change of b F_e, :func:`chewbot.food.law.maxwell_force`). The derivatives the step's Newton iteration needs are
CasADi's, exact.

Events. The law has kinks and one jump (:mod:`chewbot.food.law`): contact (delta = 0), the teeth meeting
(delta = h0), the adhesion clamp (F_d + F_m = -adhesion_N) and the fracture (delta / h0 = fracture_strain, which
switches ``broken``). Each is a guard function of the state; after every step the guards at its ends are compared,
and where one changed sign the step is cut at the crossing: the crossing's step length is found by SciPy's ``brentq``
on the guard of the step's end as a function of the step length (each evaluation one compiled Radau IIA step from
the start), to :data:`EVENT_TOLERANCE`; the step is taken to just past it, the state switched (fracture), and the
interval continued. No step straddles a kink, so the method keeps its order, and the fracture happens at its strain,
not at the next tick. :attr:`FoodPlant.events` lists them.

The controllers are not told the food's force: a model-based controller gets the task's bite force, which must be
zero with a food (refused otherwise in :mod:`chewbot.simulation.run`), except for a controller named in
:data:`FORCE_REFERENCE_CONTROLLERS`, which reads the task's force as its force reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.optimize import brentq

from chewbot.compiled.cache import cached_graph, symbols
from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.formulations.newton_euler import n_unknowns
from chewbot.food.geometry import bite_point_function, gap, home_height
from chewbot.food.law import CASADI, N_FOOD, NUMPY, Food, breaking, elastic_force, maxwell_force, normal_force, tangential_force
from chewbot.model.vector import N_P
from chewbot.simulation.forward import n_coordinates, residual_function
from chewbot.simulation.integrator import C
from chewbot.simulation.plant import MAX_STEP, Plant, PlantState, step_kernel

# Controllers that take the task's bite force as a force reference with a food in the plant (chewbot.simulation.run
# lets a task with a bite force through for them only). The hybrid force/position controller reads F_z.
FORCE_REFERENCE_CONTROLLERS = ("hybrid",)
# Step lengths of the located events are found to this (s).
EVENT_TOLERANCE = 1e-10
EVENTS = ("contact", "teeth", "fracture", "adhesion")
# s of the food step after the plant's (B, friction, p): the food's vector, then its state at the step's start
# (broken, F_m, b F_e) and B_z at home.
N_STATE = 3


@dataclass(frozen=True)
class FoodState:
    """The food's state at one time: ``broken`` (0/1), ``F_m`` the Maxwell branch's force (N), and what the state
    gives there: ``bFe`` the elastic force b F_e (N), ``delta`` the compression h0 - g (m; negative: apart), ``F_v``
    the force before the clamp F_d + F_m (N), ``F_n`` the normal force (N)."""

    broken: int
    F_m: float
    bFe: float
    delta: float
    F_v: float
    F_n: float


def _food_sx(mechanism: str, q, dq, B, p, f, broken, z_home):
    """The food's kinematic quantities at a state (SX): delta (h0 - g), its rate, b F_e, the bite point's velocity,
    cos of the lower tooth's tilt."""
    point, velocity, cos_tilt = bite_point_function(mechanism)(q, dq, B, p)
    delta = f[0] - (z_home - point[2])  # h0 - g
    ddelta = velocity[2]
    bFe = breaking(f, broken) * elastic_force(CASADI, f, delta)
    return delta, ddelta, bFe, velocity, cos_tilt


def _force_sx(f, delta, ddelta, broken, F_m, velocity):
    F_n, F_v = normal_force(CASADI, f, delta, ddelta, broken, F_m)
    Fx, Fy = tangential_force(CASADI, f, F_n, velocity[0], velocity[1])
    return F_n, F_v, ca.vertcat(Fx, Fy, -F_n)


def food_stage(mechanism: str) -> ca.Function:
    """The stage residual of the plant with a food: (q, v, a, N, w, s) -> r with w = (tau (6), the stage's time since
    the step's start (1)) and s = (B (3), friction, p, food (N_FOOD), broken, F_m and b F_e at the step's start,
    B_z at home)."""
    m = symbols(mechanism)

    def build():
        n, nN = n_coordinates(mechanism), n_unknowns(mechanism)
        q, v, a, N = ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("a", n), ca.SX.sym("N", nN)
        w, s = ca.SX.sym("w", 7), ca.SX.sym("s", 4 + N_P + N_FOOD + N_STATE + 1)
        B, fl, p = s[:3], s[3], s[4:4 + N_P]
        f = s[4 + N_P:4 + N_P + N_FOOD]
        broken, F_m0, bFe0 = (s[4 + N_P + N_FOOD + i] for i in range(N_STATE))
        delta, ddelta, bFe, velocity, _ = _food_sx(mechanism, q, v, B, p, f, broken, s[-1])
        F_m = maxwell_force(CASADI, f, F_m0, bFe0, bFe, w[6])
        _, _, F = _force_sx(f, delta, ddelta, broken, F_m, velocity)
        r = residual_function(m)(q, v, a, N, w[:6], B, F, fl, p)
        return ca.Function("food_stage", [q, v, a, N, w, s], [r])

    return cached_graph(m, ("food-stage",), build)


def food_step_kernel(mechanism: str) -> KernelSpec:
    """The plant's step with a food (:func:`chewbot.simulation.plant.step_kernel` on :func:`food_stage`)."""
    from chewbot.model.symbolic import c_name

    return step_kernel(mechanism, f"food_step_{c_name(mechanism)}", lambda: food_stage(mechanism), ("food",), 4)


def food_function(mechanism: str) -> ca.Function:
    """The food at states: (q, dq, B, p, food, broken, F_m, z_home) -> delta (m), ddelta (m/s), bFe, F_v, F_n (N),
    F (3, the force on the mandible in {S}, N), cos_tilt."""
    m = symbols(mechanism)

    def build():
        n = n_coordinates(mechanism)
        q, dq, B, f = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("B", 3), ca.SX.sym("food", N_FOOD)
        broken, F_m, z_home = ca.SX.sym("broken"), ca.SX.sym("F_m"), ca.SX.sym("z_home")
        delta, ddelta, bFe, velocity, cos_tilt = _food_sx(mechanism, q, dq, B, m.p, f, broken, z_home)
        F_n, F_v, F = _force_sx(f, delta, ddelta, broken, F_m, velocity)
        return ca.Function("food", [q, dq, B, m.p, f, broken, F_m, z_home], [delta, ddelta, bFe, F_v, F_n, F, cos_tilt],
                           ["q", "dq", "B", "p", "food", "broken", "F_m", "z_home"],
                           ["delta", "ddelta", "bFe", "F_v", "F_n", "F", "cos_tilt"], {"cse": True})

    return cached_graph(m, ("food-quantities",), build)


@dataclass
class FoodPlant(Plant):
    """The plant with ``food`` on the molar of its side. :attr:`events` lists the located events
    (``{"t", "event", "delta_m"}``)."""

    food: Food | None = None
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
        return [food_step_kernel(self.mechanism)]

    def shared(self) -> np.ndarray:
        return np.concatenate([super().shared(), self._f, np.zeros(N_STATE), [self._z_home]])

    def step_shared(self, s: np.ndarray, state: PlantState) -> np.ndarray:
        s = s.copy()
        k = 4 + N_P + N_FOOD
        s[k:k + N_STATE] = (state.food.broken, state.food.F_m, state.food.bFe)
        return s

    def quantities(self, q, dq, broken: float, F_m: float) -> FoodState:
        """The food's state at one plant state."""
        if self._fn is None:
            self._fn = food_function(self.mechanism)
        delta, _, bFe, F_v, F_n, _, _ = self._fn(q, dq, self._B, self._p, self._f, broken, F_m, self._z_home)
        return FoodState(int(broken), float(F_m), float(bFe), float(delta), float(F_v), float(F_n))

    def initial(self, t: float, q, dq) -> PlantState:
        state = super().initial(t, q, dq)
        state.food = self.quantities(q, dq, 0, 0.0)
        return state

    def ended(self, start: PlantState, end: PlantState, h: float) -> PlantState:
        b = start.food.broken
        bFe = self.quantities(end.q, end.dq, b, 0.0).bFe
        F_m = float(maxwell_force(NUMPY, self._f, start.food.F_m, start.food.bFe, bFe, h))
        end.food = self.quantities(end.q, end.dq, b, F_m)
        return end

    # ---------------------------------------------------------------------------------------------- events

    def guards(self, state: FoodState) -> np.ndarray:
        """The guard functions at a food state, in the order of :data:`EVENTS` (NaN: not armed)."""
        f = self.food
        fracture = (state.delta / f.height - f.fracture_strain if f.fracture_strain is not None and not state.broken
                    else np.nan)
        adhesion = state.F_v + f.adhesion if state.delta > 0 else np.nan
        return np.array([state.delta, state.delta - f.height, fracture, adhesion])

    def advance(self, state: PlantState, h: float, stage_data, kernel=None, shared=None) -> PlantState:
        """The state after h seconds under the torques of ``stage_data`` (its bite-force rows are not used: the
        food's force replaces them), with the food's events located (module docstring)."""
        if self._step is None:
            self._step, self._shared = native(food_step_kernel(self.mechanism)), self.shared()

        def data(t0, dt):
            return np.vstack([stage_data(t0, dt)[:6], (C * dt)[None, :]])

        n_steps = max(1, int(np.ceil(h / MAX_STEP - 1e-9)))
        end = state.t + h
        for j in range(n_steps):
            stop = state.t + (end - state.t) / (n_steps - j)
            while stop - state.t > EVENT_TOLERANCE:
                state = self._until_event(state, stop - state.t, data)
        return state

    def _until_event(self, state: PlantState, h: float, data) -> PlantState:
        """One step of h seconds from ``state``, or to just past the first event within it (then switched)."""
        fn, s = self._step, self._shared
        trial = self._interval(fn, s, state, h, data, 0)
        g0, g1 = self.guards(state.food), self.guards(trial.food)
        crossed = np.flatnonzero(np.sign(g0) * np.sign(g1) < 0)
        if not crossed.size or not trial.margin > 0:
            return trial
        first, root = None, h
        for i in crossed:
            def guard(dt, i=i):
                return self.guards(self._interval(fn, s, state, dt, data, 0).food)[i] if dt > 0 else g0[i]

            r = brentq(guard, 0.0, h, xtol=EVENT_TOLERANCE, rtol=4 * np.finfo(float).eps)
            if r < root or first is None:
                first, root = int(i), r
        # just past the crossing: the step whose end has the guard's new sign
        past = min(h, root + EVENT_TOLERANCE)
        after = self._interval(fn, s, state, past, data, 0)
        while np.sign(self.guards(after.food)[first]) == np.sign(g0[first]) and past < h:
            past = min(h, past + EVENT_TOLERANCE * 10)
            after = self._interval(fn, s, state, past, data, 0)
        self.events.append({"t": float(after.t), "event": EVENTS[first], "delta_m": after.food.delta})
        if EVENTS[first] == "fracture":
            b = self.food.stiffness_after_fracture
            after.food = self.quantities(after.q, after.dq, 1, after.food.F_m * b)
        return after

    # ---------------------------------------------------------------------------------------------- rows

    def outputs(self, t, q, dq, force, states) -> tuple[np.ndarray, dict]:
        """The food's force on the mandible at the rows, and the food's columns: ``compression`` (m, max(0, delta)),
        ``force`` (N, F_n), ``broken``, ``delta`` (m, h0 - g), ``tilt`` (rad) and ``F_m`` (N)."""
        broken = np.array([s.broken for s in states], float)
        F_m = np.array([s.F_m for s in states], float)
        delta, _, _, _, F_n, F, cos_tilt = evaluate(food_function(self.mechanism), q, dq, self._B, self._p, self._f,
                                                    broken, F_m, np.full(len(t), self._z_home))
        columns = {"compression": np.maximum(delta[:, 0], 0.0), "force": F_n[:, 0], "broken": broken, "delta": delta[:, 0],
                   "tilt": np.arccos(np.clip(cos_tilt[:, 0], -1, 1)), "F_m": F_m}
        return F, columns

    def info(self, columns: dict) -> dict:
        """What run.json says about the food: the food, the events, the deepest compression and the lower tooth's tilt
        there (the laws assume parallel teeth)."""
        k = int(np.argmax(columns["delta"])) if len(columns["delta"]) else 0
        return {"food": self.food.as_dict(), "side": self.side, "events": self.events,
                "event_location": f"guards checked after every step; crossings by scipy.optimize.brentq on the step length to "
                                  f"{EVENT_TOLERANCE:g} s",
                "deepest_compression_m": float(columns["compression"][k]) if len(columns["delta"]) else 0.0,
                "tilt_at_deepest_deg": float(np.degrees(columns["tilt"][k])) if len(columns["delta"]) else 0.0,
                "peak_force_N": float(np.max(columns["force"])) if len(columns["force"]) else 0.0}


def start_gap(plant_model, side: str, q0, dq0) -> float:
    """The gap (m) at a task's first sample."""
    return float(gap(plant_model, side, q0, dq0)["gap"][0])


__all__ = ["EVENTS", "EVENT_TOLERANCE", "FORCE_REFERENCE_CONTROLLERS", "FoodPlant", "FoodState", "food_function",
           "food_stage", "food_step_kernel", "start_gap"]
