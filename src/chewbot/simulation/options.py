"""A simulation's options, resolved once: what ``chewbot simulate``, ``chewbot tpa``, ``chewbot export-controller`` and
``chewbot.simulate`` take, completed with their defaults and checked against each other, every rule written here once.

:func:`resolve` takes the options as the command line or a Python caller gives them (strings, enums, rows) and gives a
:class:`SimulationOptions`: frozen, typed (the controller's and the engine's table rows, the friction switch a bool,
the side, goal and contact as enums, the controller's inverse dynamics resolved from the formulation table), what
run.json records under ``"options"`` (:meth:`SimulationOptions.record`). A combination that does not apply is an
:class:`~chewbot.run.options.OptionError` naming the option (the command line words it ``--rate``). The layers below
(:mod:`chewbot.simulation.run`, the simulator, the plants, the controllers) assert what is refused here.

The rules, besides those of a run (:func:`chewbot.run.options.resolve_dynamics`: the method, its goal and its options;
the contact model; ``--set`` keys that change nothing):

* ``--rate continuous`` evaluates the controller inside the integrator: it needs a controller whose law is a CasADi
  function and a plant engine that closes the loop (their rows), no sensor (the encoders are read at ticks), no food
  (its events are located between ticks), no comparison of engines;
* the sensor is ``measured`` with noise or ``--exported`` (an estimate from the crank angles), ``exact`` otherwise;
  ``exact`` with noise or ``--exported`` is refused;
* ``--exported`` runs an exportable controller, one at a time;
* a controller's needs (its row): a food to press on, the target's task coordinates, the inverse dynamics (``--method``,
  ``--goal``, ``--bite-unknown`` apply only to controllers that use it; a controller given the observer's force knows
  no other, so ``--bite-unknown`` does not apply to it either);
* ``--food`` needs an engine that holds a food; a bolus (``chewbot chew``) a food and an engine that breaks it;
* an option none of the controllers that run uses (a gain of another controller, the estimator's cut-off without the
  measured sensor) is an error naming what would use it;
* ``--plant-set`` changes the plant's model only: the default task's keys (``task.NAME``) go with ``--set``;
* ``--compare`` (the controllers of the table's comparison) and ``--compare-engines`` (every engine) exclude each
  other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import StrEnum

from chewbot.dynamics.options import Contact, Goal
from chewbot.kinematics.options import Orientation, Side
from chewbot.run.options import OptionError, Switch, refuse_unused, resolve_dynamics
from chewbot.simulation.controllers.table import CONTROLLERS, DEFAULT_CONTROLLER, ControllerRow, controller_row
from chewbot.simulation.engines import DEFAULT_ENGINE, ENGINES, EngineRow, engine_row

DEFAULT_RATE = 1000.0  # Hz
# The gains section of the crank sensor's estimator (chewbot.simulation.controllers.gains.PARTS).
ESTIMATOR_SECTION = "estimator"


class Sensor(StrEnum):
    """What the controller is given: the plant's state (exact) or its estimate from the crank angles (measured)."""

    exact = "exact"
    measured = "measured"


@dataclass(frozen=True)
class ControllerDynamics:
    """A controller's inverse dynamics, resolved (:func:`chewbot.run.options.resolve_dynamics`): the formulation
    ``method``, the ``goal`` of its distribution (None where it has none), ``friction`` in the controller's model
    (where the formulation takes friction, and the plant has it) and the ``contact`` its distribution keeps
    (unilateral: N_L, N_R >= ``contact.preload_N``, where the formulation's per-sample graph takes it; the texture
    test's, :func:`chewbot.simulation.texture.resolve_tpa`)."""

    method: str
    goal: Goal | None = None
    friction: bool = False
    contact: Contact = Contact.bilateral

    @classmethod
    def resolved(cls, method: str | None = None, goal: str | None = None, friction: bool = False,
                 has_hkp: bool = True) -> ControllerDynamics:
        """The formulation table's default method where ``method`` is None, its goal's default where it
        distributes, friction where it takes it."""
        from chewbot.dynamics.registry import formulation

        d = resolve_dynamics(method, Orientation.euler_angles.value, goal, None, has_hkp=has_hkp)
        return cls(d.method, _enum("goal", d.goal, Goal), bool(friction) and "friction" in formulation(d.method).options)

    @property
    def key(self) -> tuple:
        return (self.method, self.goal, bool(self.friction), *(() if self.contact == Contact.bilateral else (self.contact.value,)))

    def c_name(self) -> list[str]:
        """The parts of a kernel's C name: the method, and the options its per-sample graph takes."""
        from chewbot.dynamics.registry import formulation

        f = formulation(self.method)
        parts = [self.method]
        if "goal" in f.sample_options:
            parts.append(self.goal or dict(f.defaults)["goal"])
        if "friction" in f.sample_options:
            parts.append("friction" if self.friction else "frictionless")
        if "contact" in f.sample_options and self.contact != Contact.bilateral:
            parts.append(self.contact.value)
        return parts


