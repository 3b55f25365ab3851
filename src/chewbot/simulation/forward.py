"""Forward dynamics of both robots: the Newton–Euler model with friction solved for the accelerations.

The inverse dynamics of :mod:`chewbot.dynamics.newton_euler` gives the six torques from the motion and the HKP normal
forces N = (N_L, N_R) (Eqs. 33-50): tau = tau_NE(q, q_dot, q_ddot, N). The forward dynamics solves the same six
equations the other way round. With the state (q, q_dot) in the independent coordinates (Euler angles: X, Y, alpha,
beta for the target, X_EE for the 6RSS), the torques tau and the bite force F_B given, the unknowns are
z = (q_ddot, N) for the target (4 + 2) and z = q_ddot for the 6RSS (6):

    r(z) = tau_NE(q, q_dot, q_ddot, N) - tau = 0.

The HKP constraints hold by construction (Z and gamma are the parasitic functions of q, the crank angles the
closed-form inverse kinematics): nothing can drift. Without friction r is affine in z (the accelerations enter the
bodies' accelerations linearly, N the mandible's equations linearly), so one Newton step from any z is exact. With
friction r is not: the HKP friction grows with abs(N), the actuator friction with abs(F_G,i), and F_G,i is affine in
q_ddot and N. These magnitudes are smoothed exactly as the inverse dynamics smooths them (sqrt(x^2 + delta^2),
:data:`~chewbot.dynamics.newton_euler.DELTA_N`, :data:`~chewbot.dynamics.newton_euler.DELTA_F_G`), and the directions
of the velocities (known here: the state) regularised with the same constants
(:data:`~chewbot.dynamics.newton_euler.EPS_THETA_DOT`, :data:`~chewbot.dynamics.newton_euler.EPS_V_T`), so that the
forward and the inverse model are one model: the inverse dynamics evaluated at the forward's accelerations and normal
forces returns the applied torques (tested). The smoothed r is differentiable; :func:`forward_kernel` starts from the
friction-free solution and takes at most :data:`NEWTON_ITERATIONS` Newton steps with the exact Jacobian dr/dz (a bounded
cost, as a controller or a compiled simulation loop needs; the steps stop once the residual is below
:data:`TOLERANCE`) and returns the final residual so that the caller can verify it.

The residual itself (:func:`residual_function`) is what the integrator (:mod:`chewbot.simulation.integrator`) solves
at its stages, with the accelerations and normal forces of every stage as unknowns.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.newton_euler import coefficients_kernel, forces_sx, n_unknowns
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.model import Model
from chewbot.compiled.cache import cached_graph
from chewbot.model.symbolic import SymbolicModel, c_name, parameter_input

ORIENTATION = "euler-angles"
# Newton steps of the forward kernel after the friction-free start. Measured at 100 random states and torques of
# each robot, with the default friction coefficients and with both Coulomb coefficients raised to 0.3: the residual
# is below 1e-12 N m after at most 4 steps; 8 leave a margin, and the kernel returns its residual. Each step takes the
# best of the steps 1, 1/2, ..., 1/2^(HALVINGS - 1) (the full step wherever Newton converges). With Coulomb
# coefficients of 1 some states have no solution (the rigid body with Coulomb friction, Painlevé's paradox): the
# residual then stays large, and the caller reports it.
NEWTON_ITERATIONS = 8
HALVINGS = 4
# Newton stops where max abs(r) is below this (N m): rounding leaves about 1e-16 on torques of tenths of N m.
TOLERANCE = 1e-13

RESIDUAL_INPUTS = ("q", "dq", "ddq", "N", "tau", "B", "F_B", "friction")


def n_coordinates(mechanism: str) -> int:
    """Independent coordinates of the state: 4 for the target, 6 for the 6RSS."""
    return 4 if mechanism == "target" else 6


def residual_function(params: SymbolicModel) -> ca.Function:
    """The Newton–Euler equations as a residual: (q, dq, ddq, N, tau, B, F_B, friction, p) -> r = tau_NE - tau (N m).

    q in Euler angles (the independent coordinates), N the normal forces (target; size 0 for the 6RSS), tau the
    applied torques, B the bite point in {M}, F_B the bite force on the mandible in {S}, friction 0 or 1. Built on
    the model's numbers ``params`` (no p for a model's constants, folded in), once per numbers.
    """
    return cached_graph(params, ("forward-residual",), lambda: _residual(params))


def _residual(params: SymbolicModel) -> ca.Function:
    m = params
    extra, names = parameter_input(m)
    n, nN = n_coordinates(m.mechanism), n_unknowns(m.mechanism)
    q, dq, ddq, N = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n), ca.SX.sym("N", nN)
    tau, B, F, fl = ca.SX.sym("tau", 6), ca.SX.sym("B", 3), ca.SX.sym("F_B", 3), ca.SX.sym("friction")
    # the graphs of the kinematics and of the Newton-Euler coefficients on the same parameters
    kin = kinematics_kernel(m.mechanism, ORIENTATION).graph(params)
    theta = kin(q, dq, ca.SX.zeros(n), *extra)[KINEMATICS_OUTPUTS.index("theta")]
    D = coefficients_kernel(m.mechanism, ORIENTATION).graph(params)(theta, q, dq, ddq, F, B, *extra)[0]
    r = forces_sx(m, D, N, fl)["tau"] - tau
    return ca.Function("forward_residual", [q, dq, ddq, N, tau, B, F, fl, *extra], [r], [*RESIDUAL_INPUTS, *names], ["r"],
                       {"cse": True})


def plant_outputs_function(params: SymbolicModel) -> ca.Function:
    """What is reported of the plant at a state with its solved accelerations and normal forces:
    (q, dq, ddq, N, B, F_B, friction, p) -> theta, dtheta (crank angles and rates), axial and radial loads at the
    crank bearings G_i (N, the ``bearing-load`` check), margin (> 0 inside the workspace, :func:`workspace_margin_sx`);
    on the model's numbers ``params``."""
    return cached_graph(params, ("plant-outputs",), lambda: _outputs(params))


