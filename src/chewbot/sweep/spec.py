"""The SPEC file of a sweep: what to vary, how, and what to compute (docs/sweeps.md).

A SPEC is a TOML file. :func:`read_spec` parses and validates every key: an unknown key (with the closest known
one suggested), a wrong type, a distribution without its two numbers, an output that does not exist, a parameter
key that the model does not have... each is a :class:`SpecError` naming the file and the key (exit code 2). The
result is an immutable :class:`Spec`; :meth:`Spec.digest` identifies what the sweep computes (``--resume``
refuses a SPEC whose digest changed).

Parameter keys are those of ``chewbot run --set`` (parameter-file keys in the file's units with 1-based indices,
and ``task.NAME`` for the default task's parameters); pose coordinates of a ``grid`` over poses are ``X_mm``,
``Y_mm``, ``alpha_deg``, ``beta_deg`` (and ``Z_mm``, ``gamma_deg`` on the 6RSS).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path
from typing import Annotated, Generic, Literal, TypeVar

from pydantic import AfterValidator, ConfigDict, Field, field_validator, model_validator

from chewbot.config import Plausible, Strict, did_you_mean, either, key_error, quoted, read_text, validate
from chewbot.dynamics.options import CONTACT_MODELS, DEFAULT_METHOD, GOALS
from chewbot.errors import ChewbotError
from chewbot.kinematics.options import ORIENTATIONS
from chewbot.run.options import Switch
from chewbot.units import factor, key_unit

KINDS = ("monte-carlo", "sobol", "grid", "optimize")
DISTRIBUTIONS = ("uniform", "normal", "lognormal")
MAPS = ("workspace", "singularity", "force")
# Directions of the force-capability map when the SPEC names none: the axes of {S} (x forward, y to the left, z up).
DEFAULT_DIRECTIONS = {"up": (0.0, 0.0, 1.0), "down": (0.0, 0.0, -1.0), "forward": (1.0, 0.0, 0.0),
                      "back": (-1.0, 0.0, 0.0), "left": (0.0, 1.0, 0.0), "right": (0.0, -1.0, 0.0)}
# Evaluations per chunk when the SPEC says nothing: a model evaluation of the default task takes about 0.1 s, so
# a chunk takes seconds (small enough for a live progress bar and little lost work on an interrupt, large
# enough that Dask's overhead of a few milliseconds per task does not count); a pose of a map takes microseconds.
DEFAULT_CHUNK = 32
DEFAULT_POSE_CHUNK = 512
# The counterpart mechanism that ratio outputs compare with, for the built-in models.
COUNTERPARTS = {"target": "6rss", "6rss": "target", "target-as-printed": "6rss-as-printed",
                "6rss-as-printed": "target-as-printed"}


class SpecError(ChewbotError):
    """A SPEC file is malformed: names the file and the key (exit code 2)."""


@dataclass(frozen=True)
class Parameter:
    """One varied parameter: its key (as ``--set`` takes it) and how it varies.

    ``kind``: ``uniform`` (args low, high), ``normal`` (mean, standard deviation), ``lognormal`` (mu, sigma of
    ln x), ``values`` (the list of a grid), ``bounds`` (low, high of an optimisation).
    """

    key: str
    kind: str
    args: tuple[float, ...]

    def central(self) -> float:
        """A representative value (the middle, mean, median or first value), to validate the key with."""
        a = self.args
        return {"uniform": 0.5 * (a[0] + a[-1]), "bounds": 0.5 * (a[0] + a[-1]), "normal": a[0],
                "lognormal": math.exp(a[0]), "values": a[0]}[self.kind]


@dataclass(frozen=True)
class Spec:
    """A validated SPEC (see the module docstring and docs/sweeps.md). Paths are resolved against the SPEC's
    folder; ``source`` is the SPEC file (or the built-in name)."""

    source: str
    kind: str
    model: str = "target"
    task: str = "default"
    side: str | None = None
    orientation: str = "euler-angles"
    method: str | None = DEFAULT_METHOD["euler-angles"]
    goal: str | None = None
    friction: str | None = None
    contact: str = "bilateral"
    outputs: tuple[str, ...] = ()
    samples: int = 0
    seed: int = 0
    chunk: int = DEFAULT_CHUNK
    counterpart: str | None = None
    fixed: dict = field(default_factory=dict)  # [set]: overrides applied to every evaluation
    parameters: tuple[Parameter, ...] = ()
    resamples: int = 100  # sobol: bootstrap resamples of the confidence intervals
    confidence: float = 0.95  # sobol: level of the confidence intervals
    poses: tuple[Parameter, ...] = ()  # grid over poses: varied coordinates (kind "values")
    pose_fixed: dict = field(default_factory=dict)  # grid over poses: coordinates held (SPEC units)
    maps: tuple[str, ...] = ()
    directions: dict = field(default_factory=dict)  # force map: name -> unit vector in {S}
    minimize: str | None = None  # optimize
    require_feasible: bool = True  # optimize: the validity checks must pass, not only the kinematics
    optimizer: dict = field(default_factory=dict)  # optimize: differential evolution's settings

    @property
    def keys(self) -> tuple[str, ...]:
        """The varied parameters' keys (or pose coordinates), in the SPEC's order: the columns of the design."""
        return tuple(p.key for p in (self.poses or self.parameters))

    @property
    def computed_outputs(self) -> tuple[str, ...]:
        """The outputs each evaluation computes: the SPEC's, and for a search its objective and constraint."""
        if self.kind != "optimize":
            return self.outputs
        constraint = ("feasible", "violation_share") if self.require_feasible else ()
        return tuple(dict.fromkeys((self.minimize, *constraint, *self.outputs)))

    @property
    def over_poses(self) -> bool:
        return self.kind == "grid" and bool(self.poses)

    def run_options(self, model: str | None = None):
        """The options of ``chewbot run`` that this SPEC's evaluations compute with (:class:`~chewbot.run.options.RunOptions`);
        ``model``: another model's name (the counterpart of the ratio outputs)."""
        from chewbot.run.options import RunOptions

        return RunOptions(model=model or self.model, task=self.task, side=self.side, orientation=self.orientation,
                          method=self.method, goal=self.goal, friction=self.friction, contact=self.contact)

    def as_dict(self) -> dict:
        """Everything the SPEC says (for run.json), parameters as tables."""
        d = asdict(self)
        d["parameters"] = {p.key: {p.kind: list(p.args)} for p in self.parameters}
        d["poses"] = {p.key: {p.kind: list(p.args)} for p in self.poses}
        d["directions"] = {k: list(v) for k, v in self.directions.items()}
        return d

    def digest(self, files: dict[str, str] | None = None) -> str:
        """SHA-256 of what the sweep computes: the SPEC's values (not its layout or comments) and the SHA-256 of
        the files it reads (``files``: path -> digest)."""
        d = self.as_dict()
        d.pop("source")
        d["files"] = dict(sorted((files or {}).items()))
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()


