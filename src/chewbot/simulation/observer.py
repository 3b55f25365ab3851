"""The force observer: the bite-force estimator of :mod:`chewbot.dynamics.bite_force` at each tick of the loop.

At tick t_k the observer knows the state the controller sees at t_(k-1) and t_k (the plant's, or the sensor's
estimate) and the torques applied over that interval (held: the commanded ones, saturated). It solves the same six
equations for the same five unknowns as ``chewbot estimate-force`` (F_B at the molar, N_L, N_R; Newton-Euler with
the controller's model and, where the controller's model has it, friction), at the interval's midpoint: the mean
of the two states, and the acceleration (q_dot_k - q_dot_(k-1)) / h, the interval's mean acceleration, which the
held torques produced. The raw estimate then passes a first-order low-pass of cut-off ``cutoff`` (Hz; the gains'
``observer.cutoff_Hz``): u_k = b u_(k-1) + (1 - b) u_raw, b = exp(-2 pi cutoff h).

Bandwidth: the low-pass's -3 dB frequency ``cutoff``, behind a delay of half a tick (the midpoint) plus the tick the
controller waits for it: about 1/(2 pi cutoff) + 1.5 h of lag on a ramp (2.6 ms at 200 Hz and 1 kHz).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from chewbot.compiled.kernels import native
from chewbot.dynamics.bite_force import residual_kernel, solve_states
from chewbot.model import Model
from chewbot.simulation.plant import STATE_OUTPUTS, state_function


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
    _state: object = field(default=None, init=False, repr=False)
    _kernel: object = field(default=None, init=False, repr=False)

    def kernels(self) -> list:
        """The compiled kernel it uses (the estimator's residual), compiled before the loop."""
        return [residual_kernel(self.model.mechanism)]

    def start(self, t: float, q, dq) -> None:
        self._t, self._q, self._dq = t, np.array(q, float), np.array(dq, float)
        self._u, self._raw = np.zeros(5), np.zeros(5)
        self._state = native(state_function(self.model.mechanism))
        self._kernel = native(residual_kernel(self.model.mechanism))

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
            qm, dqm, ddq = (q + self._q) / 2, (dq + self._dq) / 2, (dq - self._dq) / h
            theta = dict(zip(STATE_OUTPUTS, self._state(qm, dqm, self.model.vector())))["theta"]
            u, _, _ = solve_states(self.model, np.asarray(theta).reshape(1, 6), qm[None], dqm[None], ddq[None],
                                   np.asarray(tau, float)[None], side=self.side, contact=self.contact,
                                   friction=self.friction, kernel=self._kernel, residuals=False)
            self._raw = u[0]
            b = np.exp(-2 * np.pi * self.cutoff * h)
            self._u = b * self._u + (1 - b) * self._raw
        self._t, self._q, self._dq = t, q.copy(), dq.copy()
        return self._u.copy()
