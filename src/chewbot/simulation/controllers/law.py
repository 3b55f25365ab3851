"""Control laws as CasADi functions, and the controller that evaluates one, compiled, at each tick.

A law of the table (its module's ``law(x, mechanism, inverse)``) is one CasADi function of :data:`CONTROL_INPUTS`,
``(q, dq, q_ref, dq_ref, ddq_ref, F_B, gains, B, p) -> tau``: q, dq the state the controller is given (independent
coordinates, Euler angles), q_ref, dq_ref, ddq_ref the reference at the same time, F_B the bite force it knows, gains
its section's vector (:meth:`~chewbot.simulation.controllers.gains.Section.vector`, read by the section's layout), B the
bite point in {M}, p the controller's model. :class:`CompiledLaw` evaluates it compiled at each tick, and a plant that
closes the loop puts the same function inside its integrator's stages (``--rate continuous``). The controller's model
is its own (``--model`` with ``--set``), which may differ from the plant's.

The inverse dynamics (ID) a law uses is the controller's (:class:`~chewbot.simulation.options.ControllerDynamics`,
resolved like ``chewbot run --method --goal``): each formulation's own per-sample graph from the formulation table
(:attr:`chewbot.dynamics.registry.Formulation.sample_torques`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from chewbot.compiled.cache import cached_graph, symbols
from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.registry import formulation
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.model import Model
from chewbot.model.symbolic import c_name
from chewbot.model.vector import N_P
from chewbot.rotation import matrix_from_euler_angles_sx
from chewbot.simulation.controllers.gains import Gains, Section
from chewbot.simulation.controllers.table import ControllerRow
from chewbot.simulation.forward import ORIENTATION, n_coordinates
from chewbot.simulation.interfaces import Column, ControllerCapabilities, State
from chewbot.simulation.options import ControllerDynamics
from chewbot.simulation.reference import Reference

CONTROL_INPUTS = ("q", "dq", "q_ref", "dq_ref", "ddq_ref", "F_B", "gains", "B", "p")


def control_sizes(mechanism: str, gains: int) -> dict[str, int]:
    """The size of each input of :data:`CONTROL_INPUTS` on ``mechanism`` with ``gains`` entries of gains."""
    n = n_coordinates(mechanism)
    return dict(zip(CONTROL_INPUTS, (n, n, n, n, n, 3, gains, 3, N_P)))


def inverse_dynamics_function(mechanism: str, method: str, goal: str | None = None, friction: bool = False,
                              contact: str | None = None) -> ca.Function:
    """The controller's inverse dynamics of one sample: (q, dq, ddq, B, F_B, p) -> tau (N m), q in Euler angles.

    Each formulation's own per-sample graph (:attr:`chewbot.dynamics.registry.Formulation.sample_torques`): the terms
    of Eq. (53) by the Hessian method or Liang's, Lagrange's D, J_theta, J_qEE and the minimum-norm torques, the 6RSS
    core's torques, Newton-Euler's data with the distribution of ``goal`` at a fixed cost (with the model's friction
    when ``friction``, with N_L, N_R >= ``contact.preload_N`` when ``contact`` is ``"unilateral"``). Built once per
    (mechanism, method, goal, friction, contact).
    """
    f = formulation(method)
    options = {k: v for k, v in (("goal", goal), ("friction", bool(friction)), ("contact", contact))
               if k in f.sample_options and v is not None}
    key = ("controller-inverse", method, *(options.get(k, dict(f.defaults).get(k)) for k in ("goal", "friction", "contact")))
    return cached_graph(symbols(mechanism), key, lambda: f.sample_torques(mechanism, **options))


def inverse_function(mechanism: str, inverse: ControllerDynamics) -> ca.Function:
    """The controller's inverse dynamics ``inverse`` on ``mechanism`` (:func:`inverse_dynamics_function`)."""
    return inverse_dynamics_function(mechanism, inverse.method, inverse.goal, inverse.friction, inverse.contact.value)


def task_space_sx(q: ca.SX, dq: ca.SX, B: ca.SX, p: ca.SX, mechanism: str) -> dict:
    """The task coordinates of the impedance and hybrid controllers as expressions of the state: y = (x, y, z of
    the molar point B in {S}, alpha) (m, rad), its Jacobian J = dy/dq (q in Euler angles), y_dot = J q_dot, the
    bias J_dot q_dot, and J_theta1 = d theta / d q (the map of a generalised force onto the torques). The target
    only: its four coordinates are the point's three and the pinned angle (as chewbot track-incisor --pin alpha)."""
    n = q.numel()
    assert n == 4, "the task coordinates are the target's (the options refuse these controllers on the 6RSS)"
    out = dict(zip(KINEMATICS_OUTPUTS, kinematics_kernel(mechanism, ORIENTATION).graph()(q, dq, ca.SX.zeros(n), p)))
    X = out["X"]
    y = ca.vertcat(X[0:3] + ca.mtimes(matrix_from_euler_angles_sx(X[3], X[4], X[5]), B), q[2])
    J = ca.jacobian(y, q)
    dy = ca.mtimes(J, dq)
    return {"y": y, "J": J, "dy": dy, "bias": ca.jtimes(dy, q, dq), "J_theta1": out["J_theta1_angles"]}


def _key(row: ControllerRow, inverse: ControllerDynamics) -> tuple:
    """What a law's graph depends on besides the mechanism: its name, and the inverse dynamics where it uses one."""
    return (row.name, *(inverse.key if row.needs.inverse_dynamics else ()))


