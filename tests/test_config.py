"""The one strict reader (chewbot.config): every TOML format chewbot reads words each kind of mistake the same way,
``FILE: key 'a.b[2]': reason``, with its own exception type; the pieces a format reads a file with (``validate`` at a
section, ``either``, ``Plausible``) and the unit factors the formats convert with (chewbot.units)."""

from __future__ import annotations

import math
import re
import typing
from pathlib import Path
from typing import Annotated

import pytest
from pydantic import BaseModel, Field
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.config import Plausible, Strict, either, unknown_key, validate
from chewbot.errors import ChewbotError, ParameterError, RecordingError
from chewbot.food.law import FoodError, FoodFile, FoodTable, load_food
from chewbot.model.params import ParameterFile, builtin_model_path, load_model
from chewbot.recordings.registration import RegistrationFile, load_registration
from chewbot.sweep.spec import SPEC_FILES, SpecError, read_spec
from chewbot.units import factor, key_unit, same_quantity, shown

# ------------------------------------------------------------------------------------------ the formats

PARAMETERS = builtin_model_path("target").read_text()
REGISTRATION = 'units = "mm"\nrest = "first"\nscale = 1.0\n\n[fit]\nposition_weight_per_mm = 1.0\npoint_mm = [80.0, 0.0, -25.0]\n'
FOOD = ('[food]\nname = "test cylinder"\nshape = "cylinder"\nheight_mm = 8.0\ndiameter_mm = 10.0\n'
        'young_modulus_kPa = 20.0\ndamping_s_per_m = 0.0\ntooth_friction = 0.3\n')
SPEC = ('kind = "monte-carlo"\nsamples = 4\noutputs = ["peak_tau_Nm"]\n\n[set]\n"mandible.mass_g" = 350.0\n\n'
        '[parameters]\n"couplers.density_g_per_mm3" = { uniform = [2.7e-3, 7.8e-3] }\n')
GRID = 'kind = "grid"\n\n[grid]\nX_mm = { range = [-4.0, 8.0], steps = 3 }\nbeta_deg = 5.0\n'

FORMATS = {  # name: (the file's text, its reader, its error type)
    "parameters": (PARAMETERS, load_model, ParameterError),
    "registration": (REGISTRATION, load_registration, RecordingError),
    "food": (FOOD, load_food, FoodError),
    "spec": (SPEC, read_spec, SpecError),
    "grid": (GRID, read_spec, SpecError),
}

