"""A simulation run: options -> the controller's model, the plant, the reference -> the closed loop -> a results folder.

What ``chewbot simulate`` computes and writes, as :mod:`chewbot.run.pipeline` does for ``chewbot run``: the folder is
written whole through :func:`chewbot.files.atomic_folder` (results.csv, run.json, figures, report.html) and is
recognised later by its run.json (key ``chewbot_simulation``). ``--compare`` writes one such folder per controller
inside one comparison folder, with the comparison's own run.json, table and report.

The options come resolved (:func:`chewbot.simulation.options.resolve`); :func:`build` makes the parts from them and
their tables: the controller of its row (:data:`~chewbot.simulation.controllers.table.CONTROLLERS`), the plant of its
engine (:data:`~chewbot.simulation.engines.ENGINES`), the sensor and the force observer where they are needed. Names:
``plant_file`` is the plant's parameter file (or built-in name), ``plant_model`` the :class:`~chewbot.model.Model` read
from it, ``plant`` the simulated plant (:class:`~chewbot.simulation.interfaces.Plant`).

The simulated motion is passed through the kinematics of the plant's model (:func:`solve_kinematics`), so that
results.csv has the columns of ``chewbot run`` (pose, crank angles, transmission angles, kappa_J) and the validity
checks of a run apply to it unchanged: the applied torques against the limits, the plant's normal forces N_L, N_R
(``contact-pull``), its bearing loads, crank range and speed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from chewbot.compiled.kernels import evaluate, native, prepare_kernels
from chewbot.errors import ChewbotError
from chewbot.dynamics.g1 import CONTROLLER_MARGIN_N
from chewbot.dynamics.options import Contact
from chewbot.kinematics.functions import kinematics_kernel
from chewbot.kinematics.motion import Kinematics
from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task
from chewbot.model import Model
from chewbot.model.params import load_model, split_overrides
from chewbot.run.columns import POSE_UNITS
from chewbot.run.options import RunOptions
from chewbot.run.pipeline import Chunk, load_task
from chewbot.run.pipeline import input_files as run_inputs
from chewbot.simulation.controllers.gains import Gains
from chewbot.simulation.controllers.law import ControllerParts
from chewbot.simulation.controllers.table import CONTROLLERS
from chewbot.simulation.engines import ENGINES, make_plant
from chewbot.simulation.forward import ORIENTATION, plant_outputs_kernel
from chewbot.simulation.interfaces import Controller, Plant
from chewbot.simulation.plant import DRIFT_DESCRIPTIONS
from chewbot.simulation.observer import ForceObserver
from chewbot.simulation.options import SimulationOptions
from chewbot.simulation.reference import Reference
from chewbot.simulation.sensor import CrankSensor
from chewbot.simulation.simulator import Simulation, simulate
from chewbot.table import Table
from chewbot.units import factor, shown

MM = factor("mm")


@dataclass
class SimulateResult:
    """What a simulation computed, in memory (the folder holds the same). ``model`` is the controller's,
    ``plant_model`` the simulated robot's; ``kinematics`` the simulated motion's, ``reference_kinematics`` the
    reference's (both on the plant's model); ``table`` results.csv; ``metrics`` the tracking figures
    (:func:`tracking_metrics`); ``files`` other files of its folder by name (the MuJoCo plant's robot.xml)."""

    options: SimulationOptions
    model: Model
    plant_model: Model
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

    @property
    def record(self) -> dict:
        """run.json's ``"options"``, with the side in effect (the task's)."""
        return self.options.record(self.task.side)

    def frame(self):
        """results.csv's columns as a pandas DataFrame: plain names (``tau1``), units in ``frame.attrs["units"]``,
        descriptions in ``frame.attrs["descriptions"]`` (as :func:`chewbot.read_results` reads a folder)."""
        import pandas as pd

        frame = pd.DataFrame(dict(self.table.columns))
        frame.attrs["units"], frame.attrs["descriptions"] = dict(self.table.units), dict(self.table.descriptions)
        return frame


@dataclass(frozen=True)
class Parts:
    """The parts of a simulation built from its options (:func:`build`): the controller's ``model``, the
    ``plant_model``, the ``task``, its ``reference``, the ``gains``, the ``controller``, the ``plant``, the ``sensor``
    (None: the controller is given the plant's state) and the force ``observer`` (None where the controller needs
    none)."""

    model: Model
    plant_model: Model
    task: Task
    reference: Reference
    gains: Gains
    controller: Controller
    plant: Plant
    sensor: CrankSensor | None
    observer: ForceObserver | None


def load_models(options: SimulationOptions, models: tuple[Model | None, Model | None] = (None, None)) -> tuple[Model, Model, dict[str, float]]:
    """The controller's model (``--model`` with ``--set``), the plant's (``--plant`` or the controller's file, with
    ``--set`` when the plant is the same file, then ``--plant-set``), and the default task's overrides. ``models``:
    the controller's and the plant's models given in memory instead of read (None: read; the plant defaults to the
    controller's)."""
    model_overrides, task_overrides = split_overrides(options.overrides)
    model = models[0] or load_model(options.model, model_overrides)
    plant_base = model_overrides if options.plant_file is None else {}
    if models[1] is not None:
        plant_model = models[1]
    elif models[0] is not None and options.plant_file is None:
        plant_model = models[0]
    else:
        plant_model = load_model(options.plant_file or options.model, {**plant_base, **options.plant_overrides})
    if plant_model.mechanism != model.mechanism:
        raise ChewbotError(f"--plant {options.plant_file}: a {plant_model.mechanism} model, but the controller's model "
                           f"{options.model} is a {model.mechanism}; the plant must be the same kind of robot")
    return model, plant_model, task_overrides


def build(options: SimulationOptions, task: Task | None = None, write_mjcf=None, models=(None, None)) -> Parts:
    """The parts of a simulation (:class:`Parts`). ``task``: a task built in memory instead of ``options.task``
    (``chewbot tpa``). ``write_mjcf(model, friction) -> str``: the MJCF text of a model (:func:`chewbot.export.mjcf.mjcf`,
    handed down by the caller), for an engine that simulates MJCF; ``models`` as :func:`load_models`. Refuses, with a food, a task that carries a bite
    force (unless the controller reads it as its force reference) and a task whose gap at its start is smaller than
    the sample."""
    model, plant_model, task_overrides = load_models(options, models)
    if task is None:
        task = load_task(options.task, model, options.side, task_overrides)
    reference = Reference.from_task(model, task)
    gains = Gains.load(options.gains_file, model.mechanism, options.gain_overrides)
    food = None if options.food is None else load_food_for(options, plant_model, task, reference)
    plant = make_plant(options.engine, plant_model, options.friction, task.side, food, write_mjcf, options.bolus)
    row = options.controller
    controller = ControllerParts(row, model, reference, gains, options.inverse, not options.bite_unknown).build()
    sensor = (CrankSensor(model, options.noise_rad, gains["estimator"].cutoff_Hz, options.seed, plant_model.drive)
              if options.measured else None)
    observer = (ForceObserver(model, gains["observer"].cutoff_Hz, task.side, options.inverse.friction)
                if row.needs.observer else None)
    return Parts(model, plant_model, task, reference, gains, controller, plant, sensor, observer)


def load_food_for(options: SimulationOptions, plant_model: Model, task: Task, reference: Reference):
    """The food of ``options.food``, checked against the task: no bite force in the task unless the controller reads it
    as its force reference, and room for the sample at the task's start."""
    from chewbot.food.law import load_food
    from chewbot.simulation.food import start_gap

    food = load_food(options.food)
    carries = np.flatnonzero(np.any(np.asarray(task.force) != 0, axis=1))
    if carries.size and not options.controller.force_reference:
        k = int(carries[0])
        readers = " or ".join(r.name for r in CONTROLLERS.values() if r.force_reference)
        raise ChewbotError(f"--task {options.task}: it carries a bite force (first at sample {k}, t = {task.t[k]:.6g} s, "
                           f"F = {np.round(task.force[k], 6).tolist()} N), but with --food {options.food} the bite force is "
                           f"the {food.name}'s; give a task without one (Fx = Fy = Fz = 0), or use --controller {readers}, "
                           "which reads its Fz as the force reference")
    g0 = start_gap(plant_model, task.side, reference.q[0], reference.dq[0])
    if g0 < food.height:
        raise ChewbotError(f"--food {options.food}: the {food.name} (h0 = {food.height / MM:.4g} mm) does not fit at the "
                           f"task's start: the gap at the {task.side} bite point is {g0 / MM:.4g} mm at sample 0 "
                           f"(t = {task.t[0]:.6g} s); start the task with the teeth at least h0 apart")
    return food


def compute(options: SimulationOptions, progress=None, check=None, task: Task | None = None, exported=None,
            write_mjcf=None, models=(None, None)) -> SimulateResult:
    """Simulate in memory (no files). ``progress(message, stage=None)`` is told each stage (the loop as the stage
    ``simulation``); ``check()`` is called in the loop and raises to stop it; ``task`` a task built in memory
    instead of ``options.task``. ``exported(controller, rate)``: with ``options.exported``, makes the controller
    that runs the exported C step in place of the built-in ``controller``
    (:class:`chewbot.export.controller.ExportedController`; the layer above passes it); what it adds to run.json
    (:meth:`~chewbot.simulation.interfaces.Controller.info`: its comparison with the Python controller) goes there.
    ``write_mjcf`` and ``models`` as :func:`build`."""
    step = progress or (lambda msg, stage=None: None)
    step("models and task")
    parts = build(options, task, write_mjcf, models)
    model, plant_model, task, reference, plant = parts.model, parts.plant_model, parts.task, parts.reference, parts.plant
    if options.rate is None and model.drive != plant_model.drive:
        raise ChewbotError("--rate continuous applies the controller's torques to the plant as they are: the plant's "
                           f"drive ([drive] of {options.plant_file or options.model}) must be the controller's model's; "
                           "give a control rate (--rate HZ) to simulate a plant with another drive")
    loop_controller = parts.controller
    if options.exported:
        assert exported is not None, "options.exported: pass exported(controller, rate), the exported step's controller"
        step("compiling the exported controller step")
        loop_controller = exported(parts.controller, options.rate)
    label = f"simulation ({options.controller.name}, {'continuous' if options.rate is None else f'{options.rate:g} Hz'})"
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

    sim = simulate(plant, loop_controller, reference, options.rate, parts.sensor, progress=loop_progress, check=check,
                   observer=parts.observer, drive=model.drive)
    timings = {"simulation_s": time.perf_counter() - t0, "loop_s": sim.elapsed_s, "loop_cpu_s": sim.cpu_s}
    step("kinematics of the simulated motion")
    prepare_kernels([kinematics_kernel(plant_model.mechanism, ORIENTATION), plant_outputs_kernel(plant_model.mechanism)])
    # the run's kinematics (no inverse dynamics) of the simulated motion and of the reference, on the plant's model
    kinematic = RunOptions(model=options.plant_file or options.model, orientation=ORIENTATION, method=None, contact=options.contact)
    motion = Chunk(plant_model, motion_task(plant_model, task, sim.t, sim.q, sim.dq, sim.ddq, sim.force), kinematic)
    ref_kin = Chunk(plant_model, motion_task(plant_model, task, sim.t, sim.q_ref, sim.dq_ref, sim.ddq_ref, sim.force, "reference"),
                    kinematic).kinematics
    kin = motion.kinematics
    table = simulation_table(plant, sim, kin, motion.kinematic_columns)
    metrics = tracking_metrics(sim, coordinate_names(plant_model))
    add_control_columns(table, sim, parts.observer, loop_controller)
    if options.controller.force_reference:
        metrics["force"] = force_tracking(sim, reference)
    plant_info = plant.info(sim)
    info = {"timings": timings, "simulation": {**plant_info.pop("simulation"), **loop_info(sim, options, parts),
                                               **loop_controller.info()},
            "tracking": metrics, **plant_info}
    result = SimulateResult(options, model, plant_model, task, reference, sim, kin, ref_kin, table, metrics, parts.gains,
                            info=info, files=plant.files())
    step("validity checks")
    from chewbot.analysis.checks import run_checks

    result.checks = run_checks(plant_model, table, None, options.contact, planned=False)
    if plant.capabilities.food:
        from chewbot.simulation.food import food_checks

        result.checks += food_checks(sim, plant_info["food"])
    if options.controller.force_reference:
        result.checks.append(force_tracking_check(metrics["force"], sim))
    return result


# The force-tracking error a controller that follows the task's Fz may leave: 10 % RMS of the reference's peak (the
# hybrid law's force loop at its default gains tracks a 20 N bite on the gummy to a few per cent; an error of this size
# means the food could not give the force, or the teeth met).
FORCE_TRACKING_BOUND_PERCENT = 10.0


def force_tracking_check(tracking: dict, sim: Simulation):
    """``force-tracking``: the RMS of the plant's Fz minus the task's within :data:`FORCE_TRACKING_BOUND_PERCENT` of
    the reference's peak (a failure)."""
    from chewbot.analysis.checks import CheckResult

    rms = tracking.get("rms_percent")
    if rms is None:
        return CheckResult("force-tracking", None, None, None, None, "not evaluated: the task's force reference is zero",
                           "failure")
    ok = bool(rms <= FORCE_TRACKING_BOUND_PERCENT)
    return CheckResult("force-tracking", ok, 0 if ok else tracking["samples"], None, {"value": rms, "unit": "% RMS of the reference's peak"},
                       f"the bite force followed its reference to {rms:.3g} % RMS of its peak ({tracking['rms_N']:.3g} N RMS, "
                       f"{tracking['peak_N']:.3g} N at worst); allowed {FORCE_TRACKING_BOUND_PERCENT:g} %", "failure")


def add_control_columns(table: Table, sim: Simulation, observer, controller) -> None:
    """The force observer's columns (where one ran) and the controller's own (its internal state at the ticks)."""
    if observer is not None:
        table.add_block([f"{name}_obs" for name in ("Fx", "Fy", "Fz", "N_L", "N_R")], sim.observed, "N",
                        "the force observer's estimate (docs/bite_force.md): food force on the mandible, condyles' normal forces")
    for column in controller.columns(sim.t):
        table.add(*column)


def force_tracking(sim: Simulation, reference: Reference) -> dict:
    """The force-tracking figures of a controller that follows the task's Fz: RMS and peak of the plant's Fz minus the
    task's Fz over the rows where the reference is not zero (N, and % of the reference's peak)."""
    F_ref = reference.force_at(sim.t)[:, 2]
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


def simulation_table(plant, sim: Simulation, kin: Kinematics, kinematic_columns: Table) -> Table:
    """results.csv of a simulation: ``kinematic_columns``, the columns of a run's kinematics of the plant's motion
    ``kin`` (:attr:`chewbot.run.pipeline.Chunk.kinematic_columns`), then the applied and the commanded torques, the
    reference and the tracking error in the independent coordinates, the plant's normal forces, bearing loads, the
    residual of its equations of motion, the plant's own columns (a food's) and the drift of its constraints
    (:meth:`~chewbot.simulation.interfaces.Plant.drift`)."""
    model = plant.model
    table = kinematic_columns
    table.add_block([f"tau{i + 1}" for i in range(6)], sim.tau, "N*m", "actuator torques applied to the plant (saturated at limits.torque_Nm)")
    table.add_block([f"tau_cmd{i + 1}" for i in range(6)], sim.tau_cmd, "N*m", "actuator torques the controller commanded")
    if sim.current is not None:
        table.add_block([f"tau_motor{i + 1}" for i in range(6)], sim.tau_motor, "N*m", "motor torque of crank i's drive (the plant's)")
        table.add_block([f"i{i + 1}" for i in range(6)], sim.current, "A",
                        "motor current the controller commanded through its model's drive, held until the next row")
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
    for column in plant.columns(sim.quantities):
        table.add(*column)
    for name, values in plant.drift(kin, sim.n).items():
        table.add(name, values, "m", DRIFT_DESCRIPTIONS[name])
    return table


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
    (to_mm, mm), (to_deg, deg) = shown("m"), shown("rad")
    pos_mm = np.linalg.norm(e[:, linear], axis=1) * to_mm
    ang_deg = np.linalg.norm(e[:, angular], axis=1) * to_deg

    def rms(x):
        return float(np.sqrt(np.mean(x**2)))

    per = {}
    for j, n in enumerate(names):
        scale, unit = (to_mm, mm) if j in linear else (to_deg, deg)
        per[n] = {"rms": rms(e[:, j]) * scale, "peak": float(np.max(np.abs(e[:, j]))) * scale, "unit": unit}
    saturated = sim.saturated.any(axis=1)
    return {"rms_position_mm": rms(pos_mm), "peak_position_mm": float(pos_mm.max()), "rms_orientation_deg": rms(ang_deg),
            "peak_orientation_deg": float(ang_deg.max()), "per_coordinate": per,
            "peak_torque_Nm": float(np.max(np.abs(sim.tau))), "saturated_s": float(np.sum(held_durations(sim.t)[saturated])),
            "samples": int(sim.n), "duration_s": float(sim.t[-1] - sim.t[0]), "stopped": sim.stopped}


def loop_info(sim: Simulation, options: SimulationOptions, parts: Parts) -> dict:
    """What run.json says about the loop: the control rate and hold, the controller (its row, model, inverse dynamics,
    gains, the force observer where it has one), the sensor."""
    row, inverse, gains, sensor = options.controller, options.inverse, parts.gains, parts.sensor
    return {"control": {"rate_Hz": sim.rate, "hold": "zero-order hold between ticks" if sim.rate else "evaluated at every integrator stage",
                        "reference": "quintic Hermite interpolation of the task's q, dq, ddq between its samples"},
            "controller": {"kind": row.name, "model": parts.model.name, "method": inverse.method, "goal": inverse.goal,
                           "friction": inverse.friction, "contact": inverse.contact.value,
                           **({"contact_margin_N": CONTROLLER_MARGIN_N} if inverse.contact == Contact.unilateral else {}),
                           "bite_force_known": not options.bite_unknown, "gains": gains.as_dict(),
                           **({"force_observer": {"cutoff_Hz": parts.observer.cutoff,
                                                  "method": "the bite-force estimator at each tick, one compiled kernel "
                                                            "(chewbot.simulation.observer.tick_kernel, docs/bite_force.md)"}}
                              if parts.observer is not None else {})},
            "sensor": None if sensor is None else {"measured": True, "noise_rad": sensor.noise, "seed": sensor.seed, "velocity_cutoff_Hz": sensor.cutoff,
                                                   "estimator": "Gauss-Newton forward kinematics, filtered backward difference"}}


def compare(options: SimulationOptions, progress=None, check=None, write_mjcf=None, task: Task | None = None,
            models=(None, None)) -> dict[str, SimulateResult]:
    """The simulations of :meth:`~chewbot.simulation.options.SimulationOptions.runs`: the compared controllers on the
    same task and plant (``--compare``), or one controller on each engine (``--compare-engines``); the other arguments
    as :func:`compute`'s."""
    return {label: compute(o, progress, check, task, write_mjcf=write_mjcf, models=models) for label, o in options.runs().items()}


def input_files(options: SimulationOptions) -> list[Path]:
    """The files a simulation reads (task, parameter files, gains, food), which its output must not contain."""
    files = run_inputs(RunOptions(model=options.model, task=options.task))
    files += [Path(p) for p in (options.plant_file, options.gains_file, options.food) if p is not None]
    return [p for p in files if p.suffix.lower() in (".toml", ".csv")]


def comparison_table(results: dict[str, SimulateResult]) -> Table:
    """comparison.csv: one row per controller (the index of the controller table) or per engine (the index of the
    engine table), the figures of :func:`tracking_metrics`."""
    table = Table()
    name, choices = ("controller", tuple(CONTROLLERS)) if set(results) <= set(CONTROLLERS) else ("engine", tuple(ENGINES))
    table.add(name, np.array([choices.index(k) for k in results], float), "1",
              f"{name}: " + ", ".join(f"{i} {k}" for i, k in enumerate(choices)))
    for key, unit, what in (("rms_position_mm", "mm", "RMS position error"), ("peak_position_mm", "mm", "peak position error"),
                            ("rms_orientation_deg", "deg", "RMS orientation error"), ("peak_orientation_deg", "deg", "peak orientation error"),
                            ("peak_torque_Nm", "N*m", "peak applied torque"), ("saturated_s", "s", "time in saturation")):
        table.add(key.rsplit("_", 1)[0], np.array([r.metrics[key] for r in results.values()]), unit, what)
    table.add("stopped_at", np.array([np.nan if r.metrics["stopped"] is None else r.metrics["stopped"]["t"] for r in results.values()]),
              "s", "time the robot left the workspace (empty: it did not)")
    return table