# -------------------------------------------------------------------------------------------- the file


def _interval(pair: list[float]) -> list[float]:
    if not pair[0] < pair[1]:
        raise ValueError(f"[{pair[0]}, {pair[1]}] is not an interval [low, high] with low < high")
    return pair


def _spread(pair: list[float]) -> list[float]:
    if not pair[1] > 0:
        raise ValueError(f"the standard deviation ({pair[1]}) must be positive")
    return pair


N = TypeVar("N")
Pair = Annotated[list[float], Field(min_length=2, max_length=2)]
Interval = Annotated[Pair, AfterValidator(_interval)]
Spread = Annotated[Pair, AfterValidator(_spread)]


class Distribution(Strict):
    """A parameter of a Monte Carlo or Sobol' sweep: exactly one distribution."""

    EXAMPLE = "{ uniform = [low, high] }"

    uniform: Interval | None = None
    normal: Spread | None = None
    lognormal: Spread | None = None

    @model_validator(mode="after")
    def _one(self):
        if len(self.model_fields_set) != 1:
            raise ValueError(f"give exactly one of {', '.join(DISTRIBUTIONS)}")
        return self

    def parameter(self, key: str) -> Parameter:
        kind = next(iter(self.model_fields_set))
        return Parameter(key, kind, tuple(getattr(self, kind)))