# One mistake of each kind in each format: (format, old text, new text, the key named, words of the reason).
MISTAKES = [
    # an unknown key, with the closest allowed one
    ("parameters", "mass_g = 340.22", "mas_g = 340.22", "mandible.mas_g", "unknown key; did you mean 'mandible.mass_g'?"),
    ("registration", "scale = 1.0", "scal = 1.0", "scal", "unknown key; did you mean 'scale'?"),
    ("food", "height_mm = 8.0", "heigth_mm = 8.0", "food.heigth_mm", "unknown key; did you mean 'food.height_mm'?"),
    ("spec", "samples = 4", "samples = 4\nsampels = 4", "sampels", "unknown key; did you mean 'samples'?"),
    ("grid", "beta_deg = 5.0", "beta_dge = 5.0", "grid.beta_dge", "unknown key; did you mean 'grid.beta_deg'?"),
    # a missing key
    ("parameters", "area_mm2 = 17.3494\n", "", "couplers.area_mm2", "missing key"),
    ("registration", 'units = "mm"\n', "", "units", "missing key"),
    ("food", "tooth_friction = 0.3\n", "", "food.tooth_friction", "missing key"),
    ("spec", "samples = 4\n", "", "samples", "missing key"),
    ("grid", 'kind = "grid"\n', "", "kind", "missing key"),
    # a quoted number
    ("parameters", "mass_g = 340.22", 'mass_g = "340.22"', "mandible.mass_g", "must be a number, not '340.22' (in quotes it is text"),
    ("registration", "scale = 1.0", 'scale = "1.0"', "scale", "must be a number, not '1.0' (in quotes it is text"),
    ("food", "young_modulus_kPa = 20.0", 'young_modulus_kPa = "20"', "food.young_modulus_kPa", "must be a number, not '20' (in quotes"),
    ("spec", "samples = 4", 'samples = "4"', "samples", "must be a whole number, not '4' (in quotes it is text"),
    ("grid", "beta_deg = 5.0", 'beta_deg = "5"', "grid.beta_deg", "must be a number or a table, not '5' (in quotes"),
    # NaN
    ("parameters", "mass_g = 340.22", "mass_g = nan", "mandible.mass_g", "must be a finite number, not nan"),
    ("registration", "scale = 1.0", "scale = nan", "scale", "must be a finite number, not nan"),
    ("food", "damping_s_per_m = 0.0", "damping_s_per_m = nan", "food.damping_s_per_m", "must be a finite number, not nan"),
    ("spec", '"mandible.mass_g" = 350.0', '"mandible.mass_g" = nan', 'set."mandible.mass_g"', "must be a finite number, not nan"),
    ("grid", "beta_deg = 5.0", "beta_deg = nan", "grid.beta_deg", "must be a finite number, not nan"),
    # the unit is part of the key: missing ...
    ("parameters", "mass_g = 340.22", "mass = 340.22", "mandible.mass", "the unit is part of the key: 'mandible.mass_g' (mass in g)"),
    ("registration", "point_mm =", "point =", "fit.point", "the unit is part of the key: 'fit.point_mm' (point in mm)"),
    ("food", "height_mm = 8.0", "height = 8.0", "food.height", "the unit is part of the key: 'food.height_mm' (height in mm)"),
    ("grid", "beta_deg = 5.0", "beta = 5.0", "grid.beta", "the unit is part of the key: 'grid.beta_deg' (beta in deg)"),
    # ... or another one, named with the right one (and the value converted where it is a number)
    ("parameters", "mass_g = 340.22", "mass_kg = 0.34022", "mandible.mass_kg",
     "the unit is part of the key, and mass is given in g, not kg: 'mandible.mass_g'; mass_kg = 0.34022 is mass_g = 340.22"),
    ("registration", "position_weight_per_mm", "position_weight_per_m", "fit.position_weight_per_m",
     "the unit is part of the key, and position_weight is given in 1/mm, not 1/m: 'fit.position_weight_per_mm'"),
    ("food", "height_mm = 8.0", "height_m = 0.008", "food.height_m",
     "the unit is part of the key, and height is given in mm, not m: 'food.height_mm'; height_m = 0.008 is height_mm = 8"),
    ("grid", "beta_deg = 5.0", "beta_rad = 0.1", "grid.beta_rad",
     "the unit is part of the key, and beta is given in deg, not rad: 'grid.beta_deg'; beta_rad = 0.1 is beta_deg = 5.72958"),
    # a value in another unit: implausible, with the range
    ("parameters", "mass_g = 340.22", "mass_g = 0.4", "mandible.mass_g",
     "0.4 g is implausible: masses of a mandible lie between 10 and 10000 g (is it in another unit?)"),
    ("registration", "point_mm = [80.0,", "point_mm = [80000.0,", "fit.point_mm[1]", "80000 mm is implausible"),
    ("food", "young_modulus_kPa = 20.0", "young_modulus_kPa = 7000000", "food.young_modulus_kPa",
     "7000000 kPa is implausible: Young's moduli of foods (creams tens of Pa, hard candy about 1 GPa) lie between 0.001 and 1000000 kPa"),
    ("spec", '"mandible.mass_g" = 350.0', '"mandible.mass_g" = 0.4', 'set."mandible.mass_g"', "0.4 g is implausible"),
    ("grid", "beta_deg = 5.0", "beta_deg = { values = [0.0, 1000.0] }", "grid.beta_deg.values[2]",
     "1000 deg is implausible: rotations of a mandible from its home pose lie between -180 and 180 deg"),
]


