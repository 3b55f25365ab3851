"""The force observer: the bite-force estimator of :mod:`chewbot.dynamics.bite_force` at each tick of the loop.

At tick t_k the observer knows the state the controller sees at t_(k-1) and t_k (the plant's, or the sensor's
estimate) and the torques applied over that interval (held: the commanded ones, saturated). It solves the same six
equations for the same five unknowns as ``chewbot estimate-force`` (F_B at the molar, N_L, N_R; Newton-Euler with
the controller's model and, where the controller's model has it, friction), at the interval's midpoint: the mean
of the two states, and the acceleration (q_dot_k - q_dot_(k-1)) / h, the interval's mean acceleration, which the
held torques produced. The raw estimate then passes a first-order low-pass of cut-off ``cutoff`` (Hz; the gains'
``observer.cutoff_Hz``): u_k = b u_(k-1) + (1 - b) u_raw, b = exp(-2 pi cutoff h).

The tick is one compiled kernel (:func:`tick_kernel`, a fixed cost: the loop runs at 1 kHz): the friction-free
answer (one linear least-squares solve: the residual is affine in u without friction), then :data:`TICK_STEPS`
Gauss-Newton steps on the smoothed model with the model's friction (the plant's smoothing of abs(N), as the
estimator's final polish), N_L, N_R clipped at 0 after each step under the unilateral contact. The sign patterns
the whole-log estimator tries first (:func:`chewbot.dynamics.bite_force.solve`) only choose the start of its polish;
from the friction-free answer the steps reach the same minimiser (tests/test_force_control.py compares the two).

Bandwidth: the low-pass's -3 dB frequency ``cutoff``, behind a delay of half a tick (the midpoint) plus the tick the
controller waits for it: about 1/(2 pi cutoff) + 1.5 h of lag on a ramp (2.6 ms at 200 Hz and 1 kHz).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, native
from chewbot.dynamics.bite_force import residual_kernel
from chewbot.dynamics.options import check_contact
from chewbot.model import Model
from chewbot.model.symbolic import c_name, parameter_input
from chewbot.simulation.plant import STATE_OUTPUTS, state_function

# Gauss-Newton steps of a tick on the smoothed model with friction, from the friction-free answer: the friction terms
# are a few percent of the torques, each step cuts the error by about that factor: with 4 steps the tick equals the
# whole-log estimator to 3e-12 N on the default task with friction and a 30 N bite (tests/test_force_control.py).
TICK_STEPS = 4


def tick_kernel(mechanism: str, contact: str = "bilateral") -> KernelSpec:
    """Per-tick kernel (q0, dq0, q1, dq1, h, tau, B, friction, p) -> u (5: Fx, Fy, Fz, N_L, N_R, N): the observer's
    raw estimate over the interval of length h (s) from state (q0, dq0) to (q1, dq1) under the held torques tau (N m),
    at its midpoint, ``friction`` 0 or 1 (module docstring). ``contact`` "unilateral": N_L, N_R >= 0."""
    check_contact(contact)
    name = f"force_observer_{contact}_{c_name(mechanism)}"

    def build(params):
        residual = residual_kernel(mechanism).graph(params)
        extra, names = parameter_input(params)
        n = residual.size1_in(1)
        q0, dq0, q1, dq1 = (ca.SX.sym(k, n) for k in ("q0", "dq0", "q1", "dq1"))
        h, tau, B, fl = ca.SX.sym("h"), ca.SX.sym("tau", 6), ca.SX.sym("B", 3), ca.SX.sym("friction")
        qm, dqm, ddq = (q0 + q1) / 2, (dq0 + dq1) / 2, (dq1 - dq0) / h
        theta = dict(zip(STATE_OUTPUTS, state_function(mechanism)(qm, dqm, params.p)))["theta"]
        smooth = ca.DM.zeros(2)  # signs 0: abs(N) smoothed as the plant's

        def step(u, friction):
            r, G = residual(theta, qm, dqm, ddq, B, u, tau, smooth, friction, *extra)
            u = u - ca.solve(ca.mtimes(G.T, G), ca.mtimes(G.T, r))
            return ca.vertcat(u[:3], ca.fmax(u[3:], 0.0)) if contact == "unilateral" else u

        u = step(ca.SX.zeros(5), 0.0)
        for _ in range(TICK_STEPS):
            u = step(u, fl)
        return ca.Function(name, [q0, dq0, q1, dq1, h, tau, B, fl, *extra], [u],
                           ["q0", "dq0", "q1", "dq1", "h", "tau", "B", "friction", *names], ["u"], {"cse": True})

    return KernelSpec(name, build, (mechanism, contact), mechanism)


@dataclass
class ForceObserver:
    """The observer of the module docstring on the controller's ``model``, at the molar of ``side``; ``friction``:
    the model's friction in its equations; ``contact``: bilateral or unilateral (N >= 0). :meth:`start` it at the
    initial state, then :meth:`update` it at each tick."""

    model: Model
    cutoff: float
    side: str = "left"
    friction: bool = False
    contact: str = "bilateral"
    _q: np.ndarray = field(default=None, init=False, repr=False)
    _dq: np.ndarray = field(default=None, init=False, repr=False)
    _t: float = field(default=0.0, init=False, repr=False)
    _u: np.ndarray = field(default=None, init=False, repr=False)
    _raw: np.ndarray = field(default=None, init=False, repr=False)
    _shared: tuple = field(default=(), init=False, repr=False)
    _kernel: object = field(default=None, init=False, repr=False)

    def kernels(self) -> list:
        """The compiled kernel it uses (:func:`tick_kernel`), compiled before the loop."""
        return [tick_kernel(self.model.mechanism, self.contact)]

    def start(self, t: float, q, dq) -> None:
        self._t, self._q, self._dq = t, np.array(q, float), np.array(dq, float)
        self._u, self._raw = np.zeros(5), np.zeros(5)
        self._kernel = native(tick_kernel(self.model.mechanism, self.contact))
        self._shared = (self.model.molar(self.side), 1.0 if self.friction else 0.0, self.model.vector())

    @property
    def estimate(self) -> np.ndarray:
        """(5,): the filtered Fx, Fy, Fz, N_L, N_R (N)."""
        return self._u.copy()

    @property
    def raw(self) -> np.ndarray:
        """(5,): the last unfiltered estimate (N)."""
        return self._raw.copy()

    def update(self, t: float, q, dq, tau) -> np.ndarray:
        """The filtered estimate (5,) after the interval that ends at ``t`` with the state (q, dq), the torques
        ``tau`` (6,) having acted over it."""
        h = t - self._t
        q, dq = np.asarray(q, float), np.asarray(dq, float)
        if h > 0:
            self._raw = np.asarray(self._kernel(self._q, self._dq, q, dq, h, np.asarray(tau, float), *self._shared)[0]).ravel()
            b = np.exp(-2 * np.pi * self.cutoff * h)
            self._u = b * self._u + (1 - b) * self._raw
        self._t, self._q, self._dq = t, q.copy(), dq.copy()
        return self._u.copy()
