"""The one strict reader of chewbot's TOML files: parameter files, registrations, foods, gains, sweep SPECs.

Every format is a pydantic model derived from :class:`Strict` (unknown keys refused, no quoted numbers, no NaN or
infinity unless a field allows it, frozen), read by :func:`read_toml` (or :func:`read_text` then :func:`validate`),
and every problem is reported in one form, ``FILE: key 'a.b[2]': reason`` (list positions 1-based, as chains and
rows are counted everywhere else; a key with dots or brackets quoted, ``parameters."mandible.mass_g"``), raised as the
exception type of the caller's domain (a parameter file's :class:`~chewbot.errors.ParameterError`, a registration's
:class:`~chewbot.errors.RecordingError`, ...) through the ``error=`` argument.

The reasons, the same in every format:

* an unknown key: the key that was probably meant, by :func:`unknown_key`: a key with the unit of an allowed key
  missing or different is named as such (``height`` or ``height_m`` where the file takes ``height_mm``: "the unit is
  part of the key"), otherwise the closest allowed key ("did you mean 'samples'?");
* a missing key, a value of the wrong type (a quoted number is text, not a number), NaN or infinity, a value beyond
  a hard limit (a negative mass), a list of the wrong length, a choice that is not one of its choices (with the
  closest one);
* a value outside its plausible range, declared beside the field by :class:`Plausible` (its unit and a reason): a
  value given in another unit than the key's (a mandible of ``mass_g = 0.4``, a food of ``young_modulus_kPa =
  7000000``) is named as implausible when the file is read, not found later in a result. Every plausible range is
  an error: none is a warning, because a warning would be lost in a sweep's thousand evaluations and in a Python
  caller's, and the ranges are wide enough (a factor of 100 or more around the values of real robots and foods) to
  hold what a user can mean.

For a format's own rules between keys (checked after the schema), :func:`key_error` words the message in the same
form. The pieces are public for the formats that read a file in parts (a gains file's section per controller):

* :func:`read_text`: a file parsed (its data, SHA-256 and path), errors naming the file;
* :func:`validate`: data validated as a schema, ``at=`` the location of a section inside the file
  (``validate(PDGains, raw["pd"], path, error, at=("pd",))`` names ``pd.kp_Nm_per_rad``);
* :func:`format_validation_error`: pydantic's errors as chewbot words them;
* :func:`unknown_key` and :func:`did_you_mean`: the wording of an unknown key and of the closest choice (also for
  keys that are not TOML, ``--set`` and ``--gain`` arguments);
* :func:`key_path` and :func:`quoted`: a location and a key with dots as the messages write them;
* :class:`Plausible`: a plausible range as data beside a field (``Annotated[float, Field(gt=0), Plausible(10, 1e4,
  "g", "a mandible ...")]``; on a list it applies to every entry);
* :func:`either`: a value that may be of two TOML types (a number or a list, a number or a table), validated as the
  one it is, with no trace of the alternative in the key path;
* a model's ``DOCS`` (the page that lists its keys, named beside an unknown key) and ``EXAMPLE`` (how its table is
  written, shown where something else is given).
"""

from __future__ import annotations

import difflib
import hashlib
import math
import tomllib
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, ClassVar, TypeVar

from pydantic import BaseModel, ConfigDict, Discriminator, Tag, ValidationError
from pydantic.fields import FieldInfo
from pydantic_core import PydanticCustomError, core_schema

from chewbot.errors import ChewbotError
from chewbot.units import factor, key_unit, same_quantity


class Strict(BaseModel):
    """The base of every file format: a quoted number is an error, not silently converted; an unknown key is an
    error; NaN and infinity are refused unless a field allows them; instances are frozen. ``DOCS``: the page that
    lists the format's keys, named in the message of an unknown key; ``EXAMPLE``: how a table of the model is
    written, shown where something else is given (``{ uniform = [low, high] }``)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)
    DOCS: ClassVar[str] = ""
    EXAMPLE: ClassVar[str] = ""


S = TypeVar("S", bound=BaseModel)


@dataclass(frozen=True)
class TomlText:
    """A TOML file as read: its parsed content (not validated), its bytes' SHA-256 and its path."""

    data: dict
    sha256: str
    path: Path


