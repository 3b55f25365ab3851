"""The inverse-dynamics formulations, in one table: what each is called, what it takes and what it needs.

Every formulation is a row of :data:`FORMULATIONS` (:class:`Formulation`): the function that solves a whole task,
the compiled kernels a run of it uses (compiled side by side before the run), the per-sample graph of its torques
that a controller evaluates (:mod:`chewbot.simulation.controllers`), the orientation parametrisations it is written
for, the keyword options it takes, and whether a task given in chunks must carry its state from one chunk to the
next. Everything that depends on the formulation reads this table (the run's options, the sweep's SPEC, the
controllers, the benchmark): adding a formulation is adding its module and a row here.

Options (docs/dynamics.md, docs/newton_euler.md): ``side`` (the bite side, overriding the task's) and ``contact``
(``bilateral``, ``unilateral``) for every formulation; ``goal`` (what the distribution of the target's redundant
torques minimises), ``friction`` and ``strict`` for newton-euler. A formulation given an option it does not take
raises TypeError.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from chewbot.dynamics import g1
from chewbot.dynamics.formulations import core6rss, hessian, lagrange, liang, newton_euler
from chewbot.dynamics.options import DEFAULT_METHOD
from chewbot.dynamics.base import Dynamics
from chewbot.kinematics.motion import Kinematics
from chewbot.kinematics.options import Orientation
from chewbot.model import Model
from chewbot.model import drive

EA, EP = Orientation.euler_angles.value, Orientation.euler_parameters.value


@dataclass(frozen=True)
class Formulation:
    """One inverse-dynamics formulation.

    ``solve(model, kin, **options) -> Dynamics``: the whole task (or a chunk of it); ``kernels(mechanism, orientation,
    **kernel options)``: the compiled kernels it uses; ``sample_torques(mechanism, **sample options)``: a CasADi
    function (q, dq, ddq, B, F_B, p) -> tau of one sample in Euler angles (a controller's inverse dynamics);
    ``orientations``: the parametrisations of q_EE it is written for; ``options``: the keyword options ``solve``
    takes (besides ``carry`` and ``check``); ``rates``: where the formulation is a Lagrange-d'Alembert reduction
    (:mod:`chewbot.dynamics.formulations.dalembert`), its :class:`~chewbot.dynamics.formulations.dalembert.Rates` derivation: its torques
    under the bilateral contact model (which do not depend on the normal forces) are then the minimum-norm
    solution of Eq. (53) with these rates alone, which a sweep that needs only the torques computes in one fused
    kernel (:func:`chewbot.analysis.coupling.torques_coupling_kernel`); ``kernel_options``: those that choose its kernels and its per-sample
    graph; ``carries``: a sample depends on the one before (a warm start), so a task given in chunks passes the
    previous chunk's ``Dynamics.carry`` on; ``checks``: its loops call a library that may swallow a signal, so it
    takes the command line's ``check``; ``defaults``: the values of its options where a run does not give them."""

    name: str
    solve: Callable[..., Dynamics]
    kernels: Callable[..., list]
    sample_torques: Callable[..., object]
    description: str
    orientations: tuple[str, ...] = (EA,)
    options: tuple[str, ...] = ("side", "contact")
    kernel_options: tuple[str, ...] = ()
    sample_options: tuple[str, ...] = ()
    carries: bool = False
    checks: bool = False
    defaults: tuple[tuple[str, object], ...] = ()
    rates: Callable[..., object] | None = None


FORMULATIONS: dict[str, Formulation] = {f.name: f for f in (
    Formulation("hessian", hessian.hessian, hessian.kernels, hessian.sample_torques,
                "Lagrange-d'Alembert with the rates from Hessians (seed 000, Sect. 5.1), minimum-norm torques",
                rates=hessian.hessian_rates),
    Formulation("lagrange", lagrange.lagrange, lagrange.kernels, lagrange.sample_torques,
                "Lagrange's equations of the first kind with the closure multipliers (seed 000, Sect. 5.2)"),
    Formulation("liang", liang.liang, liang.kernels, liang.sample_torques,
                "Lagrange-d'Alembert with the rates by Liang's derivative method (seed 000, Eq. 61)",
                rates=liang.liang_rates),
    Formulation("6rss-core", core6rss.core6rss, core6rss.kernels, core6rss.sample_torques,
                "the 6RSS core in X_EE with the HKPs projected out (Eq. 53), one compiled kernel per sample"),
    Formulation("newton-euler", newton_euler.newton_euler, newton_euler.kernels, g1.sample_torques,
                "Newton-Euler with friction and the optimal distribution of the redundant torques (seed 001, Sect. 4)",
                orientations=(EA, EP), options=("side", "contact", "goal", "friction", "strict"),
                kernel_options=("goal",), sample_options=("goal", "friction", "contact"), carries=True, checks=True,
                defaults=(("goal", "min-torque"), ("friction", True), ("contact", "bilateral"))),
)}
METHODS = tuple(FORMULATIONS)
assert set(DEFAULT_METHOD) == {EA, EP} and set(DEFAULT_METHOD.values()) <= set(FORMULATIONS)


def formulation(method: str) -> Formulation:
    """The row of ``method``; ValueError names the formulations there are."""
    if method not in FORMULATIONS:
        raise ValueError(f"unknown method {method!r}; available: {', '.join(METHODS)}")
    return FORMULATIONS[method]


def inverse_dynamics(model: Model, kin: Kinematics, method: str = DEFAULT_METHOD[EA], *, carry: dict | None = None,
                     check: Callable[[], None] | None = None, **options) -> Dynamics:
    """Run the formulation ``method`` on the kinematics ``kin`` of ``model`` with its keyword ``options`` (a
    misspelt one is a TypeError). ``carry``: the previous chunk's ``Dynamics.carry`` (passed on where the formulation
    carries state); ``check()``: raises to stop the loops that may swallow a signal (where the formulation has such)."""
    f = formulation(method)
    extra = {**({"carry": carry} if f.carries else {}), **({"check": check} if f.checks else {})}
    dyn = f.solve(model, kin, **options, **extra)
    if model.drive is not None:  # tau includes the rotors' inertia (Model.crank_total_inertia); the motors' share
        drive.add_columns(dyn.table, model.drive, dyn.tau, kin.dtheta)
    return dyn


def formulation_kernels(mechanism: str, orientation: str, method: str, **options) -> list:
    """The compiled kernels (:class:`~chewbot.compiled.kernels.KernelSpec`) that ``method`` uses on a mechanism in
    ``orientation``; ``options``: those of its :attr:`Formulation.kernel_options` that are given."""
    f = formulation(method)
    return f.kernels(mechanism, orientation, **{k: v for k, v in options.items() if k in f.kernel_options and v is not None})


def reduction_rates(method: str, contact: str):
    """The :attr:`Formulation.rates` of ``method`` where its torques under the ``contact`` model are the
    minimum-norm solution of Eq. (53) alone (bilateral contact), else None."""
    f = formulation(method)
    return f.rates if contact == "bilateral" else None
