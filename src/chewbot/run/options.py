"""A run's options, resolved once: what ``chewbot run``, a sweep's SPEC and ``chewbot simulate`` take, completed with
their defaults and checked against each other by the same rules.

The rules (docs/cli.md):

* the formulation (``method``) defaults by the orientation parametrisation (:data:`~chewbot.dynamics.registry.DEFAULT_METHOD`:
  hessian with Euler angles, newton-euler with Euler parameters) and must be written for it;
* ``goal`` and ``friction`` apply to the formulations that take them (newton-euler): given to another, they are
  an error; where they apply and are not given they take the formulation's defaults (min-torque, on);
* ``goal`` distributes redundant torques: on the 6RSS (no redundancy) it is an error, and it is left out;
* the ``unilateral`` contact model needs the HKPs: on the 6RSS it is an error;
* a ``--set`` override of a model key the run does not use is an error naming what would use it
  (:func:`unused_override`: the friction coefficients without friction, the preload without the unilateral
  contact).

:func:`resolve` applies them and gives a :class:`RunOptions`, complete and consistent: what run.json records under
``"options"``. ``RunOptions()`` is the default run (the target robot, the default task, Hessian). A combination
that does not apply is an :class:`OptionError` naming the option, which each caller words in its own terms (the
command line's ``--goal``, a SPEC's key ``goal``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import StrEnum

from chewbot.dynamics.options import DEFAULT_METHOD, Contact, Goal
from chewbot.errors import ChewbotError
from chewbot.kinematics.options import Orientation, Side


class Switch(StrEnum):
    """A friction switch, as files and the command line write it."""

    on = "on"
    off = "off"


class OptionError(ChewbotError):
    """Run options that do not apply: ``options`` names them (``method``, ``goal``, ``friction``, ``contact``,
    ``orientation``, ``side``), ``reason`` says why; the message is ``"goal and friction apply to ..."``. A caller
    words the names in its own terms (:meth:`worded`)."""

    def __init__(self, options: str | tuple[str, ...], reason: str):
        self.options = (options,) if isinstance(options, str) else tuple(options)
        self.reason = reason
        super().__init__(self.worded(str))

    def worded(self, name) -> str:
        """The message with each option named by ``name(option)`` (``lambda o: f"--{o}"`` on the command line)."""
        return f"{' and '.join(name(o) for o in self.options)} {self.reason}"


@dataclass(frozen=True)
class RunOptions:
    """Everything that defines a run, resolved (:func:`resolve`); recorded in run.json.

    ``method`` None: no inverse dynamics (the kinematics, the transmission angles and their checks only); ``side``
    None: left, or the side of the run whose results.csv is the task; ``goal``: newton-euler on the target only; ``friction`` ("on", "off"): newton-euler only; ``contact``: the contact model of the HKPs; ``overrides``:
    ``--set KEY=VALUE``, the model's keys and the default task's ``task.NAME``."""

    model: str = "target"
    task: str = "default"
    side: str | None = None
    orientation: str = Orientation.euler_angles.value
    method: str = DEFAULT_METHOD[Orientation.euler_angles.value]
    goal: str | None = None
    friction: str | None = None
    contact: str = Contact.bilateral.value
    overrides: dict[str, float] = field(default_factory=dict)

    def formulation_options(self) -> dict:
        """The keyword options of the formulation (:func:`chewbot.dynamics.registry.inverse_dynamics`): the contact
        model, and the goal and friction where the formulation takes them."""
        return {**({"goal": self.goal} if self.goal else {}), **({"friction": self.friction == Switch.on} if self.friction else {}),
                "contact": self.contact}


@dataclass(frozen=True)
class DynamicsOptions:
    """The inverse dynamics' part of a run's options, resolved: ``method``, ``goal``, ``friction`` ("on"/"off" or
    None), ``contact``."""

    method: str
    goal: str | None
    friction: str | None
    contact: str


def _choice(option: str, value, kind) -> str | None:
    if value is None:
        return None
    try:
        return kind(value).value
    except ValueError:
        raise OptionError(option, f"must be one of {', '.join(k.value for k in kind)}, not {value!r}") from None


def resolve_dynamics(method: str | None = None, orientation: str = Orientation.euler_angles.value, goal: str | None = None,
                     friction: str | bool | None = None, contact: str = Contact.bilateral.value, *,
                     has_hkp: bool | None = None, model: str = "target") -> DynamicsOptions:
    """``method``, ``goal``, ``friction`` and ``contact`` completed and checked by the rules of the module docstring.
    ``has_hkp``: whether the robot is the target (None: read from ``model``'s parameter file where a rule needs it)."""
    from chewbot.dynamics.registry import FORMULATIONS

    orientation = _choice("orientation", orientation, Orientation)
    goal = _choice("goal", goal, Goal)
    friction = _choice("friction", {True: "on", False: "off"}.get(friction, friction), Switch)
    contact = _choice("contact", contact, Contact)
    method = method or DEFAULT_METHOD[orientation]
    f = FORMULATIONS.get(method)
    if f is None:
        raise OptionError("method", f"{method!r} is not a formulation; choose one of {', '.join(FORMULATIONS)}")
    if orientation not in f.orientations:
        raise OptionError("method", f"{method} is written for {' and '.join(f.orientations)}, not {orientation} (the "
                          "torques of a motion do not depend on how its orientation is parametrised: take "
                          f"{' or '.join(f.orientations)}, or a formulation written for {orientation})")
    given = [name for name, value in (("goal", goal), ("friction", friction)) if value is not None and name not in f.options]
    if given:
        takers = [n for n, g in FORMULATIONS.items() if given[0] in g.options]
        raise OptionError(tuple(given), f"{'applies' if len(given) == 1 else 'apply'} to the {' and '.join(takers)} method, "
                          f"not {method} (frictionless, minimum-norm torques)")

    def target() -> bool:
        nonlocal has_hkp
        if has_hkp is None:
            from chewbot.model.params import load_model

            has_hkp = load_model(model).has_hkp
        return has_hkp

    if contact == Contact.unilateral and not target():
        raise OptionError("contact", "unilateral applies to the target robot: the 6RSS has no HKP contacts")
    defaults = dict(f.defaults)
    if "goal" in f.options:
        if goal is not None and not target():
            raise OptionError("goal", "applies to the target robot: the 6RSS has no redundant actuation to distribute")
        goal = (goal or defaults.get("goal")) if target() else None
    if "friction" in f.options and friction is None:
        friction = Switch.on.value if defaults.get("friction", True) else Switch.off.value
    return DynamicsOptions(method, goal, friction, contact)


def friction_methods() -> str:
    """The formulations that compute friction (from the formulation table): ``"newton-euler"``."""
    from chewbot.dynamics.registry import FORMULATIONS

    return " and ".join(n for n, f in FORMULATIONS.items() if "friction" in f.options)


def unused_override(key: str, *, friction: bool, contact: str, friction_users: str | None = None) -> str | None:
    """Why the model key ``key`` (a ``--set`` key: ``friction.hkp_coulomb``, ``contact.preload_N``, ``chains.G_mm[2][1]``)
    changes nothing in a computation with these options, naming what would use it; None where it is used.

    ``friction``: the computation has friction (``run``: a formulation that takes it, with friction on;
    ``simulate``: the plant's ``--friction on``), ``friction_users`` says what has it (default: the formulations of
    the table that take friction, with ``--friction on``); ``contact``: the contact model (the preload bounds the
    unilateral contact only). Every other key of the parameter file is used by every computation (geometry,
    inertia, limits of the checks). The ``task.*`` keys are the default task's (refused with a task file by
    :func:`chewbot.run.pipeline.load_task`)."""
    path = key.split("[", 1)[0].strip()
    if path.startswith("friction.") and not friction:
        users = friction_users or f"the {friction_methods()} method with --friction on (its default)"
        return f"changes nothing: the friction coefficients are used by {users}, and this computation has no friction"
    if path == "contact.preload_N" and contact != Contact.unilateral:
        return ("changes nothing: the preload is the smallest normal force of the unilateral contact (--contact "
                "unilateral), and this computation's contact is bilateral")
    return None


def refuse_unused(overrides: dict[str, float], option: str = "set", **use) -> None:
    """Raise :class:`OptionError` naming the first override (``option KEY=VALUE``) that :func:`unused_override`
    finds unused with the options ``use``: a value that would change nothing is an error, not silence."""
    for key, value in overrides.items():
        why = unused_override(key, **use)
        if why:
            raise OptionError(f"{option} {key}={value:g}", why)


def complete(options: RunOptions, has_hkp: bool) -> RunOptions:
    """``options`` with the defaults that apply filled in and checked (:func:`resolve_dynamics`); ``has_hkp``: the
    model is the target. A run without inverse dynamics (``method`` None) takes neither goal nor friction."""
    if options.method is None:
        d = resolve_dynamics(DEFAULT_METHOD[options.orientation], options.orientation, options.goal, options.friction, options.contact, has_hkp=has_hkp)
        return replace(options, contact=d.contact)
    d = resolve_dynamics(options.method, options.orientation, options.goal, options.friction, options.contact, has_hkp=has_hkp)
    return replace(options, method=d.method, goal=d.goal, friction=d.friction, contact=d.contact)


def resolve(model: str = "target", task: str = "default", side: str | None = None,
            orientation: str = Orientation.euler_angles.value, method: str | None = None, goal: str | None = None,
            friction: str | bool | None = None, contact: str = Contact.bilateral.value,
            overrides: dict[str, float] | None = None, *, has_hkp: bool | None = None) -> RunOptions:
    """The run's options, complete and consistent (the module docstring's rules); :class:`OptionError` names the
    option that does not apply. ``has_hkp``: whether ``model`` is the target robot (None: read from its file, only
    where a rule needs it)."""
    side = _choice("side", side, Side)
    d = resolve_dynamics(method, orientation, goal, friction, contact, has_hkp=has_hkp, model=model)
    uses = f"the {friction_methods()} method with --friction on (its default)"
    refuse_unused(dict(overrides or {}), friction=d.friction == Switch.on, contact=d.contact,
                  friction_users=uses if d.friction is None else f"{uses}; this run has --friction off")
    return RunOptions(model=model, task=task, side=side, orientation=Orientation(orientation).value, method=d.method,
                      goal=d.goal, friction=d.friction, contact=d.contact, overrides=dict(overrides or {}))
