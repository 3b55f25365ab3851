"""The HKP normal forces N_L, N_R of every formulation, and the contact model (bilateral or unilateral).

**Convention.** N_j (j = L, R) is the force of plane j on the centre T_j of its condylar ball along the planes'
unit normal n = (p1, 0, 1)/sqrt(p1^2 + 1) (up, the side of the mandible): N_j > 0 where the plane pushes the
condyle, N_j < 0 where it pulls it (which only a ball held in a slot allows). Seed 001 writes the same force as
N_j n with n not normalised, N_j its component along Z_S; the signs agree.

**Normal forces from tau and the motion.** The 6RSS core (:mod:`chewbot.dynamics.formulations.core6rss`) has six equations in
x = X_EE; with the normal forces on the condyles they read

    J_6' tau + P N = f_6 = M_6 x_ddot + C_6 x_dot + G_6 - Q_6,    P = [dT_L/dx' n, dT_R/dx' n]   (6 x 2),

P N being the generalised force of N_L n at T_L and N_R n at T_R (their virtual work is dT_j . n N_j). The plane
constraints n . T_j(x) + const = 0 hold along x = phi(q_EE), so P' M_J = 0: projecting onto M_J removes P N and
leaves Eq. (53), the four equations the frictionless formulations solve for tau. The two that the projection
removed give N. For a tau that solves Eq. (53), f_6 - J_6' tau is orthogonal to the range of M_J, which is the
range of P (P has full column rank and is orthogonal to M_J, 6 = 4 + 2), hence

    N = (P'P)^-1 P' (f_6 - J_6' tau) = N_0 + K tau,    N_0 = (P'P)^-1 P' f_6,   K = -(P'P)^-1 P' J_6',

exactly (any left inverse of P gives the same N). :func:`contact_kernel` evaluates N_0, K (and J_theta1, for the
unilateral distribution) per sample; :func:`normal_forces` applies them to a formulation's torques. Newton-Euler
has N among its unknowns already (with friction, which this map leaves out) and reports its own.

**Contact models.** ``bilateral`` (the papers' reading, the default): the ball is held in a slot (seed 001,
Sect. 3: a socket as wide as the ball's diameter), the plane may push or pull; N is reported, a pull is a warning.
``unilateral``: a ball pressed on a plane, N_j >= ``contact.preload_N``; the redundant actuation is used to keep
both condyles pressed. For the frictionless minimum-norm formulations that is the *unilateral fallback*
(:func:`unilateral_minimum_norm`): tau = tau_0 + Z y, tau_0 the minimum-norm torques, Z (6 x 2) an orthonormal
basis of the null space of J_theta1' (internal torques: they squeeze the mechanism without moving it), so
abs(tau)^2 = abs(tau_0)^2 + abs(y)^2 (tau_0 is orthogonal to Z) and N = N(tau_0) + A y with A = K Z (2 x 2, regular
away from singular poses). The least abs(y) with A y >= preload - N(tau_0) is the point of a polygon nearest to
the origin, found exactly by enumerating its four active sets, all samples at once. Newton-Euler adds the bounds
to its distribution (:func:`chewbot.dynamics.distribution.solve`). docs/contact.md says what each reading means
for the physical robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.base import Dynamics
from chewbot.dynamics.core import lifted_core
from chewbot.dynamics.options import check_contact
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.model.symbolic import c_name
from chewbot.table import Table
from chewbot.rotation import R_omega_sx, matrix_from_euler_angles_sx

CONTACT_OUTPUTS = ("N0", "K", "J_theta1")
NORMAL_FORCE_DESCRIPTION = "normal force of the plane on the condyle along n = (p1, 0, 1)/abs(.) (> 0: the plane pushes)"
# A candidate of the unilateral QP counts as feasible down to this much below a bound (N): the rounding of
# N (about 1e-14 N on forces of tens of newtons), far below the contact-pull check's 1e-6 N.
BOUND_TOL_N = 1e-9
# A row of K Z, or the determinant of K Z, below this share of its size before the projection (abs(K_j), abs(a_1)
# abs(a_2)) is rounding, not a lever: the null-space torques cannot change that N (a singular pose).
SINGULAR_RTOL = 1e-12
FALLBACK = ("unilateral fallback: the minimum-norm torques subject to N_L, N_R >= contact.preload_N "
            "(a QP in the two null-space torques, solved exactly by its active sets)")


def bound_names(preload: float) -> list[str]:
    """How an infeasible sample names the unilateral bounds N_L, N_R >= preload."""
    return [f"N_{j} >= {preload:g} N (contact.preload_N)" for j in "LR"]


def contact_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (q_EE, q_EE_dot, q_EE_ddot, B, F_B, p) -> N0 (2), K (2 x 6), J_theta1 (6 x 4) of the
    target, inputs as :func:`chewbot.dynamics.formulations.core6rss.torque_kernel`: N = N0 + K tau (N) for any tau that solves
    Eq. (53) (module docstring)."""
    name = f"contact_{c_name(mechanism)}"

    def build(params):
        lc = lifted_core(params)
        m, x, core = lc.params, lc.x, lc.core
        R, n = matrix_from_euler_angles_sx(x[3], x[4], x[5]), m.hkp.normal
        # dT_j = M_0a' [I, -[r_T]x] dx in twist form (omega = R_omega [alpha, beta, gamma]_dot), so dT_j/dx' n = M_0a' [n; r_T x n]
        M_0a = ca.diagcat(ca.SX.eye(3), R_omega_sx(x[3], x[4]))
        P = ca.horzcat(*[ca.mtimes(M_0a.T, ca.vertcat(n, ca.cross(ca.mtimes(R, T), n))) for T in (m.hkp.T_L, m.hkp.T_R)])
        left = ca.solve(ca.mtimes(P.T, P), P.T)  # (P'P)^-1 P'
        outputs = [ca.mtimes(left, core["f6"]), -ca.mtimes(left, core["J6"].T), ca.mtimes(core["J6"], lc.M_J)]
        return ca.Function(name, lc.inputs, [ca.densify(o) for o in outputs],
                           ["q", "dq", "ddq", "B", "F_B", "p"][:len(lc.inputs)], list(CONTACT_OUTPUTS), {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


def contact_kernels(mechanism: str) -> list[KernelSpec]:
    """The kernels :func:`frictionless_dynamics` uses on a mechanism (none for the 6RSS)."""
    return [contact_kernel(mechanism)] if mechanism == "target" else []


def normal_force_map(model: Model, kin: Kinematics, side: str | None = None) -> dict[str, np.ndarray]:
    """N0 (n, 2), K (n, 2, 6), J_theta1 (n, 6, 4) along the task of the target: N = N0 + K tau."""
    q, dq, ddq = kin.euler_angle_state()
    out = evaluate(native(contact_kernel(model.mechanism)), q, dq, ddq, model.molar(side or kin.side), kin.force, model.vector())
    return dict(zip(CONTACT_OUTPUTS, out))


def apply_map(terms: dict[str, np.ndarray], tau: np.ndarray) -> np.ndarray:
    """N (n, 2) of the torques tau (n, 6) by the map of :func:`normal_force_map`."""
    return terms["N0"] + np.einsum("nij,nj->ni", terms["K"], tau)


def normal_forces(model: Model, kin: Kinematics, tau: np.ndarray, side: str | None = None) -> np.ndarray:
    """N_L, N_R (n, 2), N, of the torques tau (n, 6) along the task of the target (module docstring)."""
    return apply_map(normal_force_map(model, kin, side), tau)


@dataclass(frozen=True)
class UnilateralSolution:
    """The unilateral fallback's torques ``tau`` (n, 6) and normal forces ``N`` (n, 2); ``raised``: the samples
    where the bound was active (tau differs from the minimum-norm torques there, nowhere else); ``infeasible``: the
    samples where the null-space torques cannot change N (a singular pose), left at the minimum-norm torques."""

    tau: np.ndarray
    N: np.ndarray
    raised: np.ndarray
    infeasible: np.ndarray


def unilateral_minimum_norm(tau: np.ndarray, terms: dict[str, np.ndarray], preload: float) -> UnilateralSolution:
    """The least-norm torques with the same motion and N_L, N_R >= ``preload`` at every sample (module docstring).

    ``tau``: the minimum-norm torques (n, 6) (Eq. 54); ``terms``: :func:`normal_force_map` of the same task.
    """
    Q, _ = np.linalg.qr(terms["J_theta1"], mode="complete")
    Z = Q[:, :, 4:]  # (n, 6, 2): J_theta1' Z = 0, Z'Z = I
    N = apply_map(terms, tau)
    A = terms["K"] @ Z
    y, feasible = _nearest_point(A, preload - N, np.linalg.norm(terms["K"], axis=2))
    y[~feasible] = 0.0  # never clipped: the infeasible samples are named and keep the minimum-norm torques
    raised = np.flatnonzero(np.any(y != 0.0, axis=1))
    tau = tau.copy()
    tau[raised] += np.einsum("nij,nj->ni", Z[raised], y[raised])
    N = N.copy()
    N[raised] = apply_map({k: v[raised] for k, v in terms.items()}, tau[raised])
    return UnilateralSolution(tau, N, raised, np.flatnonzero(~feasible))


def _nearest_point(A: np.ndarray, b: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The y of least norm with A y >= b, at every sample (A (n, 2, 2), b (n, 2)), and whether there is one.
    ``scale`` (n, 2): the size of each row's coefficients before the projection onto the null space (abs(K_j)),
    against which a row of A counts as zero.

    The KKT point of the convex QP is the equality-constrained minimiser of its active set; the four sets give
    y = 0, the projections of 0 onto each line a_j . y = b_j, and the vertex A y = b. The feasible candidate of
    least norm is the optimum; y = 0 comes first, so where the bounds already hold y is exactly 0.
    """
    n = b.shape[0]
    a_dot = np.einsum("nji,nji->nj", A, A)  # abs(a_j)^2 of the rows a_j
    det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    adjugate = np.stack([np.stack([A[:, 1, 1], -A[:, 0, 1]], -1), np.stack([-A[:, 1, 0], A[:, 0, 0]], -1)], 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        # a row of A that vanishes to rounding cannot reach its bound, nor can two parallel rows both (singular poses)
        reach = a_dot > (SINGULAR_RTOL * scale) ** 2
        candidates = [np.zeros((n, 2))]
        candidates += [np.where(reach[:, j, None], A[:, j, :] * (b[:, j] / a_dot[:, j])[:, None], np.nan) for j in range(2)]
        vertex = reach.all(axis=1) & (np.abs(det) > SINGULAR_RTOL * np.sqrt(a_dot[:, 0] * a_dot[:, 1]))
        candidates.append(np.where(vertex[:, None], np.einsum("nij,nj->ni", adjugate, b) / det[:, None], np.nan))
    best, cost = np.zeros((n, 2)), np.full(n, np.inf)
    for y in candidates:
        ok = np.isfinite(y).all(axis=1) & np.all(np.einsum("nij,nj->ni", A, y) >= b - BOUND_TOL_N, axis=1)
        c = np.where(ok, np.einsum("ni,ni->n", y, y), np.inf)
        better = c < cost
        best[better], cost[better] = y[better], c[better]
    return best, np.isfinite(cost)


def add_normal_forces(table: Table, N: np.ndarray) -> None:
    """The columns N_L, N_R (N) of ``N`` (n, 2) in ``table``."""
    table.add_block(["N_L", "N_R"], N, "N", NORMAL_FORCE_DESCRIPTION)


def frictionless_dynamics(method: str, model: Model, kin: Kinematics, tau: np.ndarray, *, side: str | None = None,
                          contact: str = "bilateral", info: dict | None = None, table: Table | None = None) -> Dynamics:
    """The :class:`Dynamics` of a frictionless minimum-norm formulation on a task, shared by hessian, lagrange,
    liang and 6rss-core: on the target, the normal forces N_L, N_R of its torques (bilateral), or the unilateral
    fallback's torques and normal forces (unilateral, ``info["infeasible"]`` naming the samples where no torques
    keep both condyles pressed). ``tau``: the formulation's minimum-norm torques (n, 6)."""
    check_contact(contact)
    info, table = dict(info or {}), table if table is not None else Table()
    if not model.has_hkp:
        return Dynamics(method, tau, table, info)
    terms = normal_force_map(model, kin, side)
    if contact == "bilateral":
        add_normal_forces(table, apply_map(terms, tau))
        info["contact"] = {"model": "bilateral", "normal_forces": "N_L, N_R from tau and the motion (the two equations that Eq. 53 projects out)"}
        return Dynamics(method, tau, table, info)
    preload = model.contact.preload
    sol = unilateral_minimum_norm(tau, terms, preload)
    add_normal_forces(table, sol.N)
    info["contact"] = {"model": "unilateral", "preload_N": preload, "distribution": FALLBACK,
                       "raised_samples": int(sol.raised.size)}
    info["infeasible"] = [{"sample": int(k), "t": float(kin.t[k]), "limits": bound_names(preload),
                           "solver": "singular: the redundant torques cannot change N here"} for k in sol.infeasible]
    return Dynamics(method, sol.tau, table, info)
