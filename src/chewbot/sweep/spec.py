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

import difflib
import hashlib
import json
import math
import tomllib
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path

from chewbot.dynamics.options import CONTACT_MODELS, GOALS
from chewbot.errors import ChewbotError
from chewbot.kinematics.options import ORIENTATIONS

KINDS = ("monte-carlo", "sobol", "grid", "optimize")
DISTRIBUTIONS = ("uniform", "normal", "lognormal")
MAPS = ("workspace", "singularity", "force")
POSE_KEYS = {"X_mm": 1e-3, "Y_mm": 1e-3, "Z_mm": 1e-3, "alpha_deg": math.pi / 180, "beta_deg": math.pi / 180,
             "gamma_deg": math.pi / 180}  # factor to SI
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
    method: str | None = "hessian"
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
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        known = ", ".join(builtin_spec_names())
        raise SpecError(f"{path}: no such SPEC file (nor a built-in SPEC: {known})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"{path}: cannot read it ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: not valid TOML ({exc})") from None
    return parse_spec(raw, str(path), base=path.parent)


def quoted(key: str) -> str:
    """A key as TOML writes it inside a table name: quoted where it has dots or brackets."""
    return f'"{key}"' if any(c in key for c in ".[]") else key


class _Reader:
    """Reads keys of a table, each once, with errors naming the file and the key; :meth:`done` refuses the rest."""

    def __init__(self, table: dict, source: str, prefix: str = ""):
        self.table, self.source, self.prefix, self.used = table, source, prefix, set()

    def error(self, key: str, reason: str) -> SpecError:
        return SpecError(f"{self.source}: key '{self.prefix}{key}': {reason}")

    def get(self, key: str, kind, default=None, required: bool = False):
        self.used.add(key)
        if key not in self.table:
            if required:
                raise self.error(key, "missing key")
            return default
        value = self.table[key]
        return _typed(value, kind, lambda reason: self.error(key, reason))

    def choice(self, key: str, choices, default=None, required: bool = False):
        value = self.get(key, str, default, required)
        if value is not None and value not in choices:
            close = difflib.get_close_matches(value, list(choices), n=1)
            raise self.error(key, f"{value!r} is not one of {', '.join(choices)}" + (f" (did you mean {close[0]!r}?)" if close else ""))
        return value

    def done(self, allowed: tuple[str, ...] | None = None) -> None:
        for key in self.table:
            if key not in self.used:
                known = sorted(self.used if allowed is None else allowed)
                close = difflib.get_close_matches(key, known, n=1)
                hint = f"; did you mean '{self.prefix}{close[0]}'?" if close else ""
                raise self.error(key, f"unknown key{hint} (docs/sweeps.md lists the keys of each kind)")


def _typed(value, kind, error):
    """``value`` checked against ``kind``: int, float (an int is accepted), str, bool, dict, list."""
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise error(f"must be a number, not {value!r}")
        if not math.isfinite(value):
            raise error(f"must be a finite number, not {value!r}")
        return float(value)
    if kind is int and (isinstance(value, bool) or not isinstance(value, int)):
        raise error(f"must be a whole number, not {value!r}")
    if kind is not int and not isinstance(value, kind):
        raise error(f"must be a {dict((int, 'whole number'), ((str, 'string'), (bool, 'true or false'), (dict, 'table'), (list, 'list')))[kind]}, not {value!r}")
    return value


def _numbers(value, error, count: int | None = None) -> tuple[float, ...]:
    if not isinstance(value, list) or (count is not None and len(value) != count) or not value:
        raise error(f"must be a list of {count or 'one or more'} numbers, not {value!r}")
    return tuple(_typed(v, float, lambda reason: error(f"entry {i + 1} {reason}")) for i, v in enumerate(value))


def _parameter(key: str, table, kinds: tuple[str, ...], error) -> Parameter:
    """A parameter's table: one of ``kinds`` (``{ uniform = [lo, hi] }``, ``{ range = [lo, hi], steps = n }`` ...).
    ``error(suffix, reason)``: the error for the key with ``suffix`` (``""``, ``".uniform"``) after it."""
    if not isinstance(table, dict):
        example = {"uniform": "{ uniform = [low, high] }", "values": "{ values = [...] } or { range = [low, high], steps = n }",
                   "bounds": "{ bounds = [low, high] }"}[kinds[0]]
        raise error("", f"must be a table such as {example}, not {table!r}")
    given = set(table)
    if "values" in kinds and given == {"range", "steps"}:
        lo, hi = _numbers(table["range"], lambda r: error(".range", r), 2)
        steps = _typed(table["steps"], int, lambda r: error(".steps", r))
        if steps < 1 or (steps > 1 and not lo < hi) or (steps == 1 and lo != hi):
            raise error("", f"range [{lo}, {hi}] with {steps} steps: give low < high and steps >= 2 (or one step with low = high)")
        return Parameter(key, "values", tuple(lo + (hi - lo) * k / max(steps - 1, 1) for k in range(steps)))
    if len(given) != 1 or not given <= set(kinds):
        unknown = sorted(given - set(kinds) - ({"range", "steps"} if "values" in kinds else set()))
        what = f"unknown entry {unknown[0]!r}; " if unknown else ""
        raise error("", f"{what}give exactly one of {', '.join(kinds)}" + (" (or range and steps)" if "values" in kinds else ""))
    kind = given.pop()
    args = table[kind]
    sub = lambda r: error(f".{kind}", r)  # noqa: E731
    if kind == "values":
        return Parameter(key, kind, _numbers(args, sub))
    a, b = _numbers(args, sub, 2)
    if kind in ("uniform", "bounds") and not a < b:
        raise sub(f"[{a}, {b}] is not an interval [low, high] with low < high")
    if kind in ("normal", "lognormal") and not b > 0:
        raise sub(f"the standard deviation ({b}) must be positive")
    return Parameter(key, kind, (a, b))


def parse_spec(raw: dict, source: str = "<spec>", base: Path | None = None) -> Spec:
    """Validate a parsed SPEC (see :func:`read_spec`); relative paths resolve against ``base``."""
    from chewbot.model.params import BUILTIN_MODELS

    top = _Reader(raw, source)
    kind = top.choice("kind", KINDS, required=True)
    base = base or Path(".")

    def resolved(key: str, value: str, builtin=()) -> str:
        if value in builtin or value == "default" and key == "task":
            return value
        path = Path(value).expanduser()
        path = path if path.is_absolute() else base / path
        if not path.is_file():
            raise top.error(key, f"{value!r} is " + (f"neither a built-in model ({', '.join(BUILTIN_MODELS)}) nor " if key != "task" else "neither 'default' nor ")
                            + f"a file (looked for {path})")
        return str(path)

    model = resolved("model", top.get("model", str, "target"), BUILTIN_MODELS)
    task = resolved("task", top.get("task", str, "default"))
    side = top.choice("side", ("left", "right"))
    orientation = top.choice("orientation", ORIENTATIONS, "euler-angles")
    method = top.get("method", str, None)
    values: dict = {"source": source, "kind": kind, "model": model, "task": task, "side": side, "orientation": orientation}
    values.update(_dynamics_options(top, method, orientation, _mechanism(top, model)))
    values["seed"] = top.get("seed", int, 0)
    if values["seed"] < 0:
        raise top.error("seed", "must be >= 0")
    values["fixed"] = _fixed(top)
    counterpart = top.get("counterpart", str, None)
    if counterpart is not None:
        counterpart = resolved("counterpart", counterpart, BUILTIN_MODELS)
    values["counterpart"] = counterpart

    if kind in ("monte-carlo", "sobol"):
        values["samples"] = top.get("samples", int, required=True)
        if values["samples"] < 1:
            raise top.error("samples", "must be at least 1")
        if kind == "sobol" and values["samples"] & (values["samples"] - 1):
            raise top.error("samples", f"{values['samples']} base samples: Sobol' sequences need a power of 2 (e.g. 1024)")
        values["parameters"] = _parameters(top, DISTRIBUTIONS)
        if kind == "sobol":
            sobol = _Reader(top.get("sobol", dict, {}), source, "sobol.")
            values["resamples"] = sobol.get("resamples", int, 100)
            values["confidence"] = sobol.get("confidence", float, 0.95)
            if values["resamples"] < 1 or not 0 < values["confidence"] < 1:
                raise sobol.error("resamples" if values["resamples"] < 1 else "confidence",
                                  "resamples >= 1 and 0 < confidence < 1")
            sobol.done()
            if len(values["parameters"]) < 2:
                raise top.error("parameters", "Sobol' indices need at least two parameters")
        values["outputs"] = _outputs(top, required=True)
    elif kind == "grid":
        grid = top.get("grid", dict, None)
        if grid is not None:
            if "parameters" in raw:
                raise top.error("grid", "a grid is over poses ([grid]) or over parameters ([parameters]), not both")
            if "outputs" in raw:
                raise top.error("outputs", "a grid over poses computes its maps (maps = [\"workspace\", \"singularity\", "
                                "\"force\"]), not outputs")
            values.update(_pose_grid(top, grid, model))
        else:
            values["parameters"] = _parameters(top, ("values",))
            values["outputs"] = _outputs(top, required=True)
    else:  # optimize
        values["parameters"] = _parameters(top, ("bounds",))
        values["minimize"] = top.get("minimize", str, required=True)
        _check_outputs([values["minimize"]], lambda r: top.error("minimize", r))
        if values["minimize"] == "feasible":
            raise top.error("minimize", "'feasible' is the constraint of the search, not an output to minimise")
        values["outputs"] = _outputs(top, required=False)
        values["require_feasible"] = top.get("require_feasible", bool, True)
        values["optimizer"] = _optimizer(_Reader(top.get("optimizer", dict, {}), source, "optimizer."))
    default_chunk = DEFAULT_POSE_CHUNK if values.get("poses") else DEFAULT_CHUNK
    values["chunk"] = top.get("chunk", int, default_chunk)
    if values["chunk"] < 1:
        raise top.error("chunk", "must be at least 1 evaluation per chunk")
    top.done()
    spec = Spec(**values)
    _check_against_model(spec, top)
    return spec


def _mechanism(top: _Reader, model: str) -> str:
    from chewbot.model.params import load_model

    try:
        return load_model(model).mechanism
    except ChewbotError as exc:
        raise top.error("model", str(exc)) from None


def _dynamics_options(top: _Reader, method: str | None, orientation: str, mechanism: str) -> dict:
    """method, goal, friction, contact as ``chewbot run`` takes them, with its defaults and rules
    (:func:`chewbot.run.options.resolve_dynamics`)."""
    from chewbot.dynamics.registry import METHODS
    from chewbot.run.options import OptionError, Switch, resolve_dynamics

    if method is not None and method not in METHODS:
        close = difflib.get_close_matches(method, list(METHODS), n=1)
        raise top.error("method", f"{method!r} is not a formulation; choose one of {', '.join(METHODS)}"
                        + (f" (did you mean {close[0]!r}?)" if close else ""))
    goal = top.choice("goal", GOALS)
    friction = top.choice("friction", tuple(Switch))
    contact = top.choice("contact", CONTACT_MODELS, "bilateral")
    try:
        d = resolve_dynamics(method, orientation, goal, friction, contact, has_hkp=mechanism == "target")
    except OptionError as exc:
        raise top.error(exc.options[0], exc.reason if len(exc.options) == 1 else exc.worded(lambda option: f"'{option}'")) from None
    return {"method": d.method, "goal": d.goal, "friction": d.friction, "contact": d.contact}


def _fixed(top: _Reader) -> dict:
    table = top.get("set", dict, {})
    out = {}
    for key, value in table.items():
        out[key] = _typed(value, float, lambda r, key=key: top.error(f"set.{quoted(key)}", r))
    return out


def _parameters(top: _Reader, kinds: tuple[str, ...]) -> tuple[Parameter, ...]:
    table = top.get("parameters", dict, required=True)
    if not table:
        raise top.error("parameters", "names no parameter")
    return tuple(_parameter(key, value, kinds, lambda suffix, r, key=key: top.error(f"parameters.{quoted(key)}{suffix}", r))
                 for key, value in table.items())


def _outputs(top: _Reader, required: bool) -> tuple[str, ...]:
    names = top.get("outputs", list, None if not required else None, required=required)
    if names is None:
        return ()
    if not names or not all(isinstance(n, str) for n in names):
        raise top.error("outputs", "must be a list of output names, e.g. [\"peak_tau_Nm\", \"mean_MCI\"]")
    _check_outputs(names, lambda r: top.error("outputs", r))
    if len(set(names)) != len(names):
        raise top.error("outputs", "names an output twice")
    return tuple(names)


def _check_outputs(names, error) -> None:
    from chewbot.sweep.quantities import OUTPUTS

    for name in names:
        if name not in OUTPUTS:
            close = difflib.get_close_matches(name, list(OUTPUTS), n=1)
            raise error(f"unknown output {name!r}" + (f"; did you mean {close[0]!r}?" if close else "")
                        + " (docs/sweeps.md lists the outputs)")


def _pose_grid(top: _Reader, grid: dict, model: str) -> dict:
    reader = _Reader(grid, top.source, "grid.")
    poses, fixed = [], {}
    for key in grid:
        if key not in POSE_KEYS:
            reader.used.add(key)
            close = difflib.get_close_matches(key, list(POSE_KEYS), n=1)
            raise reader.error(key, "not a pose coordinate" + (f" (did you mean {close[0]!r}?)" if close else "")
                               + f"; the coordinates are {', '.join(POSE_KEYS)}")
        value = grid[key]
        reader.used.add(key)
        if isinstance(value, dict):
            poses.append(_parameter(key, value, ("values",), lambda suffix, r, key=key: reader.error(key + suffix, r)))
        else:
            fixed[key] = _typed(value, float, lambda r, key=key: reader.error(key, r))
    if not poses:
        raise top.error("grid", "varies no coordinate: give one as { range = [low, high], steps = n } or { values = [...] }")
    maps = top.get("maps", list, list(MAPS))
    for name in maps:
        if name not in MAPS:
            raise top.error("maps", f"{name!r} is not a map; choose among {', '.join(MAPS)}")
    if not maps or len(set(maps)) != len(maps):
        raise top.error("maps", "must name each map once, at least one")
    directions = dict(DEFAULT_DIRECTIONS)
    force = _Reader(top.get("force", dict, {}), top.source, "force.")
    given = force.get("directions", dict, None)
    force.done()
    if given is not None:
        if "force" not in maps:
            raise force.error("directions", "the force map is not among the maps")
        if not given:
            raise force.error("directions", "names no direction")
        directions = {}
        for name, vector in given.items():
            v = _numbers(vector, lambda r, name=name: force.error(f"directions.{name}", r), 3)
            size = math.sqrt(sum(x * x for x in v))
            if not size > 0:
                raise force.error(f"directions.{name}", "is the zero vector")
            if not name.replace("_", "").isalnum():
                raise force.error(f"directions.{name}", "a direction's name is letters, digits and _ (it names a column)")
            directions[name] = tuple(x / size for x in v)
    return {"poses": tuple(poses), "pose_fixed": fixed, "maps": tuple(maps), "directions": directions}


OPTIMIZER_DEFAULTS = {"generations": 30, "popsize": 8, "tol": 0.01, "atol": 0.0, "mutation": [0.5, 1.0],
                      "recombination": 0.7, "init": "latinhypercube"}


def _optimizer(reader: _Reader) -> dict:
    """Differential evolution's settings (scipy.optimize.differential_evolution's names; generations is its
    maxiter)."""
    out = {"generations": reader.get("generations", int, 30), "popsize": reader.get("popsize", int, 8),
           "tol": reader.get("tol", float, 0.01), "atol": reader.get("atol", float, 0.0),
           "recombination": reader.get("recombination", float, 0.7),
           "init": reader.choice("init", ("latinhypercube", "sobol", "halton", "random"), "latinhypercube")}
    mutation = reader.table.get("mutation", [0.5, 1.0])
    reader.used.add("mutation")
    if isinstance(mutation, list):
        out["mutation"] = list(_numbers(mutation, lambda r: reader.error("mutation", r), 2))
        if not 0 <= out["mutation"][0] <= out["mutation"][1] < 2:
            raise reader.error("mutation", "dithering [low, high] with 0 <= low <= high < 2")
    else:
        out["mutation"] = _typed(mutation, float, lambda r: reader.error("mutation", r))
        if not 0 <= out["mutation"] < 2:
            raise reader.error("mutation", "must lie in [0, 2)")
    for key in ("generations", "popsize"):
        if out[key] < 1:
            raise reader.error(key, "must be at least 1")
    if out["tol"] < 0 or out["atol"] < 0 or not 0 <= out["recombination"] <= 1:
        raise reader.error("tol" if out["tol"] < 0 else "atol" if out["atol"] < 0 else "recombination",
                           "tol, atol >= 0 and 0 <= recombination <= 1")
    reader.done()
    return out


def _check_against_model(spec: Spec, top: _Reader) -> None:
    """The parameter keys and fixed values name numbers that the model (and the counterpart) has, with values it
    accepts at the parameters' central values; the outputs exist for its mechanism."""
    from chewbot.model.params import apply_overrides, model_from_dict, read_parameter_file, resolve_model_path, split_overrides
    from chewbot.sweep.quantities import OUTPUTS, needs_counterpart
    from chewbot.task.default import parameters_with

    models = [("model", spec.model)]
    if any(needs_counterpart(o) for o in spec.outputs + ((spec.minimize,) if spec.minimize else ())):
        counterpart = spec.counterpart or COUNTERPARTS.get(spec.model)
        if counterpart is None:
            raise top.error("counterpart", "missing: a ratio output needs the model it compares with (e.g. counterpart = \"6rss\")")
        models.append(("counterpart", counterpart))
    elif spec.counterpart is not None:
        raise top.error("counterpart", "no output compares with a counterpart (ratio_MCI...)")
    if spec.task != "default" and any(k.startswith("task.") for k in list(spec.fixed) + list(spec.keys)):
        key = next(k for k in list(spec.fixed) + list(spec.keys) if k.startswith("task."))
        raise top.error(f"{'parameters' if key in spec.keys else 'set'}.{quoted(key)}",
                        f"the default task's parameters apply to task = \"default\", not to {spec.task}")
    from chewbot.run.options import friction_methods, unused_override

    for key in list(spec.fixed) + list(spec.keys):
        why = unused_override(key, friction=spec.friction == "on", contact=spec.contact,
                              friction_users=f"the {friction_methods()} method with friction = \"on\" (its default)")
        if why:
            raise top.error(f"{'parameters' if key in spec.keys else 'set'}.{quoted(key)}", why)
    central = {p.key: p.central() for p in spec.parameters}
    for role, name in models:
        try:
            raw = read_parameter_file(resolve_model_path(name))
        except ChewbotError as exc:
            raise top.error(role, str(exc)) from None
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
                raise SpecError(f"{top.source}: key '{label}.{quoted(key)}'{what}: {exc}") from None
        if role == "model":
            for p in spec.poses:
                if p.key in ("Z_mm", "gamma_deg") and mechanism == "target":
                    raise top.error(f"grid.{p.key}", "Z and gamma of the target follow from its HKPs: vary X, Y, alpha, beta")
            for key in spec.pose_fixed:
                if key in ("Z_mm", "gamma_deg") and mechanism == "target":
                    raise top.error(f"grid.{key}", "Z and gamma of the target follow from its HKPs")
            if spec.minimize and mechanism != "target" and OUTPUTS[spec.minimize].target_only:
                raise top.error("minimize", f"{spec.minimize} is not defined on the 6RSS (it has no HKPs)")
