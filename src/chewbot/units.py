"""Units: their names and factors to SI, the units written at the end of file keys, and the ``name [unit]`` header
cells that tasks, recordings, robot logs and results tables share.

chewbot computes in SI and writes SI; the files it reads may give other units in their column headers (``X[mm]``,
``alpha [deg]``, ``dX[mm/s]``, ``ddbeta[deg/s^2]``, ``t[ms]``, ``Fz[kN]``): :func:`unit_factor` converts them, and
says in plain words why a unit cannot be used for a column. Every other conversion factor comes from here too:
:func:`factor` gives the SI factor of any product and quotient of the units of :data:`UNITS` (``factor("mm")``,
``factor("g*mm^2")``, ``factor("g/mm^3")``), and :func:`key_unit` reads the unit a TOML key ends with
(``inertia_g_mm2`` -> ``("inertia", "g*mm^2")``, ``hkp_viscous_Ns_per_m`` -> ``("hkp_viscous", "N*s/m")``), so that a
value in file units is ``value * factor(unit)`` in SI and an SI value is ``value / factor(unit)`` in file units.
"""

from __future__ import annotations

import math
import re

# Units by kind, as factors to SI.
UNITS = {
    "length": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "µm": 1e-6},
    "angle": {"rad": 1.0, "mrad": 1e-3, "deg": math.pi / 180},
    "time": {"s": 1.0, "ms": 1e-3},
    "force": {"N": 1.0, "kN": 1e3},
    "torque": {"N*m": 1.0, "Nm": 1.0, "N*mm": 1e-3, "mN*m": 1e-3},  # robot logs (chewbot identify)
    "mass": {"kg": 1.0, "g": 1e-3},
    "pressure": {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6},
    "power": {"W": 1.0},
    "energy": {"J": 1.0, "mJ": 1e-3},
    "frequency": {"Hz": 1.0, "kHz": 1e3},
}
# The dimension of each kind, as exponents of (m, kg, s, rad): what :func:`factor` multiplies to tell whether two
# units measure the same quantity. Torque is a force times a length, as N*m is.
_DIMENSIONS = {"length": (1, 0, 0, 0), "angle": (0, 0, 0, 1), "time": (0, 0, 1, 0), "force": (1, 1, -2, 0),
               "torque": (2, 1, -2, 0), "mass": (0, 1, 0, 0), "pressure": (-1, 1, -2, 0), "power": (2, 1, -3, 0),
               "energy": (2, 1, -2, 0), "frequency": (0, 0, -1, 0)}
# The units a key may end with, as keys spell them (no * or ^): the parts of a key's unit, joined by "_" for a
# product and "_per_" for a quotient (inertia_g_mm2: g*mm^2; density_g_per_mm3: g/mm^3; viscous_Nms_per_rad: N*m*s/rad).
KEY_UNITS = {"m": "m", "m2": "m^2", "m3": "m^3", "cm": "cm", "cm2": "cm^2", "cm3": "cm^3", "mm": "mm", "mm2": "mm^2", "mm3": "mm^3", "um": "um", "g": "g", "kg": "kg",
             "s": "s", "s2": "s^2", "ms": "ms", "N": "N", "kN": "kN", "Nm": "N*m", "Nmm": "N*mm", "Ns": "N*s",
             "Nms": "N*m*s", "rad": "rad", "mrad": "mrad", "deg": "deg", "Pa": "Pa", "kPa": "kPa", "MPa": "MPa", "W": "W",
             "J": "J", "mJ": "mJ", "Hz": "Hz", "kHz": "kHz"}
# How values are shown to people (figures, report tables): lengths in mm and angles in deg, their rates alike.
DISPLAY = {"m": "mm", "rad": "deg"}
# A header cell: NAME or NAME [unit] (spaces allowed around the brackets).
HEADER_CELL = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?:\[\s*([^\]]*?)\s*\])?\s*$")
_RATE_UNIT = re.compile(r"^(.+?)\s*/\s*(\w+)\s*(\^\s*2|2|²)?$")


def column_header(name: str, unit: str) -> str:
    """The header cell of a column: ``name [unit]``, or the name alone without a unit."""
    return f"{name} [{unit}]" if unit else name


def rate_unit(unit: str, order: int) -> str:
    """The unit of the ``order``-th time derivative of a quantity in ``unit`` (``m``, ``m/s``, ``m/s^2``)."""
    return unit if order == 0 else f"{unit}/s" if order == 1 else f"{unit}/s^2"


