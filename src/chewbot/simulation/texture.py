"""The robot as a texture analyser: the two-bite protocol of :mod:`chewbot.food.tpa` held by the robot with the food
in the plant, its measures and its validity checks.

:func:`resolve_tpa` resolves the test's options once (:class:`TpaOptions`: the protocol of a texture analyser, the
robot's models, the plant's friction, the gains, a log). :func:`run_tpa` runs it as a texture analyser does:

1. **The trigger.** The molar point approaches from rest ``approach`` above the sample's highest point
   (:func:`start_gap`) along {S}'s z at the pre-test speed
   on the path that keeps the lower tooth's face as parallel to the upper one as a horizontal slide of at most
   ``slide`` from the sample's top allows (:func:`chewbot.food.geometry.face_path_task`) until the plant's food force
   (the analyser's load cell, the law integrated over the tilted face) reaches the trigger force; the gap there, the reference's, is the sample's height h_t as the analyser
   measures it. The approach is simulated until the trigger, the time of the trigger interpolated between the ticks.
2. **The test.** The profile from the trigger on (:class:`chewbot.food.tpa.Profile`: test speed to h_t (1 -
   compression), post-test speed back to h_t, pause, again, back to the start) is simulated from the start: the
   approach's samples are the same, so the trigger comes where it came. The robot is the model's robot with its
   friction (``--friction on``); the position loop is the ``crosshead`` controller
   (:mod:`chewbot.simulation.controllers.crosshead`: computed torque with integral action), its inverse dynamics
   Newton-Euler with the model's friction, given the force observer's estimate of the sample's force, its
   distribution of the redundant torques unilateral (N_L, N_R >= ``contact.preload_N`` +
   :data:`chewbot.dynamics.g1.CONTROLLER_MARGIN_N`: both condyles pressed on their planes while the sample pushes).
3. **The measures** (:func:`chewbot.food.tpa.analyse`, both readings) twice: ``plant``, from the food's force in the
   plant and the plant's gap, contact at the trigger force; ``estimated``, from what the robot logs, the crank angles
   and the torques, through the bite-force estimator with the model's friction (as ``chewbot estimate-force``), contact
   at :func:`estimate_trigger` (the trigger force or five times the estimate's noise, the larger).
4. **The checks** (:func:`texture_checks`): the simulation's own (torque limits, a condyle lifted off its plane under
   the unilateral contact model, ...), the food's (the teeth met), the protocol's (compression reached, speed held:
   :func:`chewbot.food.tpa.protocol_checks` on the plant's gap and force) and the energy readings of both analyses in
   [0, 1].

:func:`tpa_from_log` analyses a robot's logged test the same way from its angles and torques alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from chewbot.dynamics.options import Contact
from chewbot.food.geometry import face_path_task, gap, largest_height
from chewbot.food.law import Food, load_food
from chewbot.food.tpa import HOLD, MEASURES, Profile, Protocol, TpaAnalysis, TpaError, analyse, protocol_checks, settings
from chewbot.model import Model
from chewbot.simulation.controllers.table import TEXTURE_CONTROLLER, controller_row
from chewbot.simulation.options import SimulationOptions, resolve
from chewbot.simulation.run import SimulateResult, build, compute, load_models
from chewbot.simulation.simulator import simulate

# The bound on the bite point's horizontal slide from the sample's top (m), where --slide does not give one: a tenth
# of a 10 mm sample's face. The target's condyles' planes make the bite point slide about 0.9 mm per mm down while the
# face stays parallel: within 1 mm the first 1.1 mm of a stroke keep the faces parallel (where the sockets allow), and
# a 10 mm sample at 50 % tilts 3.1 degrees at its top and 0.1 at the deepest point instead of 6.4 and 3.2 with the
# bite point held still (docs/food.md).
SLIDE = 1e-3
# The test's position loop and its inverse dynamics: Newton-Euler, with the model's friction where the robot has it.
TPA_CONTROLLER = controller_row(TEXTURE_CONTROLLER)
TPA_METHOD = "newton-euler"
# The contact the test is judged under (a condyle lifted off its plane is a failed check) and the controller's
# distribution keeps: N_L, N_R >= contact.preload_N (+ the controller's margin), the redundant torques pressing the
# condyles while the food pushes, its force fed forward from the force observer.
TPA_CONTACT = Contact.unilateral
# The estimate's contact force is at least this many times its noise (1.4826 MAD of its sample-to-sample
# differences over sqrt 2: white noise's standard deviation, blind to a force that changes smoothly at 1 kHz): a
# 5-sigma threshold, which noise alone crosses at about 3e-7 of the samples.
NOISE_FACTOR = 5.0
# The estimated force's contact is where it reaches its contact force and stays above it this long (s): a compression
# lasts seconds, the estimate's excursions where the robot starts or stops moving (its friction model's share of the
# torques misread over the rates' smoothing window) tens of milliseconds.
CONTACT_HOLD = 0.1
# The approach is first simulated this far past the sample's unloaded top (m), then twice as far until it triggers.
TRIGGER_SEARCH = 0.5e-3


@dataclass(frozen=True)
class TpaOptions:
    """A texture test, resolved (:func:`resolve_tpa`): the ``food`` (built-in name or file; None with a log that gives
    none), the ``protocol`` (:class:`chewbot.food.tpa.Protocol`, SI), ``side``, ``model`` (the controller's and the
    estimator's), ``plant_file`` (the plant's; None: the model's) and ``plant_overrides``, ``friction`` (the robot's:
    the plant's, the controller's model's and the estimator's), ``gain_overrides``, ``rate`` (Hz), ``log`` (a robot's
    logged test: no simulation), ``simulation`` (the simulation's options, None with a log) and ``slide`` (m, the
    bound on the bite point's horizontal slide from the sample's top: :func:`chewbot.food.geometry.face_path_task`)."""

    food: str | None
    protocol: Protocol
    side: str = "left"
    model: str = "target"
    plant_file: str | None = None
    plant_overrides: dict = field(default_factory=dict)
    friction: bool = True
    gain_overrides: dict = field(default_factory=dict)
    rate: float = 1000.0
    log: str | None = None
    simulation: SimulationOptions | None = None
    slide: float = SLIDE

    def record(self) -> dict:
        """tpa.json's ``"options"``."""
        return {"food": self.food, "side": self.side, "model": self.model, "plant": self.plant_file,
                "plant_overrides": dict(self.plant_overrides), "friction": "on" if self.friction else "off",
                "gain_overrides": dict(self.gain_overrides), "rate_Hz": self.rate, "log": self.log,
                "controller": None if self.log else TPA_CONTROLLER.name, "method": None if self.log else TPA_METHOD,
                "slide_mm": None if self.log else self.slide * 1e3}


