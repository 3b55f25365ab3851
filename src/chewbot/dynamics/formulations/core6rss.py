"""Inverse dynamics on a 6RSS core (the formulation ``6rss-core``): the 6RSS model in X_EE per sample
(:mod:`chewbot.dynamics.core`), the HKP constraints projected out, the minimum-norm torques of Eq. (53) in one
compiled kernel per sample. The kernels of :func:`torque_kernel` and :func:`dynamics_kernel` are what ``chewbot
export-c`` writes for the robot's controller.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.base import Dynamics, Sample
from chewbot.dynamics.contact import contact_kernels, frictionless_dynamics
from chewbot.dynamics.core import lifted_core
from chewbot.dynamics.energy import require_euler_angles
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.model.symbolic import SymbolicModel, c_name


DYNAMICS_OUTPUTS = ("tau", "theta", "dtheta", "J_theta1", "M_f", "C_f", "G_f", "Q_B")
TORQUE_OUTPUTS = ("tau", "theta", "dtheta")


def _kernel_terms(params: SymbolicModel, matrices: bool):
    lc = lifted_core(params)
    model, dq, ddq, M_J, dM_J, core = lc.params, lc.dq, lc.ddq, lc.M_J, lc.dM_J, lc.core
    J1 = ca.mtimes(core["J6"], M_J)
    terms = {
        "theta": core["theta"], "dtheta": ca.mtimes(J1, dq), "J_theta1": J1,
        "M_f": ca.mtimes([M_J.T, core["M6"], M_J]),
        "C_f": ca.mtimes(M_J.T, ca.mtimes(core["M6"], dM_J) + ca.mtimes(core["C6"], M_J)),
        "G_f": ca.mtimes(M_J.T, core["G6"]), "Q_B": ca.mtimes(M_J.T, core["Q6"]),
    }
    if matrices:  # the right-hand side of Eq. (53) from its terms, which this kernel forms anyway
        rhs = ca.mtimes(terms["M_f"], ddq) + ca.mtimes(terms["C_f"], dq) + terms["G_f"] - terms["Q_B"]
    else:  # without forming them
        rhs = ca.mtimes(M_J.T, core["f6"])
    terms["tau"] = ca.mtimes(J1, ca.solve(ca.mtimes(J1.T, J1), rhs)) if model.has_hkp else ca.solve(J1.T, rhs)
    return lc.inputs, terms


def _kernel(mechanism: str, prefix: str, outputs: tuple[str, ...]) -> KernelSpec:
    name = f"{prefix}_{c_name(mechanism)}"

    def build(params):
        inputs, terms = _kernel_terms(params, matrices=len(outputs) > len(TORQUE_OUTPUTS))
        return ca.Function(name, inputs, [ca.densify(terms[k]) for k in outputs],
                           ["q", "dq", "ddq", "B", "F_B", "p"][:len(inputs)], list(outputs), {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


def torque_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (q_EE, q_EE_dot, q_EE_ddot, B, F_B, p) -> tau, theta, theta_dot (no p where a model's
    numbers are folded in, :meth:`~chewbot.compiled.kernels.KernelSpec.folded`: what ``chewbot export-c`` writes).

    q_EE in Euler angles ([X, Y, alpha, beta] for the target, X_EE for the 6RSS; m, rad), B the bite point in
    {M} (m), F_B the bite force on the mandible in {S} (N). tau (N m) is the minimum-norm solution of Eq. (53)
    (unique for the 6RSS), its right-hand side built without the matrices (the lean kernel for a controller's
    feedforward).
    """
    return _kernel(mechanism, "tau", TORQUE_OUTPUTS)


def dynamics_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel with the same inputs as :func:`torque_kernel` and the terms of Eq. (53) as well:
    tau, theta, theta_dot, J_theta1, M_f, C_f, G_f, Q_B (for model-based control that needs the matrices)."""
    return _kernel(mechanism, "dynamics", DYNAMICS_OUTPUTS)


def core_terms(model: Model, kin: Kinematics, side: str | None = None, matrices: bool = True) -> dict[str, np.ndarray]:
    """The kernel outputs along the task (arrays samples first): those of :func:`dynamics_kernel`, or of
    :func:`torque_kernel` with ``matrices=False``."""
    q, dq, ddq = kin.euler_angle_state()
    outputs = DYNAMICS_OUTPUTS if matrices else TORQUE_OUTPUTS
    fn = native((dynamics_kernel if matrices else torque_kernel)(model.mechanism))
    out = evaluate(fn, q, dq, ddq, model.molar(side or kin.side), kin.force, model.vector())
    return dict(zip(outputs, out))


def core6rss(model: Model, kin: Kinematics, *, side: str | None = None, contact: str = "bilateral") -> Dynamics:
    """Minimum-norm torques from the 6RSS core with the HKPs projected out (see the module docstring), the
    target's normal forces and the ``contact`` model as :func:`chewbot.dynamics.formulations.hessian.hessian`. ``side``
    overrides the bite side of ``kin``."""
    require_euler_angles(kin, "6rss-core")
    tau = core_terms(model, kin, side, matrices=False)["tau"]
    return frictionless_dynamics("6rss-core", model, kin, tau, side=side, contact=contact,
                                 info={"equations": "6RSS core in X_EE, HKPs projected out (Eq. 53)", "friction": False})


def kernels(mechanism: str, orientation: str) -> list:
    """The compiled kernels of a run: the lean torque kernel, and the target's normal-force map."""
    return [torque_kernel(mechanism), *contact_kernels(mechanism)]


def sample_torques(mechanism: str) -> ca.Function:
    """A controller's inverse dynamics of one sample (:class:`~chewbot.dynamics.base.Sample`): the lean torque kernel."""
    s = Sample.of(mechanism)
    return s.function(torque_kernel(mechanism).graph()(s.q, s.dq, s.ddq, s.B, s.F, s.params.p)[0])
