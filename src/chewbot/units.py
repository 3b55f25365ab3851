"""Units: their names and factors to SI, and the ``name [unit]`` header cells that tasks, recordings, robot logs and
results tables share.

chewbot computes in SI and writes SI; the files it reads may give other units in their column headers (``X[mm]``,
``alpha [deg]``, ``dX[mm/s]``, ``ddbeta[deg/s^2]``, ``t[ms]``, ``Fz[kN]``): :func:`unit_factor` converts them, and
says in plain words why a unit cannot be used for a column.
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
}
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