def resolve_tpa(food: str | None = None, *, compression: float | None = None, distance: float | None = None,
                speed: float = 2.0, pre_test_speed: float = 1.0, post_test_speed: float | None = None,
                trigger_force: float | None = None, pause: float = 5.0, side: str = "left", model: str = "target",
                plant_file: str | None = None, plant_overrides: dict | None = None, friction: bool | str = True,
                gain_overrides: dict | None = None, rate: float = 1000.0, log: str | None = None,
                slide: float | None = None) -> TpaOptions:
    """The options of ``chewbot tpa``, every rule written here once (the command line's units: %, mm, mm/s, N, s).
    :class:`TpaError` or :class:`chewbot.run.options.OptionError` name the option: a compression below 1 % (a
    fraction meant as a percentage), a compression with a distance, a food missing without a log, gains or a plant
    with a log (nothing is simulated), a slide bound that is not positive. ``compression`` defaults to 50 % unless
    ``distance`` is given; ``slide`` (mm) to :data:`SLIDE`."""
    from chewbot.food.tpa import TRIGGER_FORCE
    from chewbot.run.options import OptionError

    if isinstance(friction, str):
        if friction not in ("on", "off"):
            raise OptionError("friction", f"must be on or off, not {friction!r}")
        friction = friction == "on"
    if compression is None and distance is None:
        compression = 50.0  # a texture analyser's TPA default
    protocol = settings(compression, speed, pause, pre_test_speed_mm_s=pre_test_speed, post_test_speed_mm_s=post_test_speed,
                        trigger_force_N=TRIGGER_FORCE if trigger_force is None else trigger_force, distance_mm=distance)
    gain_overrides, plant_overrides = dict(gain_overrides or {}), dict(plant_overrides or {})
    if log is not None:
        for option, given in (("gain", gain_overrides), ("plant", plant_file), ("plant-set", plant_overrides),
                              ("slide", slide)):
            if given:
                raise OptionError(option, "does not apply to --log: a logged test is not simulated")
        return TpaOptions(food, protocol, side, model, None, {}, bool(friction), {}, rate, str(log))
    if food is None:
        raise OptionError("food", "required (the sample to test), unless --log gives a robot's logged test")
    if slide is not None and not slide > 0:
        raise OptionError("slide", f"must be a positive distance (mm), not {slide:g}")
    sim = resolve(TPA_CONTROLLER, model=model, side=side, method=TPA_METHOD, friction=bool(friction), rate=rate,
                  plant_file=plant_file, plant_overrides=plant_overrides, gain_overrides=gain_overrides, food=food,
                  contact=TPA_CONTACT)
    # the condyles rest on their planes: the controller distributes its redundant torques to keep them pressed
    sim = replace(sim, inverse=replace(sim.inverse, contact=TPA_CONTACT))
    return TpaOptions(food, protocol, side, model, plant_file, plant_overrides, bool(friction), gain_overrides, rate, None, sim,
                      SLIDE if slide is None else slide * 1e-3)


