"""The built-in foods against published texture measurements: each food's published values and the protocol they were
measured with (``calibration.toml`` beside this module), the ideal texture analyser run with that protocol
(:func:`chewbot.food.tpa.ideal_test`), and the fit of the food file's keys marked fitted to the published values
(SciPy's ``least_squares`` on the relative differences, the keys in log scale, fractions kept at most 1).

:func:`compare` gives the published values beside chewbot's for the food as its file has it; :func:`fit` the values
that match them; :func:`table` the rows docs/food.md shows (a test holds the page to them).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from pydantic import field_validator

from chewbot.config import Strict, read_text, read_toml
from chewbot.food.law import Food, FoodError, builtin_foods, food_from_dict
from chewbot.food.tpa import MEASURES, TRIGGER_FORCE, TextureTest, ideal_test, settings

# The work from contact to the first bite's peak force (mJ): a compression-to-rupture test's work to fracture.
WORK_TO_PEAK = "work_to_peak_mJ"
QUANTITIES = MEASURES + (WORK_TO_PEAK,)
# Food-file keys that are fractions (at most 1): the fit keeps them there.
FRACTIONS = ("fracture_strain", "stiffness_after_fracture", "recovery_after_fracture", "yield_strain", "plastic_fraction")


class PublishedProtocol(Strict):
    """The protocol of a published measurement, in :func:`chewbot.food.tpa.settings`' units, and the rate (Hz) at which
    the ideal analyser samples it."""

    compression_percent: float | None = 50.0
    distance_mm: float | None = None
    test_speed_mm_s: float = 2.0
    pre_test_speed_mm_s: float = 1.0
    post_test_speed_mm_s: float | None = None
    trigger_force_N: float = TRIGGER_FORCE
    pause_s: float = 5.0
    rate_Hz: float = 1000.0

    def protocol(self):
        compression = None if self.distance_mm is not None else self.compression_percent
        return settings(compression, self.test_speed_mm_s, self.pause_s, pre_test_speed_mm_s=self.pre_test_speed_mm_s,
                        post_test_speed_mm_s=self.post_test_speed_mm_s, trigger_force_N=self.trigger_force_N,
                        distance_mm=self.distance_mm)


class Published(Strict):
    """One built-in food's published values (``published``: quantity -> value in its unit), where they come from
    (``source``), how they were measured (``protocol``, ``protocol_source``: what of it is the source's and what is
    assumed) and which keys of the food file are fitted to them."""

    name: str
    source: str
    protocol_source: str
    published: dict[str, float]
    fitted: list[str]
    protocol: PublishedProtocol

    @field_validator("published")
    @classmethod
    def _known(cls, value: dict) -> dict:
        unknown = sorted(set(value) - set(QUANTITIES))
        if unknown:
            raise ValueError(f"{unknown[0]!r} is not a measure ({', '.join(QUANTITIES)})")
        return value


class Calibrations(Strict):
    food: list[Published]


@dataclass(frozen=True)
class Comparison:
    """A food's published values beside the ideal analyser's with their protocol: ``simulated`` and ``published``
    (quantity -> value), the ``test`` and the ``values`` of the fitted keys it was run with."""

    entry: Published
    food: Food
    values: dict
    published: dict
    simulated: dict
    test: TextureTest

    @property
    def relative(self) -> dict:
        """(chewbot - published) / published per quantity."""
        return {k: (self.simulated[k] - v) / v for k, v in self.published.items()}


def calibrations() -> list[Published]:
    """The published values of the built-in foods (``calibration.toml``)."""
    path = Path(str(resources.files("chewbot") / "food" / "calibration.toml"))
    return read_toml(path, Calibrations, "calibration file", FoodError).food


def _file_table(name: str) -> dict:
    return read_text(builtin_foods()[name], "food file", FoodError).data["food"]


def _quantity(test: TextureTest, key: str) -> float:
    if key == WORK_TO_PEAK:
        return test.analysis.anchors["areas_mJ"]["before_peak_1"]
    value = test.measures[key]
    return float("nan") if value is None else value


def compare(entry: Published, values: dict | None = None) -> Comparison:
    """The ideal analyser on the food with the published protocol: the food file's values, or ``values`` for its
    fitted keys."""
    table = _file_table(entry.name)
    values = {k: table[k] for k in entry.fitted} if values is None else values
    food = food_from_dict({"food": {**table, **values}}, f"{entry.name} (calibration)")
    test = ideal_test(food, entry.protocol.protocol(), rate=entry.protocol.rate_Hz)
    simulated = {k: _quantity(test, k) for k in entry.published}
    return Comparison(entry, food, values, dict(entry.published), simulated, test)


def fit(entry: Published, start: dict | None = None) -> tuple[Comparison, object]:
    """The fitted keys' values that match the published values (least squares on the relative differences, from the
    file's values or ``start``): (the comparison at the fit, SciPy's result)."""
    from scipy.optimize import least_squares

    table = _file_table(entry.name)
    x0 = np.log([float((start or table)[k]) for k in entry.fitted])
    upper = np.array([0.0 if k in FRACTIONS else np.inf for k in entry.fitted])

    def residual(x):
        c = compare(entry, dict(zip(entry.fitted, np.exp(x).tolist())))
        return np.array(list(c.relative.values()))

    result = least_squares(residual, np.minimum(x0, upper - 1e-9), bounds=(-np.inf, upper), x_scale=1.0, diff_step=1e-6,
                           xtol=1e-10, ftol=1e-12)
    return compare(entry, dict(zip(entry.fitted, np.exp(result.x).tolist()))), result


def _number(v) -> str:
    return "null" if v is None else f"{v:.4g}"


def table() -> list[str]:
    """docs/food.md's rows of the calibration: food, quantity, published, chewbot's ideal analyser with the published
    protocol."""
    rows = []
    for entry in calibrations():
        c = compare(entry)
        for k, v in entry.published.items():
            rows.append(f"| `{entry.name}` | {k} | {_number(v)} | {_number(c.simulated[k])} |")
    return rows


def reference_table(protocol=None) -> list[str]:
    """docs/food.md's rows of every built-in food's measures by the ideal analyser under ``protocol`` (default: a
    texture analyser's, :class:`chewbot.food.tpa.Protocol`): the reference a robot's test is held against."""
    from chewbot.food.law import load_food
    from chewbot.food.tpa import Protocol

    rows = []
    for name in builtin_foods():
        m = ideal_test(load_food(name), protocol or Protocol()).measures
        rows.append(f"| `{name}` | " + " | ".join(_number(m[k]) for k in MEASURES) + " |")
    return rows


__all__ = ["Calibrations", "Comparison", "FRACTIONS", "Published", "PublishedProtocol", "QUANTITIES", "WORK_TO_PEAK",
           "calibrations", "compare", "fit", "reference_table", "table"]
