"""The ``[comminution]`` table of a food file: how a portion of the food breaks down when it is chewed.

One strict model (:class:`ComminutionTable`, on :class:`chewbot.config.Strict`): every key carries its unit, every
value has its hard limits and a plausible range, and :meth:`ComminutionTable.si` gives the values in SI for
:mod:`chewbot.food.bolus`, which holds the laws these parameters enter (docs/bolus.md):

* the portion: ``portion_g`` of pieces of sieve size ``piece_size_mm`` and density ``density_kg_per_m3``;
* selection: a lone particle on the occlusal table (``table_area_mm2``) is caught in a stroke with the chance
  ``placement``; crowding lowers it; the table's cusps (relief ``relief_mm``, exponent ``relief_exponent``) decide
  which sizes the closing teeth reach;
* breakage: a caught particle breaks with Weibull's probability under the stress on the loaded particles, its strength
  ``strength_at_1mm_MPa`` at 1 mm scaled with size by the Weibull modulus ``weibull_modulus``; its fragments follow a
  Rosin-Rammler law truncated at the parent's size, median ``fragment_size`` x the parent's, spread
  ``fragment_spread``;
* the particle bed: ``bed_porosity`` when loose, ``bed_modulus_kPa`` when first compressed (dry, of coarse
  fragments) and ``bed_compaction_strain``, the strain over which its stiffness grows e-fold, ``bed_damping_s_per_m``
  its Hunt-Crossley damping while it is compressed (the robot's plant); its softening as it is comminuted: the paste
  of the cells a fracture opens, ``paste_depth_mm`` deep under every particle's surface, lowers its modulus as
  (1 - paste fraction)^``paste_exponent``;
* ``fitted``: the keys a fit (``chewbot fit-comminution``) has set.

This module imports no other part of the food layer, so that the food reader (:mod:`chewbot.food.law`) can hand the
table of a food file to it.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, field_validator

from chewbot.config import Plausible, Strict
from chewbot.units import factor, key_unit

# key -> (plausible low, plausible high, what the range covers), in the unit the key ends with (chewbot.units.key_unit;
# "1" for a plain number). The one table of the parameters: the model's fields, the fit's parameters and the docs'
# list are read from it, through PARAMETERS.
_RANGES = {
    "portion_g": (0.1, 50.0, "portions of food taken into the mouth"),
    "piece_size_mm": (1.0, 22.0, "sizes of the pieces of a portion between the molars"),
    "density_kg_per_m3": (300.0, 2000.0, "densities of foods"),
    "table_area_mm2": (10.0, 1000.0, "occlusal areas of the teeth that meet a bolus"),
    "placement": (0.01, 1.0, "chances that a lone particle is caught in a stroke"),
    "relief_mm": (0.05, 5.0, "depths of the cusps' relief"),
    "relief_exponent": (0.5, 5.0, "exponents of the relief's area law"),
    "strength_at_1mm_MPa": (0.01, 1000.0, "fracture strengths of food particles"),
    "weibull_modulus": (1.0, 50.0, "Weibull moduli of brittle materials"),
    "fragment_size": (0.05, 0.95, "median fragment sizes as a share of the parent's"),
    "fragment_spread": (0.5, 10.0, "Rosin-Rammler spreads of fragments"),
    "bed_porosity": (0.1, 0.9, "porosities of loose particle beds"),
    "bed_modulus_kPa": (1.0, 1e6, "moduli of dry food particle beds at first compression"),
    "paste_depth_mm": (0.005, 1.0, "depths of the cell layer a fracture opens (the food's cells)"),
    "paste_exponent": (0.5, 10.0, "exponents of a bed's softening with its paste fraction"),
    "bed_compaction_strain": (0.02, 1.0, "strains over which a bed's stiffness grows e-fold"),
    "bed_damping_s_per_m": (0.1, 100.0, "Hunt-Crossley damping of food particle beds (75 s/m: no rebound at 2 cm/s)"),
}


def _unit(key: str) -> str:
    return key_unit(key)[1] or "1"


# key -> (factor to SI, unit as shown, plausible low, plausible high, what the range covers)
PARAMETERS = {key: (factor(_unit(key)), _unit(key), low, high, what) for key, (low, high, what) in _RANGES.items()}
# The keys a fit may set: the selection and the breakage.
FITTABLE = ("placement", "relief_mm", "relief_exponent", "strength_at_1mm_MPa", "weibull_modulus", "fragment_size",
            "fragment_spread")


def _field(key: str, **limits):
    """A parameter's annotation: a number within its hard ``limits``, then within its plausible range (a value outside
    it is most likely in another unit, and an error naming the range)."""
    _, unit, low, high, what = PARAMETERS[key]
    return Annotated[float, Field(**limits), Plausible(low, high, unit, what)]


class ComminutionTable(Strict):
    """The ``[comminution]`` table as written (file units); :meth:`si` in SI."""

    DOCS = "docs/bolus.md"

    portion_g: _field("portion_g", gt=0)
    piece_size_mm: _field("piece_size_mm", gt=0)
    density_kg_per_m3: _field("density_kg_per_m3", gt=0)
    table_area_mm2: _field("table_area_mm2", gt=0)
    placement: _field("placement", gt=0, le=1)
    relief_mm: _field("relief_mm", gt=0)
    relief_exponent: _field("relief_exponent", gt=0)
    strength_at_1mm_MPa: _field("strength_at_1mm_MPa", gt=0)
    weibull_modulus: _field("weibull_modulus", gt=0)
    fragment_size: _field("fragment_size", gt=0, lt=1)
    fragment_spread: _field("fragment_spread", gt=0)
    bed_porosity: _field("bed_porosity", gt=0, lt=1)
    bed_modulus_kPa: _field("bed_modulus_kPa", gt=0)
    paste_depth_mm: _field("paste_depth_mm", gt=0)
    paste_exponent: _field("paste_exponent", gt=0)
    bed_compaction_strain: _field("bed_compaction_strain", gt=0)
    bed_damping_s_per_m: _field("bed_damping_s_per_m", ge=0)
    fitted: list[str] = []

    @field_validator("fitted")
    @classmethod
    def _fittable(cls, keys: list[str]) -> list[str]:
        for key in keys:
            if key not in FITTABLE:
                raise ValueError(f"{key!r} is not a key a fit sets (those are {', '.join(FITTABLE)})")
        if len(set(keys)) != len(keys):
            raise ValueError("a key is listed twice")
        return keys

    def si(self) -> dict[str, float]:
        """The parameters in SI, keyed by the file's keys."""
        return {key: getattr(self, key) * PARAMETERS[key][0] for key in PARAMETERS}


__all__ = ["FITTABLE", "PARAMETERS", "ComminutionTable"]
