"""The model's numbers as one vector ``p``: the fixed layout every kernel takes as its last input.

The CasADi graphs are built once per mechanism with the model's numbers as a symbol ``p`` (n_p entries, SI
units, laid out as :data:`BLOCKS` says), so one compiled kernel serves every model of a mechanism: a new
parameter set costs an evaluation, not a graph build or a compilation. :meth:`chewbot.model.Model.vector`
gives a model's ``p``; :class:`SymbolicModel` is its symbolic counterpart, whose attributes mirror
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

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import GRAPH_LOCK
from chewbot.model.model import MechanismMixin

MM, G_MM2 = 1e-3, 1e-9  # mm -> m, g mm^2 -> kg m^2


@dataclass(frozen=True)
class Block:
    """One named part of ``p``: the model attribute ``name`` (dotted for sub-objects), its shape and SI unit,
    the parameter-file key it comes from and the factor to SI (file value * ``scale``), or ``key = None`` for
    a derived block."""

    name: str
    shape: tuple[int, ...]
    unit: str
    key: str | None
    scale: float
    description: str

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=int))


BLOCKS: tuple[Block, ...] = (
    Block("g", (), "m/s^2", "gravity_m_per_s2", 1.0, "gravity, along -Z_S"),
    Block("G", (6, 3), "m", "chains.G_mm", MM, "crank pivots G_i in {S}"),
    Block("M", (6, 3), "m", "chains.M_mm", MM, "coupler ends M_i in {M}"),
    Block("R_C0", (6, 3, 3), "1", "chains.R_C0", 1.0, "actuator frames at theta = 0 (nearest rotation to the file's)"),
    Block("crank_length", (6,), "m", "chains.crank_length_mm", MM, "abs(G_i S_i)"),
    Block("coupler_length", (6,), "m", "chains.coupler_length_mm", MM, "abs(S_i M_i)"),
    Block("branch", (6,), "1", None, 1.0, "working branch of the closed-form inverse kinematics (+1/-1), from the home pose"),
    Block("crank_inertia", (6,), "kg*m^2", "cranks.inertia_g_mm2", G_MM2, "axial inertia of crank i about its shaft"),
    Block("crank_mass", (6,), "kg", "cranks.mass_g", 1e-3, "mass of crank i (centre at G_i)"),
    Block("coupler_mass", (6,), "kg", None, 1.0, "rho A L_i: couplers.density_g_per_mm3 x couplers.area_mm2 x coupler length"),
    Block("mandible_mass", (), "kg", "mandible.mass_g", 1e-3, "m_EE"),
    Block("mandible_inertia", (3, 3), "kg*m^2", "mandible.inertia_g_mm2", G_MM2, "inertia about O_M in {M}"),
    Block("hkp.p1", (), "1", "hkp.p1", 1.0, "plane p1 x + z + p2 = 0 of the condyles"),
    Block("hkp.p2", (), "m", "hkp.p2_mm", MM, "plane p1 x + z + p2 = 0 of the condyles"),
    Block("hkp.T_L", (3,), "m", "hkp.T_L_mm", MM, "left condyle centre in {M} (T_R is its mirror in y)"),
    Block("hkp.x_range", (2,), "m", "hkp.x_range_mm", MM, "sockets' x bounds in {S}"),
    Block("hkp.y_left", (2,), "m", "hkp.y_left_mm", MM, "left socket's y bounds in {S}"),
    Block("hkp.y_right", (2,), "m", "hkp.y_right_mm", MM, "right socket's y bounds in {S}"),
    Block("incisor", (3,), "m", "points.incisor_mm", MM, "incisor point I in {M}"),
    Block("molar_left", (3,), "m", "points.molar_left_mm", MM, "left bite point B_L in {M}"),
    Block("molar_right", (3,), "m", "points.molar_right_mm", MM, "right bite point B_R in {M}"),
    Block("friction.hkp_coulomb", (), "1", "friction.hkp_coulomb", 1.0, "Coulomb coefficient at the HKPs"),
    Block("friction.hkp_viscous", (), "N*s/m", "friction.hkp_viscous_Ns_per_m", 1.0, "viscous coefficient at the HKPs"),
    Block("friction.actuator_arm", (), "m", "friction.actuator_arm_mm", MM, "friction arm R_i of the actuators"),
    Block("friction.actuator_coulomb", (), "1", "friction.actuator_coulomb", 1.0, "Coulomb coefficient of the actuators"),
    Block("friction.actuator_viscous", (), "N*m*s/rad", "friction.actuator_viscous_Nms_per_rad", 1.0, "viscous coefficient of the actuators"),
    Block("limits.torque", (), "N*m", "limits.torque_Nm", 1.0, "actuator torque limit"),
    Block("limits.power", (), "W", "limits.power_W", 1.0, "actuator power limit"),
    Block("limits.axial_load", (), "N", "limits.axial_load_N", 1.0, "bearing load along the shaft at G_i"),
    Block("limits.radial_load", (), "N", "limits.radial_load_N", 1.0, "bearing load across the shaft at G_i"),
    Block("limits.theta_range", (2,), "rad", "limits.theta_range_deg", np.pi / 180, "crank angle range [low, high] (default unbounded)"),
    Block("limits.speed", (), "rad/s", "limits.speed_rad_per_s", 1.0, "crank speed limit (default unbounded)"),
    Block("contact.preload", (), "N", "contact.preload_N", 1.0, "smallest normal force of a unilateral HKP contact"),
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


def model_vector(model) -> np.ndarray:
    """p of ``model`` (read-only): every block of :data:`BLOCKS` in SI, in order."""
    from chewbot.kinematics.ik import branches

    p = np.empty(N_P)
    for b in BLOCKS:
        if b.name == "branch":
            value = branches(model)
        else:
            value = model
            for part in b.name.split("."):
                value = getattr(value, part)
        p[block_slice(b.name)] = np.ravel(np.asarray(value, dtype=float))
    p.setflags(write=False)
    return p


def vector_digest(model) -> str:
    """SHA-256 of a model's p (float64 bytes): identifies the numbers a run used."""
    return hashlib.sha256(np.ascontiguousarray(model.vector(), dtype="<f8").tobytes()).hexdigest()


