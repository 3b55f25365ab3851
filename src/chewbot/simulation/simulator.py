"""The loop: a controller and a plant, the torques held between the ticks of the control rate.

At each tick t_k the controller is given the time and the state (the plant's own, or with sensor noise the estimate
of :class:`~chewbot.simulation.sensor.CrankSensor`) and returns six torques; they are saturated at the actuators'
limit (the plant's ``limits.torque_Nm``), held constant until t_(k+1), and the plant is integrated over the interval
(:meth:`chewbot.simulation.plant.Plant.advance`: compiled Radau IIA steps of at most 1 ms, split where their Newton
iteration needs it). As in MuJoCo (``mj_step`` between the user's control callbacks) and Drake (a ``Simulator``
advancing a diagram of a plant and a controller), the plant knows nothing of the controller and the controller sees
only what it is given.

``rate=None`` (``--rate continuous``) evaluates the controller at every stage of every integrator step instead, on
the plant's true state: the closed loop is one system of equations, integrated as accurately as the plant alone
(for verification: with the exact model, computed torque then sees only the integration error). It needs a built-in
controller (one with a CasADi :meth:`~chewbot.simulation.controllers.ModelBasedController.function`); the rows are
then at the task's samples.

The robot is stopped at the first tick whose pose leaves the workspace (a chain out of reach or at its dead point,
a condyle outside its socket): :attr:`Simulation.stopped` says when and why, and the rows end at the last pose inside.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, evaluate, native, prepare_kernels
from chewbot.errors import KinematicsError
from chewbot.model.vector import N_P
from chewbot.compiled.cache import cached_graph, symbols
from chewbot.simulation.controllers import ModelBasedController, State
from chewbot.simulation.forward import Forward, forward_kernel, n_coordinates, plant_outputs_kernel, residual_function
from chewbot.simulation.integrator import C
from chewbot.simulation.mujoco_plant import MujocoPlant
from chewbot.simulation.plant import Plant, PlantState, plant_step_kernel, stage_times, step_kernel
from chewbot.simulation.reference import Reference
from chewbot.simulation.sensor import CrankSensor
from chewbot.dynamics.bite_force import residual_kernel
from chewbot.dynamics.formulations.newton_euler import n_unknowns

DEFAULT_RATE = 1000.0  # Hz


@dataclass
class Simulation:
    """What a simulation produced, one row per tick (arrays samples first, SI).

    ``t`` (K,); ``q``, ``dq`` (K, n) the plant's state in its independent coordinates (Euler angles); ``tau`` (K, 6)
    the torques applied from each row's time on (saturated), ``tau_cmd`` (K, 6) as the controller commanded them;
    ``force`` (K, 3) the bite force on the plant; ``q_ref``, ``dq_ref``, ``ddq_ref`` (K, n) the reference;
    ``ddq`` (K, n) and ``N`` (K, 2 or 0) the accelerations and HKP normal forces that each row's state and torques
    produce (the plant's forward dynamics), ``residual`` (K,) their equations' residual (N m); ``stopped``: None, or
    {"t", "sample", "reason"} where the robot left the workspace; ``rate`` (Hz, None: continuous); ``splits``: steps
    the integrator split; ``elapsed_s``, ``cpu_s``: the loop's wall-clock and CPU time (s); ``observed`` (K, 5) the
    force observer's Fx, Fy, Fz, N_L, N_R at each tick (None without an observer).
    """

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    tau_cmd: np.ndarray
    force: np.ndarray
    q_ref: np.ndarray
    dq_ref: np.ndarray
    ddq_ref: np.ndarray
    ddq: np.ndarray
    N: np.ndarray
    residual: np.ndarray
    rate: float | None
    stopped: dict | None = None
    splits: int = 0
    elapsed_s: float = 0.0
    cpu_s: float = 0.0
    info: dict = field(default_factory=dict)
    food: dict | None = None  # the food's columns per row where the plant holds one (chewbot.simulation.food)
    observed: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.t.shape[0]

    @property
    def saturated(self) -> np.ndarray:
        """(K, 6) True where the commanded torque was beyond the limit."""
        return self.tau != self.tau_cmd


def closed_loop_stage(controller: ModelBasedController) -> ca.Function:
    """The stage residual of plant and controller together (``rate=None``): (q, v, a, N, w, s) -> r, with
    w = (q_ref, dq_ref, ddq_ref, F_B known to the controller, F_B on the plant) at the stage and
    s = (B, friction, p of the plant, gains, B and p of the controller, torque limit)."""
    mech = controller.mechanism
    law = controller.function()

    def build():
        n, nN = n_coordinates(mech), n_unknowns(mech)
        ng = law.size1_in(6)
        q, v, a, N = ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("a", n), ca.SX.sym("N", nN)
        w, s = ca.SX.sym("w", 3 * n + 6), ca.SX.sym("s", 4 + N_P + ng + 3 + N_P + 1)
        gains, B_c, p_c, limit = s[4 + N_P: 4 + N_P + ng], s[4 + N_P + ng: 7 + N_P + ng], s[7 + N_P + ng: 7 + 2 * N_P + ng], s[-1]
        tau = law(q, v, w[:n], w[n:2 * n], w[2 * n:3 * n], w[3 * n:3 * n + 3], gains, B_c, p_c)
        tau = ca.fmin(ca.fmax(tau, -limit), limit)
        r = residual_function(symbols(mech))(q, v, a, N, tau, s[:3], w[3 * n + 3:], s[3], s[4:4 + N_P])
        return ca.Function("closed_loop_stage", [q, v, a, N, w, s], [r])

    return cached_graph(symbols(mech), ("closed-loop-stage", law.name(), controller.kind, controller.method, controller.goal,
                               controller.friction), build)


def closed_loop_kernel(controller: ModelBasedController) -> KernelSpec:
    """The compiled integrator step of plant and controller together (``rate=None``)."""
    spec = controller.kernel_spec()
    name = spec.name.replace("control_", "closed_loop_", 1)
    return step_kernel(controller.mechanism, name, lambda: closed_loop_stage(controller), ("closed-loop", *spec.key), 4)


def simulate(plant: Plant | MujocoPlant, controller, reference: Reference, rate: float | None = DEFAULT_RATE,
             sensor: CrankSensor | None = None, progress=None, check=None, observer=None) -> Simulation:
    """Simulate ``plant`` (chewbot's :class:`~chewbot.simulation.plant.Plant` or MuJoCo's
    :class:`~chewbot.simulation.mujoco_plant.MujocoPlant`) under ``controller`` following ``reference`` from its first
    to its last sample, starting on the reference (its first sample's position and rate).

    ``rate``: the control rate (Hz; ticks t_0 + k / rate), or None for the controller at every integrator stage
    (rows at the reference's samples; a built-in controller). ``sensor``: noisy crank encoders and the estimator the
    controller then gets its state from (held rates only). ``progress(fraction)`` is called now and then, and
    ``check()`` too, which raises to stop the loop (a signal a library swallowed: the command line's check).
    ``observer``: a force observer (:class:`~chewbot.simulation.observer.ForceObserver`) updated at each tick from
    the state the controller sees and the torques applied since the tick before; its estimate is the controller's
    ``State.force`` and the rows' ``observed``.
    """
    if rate is None:
        if getattr(plant, "food", None) is not None:
            raise ValueError("a food in the plant needs a control rate: its events are located between the ticks, not "
                             "inside a closed-loop step (--rate continuous)")
        if isinstance(plant, MujocoPlant):
            raise ValueError("the MuJoCo plant runs the controller at the ticks of a control rate, not continuously")
        if not isinstance(controller, ModelBasedController):
            raise ValueError("rate=None evaluates the controller inside the integrator: it needs a built-in controller")
        if sensor is not None:
            raise ValueError("sensor noise is sampled at the ticks of a control rate: it needs a rate, not continuous control")
        if observer is not None:
            raise ValueError("the force observer runs at the ticks of a control rate: it needs a rate, not continuous control")
        times = np.asarray(reference.t, float)
    else:
        if not rate > 0:
            raise ValueError(f"the control rate must be positive, not {rate}")
        count = int(np.floor((reference.end - reference.start) * rate + 1e-9)) + 1
        times = reference.start + np.arange(count) / rate
    if plant.mechanism != getattr(getattr(controller, "model", plant.model), "mechanism", plant.mechanism):
        raise ValueError(f"the controller's model is a {controller.model.mechanism}, the plant a {plant.mechanism}")
    reference.prepare(times)
    kernels = [plant_step_kernel(plant.mechanism), forward_kernel(plant.mechanism), plant_outputs_kernel(plant.mechanism)]
    if isinstance(controller, ModelBasedController):
        kernels.append(closed_loop_kernel(controller) if rate is None else controller.kernel_spec())
    kernels += getattr(controller, "kernel_specs", lambda: [])() + ([residual_kernel(observer.model.mechanism)] if observer else [])
    prepare_kernels(kernels)

    K, n = len(times), n_coordinates(plant.mechanism)
    q_ref, dq_ref, ddq_ref = reference.at(times)
    force = reference.force_at(times)
    q, dq, tau_cmd = np.zeros((K, n)), np.zeros((K, n)), np.zeros((K, 6))
    limit = plant.model.limits.torque
    state = plant.initial(times[0], q_ref[0], dq_ref[0])
    if sensor is not None:
        sensor.start(times[0], q_ref[0], dq_ref[0])
    observed = np.zeros((K, 5)) if observer is not None else None
    if observer is not None:
        observer.start(times[0], q_ref[0], dq_ref[0])
    tau_k = np.zeros(6)
    if rate is None:
        kernel, shared = native(closed_loop_kernel(controller)), _closed_loop_shared(plant, controller, limit)
        data = _closed_loop_data(controller, reference)
    else:
        kernel, shared = None, None
    stopped, last = None, K - 1
    if rate is not None:  # the bite force at the stages of each tick's step, all at once
        stage_force = reference.force_at((times[:-1, None] + np.diff(times)[:, None] * C[None, :]).ravel()).reshape(K - 1, 3, 3)
    internal = [None] * K  # the plant's own state per row (a food's)
    t0, c0 = time.perf_counter(), time.process_time()
    for k in range(K):
        q[k], dq[k], internal[k] = state.q, state.dq, state.food
        if rate is not None:
            seen = sensor(times[k], state.theta) if sensor is not None else State(state.q, state.dq, state.theta)
            if observer is not None:
                if k:
                    observed[k] = observer.update(times[k], seen.q, seen.dq, tau_k)
                seen = replace(seen, force=observed[k, :3].copy())
            tau_cmd[k] = controller(times[k], seen)
            tau_k = np.clip(tau_cmd[k], -limit, limit)
            data = _held_data(tau_k, reference, (times[k], times[k + 1] - times[k], stage_force[k]) if k < K - 1 else None)
        if k == K - 1:
            break
        if k % 250 == 0:
            if progress is not None:
                progress(k / K)
            if check is not None:
                check()
        state = plant.advance(state, times[k + 1] - times[k], data, kernel, shared)
        if not state.margin > 0:
            stopped, last = {"t": float(times[k + 1]), "sample": k + 1, "reason": _reason(plant, state)}, k
            break
    elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
    rows = slice(0, last + 1)
    if rate is None:  # the law at each row's state, as the integrator evaluated it there
        gains, B_c, p_c = controller.shared()
        tau_cmd[rows] = evaluate(native(controller.kernel_spec()), q[rows], dq[rows], q_ref[rows], dq_ref[rows], ddq_ref[rows],
                                 controller.known_force(force[rows]), gains, B_c, p_c)[0]
    tau = np.clip(tau_cmd[rows], -limit, limit)
    force_rows, food = plant.outputs(times[rows], q[rows], dq[rows], force[rows], internal[: last + 1])
    force = np.array(force)
    force[rows] = force_rows
    fwd: Forward = plant.forward(q[rows], dq[rows], tau, force[rows])
    return Simulation(times[rows], q[rows], dq[rows], tau, tau_cmd[rows], force[rows], q_ref[rows], dq_ref[rows], ddq_ref[rows],
                      fwd.ddq, fwd.N, fwd.residual, rate, stopped, plant.splits, elapsed, cpu, food=food,
                      observed=None if observed is None else observed[rows])


def _held_data(tau: np.ndarray, reference: Reference, tick=None):
    """W of the plant's step under held torques: the torques and the bite force at the stage times. ``tick``:
    (t0, h, the forces at its stages (3, 3)) of the whole tick's step, used where the step is that one."""
    held = np.repeat(tau[:, None], 3, axis=1)

    def data(t0: float, h: float) -> np.ndarray:
        if tick is not None and t0 == tick[0] and h == tick[1]:
            return np.vstack([held, tick[2].T])
        return np.vstack([held, reference.force_at(stage_times(t0, h)).T])
    return data


def _closed_loop_data(controller: ModelBasedController, reference: Reference):
    """W of the closed-loop step: the reference and the bite forces (the controller's, the plant's) at the stages."""
    def data(t0: float, h: float) -> np.ndarray:
        ts = stage_times(t0, h)
        q, dq, ddq = reference.at(ts)
        F = reference.force_at(ts)
        return np.hstack([q, dq, ddq, controller.known_force(F), F]).T
    return data


def _closed_loop_shared(plant: Plant, controller: ModelBasedController, limit: float) -> np.ndarray:
    gains, B_c, p_c = controller.shared()
    return np.concatenate([plant.shared(), gains, B_c, p_c, [limit]])


def _reason(plant: Plant, state: PlantState) -> str:
    """Why a state is outside the workspace, in the words of the kinematics' own checks."""
    from chewbot.kinematics.motion import solve_kinematics
    from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task

    coords = TARGET_COORDS if plant.model.has_hkp else FULL_COORDS
    task = Task("simulated", np.array([state.t]), coords, state.q[None], state.dq[None], np.zeros((1, len(coords))),
                np.zeros((1, 3)), plant.side)
    try:
        solve_kinematics(plant.model, task)
    except KinematicsError as exc:
        return f"chain {exc.chain}: {exc.reason}" if exc.chain is not None else exc.reason
    return "the pose is outside the workspace"
