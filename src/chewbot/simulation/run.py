"""A simulation run: options -> the controller's model, the plant, the reference -> the closed loop -> a results folder.

What ``chewbot simulate`` computes and writes, as :mod:`chewbot.run.pipeline` does for ``chewbot run``: the folder is
written whole through :func:`chewbot.files.atomic_folder` (results.csv, run.json, figures, report.html) and is
recognised later by its run.json (key ``chewbot_simulation``). ``--compare`` writes one such folder per controller
inside one comparison folder, with the comparison's own run.json, table and report.

The simulated motion is passed through the kinematics of the plant's model (:func:`solve_kinematics`), so that
results.csv has the columns of ``chewbot run`` (pose, crank angles, transmission angles, kappa_J) and the validity
checks of a run apply to it unchanged: the applied torques against the limits, the plant's normal forces N_L, N_R
(``contact-pull``), its bearing loads, crank range and speed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from chewbot.compiled.kernels import evaluate, native, prepare_kernels
from chewbot.errors import ChewbotError
from chewbot.kinematics.functions import kinematics_kernel
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.model.params import load_model, split_overrides
from chewbot.run.pipeline import input_files as run_inputs
from chewbot.run.pipeline import Chunk, load_task
from chewbot.model.chains import crank_tips
from chewbot.table import Table
from chewbot.run.columns import POSE_UNITS
from chewbot.kinematics.options import Orientation, Side
from chewbot.run.options import OptionError, RunOptions, Switch, refuse_unused, resolve_dynamics
from chewbot.rotation import matrix_from_euler_angles
from chewbot.simulation import COMPARED, CONTROLLERS
from chewbot.simulation.controllers import Gains, HybridController, ModelBasedController
from chewbot.simulation.observer import ForceObserver
from chewbot.simulation.forward import ORIENTATION, plant_outputs_kernel
from chewbot.simulation.plant import Plant
from chewbot.simulation.reference import Reference
from chewbot.simulation.sensor import CrankSensor
from chewbot.simulation.simulator import DEFAULT_RATE, Simulation, simulate
from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task



# The plant's engines: chewbot's own (chewbot.simulation.plant) and MuJoCo's simulation of the MJCF model
# (chewbot.simulation.mujoco_plant).
ENGINES = ("chewbot", "mujoco")


@dataclass
class SimulateOptions:
    """Everything that defines a simulation (recorded in run.json). ``rate`` None: ``--rate continuous``;
    ``friction`` the plant's ("on"/"off"); ``overrides`` the controller's model and the default task (``--set``),
    ``plant_overrides`` the plant's only (``--plant-set``); ``noise_rad`` the standard deviation of the crank
    encoders' noise; ``sensor`` what the controller is given: "exact" (the plant's state) or "measured" (the estimate
    from the crank angles, :class:`~chewbot.simulation.sensor.CrankSensor`; None: "measured" with noise or with
    ``exported``, else "exact"); ``exported``: the controller is the exported C step (run through ctypes, the sensor
    then "measured", the one path the C step has); ``engine`` the plant's engine (:data:`ENGINES`)."""

    controller: str = "computed-torque"
    model: str = "target"
    task: str = "default"
    side: str | None = None
    method: str | None = None  # None: hessian (the default of Euler angles), recorded resolved
    goal: str | None = None
    friction: str = "off"
    contact: str = "bilateral"
    rate: float | None = DEFAULT_RATE
    noise_rad: float = 0.0
    seed: int = 0
    plant: str | None = None
    overrides: dict[str, float] = field(default_factory=dict)
    plant_overrides: dict[str, float] = field(default_factory=dict)
    bite_unknown: bool = False
    gains: str | None = None
    gain_overrides: dict[str, float] = field(default_factory=dict)
    food: str | None = None
    sensor: str | None = None
    exported: bool = False
    engine: str = "chewbot"

    @property
    def controller_friction(self) -> bool:
        """Friction in the controller's model: where its formulation has friction (newton-euler), and only where the
        plant has it on."""
        from chewbot.dynamics.registry import formulation

        return "friction" in formulation(self.method).options and self.friction == Switch.on

    def refuse_unused(self, controllers: tuple[str, ...]) -> None:
        """:class:`~chewbot.run.options.OptionError` for an option that none of ``controllers`` uses, naming what
        would use it: ``method``, ``goal`` and ``bite_unknown`` (the inverse dynamics of the model-based controllers,
        not pd's), the gains of a controller that does not run, the estimator's cut-off without sensor noise."""
        model_based = [c for c in CONTROLLERS if c != "pd"]
        if not set(controllers) & set(model_based):
            for option, given in (("method", self.method is not None), ("goal", self.goal is not None), ("bite-unknown", self.bite_unknown)):
                if given:
                    raise OptionError(option, f"applies to the model-based controllers ({' and '.join(model_based)}), not "
                                      f"{' and '.join(controllers)} (PD on the crank angles uses no inverse dynamics)")
        for key, value in self.gain_overrides.items():
            section = key.split(".", 1)[0]
            kind = section.replace("_", "-")
            if kind in CONTROLLERS and kind not in controllers:
                raise OptionError(f"gain {key}={value:g}", f"changes nothing: it is a gain of --controller {kind}, and "
                                  f"this simulation runs {' and '.join(controllers)}")
            if section == "estimator" and not (self.noise_rad > 0 or self.exported or self.sensor == "measured"):
                raise OptionError(f"gain {key}={value:g}", "changes nothing: the estimator runs only with sensor noise "
                                  "(--noise RAD > 0); without it the controller sees the plant's state")

    def resolved(self, has_hkp: bool | None = None, controllers: tuple[str, ...] | None = None) -> SimulateOptions:
        """These options checked and completed by the rules of a run (:func:`chewbot.run.options.resolve_dynamics`):
        the controller's method, its goal where it distributes the target's torques; the plant's friction switch,
        the side, the contact model; :class:`~chewbot.run.options.OptionError` names an option that does not apply.
        The controller computes in Euler angles. ``has_hkp``: the controller's model is the target (None: read from
        its file where a rule needs it). ``controllers``: the controllers that will run (``--compare``: all three);
        given, an option none of them uses is an error too (:meth:`refuse_unused`)."""
        if controllers is not None:
            self.refuse_unused(controllers)
        for option, value, kind in (("side", self.side, Side), ("friction", self.friction, Switch)):
            if value is not None and value not in tuple(kind):
                raise OptionError(option, f"must be one of {', '.join(kind)}, not {value!r}")
        if self.engine not in ENGINES:
            raise OptionError("plant-engine", f"must be one of {', '.join(ENGINES)}, not {self.engine!r}")
        if self.engine == "mujoco" and self.rate is None:
            raise OptionError("rate", "the MuJoCo plant runs the controller at the ticks of a control rate, not 'continuous'")
        d = resolve_dynamics(self.method, Orientation.euler_angles.value, self.goal, None, self.contact, has_hkp=has_hkp,
                             model=self.model)
        for option, overrides in (("set", self.overrides), ("plant-set", self.plant_overrides)):
            refuse_unused(overrides, option, friction=self.friction == Switch.on, contact=d.contact,
                          friction_users="the plant with --friction on (and a newton-euler controller's model with it)")
        sensor = self.sensor or ("measured" if self.noise_rad > 0 or self.exported else "exact")
        if sensor not in SENSORS:
            raise OptionError("sensor", f"must be one of {', '.join(SENSORS)}, not {sensor!r}")
        if sensor == "exact" and self.noise_rad > 0:
            raise OptionError("sensor", "exact gives the controller the plant's state: noise on the encoders needs --sensor measured")
        if self.exported:
            if sensor == "exact":
                raise OptionError("sensor", "the exported step estimates its state from the measured angles: --exported needs "
                                  "--sensor measured")
            if self.controller not in ("pd", "computed-torque"):
                raise OptionError("controller", f"--exported runs pd or computed-torque, not {self.controller}")
            if self.rate is None:
                raise OptionError("rate", "--exported runs the C step at the ticks of a control rate, not continuous")
        if sensor == "measured" and self.rate is None:
            raise OptionError(("noise", "sensor") if self.noise_rad > 0 else "sensor",
                              "read the encoders at the ticks of a control rate, not with --rate continuous")
        return replace(self, method=d.method, goal=d.goal, contact=d.contact, sensor=sensor)


