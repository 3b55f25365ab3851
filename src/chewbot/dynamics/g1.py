"""The optimal distribution of the target's redundant torques at a fixed cost, as one CasADi graph per sample: the
friction-aware goal-G1 kernel and what a controller's Newton–Euler inverse dynamics runs (seed 001, Sect. 4.5).

``g1_target`` is the Newton–Euler model with friction (:mod:`chewbot.dynamics.formulations.newton_euler`) with the G1 problem
solved inside the kernel on its two unknowns: the best piecewise least-squares start, then a fixed number
(:data:`G1_ITERATIONS`) of safeguarded Newton steps: a fixed cost, as a real-time loop needs. The kernel returns its
last step and the gradient of |tau|^2 at its answer (both ~0 at the optimum: the step is the one Newton proposes
there, so a stalled line search shows) and the actuator-limit values, so the caller can verify all three; it does
not handle active limits (the Python solver, :mod:`chewbot.dynamics.distribution`, falls back to SQP there).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.base import Sample
from chewbot.dynamics.distribution import MEASURABLE
from chewbot.dynamics.formulations.newton_euler import coefficients_kernel, forces_sx, goal_residual, n_unknowns, start_sx
from chewbot.kinematics.motion import Kinematics
from chewbot.kinematics.options import Orientation
from chewbot.model import Model
from chewbot.compiled.cache import cached_graph
from chewbot.model.symbolic import SymbolicModel, parameter_input

# Safeguarded Newton iterations of the G1 kernel, and step halvings tried in each. From the piecewise
# least-squares start the optimum is reached to rounding within 10 iterations for Coulomb coefficients from the
# default up to 1 (HKP) and 0.5 (actuators) on the default task; 12 leave a margin. The kernel reports the
# Newton step at its answer, so a caller sees when this was not enough. With the drive's rotors, at the rests
# between the default task's cycles (samples 1699, 2499, ...) the Newton step proposed is about 66 N long and Armijo's
# condition holds only below 1/8 of it: with 4 halvings (1 ... 1/8) every step was refused and the kernel stayed 1.3 %
# off the solver's torques whatever the iterations; 6 halvings reach the optimum there, 8 leave a margin.
G1_ITERATIONS = 12
HALVINGS = 8
ARMIJO = 1e-4
G1_ORIENTATION = "euler-parameters"


def g1_kernel(mechanism: str = "target", orientation: str = G1_ORIENTATION,
              iterations: int = G1_ITERATIONS) -> KernelSpec:
    """Per-sample friction-aware goal-G1 distribution of the target: (theta, q, dq, ddq, F_B, B, p) ->
    tau (N m), N (N_L, N_R in N), grad: gradient of |tau|^2 w.r.t. N at the answer (N m^2/N), step: the size
    of the Newton step proposed at the answer (N; tiny only at the optimum), limits (24: tau, power, axial,
    radial load per actuator, in N m, W, N, N). q_EE in ``orientation``.

    It starts from the best piecewise least-squares candidate (:func:`chewbot.dynamics.formulations.newton_euler.start_sx`)
    and takes ``iterations`` safeguarded Newton steps: the exact Hessian where it is positive definite, else
    Gauss-Newton's, and the longest of the steps 1, 1/2, ..., 1/2^(HALVINGS-1) that satisfies Armijo's
    condition (none: stay). Fixed cost, no branches in the C code. No p for a model (its numbers folded in).
    """
    if mechanism != "target":
        raise ValueError("the G1 distribution kernel is for the target robot (the 6RSS has nothing to distribute)")
    if iterations < 1:
        raise ValueError(f"iterations must be at least 1, not {iterations}")

    def build(params):
        coeff = coefficients_kernel(mechanism, orientation).graph(params)
        model = params
        extra, extra_names = parameter_input(model)
        theta, q, dq, ddq = (ca.SX.sym(name, coeff.size1_in(i)) for i, name in enumerate(("theta", "q", "dq", "ddq")))
        F, B = ca.SX.sym("F_B", 3), ca.SX.sym("B", 3)
        D = coeff(theta, q, dq, ddq, F, B, *extra)[0]
        tau, Nk, grad, newton_step, limits = distribution_function(params, orientation, "min-torque", 1.0, iterations)(D, *extra)
        return ca.Function("g1_target", [theta, q, dq, ddq, F, B, *extra], [tau, Nk, grad, newton_step, limits],
                           ["theta", "q", "dq", "ddq", "F_B", "B", *extra_names], ["tau", "N", "grad", "step", "limits"], {"cse": True})

    return KernelSpec("g1_target", build, (mechanism, orientation, iterations), mechanism)

# A controller's unilateral distribution keeps N_L, N_R this far (N) above contact.preload_N: the plant's normal forces
# differ from the ones the controller plans by what its model and its force estimate miss (the estimate's lag, the
# torques held over a tick). Held at the bare bound, the carrot's test (chewbot tpa --food carrot, the drive on) left
# N_R at -0.0042 N on 48 samples, where the controller's face put it at 0 N; 1 N is 240 times that miss and 1 % of
# the carrot's 100 N peak.
CONTROLLER_MARGIN_N = 1.0


def distribution_function(params: SymbolicModel, orientation: str, goal: str, friction: float,
                          iterations: int = G1_ITERATIONS, unilateral: bool = False, margin: float = 0.0) -> ca.Function:
    """One sample's distribution of the target's redundant torques by ``goal`` (seed 001, Sect. 4.5), at a fixed cost:
    (D, p) -> tau, N, grad, step, limits, D the sample's Newton-Euler data (:func:`coefficients_kernel` in
    ``orientation``), ``friction`` 0.0 or 1.0 (a constant of the graph). The best piecewise least-squares start
    (:func:`chewbot.dynamics.formulations.newton_euler.start_sx`), then ``iterations`` safeguarded Newton steps on the goal's
    |r|^2 (see :func:`g1_kernel`); grad and step at the answer (both ~0 at the optimum), the 24 limit values.

    ``unilateral``: N_L, N_R >= ``contact.preload_N`` (the unilateral contact, docs/contact.md) by the active sets of
    the two bounds, as the distribution solver's :func:`chewbot.dynamics.distribution.solve` does: the free optimum
    where it respects them; else the best of the admissible optima on the faces (one force held at the preload, the
    other by ``iterations`` safeguarded Newton steps) and the corner (both at the preload). On the faces and the
    corner grad is the gradient along the free unknowns only (zero along a held one), so it stays ~0 at the answer.
    ``margin`` (N): the bounds are ``contact.preload_N`` + margin (a controller's, :data:`CONTROLLER_MARGIN_N`)."""
    def build():
        model = params
        extra, _ = parameter_input(model)
        Dsym = ca.SX.sym("D", coefficients_kernel(model.mechanism, orientation).graph(params).size1_out(0))
        N = ca.SX.sym("N", n_unknowns(model.mechanism))
        out = forces_sx(model, Dsym, N, friction)
        r = goal_residual(model, goal, Dsym, N, friction)
        J = ca.sumsqr(r)
        value = ca.Function("distribution_value", [Dsym, N, *extra], [J])

        def newton(free: tuple[int, ...]) -> tuple[ca.Function, ca.Function]:
            """The safeguarded Newton step on the unknowns ``free`` (the others held), and at N the gradient along
            them and the size of the step Newton proposes there."""
            Nf = N[list(free)]
            H, g = ca.hessian(J, Nf)
            Jr = ca.jacobian(r, Nf)
            n = len(free)
            H_gn = 2 * ca.mtimes(Jr.T, Jr) + 1e-12 * ca.SX.eye(n)
            convex = ca.logic_and(H[0, 0] > 0, ca.det(H) > 0)
            pf = -ca.solve(ca.if_else(convex, H, H_gn), g)
            p = ca.SX.zeros(2)
            grad = ca.SX.zeros(2)
            for k, j in enumerate(free):
                p[j], grad[j] = pf[k], g[k]
            slope = ca.dot(g, pf)
            Np = N  # no acceptable step: stay
            for k in reversed(range(HALVINGS)):  # the longest acceptable step wins: it is tested last
                alpha = 0.5**k
                trial = N + alpha * p
                Np = ca.if_else(value(Dsym, trial, *extra) <= J + ARMIJO * alpha * slope, trial, Np)
            # where the predicted decrease is below the rounding of J, Armijo's test is noise: the full Newton step
            # is taken (the quadratic-convergence region), as the distribution solver does
            Np = ca.if_else(-slope <= MEASURABLE * J, N + p, Np)
            return (ca.Function("distribution_step", [Dsym, N, *extra], [Np]),
                    ca.Function("distribution_stationary", [Dsym, N, *extra], [grad, ca.norm_2(pf)]))

        def iterate(free: tuple[int, ...], Nk):
            step, stationary = newton(free)
            for _ in range(iterations):
                Nk = step(Dsym, Nk, *extra)
            return (Nk, *stationary(Dsym, Nk, *extra))

        start = ca.Function("distribution_start", [Dsym, *extra], [start_sx(model, goal, Dsym)])
        dth = Dsym[-6:]
        lim = ca.vertcat(out["tau"], out["tau"] * dth, out["axial"], out["radial"])
        final = ca.Function("distribution_final", [Dsym, N, *extra], [out["tau"], lim])
        # the Newton step proposed at the answer: ~0 only at a stationary point, whatever the line search did
        Nk, grad, newton_step = iterate((0, 1), start(Dsym, *extra))
        if unilateral:
            pre = model.contact.preload + margin
            corner = ca.vertcat(pre, pre)
            best = (corner, ca.SX.zeros(2), ca.SX(0.0), value(Dsym, corner, *extra))
            for held in (0, 1):  # the face N_held = preload, the other free from its clamped free optimum
                free = 1 - held
                N0 = ca.SX.zeros(2)
                N0[held], N0[free] = pre, ca.fmax(Nk[free], pre)
                Nf, gf, sf = iterate((free,), N0)
                Jf = value(Dsym, Nf, *extra)
                better = ca.logic_and(Nf[free] >= pre, Jf < best[3])
                best = tuple(ca.if_else(better, a, b) for a, b in zip((Nf, gf, sf, Jf), best))
            admissible = ca.logic_and(Nk[0] >= pre, Nk[1] >= pre)
            Nk, grad, newton_step = (ca.if_else(admissible, a, b) for a, b in zip((Nk, grad, newton_step), best[:3]))
        tau, limits = final(Dsym, Nk, *extra)
        return ca.Function("distribution", [Dsym, *extra], [tau, Nk, grad, newton_step, limits])

    return cached_graph(params, ("distribution", orientation, goal, friction, iterations, unilateral, margin), build)


def g1_distribution(model: Model, kin: Kinematics, side: str | None = None) -> dict[str, np.ndarray]:
    """Friction-aware goal-G1 distribution along a whole task with the compiled :func:`g1_kernel` (one C loop):
    tau (N, 6), N (N, 2), grad (N, 2), step (N, 1), limits (N, 24), in ``kin.orientation``."""
    fn = native(g1_kernel(model.mechanism, kin.orientation))
    out = evaluate(fn, kin.theta, kin.q, kin.dq, kin.ddq, kin.force, model.molar(side or kin.side), model.vector())
    return dict(zip(("tau", "N", "grad", "step", "limits"), out))


def sample_torques(mechanism: str, goal: str = "min-torque", friction: bool = True,
                   contact: str = "bilateral") -> ca.Function:
    """A controller's Newton–Euler inverse dynamics of one sample (:class:`~chewbot.dynamics.base.Sample`): the
    sample's data and, on the target, the distribution of ``goal`` at a fixed cost (:func:`distribution_function`;
    ``contact="unilateral"``: with N_L, N_R >= ``contact.preload_N`` + :data:`CONTROLLER_MARGIN_N`); the 6RSS's torques
    in closed form. The model's friction where ``friction``."""
    s = Sample.of(mechanism)
    m = s.params
    ea = Orientation.euler_angles.value
    D = coefficients_kernel(mechanism, ea).graph()(s.kinematics["theta"], s.q, s.dq, s.ddq, s.F, s.B, m.p)[0]
    fl = 1.0 if friction else 0.0
    if m.has_hkp:
        return s.function(distribution_function(m, ea, goal, fl, unilateral=contact == "unilateral",
                                                margin=CONTROLLER_MARGIN_N)(D, m.p)[0])
    return s.function(forces_sx(m, D, ca.SX(0, 1), fl)["tau"])
