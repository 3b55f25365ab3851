"""The gains file of ``chewbot simulate``: one section per controller of the table, and the estimator's and the force
observer's, each a strict model (:class:`Section`, on :class:`chewbot.config.Strict`).

The file is read by :func:`chewbot.config.read_text` and validated by :func:`chewbot.config.validate`: an unknown
section or key, a quoted number, a value that is not a gain are errors in the one form ``FILE: key 'pd.kp_Nm_per_rad':
reason``. A key the file leaves out takes the built-in value (``gains.toml`` beside this package), listed as
``defaulted`` in run.json. Sections are built from the controller table (:data:`~chewbot.simulation.controllers.table.CONTROLLERS`:
each row's ``gains`` names its section, its law module's ``Gains`` is the model) and :data:`PARTS`.

A key of a section is either a gain of several entries (one number for all, or a list of one per entry: six cranks,
the n independent coordinates, the molar point's x, y, z; declared by :class:`Entries` beside the field), finite and
not negative, or a single positive number. After reading, each section is sized to its entries
(:meth:`Section.sized`); ``--gain KEY=VALUE`` overrides then set a whole key, or ``KEY[i]=VALUE`` its i-th entry
(1-based), and are validated by the same model, their errors naming the override.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import PlainValidator, create_model

from chewbot.compiled.layout import Layout
from chewbot.config import Strict, read_text, validate
from chewbot.errors import ChewbotError
from chewbot.simulation.controllers.table import CONTROLLERS

# A gain of one entry per independent coordinate (Entries(COORDINATES)): 4 on the target, 6 on the 6RSS.
COORDINATES = "coordinates"


@dataclass(frozen=True)
class Entries:
    """How many entries a gain has: a number, or :data:`COORDINATES`."""

    count: int | str

    def size(self, n: int) -> int:
        return n if self.count == COORDINATES else int(self.count)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _gain(value) -> float | tuple[float, ...]:
    """One number or a list of numbers, each finite and not negative."""
    values = value if isinstance(value, (list, tuple)) else [value]
    if not values or not all(_is_number(v) for v in values):
        raise ValueError(f"{value!r} is not a number or a list of numbers")
    if not all(math.isfinite(v) and v >= 0 for v in values):
        raise ValueError(f"gains must be finite and non-negative, got {[float(v) for v in values]}")
    return tuple(float(v) for v in values) if isinstance(value, (list, tuple)) else float(value)


def _positive(value) -> float:
    if not _is_number(value) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"expected one positive number, not {value!r}")
    return float(value)


Gain = Annotated[float | tuple[float, ...], PlainValidator(_gain)]
Positive = Annotated[float, PlainValidator(_positive)]


class Section(Strict):
    """A section of the gains file. A field annotated ``Annotated[Gain, Entries(k)]`` has k entries; a
    :data:`Positive` field is one number. :meth:`vector` is the gains input of the section's control law, laid out
    as :meth:`layout` says (sized sections only)."""

    @classmethod
    def entries(cls) -> dict[str, Entries | None]:
        """Each key's :class:`Entries` (None: a single number)."""
        return {name: next((m for m in f.metadata if isinstance(m, Entries)), None) for name, f in cls.model_fields.items()}

    def sized(self, n: int, where: str, section: str) -> Section:
        """Every gain expanded to its entries (a number to all of them); a list of another length is an error naming
        ``where`` and the key."""
        values = dict(self)
        for key, entries in self.entries().items():
            value = values[key]
            if entries is not None:
                size = entries.size(n)
                value = (value,) * size if isinstance(value, float) else value
                if len(value) != size:
                    raise ChewbotError(f"{where}: key '{section}.{key}': expected one number or {size}, got {len(value)}")
            values[key] = value
        return type(self).model_validate(values)

    @classmethod
    def layout(cls, n: int) -> Layout:
        """The control law's gains input (:meth:`vector`)."""
        return Layout.of()

    def vector(self) -> np.ndarray:
        return np.zeros(0)


class ErrorDynamics(Section):
    """A section whose law reads, per coordinate, the stiffness and damping of second-order error dynamics given by
    the fields ``frequency_Hz`` and ``damping`` (each subclass declares them with their entries): kp = (2 pi f)^2,
    kd = 2 zeta (2 pi f), e_ddot + kd e_dot + kp e = 0."""

    @classmethod
    def layout(cls, n: int) -> Layout:
        return Layout.of(kp=n, kd=n)

    def vector(self) -> np.ndarray:
        w = 2 * np.pi * np.array(self.frequency_Hz)
        return self.layout(w.size).pack(kp=w**2, kd=2 * np.array(self.damping) * w)