@dataclass(frozen=True)
class SimulationOptions:
    """Everything that defines a simulation, resolved (:func:`resolve`).

    ``controller`` and ``engine``: their rows; ``model``: the controller's model (built-in name or file), also the
    plant's unless ``plant_file``; ``task``: "default" or a CSV file; ``side``: None (left, or the side of the run whose
    results.csv is the task); ``inverse``: the controller's inverse dynamics (its method recorded even for a controller
    that uses none); ``friction``: the plant's; ``contact``; ``rate`` (Hz; None: continuous); ``noise_rad`` and
    ``seed`` of the crank encoders; ``overrides`` of the controller's model and the default task (``--set``),
    ``plant_overrides`` of the plant's model only (``--plant-set``); ``bite_unknown``; ``gains_file`` and
    ``gain_overrides``; ``food`` (built-in name or file); ``measured``: the controller is given the estimate from the
    crank angles (else the plant's state); ``exported``: the controller runs as the exported C step; ``compare`` and
    ``compare_engines``: the simulations that run (:meth:`runs`); ``bolus``: the food breaks into a bolus whose particle
    bed is its force once broken (``chewbot chew``)."""

    controller: ControllerRow = field(default_factory=lambda: controller_row(DEFAULT_CONTROLLER))
    model: str = "target"
    task: str = "default"
    side: Side | None = None
    inverse: ControllerDynamics = field(default_factory=ControllerDynamics.resolved)
    friction: bool = False
    contact: Contact = Contact.bilateral
    rate: float | None = DEFAULT_RATE
    noise_rad: float = 0.0
    seed: int = 0
    plant_file: str | None = None
    overrides: dict[str, float] = field(default_factory=dict)
    plant_overrides: dict[str, float] = field(default_factory=dict)
    bite_unknown: bool = False
    gains_file: str | None = None
    gain_overrides: dict[str, float] = field(default_factory=dict)
    food: str | None = None
    measured: bool = False
    exported: bool = False
    engine: EngineRow = field(default_factory=lambda: engine_row(DEFAULT_ENGINE))
    compare: bool = False
    compare_engines: bool = False
    bolus: bool = False

    def runs(self) -> dict[str, SimulationOptions]:
        """The simulations these options run, by label: one, or one per compared controller or engine."""
        if self.compare:
            return {r.name: replace(self, controller=r, compare=False) for r in CONTROLLERS.values() if r.compared}
        if self.compare_engines:
            return {e.name: replace(self, engine=e, compare_engines=False) for e in ENGINES.values()}
        return {self.controller.name: self}

    def record(self, side: str) -> dict:
        """run.json's ``"options"``: each option as the command line writes it, ``side`` the one in effect."""
        return {"controller": self.controller.name, "model": self.model, "task": self.task, "side": str(side),
                "method": self.inverse.method, "goal": self.inverse.goal, "friction": Switch.on.value if self.friction else Switch.off.value,
                "contact": self.contact.value, "rate": self.rate, "noise_rad": self.noise_rad, "seed": self.seed,
                "plant": self.plant_file, "overrides": dict(self.overrides), "plant_overrides": dict(self.plant_overrides),
                "bite_unknown": self.bite_unknown, "gains": self.gains_file, "gain_overrides": dict(self.gain_overrides),
                "food": self.food, "sensor": (Sensor.measured if self.measured else Sensor.exact).value, "exported": self.exported,
                "engine": self.engine.name, "bolus": self.bolus}


def _row(value, rows: dict, option: str):
    """A row of ``rows`` (the controllers' or the engines' table) given as itself or by name; OptionError names the
    choices."""
    name = value if isinstance(value, str) else value.name
    if name not in rows:
        raise OptionError(option, f"must be one of {', '.join(rows)}, not {name!r}")
    return rows[name]