class Values(Strict, Generic[N]):
    """A coordinate or parameter of a grid: its values, or a range and a number of steps."""

    EXAMPLE = "{ values = [...] } or { range = [low, high], steps = n }"

    values: Annotated[list[N], Field(min_length=1)] | None = None
    range: Annotated[list[N], Field(min_length=2, max_length=2)] | None = None
    steps: int | None = None

    @model_validator(mode="after")
    def _one(self):
        given = self.model_fields_set
        if given not in ({"values"}, {"range", "steps"}):
            raise ValueError("give exactly one of values (or range and steps)")
        if given == {"range", "steps"}:
            (lo, hi), steps = self.range, self.steps
            if steps < 1 or (steps > 1 and not lo < hi) or (steps == 1 and lo != hi):
                raise ValueError(f"range [{lo}, {hi}] with {steps} steps: give low < high and steps >= 2 (or one step with low = high)")
        return self

    def parameter(self, key: str) -> Parameter:
        if self.values is not None:
            return Parameter(key, "values", tuple(self.values))
        (lo, hi), steps = self.range, self.steps
        return Parameter(key, "values", tuple(lo + (hi - lo) * k / max(steps - 1, 1) for k in range(steps)))


class Bounds(Strict):
    """A parameter of a search: its bounds."""

    EXAMPLE = "{ bounds = [low, high] }"

    bounds: Interval

    def parameter(self, key: str) -> Parameter:
        return Parameter(key, "bounds", tuple(self.bounds))


# A pose coordinate of a grid over poses, in the unit of its key: held (a number) or varied (a table).
Length = Annotated[float, Plausible(-200.0, 200.0, "mm", "displacements of a mandible from its home pose")]
Angle = Annotated[float, Plausible(-180.0, 180.0, "deg", "rotations of a mandible from its home pose")]
LengthAxis = either(number=Length, table=Values[Length])
AngleAxis = either(number=Angle, table=Values[Angle])


class PoseGrid(Strict):
    """``[grid]``: the pose coordinates, each held or varied."""

    X_mm: LengthAxis | None = None
    Y_mm: LengthAxis | None = None
    Z_mm: LengthAxis | None = None
    alpha_deg: AngleAxis | None = None
    beta_deg: AngleAxis | None = None
    gamma_deg: AngleAxis | None = None


POSE_KEYS = {key: factor(key_unit(key)[1]) for key in PoseGrid.model_fields}  # factor to SI


def _outputs(names: list[str]) -> list[str]:
    if not names:
        raise ValueError("must name at least one output, e.g. [\"peak_tau_Nm\", \"mean_MCI\"]")
    for name in names:
        _output(name)
    if len(set(names)) != len(names):
        raise ValueError("names an output twice")
    return names


def _output(name: str) -> str:
    from chewbot.sweep.quantities import OUTPUTS

    if name not in OUTPUTS:
        raise ValueError(f"unknown output {name!r}{did_you_mean(name, OUTPUTS)}; docs/sweeps.md lists the outputs")
    return name


def _objective(name: str) -> str:
    if _output(name) == "feasible":
        raise ValueError("'feasible' is the constraint of the search, not an output to minimise")
    return name


Outputs = Annotated[list[str], AfterValidator(_outputs)]


class SobolSection(Strict):
    resamples: int = Field(100, ge=1)  # bootstrap resamples of the confidence intervals
    confidence: float = Field(0.95, gt=0, lt=1)  # level of the confidence intervals


def _dither(pair: list[float]) -> list[float]:
    if not 0 <= pair[0] <= pair[1] < 2:
        raise ValueError("dithering [low, high] with 0 <= low <= high < 2")
    return pair


class OptimizerSection(Strict):
    """Differential evolution's settings (scipy.optimize.differential_evolution's names; generations is its
    maxiter)."""

    generations: int = Field(30, ge=1)
    popsize: int = Field(8, ge=1)
    tol: float = Field(0.01, ge=0)
    atol: float = Field(0.0, ge=0)
    mutation: either(number=Annotated[float, Field(ge=0, lt=2)], list=Annotated[Pair, AfterValidator(_dither)]) = [0.5, 1.0]
    recombination: float = Field(0.7, ge=0, le=1)
    init: Literal["latinhypercube", "sobol", "halton", "random"] = "latinhypercube"


