"""The simulated robot: a model (the plant's own numbers), friction on or off, and its compiled integrator step.

The plant is the Newton–Euler model of :mod:`chewbot.dynamics.formulations.newton_euler` with its friction (or none),
integrated by :mod:`chewbot.simulation.integrator` in its independent coordinates (Euler angles: X, Y, alpha, beta for
the target, X_EE for the 6RSS). Both HKP contacts stay closed (bilateral, the papers' model): N_L, N_R of either sign
are reported, and the ``contact-pull`` check says where a plane pulls its condyle.

:class:`Plant` keeps what is fixed for a simulation (its model, the bite side, friction) and advances the state one
interval at a time under the torques and bite forces it is given at the stages of the step (:meth:`Plant.advance`),
splitting the interval where the step's Newton iteration did not converge. It follows
:class:`chewbot.simulation.interfaces.Plant` and closes the loop (:meth:`Plant.closed_loop`): a controller's law
inside the stages of its steps (``--rate continuous``).

Every compiled step (:func:`step_kernel`) takes ``(q0, v0, z0, W, s, h)``: the state, z0 the accelerations and normal
forces at its start (:func:`accelerations`: the last step's end, the next one's starting guess; the plant's own state,
:class:`Solved`), W the stage inputs (a column per stage), s the inputs every stage shares, h the step. W and s are
laid out by name: :data:`~chewbot.simulation.interfaces.PLANT_INPUTS` and :data:`PLANT_SHARED` for the plant under
given torques, the food's and the closed loop's layouts extend them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import casadi as ca
import numpy as np

from chewbot.compiled.cache import cached_graph, symbols
from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.compiled.layout import Layout
from chewbot.dynamics.formulations.newton_euler import DELTA_F_G, DELTA_N, EPS_THETA_DOT, EPS_V_T, n_unknowns
from chewbot.errors import ChewbotError
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.model import Model
from chewbot.model.chains import crank_tips
from chewbot.model.symbolic import c_name
from chewbot.model.vector import N_P
from chewbot.rotation import matrix_from_euler_angles
from chewbot.simulation.forward import (ORIENTATION, Forward, forward_dynamics, forward_kernel, n_coordinates,
                                        plant_outputs_kernel, residual_function, workspace_margin_sx)
from chewbot.simulation.integrator import C, STAGES, TOLERANCE, radau_step
from chewbot.simulation.interfaces import PLANT_INPUTS, Column, PlantCapabilities, PlantState, StageInputs

# At most 2^MAX_SPLITS steps per interval: 1/1024 of a millisecond resolves the regularised Coulomb friction
# (its speed scale eps over the accelerations of the task is about 1e-4 s); a step that still fails has no solution.
MAX_SPLITS = 10
# Step sizes above this (s) are split evenly (a control rate below 1 kHz, a coarse task in --rate continuous).
MAX_STEP = 1e-3

# The inputs every stage of the plant's step shares: the bite point in {M} (m), friction (0/1), the model's numbers.
PLANT_SHARED = Layout.of(B=3, friction=1, p=N_P)
STEP_INPUTS = ("q0", "v0", "z0", "W", "s", "h")
STEP_KERNEL_OUTPUTS = ("q1", "v1", "z1", "residual", "theta", "dtheta", "margin")
STATE_OUTPUTS = ("theta", "dtheta", "margin")


class SimulationError(ChewbotError):
    """The plant's equations of motion cannot be solved (names the time and the residual)."""


def accelerations(mechanism: str) -> Layout:
    """The integrator's unknowns at a time: the accelerations of the independent coordinates and the HKP normal
    forces (none on the 6RSS)."""
    return Layout.of(ddq=n_coordinates(mechanism), N=n_unknowns(mechanism))


def plant_shared(model: Model, side: str, friction: bool) -> np.ndarray:
    """s of the plant's step (:data:`PLANT_SHARED`): the bite point of ``side``, friction, the model's numbers."""
    return PLANT_SHARED.pack(B=model.molar(side), friction=float(friction), p=model.vector())


