"""The reference motion of a simulation: the task's samples, and in between a quintic Hermite interpolation.

Between two samples t_i < t_(i+1) each coordinate is the polynomial of degree 5 that takes the task's position,
rate and acceleration at both ends (C^2 across the samples, exact for any polynomial motion of degree 5 or less),
so a controller running at another rate than the task's, or evaluated at the integrator's stages, sees a reference
as smooth as the task itself. The bite force is interpolated linearly between the samples.

The interpolation is written out (the closed-form quintic Hermite basis, all query times at once): SciPy's
``BPoly.from_derivatives`` builds the same polynomials (a test holds the two against each other) but interval by
interval in Python, 0.4 s for the 5001 samples of the default task.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from chewbot.kinematics.motion import task_coordinates
from chewbot.model import Model
from chewbot.kinematics.task import Task

# Monomial coefficients of the quintic on s in [0, 1] from (p(0), p'(0), p''(0), p(1), p'(1), p''(1)).
_ENDS = np.array([[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 2, 0, 0, 0],
                  [1, 1, 1, 1, 1, 1], [0, 1, 2, 3, 4, 5], [0, 0, 2, 6, 12, 20]], dtype=float)
HERMITE_COEFFICIENTS = np.linalg.inv(_ENDS)  # exact: the inverse of this integer matrix has small rational entries


@dataclass(frozen=True)
class Reference:
    """The reference motion in the mechanism's independent coordinates (Euler angles), samples first: ``t`` (N,) s,
    ``q``, ``dq``, ``ddq`` (N, n), ``force`` (N, 3) the bite force on the mandible (N); ``side`` its molar."""

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    force: np.ndarray
    side: str
    _grid: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    # the force's three components each contiguous (interpolating a strided column copies it whole at every call)
    _force_columns: np.ndarray = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "_force_columns", np.ascontiguousarray(np.asarray(self.force, float).T))

    @classmethod
    def from_task(cls, model: Model, task: Task) -> Reference:
        """The task's motion in ``model``'s independent coordinates (a 4-coordinate task on the 6RSS lifted by the
        sockets' parasitic motions, as :func:`chewbot.kinematics.motion.solve_kinematics` does)."""
        q, dq, ddq = task_coordinates(model, task)
        return cls(np.asarray(task.t, float), q, dq, ddq, np.asarray(task.force, float), task.side)

    @property
    def start(self) -> float:
        return float(self.t[0])

    @property
    def end(self) -> float:
        return float(self.t[-1])

    def at(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, dq, ddq (M, n) at ``times`` (M,) within [start, end]: the samples themselves at the sample times."""
        times = np.atleast_1d(np.asarray(times, float))
        i = np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, len(self.t) - 2)
        dt = (self.t[i + 1] - self.t[i])[:, None]
        s = ((times - self.t[i]) / dt[:, 0])[:, None]
        ends = np.stack([self.q[i], dt * self.dq[i], dt**2 * self.ddq[i],
                         self.q[i + 1], dt * self.dq[i + 1], dt**2 * self.ddq[i + 1]], axis=1)  # (M, 6, n)
        c = np.einsum("kj,mjn->mkn", HERMITE_COEFFICIENTS, ends)  # monomial coefficients in s
        powers = s[:, None, :] ** np.arange(6)[None, :, None]  # (M, 6, 1): 1, s, ..., s^5
        k = np.arange(6)[None, :, None]
        p = np.sum(c * powers, axis=1)
        dp = np.sum(c[:, 1:] * k[:, 1:] * powers[:, :-1], axis=1) / dt
        ddp = np.sum(c[:, 2:] * (k[:, 2:] * (k[:, 2:] - 1)) * powers[:, :-2], axis=1) / dt**2
        return p, dp, ddp

    def prepare(self, times) -> None:
        """Evaluate the reference once at ``times`` (the simulation's ticks), so that :meth:`state` at one of them is
        a lookup."""
        times = np.asarray(times, float)
        q, dq, ddq = self.at(times)
        force = self.force_at(times)
        self._grid.clear()
        self._grid.update({float(t): (q[k], dq[k], ddq[k], force[k]) for k, t in enumerate(times)})

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """q, dq, ddq (n,) and the bite force (3,) at one time."""
        hit = self._grid.get(float(t))
        if hit is not None:
            return hit
        q, dq, ddq = self.at([t])
        return q[0], dq[0], ddq[0], self.force_at([t])[0]

    def force_at(self, times) -> np.ndarray:
        """The bite force (M, 3) at ``times``, linear between the samples."""
        times = np.atleast_1d(np.asarray(times, float))
        return np.stack([np.interp(times, self.t, column) for column in self._force_columns], axis=1)
