"""The kinematics' choices, by name: how the mandible's orientation is parametrised and the side the bite force acts
on. Standard library only: the command line reads them for its help without loading NumPy or CasADi."""

from __future__ import annotations

from enum import StrEnum


class Orientation(StrEnum):
    """Parametrisation of the mandible's orientation in q_EE (docs/conventions.md)."""

    euler_angles = "euler-angles"  # XYZ Euler angles alpha, beta, gamma
    euler_parameters = "euler-parameters"  # unit quaternion e0..e3 (seed 001)


class Side(StrEnum):
    """The molar the bite force acts on (and the side the default task chews on)."""

    left = "left"
    right = "right"


ORIENTATIONS = tuple(o.value for o in Orientation)


def check_orientation(orientation: str) -> None:
    """Raise ValueError unless ``orientation`` is one of :data:`ORIENTATIONS`."""
    if orientation not in ORIENTATIONS:
        raise ValueError(f"orientation must be one of {', '.join(ORIENTATIONS)}, not {orientation!r}")