def _enum(option: str, value, kind):
    if value is None:
        return None
    try:
        return kind(value)
    except ValueError:
        raise OptionError(option, f"must be one of {', '.join(k.value for k in kind)}, not {value!r}") from None


def resolve(controller: ControllerRow | str = DEFAULT_CONTROLLER, model: str = "target", task: str = "default",
            side: Side | str | None = None, method: str | None = None, goal: Goal | str | None = None,
            friction: bool | Switch | str = False, contact: Contact | str = Contact.bilateral, rate: float | str | None = DEFAULT_RATE,
            noise_rad: float = 0.0, seed: int = 0, plant_file: str | None = None, overrides: dict[str, float] | None = None,
            plant_overrides: dict[str, float] | None = None, bite_unknown: bool = False, gains_file: str | None = None,
            gain_overrides: dict[str, float] | None = None, food: str | None = None, sensor: Sensor | str | None = None,
            exported: bool = False, engine: EngineRow | str = DEFAULT_ENGINE, compare: bool = False,
            compare_engines: bool = False, bolus: bool = False, *, has_hkp: bool | None = None) -> SimulationOptions:
    """The options of a simulation, complete and consistent (the module docstring's rules); :class:`OptionError`
    names the option that does not apply. ``rate``: Hz, or None or "continuous"; ``friction``: the plant's, a bool or
    "on"/"off"; ``sensor``: :class:`Sensor` or its value, or None (the default of the rules). ``has_hkp``: whether the
    controller's model is the target (None: read from its file, only where a rule needs it)."""
    row, engine = _row(controller, CONTROLLERS, "controller"), _row(engine, ENGINES, "plant-engine")
    side, goal, contact = _enum("side", side, Side), _enum("goal", goal, Goal), _enum("contact", contact, Contact)
    if isinstance(friction, str):
        friction = _enum("friction", friction, Switch) == Switch.on
    if rate is not None and rate != "continuous":
        given = rate
        try:
            rate = float(rate)
        except ValueError:
            rate = math.nan
        if not (math.isfinite(rate) and rate > 0):
            raise OptionError("rate", f"must be a positive number of Hz or 'continuous', not {given!r}")
    rate = None if rate == "continuous" else rate
    overrides, plant_overrides, gain_overrides = dict(overrides or {}), dict(plant_overrides or {}), dict(gain_overrides or {})
    if noise_rad < 0:
        raise OptionError("noise", f"is a standard deviation (rad): not negative, not {noise_rad:g}")

    def target() -> bool:
        nonlocal has_hkp
        if has_hkp is None:
            from chewbot.model.params import load_model

            has_hkp = load_model(model).has_hkp
        return has_hkp

    # what runs
    if compare and compare_engines:
        raise OptionError(("compare", "compare-engines"), "exclude each other: controllers on one engine, or one controller on "
                          "every engine")
    runs = [r for r in CONTROLLERS.values() if r.compared] if compare else [row]
    engines = list(ENGINES.values()) if compare_engines else [engine]
    names = " and ".join(r.name for r in runs)
    if exported and compare:
        raise OptionError(("exported", "compare"), f"exclude each other: --exported runs one controller "
                          f"({' or '.join(r.name for r in CONTROLLERS.values() if r.exportable)}), --compare {len(runs)}")

    # the sensor
    sensor = _enum("sensor", sensor, Sensor)
    measured = sensor == Sensor.measured if sensor is not None else (noise_rad > 0 or exported)
    if not measured and noise_rad > 0:
        raise OptionError("sensor", "exact gives the controller the plant's state: noise on the encoders needs --sensor measured")
    if not measured and exported:
        raise OptionError("sensor", "the exported step estimates its state from the measured angles: --exported needs "
                          "--sensor measured")

    # continuous control: every refusal of it
    if rate is None:
        if noise_rad > 0:
            raise OptionError("noise", "needs a control rate: the encoders are read at its ticks, not with --rate continuous")
        if measured:
            raise OptionError("sensor", "reads the encoders at the ticks of a control rate, not with --rate continuous")
        if exported:
            raise OptionError("exported", "runs the C step at the ticks of a control rate, not with --rate continuous")
        for r in runs:
            if not r.continuous:
                why = " (it switches on the force observer's estimate there)" if r.needs.observer else ""
                raise OptionError("controller", f"{r.name} is evaluated at the ticks of a control rate{why}: it needs a rate, "
                                  "not --rate continuous")
        for e in engines:
            if not e.closes_loop and compare_engines:
                raise OptionError("compare-engines", f"needs a control rate: the {e.name} plant runs the controller at its ticks, "
                                  "not with --rate continuous")
            if not e.closes_loop:
                raise OptionError("plant-engine", f"{e.name} runs the controller at the ticks of a control rate, not with --rate "
                                  "continuous")
        if food is not None:
            raise OptionError("food", "the food's events are located between the ticks of a control rate: --rate continuous "
                              "is not available with a food")

    # the controllers' needs
    if exported:
        if not row.exportable:
            raise OptionError("exported", f"runs {' or '.join(r.name for r in CONTROLLERS.values() if r.exportable)}, not {row.name}")
    for r in runs:
        if r.needs.food and food is None:
            raise OptionError("controller", f"{r.name} follows the task's Fz as a force reference by pressing on a food: give "
                              "--food FOOD (without one the bite force is the task's, which no controller can change)")
        if r.needs.observer and bite_unknown:
            raise OptionError("bite-unknown", f"does not apply: the {r.name} controller knows no bite force but the one its "
                              "observer estimates")
        if r.needs.target and not target():
            raise OptionError("controller", f"{r.name} is for the target (the molar point's x, y, z and alpha), not {model}")
    if not any(r.needs.inverse_dynamics for r in runs):
        model_based = " and ".join(r.name for r in CONTROLLERS.values() if r.needs.inverse_dynamics)
        for option, given in (("method", method is not None), ("goal", goal is not None), ("bite-unknown", bite_unknown)):
            if given:
                raise OptionError(option, f"applies to the model-based controllers ({model_based}), not {names} (no "
                                  "inverse dynamics in their laws)")
    if bolus and food is None:
        raise OptionError("food", "is required: the bolus is a food's, broken into particles")
    for e in engines:
        if bolus and not e.bolus:
            raise OptionError("plant-engine", f"the {e.name} plant does not break a food into a bolus")
    if food is not None:
        for e in engines:
            if not e.food:
                raise OptionError("food", f"the food's law is a plant force of an engine that holds a food; it is not in the "
                                  f"{e.name} plant (leave out --plant-engine {e.name})")

    # gains that change nothing
    sections = {r.gains: r for r in CONTROLLERS.values() if r.gains is not None}
    for key, value in gain_overrides.items():
        section = key.split(".", 1)[0]
        if section in sections and sections[section] not in runs:
            raise OptionError(f"gain {key}={value:g}", f"changes nothing: it is a gain of --controller {sections[section].name}, "
                              f"and this simulation runs {names}")
        if section == ESTIMATOR_SECTION and not measured:
            raise OptionError(f"gain {key}={value:g}", "changes nothing: the estimator runs only with sensor noise "
                              "(--noise RAD > 0); without it the controller sees the plant's state")

    # the inverse dynamics, the contact model, the models' overrides
    d = resolve_dynamics(method, Orientation.euler_angles.value, goal, None, contact or Contact.bilateral, has_hkp=has_hkp, model=model)
    for option, given in (("set", overrides), ("plant-set", plant_overrides)):
        refuse_unused(given, option, friction=friction, contact=d.contact,
                      friction_users="the plant with --friction on (and a newton-euler controller's model with it)")
    plant_task = [k for k in plant_overrides if k.startswith("task.")]
    if plant_task:
        raise OptionError(f"plant-set {plant_task[0]}={plant_overrides[plant_task[0]]:g}",
                          "changes the plant's model only: the task is the controller's and the plant's; change it with --set")
    from chewbot.dynamics.registry import formulation

    inverse = ControllerDynamics(d.method, _enum("goal", d.goal, Goal), friction and "friction" in formulation(d.method).options)
    return SimulationOptions(row, model, task, side, inverse, bool(friction), Contact(d.contact), rate, float(noise_rad), int(seed),
                             plant_file, overrides, plant_overrides, bool(bite_unknown), gains_file, gain_overrides, food,
                             measured, bool(exported), engine, bool(compare), bool(compare_engines), bool(bolus))
