"""Hybrid force/position control: position control while the teeth are apart, force control along z once they bite.

The task coordinates are those of :func:`~chewbot.simulation.controllers.law.task_space_sx`: the molar point's x, y, z
and alpha. x, y and alpha are always position-controlled (computed torque in task space, ``hybrid.frequency_Hz``,
``hybrid.damping``); z too until the observed force f = -F_z (the force observer's, ``State.force``) reaches
``hybrid.threshold_N``. Then z's acceleration follows the force loop, with f_ref = -F_z of the task (its Fz is the
force reference):

    a_z = [kv (f_ref_dot - k_hat z_dot) + kp (f_ref - f)] / k_hat,   kp = (2 pi f_F)^2, kv = 2 zeta_F (2 pi f_F),

which for a food of stiffness k_hat (f_dot = k z_dot) makes the force error obey e'' + kv e' + kp e = 0 whatever the
stiffness. Written as a velocity loop, a_z = kv (z_dot_cmd - z_dot) with z_dot_cmd = (f_ref_dot + kp/kv (f_ref - f)) /
k_hat, the commanded speed is held within ``hybrid.speed_limit_m_per_s`` (a force the food cannot give, or a soft food
far from its force, would otherwise drive the teeth together at metres per second). The position loop of z is bounded
alike: written as a_z = z_ddot_ref + kd (z_dot_ref + v - z_dot), v = kp/kd (z_ref - z) is held within the same limit,
so that where z returns to position control far from its reference (the force loop held the teeth on the food while
the task opened) the molar point closes the gap at that speed relative to the reference instead of leaping at kp
times the gap (with the drive's rotors reflected to the molar point, the leap's torques broke the bearings' load
limit). Near the reference the bound is not reached and the loop is the plain computed torque.

The drive's authority: the torques are affine in z's acceleration, tau = tau_0 + c a_z (the inverse dynamics of the
controller's model, whose drive's rotors are reflected to the cranks; with friction, its linearisation at a_z = 0), so
the largest |a_z| that keeps every torque within the limit is min_i (limit - |tau_0,i|) / |c_i| (results.csv's
``z_authority``: with the built-in robot's rotors, about 631 kg at the molar point along z, some 3.5 m/s^2 at the
chewing cycle's closed pose and 9 m/s^2 at its open one). Under position control z's commanded acceleration is held
within :data:`AUTHORITY_SHARE` of it, so that the return from force control to a reference that opens fast does not ask
for torques beyond the limit (saturated, they broke the bearings' load limit with the drive): an anti-windup of z. The
force loop is not held so: where it brakes the teeth on a stiffening food it needs all of it.

The inverse dynamics is given F_z = -f_ref under force control (the force the food should push with; the observer's lags
the motion), the observed F_x, F_y, and the observed force under position control. k_hat is estimated on line from the
observed force against the molar point's z (passed through the observer's low-pass, so that both lag alike), by least
squares with exponential forgetting (:data:`STIFFNESS_MEMORY_S`) of two laws, the one that fits the points better (the
larger coefficient of determination) giving it: a linear food's, k_hat = df/dz, or an exponentially stiffening food's,
k_hat = f d(ln f)/dz (the particle bed, f + f_0 = c e^(z/lambda): its stiffness grows with the force, and the slope of f
over the memory, behind it while the force rose, let the rotors' momentum carry the force past its reference); within
``hybrid.stiffness_min_N_per_m`` .. ``stiffness_max_N_per_m``, starting at the maximum (a stiffness overestimated by c
slows the loop by c; underestimated, it makes it faster and overshoots). The force loop is left once the force reference
is below the threshold and the task's z reference lies below the point (the task opens), whatever force the food still
gives (a food that relaxes slowly, or a bed pressed thin, would otherwise hold the teeth shut through the opening), and
not entered again while that holds.

The controller's state (the mode, the stiffness estimate, the filtered z, the regression's moments) changes at its
ticks; its log gives results.csv's ``force_mode``, ``stiffness_estimate`` and ``z_authority``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, ClassVar

import casadi as ca
import numpy as np
from pydantic import model_validator

from chewbot.compiled.cache import cached_graph, symbols
from chewbot.compiled.kernels import KernelSpec, native
from chewbot.model.symbolic import c_name
from chewbot.model.vector import N_P
from chewbot.simulation.controllers.gains import Entries, ErrorDynamics, Gain, Positive
from chewbot.simulation.controllers.law import (CONTROL_INPUTS, ControllerParts, control_name, control_sizes, inverse_function,
                                                task_space_sx)
from chewbot.simulation.options import ControllerDynamics
from chewbot.simulation.controllers.table import ControllerRow
from chewbot.simulation.forward import n_coordinates
from chewbot.simulation.interfaces import Column, ControllerCapabilities, State

HYBRID_INPUTS = CONTROL_INPUTS + ("force_mode", "a_force", "speed_limit", "torque_limit")
HYBRID_OUTPUTS = ("tau", "y", "dy", "y_ref", "dy_ref", "authority")
TASK_STATE_OUTPUTS = ("y", "dy", "y_ref", "dy_ref")
# Memory (s) of the food-stiffness estimate of the force loop, and the spread of the molar point's z (m) below which
# the estimate is not updated (the points do not tell a slope).
STIFFNESS_MEMORY_S = 0.05
STIFFNESS_SPREAD_M = 5e-6
# The share of the drive's authority along z (the largest acceleration of the molar point's z that keeps every torque
# within the limit) that z's loops may command: the rest is left to x, y, alpha and to what the model misses.
AUTHORITY_SHARE = 0.5
# Added to the torques' sensitivity to z's acceleration (N m s^2/m), so that a crank z does not move has infinite room.
AUTHORITY_FLOOR = 1e-12


class Gains(ErrorDynamics):
    """``[hybrid]``: the task-space position loop (x, y, z, alpha: Hz, damping ratio), the force loop along z (Hz,
    damping ratio), the force that switches z to force control (N), the bounds of the food stiffness the loop
    estimates (N/m), the fastest the loop moves the molar point along z (m/s)."""

    frequency_Hz: Annotated[Gain, Entries(4)]
    damping: Annotated[Gain, Entries(4)]
    force_frequency_Hz: Positive
    force_damping: Positive
    threshold_N: Positive
    stiffness_min_N_per_m: Positive
    stiffness_max_N_per_m: Positive
    speed_limit_m_per_s: Positive

    VECTOR: ClassVar[str] = "kp (1/s^2) of x, y, z, alpha, then kd (1/s)"

    @model_validator(mode="after")
    def _bounds(self) -> Gains:
        if self.stiffness_min_N_per_m > self.stiffness_max_N_per_m:
            raise ValueError(f"stiffness_min_N_per_m ({self.stiffness_min_N_per_m:g}) is above stiffness_max_N_per_m "
                             f"({self.stiffness_max_N_per_m:g})")
        return self


def hybrid_function(mechanism: str, inverse: ControllerDynamics) -> ca.Function:
    """The law as one CasADi function of :data:`HYBRID_INPUTS` -> :data:`HYBRID_OUTPUTS`: computed torque in the task
    coordinates, y_ddot = y_ddot_ref + kd (y_dot_ref - y_dot) + kp (y_ref - y) on x, y and alpha always and on z unless
    ``force_mode`` is 1, where z's acceleration is ``a_force`` (the force loop's); z's term kp (z_ref - z) is written as