@dataclass
class TpaResult:
    """A simulated texture test: its options, the food, the profile as run, the simulation, the two analyses
    (``plant``, ``estimated``), the curves they were computed from, the largest sample height at the side (m), what
    the estimator did, the checks and the approach's trigger."""

    options: TpaOptions
    food: Food
    profile: Profile
    simulation: SimulateResult
    plant: TpaAnalysis
    estimated: TpaAnalysis
    curves: dict
    largest_height: float
    estimator: dict
    checks: list

    def record(self) -> dict:
        """tpa.json (``"chewbot_tpa": 2``)."""
        info = self.simulation.info.get("food", {})
        return {"chewbot_tpa": 2, "options": self.options.record(), "food": self.food.as_dict(),
                "protocol": self.profile.record(), "largest_height_mm": {self.options.side: self.largest_height * 1e3},
                "deepest_compression_mm": info.get("deepest_compression_m", 0.0) * 1e3,
                "tilt_at_deepest_deg": info.get("tilt_at_deepest_deg"), "face": self.face(),
                "events": info.get("events", []),
                "plant": self.plant.measures, "estimated": self.estimated.measures,
                "estimated_ci95": self.estimated.intervals,
                "definitions": self.plant.definitions, "anchors": {"plant": self.plant.anchors, "estimated": self.estimated.anchors},
                "estimator": self.estimator, "checks": [c.as_dict() for c in self.checks]}


    def face(self) -> dict:
        """The lower tooth's face in the test (mm, deg): its tilt against the upper tooth at the deepest point of the
        first bite and the largest while the sample is loaded, the spread of the gap across the sample's face there
        (its diameter x sin tilt), and the bite point's horizontal slide from where the trigger found the sample (at
        the deepest point, and the largest while loaded), beside the path's slide bound."""
        sim, model = self.simulation.simulation, self.simulation.plant_model
        g = gap(model, self.options.side, sim.q, sim.dq)
        loaded = np.flatnonzero(self.curves["force_plant"] > 0)
        k = int(np.argmin(self.curves["gap_plant"]))
        j = int(np.searchsorted(self.curves["t"], self.profile.trigger_time))
        slide = np.linalg.norm(g["point"][:, :2] - g["point"][j, :2], axis=1)
        diameter = 0.0 if self.food.diameter is None else self.food.diameter
        worst = loaded[np.argmax(g["tilt"][loaded])] if loaded.size else k
        return {"path": "the lower tooth translated (its face parallel to the upper tooth) while the bite point's "
                        "slide from the sample's top stays within the bound, then held at the bound with the tilt "
                        "the gap needs (chewbot.food.geometry.face_path_task)",
                "slide_bound_mm": self.options.slide * 1e3,
                "tilt_deg": float(np.degrees(g["tilt"][k])), "spread_mm": float(diameter * np.sin(g["tilt"][k]) * 1e3),
                "slide_mm": float(slide[k] * 1e3), "largest_tilt_loaded_deg": float(np.degrees(g["tilt"][worst])),
                "largest_spread_loaded_mm": float(diameter * np.sin(g["tilt"][worst]) * 1e3),
                "largest_slide_loaded_mm": float(np.max(slide[loaded]) * 1e3) if loaded.size else 0.0}


