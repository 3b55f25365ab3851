"""The closure equation of each chain in closed form, and the working branch it is solved on.

With d = O_M + R M_i - G_i and u, v the first two columns of R_C0,i, the closure equation abs(S_i - M_i)^2 = L_r^2
of chain i reads A cos(theta) + B sin(theta) = C with A = 2 L_c u.d, B = 2 L_c v.d, C = L_c^2 + abs(d)^2 - L_r^2
(docs/conventions.md). Its two solutions are theta = atan2(B, A) +/- acos(C / r), r = sqrt(A^2 + B^2); the working
branch is the one through theta = 0 at the home pose, a property of the model's geometry: its sign per chain is an
entry of the parameter vector (:mod:`chewbot.model.vector`), and :mod:`chewbot.kinematics.ik` solves it. Given the
crank angles, :func:`crank_tips` places the crank tips S_i.
"""

from __future__ import annotations

import numpy as np


def closure_coefficients(model, p: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A, B, C (N, 6) of every chain at the poses p (N, 3) m, R (N, 3, 3)."""
    Mi = p[:, None, :] + np.einsum("nij,kj->nki", R, model.M)  # (N, 6, 3)
    d = Mi - model.G[None]
    u = model.R_C0[:, :, 0]
    v = model.R_C0[:, :, 1]
    Lc, Lr = model.crank_length, model.coupler_length
    A = 2 * Lc * np.einsum("nki,ki->nk", d, u)
    B = 2 * Lc * np.einsum("nki,ki->nk", d, v)
    C = Lc**2 + np.einsum("nki,nki->nk", d, d) - Lr**2
    return A, B, C


def working_branches(model) -> np.ndarray:
    """The working branch of each chain: the sign (+1/-1) of dh_i/dtheta_i at the home pose, (6,)."""
    A, B, C = closure_coefficients(model, np.zeros((1, 3)), np.eye(3)[None])
    r = np.hypot(A, B)
    phi = np.arctan2(B, A)
    acos = np.arccos(np.clip(C / r, -1, 1))
    plus, minus = _wrap(phi + acos), _wrap(phi - acos)
    return np.where(np.abs(plus) <= np.abs(minus), 1.0, -1.0)[0]


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def crank_tips(model, theta: np.ndarray) -> np.ndarray:
    """S_i = G_i + R_C0,i Rz(theta_i) [L_c,i, 0, 0] in {S}, (N, 6, 3) m, from theta (N, 6) rad."""
    u, v = model.R_C0[:, :, 0], model.R_C0[:, :, 1]
    arm = np.cos(theta)[..., None] * u + np.sin(theta)[..., None] * v
    return model.G + model.crank_length[:, None] * arm
