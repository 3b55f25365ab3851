"""The simulated robot: a model (the plant's own numbers), friction on or off, and its compiled integrator step.

The plant is the Newton–Euler model of :mod:`chewbot.dynamics.formulations.newton_euler` with its friction (or none), integrated
by :mod:`chewbot.simulation.integrator` in its independent coordinates (Euler angles: X, Y, alpha, beta for the
target, X_EE for the 6RSS). Both HKP contacts stay closed (bilateral, the papers' model): N_L, N_R of either sign
are reported, and the ``contact-pull`` check says where a plane pulls its condyle.

:class:`Plant` keeps what is fixed for a simulation (its model, the bite side, friction) and advances the state
one interval at a time under the torques and bite forces it is given at the stages of the step
(:meth:`Plant.advance`), splitting the interval where the step's Newton iteration did not converge.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, native
from chewbot.dynamics.formulations.newton_euler import n_unknowns
from chewbot.errors import ChewbotError
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.model import Model
from chewbot.model.vector import N_P
from chewbot.compiled.cache import cached_graph, symbols
from chewbot.model.symbolic import c_name
from chewbot.simulation.forward import ORIENTATION, n_coordinates, residual_function, workspace_margin_sx
from chewbot.simulation.integrator import C, STAGES, TOLERANCE, radau_step

# At most 2^MAX_SPLITS steps per interval: 1/1024 of a millisecond resolves the regularised Coulomb friction
# (its speed scale eps over the accelerations of the task is about 1e-4 s); a step that still fails has no solution.
MAX_SPLITS = 10
# Step sizes above this (s) are split evenly (a control rate below 1 kHz, a coarse task in --rate continuous).
MAX_STEP = 1e-3


class SimulationError(ChewbotError):
    """The plant's equations of motion cannot be solved (names the time and the residual)."""


def state_function(mechanism: str) -> ca.Function:
    """(q, dq, p) -> theta, dtheta (crank angles and rates, rad, rad/s) and margin (> 0 inside the workspace,
    :func:`chewbot.simulation.forward.workspace_margin_sx`) of a state in the independent coordinates."""

    m = symbols(mechanism)

    def build():
        n = n_coordinates(mechanism)
        q, dq = ca.SX.sym("q", n), ca.SX.sym("dq", n)
        extra = [m.p]
        out = dict(zip(KINEMATICS_OUTPUTS, kinematics_kernel(mechanism, ORIENTATION).graph()(q, dq, ca.SX.zeros(n), *extra)))
        return ca.Function("plant_state", [q, dq, *extra], [out["theta"], out["dtheta"], workspace_margin_sx(m, out)],
                           ["q", "dq", *(["p"] if extra else [])], ["theta", "dtheta", "margin"], {"cse": True})

    return cached_graph(m, ("plant-state",), build)


def held_stage(mechanism: str) -> ca.Function:
    """The stage residual of the plant under given torques: (q, v, a, N, w, s) -> r with w = (tau (6), F_B (3)) at the
    stage and s = (B (3), friction, p)."""

    def build():
        n, nN = n_coordinates(mechanism), n_unknowns(mechanism)
        q, v, a, N = ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("a", n), ca.SX.sym("N", nN)
        w, s = ca.SX.sym("w", 9), ca.SX.sym("s", 4 + N_P)
        r = residual_function(symbols(mechanism))(q, v, a, N, w[:6], s[:3], w[6:], s[3], s[4:])
        return ca.Function("held_stage", [q, v, a, N, w, s], [r])

    return cached_graph(symbols(mechanism), ("held-stage",), build)


STEP_INPUTS = ("q0", "v0", "z0", "W", "s", "h")
STEP_KERNEL_OUTPUTS = ("q1", "v1", "z1", "residual", "theta", "dtheta", "margin")


def step_kernel(mechanism: str, name: str, stage: Callable[[], ca.Function], key: tuple, n_p_offset: int) -> KernelSpec:
    """A compiled integrator step (:func:`chewbot.simulation.integrator.radau_step`) of the plant with the stage
    residual ``stage()``, followed by the crank angles, rates and workspace margin at the end of the step. The plant's
    p is ``s[n_p_offset : n_p_offset + N_P]``."""

    def build(params):
        st = stage()
        n, nN = n_coordinates(mechanism), n_unknowns(mechanism)
        core = radau_step(f"{name}_radau", st, n, nN)
        ins = [ca.MX.sym(nm, core.size1_in(i), core.size2_in(i)) for i, nm in enumerate(STEP_INPUTS)]
        q1, v1, z1, res = core(*ins)
        theta, dtheta, margin = state_function(mechanism)(q1, v1, ins[4][n_p_offset:n_p_offset + N_P])
        return ca.Function(name, ins, [q1, v1, z1, res, theta, dtheta, margin], list(STEP_INPUTS), list(STEP_KERNEL_OUTPUTS))

    return KernelSpec(name, build, (mechanism, *key), mechanism)


def plant_step_kernel(mechanism: str) -> KernelSpec:
    """The plant's step under torques held or given per stage: W = (tau (6), F_B (3)) at the three stages (9 x 3),
    s = (B, friction, p). Outputs :data:`STEP_KERNEL_OUTPUTS`."""
    return step_kernel(mechanism, f"plant_step_{c_name(mechanism)}", lambda: held_stage(mechanism), ("held",), 4)