def check_height(model: Model, food: Food, side: str) -> float:
    """The largest sample height at ``side`` (m); a :class:`TpaError` naming the sample where it is taller."""
    h_max = largest_height(model, side)
    if food.height > h_max:
        raise TpaError(f"the {food.name} (h0 = {food.height * 1e3:.4g} mm) is too tall for a texture test at the {side} "
                       f"molar of {model.name}: the bite point opens at most {(h_max + 1e-3) * 1e3:.4g} mm along z with alpha "
                       f"= 0, so the largest sample is {h_max * 1e3:.4g} mm (the test starts at h0 + 1 mm)")
    return h_max


def start_gap(options: TpaOptions, model: Model, food: Food) -> float:
    """The gap (m) the test starts from: ``approach`` above the sample's highest point. Where the path tilts the face
    at the sample's top by theta, the face's edge stands a sin(theta) above its centre (a the face's radius), so the
    start is h0 + approach + a sin(theta), theta the path's tilt at h0 + approach (once: the tilt changes by about
    0.64 degrees per mm of gap, the edge's height then by a hundredth of a millimetre per millimetre of a 10 mm
    face, well inside the approach)."""
    p = options.protocol
    start = food.height + p.approach
    if food.diameter is None:
        return start
    deepest = p.target_gap(food.height)
    task = face_path_task(model, options.side, np.array([0.0, 1.0]), np.array([start, deepest]), np.zeros(2), np.zeros(2),
                          food.height, options.slide)
    return start + food.diameter / 2 * float(np.sin(gap(model, options.side, task.q[:1])["tilt"][0]))


def find_trigger(options: TpaOptions, model: Model, food: Food, check=None) -> float:
    """The time (s) the plant's food force first reaches the trigger force on the approach from :func:`start_gap` at
    the pre-test speed, interpolated between the ticks (the approach simulated until then)."""
    p = options.protocol
    start = start_gap(options, model, food)
    reach = p.approach + TRIGGER_SEARCH
    while True:
        t = np.arange(int(np.ceil((HOLD + p.blend + reach / p.pre_test_speed) * options.rate)) + 1) / options.rate
        task = face_path_task(model, options.side, t, *p.approach_path(start, t), food.height, options.slide,
                              name=f"approach to the {food.name}")
        parts = build(options.simulation, task)  # the loop alone: the approach's rows are not kept
        sim = simulate(parts.plant, parts.controller, parts.reference, options.rate, parts.sensor, check=check,
                       observer=parts.observer)
        F = sim.quantities["force"]
        hits = np.flatnonzero(F >= p.trigger_force)
        if hits.size:
            k = int(hits[0])
            w = (p.trigger_force - F[k - 1]) / (F[k] - F[k - 1])
            return float(sim.t[k - 1] + w * (sim.t[k] - sim.t[k - 1]))
        if reach >= start:
            raise TpaError(f"the {food.name} never pushed back {p.trigger_force:g} N (--trigger-force) before the teeth met")
        reach = min(2 * reach, start)


