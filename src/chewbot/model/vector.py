"""The model's numbers as one vector ``p``: the fixed layout every kernel takes as its last input.

The CasADi graphs are built once per mechanism with the model's numbers as a symbol ``p`` (n_p entries, SI
units, laid out as :data:`BLOCKS` says), so one compiled kernel serves every model of a mechanism: a new
parameter set costs an evaluation, not a graph build or a compilation. :meth:`chewbot.model.Model.vector`
gives a model's ``p``; :class:`~chewbot.model.symbolic.SymbolicModel` is its symbolic counterpart, whose attributes mirror
:class:`~chewbot.model.Model` (``G[i]``, ``R_C0[i]``, ``crank_length[i]``, ``hkp.T_L``, ``friction.hkp_coulomb``
...) as slices of ``p``, so a graph builder reads like code written against a model.

Entries are named like the model's attributes with 1-based indices (``"G[3][1]"``: x of G_3, in m), or by
the parameter-file key they come from, in the file's units (``"chains.G_mm[3][1]"``): :func:`parameter_index`
takes either. Arrays are laid out row by row (C order). Derived entries (the working branch of each chain,
the coupler masses, T_R as the mirror of T_L) follow from the others as the loader computes them.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from functools import cache

import numpy as np

from chewbot.model.chains import working_branches
from chewbot.units import factor, key_unit


@dataclass(frozen=True)
class Block:
    """One named part of ``p``: the model attribute ``name`` (dotted for sub-objects), its shape and SI unit,
    the parameter-file key it comes from, or ``key = None`` for a derived block; ``absent``: its value for a model
    without the block's optional section (the drive's neutral entries, with which its law is the identity)."""

    name: str
    shape: tuple[int, ...]
    unit: str
    key: str | None
    description: str
    absent: float | None = None

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=int))

    @property
    def scale(self) -> float:
        """The factor to SI of the unit the block's key ends with (file value * ``scale``; 1 for a derived block
        or a key without a unit)."""
        unit = key_unit(self.key.rsplit(".", 1)[-1])[1] if self.key else None
        return factor(unit) if unit else 1.0


BLOCKS: tuple[Block, ...] = (
    Block("g", (), "m/s^2", "gravity_m_per_s2", "gravity, along -Z_S"),
    Block("G", (6, 3), "m", "chains.G_mm", "crank pivots G_i in {S}"),
    Block("M", (6, 3), "m", "chains.M_mm", "coupler ends M_i in {M}"),
    Block("R_C0", (6, 3, 3), "1", "chains.R_C0", "actuator frames at theta = 0 (nearest rotation to the file's)"),
    Block("crank_length", (6,), "m", "chains.crank_length_mm", "abs(G_i S_i)"),
    Block("coupler_length", (6,), "m", "chains.coupler_length_mm", "abs(S_i M_i)"),
    Block("branch", (6,), "1", None, "working branch of the closed-form inverse kinematics (+1/-1), from the home pose"),
    Block("crank_inertia", (6,), "kg*m^2", "cranks.inertia_g_mm2", "axial inertia of crank i about its shaft"),
    Block("crank_mass", (6,), "kg", "cranks.mass_g", "mass of crank i (centre at G_i)"),
    Block("coupler_mass", (6,), "kg", None, "rho A L_i: couplers.density_g_per_mm3 x couplers.area_mm2 x coupler length"),
    Block("mandible_mass", (), "kg", "mandible.mass_g", "m_EE"),
    Block("mandible_inertia", (3, 3), "kg*m^2", "mandible.inertia_g_mm2", "inertia about O_M in {M}"),
    Block("hkp.p1", (), "1", "hkp.p1", "plane p1 x + z + p2 = 0 of the condyles"),
    Block("hkp.p2", (), "m", "hkp.p2_mm", "plane p1 x + z + p2 = 0 of the condyles"),
    Block("hkp.T_L", (3,), "m", "hkp.T_L_mm", "left condyle centre in {M} (T_R is its mirror in y)"),
    Block("hkp.x_range", (2,), "m", "hkp.x_range_mm", "sockets' x bounds in {S}"),
    Block("hkp.y_left", (2,), "m", "hkp.y_left_mm", "left socket's y bounds in {S}"),
    Block("hkp.y_right", (2,), "m", "hkp.y_right_mm", "right socket's y bounds in {S}"),
    Block("incisor", (3,), "m", "points.incisor_mm", "incisor point I in {M}"),
    Block("molar_left", (3,), "m", "points.molar_left_mm", "left bite point B_L in {M}"),
    Block("molar_right", (3,), "m", "points.molar_right_mm", "right bite point B_R in {M}"),
    Block("friction.hkp_coulomb", (), "1", "friction.hkp_coulomb", "Coulomb coefficient at the HKPs"),
    Block("friction.hkp_viscous", (), "N*s/m", "friction.hkp_viscous_Ns_per_m", "viscous coefficient at the HKPs"),
    Block("friction.actuator_arm", (), "m", "friction.actuator_arm_mm", "friction arm R_i of the actuators"),
    Block("friction.actuator_coulomb", (), "1", "friction.actuator_coulomb", "Coulomb coefficient of the actuators"),
    Block("friction.actuator_viscous", (), "N*m*s/rad", "friction.actuator_viscous_Nms_per_rad", "viscous coefficient of the actuators"),
    Block("limits.torque", (), "N*m", "limits.torque_Nm", "actuator torque limit"),
    Block("limits.power", (), "W", "limits.power_W", "actuator power limit"),
    Block("limits.axial_load", (), "N", "limits.axial_load_N", "bearing load along the shaft at G_i"),
    Block("limits.radial_load", (), "N", "limits.radial_load_N", "bearing load across the shaft at G_i"),
    Block("limits.theta_range", (2,), "rad", "limits.theta_range_deg", "crank angle range [low, high] (default unbounded)"),
    Block("limits.speed", (), "rad/s", "limits.speed_rad_per_s", "crank speed limit"),
    Block("limits.acceleration", (), "rad/s^2", "limits.acceleration_rad_per_s2", "crank acceleration limit"),
    Block("contact.preload", (), "N", "contact.preload_N", "smallest normal force of a unilateral HKP contact"),
    # a model without a drive: no rotor, ratio 1, loss-free, 1 N m/A (the "current" is the crank torque), no encoder
    Block("drive.rotor_inertia", (), "kg*m^2", "drive.rotor_inertia_g_mm2", "each motor's rotor inertia at the motor", 0.0),
    Block("drive.gear_ratio", (), "1", "drive.gear_ratio", "motor turns per crank turn", 1.0),
    Block("drive.efficiency", (), "1", "drive.gear_efficiency", "gearbox efficiency of the loss law", 1.0),
    Block("drive.torque_constant", (), "N*m/A", "drive.torque_constant_mNm_per_A", "motor torque per ampere", 1.0),
    Block("drive.encoder_counts", (), "1", "drive.encoder_counts_per_rev", "encoder counts per motor revolution after quadrature", 0.0),
)

_OFFSETS = np.cumsum([0] + [b.size for b in BLOCKS])
N_P = int(_OFFSETS[-1])  # the number of entries of p
BLOCK = {b.name: b for b in BLOCKS}
START = {b.name: int(o) for b, o in zip(BLOCKS, _OFFSETS)}


def block_slice(name: str) -> slice:
    """The entries of p that hold the block ``name`` (e.g. ``"crank_length"``, ``"hkp.T_L"``)."""
    return slice(START[name], START[name] + BLOCK[name].size)


@cache
def parameter_names() -> tuple[tuple[str, str], ...]:
    """(name, SI unit) of every entry of p, in order: ``("G[1][1]", "m")``, ... (1-based indices)."""
    out = []
    for b in BLOCKS:
        for idx in np.ndindex(*b.shape):
            out.append((b.name + "".join(f"[{i + 1}]" for i in idx), b.unit))
    return tuple(out)


@cache
def _index() -> dict[str, int]:
    names = {name: k for k, (name, _) in enumerate(parameter_names())}
    for b in BLOCKS:
        if b.key is not None:
            for j, idx in enumerate(np.ndindex(*b.shape)):
                names[b.key + "".join(f"[{i + 1}]" for i in idx)] = START[b.name] + j
    return names


def parameter_index(key: str) -> int:
    """The entry of p named ``key``: a model attribute with 1-based indices (``"crank_length[3]"``,
    ``"G[2][1]"``, ``"friction.hkp_coulomb"``) or the parameter-file key it comes from (``"chains.crank_length_mm[3]"``,
    ``"chains.G_mm[2][1]"``); the entry holds the file's value times its block's ``scale`` (SI)."""
    k = _index().get(re.sub(r"\s+", "", key))
    if k is None:
        raise KeyError(f"{key!r} names no entry of the parameter vector (see chewbot.model.vector.parameter_names())")
    return k


# Blocks that hold a symmetric matrix: a file key of an off-diagonal entry sets both (as --set does).
SYMMETRIC = ("mandible_inertia",)


def file_key_entries(key: str) -> tuple[tuple[int, ...], float]:
    """The entries of p that the parameter-file key ``key`` (1-based indices, e.g. ``"cranks.inertia_g_mm2[3]"``)
    sets, and the factor from the file's unit to SI: one entry, or two for an off-diagonal entry of a symmetric
    block (:data:`SYMMETRIC`). A ``KeyError`` names a key that is no file key of p."""
    k = parameter_index(key)
    block = next((b for b in BLOCKS if b.key is not None and START[b.name] <= k < START[b.name] + b.size), None)
    if block is None or not re.sub(r"\s+", "", key).startswith(block.key):
        raise KeyError(f"{key!r} is not a key of the parameter file that sets a number of the model")
    entries = (k,)
    if block.name in SYMMETRIC:
        r, c = divmod(k - START[block.name], block.shape[1])
        if r != c:
            entries += (START[block.name] + c * block.shape[1] + r,)
    return entries, block.scale


def model_vector(model) -> np.ndarray:
    """p of ``model`` (read-only): every block of :data:`BLOCKS` in SI, in order."""
    p = np.empty(N_P)
    for b in BLOCKS:
        if b.name == "branch":
            value = working_branches(model)
        else:
            value = model
            for part in b.name.split("."):
                value = getattr(value, part)
                if value is None:  # an optional section the model has not: its neutral entry
                    value = b.absent
                    break
        p[block_slice(b.name)] = np.ravel(np.asarray(value, dtype=float))
    p.setflags(write=False)
    return p


def vector_digest(model) -> str:
    """SHA-256 of a model's p (float64 bytes): identifies the numbers a run used."""
    return hashlib.sha256(np.ascontiguousarray(model.vector(), dtype="<f8").tobytes()).hexdigest()