@dataclass
class SimulateResult:
    """What a simulation computed, in memory (the folder holds the same). ``model`` is the controller's, ``plant``
    the simulated robot's; ``kinematics`` the simulated motion's, ``reference_kinematics`` the reference's (both
    on the plant's model); ``table`` results.csv; ``metrics`` the tracking figures (:func:`tracking_metrics`); ``files``
    other files of its folder by name (the MuJoCo plant's robot.xml)."""

    options: SimulateOptions
    model: Model
    plant: Model
    task: Task
    reference: Reference
    simulation: Simulation
    kinematics: Kinematics
    reference_kinematics: Kinematics
    table: Table
    metrics: dict
    gains: Gains
    checks: list = field(default_factory=list)
    info: dict = field(default_factory=dict)
    files: dict[str, str] = field(default_factory=dict)


def load_models(options: SimulateOptions) -> tuple[Model, Model, dict[str, float]]:
    """The controller's model (``--model`` with ``--set``), the plant's (``--plant`` or the controller's file, with
    ``--set`` when the plant is the same file, then ``--plant-set``), and the default task's overrides."""
    model_overrides, task_overrides = split_overrides(options.overrides)
    model = load_model(options.model, model_overrides)
    plant_base = model_overrides if options.plant is None else {}
    plant_overrides, plant_task = split_overrides(options.plant_overrides)
    if plant_task:
        raise ChewbotError(f"--plant-set {', '.join(f'task.{k}' for k in plant_task)}: the task is the controller's and the "
                           "plant's; change it with --set")
    plant = load_model(options.plant or options.model, {**plant_base, **plant_overrides})
    if plant.mechanism != model.mechanism:
        raise ChewbotError(f"--plant {options.plant}: a {plant.mechanism} model, but the controller's model {options.model} "
                           f"is a {model.mechanism}; the plant must be the same kind of robot")
    return model, plant, task_overrides