def control_function(row: ControllerRow, mechanism: str, inverse: ControllerDynamics) -> ca.Function:
    """The law of ``row`` as one CasADi function of :data:`CONTROL_INPUTS` -> tau (N m, before saturation)."""
    return cached_graph(symbols(mechanism), ("control", *_key(row, inverse)), lambda: _control(row, mechanism, inverse))


def _control(row: ControllerRow, mechanism: str, inverse: ControllerDynamics) -> ca.Function:
    module = row.module()
    gains = 0 if module.Gains is None else module.Gains.layout(n_coordinates(mechanism)).size
    x = {name: ca.SX.sym(name, size) for name, size in control_sizes(mechanism, gains).items()}
    tau = module.law(x, mechanism, inverse)
    return ca.Function(f"control_{row.name.replace('-', '_')}", list(x.values()), [tau], list(CONTROL_INPUTS), ["tau"])


def control_name(row: ControllerRow, mechanism: str, inverse: ControllerDynamics) -> str:
    """A C name for a control law's kernels: the controller, and the inverse dynamics where its law uses one."""
    parts = [row.name, *(inverse.c_name() if row.needs.inverse_dynamics else ())]
    return "_".join(p.replace("-", "_").replace("6rss", "sixrss") for p in parts) + f"_{c_name(mechanism)}"


def control_kernel(row: ControllerRow, mechanism: str, inverse: ControllerDynamics) -> KernelSpec:
    """:func:`control_function` compiled, for the ticks of a held-rate simulation."""
    name = f"control_{control_name(row, mechanism, inverse)}"

    def build(params):
        fn = control_function(row, mechanism, inverse)
        x = [ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(fn.n_in())]
        return ca.Function(name, x, fn.call(x), list(CONTROL_INPUTS), ["tau"], {"cse": True})

    return KernelSpec(name, build, (mechanism, *_key(row, inverse)), mechanism)


@dataclass(frozen=True)
class ControllerParts:
    """What a controller of the table is built from: its ``row``, the controller's ``model``, the ``reference`` it
    follows, the ``gains`` (all sections; its own is :attr:`section`), its inverse dynamics ``inverse`` and whether it
    knows the bite force (``bite_known``; ``--bite-unknown`` hides it)."""

    row: ControllerRow
    model: Model
    reference: Reference
    gains: Gains
    inverse: ControllerDynamics
    bite_known: bool = True

    @property
    def section(self) -> Section | None:
        """Its section of the gains file."""
        return None if self.row.gains is None else self.gains[self.row.gains]

    def gains_vector(self) -> np.ndarray:
        """The gains input of its law."""
        return np.zeros(0) if self.section is None else self.section.vector()

    def build(self):
        """The controller (the row's law module's ``build``)."""
        return self.row.module().build(self)


def make_controller(row: ControllerRow, model: Model, reference: Reference, gains: Gains | None = None,
                    inverse: ControllerDynamics | None = None, bite_known: bool = True):
    """The controller of ``row`` on ``model`` following ``reference``: ``gains`` default to the built-in ones,
    ``inverse`` to the formulation table's default method (without friction)."""
    gains = Gains.load(mechanism=model.mechanism) if gains is None else gains
    inverse = ControllerDynamics.resolved(has_hkp=model.has_hkp) if inverse is None else inverse
    return ControllerParts(row, model, reference, gains, inverse, bite_known).build()


@dataclass
class CompiledLaw:
    """A controller whose law is one CasADi function (:func:`control_function`), evaluated compiled at each tick:
    ``__call__(t, state)``; :meth:`function` is the same law for a plant that closes the loop."""

    parts: ControllerParts
    capabilities: ControllerCapabilities = field(default=ControllerCapabilities(continuous=True), init=False)
    _kernel: object = field(default=None, init=False, repr=False)
    _shared: tuple = field(default=(), init=False, repr=False)

    @property
    def row(self) -> ControllerRow:
        return self.parts.row

    @property
    def model(self) -> Model:
        return self.parts.model

    @property
    def reference(self) -> Reference:
        return self.parts.reference

    def function(self) -> ca.Function:
        return control_function(self.row, self.model.mechanism, self.parts.inverse)

    def kernel_spec(self) -> KernelSpec:
        return control_kernel(self.row, self.model.mechanism, self.parts.inverse)

    def kernels(self) -> list[KernelSpec]:
        return [self.kernel_spec()]

    def shared(self) -> dict[str, np.ndarray]:
        """The inputs that do not change during a simulation: gains, B, p."""
        return {"gains": self.parts.gains_vector(), "B": self.model.molar(self.reference.side), "p": self.model.vector()}

    def known_force(self, force: np.ndarray) -> np.ndarray:
        """The bite force the controller uses: the task's, or zero where it is hidden from it."""
        return force if self.parts.bite_known else np.zeros_like(force)

    def __call__(self, t: float, state: State) -> np.ndarray:
        if self._kernel is None:
            s = self.shared()
            self._kernel, self._shared = native(self.kernel_spec()), (s["gains"], s["B"], s["p"])
        q_ref, dq_ref, ddq_ref, force = self.reference.state(t)
        return self._kernel(state.q, state.dq, q_ref, dq_ref, ddq_ref, self.known_force(force), *self._shared)[0]

    def commands(self, t: np.ndarray, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """The law's torques (K, 6) at the rows' times and states."""
        q_ref, dq_ref, ddq_ref = self.reference.at(t)
        s = self.shared()
        return evaluate(native(self.kernel_spec()), q, dq, q_ref, dq_ref, ddq_ref, self.known_force(self.reference.force_at(t)),
                        s["gains"], s["B"], s["p"])[0]

    def columns(self, t: np.ndarray) -> list[Column]:
        return []

    def info(self) -> dict:
        return {}