def unit_factor(unit: str, kind: str, order: int = 0) -> float:
    """Factor to SI of ``unit`` for a column of ``kind`` (a key of :data:`UNITS`) differentiated ``order`` times;
    ValueError says why not."""
    if order:
        m = _RATE_UNIT.match(unit)
        if m is None:
            raise ValueError(f"a rate of order {order} needs a unit like '{next(iter(UNITS[kind]))}/s{'^2' if order == 2 else ''}'")
        base, per, squared = m.group(1), m.group(2), m.group(3)
        if (2 if squared else 1) != order:
            raise ValueError(f"the unit is per time{'^2' if squared else ''}, the column is a derivative of order {order}")
        if per not in UNITS["time"]:
            raise ValueError(f"unknown time unit {per!r} (known: {', '.join(UNITS['time'])})")
        return unit_factor(base, kind, 0) / UNITS["time"][per] ** order
    if unit in UNITS[kind]:
        return UNITS[kind][unit]
    for other, table in UNITS.items():
        if unit in table:
            raise ValueError(f"{unit!r} is a unit of {other}, the column is a {kind}")
    raise ValueError(f"unknown unit {unit!r} (known {kind} units: {', '.join(UNITS[kind])})")


def _atoms() -> dict[str, tuple[float, tuple[int, ...]]]:
    return {unit: (scale, _DIMENSIONS[kind]) for kind, table in UNITS.items() for unit, scale in table.items()
            if "*" not in unit}


_ATOM = re.compile(r"^([A-Za-zµ]+)(?:\^?(-?\d+))?$")


def _parse(unit: str) -> tuple[float, tuple[int, ...]]:
    """(factor to SI, dimension) of a product and quotient of units: ``g*mm^2``, ``N*s/m``, ``1/mm``, ``m/s^2``."""
    atoms = _atoms()
    scale, dims = 1.0, (0, 0, 0, 0)
    numerator, *denominators = unit.replace(" ", "").split("/")
    for sign, part in [(1, numerator)] + [(-1, d) for d in denominators]:
        for atom in part.split("*"):
            if atom == "1" and sign == 1:
                continue
            m = _ATOM.match(atom)
            if m is None or m.group(1) not in atoms:
                raise ValueError(f"unknown unit {atom!r} in {unit!r} (known: {', '.join(atoms)})")
            base, power = atoms[m.group(1)], sign * int(m.group(2) or 1)
            term = base[0] ** abs(power)
            scale = scale * term if power > 0 else scale / term
            dims = tuple(d + power * e for d, e in zip(dims, base[1]))
    return scale, dims


def factor(unit: str) -> float:
    """The factor to SI of ``unit``, a product and quotient of the units of :data:`UNITS` with integer powers
    (``"mm"``: 1e-3, ``"g*mm^2"``: 1e-9, ``"g/mm^3"``: 1e6, ``"deg"``: pi/180, ``"1"``: 1); ValueError names an
    unknown unit."""
    return _parse(unit)[0]


def same_quantity(a: str, b: str) -> bool:
    """Whether units ``a`` and ``b`` measure the same kind of quantity (mm and m; not mm and deg)."""
    return _parse(a)[1] == _parse(b)[1]


def shown(unit: str) -> tuple[float, str]:
    """(multiplier, unit) to show a value of ``unit`` (SI) in: m -> mm, rad -> deg (:data:`DISPLAY`), their rates
    alike (``m/s`` -> ``mm/s``), any other unit as it is."""
    base, sep, rest = unit.partition("/")
    if base not in DISPLAY:
        return 1.0, unit
    return factor(base) / factor(DISPLAY[base]), DISPLAY[base] + sep + rest


def key_unit(key: str) -> tuple[str, str | None]:
    """(stem, unit) of a file key that ends with its unit (``"height_mm"`` -> ``("height", "mm")``,
    ``"density_g_per_mm3"`` -> ``("density", "g/mm^3")``, ``"position_weight_per_mm"`` -> ``("position_weight",
    "1/mm")``); unit None for a key without one (``"tooth_friction"``, ``"p1"``)."""
    parts = key.split("_")
    k = len(parts)
    while k > 1 and (parts[k - 1] in KEY_UNITS or parts[k - 1] == "per"):
        k -= 1
    tail = parts[k:]
    if not tail or tail[-1] == "per":
        return key, None
    unit, joiner = "", ""
    for part in tail:
        if part == "per":
            unit, joiner = (unit or "1") + "/", ""
        else:
            unit, joiner = unit + joiner + KEY_UNITS[part], "*"
    return "_".join(parts[:k]), unit