def build(options: SimulateOptions, task: Task | None = None, write_mjcf=None):
    """The options resolved (:meth:`SimulateOptions.resolved`, with the side in effect) and the parts of a simulation:
    controller's model, plant model, task, reference, gains, the controller, the plant and the sensor (None without
    noise). ``task``: a task built in memory instead of ``options.task`` (``chewbot tpa``). ``write_mjcf(model,
    friction) -> str``: the MJCF text of a model (:func:`chewbot.export.mjcf.mjcf`, handed down by the caller),
    needed by the MuJoCo engine."""
    model, plant_model, task_overrides = load_models(options)
    options = options.resolved(model.has_hkp)
    if task is None:
        task = load_task(options.task, model, options.side, task_overrides)
    options = replace(options, side=task.side)
    reference = Reference.from_task(model, task)
    gains = Gains.load(options.gains, model.mechanism, options.gain_overrides)
    if options.controller == "hybrid":
        if options.food is None:
            raise ChewbotError("--controller hybrid follows the task's Fz as a force reference by pressing on a food: give "
                               "--food FOOD (without one the bite force is the task's, which no controller can change)")
        if options.bite_unknown:
            raise ChewbotError("--bite-unknown: the hybrid controller knows no bite force but the one its observer estimates")
        controller = HybridController(model, reference, gains, options.method, options.goal, options.controller_friction)
    else:
        controller = ModelBasedController(options.controller, model, reference, gains, options.method, options.goal,
                                          options.controller_friction, not options.bite_unknown)
    if options.food is None:
        plant = make_plant(options.engine, plant_model, options.friction == "on", task.side, write_mjcf)
    elif options.engine != "chewbot":
        raise ChewbotError(f"--food {options.food}: the food's law is a plant force of chewbot's engine; it is not in the "
                           f"{options.engine} plant (leave out --plant-engine {options.engine})")
    else:
        plant = food_plant(options, plant_model, task, reference)
    sensor = CrankSensor(model, options.noise_rad, gains.cutoff, options.seed) if options.sensor == "measured" else None
    return options, model, plant_model, task, reference, gains, controller, plant, sensor