def run_tpa(options: TpaOptions, progress=None, check=None, simulated=None) -> TpaResult:
    """Trigger, test, measures and checks (module docstring). ``simulated(result)``: called with the test's
    simulation (:class:`~chewbot.simulation.run.SimulateResult`) as soon as it is done, before the estimate (the
    command writes its files meanwhile)."""
    step = progress or (lambda msg, stage=None: None)
    step("food, protocol and trigger")
    food = load_food(options.food)
    model, plant_model, _ = load_models(options.simulation)
    h_max = check_height(plant_model, food, options.side)
    step("the approach, until the trigger", stage="simulation")
    t_trigger = find_trigger(options, model, food, check)
    profile = options.protocol.profile(start_gap(options, model, food), t_trigger, options.rate)
    t = profile.times()
    task = face_path_task(model, options.side, t, *profile.path(t), food.height, options.slide,
                          name=f"texture test of the {food.name}")
    result = compute(options.simulation, progress=step, check=check, task=task)
    if simulated is not None:
        simulated(result)
    sim = result.simulation
    g_plant = gap(plant_model, options.side, sim.q, sim.dq)
    plant = analyse(sim.t, g_plant["gap"], sim.quantities["force"], options.protocol.trigger_force, label="plant")
    step("bite force from the torques")
    curve, estimator = estimate_from_log(model, simulated_log(result), options.side, options.friction)
    estimated = analyse_estimate(curve, estimator["contact_force_N"])
    curves = {"t": sim.t, "gap_plant": g_plant["gap"], "force_plant": sim.quantities["force"], "gap_estimated": curve["gap"],
              "force_estimated": curve["force"], "force_estimated_se": curve["se"],
              "force_estimated_low95": curve["low95"], "force_estimated_high95": curve["high95"]}
    checks = texture_checks(result, food, profile, g_plant, plant, estimated)
    return TpaResult(options, food, profile, result, plant, estimated, curves, h_max, estimator, checks)


def texture_checks(result: SimulateResult, food: Food, profile: Profile, g_plant: dict, plant: TpaAnalysis,
                   estimated: TpaAnalysis) -> list:
    """The checks of a simulated texture test (module docstring): the simulation's, the protocol's on the plant's gap
    and force, the energy readings of both analyses."""
    sim = result.simulation
    held = protocol_checks(sim.t, g_plant["gap"], sim.quantities["force"], profile, rate=g_plant["rate"])
    return [*result.checks, *held, *plant.checks, *estimated.checks]


def estimate_trigger(force: np.ndarray, trigger_force: float) -> tuple[float, float]:
    """The contact force of an estimated curve (N) and the estimate's noise (N): the larger of ``trigger_force`` and
    :data:`NOISE_FACTOR` times the noise, 1.4826 MAD(diff F) / sqrt 2 (white noise's standard deviation; a force that
    changes smoothly from sample to sample barely moves it)."""
    d = np.diff(np.asarray(force, float))
    noise = float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2)) if d.size else 0.0
    return max(float(trigger_force), NOISE_FACTOR * noise), noise


def estimate_from_log(model: Model, log, side: str, friction: bool = True, trigger_force: float | None = None) -> tuple[dict, dict]:
    """The sample's force along the gap from a log's crank angles and torques (or currents), as ``chewbot
    estimate-force`` estimates it (:func:`chewbot.identification.force.estimate_log`: the motion as ``chewbot
    identify`` recovers it, rates smoothed from the angles unless logged, the held torques averaged with the smoothed
    accelerations' weights, the smoothing kept from reaching across the force's steps; ``friction``: the model's
    friction subtracted), the gap from the recovered poses. Returns the curve {"t", "gap", "force", "se", "low95",
    "high95"} (the force's 95 % interval) and what tpa.json says of the estimator, with the contact force the
    measures use (:func:`estimate_trigger`)."""
    from chewbot.food.tpa import TRIGGER_FORCE
    from chewbot.identification.force import estimate_log_motion

    est, motion = estimate_log_motion(model, log, side=side, friction=friction)
    q, dq, _ = motion.kin.euler_angle_state()
    force = -est.F_B[:, 2]
    low, high = est.interval()
    contact, noise = estimate_trigger(force, TRIGGER_FORCE if trigger_force is None else trigger_force)
    curve = {"t": est.t, "gap": gap(model, side, q, dq)["gap"], "force": force, "se": est.se[:, 2],
             "low95": -high[:, 2], "high95": -low[:, 2]}
    return curve, {"method": "chewbot.identification.force.estimate_log (chewbot estimate-force's estimator) on the "
                             f"crank angles and the logged {est.info['reads']}, the model's friction "
                             f"{'on' if friction else 'off'}",
                   "friction": "on" if friction else "off", "reads": est.info["reads"], "rates": motion.rates,
                   "torques": est.info["torques"], "window_samples": motion.window_samples, "events": est.info["events"],
                   "sigma_Nm": est.sigma, "noise_N": noise, "contact_force_N": contact,
                   "contact_force_rule": f"the larger of the trigger force and {NOISE_FACTOR:g} x the estimate's noise "
                                         "(1.4826 MAD of its sample-to-sample differences / sqrt 2), held for "
                                         f"{CONTACT_HOLD:g} s",
                   "standard_error_rms_N": {k: float(np.sqrt(np.mean(v[:, 2] ** 2))) for k, v in est.se_parts.items()},
                   "ill_conditioned_samples": int(np.size(est.ill_conditioned)), "warnings": list(est.warnings)}


