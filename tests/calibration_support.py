"""The lab's calibration chain with chewbot's plant as the robot, shared by tests/test_calibration.py and the table of
docs/bite_force.md: an excitation task (chewbot excite's design), its log on a plant whose parameters are off from
the nominal model, the identified model (written as chewbot identify writes it), a texture test of a food on the
same plant and its log as a robot records it (angles and torques, no rates). Not a test module."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from chewbot.food.geometry import gap, molar_path_task
from chewbot.food.law import load_food
from chewbot.food.tpa import protocol, tpa_measures
from chewbot.identification.excitation import design
from chewbot.identification.identifier import identify
from chewbot.identification.log import RobotLog
from chewbot.identification.output import model_text
from chewbot.model.params import load_model
from chewbot.simulation.options import resolve
from chewbot.simulation.run import compute
from chewbot.simulation.texture import simulated_log
from chewbot.task.csvio import task_table

# The plant's assumed friction coefficients (the built-in target's), and its inertias.
FRICTION = {"friction.hkp_coulomb": 0.1, "friction.hkp_viscous_Ns_per_m": 0.5, "friction.actuator_coulomb": 0.05,
            "friction.actuator_viscous_Nms_per_rad": 0.01}
CRANKS = (3510.0, 3510.0, 6630.0, 6630.0, 17628.0, 17628.0)
MANDIBLE_DIAGONAL = (820091.15, 423459.18, 818784.7)
MASS_G = 340.22


@functools.cache
def excitation(folder: str, duration: float = 4.0, seed: int = 0):
    """(the design, the path of its task CSV) for the target: ``duration`` s of chewbot excite's series."""
    nominal = load_model("target")
    d = design(nominal, seed=seed)
    path = Path(folder) / f"excitation_{seed}_{duration:g}.csv"
    task_table(d.task(nominal, duration, 1000.0)).to_csv(path)
    return d, path


def drawn_plant(seed: int, mass_factor: float = 1.05) -> dict[str, float]:
    """A plant as a lab gets it wrong: each friction coefficient off by up to +-30 %, each crank inertia by +-20 %, the
    mandible's principal moments by +-10 % (uniform), the mass by ``mass_factor``."""
    rng = np.random.default_rng(seed)
    plant = {k: v * rng.uniform(0.7, 1.3) for k, v in FRICTION.items()}
    plant["mandible.mass_g"] = MASS_G * mass_factor
    for i, J in enumerate(CRANKS):
        plant[f"cranks.inertia_g_mm2[{i + 1}]"] = J * rng.uniform(0.8, 1.2)
    for i, I in enumerate(MANDIBLE_DIAGONAL):
        plant[f"mandible.inertia_g_mm2[{i + 1}][{i + 1}]"] = I * rng.uniform(0.9, 1.1)
    return plant


def plant_log(task_path: Path, plant: dict[str, float], sigma_tau: float = 0.0, seed: int = 0, rates: bool = True):
    """The log of the excitation on the plant: the simulation's angles (and exact rates with ``rates``) and its
    applied torques with Gaussian noise of ``sigma_tau`` N*m (``seed``)."""
    r = excited(str(task_path), tuple(sorted(plant.items())))
    k, s = r.kinematics, r.simulation
    log = RobotLog("excitation", s.t, k.theta, k.dtheta if rates else None, k.ddtheta if rates else None, s.tau,
                   np.zeros((s.t.size, 3)), np.arange(s.t.size) + 2)
    return noisy(log, sigma_tau, seed)


def current_log(task_path: Path, plant: dict[str, float], sigma_i: float = 0.0, seed: int = 0) -> RobotLog:
    """The log of the excitation on the plant as a robot with a drive records it: the simulation's angles and exact
    rates, and the motors' currents the controller commanded (no torques), with Gaussian noise of ``sigma_i`` A."""
    r = excited(str(task_path), tuple(sorted(plant.items())))
    k, s = r.kinematics, r.simulation
    current = s.current + sigma_i * np.random.default_rng(seed).standard_normal(s.current.shape)
    return RobotLog("excitation (currents)", s.t, k.theta, k.dtheta, k.ddtheta, None, np.zeros((s.t.size, 3)),
                    np.arange(s.t.size) + 2, current=current)


@functools.cache
def excited(task_path: str, plant: tuple = ()):
    """chewbot simulate of the excitation task on the plant (``plant``: sorted overrides): computed torque with the
    nominal model's Newton-Euler dynamics, friction in the plant and the controller."""
    return compute(resolve(controller="computed-torque", task=task_path, method="newton-euler", friction="on",
                           plant_overrides=dict(plant)))