def make_plant(engine: str, model: Model, friction: bool, side: str, write_mjcf=None):
    """The plant of ``engine``: chewbot's :class:`Plant`, or a :class:`~chewbot.simulation.mujoco_plant.MujocoPlant` of
    the MJCF text ``write_mjcf(model, friction)``."""
    if engine == "chewbot":
        return Plant(model, friction=friction, side=side)
    if write_mjcf is None:
        raise ValueError("the MuJoCo engine needs write_mjcf, the MJCF writer (chewbot.export.mjcf.mjcf)")
    from chewbot.simulation.mujoco_plant import MujocoPlant

    return MujocoPlant(model, write_mjcf(model, friction), friction=friction, side=side)


def food_plant(options: SimulateOptions, plant_model: Model, task: Task, reference: Reference):
    """The plant with ``options.food`` on the molar of the task's side; refuses a task that carries a bite force
    (unless the controller takes it as its force reference), a task whose gap at its start is smaller than the
    sample, and continuous control."""
    from chewbot.food.law import load_food
    from chewbot.simulation.food import FORCE_REFERENCE_CONTROLLERS, FoodPlant, start_gap

    food = load_food(options.food)
    if options.rate is None:
        raise ChewbotError(f"--food {options.food}: the food's events are located between the ticks of a control rate; "
                           "--rate continuous is not available with a food")
    carries = np.flatnonzero(np.any(np.asarray(task.force) != 0, axis=1))
    if carries.size and options.controller not in FORCE_REFERENCE_CONTROLLERS:
        k = int(carries[0])
        raise ChewbotError(f"--task {options.task}: it carries a bite force (first at sample {k}, t = {task.t[k]:.6g} s, "
                           f"F = {np.round(task.force[k], 6).tolist()} N), but with --food {options.food} the bite force is "
                           f"the {food.name}'s; give a task without one (Fx = Fy = Fz = 0), or use --controller "
                           f"{' or '.join(FORCE_REFERENCE_CONTROLLERS)}, which reads its Fz as the force reference")
    g0 = start_gap(plant_model, task.side, reference.q[0], reference.dq[0])
    if g0 < food.height:
        raise ChewbotError(f"--food {options.food}: the {food.name} (h0 = {food.height * 1e3:.4g} mm) does not fit at the "
                           f"task's start: the gap at the {task.side} bite point is {g0 * 1e3:.4g} mm at sample 0 "
                           f"(t = {task.t[0]:.6g} s); start the task with the teeth at least h0 apart")
    return FoodPlant(plant_model, friction=options.friction == "on", side=task.side, food=food)