@dataclass
class PlantState:
    """The plant's state at one time: q, dq (independent coordinates, Euler angles), z = (q_ddot, N) of the last
    step's end (the next step's starting guess), theta, dtheta (crank angles and rates) and the workspace margin."""

    t: float
    q: np.ndarray
    dq: np.ndarray
    z: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray
    margin: float
    food: object = None  # the food's own state (chewbot.simulation.food.FoodState) where the plant holds a food


@dataclass
class Plant:
    """The simulated robot: ``model`` (the plant's numbers), ``friction`` (HKP and actuator friction of the model, on
    or off), ``side`` (the molar where the bite force acts)."""

    model: Model
    friction: bool = False
    side: str = "left"
    splits: int = field(default=0, init=False)  # steps split because the iteration did not converge (diagnostics)
    _step: object = field(default=None, init=False, repr=False)

    @property
    def mechanism(self) -> str:
        return self.model.mechanism

    def kernels(self) -> list[KernelSpec]:
        return [plant_step_kernel(self.mechanism)]

    def shared(self) -> np.ndarray:
        """s of :func:`plant_step_kernel`: bite point, friction flag, p."""
        return np.concatenate([self.model.molar(self.side), [float(self.friction)], self.model.vector()])

    def initial(self, t: float, q, dq) -> PlantState:
        """The state at t (z: the accelerations and normal forces are solved at the first step)."""
        theta, dtheta, margin = native(state_function(self.mechanism))(q, dq, self.model.vector())
        return PlantState(t, np.array(q, float), np.array(dq, float), np.zeros(len(q) + n_unknowns(self.mechanism)),
                          theta, dtheta, float(margin[0]))

    def advance(self, state: PlantState, h: float, stage_data: Callable[[float, float], np.ndarray],
                kernel=None, shared: np.ndarray | None = None) -> PlantState:
        """The state after h seconds. ``stage_data(t0, dt)`` gives W (n_w x 3) of a step from t0 to t0 + dt at its
        stage times t0 + C_k dt; ``kernel`` a compiled step (default: :func:`plant_step_kernel`, W = torques and bite
        forces) with its ``shared`` s. The interval is split evenly into steps of at most :data:`MAX_STEP`, and a step
        whose iteration did not converge (residual above :data:`TOLERANCE`) is split again, up to
        2^:data:`MAX_SPLITS` times."""
        if kernel is None:
            if self._step is None:
                self._step, self._shared = native(plant_step_kernel(self.mechanism)), self.shared()
            kernel, shared = self._step, self._shared
        fn, s = kernel, shared
        n_steps = max(1, int(np.ceil(h / MAX_STEP - 1e-9)))
        for j in range(n_steps):
            state = self._interval(fn, s, state, h / n_steps, stage_data, 0)
        return state

    def step_shared(self, s: np.ndarray, state: PlantState) -> np.ndarray:
        """s of a step from ``state`` (a plant with a state of its own beyond q, dq adds it here)."""
        return s

    def ended(self, start: PlantState, end: PlantState, h: float) -> PlantState:
        """The state at the end of a converged step of h seconds from ``start`` (the plant's own state updated)."""
        return end

    def outputs(self, t: np.ndarray, q: np.ndarray, dq: np.ndarray, force: np.ndarray, states: list) -> tuple[np.ndarray, dict | None]:
        """The bite force on the plant at the rows (the task's, given as ``force``) and the plant's own columns (None);
        ``states`` the rows' :attr:`PlantState.food`."""
        return force, None

    def forward(self, q, dq, tau, force):
        """The accelerations and normal forces at states (q, dq) (N, n) under torques (N, 6) and bite forces (N, 3)
        (:func:`chewbot.simulation.forward.forward_dynamics` on the plant's model, side and friction)."""
        from chewbot.simulation.forward import forward_dynamics

        return forward_dynamics(self.model, q, dq, tau, force, self.side, self.friction)

    def _interval(self, fn, s, state: PlantState, h: float, stage_data, depth: int) -> PlantState:
        q1, v1, z1, res, theta, dtheta, margin = fn(state.q, state.dq, state.z, stage_data(state.t, h), self.step_shared(s, state), h)
        if res[0] <= TOLERANCE or not margin[0] > 0:  # converged, or ended outside the workspace (the caller stops)
            return self.ended(state, PlantState(state.t + h, q1, v1, z1, theta, dtheta, float(margin[0])), h)
        if depth >= MAX_SPLITS:
            raise SimulationError(f"the plant's equations of motion have no solution near t = {state.t:.6g} s (residual "
                                  f"{res[0]:.3g} N m after splitting the step {2 ** MAX_SPLITS} times); with friction this "
                                  "happens where the Coulomb coefficients are too large for a rigid model (Painlevé's paradox)")
        self.splits += 1
        half = self._interval(fn, s, state, h / 2, stage_data, depth + 1)
        return self._interval(fn, s, half, h / 2, stage_data, depth + 1)


def stage_times(t0: float, h: float) -> np.ndarray:
    """The three stage times of a step from t0 to t0 + h."""
    return t0 + C * h


__all__ = ["MAX_STEP", "Plant", "PlantState", "TOLERANCE", "STAGES", "SimulationError", "plant_step_kernel", "state_function"]
