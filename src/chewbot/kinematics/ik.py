"""Inverse kinematics in closed form (one chain at a time) and forward kinematics by Newton's method.

Inverse kinematics of chain i (docs/conventions.md): with d = O_M + R M_i - G_i and u, v the first two columns of R_C0,i,
the closure equation abs(S_i - M_i)^2 = L_r^2 reads A cos(theta) + B sin(theta) = C with A = 2 L_c u.d,
B = 2 L_c v.d, C = L_c^2 + abs(d)^2 - L_r^2. Its two solutions are theta = atan2(B, A) +/- acos(C / r),
r = sqrt(A^2 + B^2); abs(C) > r means the chain cannot reach the pose, abs(C) = r is the singular
configuration where crank and coupler are aligned and the two branches meet. The sign of
dh_i/dtheta_i = r sin(theta - atan2(B, A)) tells the branch; the working branch is the one through
theta = 0 at the home pose, kept along the whole trajectory. Its sign per chain is part of the model's parameter
vector (:mod:`chewbot.model.vector`), so the compiled kinematics (:func:`chewbot.kinematics.functions.kinematics_kernel`)
solves the same branch; this NumPy version is its independent reference.
"""

from __future__ import annotations

import numpy as np

from chewbot.compiled.kernels import evaluate
from chewbot.errors import KinematicsError
from chewbot.kinematics.functions import closure_function
from chewbot.model import Model
from chewbot.model.chains import closure_coefficients, working_branches

# A chain closer than this to its singular configuration (sin of the transmission angle, :func:`transmission`: 1
# when the coupler lies along the crank tip's motion, 0 at the dead point) is reported as singular: its
# theta_dot would be more than 1e4 times the speed of the coupler end along the coupler divided by the crank length.
SINGULAR_TOLERANCE = 1e-4


