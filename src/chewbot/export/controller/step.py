"""What one exported step is (:class:`StepSpec`), its two CasADi graphs, its status bits and the defaults of its
configuration.

Three graphs carry the numerical work of the step, the first two generated as C with the model's numbers folded in:
:func:`fk_function` (the estimate of the pose from the angles, its residual, last step and conditioning, the pose
X_EE, the transmission and the workspace margin) and :func:`law_function` (the torques, the HKP normal forces, the
reference's workspace margin, for Newton-Euler the distribution's last step and how far past the actuator limits it
is); and :func:`drive_function` (the motors' torques and currents of the output torques through the drive's loss law,
its gear ratio, efficiency and torque constant inputs from the context's configuration).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from chewbot.compiled.cache import folded, symbols
from chewbot.dynamics.formulations.newton_euler import coefficients_kernel, forces_sx, limit_bounds, n_unknowns
from chewbot.dynamics.g1 import distribution_function
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.model import Drive, Model
from chewbot.model import drive as drive_law
from chewbot.dynamics.registry import formulation
from chewbot.simulation.controllers.law import CompiledLaw, control_function
from chewbot.simulation.controllers.table import EXPORTABLE, controller_row
from chewbot.simulation.options import ControllerDynamics
from chewbot.simulation.forward import ORIENTATION, n_coordinates, workspace_margin_sx
from chewbot.simulation.plant import state_function
from chewbot.simulation.sensor import gauss_newton_sx

EXPORT_FORMAT = 1
PREFIX = "chewbot_ctrl"


@dataclass(frozen=True)
class StatusBit:
    """One bit of the step's status word: the header's ``CHEWBOT_CTRL_{name}``, when it is raised and what the step
    then does (the README's table of safe behaviours)."""

    name: str
    behaviour: str


# The status word, bit 0 first (bit k has the value 1 << k); docs/realtime.md gives each one's safe behaviour too.
STATUS = (
    StatusBit("FK_NOT_CONVERGED", "the estimate's last Gauss-Newton step > `fk_step_tolerance` or its closure residual > "
                                  "`fk_residual_tolerance`: the estimate is not updated; torques held (see HOLDING)"),
    StatusBit("NEAR_SINGULAR", "the estimate's conditioning < `conditioning_min` or its transmission < `transmission_min`: as "
                               "FK_NOT_CONVERGED (the angles no longer pin the pose down)"),
    StatusBit("TORQUE_SATURATED", "a commanded torque beyond `torque_limit`: that torque clipped to the limit, the others unchanged"),
    StatusBit("REFERENCE_OUTSIDE", "the reference at t is outside the workspace (a chain out of reach or near its dead point, a "
                                   "condyle outside its socket): the last reference inside is held at rest (zero rate and "
                                   "acceleration) and the law evaluated on it"),
    StatusBit("WATCHDOG", "the step was called more than `watchdog_s` after the previous one: latched; zero torques until "
                          "`chewbot_ctrl_clear_faults`"),
    StatusBit("ESTOP", "the emergency stop is on: zero torques at once (no rate limit), the estimator keeps running"),
    StatusBit("RATE_LIMITED", "a torque changed faster than `torque_rate_limit`: its change limited to the limit times dt"),
    StatusBit("LIMIT_ACTIVE", "Newton-Euler distribution: its torques exceed an actuator limit (torque, power, axial or radial "
                              "load). Fallback: the distribution's torques, saturated at `torque_limit` (no constrained "
                              "re-solve in the step)"),
    StatusBit("DISTRIBUTION_NOT_CONVERGED", "Newton-Euler distribution: its last Newton step > `distribution_step_tolerance`: "
                                            "the torques still satisfy the equations of motion, but are not the optimum"),
    StatusBit("HOLDING", "the estimate is unusable (FK_NOT_CONVERGED, NEAR_SINGULAR, BAD_INPUT, or torques not finite): the "
                         "last output torques are held, for at most `max_hold_ticks` ticks in a row, then zero"),
    StatusBit("BAD_INPUT", "a measured angle or t not finite, or t before the previous step's: as HOLDING, t not taken"),
)
STATUS_BITS = {bit.name: 1 << k for k, bit in enumerate(STATUS)}

# Defaults of the configuration the caller may change in ctx->config after chewbot_ctrl_init.
# m or rad: the last Gauss-Newton step of a converged estimate. Measured along the default task: 2e-12 with exact
# angles, 1.4e-10 with 1e-4 rad of encoder noise, 3e-9 with 1e-3 rad (the least-squares fit of the target's four
# coordinates to six noisy angles converges linearly); 1e-7 m or rad is far below what the noise does to the estimate.
FK_STEP_TOLERANCE = 1e-7
# The scaled closure residual (each chain's |S M|^2 - L^2 over L^2) at the estimate: about 1.3 times the encoders'
# noise (rad) for the least-squares fit, 0.15 times the error of one crank angle inconsistent with the others.
# Beyond 1e-2, an angle off by about 4 degrees, the angles are rejected.
FK_RESIDUAL_TOLERANCE = 1e-2
CONDITIONING_MIN = 1e-4           # det(J'J)^(1/n) / (trace/n) below this: near a direct-kinematics singularity
TRANSMISSION_MIN = 0.05           # sin of the smallest transmission angle below this: near a crank's dead point
DISTRIBUTION_STEP_TOLERANCE = 1e-6  # N: the distribution's last Newton step at a converged answer
MAX_HOLD_TICKS = 10               # ticks the last torques are held while the estimate is unusable, then zero
WATCHDOG_PERIODS = 1.5            # a step later than this many periods after the previous one trips the watchdog


@dataclass(frozen=True)
class StepSpec:
    """What one exported step is: the controller's ``model``, law ``kind`` (pd or computed-torque), inverse dynamics
    ``method`` with ``goal`` and ``friction`` (Newton-Euler's), ``gains`` (the law's vector), the velocity filter's
    ``cutoff`` (Hz), the control ``rate`` (Hz), the bite ``side`` and the reference table ``t``, ``q``, ``dq``,
    ``ddq``, ``force`` (samples first; the force the controller knows), ``torque_rate_limit`` (N m/s, 0: off)."""

    model: Model
    kind: str
    method: str
    goal: str | None
    friction: bool
    gains: np.ndarray
    cutoff: float
    rate: float
    side: str
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    force: np.ndarray
    torque_rate_limit: float = 0.0

    @classmethod
    def of(cls, controller: CompiledLaw, rate: float, torque_rate_limit: float = 0.0) -> StepSpec:
        """The step of a simulation's built-in controller (its model, law, gains and reference)."""
        parts = controller.parts
        if not parts.row.exportable:
            raise ValueError(f"the exported step runs {' or '.join(EXPORTABLE)}, not {parts.row.name}")
        r, inverse = controller.reference, parts.inverse
        return cls(controller.model, parts.row.name, inverse.method, inverse.goal, bool(inverse.friction),
                   parts.gains_vector(), parts.gains["estimator"].cutoff_Hz, float(rate), r.side,
                   np.asarray(r.t, float), r.q, r.dq, r.ddq, controller.known_force(np.asarray(r.force, float)),
                   float(torque_rate_limit))

    @property
    def uses_inverse_dynamics(self) -> bool:
        """Its controller's law evaluates the inverse dynamics (its row)."""
        return controller_row(self.kind).needs.inverse_dynamics

    @property
    def n(self) -> int:
        return n_coordinates(self.model.mechanism)

    @property
    def n_normal(self) -> int:
        return n_unknowns(self.model.mechanism)

    @property
    def distributes(self) -> bool:
        """The law distributes the target's torques by Newton-Euler's fixed-cost solver (limits checked)."""
        return self.uses_inverse_dynamics and "goal" in formulation(self.method).sample_options and self.model.has_hkp


def fk_function(model: Model) -> ca.Function:
    """(theta, q_guess) -> q, X (pose X_EE), residual, step, conditioning (:func:`gauss_newton_sx`), transmission (the
    smallest sin of the chains' transmission angles), margin (> 0: the estimated pose inside the workspace), the
    model's numbers folded in."""
    m = folded(model)
    mech = model.mechanism
    n = n_coordinates(mech)
    theta, guess = ca.SX.sym("theta", 6), ca.SX.sym("q_guess", n)
    fk = gauss_newton_sx(mech, m, theta, guess)
    kin = dict(zip(KINEMATICS_OUTPUTS, kinematics_kernel(mech, ORIENTATION).graph()(fk["q"], ca.SX.zeros(n), ca.SX.zeros(n), m.p)))
    return ca.Function(f"{PREFIX}_fk", [theta, guess],
                       [fk["q"], kin["X"], fk["residual"], fk["step"], fk["conditioning"], ca.mmin(kin["transmission"]),
                        workspace_margin_sx(m, kin)],
                       ["theta", "q_guess"], ["q", "X", "residual", "step", "conditioning", "transmission", "margin"], {"cse": True})


def law_function(spec: StepSpec) -> ca.Function:
    """(q, dq, q_ref, dq_ref, ddq_ref, F_B, gains) -> tau (before saturation), N (the HKP normal forces), ref_margin
    (> 0: the reference inside the workspace), dist_step and limit_excess (Newton-Euler's distribution: its last Newton
    step, and the largest of |limit value| / bound - 1 over its 24 actuator limits; 0 and -1 otherwise), the model's
    numbers folded in.

    N: Newton-Euler's distribution's own where it distributes; else the normal forces that the controller's model
    without friction gives under the commanded torques at the estimated state (its forward dynamics: the accelerations
    and N that make the Newton-Euler equations hold, one linear solve)."""
    model, mech = spec.model, spec.model.mechanism
    m, p = folded(model), folded(model).p
    n, nN = spec.n, spec.n_normal
    q, dq, q_ref, dq_ref, ddq_ref = (ca.SX.sym(name, n) for name in ("q", "dq", "q_ref", "dq_ref", "ddq_ref"))
    F, gains = ca.SX.sym("F_B", 3), ca.SX.sym("gains", len(spec.gains))
    B = ca.DM(model.molar(spec.side))
    law = control_function(controller_row(spec.kind), mech, ControllerDynamics(spec.method, spec.goal, spec.friction))
    tau = law(q, dq, q_ref, dq_ref, ddq_ref, F, gains, B, p)
    ref_margin = state_function(mech)(q_ref, dq_ref, p)[2]
    kin = kinematics_kernel(mech, ORIENTATION).graph()
    coefficients = coefficients_kernel(mech, ORIENTATION).graph()
    i_theta = KINEMATICS_OUTPUTS.index("theta")
    dist_step, excess = ca.SX(0), ca.SX(-1)
    if spec.distributes:
        ddq = ddq_ref + gains[n:] * (dq_ref - dq) + gains[:n] * (q_ref - q)
        D = coefficients(kin(q, dq, ddq, p)[i_theta], q, dq, ddq, F, B, p)[0]
        _, N, _, dist_step, limits = distribution_function(symbols(mech), ORIENTATION, spec.goal, 1.0 if spec.friction else 0.0)(D, p)
        bounds = ca.DM(limit_bounds(model))
        excess = ca.mmax(ca.fabs(limits) / bounds - 1)
    elif nN:
        x = ca.SX.sym("x", n + nN)  # accelerations and normal forces
        D = coefficients(kin(q, dq, x[:n], p)[i_theta], q, dq, x[:n], F, B, p)[0]
        model_tau = forces_sx(m, D, x[n:], 0.0)["tau"]  # linear in x
        A = ca.jacobian(model_tau, x)
        b = ca.substitute(model_tau, x, ca.SX.zeros(n + nN))
        A = ca.substitute(A, x, ca.SX.zeros(n + nN))
        N = ca.solve(A, tau - b)[n:]
    else:
        N = ca.SX(0, 1)
    return ca.Function(f"{PREFIX}_law", [q, dq, q_ref, dq_ref, ddq_ref, F, gains],
                       [tau, ca.densify(N) if nN else ca.SX.zeros(1), ref_margin, dist_step, excess],
                       ["q", "dq", "q_ref", "dq_ref", "ddq_ref", "F_B", "gains"], ["tau", "N", "ref_margin", "dist_step", "limit_excess"],
                       {"cse": True})


# The drive's numbers the step's configuration holds, in the order of the drive graph's input "drive".
DRIVE_CONFIG = ("gear_ratio", "gear_efficiency", "torque_constant")


def drive_config(model: Model) -> dict[str, float]:
    """The configuration's drive members for ``model``: its drive's numbers (SI), the neutral law's without a drive
    (ratio 1, loss-free, 1 N m/A: the current is the crank torque) and ``encoder_counts`` (0: no encoder)."""
    d = drive_law.of(model)
    return {"gear_ratio": d.gear_ratio, "gear_efficiency": d.efficiency, "torque_constant": d.torque_constant,
            "encoder_counts": d.encoder_counts}


def drive_function() -> ca.Function:
    """(tau, dtheta, drive) -> tau_motor, current: the motors' torques (N m) that give the cranks' ``tau`` (N m) at the
    crank rates ``dtheta`` (rad/s) through the drive's loss law inverted (:func:`chewbot.model.drive.motor_torque`, the
    Python controllers' path), and their currents (A); ``drive`` holds :data:`DRIVE_CONFIG`."""
    tau, dtheta, numbers = ca.SX.sym("tau", 6), ca.SX.sym("dtheta", 6), ca.SX.sym("drive", len(DRIVE_CONFIG))
    d = Drive(0.0, numbers[0], numbers[1], numbers[2], 0.0)
    tau_motor = drive_law.motor_torque(d, tau, dtheta)
    return ca.Function(f"{PREFIX}_drive", [tau, dtheta, numbers], [tau_motor, drive_law.current(d, tau_motor)],
                       ["tau", "dtheta", "drive"], ["tau_motor", "current"], {"cse": True})


def home_angles(model: Model) -> np.ndarray:
    """The crank angles at the home pose (q = 0), the model's inverse kinematics (rad)."""
    n = n_coordinates(model.mechanism)
    out = kinematics_kernel(model.mechanism, ORIENTATION).graph()(np.zeros(n), np.zeros(n), np.zeros(n), model.vector())
    return np.asarray(out[KINEMATICS_OUTPUTS.index("theta")]).ravel()