OPTIMIZER_DEFAULTS = OptimizerSection().model_dump()
Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


class ForceSection(Strict):
    directions: dict[str, Vec3] | None = None  # name -> a direction in {S} (any length but zero)


class SpecKind(Strict):
    """The key that decides which keys a SPEC has."""

    model_config = ConfigDict(extra="ignore")
    DOCS = "docs/sweeps.md"

    kind: Literal[KINDS]


class SpecFile(SpecKind):
    """The keys every kind shares."""

    model_config = ConfigDict(extra="forbid")

    model: str = "target"
    task: str = "default"
    side: Literal["left", "right"] | None = None
    orientation: Literal[ORIENTATIONS] = "euler-angles"
    method: str | None = None
    goal: Literal[GOALS] | None = None
    friction: Literal[tuple(s.value for s in Switch)] | None = None
    contact: Literal[CONTACT_MODELS] = "bilateral"
    seed: int = Field(0, ge=0)
    fixed: dict[str, float] = Field({}, alias="set")  # overrides applied to every evaluation
    counterpart: str | None = None
    chunk: int | None = Field(None, ge=1)


class MonteCarloFile(SpecFile):
    samples: int = Field(ge=1)
    parameters: dict[str, Distribution]
    outputs: Outputs


class SobolFile(MonteCarloFile):
    sobol: SobolSection = SobolSection()

    @field_validator("samples")
    @classmethod
    def _power_of_two(cls, n: int) -> int:
        if n & (n - 1):
            raise ValueError(f"{n} base samples: Sobol' sequences need a power of 2 (e.g. 1024)")
        return n


class GridFile(SpecFile):
    grid: PoseGrid | None = None
    parameters: dict[str, Values[float]] | None = None
    outputs: Outputs | None = None
    maps: list[Literal[MAPS]] | None = None
    force: ForceSection | None = None


class OptimizeFile(SpecFile):
    parameters: dict[str, Bounds]
    minimize: Annotated[str, AfterValidator(_objective)]
    outputs: Outputs = []
    require_feasible: bool = True  # the validity checks must pass, not only the kinematics
    optimizer: OptimizerSection = OptimizerSection()


SPEC_FILES = {"monte-carlo": MonteCarloFile, "sobol": SobolFile, "grid": GridFile, "optimize": OptimizeFile}


# -------------------------------------------------------------------------------------------- reading


def builtin_spec_names() -> tuple[str, ...]:
    """The SPECs shipped with chewbot (``chewbot sweep NAME``)."""
    folder = resources.files("chewbot.sweep") / "specs"
    return tuple(sorted(p.name.removesuffix(".toml") for p in folder.iterdir() if p.name.endswith(".toml")))


def spec_path(name_or_path: str | Path) -> Path:
    """A built-in SPEC's name, or a path to a TOML file."""
    s = str(name_or_path)
    if s in builtin_spec_names():
        return Path(str(resources.files("chewbot.sweep") / "specs" / f"{s}.toml"))
    return Path(s)


def read_spec(name_or_path: str | Path) -> Spec:
    """Parse and validate a SPEC file (or a built-in SPEC by name); :class:`SpecError` names the file and key."""
    path = spec_path(name_or_path)
    text = read_text(path, f"SPEC file (nor a built-in SPEC: {', '.join(builtin_spec_names())})", SpecError)
    return parse_spec(text.data, str(path), base=path.parent)