def transmission(model: Model, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """sin of each chain's transmission angle mu_i at the poses (p (N, 3) m, R (N, 3, 3)): (N, 6), 1 at best, 0 at
    the singular configuration (docs/conventions.md, "Transmission angle").

    With w_i = z_i x (S_i - G_i) / L_c the direction in which the crank moves its tip S_i and e_i = (M_i - S_i) / L_r
    the coupler's direction, mu_i is the angle between e_i and the plane normal to w_i (the plane of the crank
    and its shaft):

        sin mu_i = abs(e_i . w_i) = abs(dh_i/dtheta_i) / (2 L_c L_r) = sqrt(A^2 + B^2 - C^2) / (2 L_c L_r)

    (A, B, C of the module docstring; the last form holds on a closed chain, on either branch). It is the share of
    the crank tip's motion that goes along the coupler: turning at theta_dot_i, the crank moves M_i along the
    coupler at L_c theta_dot_i sin mu_i, so a motion of the mandible needs crank rates that grow as 1/sin mu_i
    (the input transmission index of motion/force transmissibility).
    """
    A, B, C = closure_coefficients(model, p, R)
    return np.sqrt(np.clip(A**2 + B**2 - C**2, 0, None)) / (2 * model.crank_length * model.coupler_length)


def inverse_kinematics(model: Model, p: np.ndarray, R: np.ndarray, times: np.ndarray | None = None) -> np.ndarray:
    """Actuator angles theta (N, 6) of the poses (p (N, 3) in m, R (N, 3, 3)), on the working branch.

    The result is continuous along the samples (no 2 pi jumps) and starts in (-pi, pi]. A pose that a
    chain cannot reach, or a chain at its singular configuration, raises :class:`KinematicsError` naming the
    first such sample and chain.
    """
    p = np.atleast_2d(p)
    R = np.asarray(R).reshape(-1, 3, 3)
    A, B, C = closure_coefficients(model, p, R)
    ratio = C / np.hypot(A, B)
    check_chains(np.abs(ratio), transmission(model, p, R), times)
    return continuous(np.arctan2(B, A) + working_branches(model)[None, :] * np.arccos(ratio))


def check_chains(reach: np.ndarray, sin_transmission: np.ndarray, times: np.ndarray | None = None) -> None:
    """Raise :class:`KinematicsError` at the first sample (and chain) out of reach (abs(C)/sqrt(A^2 + B^2) > 1),
    else at the first singular one (sin of the transmission angle below :data:`SINGULAR_TOLERANCE`)."""
    _raise_first(reach > 1, times, lambda n, k: "pose out of reach: "
                 f"abs(C)/sqrt(A^2+B^2) = {reach[n, k]:.6f} > 1 (the coupler cannot close the loop)")
    _raise_first(sin_transmission < SINGULAR_TOLERANCE, times, lambda n, k: f"chain {k + 1} is singular: crank and "
                 f"coupler aligned (sin of transmission angle {sin_transmission[n, k]:.2e} < {SINGULAR_TOLERANCE:g})")


def continuous(theta: np.ndarray) -> np.ndarray:
    """Angles (N, 6) made continuous along the samples (no 2 pi jumps), the first sample in (-pi, pi]."""
    theta = np.unwrap(theta, axis=0)
    return theta - 2 * np.pi * np.round(theta[:1] / (2 * np.pi))


def _raise_first(mask: np.ndarray, times, message) -> None:
    if mask.any():
        n, k = np.argwhere(mask)[0]
        raise KinematicsError(message(n, k), sample=int(n), chain=int(k) + 1, time=None if times is None else float(times[n]))


def forward_kinematics(
    model: Model,
    theta: np.ndarray,
    orientation: str = "euler-angles",
    q0: np.ndarray | None = None,
    tol: float = 1e-13,
    max_iter: int = 30,
) -> np.ndarray:
    """Mandible coordinates q_EE (N, n) from actuator angles theta (N, 6), by Newton's method on H = 0.

    All samples are solved at once (Gauss-Newton on the 6 closure equations, plus abs(e) = 1 for Euler
    parameters; the target's 4 or 5 coordinates make the system overdetermined but consistent). ``q0`` is the
    initial guess (default: home). Raises :class:`KinematicsError` for samples that do not converge to a
    closure residual below ``tol`` (in units of the coordinates' step).
    """
    theta = np.atleast_2d(theta)
    fn, p = closure_function(model.mechanism, orientation), model.vector()
    n = fn.numel_in(1)
    N = theta.shape[0]
    if q0 is None:
        q0 = _home(n, orientation)
    q = np.array(np.broadcast_to(q0, (N, n)), dtype=float)
    scale = model.coupler_length[None, :] ** 2  # H is in m^2: normalise each equation by L_r^2
    for _ in range(max_iter):
        H, J, unit, Ju = evaluate(fn, theta, q, p)
        res = np.concatenate([H / scale, unit], axis=1)
        Jac = np.concatenate([J / scale[:, :, None], Ju.reshape(N, 1, n)], axis=1)
        step = _batched_lstsq(Jac, -res)
        q = q + step
        if np.abs(step).max() < tol:
            break
    H, _, unit, _ = evaluate(fn, theta, q, p)
    bad = np.flatnonzero(np.abs(H / scale).max(axis=1) > 1e-9)
    if bad.size:
        raise KinematicsError(f"forward kinematics did not converge (closure residual {np.abs(H[bad[0]] / scale[0]).max():.2e})", sample=int(bad[0]))
    return q


def _batched_lstsq(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    # Normal equations, batched; J has full column rank away from singular configurations.
    JtJ = np.einsum("nki,nkj->nij", J, J)
    Jtr = np.einsum("nki,nk->ni", J, r)
    return np.linalg.solve(JtJ, Jtr[..., None])[..., 0]


def _home(n: int, orientation: str) -> np.ndarray:
    q = np.zeros(n)
    if orientation == "euler-parameters":
        q[n - 4 if n == 7 else 2] = 1.0  # e0 = 1
    return q
