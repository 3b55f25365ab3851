"""The loop: a controller and a plant, the torques held between the ticks of the control rate.

At each tick t_k the controller is given the time and the state (the plant's own, or with sensor noise the estimate
of :class:`~chewbot.simulation.sensor.CrankSensor`) and returns six torques; they are saturated at the actuators'
limit (the plant's ``limits.torque_Nm``), held constant until t_(k+1), and the plant is integrated over the interval
(:meth:`chewbot.simulation.interfaces.Plant.advance`; chewbot's plant: compiled Radau IIA steps of at most 1 ms, split
where their Newton iteration needs it). As in MuJoCo (``mj_step`` between the user's control callbacks) and Drake (a
``Simulator`` advancing a diagram of a plant and a controller), the plant knows nothing of the controller and the
controller sees only what it is given; the simulator knows both only by their declared interfaces
(:mod:`chewbot.simulation.interfaces`) and what their capabilities say.

With a drive train (the controller's model's or the plant's ``[drive]``, :mod:`chewbot.model.drive`) the controller
commands currents: its saturated crank torques become motor currents through its model's drive at the crank rates it
sees, and the currents, held between the ticks, become the plant's crank torques through the plant's drive at the
plant's crank rates at the tick (the gearbox's loss law held with them for the tick). The force observer is given the
torques the controller's model makes of its currents (its saturated commands). Without a drive on either side, the
torques are held as they are.

``rate=None`` (``--rate continuous``) evaluates the controller at every stage of every integrator step instead, on
the plant's true state: the closed loop is one system of equations, integrated as accurately as the plant alone
(for verification: with the exact model, computed torque then sees only the integration error). It needs a plant
that closes the loop and a controller whose law is a CasADi function (their capabilities); the rows are then at the
task's samples. The options (:mod:`chewbot.simulation.options`) refuse what does not apply; here it is asserted.

The robot is stopped at the first tick whose pose leaves the workspace (a chain out of reach or at its dead point,
a condyle outside its socket): :attr:`Simulation.stopped` says when and why, and the rows end at the last pose inside.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from types import SimpleNamespace

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, native, prepare_kernels
from chewbot.compiled.layout import Layout
from chewbot.errors import KinematicsError
from chewbot.model import drive as drive_law
from chewbot.simulation.forward import n_coordinates
from chewbot.simulation.integrator import C, STAGES
from chewbot.simulation.interfaces import PLANT_INPUTS, Controller, Plant, PlantState, State, StageInputs
from chewbot.simulation.options import DEFAULT_RATE
from chewbot.simulation.plant import stage_times
from chewbot.simulation.reference import Reference


@dataclass
class Simulation:
    """What a simulation produced, one row per tick (arrays samples first, SI).

    ``t`` (K,); ``q``, ``dq`` (K, n) the plant's state in its independent coordinates (Euler angles); ``tau`` (K, 6)
    the torques applied from each row's time on (saturated), ``tau_cmd`` (K, 6) as the controller commanded them;
    ``force`` (K, 3) the bite force on the plant; ``q_ref``, ``dq_ref``, ``ddq_ref`` (K, n) the reference;
    ``current`` (K, 6) the motors' currents held from each row's time on (A) and ``tau_motor`` (K, 6) their torques in the
    plant (N m), None without a drive; ``limit`` the torque limit the commands were saturated at (N m);
    ``ddq`` (K, n) and ``N`` (K, 2 or 0) the accelerations and HKP normal forces that each row's state and torques
    produce (the plant's forward dynamics), ``residual`` (K,) their equations' residual (N m); ``stopped``: None, or
    {"t", "sample", "reason"} where the robot left the workspace; ``rate`` (Hz, None: continuous); ``splits``: steps
    the integrator split; ``elapsed_s``, ``cpu_s``: the loop's wall-clock and CPU time (s); ``quantities``: the plant's
    own quantities per row, by name (a food's, :meth:`chewbot.simulation.food.FoodPlant.outputs`; empty where it has
    none); ``observed`` (K, 5) the force observer's Fx, Fy, Fz, N_L, N_R at each tick (None without an observer).
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
    quantities: dict = field(default_factory=dict)
    observed: np.ndarray | None = None
    current: np.ndarray | None = None
    tau_motor: np.ndarray | None = None
    limit: float = np.inf

    @property
    def n(self) -> int:
        return self.t.shape[0]

    @property
    def saturated(self) -> np.ndarray:
        """(K, 6) True where the commanded torque was beyond the limit."""
        return np.abs(self.tau_cmd) > self.limit


def simulate(plant: Plant, controller: Controller, reference: Reference, rate: float | None = DEFAULT_RATE,
             sensor=None, progress=None, check=None, observer=None, drive=None) -> Simulation:
    """Simulate ``plant`` (:class:`~chewbot.simulation.interfaces.Plant`) under ``controller``
    (:class:`~chewbot.simulation.interfaces.Controller`) following ``reference`` from its first to its last sample,
    starting on the reference (its first sample's position and rate).

    ``rate``: the control rate (Hz; ticks t_0 + k / rate), or None for the controller at every integrator stage
    (rows at the reference's samples; a plant that closes the loop and a controller with a CasADi law). ``sensor``:
    noisy crank encoders and the estimator the controller then gets its state from (held rates only).
    ``progress(fraction)`` is called now and then, and ``check()`` too, which raises to stop the loop (a signal a
    library swallowed: the command line's check). ``observer``: a force observer
    (:class:`~chewbot.simulation.observer.ForceObserver`) updated at each tick from the state the controller sees and
    the torques applied since the tick before; its estimate is the controller's ``State.force`` and the rows'
    ``observed``. ``drive``: the controller's model's drive (:class:`~chewbot.model.Drive`, None: none); with it or
    the plant's, the controller commands currents (the module docstring).
    """
    continuous = rate is None
    if continuous:
        assert plant.capabilities.closes_loop and controller.capabilities.continuous and sensor is None and observer is None, \
            "continuous control needs a plant that closes the loop and a controller with a CasADi law, no sensor, no observer"
        times = np.asarray(reference.t, float)
    else:
        assert rate > 0, f"the control rate must be positive, not {rate}"
        count = int(np.floor((reference.end - reference.start) * rate + 1e-9)) + 1
        times = reference.start + np.arange(count) / rate
    limit = plant.model.limits.torque
    loop = plant.closed_loop(controller, reference, limit) if continuous else None
    reference.prepare(times)
    drives = None if drive is None and plant.model.drive is None else (drive or drive_law.NEUTRAL, drive_law.of(plant.model))
    kernels = plant.kernels() + (loop.kernels() if continuous else controller.kernels())
    prepare_kernels(kernels + (observer.kernels() if observer is not None else []) + ([drive_tick_kernel()] if drives else []))

    K, n = len(times), n_coordinates(plant.mechanism)
    q_ref, dq_ref, ddq_ref = reference.at(times)
    force = reference.force_at(times)
    q, dq, tau_cmd = np.zeros((K, n)), np.zeros((K, n)), np.zeros((K, 6))
    state = plant.initial(times[0], q_ref[0], dq_ref[0])
    if sensor is not None:
        sensor.start(times[0], q_ref[0], dq_ref[0])
    observed = np.zeros((K, 5)) if observer is not None else None
    if observer is not None:
        observer.start(times[0], q_ref[0], dq_ref[0])
    tau_k = np.zeros(6)
    if drives is not None:
        tick, numbers = native(drive_tick_kernel()), [DRIVE.pack(gear_ratio=d.gear_ratio, efficiency=d.efficiency,
                                                                  torque_constant=d.torque_constant) for d in drives]
    current, applied, dtheta = np.zeros((K, 6)), np.zeros((K, 6)), np.zeros((K, 6))
    stopped, last = None, K - 1
    if not continuous:  # the bite force at the stages of each tick's step, all at once
        stage_force = reference.force_at((times[:-1, None] + np.diff(times)[:, None] * C[None, :]).ravel()).reshape(K - 1, 3, 3)
    internal = [None] * K  # the plant's own state per row
    t0, c0 = time.perf_counter(), time.process_time()
    for k in range(K):
        q[k], dq[k], internal[k], dtheta[k] = state.q, state.dq, state.internal, state.dtheta
        if not continuous:
            seen = sensor(times[k], state.theta) if sensor is not None else State(state.q, state.dq, state.theta, dtheta=state.dtheta)
            if observer is not None:
                if k:
                    observed[k] = observer.update(times[k], seen.q, seen.dq, tau_k)
                seen = replace(seen, force=observed[k, :3].copy())
            tau_cmd[k] = controller(times[k], seen)
            if drives is not None:  # the controller's current, the plant's torque of it
                tau_k, current[k], applied[k] = tick(tau_cmd[k], limit, seen.dtheta, state.dtheta, *numbers)
                held = applied[k]
            else:
                held = tau_k = np.clip(tau_cmd[k], -limit, limit)
            inputs = _held(held, reference, (times[k], times[k + 1] - times[k], stage_force[k]) if k < K - 1 else None)
        if k == K - 1:
            break
        if k % 250 == 0:
            if progress is not None:
                progress(k / K)
            if check is not None:
                check()
        h = times[k + 1] - times[k]
        state = loop.advance(state, h) if continuous else plant.advance(state, h, inputs)
        if not state.margin > 0:
            stopped, last = {"t": float(times[k + 1]), "sample": k + 1, "reason": _reason(plant, state)}, k
            break
    elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
    rows = slice(0, last + 1)
    if continuous:  # the law at each row's state, as the integrator evaluated it there
        tau_cmd[rows] = controller.commands(times[rows], q[rows], dq[rows])
    tau = np.clip(tau_cmd[rows], -limit, limit)
    tau_motor = None
    if drives is not None:
        if continuous:  # the law's torques through the one drive (compute() refuses two different ones)
            current[rows] = drive_law.current(drives[0], drive_law.motor_torque(drives[0], tau, dtheta[rows]))
        else:
            tau = applied[rows]
        tau_motor = drive_law.torque_of_current(drives[1], current[rows])
    force_rows, quantities = plant.outputs(times[rows], q[rows], dq[rows], force[rows], internal[: last + 1])
    force = np.array(force)
    force[rows] = force_rows
    fwd = plant.forward(q[rows], dq[rows], tau, force[rows])
    return Simulation(times[rows], q[rows], dq[rows], tau, tau_cmd[rows], force[rows], q_ref[rows], dq_ref[rows], ddq_ref[rows],
                      fwd.ddq, fwd.N, fwd.residual, rate, stopped, plant.splits, elapsed, cpu, quantities=quantities,
                      observed=None if observed is None else observed[rows],
                      current=None if drives is None else current[rows], tau_motor=tau_motor, limit=limit)


_TAU, _F_B = (PLANT_INPUTS.slices()[name] for name in ("tau", "F_B"))
# A drive's numbers as :func:`drive_tick_kernel` takes them (:class:`chewbot.model.Drive`'s fields).
DRIVE = Layout.of(gear_ratio=1, efficiency=1, torque_constant=1)


def drive_tick_kernel() -> KernelSpec:
    """The drives at a tick, compiled (the loss law's Newton iteration is a few hundred NumPy calls a tick):
    (tau_cmd (6), limit, the crank rates the controller sees and the plant's (6 each, rad/s), the controller's model's
    drive and the plant's (:data:`DRIVE`)) -> the commands saturated at the limit (N m), the motors' currents the
    controller commands for them through its drive (A), the crank torques the plant's drive makes of those currents
    (N m) (:mod:`chewbot.model.drive`)."""

    def build(params):
        tau, limit, seen, rates = ca.SX.sym("tau_cmd", 6), ca.SX.sym("limit"), ca.SX.sym("dtheta_seen", 6), ca.SX.sym("dtheta", 6)
        (c, ours), (p, theirs) = DRIVE.symbols("drive_c", ca.SX.sym), DRIVE.symbols("drive_p", ca.SX.sym)
        ours, theirs = SimpleNamespace(**ours), SimpleNamespace(**theirs)
        tau_k = ca.fmin(ca.fmax(tau, -limit), limit)
        current = drive_law.current(ours, drive_law.motor_torque(ours, tau_k, seen))
        applied = drive_law.crank_torque(theirs, drive_law.torque_of_current(theirs, current), rates)
        return ca.Function("drive_tick", [tau, limit, seen, rates, c, p], [tau_k, current, applied],
                           ["tau_cmd", "limit", "dtheta_seen", "dtheta", "drive_c", "drive_p"], ["tau", "current", "applied"],
                           {"cse": True})

    return KernelSpec("drive_tick", build, ("drive-tick",))


def _held(tau: np.ndarray, reference: Reference, tick=None) -> StageInputs:
    """The plant's stage inputs under held torques (:data:`~chewbot.simulation.interfaces.PLANT_INPUTS`, one column
    per stage): the torques and the bite force at the stage times. ``tick``: (t0, h, the forces at its stages (3, 3))
    of the whole tick's step, used where the step is that one."""
    W = np.empty((PLANT_INPUTS.size, STAGES))
    W[_TAU] = tau[:, None]

    def inputs(t0: float, h: float) -> np.ndarray:
        if tick is not None and t0 == tick[0] and h == tick[1]:
            W[_F_B] = tick[2].T
        else:
            W[_F_B] = reference.force_at(stage_times(t0, h)).T
        return W
    return inputs


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
