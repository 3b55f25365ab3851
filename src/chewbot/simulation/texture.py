"""The robot as a texture analyser: the two-bite test of :mod:`chewbot.food.tpa` simulated with the food in the plant.

:func:`run_tpa` builds the test as a point-path task (the bite point of ``side`` along {S}'s z, alpha pinned at 0:
:func:`chewbot.food.geometry.molar_path_task`), simulates it under position control (computed torque, the controller
not told the food's force: :mod:`chewbot.simulation.run` with the food in the plant), and computes Bourne's measures
twice: ``plant``, from the food's force in the plant and the plant's gap; ``estimated``, from what a robot would log,
the crank angles and the torques, through the bite-force estimator (:func:`chewbot.identification.force.estimate_angles`:
rates smoothed from the angles, F_B by least squares on the model's dynamics), and the gap from the angles' pose.
:func:`tpa_from_log` computes the second from a robot's log alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from chewbot.food.geometry import gap, largest_height, molar_path_task
from chewbot.food.law import Food, load_food
from chewbot.food.tpa import Protocol, TpaError, protocol, tpa_measures
from chewbot.model import Model
from chewbot.model.params import load_model
from chewbot.simulation.controllers.table import DEFAULT_CONTROLLER, controller_row
from chewbot.simulation.options import resolve
from chewbot.simulation.run import SimulateResult, compute


# The test's position controller: chewbot simulate's default, computed torque.
TPA_CONTROLLER = controller_row(DEFAULT_CONTROLLER)
# A texture analyser's crosshead is stiff: the test's computed-torque controller has its error dynamics at this
# frequency. Not told the food's force, it yields about 1 mm per 160 N along z at the molar (gains.toml's 30 Hz: 1 mm
# per 14 N, half a millimetre under the cheddar); --gain computed_torque.frequency_Hz=... overrides it.
TPA_FREQUENCY_HZ = 100.0


@dataclass(frozen=True)
class TpaOptions:
    """A texture test: the ``food`` (built-in name or file), ``compression`` (% of h0), ``speed`` (mm/s), ``pause``
    (s), ``side``, ``model`` (the robot's, controller and plant), ``gain_overrides`` of the computed-torque controller
    (``--gain``), ``rate`` (Hz)."""

    food: str
    compression: float = 50.0
    speed: float = 2.0
    pause: float = 2.0
    side: str = "left"
    model: str = "target"
    gain_overrides: dict = field(default_factory=dict)
    rate: float = 1000.0


@dataclass
class TpaResult:
    """A texture test: its options, the food, the protocol, the simulation, the measures (``plant`` and
    ``estimated``), the curves both were computed from and the largest sample height at the side (m)."""

    options: TpaOptions
    food: Food
    protocol: Protocol
    simulation: SimulateResult
    plant: dict
    estimated: dict | None
    curves: dict
    largest_height: float
    estimator: dict

    def record(self) -> dict:
        """tpa.json."""
        info = self.simulation.info.get("food", {})
        return {"chewbot_tpa": 1, "options": vars(self.options), "food": self.food.as_dict(),
                "protocol": {"start_gap_mm": self.protocol.start_gap * 1e3, "deepest_gap_mm": self.protocol.deepest_gap * 1e3,
                             "speed_mm_s": self.protocol.speed * 1e3, "pause_s": self.protocol.pause,
                             "duration_s": self.protocol.duration, "controller": TPA_CONTROLLER.name,
                             "pinned": "alpha = 0"},
                "largest_height_mm": {self.options.side: self.largest_height * 1e3},
                "deepest_compression_mm": info.get("deepest_compression_m", 0.0) * 1e3,
                "tilt_at_deepest_deg": info.get("tilt_at_deepest_deg"), "events": info.get("events", []),
                "plant": self.plant, "estimated": self.estimated, "estimator": self.estimator,
                "definitions": "docs/food.md#texture-profile-analysis"}


def check_height(model: Model, food: Food, side: str) -> float:
    """The largest sample height at ``side`` (m); a :class:`TpaError` naming the sample where it is taller."""
    h_max = largest_height(model, side)
    if food.height > h_max:
        raise TpaError(f"the {food.name} (h0 = {food.height * 1e3:.4g} mm) is too tall for a texture test at the {side} "
                       f"molar of {model.name}: the bite point opens at most {(h_max + 1e-3) * 1e3:.4g} mm along z with alpha "
                       f"= 0, so the largest sample is {h_max * 1e3:.4g} mm (the test starts at h0 + 1 mm)")
    return h_max


def run_tpa(options: TpaOptions, progress=None, check=None) -> TpaResult:
    """Build, simulate and analyse the two-bite test (module docstring)."""
    step = progress or (lambda msg, stage=None: None)
    step("food, protocol and task")
    food = load_food(options.food)
    model = load_model(options.model)
    h_max = check_height(model, food, options.side)
    p = replace(protocol(food.height, options.compression, options.speed, options.pause), rate=options.rate)
    t = p.times()
    task = molar_path_task(model, options.side, t, *p.path(t), name=f"texture test of the {food.name}")
    gains = {f"{TPA_CONTROLLER.gains}.frequency_Hz": TPA_FREQUENCY_HZ, **options.gain_overrides}
    sim_options = resolve(TPA_CONTROLLER, model=options.model, side=options.side, rate=options.rate, gain_overrides=gains,
                          food=options.food)
    result = compute(sim_options, progress=step, check=check, task=task)
    sim = result.simulation
    g_plant = food.height - sim.quantities["delta"]
    plant = tpa_measures(sim.t, g_plant, sim.quantities["force"])
    step("bite force from the torques")
    curve, estimator = estimate_from_log(result.plant_model, simulated_log(result), options.side)
    estimated_measures = tpa_measures(curve["t"], curve["gap"], curve["force"])
    curves = {"t": sim.t, "gap_plant": g_plant, "force_plant": sim.quantities["force"], "gap_estimated": curve["gap"],
              "force_estimated": curve["force"], "force_estimated_se": curve["se"]}
    return TpaResult(options, food, p, result, plant, estimated_measures, curves, h_max, estimator)


def estimate_from_log(model: Model, log, side: str) -> tuple[dict, dict]:
    """The sample's force along the gap from a log's crank angles and torques: the motion as ``chewbot identify``
    recovers it (poses by least squares on the angles, rates smoothed from them unless logged), the force by the
    bite-force estimator (friction as in ``model``'s plant: off), the gap from the recovered poses. Returns the curve
    {"t", "gap", "force", "se"} and what tpa.json says of the estimator."""
    from chewbot.dynamics.bite_force import estimate
    from chewbot.identification.motion import log_motion

    motion = log_motion(model, log, side)
    est = estimate(model, motion.kin, log.tau, side=side, friction=False)
    q, dq, _ = motion.kin.euler_angle_state()
    curve = {"t": est.t, "gap": gap(model, side, q, dq)["gap"], "force": -est.F_B[:, 2], "se": est.se[:, 2]}
    return curve, {"method": "chewbot.dynamics.bite_force.estimate on the motion recovered from the crank angles "
                             "(chewbot.identification.motion.log_motion), the model's friction off",
                   "rates": motion.rates, "window_samples": motion.window_samples, "sigma_Nm": est.sigma,
                   "ill_conditioned_samples": int(np.size(est.ill_conditioned)), "warnings": list(est.warnings)}


def simulated_log(result: SimulateResult):
    """What the robot would log in a simulation: times, crank angles and applied torques (no rates, no force)."""
    from chewbot.identification.log import RobotLog

    sim = result.simulation
    n = sim.t.size
    return RobotLog(f"simulated {result.task.name}", sim.t, result.kinematics.theta, None, None, sim.tau, np.zeros((n, 3)),
                    np.arange(n) + 2)


def tpa_from_log(path, model_name: str = "target", side: str = "left") -> tuple[dict, dict, dict]:
    """Bourne's measures of a robot's logged two-bite test (``chewbot identify``'s log format): (measures, curve,
    estimator)."""
    from chewbot.identification.log import read_log

    model = load_model(model_name)
    log = read_log(path)
    curve, estimator = estimate_from_log(model, log, side)
    return tpa_measures(curve["t"], curve["gap"], curve["force"]), curve, estimator


__all__ = ["TPA_FREQUENCY_HZ", "TpaError", "TpaOptions", "TpaResult", "check_height", "estimate_from_log", "run_tpa", "simulated_log", "tpa_from_log"]