def _outputs(params: SymbolicModel) -> ca.Function:
    m = params
    extra, names = parameter_input(m)
    n, nN = n_coordinates(m.mechanism), n_unknowns(m.mechanism)
    q, dq, ddq, N = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n), ca.SX.sym("N", nN)
    B, F, fl = ca.SX.sym("B", 3), ca.SX.sym("F_B", 3), ca.SX.sym("friction")
    out = dict(zip(KINEMATICS_OUTPUTS, kinematics_kernel(m.mechanism, ORIENTATION).graph(params)(q, dq, ddq, *extra)))
    D = coefficients_kernel(m.mechanism, ORIENTATION).graph(params)(out["theta"], q, dq, ddq, F, B, *extra)[0]
    forces = forces_sx(m, D, N, fl)
    margin = workspace_margin_sx(m, out)
    return ca.Function("plant_outputs", [q, dq, ddq, N, B, F, fl, *extra],
                       [out["theta"], out["dtheta"], forces["axial"], forces["radial"], margin],
                       ["q", "dq", "ddq", "N", "B", "F_B", "friction", *names], ["theta", "dtheta", "axial", "radial", "margin"],
                       {"cse": True})


def plant_outputs_kernel(mechanism: str) -> KernelSpec:
    """:func:`plant_outputs_function` compiled (p as its last input), for whole simulations at once."""
    name = f"plant_outputs_{c_name(mechanism)}"

    def build(params):
        fn = plant_outputs_function(params)
        x = [ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(fn.n_in())]
        return ca.Function(name, x, fn.call(x), fn.name_in(), fn.name_out(), {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


def workspace_margin_sx(m, kinematics: dict) -> ca.SX:
    """How far a pose is inside the workspace, from the outputs of the kinematics graph: the smallest of, per chain,
    1 - abs(C)/sqrt(A^2 + B^2) (reach) and sin(mu) - SINGULAR_TOLERANCE (transmission), and for the target each
    condyle's distance to its socket's x and y bounds (m). Negative (or NaN, past reach) outside; the reason is then
    found by the kinematics' own checks (:func:`chewbot.kinematics.motion.solve_kinematics`)."""
    from chewbot.kinematics.ik import SINGULAR_TOLERANCE

    parts = [1 - kinematics["reach"], kinematics["transmission"] - SINGULAR_TOLERANCE]
    if m.has_hkp:
        h = m.hkp
        for T, y in ((kinematics["T_L"], h.y_left), (kinematics["T_R"], h.y_right)):
            parts += [T[0] - h.x_range[0], h.x_range[1] - T[0], T[1] - y[0], y[1] - T[1]]
    return ca.mmin(ca.vertcat(*parts))


FORWARD_OUTPUTS = {"target": ("ddq", "N", "residual"), "6rss": ("ddq", "residual")}


def forward_kernel(mechanism: str) -> KernelSpec:
    """Per-sample forward dynamics (q, dq, tau, B, F_B, friction, p) -> q_ddot, N (target only), residual.

    q, dq: the independent coordinates in Euler angles and their rates (m, rad; m/s, rad/s); tau (N m); B the bite
    point in {M} (m); F_B the bite force on the mandible in {S} (N); friction 0 (off) or 1 (on, the model's
    coefficients). q_ddot (m/s^2, rad/s^2), N = (N_L, N_R) (N) the normal forces of the planes on the condyles,
    residual = max abs(tau_NE - tau) at the answer (N m; rounding when the Newton iteration converged). No p for a
    model (its numbers folded in, as ``chewbot export-c`` writes it).
    """
    name = f"forward_{c_name(mechanism)}"

    def build(params):
        n, nN = n_coordinates(mechanism), n_unknowns(mechanism)
        R = residual_function(params)
        x = [ca.SX.sym(R.name_in(i), R.sparsity_in(i)) for i in range(R.n_in())]
        r = R.call(x)[0]
        newton_step = ca.Function("forward_newton_step", x, [r, -ca.solve(ca.jacobian(r, ca.vertcat(x[2], x[3])), r)],
                                  {"cse": True})
        # one MX graph calling the residual and the Newton step as functions: each is compiled once, not per iteration
        q, dq, tau, B, F, fl = (ca.MX.sym(R.name_in(i), R.sparsity_in(i)) for i in (0, 1, 4, 5, 6, 7))
        extra = [ca.MX.sym("p", R.sparsity_in(8))] if R.n_in() > 8 else []

        args = [q, dq, tau, B, F, fl, *extra]

        def residual(z, q, dq, tau, B, F, fl, *extra):
            return R(q, dq, z[:n], z[n:], tau, B, F, fl, *extra)

        # One safeguarded Newton step as a function of (z, r, inputs) -> (z, r), skipped at run time once the residual
        # is below TOLERANCE (a Switch: the C code evaluates only the branch taken): without friction the start is
        # exact and no step runs; with it, as many as Newton needs.
        zs, rs = ca.MX.sym("z", n + nN), ca.MX.sym("r", 6)
        xs = [ca.MX.sym(a.name(), a.sparsity()) for a in args]
        step = newton_step(xs[0], xs[1], zs[:n], zs[n:], *xs[2:])[1]
        best, best_r = zs + step, residual(zs + step, *xs)
        for k in range(1, HALVINGS):  # the trial step with the smallest residual (the full step where Newton converges)
            trial = zs + 0.5**k * step
            r_trial = residual(trial, *xs)
            better = ca.sumsqr(r_trial) < ca.sumsqr(best_r)
            best, best_r = ca.if_else(better, trial, best), ca.if_else(better, r_trial, best_r)
        correct = ca.Function("forward_correct", [zs, rs, *xs], [best, best_r])
        keep = ca.Function("forward_keep", [zs, rs, *xs], [zs, rs])
        iteration = ca.Function.if_else("forward_iteration", keep, correct)
        # without friction r is affine in z: one step from 0 is exact; with it, Newton from there
        z = newton_step(q, dq, ca.MX.zeros(n), ca.MX.zeros(nN), tau, B, F, 0, *extra)[1]
        r = residual(z, *args)
        for _ in range(NEWTON_ITERATIONS):
            z, r = iteration(ca.norm_inf(r) <= TOLERANCE, z, r, *args)
        res = ca.norm_inf(r)
        outs = [z[:n], z[n:], res] if nN else [z[:n], res]
        return ca.Function(name, [q, dq, tau, B, F, fl, *extra], outs,
                           ["q", "dq", "tau", "B", "F_B", "friction", *(["p"] if extra else [])], list(FORWARD_OUTPUTS[mechanism]))

    return KernelSpec(name, build, (mechanism, NEWTON_ITERATIONS), mechanism)


@dataclass(frozen=True)
class Forward:
    """Forward dynamics along samples (arrays samples first, SI): ``ddq`` (N, n) the accelerations of the independent
    coordinates, ``N`` (N, 2) the HKP normal forces (target; (N, 0) for the 6RSS), ``residual`` (N,) the largest
    torque residual of the Newton-Euler equations at the answer (N m)."""

    ddq: np.ndarray
    N: np.ndarray
    residual: np.ndarray


def forward_dynamics(model: Model, q, dq, tau, force, side: str = "left", friction: bool = False) -> Forward:
    """The accelerations (and normal forces) of ``model`` at states (q, dq) (N, n) under torques tau (N, 6) and bite
    forces (N, 3) at the molar of ``side``, all samples in one call of the compiled :func:`forward_kernel`; inputs of
    one sample's size are shared by every sample."""
    fn = native(forward_kernel(model.mechanism))
    q = np.atleast_2d(q)
    out = evaluate(fn, q, dq, tau, model.molar(side), force, float(friction), model.vector())
    if model.has_hkp:
        return Forward(out[0], out[1], out[2][:, 0])
    return Forward(out[0], np.zeros((q.shape[0], 0)), out[1][:, 0])
