"""The parameters a log can identify, their place in the model's vector p, and a physical parametrisation.

The physical parameters x (SI), in this order: the mandible's mass m; its inertia about O_M in {M},
I_xx, I_yy, I_zz, I_xy, I_xz, I_yz; the HKP Coulomb coefficient mu_H and viscous coefficient c_H; the product
rho = R mu_c of the actuators' friction arm and Coulomb coefficient (the only way they enter the torques); the
actuators' viscous coefficient c_A. Each friction coefficient is one number shared by the six actuators or the
two contacts, as in the parameter file. The first moment of the mandible is not a parameter: {M} is at its
mass centre by the model's convention (docs/identification.md).

The estimator works in ``phi``, a parametrisation in which every value within simple bounds is a physical body:
m > 0, and the inertia through the Cholesky factor L of the mandible's second moment of mass about O_M,
Sigma = integral of r r' dm = L L' (lower triangular, positive diagonal), I = trace(Sigma) 1 - Sigma. Sigma
positive definite is exactly the condition that I is positive definite and its principal moments satisfy the
strict triangle inequality (the pseudo-inertia of a body with its frame at the mass centre). The friction
entries of phi are those of x, bounded below by 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chewbot.model import Model
from chewbot.model.vector import parameter_index
from chewbot.units import factor

INERTIA_ENTRIES = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@dataclass(frozen=True)
class Parameter:
    """One entry of x: its name, the parameter-file key it is written to (with a 1-based entry for the inertia),
    its SI unit and the file's unit."""

    name: str
    key: str
    unit: str
    file_unit: str
    group: str

    def in_file_units(self, value):
        """``value`` (SI) in the file's unit."""
        return value / factor(self.file_unit)


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("m", "mandible.mass_g", "kg", "g", "mandible.mass_g"),
    *(Parameter(f"I_{'xyz'[a]}{'xyz'[b]}", f"mandible.inertia_g_mm2[{a + 1}][{b + 1}]", "kg*m^2", "g*mm^2",
                "mandible.inertia_g_mm2") for a, b in INERTIA_ENTRIES),
    Parameter("mu_H", "friction.hkp_coulomb", "1", "1", "friction.hkp_coulomb"),
    Parameter("c_H", "friction.hkp_viscous_Ns_per_m", "N*s/m", "N*s/m", "friction.hkp_viscous_Ns_per_m"),
    Parameter("R*mu_c", "friction.actuator_arm_mm*friction.actuator_coulomb", "m", "mm", "friction.actuator_coulomb"),
    Parameter("c_A", "friction.actuator_viscous_Nms_per_rad", "N*m*s/rad", "N*m*s/rad", "friction.actuator_viscous_Nms_per_rad"),
)
N_X = len(PARAMETERS)
NAMES = tuple(p.name for p in PARAMETERS)
INERTIA = slice(1, 7)
HKP = (7, 8)  # the HKP friction: none on the 6RSS
# The keys a user may hold at the file's value (--fix): each is one group of x.
GROUPS = tuple(dict.fromkeys(p.group for p in PARAMETERS))
_P_INDEX = {name: parameter_index(name) for name in ("mandible_mass", "mandible_inertia[1][1]", "friction.hkp_coulomb",
                                                     "friction.hkp_viscous", "friction.actuator_arm",
                                                     "friction.actuator_coulomb", "friction.actuator_viscous")}


def x_of(model: Model) -> np.ndarray:
    """x of a model (SI)."""
    I, fr = model.mandible_inertia, model.friction
    return np.array([model.mandible_mass, *(I[a, b] for a, b in INERTIA_ENTRIES), fr.hkp_coulomb, fr.hkp_viscous,
                     fr.actuator_arm * fr.actuator_coulomb, fr.actuator_viscous])


def inertia_matrix(x) -> list:
    """The 3x3 inertia (rows of entries of x, symbolic or numeric)."""
    xx, yy, zz, xy, xz, yz = (x[k] for k in range(1, 7))
    return [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]


def p_entries() -> dict[int, object]:
    """Entry of p -> a function of x giving it: the model's p with x in place. The arm R takes rho = R mu_c and the
    Coulomb coefficient 1, since only their product enters the torques."""
    at = _P_INDEX
    entries = {at["mandible_mass"]: lambda x: x[0]}
    for r in range(3):
        for c in range(3):
            entries[at["mandible_inertia[1][1]"] + 3 * r + c] = lambda x, r=r, c=c: inertia_matrix(x)[r][c]
    entries[at["friction.hkp_coulomb"]] = lambda x: x[7]
    entries[at["friction.hkp_viscous"]] = lambda x: x[8]
    entries[at["friction.actuator_arm"]] = lambda x: x[9]
    entries[at["friction.actuator_coulomb"]] = lambda x: 1.0
    entries[at["friction.actuator_viscous"]] = lambda x: x[10]
    return entries


def p_with(model: Model, x: np.ndarray) -> np.ndarray:
    """The model's p with the parameters x in place (:func:`p_entries`)."""
    p = np.array(model.vector())
    for k, f in p_entries().items():
        p[k] = f(x)
    return p


# ------------------------------------------------------------------------------------------ phi <-> x

_L_ENTRIES = ((0, 0), (1, 0), (1, 1), (2, 0), (2, 1), (2, 2))


def _inertia_of_factor(L: np.ndarray) -> np.ndarray:
    S = L @ L.T
    return np.trace(S) * np.eye(3) - S


def phi_of(x: np.ndarray) -> np.ndarray:
    """phi of physical parameters x (the inertia must be physical: Sigma positive definite)."""
    I = np.array(inertia_matrix(x), dtype=float)
    L = np.linalg.cholesky(0.5 * np.trace(I) * np.eye(3) - I)
    return np.concatenate([[x[0]], [L[a, b] for a, b in _L_ENTRIES], x[7:]])


def x_of_phi(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x of phi and the Jacobian dx/dphi (N_X, N_X)."""
    L = np.zeros((3, 3))
    for k, (a, b) in enumerate(_L_ENTRIES):
        L[a, b] = phi[1 + k]
    I = _inertia_of_factor(L)
    x = np.concatenate([[phi[0]], [I[a, b] for a, b in INERTIA_ENTRIES], phi[7:]])
    J = np.eye(N_X)
    J[INERTIA, INERTIA] = 0.0
    for k, (a, b) in enumerate(_L_ENTRIES):
        E = np.zeros((3, 3))
        E[a, b] = 1.0
        dS = E @ L.T + L @ E.T  # Sigma = L L' is bilinear in L
        dI = np.trace(dS) * np.eye(3) - dS
        J[INERTIA, 1 + k] = [dI[r, c] for r, c in INERTIA_ENTRIES]
    return x, J


def phi_bounds(phi0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of phi: friction >= 0; the mass and the diagonal of L at least 1e-4 of their start
    (a body lighter or thinner than that is not a mandible, and strictly inside, the loader's checks hold)."""
    lo = np.full(N_X, -np.inf)
    lo[0] = 1e-4 * phi0[0]
    for k, (a, b) in enumerate(_L_ENTRIES):
        if a == b:
            lo[1 + k] = 1e-4 * phi0[1 + k]
    lo[7:] = 0.0
    return lo, np.full(N_X, np.inf)