def state_function(mechanism: str) -> ca.Function:
    """(q, dq, p) -> theta, dtheta (crank angles and rates, rad, rad/s) and margin (> 0 inside the workspace,
    :func:`chewbot.simulation.forward.workspace_margin_sx`) of a state in the independent coordinates."""

    m = symbols(mechanism)

    def build():
        n = n_coordinates(mechanism)
        q, dq = ca.SX.sym("q", n), ca.SX.sym("dq", n)
        out = dict(zip(KINEMATICS_OUTPUTS, kinematics_kernel(mechanism, ORIENTATION).graph()(q, dq, ca.SX.zeros(n), m.p)))
        return ca.Function("plant_state", [q, dq, m.p], [out["theta"], out["dtheta"], workspace_margin_sx(m, out)],
                           ["q", "dq", "p"], list(STATE_OUTPUTS), {"cse": True})

    return cached_graph(m, ("plant-state",), build)


def held_stage(mechanism: str) -> ca.Function:
    """The stage residual of the plant under given torques: (q, v, a, N, w, s) -> r with w laid out as
    :data:`~chewbot.simulation.interfaces.PLANT_INPUTS` and s as :data:`PLANT_SHARED`."""

    def build():
        n, nN = n_coordinates(mechanism), n_unknowns(mechanism)
        q, v, a, N = ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("a", n), ca.SX.sym("N", nN)
        w, stage = PLANT_INPUTS.symbols("w", ca.SX.sym)
        s, shared = PLANT_SHARED.symbols("s", ca.SX.sym)
        r = residual_function(symbols(mechanism))(q, v, a, N, stage["tau"], shared["B"], stage["F_B"], shared["friction"], shared["p"])
        return ca.Function("held_stage", [q, v, a, N, w, s], [r])

    return cached_graph(symbols(mechanism), ("held-stage",), build)


def step_kernel(mechanism: str, name: str, stage: Callable[[], ca.Function], key: tuple, shared: Layout,
                ended: Callable | None = None) -> KernelSpec:
    """A compiled integrator step (:func:`chewbot.simulation.integrator.radau_step`) of the plant with the stage
    residual ``stage()``, followed by the crank angles, rates and workspace margin at the end of the step; s is laid
    out as ``shared``, whose block ``p`` is the plant's numbers. ``ended(q1, v1, blocks of s, h)``: the plant's own
    state at the end of the step, a dict of outputs added after :data:`STEP_KERNEL_OUTPUTS` in its order (a food's,
    so that a step is one call)."""

    def build(params):
        st = stage()
        n, nN = n_coordinates(mechanism), n_unknowns(mechanism)
        core = radau_step(f"{name}_radau", st, n, nN)
        ins = {nm: ca.MX.sym(nm, core.size1_in(i), core.size2_in(i)) for i, nm in enumerate(STEP_INPUTS)}
        q1, v1, z1, res = core(*ins.values())
        blocks = shared.split(ins["s"])
        theta, dtheta, margin = state_function(mechanism)(q1, v1, blocks["p"])
        own = {} if ended is None else ended(q1, v1, blocks, ins["h"])
        return ca.Function(name, list(ins.values()), [q1, v1, z1, res, theta, dtheta, margin, *own.values()],
                           list(STEP_INPUTS), [*STEP_KERNEL_OUTPUTS, *own])

    return KernelSpec(name, build, (mechanism, *key), mechanism)


def plant_step_kernel(mechanism: str) -> KernelSpec:
    """The plant's step under torques and bite forces given per stage (W: :data:`~chewbot.simulation.interfaces.PLANT_INPUTS`,
    s: :data:`PLANT_SHARED`). Outputs :data:`STEP_KERNEL_OUTPUTS`."""
    return step_kernel(mechanism, f"plant_step_{c_name(mechanism)}", lambda: held_stage(mechanism), ("held",), PLANT_SHARED)


@dataclass(frozen=True)
class Solved:
    """chewbot's plant's own state (:attr:`~chewbot.simulation.interfaces.PlantState.internal`): ``z`` the accelerations
    and normal forces at the state (:func:`accelerations`), the next step's start."""

    z: np.ndarray

    def at(self, z: np.ndarray) -> Solved:
        """This state with the accelerations and normal forces ``z`` of a step's end."""
        return Solved(z)