def compute(options: SimulateOptions, progress=None, check=None, task: Task | None = None, exported=None,
            write_mjcf=None) -> SimulateResult:
    """Simulate in memory (no files). ``progress(message, stage=None)`` is told each stage (the loop as the stage
    ``simulation``); ``check()`` is called in the loop and raises to stop it; ``task`` a task built in memory
    instead of ``options.task``. ``exported(controller, rate)``: with ``options.exported``, makes the controller
    that runs the exported C step in place of the built-in ``controller``
    (:class:`chewbot.export.controller.ExportedController`; the layer above passes it); its ``comparison()`` with the
    Python controller goes into run.json. ``write_mjcf`` as :func:`build`."""
    step = progress or (lambda msg, stage=None: None)
    step("models and task")
    options, model, plant_model, task, reference, gains, controller, plant, sensor = build(options, task, write_mjcf)
    loop_controller = controller
    if options.exported:
        if exported is None:
            raise ValueError("options.exported: pass exported(controller, rate), the exported step's controller")
        step("compiling the exported controller step")
        loop_controller = exported(controller, options.rate)
    label = f"simulation ({options.controller}, {'continuous' if options.rate is None else f'{options.rate:g} Hz'})"
    step(label, stage="simulation")
    t0 = time.perf_counter()
    duration = reference.end - reference.start

    loop_start = [t0]

    def loop_progress(fraction: float) -> None:  # the time simulated and the real-time factor, from the loop's start
        if fraction == 0:  # the kernels are ready: the loop starts
            loop_start[0] = time.perf_counter()
            return
        simulated = fraction * duration
        step(f"{label}: {simulated:.3g} of {duration:.3g} s simulated, "
             f"{simulated / max(time.perf_counter() - loop_start[0], 1e-9):.2g} x real time")

    observer = None
    if options.controller == "hybrid":
        observer = ForceObserver(model, gains.observer_cutoff, task.side, options.controller_friction)
    sim = simulate(plant, loop_controller, reference, options.rate, sensor, progress=loop_progress, check=check, observer=observer)
    timings = {"simulation_s": time.perf_counter() - t0, "loop_s": sim.elapsed_s, "loop_cpu_s": sim.cpu_s}
    step("kinematics of the simulated motion")
    prepare_kernels([kinematics_kernel(plant_model.mechanism, ORIENTATION), plant_outputs_kernel(plant_model.mechanism)])
    # the run's kinematics (no inverse dynamics) of the simulated motion and of the reference, on the plant's model
    kinematic = RunOptions(model=options.plant or options.model, orientation=ORIENTATION, method=None, contact=options.contact)
    motion = Chunk(plant_model, motion_task(plant_model, task, sim.t, sim.q, sim.dq, sim.ddq, sim.force), kinematic)
    ref_kin = Chunk(plant_model, motion_task(plant_model, task, sim.t, sim.q_ref, sim.dq_ref, sim.ddq_ref, sim.force, "reference"),
                    kinematic).kinematics
    kin = motion.kinematics
    drift = None
    if options.engine == "mujoco":  # the engine's own violations: chewbot's kinematics of q closes every constraint
        d = np.asarray(plant.drift)[:sim.n]
        drift = {"drift_chains": d[:, 0], **({"drift_hkp": d[:, 1]} if plant_model.has_hkp else {})}
    table = simulation_table(plant, sim, kin, motion.kinematic_columns, drift)
    metrics = tracking_metrics(sim, coordinate_names(plant_model))
    if observer is not None:
        metrics["force"] = add_force_control(table, sim, reference, controller)
    info = {"timings": timings, "simulation": simulation_info(sim, plant, controller, sensor), "tracking": metrics}
    if sim.food is not None:
        info["food"] = plant.info(sim.food)
    if loop_controller is not controller:
        info["simulation"]["exported"] = loop_controller.comparison()
    result = SimulateResult(options, model, plant_model, task, reference, sim, kin, ref_kin, table, metrics, gains, info=info,
                            files={"robot.xml": plant.xml} if options.engine == "mujoco" else {})
    step("validity checks")
    from chewbot.analysis.checks import run_checks

    result.checks = run_checks(plant_model, table, None, options.contact, planned=False)
    return result


def add_force_control(table: Table, sim: Simulation, reference: Reference, controller: HybridController) -> dict:
    """The force observer's and the hybrid controller's columns (the observed forces, the force reference, the
    controller's mode and its food-stiffness estimate) and the force-tracking figures: RMS and peak of the plant's
    Fz minus the task's Fz over the rows where the reference is not zero (N, and % of the reference's peak)."""
    table.add_block([f"{name}_obs" for name in ("Fx", "Fy", "Fz", "N_L", "N_R")], sim.observed, "N",
                    "the force observer's estimate (docs/bite_force.md): food force on the mandible, condyles' normal forces")
    F_ref = reference.force_at(sim.t)[:, 2]
    table.add("Fz_ref", F_ref, "N", "the hybrid controller's force reference: the task's Fz")
    log = np.array(controller.log[: sim.n]) if controller.log else np.zeros((0, 3))
    table.add("force_mode", log[:, 1], "1", "1 where z is force-controlled, 0 where position-controlled")
    table.add("stiffness_estimate", log[:, 2], "N/m", "the hybrid controller's estimate of the food's stiffness along z")
    active = F_ref != 0
    if not active.any():
        return {"rms_N": None, "peak_N": None, "rms_percent": None, "samples": 0}
    e = sim.force[active, 2] - F_ref[active]
    peak = float(np.abs(F_ref).max())
    rms = float(np.sqrt(np.mean(e**2)))
    return {"rms_N": rms, "peak_N": float(np.abs(e).max()), "rms_percent": 100 * rms / peak, "reference_peak_N": peak,
            "samples": int(active.sum())}


