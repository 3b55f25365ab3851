"""The arrays the verbs of :mod:`chewbot.api` take: one sample or many, checked against the model, and their kinematics.

Each array argument is one sample (its own shape: ``q`` (n,), ``bite_force`` (3,)) or many (a leading axis:
(N, n), (N, 3)). The arguments with a leading axis must agree on N; one without is the same for every sample. The
result has a leading axis where an argument has one: one sample in, one sample out (no leading axis); many in, many
out. A wrong shape is a ValueError naming the argument, the shape expected for this model and the shape given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chewbot.errors import KinematicsError
from chewbot.kinematics.motion import Kinematics, euler_angle_motion, solve_kinematics
from chewbot.kinematics.options import Orientation
from chewbot.kinematics.symbolic import COORDINATES
from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task
from chewbot.model import Model
from chewbot.units import rate_unit

COORDINATE_UNITS = {"X": "m", "Y": "m", "Z": "m", "alpha": "rad", "beta": "rad", "gamma": "rad",
                    "e0": "1", "e1": "1", "e2": "1", "e3": "1"}
ROBOTS = {"target": "the target", "6rss": "the 6RSS"}


@dataclass(frozen=True)
class Argument:
    """An array argument: its ``name``, the ``value`` given, the ``size`` of one sample and what one sample holds
    (``meaning``, with its units)."""

    name: str
    value: object
    size: int
    meaning: str


def coordinates(model: Model, orientation: str, name: str, value, order: int = 0) -> Argument:
    """The argument ``name`` holding the mechanism's independent coordinates in ``orientation`` (``order`` 0), or their
    rates (1) or accelerations (2)."""
    coords = COORDINATES[(model.mechanism, orientation)]
    units = [rate_unit(COORDINATE_UNITS[c], order) for c in coords]
    level = ("", "the rates of ", "the accelerations of ")[order]
    parameters = " (Euler parameters)" if orientation == Orientation.euler_parameters else ""
    return Argument(name, value, len(coords), f"{level}{', '.join(coords)} of {ROBOTS[model.mechanism]}{parameters}, "
                    f"in {', '.join(dict.fromkeys(units))}")


def bite_force(value) -> Argument:
    """The ``bite_force`` argument: (Fx, Fy, Fz) in {S} at the molar, N; None is zero."""
    return Argument("bite_force", np.zeros(3) if value is None else value, 3,
                    "Fx, Fy, Fz on the mandible at the molar of side, in {S}, N")


@dataclass(frozen=True)
class Batch:
    """The arrays of the arguments, each (N, size), and whether they were one sample (``single``)."""

    arrays: tuple[np.ndarray, ...]
    single: bool

    @property
    def n(self) -> int:
        return self.arrays[0].shape[0]

    def out(self, x: np.ndarray) -> np.ndarray:
        """An array of the samples as the caller gave them: without the leading axis for one sample."""
        return x[0] if self.single else x


def batch(*arguments: Argument) -> Batch:
    """The arguments as arrays of N samples each (see the module docstring); ValueError names the argument that is
    not of its shape, has no sample, or a value that is not a finite number."""
    arrays, counts = [], {}
    for a in arguments:
        try:
            x = np.asarray(a.value, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{a.name}: expected numbers, shape ({a.size},) or (N, {a.size}) ({a.meaning}): {exc}") from None
        if x.ndim not in (1, 2) or x.shape[-1] != a.size:
            raise ValueError(f"{a.name}: expected shape ({a.size},) for one sample or (N, {a.size}) for N samples "
                             f"({a.meaning}), got {x.shape}")
        if x.ndim == 2:
            if x.shape[0] == 0:
                raise ValueError(f"{a.name}: no sample (shape {x.shape})")
            counts[a.name] = x.shape[0]
        bad = np.flatnonzero(~np.isfinite(x.reshape(-1, a.size)).all(axis=1))
        if bad.size:
            where = f"sample {int(bad[0])}" if x.ndim == 2 else "the sample"
            raise ValueError(f"{a.name}: {where} is not finite: {x.reshape(-1, a.size)[bad[0]].tolist()}")
        arrays.append(x)
    if len(set(counts.values())) > 1:
        (first, n), *rest = counts.items()
        other, m = next((k, v) for k, v in rest if v != n)
        raise ValueError(f"{other}: {m} samples, but {first} has {n}: the arguments with a leading axis must have "
                         "the same number of samples")
    n = next(iter(counts.values()), 1)
    return Batch(tuple(np.broadcast_to(x, (n, x.shape[-1])) for x in arrays), not counts)


def kinematics(model: Model, orientation: str, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, force: np.ndarray,
               side: str) -> Kinematics:
    """The kinematics (:func:`chewbot.kinematics.motion.solve_kinematics`) of the samples (N, n) of q_EE in
    ``orientation`` and its rates, with the bite force (N, 3) at the molar of ``side``: the samples as a task whose
    time is the sample's index. A :class:`~chewbot.errors.KinematicsError` names the sample (and the chain), not
    that time."""
    t = np.arange(q.shape[0], dtype=float)
    try:
        x = euler_angle_motion(model, orientation, q, dq, ddq)
        task = Task(name="samples", t=t, coords=TARGET_COORDS if model.has_hkp else FULL_COORDS, q=x[0], dq=x[1],
                    ddq=x[2], force=force, side=side, source="chewbot.api")
        return solve_kinematics(model, task, orientation)
    except KinematicsError as exc:
        raise KinematicsError(exc.reason, exc.sample, exc.chain) from None