@dataclass(frozen=True)
class Step:
    """A compiled step (:func:`step_kernel`, loaded), ``shared(state)``, its s for a step from a state (its W, the
    stage inputs, is given with each interval), and the names of its ``outputs``."""

    kernel: object
    shared: Callable[[PlantState], np.ndarray]
    outputs: tuple[str, ...] = STEP_KERNEL_OUTPUTS


@dataclass
class Plant:
    """The simulated robot: ``model`` (the plant's numbers), ``friction`` (HKP and actuator friction of the model, on
    or off), ``side`` (the molar where the bite force acts)."""

    model: Model
    friction: bool = False
    side: str = "left"
    capabilities: PlantCapabilities = field(default=PlantCapabilities(closes_loop=True), init=False)
    splits: int = field(default=0, init=False)  # steps split because the iteration did not converge (diagnostics)
    _step: object = field(default=None, init=False, repr=False)

    @property
    def mechanism(self) -> str:
        return self.model.mechanism

    def kernels(self) -> list[KernelSpec]:
        return [plant_step_kernel(self.mechanism), forward_kernel(self.mechanism), plant_outputs_kernel(self.mechanism)]

    def shared(self) -> np.ndarray:
        """s of :func:`plant_step_kernel`."""
        return plant_shared(self.model, self.side, self.friction)

    def initial(self, t: float, q, dq) -> PlantState:
        """The state at t (the accelerations and normal forces are solved at the first step)."""
        out = dict(zip(STATE_OUTPUTS, native(state_function(self.mechanism))(q, dq, self.model.vector())))
        z = accelerations(self.mechanism).pack(ddq=0.0, N=0.0)
        return PlantState(t, np.array(q, float), np.array(dq, float), out["theta"], out["dtheta"], float(out["margin"][0]), Solved(z))

    def advance(self, state: PlantState, h: float, inputs: StageInputs) -> PlantState:
        """The state after h seconds under ``inputs`` (W: the torques and bite forces at the stage times)."""
        if self._step is None:
            s = self.shared()
            self._step = Step(native(plant_step_kernel(self.mechanism)), lambda state: s)
        return self.steps(state, h, self._step, inputs)

    def steps(self, state: PlantState, h: float, step: Step, stage: StageInputs) -> PlantState:
        """The state after h seconds by ``step`` with the stage inputs ``stage(t0, dt)``: the interval split evenly
        into steps of at most :data:`MAX_STEP`, and a step whose iteration did not converge (residual above
        :data:`TOLERANCE`) split again, up to 2^:data:`MAX_SPLITS` times."""
        n_steps = max(1, int(np.ceil(h / MAX_STEP - 1e-9)))
        for _ in range(n_steps):
            state = self.interval(step, stage, state, h / n_steps, 0)
        return state

    def ended(self, start: PlantState, end: PlantState, h: float, outputs: dict) -> PlantState:
        """The state at the end of a converged step of h seconds from ``start`` (the plant's own state updated from the
        step's ``outputs`` by name)."""
        return end

    def interval(self, step: Step, stage: StageInputs, state: PlantState, h: float, depth: int) -> PlantState:
        """One step of h seconds from ``state``, split in halves where its iteration did not converge."""
        out = step.kernel(state.q, state.dq, state.internal.z, stage(state.t, h), step.shared(state), h)
        out = dict(zip(step.outputs, out))
        margin = float(out["margin"][0])
        if out["residual"][0] <= TOLERANCE or not margin > 0:  # converged, or ended outside the workspace (the caller stops)
            end = PlantState(state.t + h, out["q1"], out["v1"], out["theta"], out["dtheta"], margin, state.internal.at(out["z1"]))
            return self.ended(state, end, h, out)
        if depth >= MAX_SPLITS:
            raise SimulationError(f"the plant's equations of motion have no solution near t = {state.t:.6g} s (residual "
                                  f"{out['residual'][0]:.3g} N m after splitting the step {2 ** MAX_SPLITS} times); with friction "
                                  "this happens where the Coulomb coefficients are too large for a rigid model (Painlevé's paradox)")
        self.splits += 1
        half = self.interval(step, stage, state, h / 2, depth + 1)
        return self.interval(step, stage, half, h / 2, depth + 1)

    def closed_loop(self, controller, reference, limit: float) -> ClosedLoop:
        """This plant with ``controller``'s law (:class:`~chewbot.simulation.interfaces.LawController`) at every stage of
        its steps, following ``reference``, the torques saturated at ``limit`` (N m)."""
        return ClosedLoop(self, controller, reference, limit)

    def outputs(self, t, q, dq, force, internal) -> tuple[np.ndarray, dict]:
        """The bite force on the plant at the rows (the task's, ``force``) and no quantities of its own."""
        return force, {}

    def columns(self, quantities: dict) -> list[Column]:
        """Its own columns of results.csv, from :meth:`outputs`' quantities: none."""
        return []

    def forward(self, q, dq, tau, force) -> Forward:
        """The accelerations and normal forces at states (q, dq) (N, n) under torques (N, 6) and bite forces (N, 3)
        (:func:`chewbot.simulation.forward.forward_dynamics` on the plant's model, side and friction)."""
        return forward_dynamics(self.model, q, dq, tau, force, self.side, self.friction)

    def drift(self, kinematics, rows: int) -> dict[str, np.ndarray]:
        """:func:`constraint_drift` of the simulated motion's kinematics: the plant's state is in independent
        coordinates, so this is what the kinematics of q leaves (none, to rounding)."""
        return constraint_drift(self.model, kinematics)

    def info(self, sim) -> dict:
        """run.json's ``simulation`` entries of the plant: the integrator and the plant (engine, model, friction, contact
        model, the smoothing of friction)."""
        return {"simulation": {
            "integrator": {"method": "Radau IIA, 3 stages (order 5, L-stable), compiled", "max_step_s": MAX_STEP,
                           "stage_residual_tolerance_Nm": TOLERANCE, "split_steps": sim.splits,
                           "largest_residual_Nm": float(np.max(sim.residual))},
            "plant": {"engine": "chewbot", "model": self.model.name, "file": self.model.source, "friction": self.friction,
                      "contact": "bilateral: both contacts stay closed, N_L and N_R of either sign (contact-pull reports N < 0)"
                      if self.model.has_hkp else None,
                      "friction_smoothing": {"eps_theta_dot_rad_s": EPS_THETA_DOT, "eps_v_T_m_s": EPS_V_T, "delta_N_N": DELTA_N,
                                             "delta_F_G_N": DELTA_F_G}}}}

    def files(self) -> dict[str, str]:
        return {}


