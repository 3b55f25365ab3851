"""Crank encoders with noise, and the state estimate a controller gets from them.

The robot measures its six crank angles. With sensor noise (``--noise RAD``) the simulation adds independent Gaussian
noise of that standard deviation to each measured angle, and the controller no longer sees the plant's state but an
estimate made from the measured angles alone, with the controller's model (it does not know the plant's):

* position: forward kinematics, the q in the independent coordinates whose chains close best with the measured
  angles (Gauss-Newton on the six closure equations, each scaled by the coupler length squared; :data:`FK_ITERATIONS`
  steps from the previous estimate: the pose moves by micrometres per tick, and Newton converges quadratically).
  For the target the six noisy angles over-determine the four coordinates: this is their least-squares fit;
* velocity: the backward difference of consecutive position estimates, through a first-order low-pass of cut-off
  ``cutoff`` (Hz; ``estimator.cutoff_Hz`` of the gains): v_k = b v_(k-1) + (1 - b) (q_k - q_(k-1)) / dt,
  b = exp(-2 pi cutoff dt). It trades noise (a raw difference amplifies the angles' noise by sqrt(2)/dt) for a lag of
  about 1/(2 pi cutoff) seconds.

The estimator starts from the simulation's initial state. It is what the controller is given with noise, and with
``--sensor measured`` (then noise-free): the path of the exported C step (:mod:`chewbot.export.controller`);
otherwise the controller is given the plant's state.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, native
from chewbot.kinematics.functions import closure_function
from chewbot.model import Model
from chewbot.model.symbolic import c_name
from chewbot.simulation.forward import ORIENTATION, n_coordinates
from chewbot.simulation.interfaces import State

FK_ITERATIONS = 3


def gauss_newton_sx(mechanism: str, m, theta: ca.SX, q: ca.SX) -> dict[str, ca.SX]:
    """:data:`FK_ITERATIONS` Gauss-Newton steps on the closure equations (each scaled by the coupler length squared)
    from ``q`` (Euler angles) for the crank angles ``theta``, on the model's numbers ``m``: the answer ``q``, the scaled
    closure residual at it (inf-norm, m^2 / m^2), the size of the last step (inf-norm, m or rad: ~0 once converged)
    and ``conditioning``, det(J'J)^(1/n) / (trace(J'J)/n) of the scaled closure Jacobian J at the answer (the ratio
    of the geometric to the arithmetic mean of the eigenvalues of J'J: 1 for a well-conditioned J, 0 where the crank
    angles no longer determine the pose, a singularity of the direct kinematics)."""
    n = n_coordinates(mechanism)
    closure = closure_function(mechanism, ORIENTATION)
    scale = m.coupler_length**2

    def residual(x):
        H, J = closure(theta, x, m.p)[:2]
        return H / scale, J / ca.repmat(scale, 1, n)

    x, step = q, ca.SX(0)
    for _ in range(FK_ITERATIONS):
        H, J = residual(x)
        dx = ca.solve(ca.mtimes(J.T, J), ca.mtimes(J.T, H))
        x, step = x - dx, ca.norm_inf(dx)
    H, J = residual(x)
    JtJ = ca.mtimes(J.T, J)
    conditioning = ca.fabs(ca.det(JtJ)) ** (1.0 / n) / (ca.trace(JtJ) / n)
    return {"q": x, "residual": ca.norm_inf(H), "step": step, "conditioning": conditioning}


def forward_kinematics_kernel(mechanism: str) -> KernelSpec:
    """(theta, q_guess, p) -> q: :data:`FK_ITERATIONS` Gauss-Newton steps on the closure equations from q_guess
    (Euler angles), and the scaled closure residual at the answer (m^2 / m^2) (:func:`gauss_newton_sx`)."""
    name = f"forward_kinematics_{c_name(mechanism)}"

    def build(params):
        n = n_coordinates(mechanism)
        theta, q = ca.SX.sym("theta", 6), ca.SX.sym("q", n)
        fk = gauss_newton_sx(mechanism, params, theta, q)
        return ca.Function(name, [theta, q, params.p], [fk["q"], fk["residual"]], ["theta", "q_guess", "p"], ["q", "residual"],
                           {"cse": True})

    return KernelSpec(name, build, (mechanism, FK_ITERATIONS), mechanism)


@dataclass
class CrankSensor:
    """Encoders on the six cranks with Gaussian noise of standard deviation ``noise`` (rad), and the estimator of the
    module docstring on the controller's ``model`` with the velocity low-pass at ``cutoff`` (Hz). ``seed`` fixes the
    noise. :meth:`start` it at the initial state, then call it with each tick's true crank angles."""

    model: Model
    noise: float
    cutoff: float
    seed: int | None = 0
    _rng: np.random.Generator = field(init=False, repr=False)
    _q: np.ndarray = field(init=False, repr=False)
    _dq: np.ndarray = field(init=False, repr=False)
    _t: float = field(init=False, repr=False)

    def start(self, t: float, q: np.ndarray, dq: np.ndarray) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._q, self._dq, self._t = np.array(q, float), np.array(dq, float), t
        self._fk = native(forward_kinematics_kernel(self.model.mechanism))
        if len(q) != n_coordinates(self.model.mechanism):
            raise ValueError(f"the sensor's model is a {self.model.mechanism}, the state has {len(q)} coordinates")

    def __call__(self, t: float, theta: np.ndarray) -> State:
        """The estimate at time t from the true crank angles ``theta`` (6,)."""
        measured = theta + self._rng.normal(0.0, self.noise, 6)
        q = self._fk(measured, self._q, self.model.vector())[0]
        dt = t - self._t
        if dt > 0:
            b = np.exp(-2 * np.pi * self.cutoff * dt)
            self._dq = b * self._dq + (1 - b) * (q - self._q) / dt
        self._q, self._t = q, t
        return State(q, self._dq.copy(), measured)
