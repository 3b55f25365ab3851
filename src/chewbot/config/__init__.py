"""The one strict reader of chewbot's TOML files: parameter files, registrations, foods, gains, sweep SPECs.

Every format is a pydantic model derived from :class:`Strict` (unknown keys refused, no quoted numbers, no NaN or
infinity unless a field allows it, frozen), read by :func:`read_toml`, and every problem is reported in one form,
``FILE: key 'a.b[2]': reason`` (list positions 1-based, as chains and rows are counted everywhere else), raised as
the exception type of the caller's domain (a parameter file's :class:`~chewbot.errors.ParameterError`, a
registration's :class:`~chewbot.errors.RecordingError`, ...).
"""

from __future__ import annotations

import hashlib
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, ConfigDict, ValidationError

from chewbot.errors import ChewbotError


class Strict(BaseModel):
    """The base of every file format: a quoted number is an error, not silently converted; an unknown key is an
    error; NaN and infinity are refused unless a field allows them; instances are frozen."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


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


def validate(schema: type[S], data: dict, source: str, error: type[ChewbotError] = ChewbotError) -> S:
    """``data`` validated as ``schema``; every problem in one message of :func:`format_validation_error`."""
    try:
        return schema.model_validate(data)
    except ValidationError as exc:
        raise error(format_validation_error(source, exc)) from None


def read_toml(path: Path | str, schema: type[S], what: str = "file", error: type[ChewbotError] = ChewbotError) -> S:
    """A TOML file read and validated as ``schema``."""
    text = read_text(path, what, error)
    return validate(schema, text.data, str(text.path), error)


def format_validation_error(source: str, exc: ValidationError) -> str:
    """pydantic's errors as chewbot words them: one line per problem, ``SOURCE: key 'a.b[2]': reason``."""
    lines = []
    for err in exc.errors():
        key = ""
        for part in err["loc"]:  # list positions 1-based, as chains and rows are counted everywhere else
            key += f"[{part + 1}]" if isinstance(part, int) else (f".{part}" if key else str(part))
        key = key or "(top level)"
        if err["type"] == "missing":
            reason = "missing key"
        elif err["type"] == "extra_forbidden":
            reason = "unknown key"
        else:
            reason = err["msg"].removeprefix("Value error, ")
        lines.append(f"{source}: key '{key}': {reason}")
    return "\n".join(lines)
