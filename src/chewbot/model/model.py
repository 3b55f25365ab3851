"""The robot model: everything about a mechanism that never changes, in SI units, immutable.

Build one with :func:`chewbot.load_model` (``"target"``, ``"6rss"``, their ``-as-printed`` variants, or a
TOML file). Arrays are read-only; a model is hashable by identity and safe to share.

| field | shape | unit | meaning |
|---|---|---|---|
| ``G`` | (6, 3) | m | crank pivots G_i in {S} |
| ``S0`` | (6, 3) | m | crank tips S_i at theta = 0 as printed (checks only) |
| ``M`` | (6, 3) | m | coupler ends M_i in {M} |
| ``crank_length`` | (6,) | m | abs(G_i S_i) |
| ``coupler_length`` | (6,) | m | abs(S_i M_i) |
| ``R_C0`` | (6, 3, 3) | - | actuator frames at theta = 0 (column 1: crank, column 3: shaft) |
| ``crank_inertia`` | (6,) | kg m^2 | axial inertia of crank i about its shaft |
| ``crank_mass`` | (6,) | kg | mass of crank i (centre at G_i) |
| ``coupler_mass`` | (6,) | kg | rho A L_i of coupler i |
| ``mandible_mass`` | () | kg | m_EE |
| ``mandible_inertia`` | (3, 3) | kg m^2 | inertia about O_M in {M} |
| ``incisor``, ``molar_left``, ``molar_right`` | (3,) | m | points I, B_L, B_R in {M} |
| ``g`` | () | m/s^2 | gravity, along -Z_S |
| ``hkp`` | | | the HKP planes, sockets and condyle centres (:class:`HKPGeometry`) |
| ``friction``, ``limits``, ``contact`` | | | :class:`Friction`, :class:`Limits`, :class:`Contact` |
| ``drive`` | | | :class:`Drive` (each crank's motor and gearhead), or None: no drive (the torques act on the cranks) |
| ``uncertainty`` | | | the covariance of identified values and of the torque error (:class:`Uncertainty`), or None |

:meth:`Model.vector` gives the numbers the CasADi graphs take as their input ``p``, in the fixed layout of
:mod:`chewbot.model.vector`. The model holds nothing else: what is built from it (graphs, compiled kernels) is kept in
the kernel cache (:mod:`chewbot.compiled.cache`), keyed by the digest of its numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from chewbot.model.vector import model_vector


def _freeze(obj) -> None:
    for f in fields(obj):
        if not f.init:
            continue
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray):
            v = np.array(v, dtype=float)
            v.setflags(write=False)
            object.__setattr__(obj, f.name, v)


@dataclass(frozen=True, eq=False)
class HKPGeometry:
    """The two higher kinematic pairs: condyle centres T_L, T_R (in {M}) on the plane p1 x + z + p2 = 0.

    ``x_range``, ``y_left``, ``y_right`` bound the sockets in {S} (m).
    """

    p1: float
    p2: float
    x_range: np.ndarray
    y_left: np.ndarray
    y_right: np.ndarray
    T_L: np.ndarray
    T_R: np.ndarray

    def __post_init__(self):
        _freeze(self)

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the plane, pointing up (positive z)."""
        n = np.array([self.p1, 0.0, 1.0])
        return n / np.linalg.norm(n)


@dataclass(frozen=True, eq=False)
class Friction:
    """Coulomb + viscous friction coefficients (seed 001): HKPs and actuators. SI units."""

    hkp_coulomb: float  # -
    hkp_viscous: float  # N s/m
    actuator_arm: float  # m
    actuator_coulomb: float  # -
    actuator_viscous: float  # N m s/rad


@dataclass(frozen=True, eq=False)
class Limits:
    """Actuator limits (seed 001, Sect. 4.5), SI units; ``theta_range``, ``speed`` and ``acceleration`` are
    unbounded (-inf, inf and inf) unless the parameter file gives them."""

    torque: float  # N m
    power: float  # W
    axial_load: float  # N, along the shaft, at G_i
    radial_load: float  # N, across the shaft, at G_i
    theta_range: np.ndarray = field(default_factory=lambda: np.array([-np.inf, np.inf]))  # rad, crank angle [low, high]
    speed: float = np.inf  # rad/s, crank speed abs(theta_dot)
    acceleration: float = np.inf  # rad/s^2, crank acceleration abs(theta_ddot)

    def __post_init__(self):
        _freeze(self)


@dataclass(frozen=True, eq=False)
class Contact:
    """The HKP contact: ``preload`` (N) is the smallest normal force a unilateral contact model admits."""

    preload: float = 0.0