# ------------------------------------------------------------------------------------------- the closed loop


def closed_loop_layouts(mechanism: str, gains: int) -> tuple[Layout, Layout]:
    """W and s of the closed loop's step: W = the reference (q_ref, dq_ref, ddq_ref), the bite force the controller
    knows (F_known) and the one on the plant (F_B) at the stage; s = the plant's (:data:`PLANT_SHARED`), then the
    controller's gains, bite point B_c and numbers p_c, and the torque limit."""
    n = n_coordinates(mechanism)
    return (Layout.of(q_ref=n, dq_ref=n, ddq_ref=n, F_known=3, F_B=3),
            PLANT_SHARED + Layout.of(gains=gains, B_c=3, p_c=N_P, limit=1))


def closed_loop_stage(controller) -> ca.Function:
    """The stage residual of plant and controller together: (q, v, a, N, w, s) -> r, w and s laid out as
    :func:`closed_loop_layouts` say; the law's torques saturated at the limit."""
    law = controller.function()
    mech = controller.model.mechanism

    def build():
        n, nN = n_coordinates(mech), n_unknowns(mech)
        W, S = closed_loop_layouts(mech, law.size1_in(law.index_in("gains")))
        q, v, a, N = ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("a", n), ca.SX.sym("N", nN)
        w, stage = W.symbols("w", ca.SX.sym)
        s, shared = S.symbols("s", ca.SX.sym)
        tau = law(q, v, stage["q_ref"], stage["dq_ref"], stage["ddq_ref"], stage["F_known"], shared["gains"], shared["B_c"], shared["p_c"])
        tau = ca.fmin(ca.fmax(tau, -shared["limit"]), shared["limit"])
        r = residual_function(symbols(mech))(q, v, a, N, tau, shared["B"], stage["F_B"], shared["friction"], shared["p"])
        return ca.Function("closed_loop_stage", [q, v, a, N, w, s], [r])

    return cached_graph(symbols(mech), ("closed-loop-stage", law.name(), *controller.kernel_spec().key[1:]), build)