class EstimatorGains(Section):
    """The crank sensor's velocity estimate (:class:`chewbot.simulation.sensor.CrankSensor`)."""

    cutoff_Hz: Positive


class ObserverGains(Section):
    """The force observer's low-pass (:class:`chewbot.simulation.observer.ForceObserver`)."""

    cutoff_Hz: Positive


# The sections of parts other than the controllers.
PARTS: dict[str, type[Section]] = {"estimator": EstimatorGains, "observer": ObserverGains}


def default_gains_file() -> Path:
    return Path(__file__).parent.parent / "gains.toml"


@cache
def sections() -> dict[str, type[Section]]:
    """Every section of the gains file and its model, in the order of the table, then :data:`PARTS`."""
    out = {row.gains: row.module().Gains for row in CONTROLLERS.values() if row.gains is not None}
    return {**out, **PARTS}


@cache
def file_model() -> type[Strict]:
    """The gains file as a strict model: a section per :func:`sections`, each optional (filled from the built-in
    file before validation)."""
    return create_model("GainsFile", __base__=Strict, **{name: (model | None, None) for name, model in sections().items()})


def _keys() -> list[str]:
    return [f"{s}.{k}" for s, model in sections().items() for k in model.model_fields]


@dataclass(frozen=True)
class Gains:
    """The gains of a simulation, each section sized (:meth:`Section.sized`): ``gains["pd"]`` is the ``[pd]`` section.
    ``source``: the file they were read from; ``overrides``: the single values changed (``--gain``); ``defaulted``:
    keys the file left out (built-in values)."""

    sections: dict[str, Section]
    source: str = ""
    overrides: dict = field(default_factory=dict)
    defaulted: tuple[str, ...] = ()

    def __getitem__(self, section: str) -> Section:
        return self.sections[section]

    @classmethod
    def load(cls, path: str | Path | None = None, mechanism: str = "target", overrides: dict[str, float] | None = None) -> Gains:
        """Gains from a TOML file (default: the built-in ``gains.toml``), then single values ``overrides``
        (``{"pd.kp_Nm_per_rad": 3.0, "pd.kp_Nm_per_rad[2]": 4.0}``: a key sets every entry, KEY[i] the i-th, 1-based).
        A key the file leaves out takes the built-in value. Errors name the file (or the override) and the key."""
        from chewbot.simulation.forward import n_coordinates

        builtin = default_gains_file()
        path = Path(path) if path is not None else builtin
        data = read_text(path, "gains file").data
        defaulted = []
        if path != builtin:
            for section, content in read_text(builtin, "gains file").data.items():
                given = data.setdefault(section, {})
                if isinstance(given, dict):
                    for key, value in content.items():
                        if key not in given:
                            given[key] = value
                            defaulted.append(f"{section}.{key}")
        read = validate(file_model(), data, str(path))
        n = n_coordinates(mechanism)
        sized = {name: section.sized(n, str(path), name) for name, section in dict(read).items()}
        for key, value in (overrides or {}).items():
            sized = _override(sized, key, value)
        return cls(sized, str(path), dict(overrides or {}), tuple(defaulted))

    def as_dict(self) -> dict:
        """run.json's record of the gains: file, overrides, defaulted, and every ``section.key``."""
        out = {"file": self.source, "overrides": self.overrides, "defaulted": list(self.defaulted)}
        for name, section in self.sections.items():
            for key, value in section.model_dump().items():
                out[f"{name}.{key}"] = list(value) if isinstance(value, tuple) else value
        return out


def _override(sized: dict[str, Section], key: str, value: float) -> dict[str, Section]:
    """``sized`` with the override ``key`` (``section.key`` or ``section.key[i]``) set to ``value``."""
    where = f"--gain {key}={value:g}"
    base, _, index = key.partition("[")
    section, _, name = base.partition(".")
    if section not in sized or name not in type(sized[section]).model_fields:
        raise ChewbotError(f"{where}: unknown key {base!r}; the keys are {', '.join(sorted(_keys()))}")
    current = dict(sized[section])[name]
    if index:
        try:
            i = int(index.rstrip("]")) - 1
        except ValueError:
            raise ChewbotError(f"{where}: the index must be a whole number (1-based)") from None
        count = len(current) if isinstance(current, tuple) else 1
        if not isinstance(current, tuple) or not 0 <= i < count:
            raise ChewbotError(f"{where}: {base} has {count} entr{'ies' if count > 1 else 'y'}")
        new = current[:i] + (value,) + current[i + 1:]
    else:
        new = (value,) * len(current) if isinstance(current, tuple) else value
    checked = validate(file_model(), {section: {**sized[section].model_dump(), name: new}}, where)
    return {**sized, section: dict(checked)[section]}