def parse_spec(raw: dict, source: str = "<spec>", base: Path | None = None) -> Spec:
    """Validate a parsed SPEC (see :func:`read_spec`); relative paths resolve against ``base``."""
    from chewbot.model.params import BUILTIN_MODELS

    kind = validate(SpecKind, raw, source, SpecError).kind
    f = validate(SPEC_FILES[kind], raw, source, SpecError)
    base = base or Path(".")

    def fail(key: str, reason: str) -> SpecError:
        return key_error(source, key, reason, SpecError)

    def resolved(key: str, value: str, builtin=()) -> str:
        if value in builtin or value == "default" and key == "task":
            return value
        path = Path(value).expanduser()
        path = path if path.is_absolute() else base / path
        if not path.is_file():
            raise fail(key, f"{value!r} is " + (f"neither a built-in model ({', '.join(BUILTIN_MODELS)}) nor " if key != "task" else "neither 'default' nor ")
                       + f"a file (looked for {path})")
        return str(path)

    model = resolved("model", f.model, BUILTIN_MODELS)
    values: dict = {"source": source, "kind": kind, "model": model, "task": resolved("task", f.task), "side": f.side,
                    "orientation": f.orientation, "seed": f.seed, "fixed": dict(f.fixed),
                    "counterpart": None if f.counterpart is None else resolved("counterpart", f.counterpart, BUILTIN_MODELS)}
    values.update(_dynamics_options(f, _mechanism(model, fail), fail))
    if kind == "grid":
        values.update(_grid(f, raw.get("grid", {}), fail))
    else:
        values["parameters"] = tuple(table.parameter(key) for key, table in f.parameters.items())
        values["outputs"] = tuple(f.outputs)
        if not values["parameters"]:
            raise fail("parameters", "names no parameter")
    if kind in ("monte-carlo", "sobol"):
        values["samples"] = f.samples
    if kind == "sobol":
        values.update(resamples=f.sobol.resamples, confidence=f.sobol.confidence)
        if len(values["parameters"]) < 2:
            raise fail("parameters", "Sobol' indices need at least two parameters")
    if kind == "optimize":
        values.update(minimize=f.minimize, require_feasible=f.require_feasible, optimizer=f.optimizer.model_dump())
    values["chunk"] = f.chunk or (DEFAULT_POSE_CHUNK if values.get("poses") else DEFAULT_CHUNK)
    spec = Spec(**values)
    _check_against_model(spec, fail)
    return spec


def _mechanism(model: str, fail) -> str:
    from chewbot.model.params import load_model

    try:
        return load_model(model).mechanism
    except ChewbotError as exc:
        raise fail("model", str(exc)) from None


def _dynamics_options(f: SpecFile, mechanism: str, fail) -> dict:
    """method, goal, friction, contact as ``chewbot run`` takes them, with its defaults and rules
    (:func:`chewbot.run.options.resolve_dynamics`)."""
    from chewbot.dynamics.registry import METHODS
    from chewbot.run.options import OptionError, resolve_dynamics

    if f.method is not None and f.method not in METHODS:
        raise fail("method", f"{f.method!r} is not a formulation; choose one of {', '.join(METHODS)}" + did_you_mean(f.method, METHODS))
    try:
        d = resolve_dynamics(f.method, f.orientation, f.goal, f.friction, f.contact, has_hkp=mechanism == "target")
    except OptionError as exc:
        raise fail(exc.options[0], exc.reason if len(exc.options) == 1 else exc.worded(lambda option: f"'{option}'")) from None
    return {"method": d.method, "goal": d.goal, "friction": d.friction, "contact": d.contact}


def _grid(f: GridFile, raw_grid: dict, fail) -> dict:
    """A grid over parameters, or over poses: its coordinates in the SPEC's order, the held ones, the maps and the
    force map's directions."""
    if f.grid is None:
        for key in ("maps", "force"):
            if key in f.model_fields_set:
                raise fail(key, "belongs to a grid over poses ([grid]), not to a grid over parameters")
        for key in ("parameters", "outputs"):
            if getattr(f, key) is None:
                raise fail(key, "missing key")
        return {"parameters": tuple(table.parameter(key) for key, table in f.parameters.items()), "outputs": tuple(f.outputs)}
    if f.parameters is not None:
        raise fail("grid", "a grid is over poses ([grid]) or over parameters ([parameters]), not both")
    if f.outputs is not None:
        raise fail("outputs", "a grid over poses computes its maps (maps = [\"workspace\", \"singularity\", \"force\"]), not outputs")
    poses, held = [], {}
    for key in raw_grid:  # the SPEC's order: the design's columns
        value = getattr(f.grid, key)
        if isinstance(value, Values):
            poses.append(value.parameter(key))
        else:
            held[key] = value
    if not poses:
        raise fail("grid", "varies no coordinate: give one as { range = [low, high], steps = n } or { values = [...] }")
    maps = list(MAPS) if f.maps is None else f.maps
    if not maps or len(set(maps)) != len(maps):
        raise fail("maps", "must name each map once, at least one")
    directions = dict(DEFAULT_DIRECTIONS)
    given = None if f.force is None else f.force.directions
    if given is not None:
        if "force" not in maps:
            raise fail("force.directions", "the force map is not among the maps")
        if not given:
            raise fail("force.directions", "names no direction")
        directions = {}
        for name, v in given.items():
            size = math.sqrt(sum(x * x for x in v))
            if not size > 0:
                raise fail(f"force.directions.{quoted(name)}", "is the zero vector")
            if not name.replace("_", "").isalnum():
                raise fail(f"force.directions.{quoted(name)}", "a direction's name is letters, digits and _ (it names a column)")
            directions[name] = tuple(x / size for x in v)
    return {"poses": tuple(poses), "pose_fixed": held, "maps": tuple(maps), "directions": directions}