def closed_loop_kernel(controller) -> KernelSpec:
    """The compiled integrator step of plant and controller together."""
    spec = controller.kernel_spec()
    name = spec.name.replace("control_", "closed_loop_", 1)
    gains = controller.function().size1_in(controller.function().index_in("gains"))
    shared = closed_loop_layouts(controller.model.mechanism, gains)[1]
    return step_kernel(controller.model.mechanism, name, lambda: closed_loop_stage(controller), ("closed-loop", *spec.key), shared)


@dataclass
class ClosedLoop:
    """A :class:`Plant` with a controller's law at every stage of its steps (:meth:`Plant.closed_loop`)."""

    plant: Plant
    controller: object
    reference: object
    limit: float
    _step: Step | None = field(default=None, init=False, repr=False)
    _stage: StageInputs | None = field(default=None, init=False, repr=False)

    def kernels(self) -> list[KernelSpec]:
        return [closed_loop_kernel(self.controller)]

    def advance(self, state: PlantState, h: float) -> PlantState:
        if self._step is None:
            c = self.controller.shared()
            W, S = closed_loop_layouts(self.plant.mechanism, c["gains"].size)
            s = S.pack(**PLANT_SHARED.unpack(self.plant.shared()), gains=c["gains"], B_c=c["B"], p_c=c["p"], limit=self.limit)

            def stage(t0: float, dt: float) -> np.ndarray:
                ts = stage_times(t0, dt)
                q, dq, ddq = self.reference.at(ts)
                F = self.reference.force_at(ts)
                return W.pack(columns=STAGES, q_ref=q.T, dq_ref=dq.T, ddq_ref=ddq.T, F_known=self.controller.known_force(F).T, F_B=F.T)

            self._step, self._stage = Step(native(closed_loop_kernel(self.controller)), lambda state: s), stage
        return self.plant.steps(state, h, self._step, self._stage)


def stage_times(t0: float, h: float) -> np.ndarray:
    """The three stage times of a step from t0 to t0 + h."""
    return t0 + C * h


# ------------------------------------------------------------------------------------------- constraint drift


DRIFT_DESCRIPTIONS = {"drift_chains": "largest abs(|S_i M_i| - coupler length) of the simulated pose and crank angles",
                      "drift_hkp": "largest distance of a condyle from its socket's plane in the simulated pose"}


def constraint_drift(model: Model, kin) -> dict[str, np.ndarray]:
    """How far the simulated poses are from satisfying the mechanism's constraints (m), computed from the points
    themselves: each chain's coupler length between the crank tip S_i (from theta) and M_i (from the pose), and
    (target) each condyle's distance from its plane p1 x + z + p2 = 0."""
    R = matrix_from_euler_angles(kin.X[:, 3:6])
    M = kin.X[:, None, :3] + np.einsum("nij,kj->nki", R, model.M)
    S = crank_tips(model, kin.theta)
    out = {"drift_chains": np.max(np.abs(np.linalg.norm(M - S, axis=2) - model.coupler_length), axis=1)}
    if model.has_hkp:
        h = model.hkp
        dist = [np.abs(h.p1 * kin.points[k][:, 0] + kin.points[k][:, 2] + h.p2) / np.hypot(h.p1, 1.0) for k in ("T_L", "T_R")]
        out["drift_hkp"] = np.maximum(*dist)
    return out


def plant_residual(model: Model, q, dq, ddq, N, tau, force, side: str, friction: bool) -> np.ndarray:
    """max abs(tau_NE(q, dq, ddq, N) - tau) of chewbot's Newton-Euler equations at given accelerations and normal
    forces (N m), per sample: how far another engine's answer is from this plant's equations."""
    w = PLANT_INPUTS.pack(columns=len(np.atleast_2d(q)), tau=np.atleast_2d(tau).T, F_B=np.atleast_2d(force).T).T
    r = evaluate(held_stage(model.mechanism), q, dq, ddq, N, w, plant_shared(model, side, friction))[0]
    return np.max(np.abs(r), axis=1)


__all__ = ["MAX_STEP", "PLANT_SHARED", "Plant", "SimulationError", "Solved", "TOLERANCE", "STAGES", "constraint_drift",
           "plant_residual", "plant_step_kernel", "state_function"]