@dataclass(frozen=True)
class Drive:
    """The drive train of each of the six cranks (all alike): a DC motor on a gearhead. SI units.

    ``rotor_inertia`` (kg m^2) is the rotor's at the motor shaft, ``gear_ratio`` N motor turns per crank turn,
    ``efficiency`` the gearbox's (the loss law of :mod:`chewbot.model.drive`), ``torque_constant`` (N m/A) the motor's,
    ``encoder_counts`` the counts per motor revolution after quadrature. The rotor is seen at the crank as
    :attr:`reflected_inertia` J_r N^2."""

    rotor_inertia: float  # kg m^2, at the motor
    gear_ratio: float  # 1
    efficiency: float  # 1
    torque_constant: float  # N m / A
    encoder_counts: float  # counts per motor revolution

    @property
    def reflected_inertia(self) -> float:
        """J_r N^2 (kg m^2): the rotor's inertia seen at the crank."""
        return self.rotor_inertia * self.gear_ratio**2


@dataclass(frozen=True, eq=False)
class Uncertainty:
    """How well a calibrated model is known (the file's ``[uncertainty]``, written by ``chewbot identify``).

    ``keys``: parameter-file keys (1-based entries, e.g. ``cranks.inertia_g_mm2[3]``); ``entries``: the entries of
    p each one sets (two for an off-diagonal entry of the mandible's inertia); ``cov`` (k, k): their covariance in
    SI (the units of p); ``torque_cov`` (6, 6) N^2 m^2: the covariance of the torque error the model leaves (the
    torque sensors' noise and what the model does not explain, from the identification's residuals), or None."""

    keys: tuple[str, ...]
    entries: tuple[tuple[int, ...], ...]
    cov: np.ndarray
    torque_cov: np.ndarray | None = None

    def __post_init__(self):
        _freeze(self)

    def directions(self, n_p: int) -> np.ndarray:
        """(n_p, k): the change of p per unit (SI) change of each key."""
        D = np.zeros((n_p, len(self.keys)))
        for j, entries in enumerate(self.entries):
            D[list(entries), j] = 1.0
        return D


class MechanismMixin:
    """What follows from the mechanism's name, shared by :class:`Model` and its symbolic counterpart
    (:class:`chewbot.model.vector.SymbolicModel`)."""

    mechanism: str

    @property
    def has_hkp(self) -> bool:
        """True for the target robot: the two HKPs constrain the mandible."""
        return self.mechanism == "target"

    @property
    def dof(self) -> int:
        """Degrees of freedom: 4 for the target, 6 for the 6RSS."""
        return 4 if self.has_hkp else 6

    @property
    def crank_total_inertia(self):
        """Each crank's axial inertia with its drive's rotor reflected to it, I_i + J_r N^2 (kg m^2): what the dynamics
        accelerates (the crank's own inertia, ``crank_inertia``, without a drive)."""
        d = self.drive
        return self.crank_inertia if d is None else self.crank_inertia + d.rotor_inertia * d.gear_ratio**2

    def molar(self, side: str):
        """The bite point B in {M} for ``side`` = ``"left"`` or ``"right"``."""
        if side == "left":
            return self.molar_left
        if side == "right":
            return self.molar_right
        raise ValueError(f"side must be 'left' or 'right', not {side!r}")


@dataclass(frozen=True, eq=False)
class Model(MechanismMixin):
    """An immutable robot model in SI units (see the module docstring for the table of fields)."""

    name: str
    mechanism: str  # "target" or "6rss"
    description: str
    source: str
    sha256: str
    assumed: tuple[str, ...]
    g: float
    G: np.ndarray
    S0: np.ndarray
    M: np.ndarray
    crank_length: np.ndarray
    coupler_length: np.ndarray
    R_C0: np.ndarray
    crank_inertia: np.ndarray
    crank_mass: np.ndarray
    coupler_density: float
    coupler_area: float
    coupler_mass: np.ndarray
    mandible_mass: float
    mandible_inertia: np.ndarray
    hkp: HKPGeometry
    incisor: np.ndarray
    molar_left: np.ndarray
    molar_right: np.ndarray
    friction: Friction
    limits: Limits
    contact: Contact = field(default_factory=Contact)
    overrides: dict = field(default_factory=dict)  # the --set values applied to the file, as given
    identified: tuple[str, ...] = ()  # keys estimated from robot logs (the file's `identified`)
    drive: Drive | None = None  # the file's [drive]; None: no drive train
    uncertainty: Uncertainty | None = None  # the file's [uncertainty]: how well the identified values are known
    p: np.ndarray = field(init=False, repr=False)  # the parameter vector, derived from the fields above

    def __post_init__(self):
        _freeze(self)
        object.__setattr__(self, "p", model_vector(self))

    def vector(self) -> np.ndarray:
        """The model's numbers as one read-only vector (n_p,) in SI, the input ``p`` of every kernel
        (layout: :mod:`chewbot.model.vector`), computed when the model is made."""
        return self.p