def coordinate_names(model: Model) -> tuple[str, ...]:
    """The independent coordinates of the mechanism, named as in task files."""
    return TARGET_COORDS if model.has_hkp else FULL_COORDS


def motion_task(model: Model, task: Task, t, q, dq, ddq, force, name: str = "simulated") -> Task:
    """A motion in the independent coordinates as a task (for the kinematics of the plant's model)."""
    return Task(f"{name} ({task.name})", t, coordinate_names(model), q, dq, ddq, force, task.side, task.source)


def coordinate_units(names) -> list[str]:
    """m or rad per coordinate name."""
    return [POSE_UNITS[("X", "Y", "Z", "alpha", "beta", "gamma").index(n)] for n in names]


def simulation_table(plant: Plant, sim: Simulation, kin: Kinematics, kinematic_columns: Table, drift: dict | None = None) -> Table:
    """results.csv of a simulation: ``kinematic_columns``, the columns of a run's kinematics of the plant's motion
    ``kin`` (:attr:`chewbot.run.pipeline.Chunk.kinematic_columns`), then the applied and the commanded torques, the
    reference and the tracking error in the independent coordinates, the plant's normal forces, bearing loads, the
    residual of its equations of motion and the drift of its constraints (``drift``: the engine's own, by column name;
    default: :func:`constraint_drift` of the simulated pose and crank angles)."""
    model = plant.model
    table = kinematic_columns
    table.add_block([f"tau{i + 1}" for i in range(6)], sim.tau, "N*m", "actuator torques applied to the plant (saturated at limits.torque_Nm)")
    table.add_block([f"tau_cmd{i + 1}" for i in range(6)], sim.tau_cmd, "N*m", "actuator torques the controller commanded")
    names = coordinate_names(model)
    units = coordinate_units(names)
    for j, (name, unit) in enumerate(zip(names, units)):
        table.add(f"{name}_ref", sim.q_ref[:, j], unit, "reference coordinate (the task, quintic Hermite between its samples)")
    for j, (name, unit) in enumerate(zip(names, units)):
        table.add(f"e_{name}", sim.q_ref[:, j] - sim.q[:, j], unit, "tracking error: reference minus simulated coordinate")
    fn = native(plant_outputs_kernel(model.mechanism))
    _, _, axial, radial, _ = evaluate(fn, sim.q, sim.dq, sim.ddq, sim.N, model.molar(plant.side), sim.force,
                                      float(plant.friction), model.vector())
    if model.has_hkp:
        table.add_block(["N_L", "N_R"], sim.N, "N", "normal force of the plane on the condyle, along n = (p1, 0, 1)/|.| (the plant's)")
    table.add_block([f"FG{i + 1}_axial" for i in range(6)], axial, "N", "axial force at the crank bearing G_i (the plant's)")
    table.add_block([f"FG{i + 1}_radial" for i in range(6)], radial, "N", "radial force at the crank bearing G_i (the plant's)")
    table.add("residual", sim.residual, "N*m", "largest residual of the plant's equations of motion at the row's accelerations")
    if sim.food is not None:
        table.add("food_compression", sim.food["compression"], "m", "the food's compression max(0, h0 - g), g the bite point's gap along {S}'s z")
        table.add("food_force", sim.food["force"], "N", "the food's normal force on the teeth (positive pushing them apart; Fz = -food_force)")
        table.add("food_broken", sim.food["broken"], "1", "1 once the food has broken (its fracture strain reached)")
    drift = constraint_drift(model, kin) if drift is None else drift
    for name, values in drift.items():
        table.add(name, values, "m", DRIFT_DESCRIPTIONS[name])
    return table


DRIFT_DESCRIPTIONS = {"drift_chains": "largest abs(|S_i M_i| - coupler length) of the simulated pose and crank angles",
                      "drift_hkp": "largest distance of a condyle from its socket's plane in the simulated pose"}


