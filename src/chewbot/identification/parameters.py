"""The parameters a log can identify, their place in the model's vector p, and a physical parametrisation.

The physical parameters x (SI) are the rows of :data:`PARAMETERS`, one table: the mandible's mass m; its inertia about
O_M in {M}, I_xx, I_yy, I_zz, I_xy, I_xz, I_yz; each crank's total axial inertia J_1 .. J_6 (everything that turns
with the shaft: the crank's own, and a drive's rotor reflected through its gearbox once the model has one: the
torques identify their sum only); the HKP Coulomb coefficient mu_H and viscous coefficient c_H; the product
rho = R mu_c of the actuators' friction arm and Coulomb coefficient (the only way they enter the torques); the
actuators' viscous coefficient c_A. Each friction coefficient is one number shared by the six actuators or the
two contacts, as in the parameter file. The first moment of the mandible is not a parameter: {M} is at its
mass centre by the model's convention (docs/identification.md). The mass is the weighed one by default
(``given``): it is the scale the torques are measured in once a drive's torque constant is estimated too (gravity on
the known mass fixes the currents' scale; with the mass free too, every parameter and 1/k_t scale together).

The estimator works in ``phi``, a parametrisation in which every value within simple bounds is a physical body:
m > 0, the crank inertias > 0, and the mandible's inertia through the Cholesky factor L of its second moment of
mass about O_M, Sigma = integral of r r' dm = L L' (lower triangular, positive diagonal), I = trace(Sigma) 1 - Sigma.
Sigma positive definite is exactly the condition that I is positive definite and its principal moments satisfy
the strict triangle inequality (the pseudo-inertia of a body with its frame at the mass centre). The friction
entries of phi are those of x, bounded below by 0; the efficiency is at most 1 (a gearbox gives no power).
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
    """One entry of x: its name, the parameter-file key it is written to (with 1-based entries for arrays), its SI
    unit, the file's unit, the file key it belongs to (``group``, what ``--fix`` names),
    the entry of p it sets (``p_key``, a name of :func:`chewbot.model.vector.parameter_index`), what combination of
    the robot's properties the torques identify (``combination``), its lower bound in phi as a fraction of its start
    (``floor``: None where it may be any real, 0 for a coefficient that may vanish), its upper bound in phi (``ceiling``,
    SI; None: none), ``given``: why it is held at the file's value unless freed (``--free``), empty where it is
    estimated by default, and ``drive``: True for the drive's numbers, which only a log of currents identifies."""

    name: str
    key: str
    unit: str
    file_unit: str
    group: str
    p_key: str
    combination: str
    floor: float | None = 0.0
    given: str = ""
    ceiling: float | None = None
    drive: bool = False

    def in_file_units(self, value):
        """``value`` (SI) in the file's unit."""
        return value / factor(self.file_unit)


_INERTIA_COMBINATION = "the mandible's inertia about its mass centre O_M, in {M}"
_CRANK_COMBINATION = ("everything that turns with shaft {i}: the crank's axial inertia (cranks.inertia_g_mm2[{i}]) "
                      "plus, with a drive, its rotor's J_r N^2; the torques identify the sum only")
PARAMETERS: tuple[Parameter, ...] = (
    Parameter("m", "mandible.mass_g", "kg", "g", "mandible.mass_g", "mandible_mass", "the mandible's mass",
              floor=1e-4, given="the weighed mass: the model file's"),
    *(Parameter(f"I_{'xyz'[a]}{'xyz'[b]}", f"mandible.inertia_g_mm2[{a + 1}][{b + 1}]", "kg*m^2", "g*mm^2",
                "mandible.inertia_g_mm2", f"mandible_inertia[{a + 1}][{b + 1}]", _INERTIA_COMBINATION, floor=None)
      for a, b in INERTIA_ENTRIES),
    *(Parameter(f"J_{i}", f"cranks.inertia_g_mm2[{i}]", "kg*m^2", "g*mm^2", "cranks.inertia_g_mm2",
                f"crank_inertia[{i}]", _CRANK_COMBINATION.format(i=i), floor=1e-4) for i in range(1, 7)),
    Parameter("mu_H", "friction.hkp_coulomb", "1", "1", "friction.hkp_coulomb", "friction.hkp_coulomb",
              "the HKPs' Coulomb coefficient (both condyles)"),
    Parameter("c_H", "friction.hkp_viscous_Ns_per_m", "N*s/m", "N*s/m", "friction.hkp_viscous_Ns_per_m",
              "friction.hkp_viscous", "the HKPs' viscous coefficient (both condyles)"),
    Parameter("R*mu_c", "friction.actuator_arm_mm*friction.actuator_coulomb", "m", "mm", "friction.actuator_coulomb",
              "friction.actuator_arm", "the actuators' friction arm times their Coulomb coefficient (the six actuators); "
              "written back as mu_c with the file's arm"),
    Parameter("c_A", "friction.actuator_viscous_Nms_per_rad", "N*m*s/rad", "N*m*s/rad",
              "friction.actuator_viscous_Nms_per_rad", "friction.actuator_viscous",
              "the actuators' viscous coefficient (the six actuators)"),
    Parameter("k_t", "drive.torque_constant_mNm_per_A", "N*m/A", "mN*m/A", "drive.torque_constant_mNm_per_A",
              "drive.torque_constant", "the motors' torque constant (the six alike), the scale of the currents: fixed by "
              "gravity on the weighed mandible mass", floor=1e-2, drive=True),
    Parameter("eta", "drive.gear_efficiency", "1", "1", "drive.gear_efficiency", "drive.efficiency",
              "the gearboxes' efficiency (the six alike): the ratio of the torques driving (eta N k_t i) to back-driven "
              "(N k_t i / eta)", floor=0.2, ceiling=1.0, drive=True),
)
N_X = len(PARAMETERS)
NAMES = tuple(p.name for p in PARAMETERS)
INDEX = {name: j for j, name in enumerate(NAMES)}
# The keys a user may hold at the file's value (--fix) or free (--free): each is one group of x.
GROUPS = tuple(dict.fromkeys(p.group for p in PARAMETERS))


