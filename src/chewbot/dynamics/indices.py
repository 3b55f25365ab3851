"""Performance indices of an inverse-dynamics run (seed 001, Sect. 5.3, Eqs. 73–75; reading of docs/conventions.md).

Each index F_k is the mean over the samples of the Euclidean norm of one stacked vector:
F1 torques tau (goal G1), F2 constraint forces at S_1..S_6 (goal G2), F3 HKP normal forces (goal G3),
F4 actuator friction torques, F5 constraint moments at G_1..G_6, F6 constraint forces at G_1..G_6,
F7 HKP friction forces. A mechanism without HKPs (6RSS) has no F3, F7: they are NaN.
"""

from __future__ import annotations

import numpy as np

INDEX_UNITS = {"F1": "N*m", "F2": "N", "F3": "N", "F4": "N*m", "F5": "N*m", "F6": "N", "F7": "N"}


def mean_norm(values: np.ndarray | None) -> float:
    """Mean over the samples (rows) of the Euclidean norm of each row; NaN for None."""
    if values is None:
        return float("nan")
    values = np.asarray(values, dtype=float)
    return float(np.linalg.norm(values.reshape(values.shape[0], -1), axis=1).mean())


def performance_indices(tau, f_S, N, tau_f, M_G, F_G, f_T) -> dict[str, float]:
    """F1..F7 from (N_samples, k) arrays: torques, forces at S_i, HKP normal forces (None or (N, 0) for a
    6RSS), actuator friction torques, moments at G_i, forces at G_i, HKP friction forces (None for a 6RSS)."""
    if N is not None and np.shape(N)[1] == 0:
        N = None
    return {"F1": mean_norm(tau), "F2": mean_norm(f_S), "F3": mean_norm(N), "F4": mean_norm(tau_f),
            "F5": mean_norm(M_G), "F6": mean_norm(F_G), "F7": mean_norm(f_T)}


def friction_share(tau, tau_f, tau_fT) -> np.ndarray:
    """Friction share of each actuator in percent (seed 001, Eq. 75): abs(tau_f + tau_fT) / abs(tau) * 100.

    ``tau_f``: the actuator's own friction torque; ``tau_fT``: the HKP friction mapped onto its shaft (the
    part of tau that the HKP friction forces cause at the sample's normal forces). Where tau = 0 the share is
    infinite (friction with no net torque).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        return 100.0 * np.abs(np.asarray(tau_f) + np.asarray(tau_fT)) / np.abs(np.asarray(tau))