def constraint_drift(model: Model, kin: Kinematics) -> dict[str, np.ndarray]:
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


def held_durations(t: np.ndarray) -> np.ndarray:
    """How long each row's torques act: until the next row (the last row: as long as the one before)."""
    if len(t) < 2:
        return np.zeros(len(t))
    dt = np.diff(t)
    return np.append(dt, dt[-1])


def tracking_metrics(sim: Simulation, names) -> dict:
    """RMS and peak tracking error of the position (the norm of the translational errors, mm) and of the orientation
    (the norm of the angular errors, deg) and per coordinate, the peak applied torque, the time in saturation (s; a
    row counts for as long as its torques are held), the samples simulated and where the robot was stopped."""
    e = sim.q_ref - sim.q
    linear = [j for j, n in enumerate(names) if n in ("X", "Y", "Z")]
    angular = [j for j, n in enumerate(names) if n not in ("X", "Y", "Z")]
    pos_mm = np.linalg.norm(e[:, linear], axis=1) * 1e3
    ang_deg = np.degrees(np.linalg.norm(e[:, angular], axis=1))

    def rms(x):
        return float(np.sqrt(np.mean(x**2)))

    per = {}
    for j, n in enumerate(names):
        scale, unit = (1e3, "mm") if j in linear else (180 / np.pi, "deg")
        per[n] = {"rms": rms(e[:, j]) * scale, "peak": float(np.max(np.abs(e[:, j]))) * scale, "unit": unit}
    saturated = sim.saturated.any(axis=1)
    return {"rms_position_mm": rms(pos_mm), "peak_position_mm": float(pos_mm.max()), "rms_orientation_deg": rms(ang_deg),
            "peak_orientation_deg": float(ang_deg.max()), "per_coordinate": per,
            "peak_torque_Nm": float(np.max(np.abs(sim.tau))), "saturated_s": float(np.sum(held_durations(sim.t)[saturated])),
            "samples": int(sim.n), "duration_s": float(sim.t[-1] - sim.t[0]), "stopped": sim.stopped}


def simulation_info(sim: Simulation, plant, controller: ModelBasedController, sensor) -> dict:
    """What run.json says about the loop: the integrator, the control rate, the controller's model, the plant's."""
    if not isinstance(plant, Plant):
        return {**_loop_info(sim, controller, sensor), "plant": mujoco_info(plant)}
    from chewbot.dynamics.formulations.newton_euler import DELTA_F_G, DELTA_N, EPS_THETA_DOT, EPS_V_T
    from chewbot.simulation.integrator import TOLERANCE
    from chewbot.simulation.plant import MAX_STEP

    return {"integrator": {"method": "Radau IIA, 3 stages (order 5, L-stable), compiled", "max_step_s": MAX_STEP,
                           "stage_residual_tolerance_Nm": TOLERANCE, "split_steps": sim.splits,
                           "largest_residual_Nm": float(np.max(sim.residual))},
            **_loop_info(sim, controller, sensor),
            "plant": {"engine": "chewbot", "model": plant.model.name, "file": plant.model.source, "friction": plant.friction,
                      "contact": "bilateral: both contacts stay closed, N_L and N_R of either sign (contact-pull reports N < 0)"
                      if plant.model.has_hkp else None,
                      "friction_smoothing": {"eps_theta_dot_rad_s": EPS_THETA_DOT, "eps_v_T_m_s": EPS_V_T, "delta_N_N": DELTA_N,
                                             "delta_F_G_N": DELTA_F_G}}}