def group_entries(group: str) -> np.ndarray:
    """The entries of x that belong to the file key ``group``."""
    return np.array([j for j, p in enumerate(PARAMETERS) if p.group == group])


def _block(group: str) -> slice:
    j = group_entries(group)
    return slice(int(j[0]), int(j[-1]) + 1)


INERTIA = _block("mandible.inertia_g_mm2")
CRANKS = _block("cranks.inertia_g_mm2")
HKP = tuple(group_entries("friction.hkp_coulomb")) + tuple(group_entries("friction.hkp_viscous_Ns_per_m"))  # none on the 6RSS
K_T, ETA = INDEX["k_t"], INDEX["eta"]
DRIVE = np.array([K_T, ETA])  # the entries a log of currents identifies (their order: the measured torques' derivatives)
_P_INDEX = {p.name: parameter_index(p.p_key) for p in PARAMETERS}
_COULOMB = parameter_index("friction.actuator_coulomb")


def x_of(model: Model) -> np.ndarray:
    """x of a model (SI): each row's entry of the model's p (the product R mu_c for the actuators' Coulomb row)."""
    p = model.vector()
    x = np.array([p[_P_INDEX[name]] for name in NAMES])
    x[INDEX["R*mu_c"]] *= p[_COULOMB]
    return x


def inertia_matrix(x) -> list:
    """The 3x3 inertia (rows of entries of x, symbolic or numeric)."""
    xx, yy, zz, xy, xz, yz = (x[k] for k in range(INERTIA.start, INERTIA.stop))
    return [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]


def p_entries() -> dict[int, object]:
    """Entry of p -> a function of x giving it: the model's p with x in place. Each row sets its own entry; the
    inertia's off-diagonal rows set both symmetric entries; the arm R takes rho = R mu_c and the Coulomb
    coefficient 1, since only their product enters the torques."""
    entries = {_P_INDEX[p.name]: (lambda x, j=j: x[j]) for j, p in enumerate(PARAMETERS)}
    at = parameter_index("mandible_inertia[1][1]")
    for r in range(3):
        for c in range(3):
            entries[at + 3 * r + c] = lambda x, r=r, c=c: inertia_matrix(x)[r][c]
    entries[_COULOMB] = lambda x: 1.0
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
    """phi of physical parameters x (the inertia must be physical: Sigma positive definite): x with the inertia's
    entries replaced by those of the Cholesky factor."""
    I = np.array(inertia_matrix(x), dtype=float)
    L = np.linalg.cholesky(0.5 * np.trace(I) * np.eye(3) - I)
    phi = np.array(x, dtype=float)
    phi[INERTIA] = [L[a, b] for a, b in _L_ENTRIES]
    return phi


def x_of_phi(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x of phi and the Jacobian dx/dphi (N_X, N_X)."""
    L = np.zeros((3, 3))
    for k, (a, b) in enumerate(_L_ENTRIES):
        L[a, b] = phi[INERTIA.start + k]
    I = _inertia_of_factor(L)
    x = np.array(phi, dtype=float)
    x[INERTIA] = [I[a, b] for a, b in INERTIA_ENTRIES]
    J = np.eye(N_X)
    J[INERTIA, INERTIA] = 0.0
    for k, (a, b) in enumerate(_L_ENTRIES):
        E = np.zeros((3, 3))
        E[a, b] = 1.0
        dS = E @ L.T + L @ E.T  # Sigma = L L' is bilinear in L
        dI = np.trace(dS) * np.eye(3) - dS
        J[INERTIA, INERTIA.start + k] = [dI[r, c] for r, c in INERTIA_ENTRIES]
    return x, J


def phi_bounds(phi0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of phi: each row's ``floor`` times its start (friction >= 0; the mass and the crank
    inertias at least 1e-4 of their start: a body lighter than that is not the robot's, and strictly inside, the
    loader's checks hold; the torque constant at least 1e-2 of its start, the efficiency at least 0.2 of it, where the
    loss law's inverse stays monotonic); the diagonal of L at least 1e-4 of its start, its other entries free; above,
    each row's ``ceiling`` (the efficiency's 1)."""
    lo = np.array([-np.inf if p.floor is None else p.floor * phi0[j] for j, p in enumerate(PARAMETERS)])
    for k, (a, b) in enumerate(_L_ENTRIES):
        if a == b:
            lo[INERTIA.start + k] = 1e-4 * phi0[INERTIA.start + k]
    return lo, np.array([np.inf if p.ceiling is None else p.ceiling for p in PARAMETERS])
