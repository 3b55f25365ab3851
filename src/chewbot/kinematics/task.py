"""A task: the motion of the mandible over time and the bite force on it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from chewbot.errors import TaskError

TARGET_COORDS = ("X", "Y", "alpha", "beta")
FULL_COORDS = ("X", "Y", "Z", "alpha", "beta", "gamma")


@dataclass(frozen=True, eq=False)
class Task:
    """A motion of the mandible in XYZ Euler angles with its rates, and the bite force.

    ``coords`` is ``("X", "Y", "alpha", "beta")`` (the target's independent coordinates; Z and gamma follow
    from the HKPs) or ``("X", "Y", "Z", "alpha", "beta", "gamma")`` (all six, as the 6RSS needs).
    Arrays are samples first: ``t`` (N,) s; ``q``, ``dq``, ``ddq`` (N, k) in m, rad and their rates;
    ``force`` (N, 3) the bite force F_B on the mandible in {S}, N; ``side`` the molar it acts on; ``lines``:
    for a task read from a file, the file's line of each sample. The arrays are kept read-only: an array given
    read-only (float64) is kept as it is, any other copied.
    """

    name: str
    t: np.ndarray
    coords: tuple[str, ...]
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    force: np.ndarray
    side: str = "left"
    source: str = "generated"
    meta: dict = field(default_factory=dict)
    lines: np.ndarray | None = None  # line of the source file of each sample, for error messages

    def __post_init__(self):
        if self.coords not in (TARGET_COORDS, FULL_COORDS):
            raise TaskError(f"task {self.name!r}: coordinates must be {TARGET_COORDS} or {FULL_COORDS}, not {self.coords}")
        if self.side not in ("left", "right"):
            raise TaskError(f"task {self.name!r}: side must be 'left' or 'right', not {self.side!r}")
        n = np.shape(self.t)[0]
        for name in ("q", "dq", "ddq"):
            a = getattr(self, name)
            if np.shape(a) != (n, len(self.coords)):
                raise TaskError(f"task {self.name!r}: {name} has shape {np.shape(a)}, expected {(n, len(self.coords))}")
        if np.shape(self.force) != (n, 3):
            raise TaskError(f"task {self.name!r}: force has shape {np.shape(self.force)}, expected {(n, 3)}")
        for name in ("t", "q", "dq", "ddq", "force"):
            a = getattr(self, name)
            if not (isinstance(a, np.ndarray) and a.dtype == np.float64 and not a.flags.writeable):
                a = np.array(a, dtype=float)  # a copy: the caller's array stays writeable and cannot change the task
                a.setflags(write=False)
            object.__setattr__(self, name, a)

    @property
    def n(self) -> int:
        return self.t.shape[0]

    def column(self, name: str) -> np.ndarray:
        return self.q[:, self.coords.index(name)]

    def window(self, start: int, stop: int) -> Task:
        """The samples ``start`` to ``stop - 1`` as a task of their own (a chunk of a long task)."""
        part = slice(start, stop)
        return Task(name=self.name, t=self.t[part], coords=self.coords, q=self.q[part], dq=self.dq[part],
                    ddq=self.ddq[part], force=self.force[part], side=self.side, source=self.source, meta=self.meta,
                    lines=None if self.lines is None else self.lines[part])