def noisy(log: RobotLog, sigma_tau: float, seed: int) -> RobotLog:
    """``log`` with Gaussian noise of ``sigma_tau`` N*m on its torques."""
    if not sigma_tau:
        return log
    tau = log.tau + sigma_tau * np.random.default_rng(seed).standard_normal(log.tau.shape)
    return RobotLog(log.source, log.t, log.theta, log.dtheta, log.ddtheta, tau, log.force, log.lines, log.force_given)


def identified_model(log: RobotLog, path: Path, **options):
    """The model chewbot identify writes for ``log`` (from the built-in target), loaded; and the identification."""
    nominal = load_model("target")
    result = identify(nominal, log, **options)
    path.write_text(model_text(Path(nominal.source).read_text("utf-8"), result.values(), result.identified, ["# test"], {},
                               result.uncertainty()), encoding="utf-8")
    return load_model(str(path)), result


# The bandwidth of the computed-torque loop these texture tests run under (Hz): stiff enough to hold the crosshead's
# path under the food's load, as a texture analyser's crosshead is.
TEXTURE_FREQUENCY_HZ = 100.0

@functools.cache
def texture_test(food: str, plant: tuple = (), speed_mm_s: float = 4.0, friction: str = "on", pause_s: float = 1.0,
                 encoder_noise: float = 0.0):
    """The two-bite test of ``food`` on the plant (``plant``: sorted overrides), as chewbot tpa simulates it with the
    nominal model in the controller: (the simulation, the robot's log of it: angles and torques). ``encoder_noise``
    (rad): the encoders' noise in the loop (the controller's state estimate; the log has the plant's angles)."""
    nominal = load_model("target")
    f = load_food(food)
    p = protocol(f.height, 50.0, speed_mm_s, pause_s)
    t = p.times()
    task = molar_path_task(nominal, "left", t, *p.path(t), name=f"texture test of the {f.name}")
    r = compute(resolve(controller="computed-torque", model="target", side="left", rate=1000.0, food=food,
                        gain_overrides={"computed_torque.frequency_Hz": TEXTURE_FREQUENCY_HZ}, friction=friction,
                        plant_overrides=dict(plant), noise_rad=encoder_noise), task=task)
    return r, simulated_log(r)


def hardness(result, force: np.ndarray) -> float:
    """The hardness (N) of a force curve along the plant's gap of a texture test's simulation."""
    q, dq, _ = result.kinematics.euler_angle_state()
    return tpa_measures(result.simulation.t, gap(result.plant_model, "left", q, dq)["gap"], force)["hardness_N"]


# The table (docs/bite_force.md): each log from chewbot's plant with one thing off, on the cheddar at the
# issue's protocol (2 mm/s, a 2 s pause); (name, plant overrides, plant friction, encoder noise, whether the estimate
# uses friction, whether a calibration can change it).
TABLE_CASES = (
    ("nothing (frictionless)", {}, "off", 0.0, False, False),
    ("mandible mass +5 %", {"mandible.mass_g": MASS_G * 1.05}, "off", 0.0, False, True),
    ("the plant with its friction, exact model", {}, "on", 0.0, True, False),
    ("friction -30 %", {k: 0.7 * v for k, v in FRICTION.items()}, "on", 0.0, True, True),
    ("friction +30 %", {k: 1.3 * v for k, v in FRICTION.items()}, "on", 0.0, True, True),
    ("encoder noise 1e-4 rad in the loop", {}, "off", 1e-4, False, False),
)


def table_row(case, folder: Path, calibrate: bool) -> dict:
    """One row of the table: the RMS and the largest error of Fz (N), the hardness error (%) and the share of the
    samples outside the 95 % interval, estimated with the nominal model and, where ``calibrate`` and the case can
    change it, with the model identified from the plant's excitation log (4 s, exact rates, 1 mN*m of torque noise;
    the file's mass given)."""
    from chewbot.identification.force import estimate_log

    name, plant, friction, noise, with_friction, calibrable = case
    r, log = texture_test("cheddar", tuple(sorted(plant.items())), 2.0, friction, 2.0, noise)
    F = r.simulation.quantities["force"]
    models = {"nominal": load_model("target")}
    if calibrate and calibrable:
        _, path = excitation(str(folder))
        models["calibrated"] = identified_model(plant_log(path, plant, 1e-3, 0), folder / f"table_{abs(hash(name))}.toml")[0]
    row = {"case": name}
    for label, model in models.items():
        est = estimate_log(model, log, friction=with_friction)
        err = -est.F_B[:, 2] - F
        low, high = est.interval()
        outside = ~((-high[:, 2] <= F) & (F <= -low[:, 2]))
        row[label] = {"rms_N": float(np.sqrt(np.mean(err**2))), "max_N": float(np.abs(err).max()),
                      "hardness_percent": 100 * (hardness(r, -est.F_B[:, 2]) / hardness(r, F) - 1),
                      "outside_percent": 100 * float(np.mean(outside))}
    return row