@pytest.mark.parametrize("fmt, old, new, key, words", MISTAKES, ids=[f"{m[0]}:{m[3]}" for m in MISTAKES])
def test_every_format_words_a_mistake_the_same_way(tmp_path, fmt, old, new, key, words):
    text, read, error = FORMATS[fmt]
    assert text.count(old) == 1, old
    path = tmp_path / f"{fmt}.toml"
    path.write_text(text.replace(old, new))
    with pytest.raises(error) as exc:
        read(path)
    lines = str(exc.value).splitlines()
    assert all(re.match(rf"^{re.escape(str(path))}: key '[^']+'", line) for line in lines), lines
    mine = [line for line in lines if line.startswith(f"{path}: key '{key}'")]
    assert mine and words in mine[0], lines


@pytest.mark.parametrize("fmt", FORMATS)
def test_the_unchanged_files_read(tmp_path, fmt):
    """The base of each case above is a good file: each mistake is the only one."""
    text, read, _ = FORMATS[fmt]
    path = tmp_path / f"{fmt}.toml"
    path.write_text(text)
    read(path)


def test_a_food_in_kilopascals_given_in_pascals_fails_when_read_not_in_the_test(tmp_path):
    """The issue's case: young_modulus_kPa = 7000000 (a peanut's 7 MPa written in Pa) stops `chewbot tpa` at the
    file, exit 2, nothing written; it is not found later as a test that compressed nothing."""
    path = tmp_path / "stiff.toml"
    path.write_text(FOOD.replace("young_modulus_kPa = 20.0", "young_modulus_kPa = 7000000"))
    result = CliRunner().invoke(app, ["tpa", "--food", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    assert "young_modulus_kPa" in result.output and "implausible" in result.output
    assert not (tmp_path / "out").exists()


def test_every_format_is_a_strict_model_whose_ranges_carry_their_keys_units():
    """Each file format derives from config.Strict, and every Plausible marker's unit is the unit its key ends
    with (a range in kPa on a key in kPa; "1" on a key without a unit), a unit chewbot.units knows."""
    formats = [ParameterFile, RegistrationFile, FoodFile, *SPEC_FILES.values()]
    seen = set()

    def walk(model: type[BaseModel], outer: str | None = None):
        """``outer``: the unit of the key whose value this table is (a grid coordinate's { values = [...] })."""
        seen.add(model)
        assert issubclass(model, Strict), model
        for name, info in model.model_fields.items():
            key = info.alias or name
            unit = key_unit(key)[1] or outer
            for marker in _markers(info.annotation) + list(info.metadata):
                if isinstance(marker, Plausible):
                    expected = unit or "1"  # a key without a unit is a plain number
                    assert same_quantity(marker.unit, expected) and factor(marker.unit) == factor(expected), \
                        (model.__name__, key, marker.unit)
            for inner in _models(info.annotation):
                if (inner, unit) not in seen:
                    seen.add((inner, unit))
                    walk(inner, unit)

    for fmt in formats:
        walk(fmt)
    assert len(seen) > 15


def _markers(annotation) -> list:
    out = []
    if typing.get_origin(annotation) is Annotated:
        out += list(typing.get_args(annotation)[1:])
    for arg in typing.get_args(annotation):
        out += _markers(arg)
    return out


def _models(annotation) -> list:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models(arg)]


# ------------------------------------------------------------------------------------------ the pieces


class PD(Strict):
    kp_Nm_per_rad: either(number=Annotated[float, Field(ge=0)], list=Annotated[list[Annotated[float, Field(ge=0)]], Field(min_length=6, max_length=6)])
    cutoff_Hz: Annotated[float, Field(gt=0), Plausible(1.0, 1e5, "Hz", "cut-off frequencies of a 1 kHz loop")] = 300.0


@pytest.mark.parametrize("section, line", [
    ({"kp_Nm_per_rad": [1.0] * 5}, "gains.toml: key 'pd.kp_Nm_per_rad': must be a list of 6 numbers, not 5"),
    ({"kp_Nm_per_rad": [1.0, 1.0, -1.0, 1.0, 1.0, 1.0]}, "gains.toml: key 'pd.kp_Nm_per_rad[3]': must be at least 0, not -1.0"),
    ({"kp_Nm_per_rad": "2"}, "gains.toml: key 'pd.kp_Nm_per_rad': must be a number or a list, not '2' (in quotes it is text"),
    ({"kp_Nm_per_rad": 2.0, "cutoff_Hz": 0.3}, "gains.toml: key 'pd.cutoff_Hz': 0.3 Hz is implausible: cut-off frequencies"),
    ({"kp_Nm_per_rad": 2.0, "cutof_Hz": 300.0}, "gains.toml: key 'pd.cutof_Hz': unknown key; did you mean 'pd.cutoff_Hz'?"),
    ({"kp_Nm_per_rad": 2.0, "cutoff_kHz": 0.3}, "gains.toml: key 'pd.cutoff_kHz': unknown key: the unit is part of the key, "
                                                "and cutoff is given in Hz, not kHz: 'pd.cutoff_Hz'; cutoff_kHz = 0.3 is cutoff_Hz = 300"),
])
def test_a_section_validated_in_place_names_its_keys_from_the_file(section, line):
    """validate(..., at=("pd",)) names keys as in the whole file; either() leaves no trace of the other type."""
    with pytest.raises(ChewbotError) as exc:
        validate(PD, section, "gains.toml", at=("pd",))
    assert str(exc.value).startswith(line), str(exc.value)
    assert validate(PD, {"kp_Nm_per_rad": 2}, "gains.toml").kp_Nm_per_rad == 2.0
    assert validate(PD, {"kp_Nm_per_rad": [0, 1, 2, 3, 4, 5]}, "gains.toml").kp_Nm_per_rad[5] == 5.0


def test_unknown_key_wording():
    keys = ["height_mm", "tooth_friction", "density_g_per_mm3"]
    assert unknown_key("heigt_mm", keys) == "unknown key; did you mean 'height_mm'?"
    assert unknown_key("height", keys) == "unknown key: the unit is part of the key: 'height_mm' (height in mm)"
    assert unknown_key("density_kg_per_m3", keys, value=7800) == ("unknown key: the unit is part of the key, and density "
                                                                 "is given in g/mm^3, not kg/m^3: 'density_g_per_mm3'; "
                                                                 "density_kg_per_m3 = 7800 is density_g_per_mm3 = 0.0078")
    assert unknown_key("height_deg", keys, value=3) == ("unknown key: the unit is part of the key, and height is given in "
                                                        "mm, not deg: 'height_mm'")  # no conversion across quantities
    assert unknown_key("tooth_friction_N", keys) == "unknown key: tooth_friction is a plain number (no unit in its key)"
    assert unknown_key("colour", keys, docs="docs/food.md") == ("unknown key; the keys here are height_mm, tooth_friction, "
                                                                "density_g_per_mm3 (docs/food.md lists the keys)")


# ------------------------------------------------------------------------------------------ units


def test_unit_factors_are_the_si_definitions():
    """Against the definitions (the gram is 1e-3 kg, the millimetre 1e-3 m, the degree pi/180 rad), computed here
    another way: as exact fractions."""
    from fractions import Fraction

    assert factor("mm") == float(Fraction(1, 1000)) and factor("g") == float(Fraction(1, 1000))
    assert factor("g*mm^2") == float(Fraction(1, 10**9))  # g mm^2 -> kg m^2
    assert factor("g/mm^3") == float(Fraction(10**6))  # 7.8e-3 g/mm^3 is steel's 7800 kg/m^3
    assert factor("kPa") == 1e3 and factor("mJ") == 1e-3 and factor("mm/s") == 1e-3
    assert factor("deg") * 180 == pytest.approx(math.pi, rel=1e-16)
    assert factor("N*m*s/rad") == factor("N*s/m") == factor("1") == factor("m/s^2") == 1.0
    assert factor("1/mm") == 1000.0
    with pytest.raises(ValueError, match="unknown unit 'furlong'"):
        factor("furlong")
    assert same_quantity("N*m", "Nm") and same_quantity("kPa", "N/mm^2") and not same_quantity("mm", "deg")
    assert shown("m/s") == (1000.0, "mm/s") and shown("N") == (1.0, "N") and shown("rad")[1] == "deg"


@pytest.mark.parametrize("key, stem, unit", [
    ("height_mm", "height", "mm"), ("inertia_g_mm2", "inertia", "g*mm^2"), ("density_g_per_mm3", "density", "g/mm^3"),
    ("hkp_viscous_Ns_per_m", "hkp_viscous", "N*s/m"), ("actuator_viscous_Nms_per_rad", "actuator_viscous", "N*m*s/rad"),
    ("gravity_m_per_s2", "gravity", "m/s^2"), ("position_weight_per_mm", "position_weight", "1/mm"),
    ("T_L_mm", "T_L", "mm"), ("R_C0", "R_C0", None), ("p1", "p1", None), ("tooth_friction", "tooth_friction", None),
    ("young_modulus_kPa", "young_modulus", "kPa"), ("kp_Nm_per_rad", "kp", "N*m/rad"),
])
def test_the_unit_a_key_ends_with(key, stem, unit):
    assert key_unit(key) == (stem, unit)


def test_every_unit_of_every_key_is_known():
    """Each key of the built-in files that ends with a unit names one chewbot.units can convert."""
    import tomllib

    from chewbot.food.law import builtin_foods

    def keys(table: dict):
        for k, v in table.items():
            yield k
            if isinstance(v, dict):
                yield from keys(v)

    files = [builtin_model_path(n) for n in ("target", "6rss")] + list(builtin_foods().values())
    found = {key_unit(k)[1] for f in files for k in keys(tomllib.loads(Path(f).read_text()))} - {None}
    assert {"mm", "g", "g*mm^2", "g/mm^3", "kPa", "deg", "N*s/m"} - {"deg"} <= found
    for unit in found:
        factor(unit)


@pytest.mark.parametrize("schema, page, prefix", [(ParameterFile, "models.md", ""), (FoodTable, "food.md", "")])
def test_the_documented_plausible_ranges_are_the_codes(schema, page, prefix):
    """docs/models.md and docs/food.md give each key's plausible range as the schema declares it (docs/bolus.md the
    [comminution] table's, from its own table)."""
    rows = [line for line in (Path(__file__).parents[1] / "docs" / page).read_text().splitlines()
            if line.startswith("| `") and " to " in line]

    def number(x: float) -> str:
        return f"{x:g}".replace("e+0", "e").replace("e+", "e")

    def walk(model: type[BaseModel], path: str = ""):
        for name, info in model.model_fields.items():
            key = path + (info.alias or name)
            for marker in _markers(info.annotation) + list(info.metadata):
                if isinstance(marker, Plausible):
                    shown_key = f"`{key.removeprefix(prefix)}`"
                    row = next((r for r in rows if shown_key in r.split("|")[1]), None)
                    assert row is not None, key
                    assert f"{number(marker.low)} to {number(marker.high)}" in row, (key, row)
                    found.add(key)
            for inner in _models(info.annotation):
                walk(inner, key + ".")

    found: set[str] = set()
    walk(schema)
    assert len(found) >= 7