class _Group:
    """Attributes of a sub-object (hkp, friction, limits, contact) of :class:`SymbolicModel`."""


class SymbolicModel(MechanismMixin):
    """The model's numbers as CasADi expressions: slices of ``p``, with the attributes and shapes of
    :class:`~chewbot.model.Model` as a graph builder uses them.

    Vectors are columns (``crank_length``: 6x1, ``hkp.T_L``: 3x1); ``G``, ``M`` are lists of six 3x1 columns and
    ``R_C0`` a list of six 3x3 matrices (so ``R_C0[i][:, 2]`` is shaft i); ``hkp.T_R`` mirrors ``hkp.T_L`` in y
    and ``hkp.normal`` is the planes' unit normal. ``p`` is a symbol (``SymbolicModel(mechanism)``: the graph
    takes the parameters as an input) or constants (``SymbolicModel.of(model)``: the model's numbers folded in).
    """

    def __init__(self, mechanism: str, p: ca.SX | None = None):
        if mechanism not in ("target", "6rss"):
            raise ValueError(f"mechanism must be 'target' or '6rss', not {mechanism!r}")
        self.mechanism = mechanism
        self.p = ca.SX.sym("p", N_P) if p is None else p
        if self.p.numel() != N_P:
            raise ValueError(f"p has {self.p.numel()} entries, the layout {N_P}")
        for b in BLOCKS:
            owner = self
            *groups, leaf = b.name.split(".")
            for g in groups:
                if not hasattr(owner, g):
                    setattr(owner, g, _Group())
                owner = getattr(owner, g)
            setattr(owner, leaf, self._view(b))
        T_L = self.hkp.T_L
        self.hkp.T_R = ca.vertcat(T_L[0], -T_L[1], T_L[2])
        self.hkp.normal = ca.vertcat(self.hkp.p1, 0, 1) / ca.sqrt(self.hkp.p1**2 + 1)

    @classmethod
    def of(cls, model) -> SymbolicModel:
        """The numbers of ``model`` as constants: graphs built on it have them folded in (no input p)."""
        return cls(model.mechanism, ca.SX(ca.DM(model.vector())))

    def _view(self, b: Block):
        x = self.p[block_slice(b.name)]
        if b.shape in ((), (1,)):
            return x[0]
        if len(b.shape) == 1:
            return x
        if b.shape == (3, 3):
            return ca.reshape(x, 3, 3).T  # row-major in p, column-major in CasADi
        rows = b.shape[0]
        width = b.size // rows
        parts = [x[i * width:(i + 1) * width] for i in range(rows)]
        return [ca.reshape(part, 3, 3).T for part in parts] if len(b.shape) == 3 else parts


def symbols(model_or_mechanism) -> SymbolicModel:
    """The parameters a graph is built on: a mechanism's name gives the symbol p (parametric graph), a
    :class:`~chewbot.model.Model` its numbers as constants (folded graph)."""
    if isinstance(model_or_mechanism, str):
        return SymbolicModel(model_or_mechanism)
    return SymbolicModel.of(model_or_mechanism)


def c_name(mechanism: str) -> str:
    """The mechanism's name in C identifiers: ``target``, ``sixrss``."""
    return mechanism.replace("6rss", "sixrss")


def mechanism_of(model_or_mechanism) -> str:
    """``"target"`` or ``"6rss"`` of a model or a mechanism's name."""
    return model_or_mechanism if isinstance(model_or_mechanism, str) else model_or_mechanism.mechanism


_GRAPHS: dict[tuple, object] = {}


def cached_graph(model_or_mechanism, key, build):
    """``build()`` once per mechanism (a parametric graph, kept for the process) or once per model (a folded
    graph, kept on the model)."""
    with GRAPH_LOCK:
        if not isinstance(model_or_mechanism, str):
            return model_or_mechanism.cached(("graph", key), build)
        k = (model_or_mechanism, key)
        if k not in _GRAPHS:
            _GRAPHS[k] = build()
        return _GRAPHS[k]


def graph_key(model_or_mechanism, *parts) -> tuple:
    """The key of a kernel (:class:`chewbot.compiled.kernels.KernelSpec`): the mechanism and ``parts``, and for a
    model (numbers folded in) the digest of its p."""
    if isinstance(model_or_mechanism, str):
        return (model_or_mechanism, *parts)
    return (model_or_mechanism.mechanism, *parts, ("p", vector_digest(model_or_mechanism)))


def parameter_input(params: SymbolicModel) -> tuple[list, list[str]]:
    """The inputs a graph built on ``params`` adds last: ``([p], ["p"])`` for the symbol p, none for a model's
    constants."""
    return ([params.p], ["p"]) if params.p.is_symbolic() else ([], [])
