"""Forward dynamics of both robots: the Newton–Euler model with friction solved for the accelerations.

The inverse dynamics of :mod:`chewbot.dynamics.formulations.newton_euler` gives the six torques from the motion and the HKP normal
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
:data:`~chewbot.dynamics.formulations.newton_euler.DELTA_N`, :data:`~chewbot.dynamics.formulations.newton_euler.DELTA_F_G`), and the directions
of the velocities (known here: the state) regularised with the same constants
(:data:`~chewbot.dynamics.formulations.newton_euler.EPS_THETA_DOT`, :data:`~chewbot.dynamics.formulations.newton_euler.EPS_V_T`), so that the
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
from chewbot.dynamics.formulations.newton_euler import coefficients_kernel, forces_sx, n_unknowns
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


def forward_data_function(params: SymbolicModel) -> ca.Function:
    """The sample's Newton-Euler data D (:func:`chewbot.dynamics.formulations.newton_euler.coefficients_kernel`) split into what
    does not depend on the accelerations and what multiplies them: (q, dq, B, F_B, p) -> D0, Dq with
    D(q_ddot) = D0 + Dq q_ddot exactly (the bodies' accelerations are affine in q_ddot; checked when built). The
    whole cost of the kinematics and of the bodies' equations is here, once per sample."""

    def build():
        m = params
        extra, names = parameter_input(m)
        n = n_coordinates(m.mechanism)
        q, dq, ddq = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n)
        B, F = ca.SX.sym("B", 3), ca.SX.sym("F_B", 3)
        kin = kinematics_kernel(m.mechanism, ORIENTATION).graph(params)
        theta = kin(q, dq, ca.SX.zeros(n), *extra)[KINEMATICS_OUTPUTS.index("theta")]
        D = coefficients_kernel(m.mechanism, ORIENTATION).graph(params)(theta, q, dq, ddq, F, B, *extra)[0]
        Dq = ca.jacobian(D, ddq)
        if ca.depends_on(Dq, ddq):
            raise AssertionError("the Newton-Euler data are not affine in the accelerations")
        D0 = ca.substitute(D, ddq, ca.SX.zeros(n))
        return ca.Function("forward_data", [q, dq, B, F, *extra], [D0, Dq], ["q", "dq", "B", "F_B", *names],
                           ["D0", "Dq"], {"cse": True})

    return cached_graph(params, ("forward-data",), build)


