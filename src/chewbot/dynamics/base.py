"""What every inverse-dynamics formulation returns, and the registry that names them.

A formulation is a function ``f(model, kin, **options) -> Dynamics``: the model, the kinematics of the
whole task (:class:`~chewbot.kinematics.motion.Kinematics`), and options of its own (side, friction, goal, ...).
Adding a formulation is adding one module that calls :func:`register`.

A run may give a long task in chunks of consecutive samples (:mod:`chewbot.run.pipeline`), one call per chunk. A
formulation whose samples depend on earlier ones (a solver warm-started from the previous sample's solution) takes
the option ``carry``, the previous chunk's :attr:`Dynamics.carry` (None for the task's first chunk), and returns
in ``carry`` what the next chunk needs: the chunks then give the results of the whole task in one call.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.table import Table


@dataclass(frozen=True, eq=False)
class Dynamics:
    """Result of an inverse-dynamics formulation along a task.

    ``tau``: (N, 6) actuator torques, N m. ``table``: further named columns with units (forces, friction,
    multipliers ...) that go into ``results.csv``. ``info``: scalars and notes for run.json and reports.
    ``carry``: the state the next chunk of the same task starts from (see the module docstring), e.g. the last
    sample's solution as a warm start; empty for a formulation whose samples are independent.
    """

    method: str
    tau: np.ndarray
    table: Table = field(default_factory=Table)
    info: dict = field(default_factory=dict)
    carry: dict = field(default_factory=dict)


Formulation = Callable[..., Dynamics]
METHODS: dict[str, Formulation] = {}
KERNELS: dict[str, Callable[..., list]] = {}


def register(name: str, kernels: Callable[..., list] | None = None):
    """Decorator: make a formulation available under ``name`` (``chewbot run --method NAME``). ``kernels``:
    ``(mechanism, orientation, **options) -> [KernelSpec]``, the compiled kernels it uses (compiled side by side
    before a run, see :func:`formulation_kernels`)."""

    def wrap(fn: Formulation) -> Formulation:
        METHODS[name] = fn
        KERNELS[name] = kernels or (lambda mechanism, orientation, **options: [])
        return fn

    return wrap


def formulation_kernels(mechanism: str, orientation: str, method: str, **options) -> list:
    """The compiled kernels (:class:`~chewbot.compiled.kernels.KernelSpec`) that ``method`` uses on a mechanism."""
    import chewbot.dynamics  # noqa: F401  (imports every formulation module, which registers itself)

    return KERNELS[method](mechanism, orientation, **options)


def inverse_dynamics(model: Model, kin: Kinematics, method: str = "hessian", **options) -> Dynamics:
    """Run the formulation ``method`` on the kinematics ``kin`` of ``model``."""
    import chewbot.dynamics  # noqa: F401  (imports every formulation module, which registers itself)

    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; available: {', '.join(sorted(METHODS))}")
    return METHODS[method](model, kin, **options)