kd v, v = kp/kd (z_ref - z) held within +-``speed_limit`` (m/s, module docstring); q_ddot = J^-1 (y_ddot - J_dot q_dot)
    and tau = ID(q, q_dot, q_ddot, F_B), F_B the bite force the controller knows (the observer's). Also returns y,
    y_dot and the reference's."""
    return cached_graph(symbols(mechanism), ("hybrid-law", *inverse.key), lambda: _hybrid(mechanism, inverse))


def _hybrid(mechanism: str, inverse: ControllerDynamics) -> ca.Function:
    n = n_coordinates(mechanism)
    x = {name: ca.SX.sym(name, size) for name, size in control_sizes(mechanism, Gains.layout(n).size).items()}
    mode, a_force, limit = ca.SX.sym("force_mode"), ca.SX.sym("a_force"), ca.SX.sym("speed_limit")
    torque_limit = ca.SX.sym("torque_limit")
    now = task_space_sx(x["q"], x["dq"], x["B"], x["p"], mechanism)
    ref = task_space_sx(x["q_ref"], x["dq_ref"], x["B"], x["p"], mechanism)
    g = Gains.layout(n).split(x["gains"])
    ddy_ref = ca.mtimes(ref["J"], x["ddq_ref"]) + ref["bias"]
    a = ddy_ref + g["kd"] * (ref["dy"] - now["dy"]) + g["kp"] * (ref["y"] - now["y"])
    # z as a velocity loop whose proportional speed kp/kd (z_ref - z) is held within the speed limit
    approach = ca.fmin(ca.fmax(g["kp"][2] / g["kd"][2] * (ref["y"][2] - now["y"][2]), -limit), limit)
    a_z = ddy_ref[2] + g["kd"][2] * (ref["dy"][2] - now["dy"][2] + approach)
    # the torques as tau_0 + c a_z (exact where the inverse dynamics is linear in the accelerations; with friction's
    # distribution, its linearisation at a_z = 0); the drive's authority along z is the largest a_z (either sign) that
    # keeps every torque within the limit
    a_sym = ca.SX.sym("a_z")
    ddq = ca.solve(now["J"], ca.vertcat(a[0:2], a_sym, a[3:]) - now["bias"])
    tau = inverse_function(mechanism, inverse)(x["q"], x["dq"], ddq, x["B"], x["F_B"], x["p"])
    c = ca.substitute(ca.jacobian(tau, a_sym), a_sym, 0)
    tau_0 = ca.substitute(tau, a_sym, 0)
    room = ca.fmax(torque_limit - ca.fabs(tau_0), 0) / (ca.fabs(c) + AUTHORITY_FLOOR)
    authority = ca.mmin(room)
    a_cmd = ca.if_else(mode > 0.5, a_force, ca.fmin(ca.fmax(a_z, -AUTHORITY_SHARE * authority), AUTHORITY_SHARE * authority))
    tau = ca.substitute(tau, a_sym, a_cmd)
    return ca.Function("control_hybrid", [*x.values(), mode, a_force, limit, torque_limit],
                       [tau, now["y"], now["dy"], ref["y"], ref["dy"], authority], list(HYBRID_INPUTS), list(HYBRID_OUTPUTS))


def hybrid_kernel(row: ControllerRow, mechanism: str, inverse: ControllerDynamics) -> KernelSpec:
    """:func:`hybrid_function` compiled, for the ticks of a simulation."""
    name = f"hybrid_{control_name(row, mechanism, inverse)}"

    def build(params):
        fn = hybrid_function(mechanism, inverse)
        x = [ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(fn.n_in())]
        return ca.Function(name, x, fn.call(x), list(HYBRID_INPUTS), list(HYBRID_OUTPUTS), {"cse": True})

    return KernelSpec(name, build, (mechanism, row.name, *inverse.key), mechanism)


def task_state_kernel(mechanism: str) -> KernelSpec:
    """(q, dq, q_ref, dq_ref, B, p) -> y, y_dot of the state and of the reference (:func:`task_space_sx`)."""
    name = f"task_state_{c_name(mechanism)}"

    def build(params):
        n = n_coordinates(mechanism)
        q, dq, q_ref, dq_ref = (ca.SX.sym(s, n) for s in ("q", "dq", "q_ref", "dq_ref"))
        B, p = ca.SX.sym("B", 3), ca.SX.sym("p", N_P)
        now, ref = task_space_sx(q, dq, B, p, mechanism), task_space_sx(q_ref, dq_ref, B, p, mechanism)
        return ca.Function(name, [q, dq, q_ref, dq_ref, B, p], [now["y"], now["dy"], ref["y"], ref["dy"]],
                           ["q", "dq", "q_ref", "dq_ref", "B", "p"], list(TASK_STATE_OUTPUTS), {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


@dataclass
class HybridController:
    """The controller of the module docstring, built from its ``parts``. ``log`` holds (t, mode, stiffness estimate,
    z's authority) of each tick."""

    parts: ControllerParts
    capabilities: ControllerCapabilities = field(default=ControllerCapabilities(), init=False)
    log: list = field(default_factory=list, init=False, repr=False)
    _kernels: tuple = field(default=(), init=False, repr=False)
    _shared: tuple = field(default=(), init=False, repr=False)
    _mode: int = field(default=0, init=False, repr=False)
    _k: float = field(default=0.0, init=False, repr=False)
    _moments: np.ndarray = field(default=None, init=False, repr=False)
    _z: float | None = field(default=None, init=False, repr=False)
    _t: float | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        self._k = self.parts.section.stiffness_max_N_per_m

    def kernels(self) -> list[KernelSpec]:
        mechanism = self.parts.model.mechanism
        return [hybrid_kernel(self.parts.row, mechanism, self.parts.inverse), task_state_kernel(mechanism)]

    def __call__(self, t: float, state: State) -> np.ndarray:
        assert state.force is not None, "the hybrid controller is given the force observer's estimate (its row needs it)"
        model, reference, g = self.parts.model, self.parts.reference, self.parts.section
        if not self._kernels:
            self._kernels = tuple(native(k) for k in self.kernels())
            self._shared = (self.parts.gains_vector(), model.molar(reference.side), model.vector())
        law, task = self._kernels
        gains, B, p = self._shared
        q_ref, dq_ref, ddq_ref, force = reference.state(t)
        y, dy, y_ref, dy_ref = (np.asarray(v).ravel() for v in task(state.q, state.dq, q_ref, dq_ref, B, p))
        f, f_ref = -float(state.force[2]), -float(force[2])
        h = 0.0 if self._t is None else t - self._t
        self._t = t
        # z through the observer's low-pass, so that the stiffness's two signals lag alike
        b = np.exp(-2 * np.pi * self.parts.gains["observer"].cutoff_Hz * h)
        self._z = y[2] if self._z is None else b * self._z + (1 - b) * y[2]
        leaving = f_ref < g.threshold_N and y_ref[2] < y[2]
        if self._mode == 0 and f >= g.threshold_N and not leaving:
            self._mode, self._moments = 1, np.zeros(9)
        elif self._mode == 1 and leaving:
            self._mode = 0
        a_force = 0.0
        if self._mode == 1:
            if f >= g.threshold_N:  # in contact: a point of the food's force (and its logarithm) against z
                lam = np.exp(-h / STIFFNESS_MEMORY_S)
                z, u = self._z, np.array([f, np.log(f)])
                self._moments = lam * self._moments + np.concatenate([[1.0, z, z * z], u, z * u, u * u])
            w = self._moments[0]
            mean_z, mean_u = self._moments[1] / w, self._moments[3:5] / w
            var_z = self._moments[2] / w - mean_z**2
            if var_z > STIFFNESS_SPREAD_M**2 and f >= g.threshold_N:
                cov = self._moments[5:7] / w - mean_z * mean_u
                var_u = np.maximum(self._moments[7:9] / w - mean_u**2, 1e-300)
                slope = cov / var_z  # of f, and of ln f, against z
                linear = cov[0] ** 2 / var_u[0] >= cov[1] ** 2 / var_u[1]  # the law that fits better (R^2)
                self._k = float(np.clip(slope[0] if linear else f * slope[1], g.stiffness_min_N_per_m, g.stiffness_max_N_per_m))
            dt = 1e-3
            before, after = reference.force_at((t - dt / 2, t + dt / 2))[:, 2]
            df_ref = -(after - before) / dt
            w_f = 2 * np.pi * g.force_frequency_Hz
            kv, kp = 2 * g.force_damping * w_f, w_f**2
            # the law written as a velocity loop, kv (z_dot_cmd - z_dot), with z_dot_cmd within the speed limit
            dz_cmd = np.clip((df_ref + kp / kv * (f_ref - f)) / self._k, -g.speed_limit_m_per_s, g.speed_limit_m_per_s)
            a_force = kv * (dz_cmd - dy[2])
        known = np.array([state.force[0], state.force[1], -f_ref]) if self._mode else state.force
        out = law(state.q, state.dq, q_ref, dq_ref, ddq_ref, known, gains, B, p, float(self._mode), a_force,
                  g.speed_limit_m_per_s, model.limits.torque)
        self.log.append((t, self._mode, self._k, float(out[-1][0])))
        return np.asarray(out[0]).ravel()

    def columns(self, t: np.ndarray) -> list[Column]:
        """The force reference (the task's Fz), the mode, the stiffness estimate and z's authority at the rows (one
        per tick)."""
        log = np.array(self.log[: len(t)]) if self.log else np.zeros((0, 4))
        return [Column("Fz_ref", self.parts.reference.force_at(t)[:, 2], "N", "the hybrid controller's force reference: the task's Fz"),
                Column("force_mode", log[:, 1], "1", "1 where z is force-controlled, 0 where position-controlled"),
                Column("stiffness_estimate", log[:, 2], "N/m", "the hybrid controller's estimate of the food's stiffness along z"),
                Column("z_authority", log[:, 3], "m/s^2", "the largest acceleration of the molar point's z that keeps the "
                       "torques within their limit at the tick's state (under position control the hybrid controller "
                       "commands at most half of it)")]

    def info(self) -> dict:
        return {}


def build(parts: ControllerParts) -> HybridController:
    return HybridController(parts)