def forward_kernel(mechanism: str) -> KernelSpec:
    """Per-sample forward dynamics (q, dq, tau, B, F_B, friction, p) -> q_ddot, N (target only), residual.

    q, dq: the independent coordinates in Euler angles and their rates (m, rad; m/s, rad/s); tau (N m); B the bite
    point in {M} (m); F_B the bite force on the mandible in {S} (N); friction 0 (off) or 1 (on, the model's
    coefficients). q_ddot (m/s^2, rad/s^2), N = (N_L, N_R) (N) the normal forces of the planes on the condyles,
    residual = max abs(tau_NE - tau) at the answer (N m; rounding when the Newton iteration converged). No p for a
    model (its numbers folded in, as ``chewbot export-c`` writes it).

    The kinematics and the bodies' equations are evaluated once (:func:`forward_data_function`: D = D0 + Dq q_ddot);
    the Newton iteration then works on the torques of D0 + Dq q_ddot and N (:func:`chewbot.dynamics.formulations.newton_euler.forces_sx`),
    a small graph: without friction one step from 0 is exact, with it each step and each trial of its step length
    costs a few hundred operations.
    """
    name = f"forward_{c_name(mechanism)}"

    def build(params):
        m = params
        n, nN = n_coordinates(mechanism), n_unknowns(mechanism)
        data = forward_data_function(params)
        nD = data.size1_out(0)
        # the residual of the torques given D0, Dq: r(z) = tau_NE(D0 + Dq z[:n], z[n:]) - tau
        # Dq keeps its sparsity (166 of 624 entries on the target): most of D does not depend on the accelerations
        D0s, Dqs, zs = ca.SX.sym("D0", nD), ca.SX.sym("Dq", data.sparsity_out(1)), ca.SX.sym("z", n + nN)
        taus, fls = ca.SX.sym("tau", 6), ca.SX.sym("friction")
        ps, _ = parameter_input(m)  # [p] where the model's numbers are an input, [] where they are folded in
        r = forces_sx(m, D0s + ca.mtimes(Dqs, zs[:n]), zs[n:], fls)["tau"] - taus
        residual = ca.Function("forward_residual_of_data", [zs, D0s, Dqs, taus, fls, *ps], [r], {"cse": True})
        step = ca.Function("forward_newton_step", [zs, D0s, Dqs, taus, fls, *ps], [r, -ca.solve(ca.jacobian(r, zs), r)],
                           {"cse": True})

        R = residual_function(params)
        q, dq, tau, B, F, fl = (ca.MX.sym(R.name_in(i), R.sparsity_in(i)) for i in (0, 1, 4, 5, 6, 7))
        extra = [ca.MX.sym("p", R.sparsity_in(8))] if R.n_in() > 8 else []
        D0, Dq = data(q, dq, B, F, *extra)

        # One safeguarded Newton step as a function of (z, r, data) -> (z, r), skipped at run time once the residual is
        # below TOLERANCE (a Switch: the C code evaluates only the branch taken).
        z_, r_, D0_, Dq_, tau_, fl_ = (ca.MX.sym(nm, sp) for nm, sp in (("z", ca.Sparsity.dense(n + nN, 1)), ("r", ca.Sparsity.dense(6, 1)),
                                                                        ("D0", ca.Sparsity.dense(nD, 1)), ("Dq", data.sparsity_out(1)),
                                                                        ("tau", ca.Sparsity.dense(6, 1)), ("friction", ca.Sparsity.dense(1, 1))))
        p_ = [ca.MX.sym("p", x.sparsity()) for x in extra]
        data_ = [D0_, Dq_, tau_, fl_, *p_]
        full = step(z_, *data_)[1]
        z_full = z_ + full
        r_full = residual(z_full, *data_)
        # the shorter trials (steps 1/2, ..., 1/2^(HALVINGS - 1)) only where the full step did not lower the residual:
        # the trial with the smallest residual, the full step included
        zf_, rf_, s_ = ca.MX.sym("z_full", n + nN), ca.MX.sym("r_full", 6), ca.MX.sym("step", n + nN)
        best, best_r = zf_, rf_
        for k in range(1, HALVINGS):
            trial = z_ + 0.5**k * s_
            r_trial = residual(trial, *data_)
            better = ca.sumsqr(r_trial) < ca.sumsqr(best_r)
            best, best_r = ca.if_else(better, trial, best), ca.if_else(better, r_trial, best_r)
        trial_ins = [z_, zf_, rf_, s_, *data_]
        shorter = ca.Function("forward_shorter", trial_ins, [best, best_r])
        accept = ca.Function("forward_accept", trial_ins, [zf_, rf_])
        choose = ca.Function.if_else("forward_choose", accept, shorter)
        z_next, r_next = choose(ca.sumsqr(r_full) < ca.sumsqr(r_), z_, z_full, r_full, full, *data_)
        ins = [z_, r_, *data_]
        correct = ca.Function("forward_correct", ins, [z_next, r_next])
        keep = ca.Function("forward_keep", ins, [z_, r_])
        iteration = ca.Function.if_else("forward_iteration", keep, correct)
        # without friction r is affine in z: one step from 0 is exact; with it, Newton from there
        z = step(ca.MX.zeros(n + nN), D0, Dq, tau, 0, *extra)[1]
        r = residual(z, D0, Dq, tau, fl, *extra)
        for _ in range(NEWTON_ITERATIONS):
            z, r = iteration(ca.norm_inf(r) <= TOLERANCE, z, r, D0, Dq, tau, fl, *extra)
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