def read_text(path: Path | str, what: str = "file", error: type[ChewbotError] = ChewbotError) -> TomlText:
    """Parse a TOML file; a missing, unreadable or malformed file is ``error`` naming it (``what``: the kind of file,
    for the message: "no such parameter file")."""
    path = Path(path)
    try:
        raw_bytes = path.read_bytes()
    except FileNotFoundError:
        raise error(f"{path}: no such {what}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror})") from None
    try:
        data = tomllib.loads(raw_bytes.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not valid TOML ({exc})") from None
    return TomlText(data, hashlib.sha256(raw_bytes).hexdigest(), path)


def validate(schema: type[S], data: Any, source: str, error: type[ChewbotError] = ChewbotError, at: tuple = ()) -> S:
    """``data`` validated as ``schema``; every problem in one message of :func:`format_validation_error`. ``at``:
    where ``data`` sits in the file (a section's name), put in front of every key."""
    try:
        return schema.model_validate(data)
    except ValidationError as exc:
        raise error(format_validation_error(source, exc, schema, at)) from None


def read_toml(path: Path | str, schema: type[S], what: str = "file", error: type[ChewbotError] = ChewbotError) -> S:
    """A TOML file read and validated as ``schema``."""
    text = read_text(path, what, error)
    return validate(schema, text.data, str(text.path), error)


def key_error(source: str, key: str, reason: str, error: type[ChewbotError] = ChewbotError) -> ChewbotError:
    """The error of one key, worded as every other: ``SOURCE: key 'KEY': REASON`` (raise it)."""
    return error(f"{source}: key '{key}': {reason}")


# ------------------------------------------------------------------------------------------ wording


def quoted(key: str) -> str:
    """A key as TOML writes it in a dotted path: in quotes where it has dots, brackets or spaces."""
    return f'"{key}"' if any(c in key for c in ".[] ") or not key else key


def key_path(loc: tuple) -> str:
    """A location as the messages write it: ``("chains", "G_mm", 2, 0)`` -> ``chains.G_mm[3][1]`` (1-based);
    the tags of :func:`either` left out."""
    key = ""
    for part in loc:
        if isinstance(part, int):
            key += f"[{part + 1}]"
        elif not part.startswith("<"):
            key += f".{quoted(part)}" if key else quoted(part)
    return key or "(top level)"


def did_you_mean(value: str, choices, quote: bool = True) -> str:
    """``" (did you mean 'x'?)"`` with the choice closest to ``value``, or ``""`` when none is close."""
    close = difflib.get_close_matches(value, [str(c) for c in choices], n=1)
    if not close:
        return ""
    return f" (did you mean {close[0]!r}?)" if quote else f" (did you mean {close[0]}?)"


def unknown_key(key: str, allowed, prefix: str = "", value: Any = None, docs: str = "") -> str:
    """Why ``key`` is not a key where ``allowed`` are (``prefix``: the path in front of them, ``"food."``;
    ``value``: the value given, for the conversion of a key with another unit): the allowed key with the same name
    and another unit or none ("the unit is part of the key"), else the closest allowed key, else the allowed keys
    where they are few; ``docs``, the page that lists them, is named after the reason."""
    allowed = list(allowed)
    stem, unit = key_unit(key)
    for other in allowed:
        other_stem, other_unit = key_unit(other)
        if other_stem != stem or other == key:
            continue
        if other_unit is None:
            return f"unknown key: {prefix}{other} is a plain number (no unit in its key)"
        if unit is None:
            return f"unknown key: the unit is part of the key: '{prefix}{other}' ({stem} in {other_unit})"
        hint = ""
        if same_quantity(unit, other_unit) and isinstance(value, (int, float)) and not isinstance(value, bool):
            hint = f"; {key} = {value:g} is {other} = {value * factor(unit) / factor(other_unit):g}"
        return f"unknown key: the unit is part of the key, and {stem} is given in {other_unit}, not {unit}: '{prefix}{other}'{hint}"
    close = difflib.get_close_matches(key, allowed, n=1)
    pointer = f" ({docs} lists the keys)" if docs else ""
    if close:
        return f"unknown key; did you mean '{prefix}{close[0]}'?{pointer}"
    if len(allowed) <= 8 or not docs:
        return f"unknown key; the keys here are {', '.join(allowed)}{pointer}" if allowed else "unknown key: no key goes here"
    return f"unknown key{pointer}"


def _number_text(value: Any) -> bool:
    try:
        float(value)
    except (TypeError, ValueError):
        return False
    return isinstance(value, str)


_TYPE_WORDS = {"float_type": "a number", "int_type": "a whole number", "int_from_float": "a whole number",
               "string_type": "text (in quotes)", "bool_type": "true or false", "list_type": "a list",
               "dict_type": "a table", "model_type": "a table", "model_attributes_type": "a table"}
_BOUND_WORDS = {"greater_than": ("gt", "greater than"), "greater_than_equal": ("ge", "at least"),
                "less_than": ("lt", "less than"), "less_than_equal": ("le", "at most")}


def _reason(err: dict, schema: type[BaseModel] | None, at: tuple = ()) -> str:
    kind, value, ctx = err["type"], err.get("input"), err.get("ctx") or {}
    loc = err["loc"]
    if kind == "missing":
        return "missing key"
    if kind == "extra_forbidden":
        model = _at(schema, loc[:-1])
        allowed = _keys(model) if model is not None else []
        parent = key_path(at + tuple(loc[:-1]))
        prefix = "" if parent == "(top level)" else parent + "."
        return unknown_key(str(loc[-1]), allowed, prefix, value, getattr(model, "DOCS", "") or getattr(schema, "DOCS", ""))
    if kind in _TYPE_WORDS or kind == "either_type":
        hint = " (in quotes it is text: write the number without them)" if _number_text(value) else ""
        expected = err["msg"] if kind == "either_type" else f"must be {_TYPE_WORDS[kind]}"
        model = _at(schema, loc) if kind == "model_type" else None
        if getattr(model, "EXAMPLE", ""):
            expected += f" such as {model.EXAMPLE}"
        return f"{expected}, not {value!r}{hint}"
    if kind == "finite_number":
        return f"must be a finite number, not {value!r}"
    if kind in _BOUND_WORDS:
        name, words = _BOUND_WORDS[kind]
        return f"must be {words} {ctx[name]:g}, not {value!r}"
    if kind in ("too_short", "too_long"):
        low, high = _lengths(schema, loc)
        count = len(value) if hasattr(value, "__len__") else "?"
        if low is not None and low == high:
            return f"must be a list of {low} {_noun(schema, loc)}, not {count}"
        if kind == "too_short":
            return f"must be a list of at least {ctx.get('min_length')} {_noun(schema, loc)}, not {count}"
        return f"must be a list of at most {ctx.get('max_length')} {_noun(schema, loc)}, not {count}"
    if kind == "literal_error":
        choices = _choices(schema, loc)
        return f"{value!r} is not one of {', '.join(map(str, choices))}" + did_you_mean(str(value), choices)
    if kind == "string_too_short":
        return "must not be empty"
    return err["msg"].removeprefix("Value error, ").removeprefix("Assertion failed, ")


def format_validation_error(source: str, exc: ValidationError, schema: type[BaseModel] | None = None,
                            at: tuple = ()) -> str:
    """pydantic's errors as chewbot words them: one line per problem, ``SOURCE: key 'a.b[2]': reason``. ``schema``:
    the model validated (for the keys allowed beside an unknown one, the choices of a choice, the length of a
    list); ``at``: where the validated data sits in the file."""
    return "\n".join(f"{source}: key '{key_path(at + tuple(err['loc']))}': {_reason(err, schema, at)}" for err in exc.errors())


# ------------------------------------------------------------------------------------------ the schema at a key


def _unwrap(annotation) -> tuple[Any, list]:
    """(the type, its metadata) of an annotation, through Annotated."""
    metadata = []
    while typing.get_origin(annotation) is Annotated:
        annotation, *extra = typing.get_args(annotation)
        metadata = extra + metadata
    return annotation, metadata


def _members(annotation) -> list:
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        return [a for a in typing.get_args(annotation) if a is not type(None)]
    return [annotation]


def _step(annotation, part):
    """The annotation one step of a location below ``annotation`` (a field, an entry, a union's tag), or None."""
    annotation, _ = _unwrap(annotation)
    members = _members(annotation)
    if isinstance(part, str) and part.startswith("<"):
        for member in members:
            if any(isinstance(m, Tag) and m.tag == part for m in _unwrap(member)[1]):
                return member
        return None
    for member in members:
        inner, _ = _unwrap(member)
        if isinstance(inner, type) and issubclass(inner, BaseModel) and isinstance(part, str):
            for name, info in inner.model_fields.items():
                if (info.alias or name) == part:
                    return Annotated[(info.annotation, *info.metadata)] if info.metadata else info.annotation
        origin, args = typing.get_origin(inner), typing.get_args(inner)
        if origin in (list, tuple) and isinstance(part, int) and args:
            return args[0]
        if origin is dict and isinstance(part, str) and len(args) == 2:
            return args[1]
    return None


def _at(schema, loc: tuple):
    """The model (a Strict subclass) at ``loc`` in ``schema``, or None."""
    for member in _members(_unwrap(_annotation(schema, loc))[0]):
        inner = _unwrap(member)[0]
        if isinstance(inner, type) and issubclass(inner, BaseModel):
            return inner
    return None


def _annotation(schema, loc: tuple):
    """The annotation at ``loc`` in ``schema`` (None where it cannot be followed)."""
    annotation = schema
    for part in loc:
        if annotation is None:
            return None
        annotation = _step(annotation, part)
    return annotation


def _keys(model: type[BaseModel]) -> list[str]:
    return [info.alias or name for name, info in model.model_fields.items()]


def _choices(schema, loc: tuple) -> list:
    for member in _members(_unwrap(_annotation(schema, loc))[0]):
        inner = _unwrap(member)[0]
        if typing.get_origin(inner) is typing.Literal:
            return list(typing.get_args(inner))
    return []


def _lengths(schema, loc: tuple) -> tuple[int | None, int | None]:
    annotation = _annotation(schema, loc)
    low = high = None
    for member in [annotation] + _members(_unwrap(annotation)[0]):
        for m in _unwrap(member)[1]:
            for constraint in m.metadata if isinstance(m, FieldInfo) else [m]:
                low = getattr(constraint, "min_length", low)
                high = getattr(constraint, "max_length", high)
    return low, high


def _noun(schema, loc: tuple) -> str:
    item = _step(_annotation(schema, loc), 0)
    inner = _unwrap(item)[0] if item is not None else None
    return "numbers" if inner in (float, int) else "lists" if typing.get_origin(inner) is list else "entries"


# ------------------------------------------------------------------------------------------ plausible ranges


@dataclass(frozen=True)
class Plausible:
    """The plausible range of a quantity, in ``unit`` (the unit its key ends with), and ``reason``, why: a value
    outside it is most likely given in another unit or mistyped, and an error naming the range when the file is
    read. Beside a field: ``Annotated[float, Field(gt=0), Plausible(10.0, 1e4, "g", "a mandible of ...")]``; on a list
    (of lists) of numbers it applies to every entry, and ``diagonal=True`` to the magnitude of the diagonal of a
    square matrix only (an inertia, whose products of inertia may be near zero, and whose negative moment is for the
    positive-definiteness check to name). Infinity passes: a field that allows it means "no
    limit" by it, not a value."""

    low: float
    high: float
    unit: str
    reason: str
    diagonal: bool = False

    def problem(self, value: float) -> str | None:
        """Why ``value`` is implausible, or None."""
        if math.isinf(value) or self.low <= value <= self.high:
            return None
        unit = "" if self.unit == "1" else f" {self.unit}"
        return (f"{value:.15g}{unit} is implausible: {self.reason} lie between {self.low:.15g} and {self.high:.15g}{unit}"
                + (" (is it in another unit?)" if unit else ""))

    def _check(self, value):
        reason = self.problem(value)
        if reason is not None:
            raise PydanticCustomError("implausible", "{reason}", {"reason": reason})
        return value

    def _check_diagonal(self, matrix):
        for i, row in enumerate(matrix):
            if self.problem(abs(row[i])) is not None:
                reason = self.problem(row[i])
                raise PydanticCustomError("implausible", "{reason}", {"reason": f"entry [{i + 1}][{i + 1}]: {reason}"})
        return matrix

    def _wrap(self, schema: dict) -> dict:
        kind = schema["type"]
        if kind == "list":
            return {**schema, "items_schema": self._wrap(schema["items_schema"])}
        if kind in ("nullable", "default"):
            return {**schema, "schema": self._wrap(schema["schema"])}
        if kind in ("float", "int") or kind.startswith("function-"):
            return core_schema.no_info_after_validator_function(self._check, schema)
        raise TypeError(f"Plausible applies to numbers and lists of numbers, not to a {kind} schema")

    def __get_pydantic_core_schema__(self, source, handler):
        schema = handler(source)
        if self.diagonal:
            return core_schema.no_info_after_validator_function(self._check_diagonal, schema)
        return self._wrap(schema)


# ------------------------------------------------------------------------------------------ either type


_TOML_TYPES = {"number": (int, float), "text": str, "list": list, "table": dict, "boolean": bool}


def _toml_type(value) -> str | None:
    if isinstance(value, bool):
        return "boolean"
    return next((name for name, kinds in _TOML_TYPES.items() if isinstance(value, kinds)), None)


def either(**members):
    """A value that may be of several TOML types (``number``, ``text``, ``list``, ``table``, ``boolean``), each
    validated as its own annotation: ``either(number=float, list=Annotated[list[float], Field(min_length=2,
    max_length=2)])``. The value's TOML type picks the one (no trace of the others in the message); a value of
    another type is "must be a number or a list"."""
    unknown = set(members) - set(_TOML_TYPES)
    if unknown or len(members) < 2:
        raise TypeError(f"either() takes two or more of the TOML types {', '.join(_TOML_TYPES)}, not {', '.join(members)}")
    words = {"number": "a number", "text": "text (in quotes)", "list": "a list", "table": "a table", "boolean": "true or false"}
    expected = " or ".join(words[m] for m in members)

    def pick(value):
        kind = _toml_type(value)
        return f"<{kind}>" if kind in members else None

    tagged = tuple(Annotated[annotation, Tag(f"<{name}>")] for name, annotation in members.items())
    return Annotated[typing.Union[tagged], Discriminator(pick, custom_error_type="either_type",
                                                         custom_error_message=f"must be {expected}")]