def mujoco_info(plant) -> dict:
    """run.json's plant of a MuJoCo simulation: the engine, its version and the solver settings read from the model."""
    import mujoco

    o = plant.mj.opt
    return {"engine": "mujoco", "mujoco_version": mujoco.__version__, "model": plant.model.name, "file": plant.model.source,
            "mjcf": "robot.xml", "friction": plant.friction,
            "contact": "unilateral: a sphere on a plane per condyle (MuJoCo contact pairs), N_L, N_R >= 0" if plant.model.has_hkp else None,
            "solver": {"timestep_s": float(o.timestep), "integrator": mujoco.mjtIntegrator(o.integrator).name,
                       "solver": mujoco.mjtSolver(o.solver).name, "iterations": int(o.iterations), "tolerance": float(o.tolerance),
                       "cone": mujoco.mjtCone(o.cone).name, "impratio": float(o.impratio), "noslip_iterations": int(o.noslip_iterations),
                       "equality_solref": plant.mj.eq_solref[0].tolist(), "equality_solimp": plant.mj.eq_solimp[0].tolist()},
            "residual": "residual column: chewbot's equations of motion at MuJoCo's accelerations and normal forces"}


def _loop_info(sim: Simulation, controller: ModelBasedController, sensor) -> dict:
    return {"control": {"rate_Hz": sim.rate, "hold": "zero-order hold between ticks" if sim.rate else "evaluated at every integrator stage",
                        "reference": "quintic Hermite interpolation of the task's q, dq, ddq between its samples"},
            "controller": {"kind": controller.kind, "model": controller.model.name, "method": controller.method,
                           "goal": controller.goal, "friction": controller.friction, "bite_force_known": controller.bite_known,
                           "gains": controller.gains.as_dict(),
                           **({"force_observer": {"cutoff_Hz": controller.gains.observer_cutoff,
                                                  "method": "the bite-force estimator at each tick (docs/bite_force.md)"}}
                              if controller.kind == "hybrid" else {})},
            "sensor": None if sensor is None else {"measured": True, "noise_rad": sensor.noise, "seed": sensor.seed, "velocity_cutoff_Hz": sensor.cutoff,
                                                   "estimator": "Gauss-Newton forward kinematics, filtered backward difference"}}


def compare(options: SimulateOptions, progress=None, check=None, write_mjcf=None) -> dict[str, SimulateResult]:
    """The three controllers on the same task and plant (``options.controller`` is ignored)."""
    return {kind: compute(replace(options, controller=kind), progress, check, write_mjcf=write_mjcf) for kind in COMPARED}




def compare_engines(options: SimulateOptions, progress=None, check=None, write_mjcf=None) -> dict[str, SimulateResult]:
    """One controller on the same task and model simulated by each engine of :data:`ENGINES` (``options.engine`` is
    ignored)."""
    return {engine: compute(replace(options, engine=engine), progress, check, write_mjcf=write_mjcf) for engine in ENGINES}


SENSORS = ("exact", "measured")


def input_files(options: SimulateOptions) -> list[Path]:
    """The files a simulation reads (task, parameter files, gains), which its output must not contain."""
    files = run_inputs(RunOptions(model=options.model, task=options.task))
    files += [Path(p) for p in (options.plant, options.gains, options.food) if p is not None]
    return [p for p in files if p.suffix.lower() in (".toml", ".csv")]


def comparison_table(results: dict[str, SimulateResult]) -> Table:
    """comparison.csv: one row per controller (the index of CONTROLLERS) or per engine (the index of ENGINES), the
    figures of :func:`tracking_metrics`."""
    table = Table()
    name, choices = ("controller", CONTROLLERS) if set(results) <= set(CONTROLLERS) else ("engine", ENGINES)
    table.add(name, np.array([choices.index(k) for k in results], float), "1",
              f"{name}: " + ", ".join(f"{i} {k}" for i, k in enumerate(choices)))
    for key, unit, what in (("rms_position_mm", "mm", "RMS position error"), ("peak_position_mm", "mm", "peak position error"),
                            ("rms_orientation_deg", "deg", "RMS orientation error"), ("peak_orientation_deg", "deg", "peak orientation error"),
                            ("peak_torque_Nm", "N*m", "peak applied torque"), ("saturated_s", "s", "time in saturation")):
        table.add(key.rsplit("_", 1)[0], np.array([r.metrics[key] for r in results.values()]), unit, what)
    table.add("stopped_at", np.array([np.nan if r.metrics["stopped"] is None else r.metrics["stopped"]["t"] for r in results.values()]),
              "s", "time the robot left the workspace (empty: it did not)")
    return table
