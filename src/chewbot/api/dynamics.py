"""Inverse and forward dynamics of samples of a motion, one call each, as a Pinocchio user calls ``rnea`` and ``aba``.

:func:`inverse_dynamics` wraps :func:`chewbot.dynamics.registry.inverse_dynamics` (every formulation of the table,
with the options ``chewbot run`` takes, checked by the same rules: :func:`chewbot.run.options.resolve`), and gives
the numbers of ``chewbot run``'s columns on the same samples. :func:`forward_dynamics` wraps
:func:`chewbot.simulation.forward.forward_dynamics` (the Newton-Euler model solved for the accelerations, the plant
of ``chewbot simulate``). Arrays: one sample or many (:mod:`chewbot.api.samples`); SI units.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np

from chewbot.analysis.checks import PULL_TOLERANCE_N
from chewbot.api.samples import Argument, batch, bite_force as bite_force_argument, coordinates, kinematics
from chewbot.dynamics import registry
from chewbot.dynamics.options import Contact
from chewbot.errors import ChewbotError
from chewbot.kinematics.options import Orientation, Side
from chewbot.model import Model
from chewbot.run.options import Switch, resolve
from chewbot.simulation import forward

# The forward dynamics' Newton iteration stops below 1e-13 N m (chewbot.simulation.forward.TOLERANCE); a residual
# above this (N m) means it found no solution (Coulomb friction too large for the rigid bodies: Painleve's paradox).
RESIDUAL_TOLERANCE = 1e-9
EA = Orientation.euler_angles.value


class Columns:
    """The formulation's own columns of a result, by name: ``result.N_L``, ``result["N_L"]``, from its ``columns``
    (each name to its values, one per sample)."""

    columns: Mapping[str, np.ndarray]

    def __getattr__(self, name: str):
        columns = self.__dict__.get("columns", {})
        if name in columns:
            return columns[name]
        raise AttributeError(f"{type(self).__name__} has no field or column {name!r}"
                             + (f" (columns: {', '.join(columns)})" if columns else ""))

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.columns:
            raise KeyError(f"no column {name!r}; columns: {', '.join(self.columns) or 'none'}")
        return self.columns[name]

    def __dir__(self):
        return [*super().__dir__(), *self.columns]


@dataclass(frozen=True, eq=False)
class InverseDynamics(Columns):
    """The inverse dynamics of samples (one sample: no leading axis; N samples: a leading axis of N).

    ``tau`` (..., 6): actuator torques, N*m (``chewbot run``'s tau1..tau6). ``N`` (..., 2): the normal forces
    N_L, N_R of the sockets' planes on the condyles, N (> 0: the plane pushes), on the target; None on the 6RSS.
    ``bite_force`` (..., 3): the bite force on the mandible at the molar of ``side``, in {S}, N, as used.
    ``method``: the formulation; ``options``: the options in effect (the method's defaults filled in, as run.json
    records them; ``friction`` True, False, or None where the method has none). ``columns``, ``units``: the formulation's own columns and their units (``chewbot run``'s columns
    after tau1..tau6: N_L, N_R, lagrange's multipliers lambda1.., newton-euler's friction torques tau_f1.., forces
    FS1_x.., ...; docs/dynamics.md, docs/newton_euler.md), each also an attribute and an item: ``result.N_L``,
    ``result["tau_f1"]``. ``info``: the formulation's notes and scalars (newton-euler's performance indices F1..F7,
    its infeasible samples, the contact model; sample numbers count from 0, and a ``t`` among them is the sample's
    number)."""

    method: str
    tau: np.ndarray
    N: np.ndarray | None
    bite_force: np.ndarray
    options: Mapping[str, object]
    columns: Mapping[str, np.ndarray] = field(repr=False)
    units: Mapping[str, str] = field(repr=False)
    info: Mapping[str, object] = field(repr=False)

    @property
    def infeasible(self) -> tuple[int, ...]:
        """The samples where the formulation found no torques within its bounds (the unilateral contact's
        N >= contact.preload_N, newton-euler's actuator limits; ``info["infeasible"]`` says which bounds): their
        torques break one, as ``chewbot run``'s check distribution-infeasible reports. Empty where every sample is
        admissible."""
        return tuple(int(entry["sample"]) for entry in self.info.get("infeasible", ()))


@dataclass(frozen=True, eq=False)
class ForwardDynamics:
    """The forward dynamics of samples (one sample: no leading axis; N samples: a leading axis of N).

    ``ddq`` (..., n): the accelerations of the independent coordinates in Euler angles (X, Y, alpha, beta on the
    target, X_EE on the 6RSS), m/s^2 and rad/s^2. ``N`` (..., 2): the normal forces N_L, N_R of the planes on the
    condyles, N, on the target (both contacts held closed); None on the 6RSS. ``bite_force`` (..., 3): the bite force
    used, N, in {S}. ``residual`` (...): max abs(tau_NE - tau) of the Newton-Euler equations at the answer, N*m.
    ``pulls`` (...) bool, under the unilateral contact model: where a plane would have to pull its condyle (N_L or
    N_R below 0): the condyle leaves its plane there, which these closed-contact equations do not follow (MuJoCo's
    plant does: ``chewbot simulate --plant-engine mujoco``); None under the bilateral model."""

    ddq: np.ndarray
    N: np.ndarray | None
    bite_force: np.ndarray
    residual: np.ndarray
    pulls: np.ndarray | None = None


def inverse_dynamics(model: Model, q, dq, ddq, *, method: str | None = None, goal: str | None = None,
                     friction: bool | None = None, contact: str = Contact.bilateral.value, side: str = Side.left.value,
                     bite_force=None, orientation: str = EA) -> InverseDynamics:
    """The actuator torques (and the formulation's other columns) at the samples (q, dq, ddq) of a motion of
    ``model`` with the bite force ``bite_force`` ((3,) or (N, 3), N, in {S}, on the mandible at the molar of
    ``side``; None: zero).

    ``q``, ``dq``, ``ddq``: (n,) or (N, n), the mechanism's coordinates in ``orientation`` and their rates (Euler
    angles: X, Y, alpha, beta on the target, X, Y, Z, alpha, beta, gamma on the 6RSS; m, rad, /s, /s^2; Euler
    parameters: X, Y, e0, e1, e2 on the target, X, Y, Z, e0..e3 on the 6RSS, with abs(e) = 1 at every level).
    ``method``: a formulation of :data:`chewbot.dynamics.registry.FORMULATIONS` (None: the table's default for
    ``orientation``, :data:`~chewbot.dynamics.registry.DEFAULT_METHOD`); ``goal``, ``friction`` (True, False; None:
    the method's default) and ``contact`` (``"bilateral"``, ``"unilateral"``) as ``chewbot run``'s --goal,
    --friction, --contact: an option the method does not use is an :class:`~chewbot.run.options.OptionError` with
    run's message. A sample the kinematics refuses (out of the sockets, out of reach, singular) is a
    :class:`~chewbot.errors.KinematicsError` naming it. Samples are solved in order, as a run's task (newton-euler's
    distribution warm-starts a constrained sample from the one before)."""
    options = resolve(side=side, orientation=orientation, method=method, goal=goal, friction=friction, contact=contact,
                      has_hkp=model.has_hkp)
    b = batch(*(coordinates(model, options.orientation, name, x, order) for order, (name, x) in enumerate(
        (("q", q), ("dq", dq), ("ddq", ddq)))), bite_force_argument(bite_force))
    q, dq, ddq, force = b.arrays
    kin = kinematics(model, options.orientation, q, dq, ddq, force, options.side)
    dyn = registry.inverse_dynamics(model, kin, options.method, **options.formulation_options())
    columns = {name: b.out(values) for name, values in dyn.table.columns.items()}
    N = np.stack([columns["N_L"], columns["N_R"]], axis=-1) if model.has_hkp else None
    in_effect = {name: getattr(options, name) for name in ("method", "orientation", "goal", "contact", "side")}
    in_effect["friction"] = None if options.friction is None else options.friction == Switch.on
    return InverseDynamics(method=dyn.method, tau=b.out(dyn.tau), N=N, bite_force=b.out(kin.force),
                           options=MappingProxyType(in_effect), columns=MappingProxyType(columns),
                           units=MappingProxyType(dict(dyn.table.units)), info=MappingProxyType(dict(dyn.info)))


def forward_dynamics(model: Model, q, dq, tau, *, friction: bool | None = None, contact: str = Contact.bilateral.value,
                     side: str = Side.left.value, bite_force=None) -> ForwardDynamics:
    """The accelerations ddq (and the planes' normal forces N) of ``model`` at the states (q, dq) under the actuator
    torques ``tau`` ((6,) or (N, 6), N*m) and the bite force ``bite_force`` ((3,) or (N, 3), N, in {S}, at the molar
    of ``side``; None: zero); the inverse of :func:`inverse_dynamics` (its torques give back its ddq).

    ``q``, ``dq``: (n,) or (N, n) in Euler angles (X, Y, alpha, beta on the target, X_EE on the 6RSS; m, rad and
    their rates): the plant of ``chewbot simulate`` computes in them. ``friction``: the model's HKP and actuator
    friction (True), or none (False; None: none, as ``chewbot simulate --friction off``); ``contact``:
    ``"unilateral"`` marks the samples where a plane would pull (:attr:`ForwardDynamics.pulls`), on the target only.
    The states are checked as :func:`inverse_dynamics` checks its samples (a
    :class:`~chewbot.errors.KinematicsError` names the first one out of the sockets, out of reach or singular).
    Equations without a solution (a residual above :data:`RESIDUAL_TOLERANCE`) are a
    :class:`~chewbot.errors.ChewbotError` naming the first such sample."""
    if friction not in (None, True, False):
        raise ValueError(f"friction must be True, False or None (none), not {friction!r}")
    options = resolve(side=side, contact=contact, has_hkp=model.has_hkp)
    b = batch(coordinates(model, EA, "q", q), coordinates(model, EA, "dq", dq, 1),
              Argument("tau", tau, 6, "the actuator torques tau1..tau6 in N*m"), bite_force_argument(bite_force))
    q, dq, tau, force = b.arrays
    kinematics(model, EA, q, dq, np.zeros_like(q), force, options.side)  # the states' checks, as inverse_dynamics'
    out = forward.forward_dynamics(model, q, dq, tau, force, options.side, friction=bool(friction))
    bad = np.flatnonzero(~(out.residual <= RESIDUAL_TOLERANCE))
    if bad.size:
        k = int(bad[0])
        raise ChewbotError(f"sample {k}: the equations of motion have no solution under these torques (residual "
                           f"{out.residual[k]:.3g} N*m after Newton's method; {bad.size} sample(s) affected)")
    N = out.N if model.has_hkp else None
    pulls = None if options.contact != Contact.unilateral else (N < -PULL_TOLERANCE_N).any(axis=1)
    return ForwardDynamics(b.out(out.ddq), None if N is None else b.out(N), b.out(force), b.out(out.residual),
                           None if pulls is None else b.out(pulls))