def _check_against_model(spec: Spec, fail) -> None:
    """The parameter keys and fixed values name numbers that the model (and the counterpart) has, with values it
    accepts at the parameters' central values; the outputs exist for its mechanism."""
    from chewbot.model.params import apply_overrides, model_from_dict, read_parameter_file, resolve_model_path, split_overrides
    from chewbot.sweep.quantities import OUTPUTS, needs_counterpart
    from chewbot.task.default import parameters_with

    models = [("model", spec.model)]
    if any(needs_counterpart(o) for o in spec.outputs + ((spec.minimize,) if spec.minimize else ())):
        counterpart = spec.counterpart or COUNTERPARTS.get(spec.model)
        if counterpart is None:
            raise fail("counterpart", "missing: a ratio output needs the model it compares with (e.g. counterpart = \"6rss\")")
        models.append(("counterpart", counterpart))
    elif spec.counterpart is not None:
        raise fail("counterpart", "no output compares with a counterpart (ratio_MCI...)")
    if spec.task != "default" and any(k.startswith("task.") for k in list(spec.fixed) + list(spec.keys)):
        key = next(k for k in list(spec.fixed) + list(spec.keys) if k.startswith("task."))
        raise fail(f"{'parameters' if key in spec.keys else 'set'}.{quoted(key)}",
                        f"the default task's parameters apply to task = \"default\", not to {spec.task}")
    from chewbot.run.options import friction_methods, unused_override

    for key in list(spec.fixed) + list(spec.keys):
        why = unused_override(key, friction=spec.friction == "on", contact=spec.contact,
                              friction_users=f"the {friction_methods()} method with friction = \"on\" (its default)")
        if why:
            raise fail(f"{'parameters' if key in spec.keys else 'set'}.{quoted(key)}", why)
    central = {p.key: p.central() for p in spec.parameters}
    for role, name in models:
        try:
            raw = read_parameter_file(resolve_model_path(name))
        except ChewbotError as exc:
            raise fail(role, str(exc)) from None
        raw.pop("__sha256__")
        mechanism = raw.get("mechanism")
        for label, overrides in ([("set", {k: v}) for k, v in spec.fixed.items()]
                                 + [("parameters", {k: v}) for k, v in central.items()]):
            key = next(iter(overrides))
            model_part, task_part = split_overrides({**spec.fixed, **overrides})
            try:
                if task_part:
                    parameters_with(task_part)
                model_from_dict(apply_overrides(raw, model_part), source=name)
            except ChewbotError as exc:
                what = "" if label == "set" else f" (at its central value {overrides[key]:g})"
                raise SpecError(f"{spec.source}: key '{label}.{quoted(key)}'{what}: {exc}") from None
        if role == "model":
            for p in spec.poses:
                if p.key in ("Z_mm", "gamma_deg") and mechanism == "target":
                    raise fail(f"grid.{p.key}", "Z and gamma of the target follow from its HKPs: vary X, Y, alpha, beta")
            for key in spec.pose_fixed:
                if key in ("Z_mm", "gamma_deg") and mechanism == "target":
                    raise fail(f"grid.{key}", "Z and gamma of the target follow from its HKPs")
            if spec.minimize and mechanism != "target" and OUTPUTS[spec.minimize].target_only:
                raise fail("minimize", f"{spec.minimize} is not defined on the 6RSS (it has no HKPs)")
