"""A texture analyser's crosshead: computed torque with integral action on the independent coordinates.

    tau = ID(q, q_dot, q_ddot_ref + kd e_dot + kp e + ki int e dt, F_B),   e = q_ref - q,

with kp = (2 pi f)^2, kd = 2 zeta (2 pi f) (``crosshead.frequency_Hz``, ``.damping``) and ki = kp 2 pi f_i
(``crosshead.integral_Hz``) per independent coordinate; F_B the force observer's estimate (the observer's ``cutoff_Hz``,
docs/bite_force.md): force feed-forward, which the inverse dynamics needs to distribute the redundant torques so that
the condyles stay pressed on their planes while the sample pushes (the unilateral contact of ``chewbot tpa``). What the
estimate misses (its lag, a fracture's drop) is a load the path is held against by the integral: a disturbance d of the error
dynamics, e''' + kd e'' + kp e' + ki e = d': a constant load leaves no error, a load that rises at a constant rate (a
sample compressed at a held speed) a constant error d'/ki and no error of speed, so the test speed is held and the
deepest point reached within that error. Stable while ki < kd kp, i.e. ``integral_Hz`` < 2 ``damping``
``frequency_Hz`` (refused otherwise).

The law is computed torque's compiled kernel (:mod:`chewbot.simulation.controllers.computed_torque`) given the
acceleration with the integral's share added; the integral is the controller's state, summed at its ticks (the
torques are held between them), so the controller runs at a control rate (its row is not continuous).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, ClassVar

import numpy as np
from pydantic import model_validator

from chewbot.compiled.kernels import KernelSpec, native
from chewbot.compiled.layout import Layout
from chewbot.simulation.controllers.gains import COORDINATES, Entries, ErrorDynamics, Gain
from chewbot.simulation.controllers.law import ControllerParts, control_kernel
from chewbot.simulation.controllers.table import controller_row
from chewbot.simulation.interfaces import Column, ControllerCapabilities, State

class Gains(ErrorDynamics):
    """``[crosshead]``: the error dynamics' natural frequency (Hz) and damping ratio, and the integral's corner
    frequency (Hz, ki = kp 2 pi integral_Hz), per coordinate."""

    frequency_Hz: Annotated[Gain, Entries(COORDINATES)]
    damping: Annotated[Gain, Entries(COORDINATES)]
    integral_Hz: Annotated[Gain, Entries(COORDINATES)]

    VECTOR: ClassVar[str] = "kp (1/s^2) of each coordinate, then kd (1/s), then ki (1/s^3)"

    @classmethod
    def layout(cls, n: int) -> Layout:
        return Layout.of(kp=n, kd=n, ki=n)

    def vector(self) -> np.ndarray:
        w = 2 * np.pi * np.array(self.frequency_Hz)
        kp = w**2
        return self.layout(w.size).pack(kp=kp, kd=2 * np.array(self.damping) * w, ki=kp * 2 * np.pi * np.array(self.integral_Hz))

    @model_validator(mode="after")
    def _stable(self) -> Gains:
        f, zeta, fi = (np.atleast_1d(np.array(x, float)) for x in (self.frequency_Hz, self.damping, self.integral_Hz))
        if np.any(fi >= 2 * zeta * f):
            raise ValueError(f"integral_Hz ({np.array2string(fi, separator=', ')}) must stay below 2 damping frequency_Hz "
                             f"({np.array2string(2 * zeta * f, separator=', ')}): the error dynamics with the integral are "
                             "unstable otherwise (ki < kd kp)")
        return self


@dataclass
class CrossheadController:
    """The controller of the module docstring, built from its ``parts``; the integral of the error is its state."""

    parts: ControllerParts
    capabilities: ControllerCapabilities = field(default=ControllerCapabilities(), init=False)
    _kernel: object = field(default=None, init=False, repr=False)
    _shared: tuple = field(default=(), init=False, repr=False)
    _integral: np.ndarray = field(default=None, init=False, repr=False)
    _t: float | None = field(default=None, init=False, repr=False)
    _ki: np.ndarray = field(default=None, init=False, repr=False)

    def kernel_spec(self) -> KernelSpec:
        return control_kernel(controller_row(self.parts.row.extends), self.parts.model.mechanism, self.parts.inverse)

    def kernels(self) -> list[KernelSpec]:
        return [self.kernel_spec()]

    def __call__(self, t: float, state: State) -> np.ndarray:
        if self._kernel is None:
            model, side = self.parts.model, self.parts.reference.side
            n = np.size(state.q)
            g = type(self.parts.section).layout(n).split(self.parts.gains_vector())
            self._kernel = native(self.kernel_spec())
            self._shared = (np.concatenate([g["kp"], g["kd"]]), model.molar(side), model.vector())
            self._ki, self._integral = np.asarray(g["ki"], float), np.zeros(n)
        assert state.force is not None, "the crosshead controller is given the force observer's estimate (its row needs it)"
        q_ref, dq_ref, ddq_ref, _ = self.parts.reference.state(t)
        # the integral of the error up to this tick (the rectangle of the interval before: the error seen at its end)
        if self._t is not None:
            self._integral += (np.asarray(q_ref) - state.q) * (t - self._t)
        self._t = t
        return np.asarray(self._kernel(state.q, state.dq, q_ref, dq_ref, ddq_ref + self._ki * self._integral,
                                       state.force,
                                       *self._shared)[0]).ravel()

    def columns(self, t: np.ndarray) -> list[Column]:
        return []

    def info(self) -> dict:
        return {}


def build(parts: ControllerParts) -> CrossheadController:
    return CrossheadController(parts)