def analyse_estimate(curve: dict, contact_force: float) -> TpaAnalysis:
    """Bourne's measures of an estimated force curve (:func:`estimate_from_log`'s), with each measure's 95 % interval
    (``intervals``, tpa.json's ``"estimated_ci95"``): the range of the measure over three curves, the estimate and
    the two bounds of its 95 % interval (each sample's estimate -/+ 1.96 standard errors), all with the same contact
    force. The interval's width is mostly the same sign along a stroke (the smoothed rates' error, a model
    parameter's: they move the whole curve), so the bounds are curves the force could have been; a measure the
    bounds' curves cannot be analysed on (the lower bound never positive) has the interval null."""
    estimated = analyse(curve["t"], curve["gap"], curve["force"], contact_force, label="estimated",
                        contact_hold=CONTACT_HOLD)
    try:
        bounds = [analyse(curve["t"], curve["gap"], curve[k], contact_force, contact_hold=CONTACT_HOLD).measures
                  for k in ("low95", "high95")]
    except TpaError:
        return replace(estimated, intervals=dict.fromkeys(MEASURES))
    intervals = {}
    for key, value in estimated.measures.items():
        values = [v for v in (value, *(b[key] for b in bounds)) if v is not None]
        intervals[key] = None if value is None else [min(values), max(values)]
    return replace(estimated, intervals=intervals)


def simulated_log(result: SimulateResult):
    """What the robot would log in a simulation: times, crank angles, applied torques and, with a drive, the motors'
    currents (no rates, no force)."""
    from chewbot.identification.log import RobotLog

    sim = result.simulation
    n = sim.t.size
    return RobotLog(f"simulated {result.task.name}", sim.t, result.kinematics.theta, None, None, sim.tau, np.zeros((n, 3)),
                    np.arange(n) + 2, current=sim.current)


def tpa_from_log(options: TpaOptions) -> tuple[TpaAnalysis, dict, dict]:
    """Bourne's measures of a robot's logged two-bite test (``chewbot identify``'s log format, ``options.log``):
    (analysis, curve, estimator)."""
    from chewbot.identification.log import read_log
    from chewbot.model.params import load_model

    model = load_model(options.model)
    log = read_log(options.log)
    curve, estimator = estimate_from_log(model, log, options.side, options.friction, options.protocol.trigger_force)
    return analyse_estimate(curve, estimator["contact_force_N"]), curve, estimator


__all__ = ["CONTACT_HOLD", "NOISE_FACTOR", "SLIDE", "TPA_CONTROLLER", "TPA_METHOD", "TpaError", "TpaOptions", "TpaResult",
           "analyse_estimate", "check_height", "start_gap",
           "estimate_from_log", "estimate_trigger", "find_trigger", "resolve_tpa", "run_tpa", "simulated_log",
           "texture_checks", "tpa_from_log"]
