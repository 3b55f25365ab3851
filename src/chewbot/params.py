"""Parameter files: the schema of a robot's TOML file and the loader that turns it into a :class:`Model`.

A parameter file keeps the papers' units, written at the end of every key (``G_mm``, ``mass_g``,
``inertia_g_mm2`` ...). The loader validates it with pydantic (unknown and missing keys, shapes, signs),
checks the physics (rotations, positive masses, positive-definite inertia, lengths that agree with the
printed coordinates) and converts everything to SI. Every error names the file and the key.
"""

from __future__ import annotations

import hashlib
import tomllib
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from chewbot.errors import ParameterError
from chewbot.model import Friction, HKPGeometry, Limits, Model

BUILTIN_MODELS = ("target", "6rss", "target-as-printed", "6rss-as-printed")

# How far the printed geometry may disagree with the nominal lengths before a file is rejected. The papers'
# own numbers disagree by up to 0.07 % (docs/conventions.md); 1 % catches a typo without tripping on rounding.
LENGTH_TOLERANCE = 0.01
# The condyles must lie on their planes at the home pose; this allows for coordinates rounded to 0.01 mm.
HOME_PLANE_TOLERANCE_MM = 0.01
# Printed rotation matrices are rounded to 4 digits: |R^T R - I| is about 1e-4 for them.
ROTATION_TOLERANCE = 2e-3

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Mat3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]
Six = Annotated[list[float], Field(min_length=6, max_length=6)]
Six3 = Annotated[list[Vec3], Field(min_length=6, max_length=6)]
Range = Annotated[list[float], Field(min_length=2, max_length=2)]


class _Strict(BaseModel):
    # strict: a quoted number is an error, not silently converted; no NaN or infinity anywhere
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


class ChainsSection(_Strict):
    G_mm: Six3
    S0_mm: Six3
    M_mm: Six3
    crank_length_mm: Six
    coupler_length_mm: Six
    R_C0: Annotated[list[Mat3], Field(min_length=6, max_length=6)]

    @field_validator("crank_length_mm", "coupler_length_mm")
    @classmethod
    def _positive(cls, v: list[float]) -> list[float]:
        return _all_positive(v)


def _all_positive(v: list[float]) -> list[float]:
    for i, x in enumerate(v):
        if not x > 0:
            raise ValueError(f"entry {i + 1} (chain {i + 1}) is {x}: must be positive")
    return v


class CranksSection(_Strict):
    inertia_g_mm2: Six
    mass_g: Six

    @field_validator("inertia_g_mm2", "mass_g")
    @classmethod
    def _positive(cls, v: list[float]) -> list[float]:
        return _all_positive(v)


class CouplersSection(_Strict):
    density_g_per_mm3: float = Field(gt=0)
    area_mm2: float = Field(gt=0)


class MandibleSection(_Strict):
    mass_g: float = Field(gt=0)
    inertia_g_mm2: Mat3


class HKPSection(_Strict):
    p1: float
    p2_mm: float
    x_range_mm: Range
    y_left_mm: Range
    y_right_mm: Range
    T_L_mm: Vec3
    T_R_mm: Vec3

    @field_validator("x_range_mm", "y_left_mm", "y_right_mm")
    @classmethod
    def _ordered(cls, v: list[float]) -> list[float]:
        if not v[0] < v[1]:
            raise ValueError(f"[{v[0]}, {v[1]}] is not an interval [low, high] with low < high")
        return v


class PointsSection(_Strict):
    incisor_mm: Vec3
    molar_left_mm: Vec3
    molar_right_mm: Vec3


class FrictionSection(_Strict):
    hkp_coulomb: float = Field(ge=0)
    hkp_viscous_Ns_per_m: float = Field(ge=0)
    actuator_arm_mm: float = Field(ge=0)
    actuator_coulomb: float = Field(ge=0)
    actuator_viscous_Nms_per_rad: float = Field(ge=0)


class LimitsSection(_Strict):
    torque_Nm: float = Field(gt=0)
    power_W: float = Field(gt=0)
    axial_load_N: float = Field(gt=0)
    radial_load_N: float = Field(gt=0)


class ParameterFile(_Strict):
    """The whole TOML file, as written (papers' units)."""

    schema_: Literal[1] = Field(alias="schema")
    name: str = Field(min_length=1)
    mechanism: Literal["target", "6rss"]
    description: str = ""
    gravity_m_per_s2: float = Field(gt=0)
    assumed: list[str] = []
    chains: ChainsSection
    cranks: CranksSection
    couplers: CouplersSection
    mandible: MandibleSection
    hkp: HKPSection
    points: PointsSection
    friction: FrictionSection
    limits: LimitsSection


def builtin_model_path(name: str) -> Path:
    """Path of a built-in parameter file (``target``, ``6rss``, ``target-as-printed``, ``6rss-as-printed``)."""
    if name not in BUILTIN_MODELS:
        raise ParameterError(f"unknown built-in model {name!r}; choose one of {', '.join(BUILTIN_MODELS)} or give a .toml file")
    return Path(str(resources.files("chewbot") / "models" / f"{name}.toml"))


def resolve_model_path(name_or_path: str | Path) -> Path:
    """A built-in model's name, or a path to a TOML file."""
    s = str(name_or_path)
    if s in BUILTIN_MODELS:
        return builtin_model_path(s)
    p = Path(s)
    if p.suffix.lower() != ".toml" and not p.exists():
        raise ParameterError(f"unknown model {s!r}: not a built-in model ({', '.join(BUILTIN_MODELS)}) and no such file")
    return p


def load_model(name_or_path: str | Path = "target") -> Model:
    """Load a built-in model by name or a parameter file by path, validated and converted to SI."""
    path = resolve_model_path(name_or_path)
    try:
        raw_bytes = path.read_bytes()
    except FileNotFoundError:
        raise ParameterError(f"{path}: no such parameter file") from None
    except OSError as exc:
        raise ParameterError(f"{path}: cannot read ({exc.strerror})") from None
    try:
        raw = tomllib.loads(raw_bytes.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ParameterError(f"{path}: not valid TOML ({exc})") from None
    return model_from_dict(raw, source=str(path), sha256=hashlib.sha256(raw_bytes).hexdigest())


def _format_validation_error(source: str, exc: ValidationError) -> str:
    lines = []
    for err in exc.errors():
        key = ""
        for part in err["loc"]:  # list positions 1-based, as chains and rows are counted everywhere else
            key += f"[{part + 1}]" if isinstance(part, int) else (f".{part}" if key else str(part))
        key = key or "(top level)"
        if err["type"] == "missing":
            reason = "missing key"
        elif err["type"] == "extra_forbidden":
            reason = "unknown key"
        else:
            reason = err["msg"].removeprefix("Value error, ")
        lines.append(f"{source}: key '{key}': {reason}")
    return "\n".join(lines)


def _nearest_rotation(a: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(a)
    return u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt


def _known_keys(f: ParameterFile) -> set[str]:
    keys = set()
    for section, value in f:
        if isinstance(value, BaseModel):
            keys |= {f"{section}.{k}" for k in type(value).model_fields}
        else:
            keys.add(section)
    return keys


def model_from_dict(raw: dict, source: str = "<dict>", sha256: str = "") -> Model:
    """Validate a parsed parameter file (papers' units) and build the SI :class:`Model`."""
    try:
        f = ParameterFile.model_validate(raw)
    except ValidationError as exc:
        raise ParameterError(_format_validation_error(source, exc)) from None

    def fail(key: str, reason: str) -> None:
        raise ParameterError(f"{source}: key '{key}': {reason}")

    mm = 1e-3
    ch = f.chains
    R_C0 = np.array(ch.R_C0, dtype=float)
    for i, r in enumerate(R_C0):
        dev = np.abs(r.T @ r - np.eye(3)).max()
        if dev > ROTATION_TOLERANCE or np.linalg.det(r) <= 0:
            fail(f"chains.R_C0[{i + 1}]", f"not a rotation matrix (max |R^T R - I| = {dev:.3g}, det = {np.linalg.det(r):.4g})")
    R_C0 = np.array([_nearest_rotation(r) for r in R_C0])

    G = np.array(ch.G_mm) * mm
    S0 = np.array(ch.S0_mm) * mm
    M = np.array(ch.M_mm) * mm
    Lc = np.array(ch.crank_length_mm) * mm
    Lr = np.array(ch.coupler_length_mm) * mm
    for i in range(6):
        printed = np.linalg.norm(S0[i] - G[i])
        if abs(printed - Lc[i]) > LENGTH_TOLERANCE * Lc[i]:
            fail(f"chains.crank_length_mm[{i + 1}]", f"{Lc[i] / mm:g} mm disagrees with |G S0| = {printed / mm:.4g} mm from chains.G_mm and chains.S0_mm")
        direction = (S0[i] - G[i]) / printed
        if np.linalg.norm(direction - R_C0[i][:, 0]) > 10 * LENGTH_TOLERANCE:
            fail(f"chains.R_C0[{i + 1}]", "first column is not the crank direction S0 - G at theta = 0")
        printed = np.linalg.norm(M[i] - S0[i])  # {M} = {S} at home
        if abs(printed - Lr[i]) > LENGTH_TOLERANCE * Lr[i]:
            fail(f"chains.coupler_length_mm[{i + 1}]", f"{Lr[i] / mm:g} mm disagrees with |S0 M| = {printed / mm:.4g} mm at home from chains.S0_mm and chains.M_mm")

    I_EE = np.array(f.mandible.inertia_g_mm2) * 1e-9  # g mm^2 -> kg m^2
    if np.abs(I_EE - I_EE.T).max() > 1e-12 * np.abs(I_EE).max():
        fail("mandible.inertia_g_mm2", "not symmetric")
    eig = np.linalg.eigvalsh(I_EE)
    if eig.min() <= 0:
        fail("mandible.inertia_g_mm2", f"not positive definite (eigenvalues {np.round(eig * 1e9, 3).tolist()} g mm^2)")
    if eig.max() > eig.sum() - eig.max() + 1e-12 * eig.max():
        fail("mandible.inertia_g_mm2", "principal moments violate the triangle inequality: no rigid body has them")

    h = f.hkp
    if abs(h.T_L_mm[0] - h.T_R_mm[0]) > 1e-9 or abs(h.T_L_mm[2] - h.T_R_mm[2]) > 1e-9 or abs(h.T_L_mm[1] + h.T_R_mm[1]) > 1e-9:
        fail("hkp.T_R_mm", "must mirror hkp.T_L_mm in y (x and z equal, y opposite): the parasitic motions assume left-right symmetry")
    if not h.T_L_mm[1] > 0:
        fail("hkp.T_L_mm", "the left condyle has y > 0")
    # {M} = {S} at home (docs/conventions.md): the home pose must satisfy the HKPs, the condyles on their planes in their sockets
    for key, T, y_range in (("hkp.T_L_mm", h.T_L_mm, h.y_left_mm), ("hkp.T_R_mm", h.T_R_mm, h.y_right_mm)):
        residual = h.p1 * T[0] + T[2] + h.p2_mm
        if abs(residual) > HOME_PLANE_TOLERANCE_MM:
            fail(key, f"the condyle is {residual:.4g} mm off its plane p1 x + z + p2 = 0 at the home pose ({{M}} = {{S}}); "
                      f"its z should be {-(h.p1 * T[0] + h.p2_mm):.6g} mm")
        if not (h.x_range_mm[0] <= T[0] <= h.x_range_mm[1] and y_range[0] <= T[1] <= y_range[1]):
            fail(key, f"the condyle ({T[0]:g}, {T[1]:g}) mm is outside its socket at the home pose "
                      f"(x in {h.x_range_mm}, y in {y_range} mm)")

    known = _known_keys(f)
    for key in f.assumed:
        if key not in known:
            fail("assumed", f"{key!r} is not a key of this file")

    density = f.couplers.density_g_per_mm3 * 1e-3 / mm**3  # g/mm^3 -> kg/m^3
    area = f.couplers.area_mm2 * mm**2
    fr, lim = f.friction, f.limits
    return Model(
        name=f.name,
        mechanism=f.mechanism,
        description=f.description,
        source=source,
        sha256=sha256,
        assumed=tuple(f.assumed),
        g=f.gravity_m_per_s2,
        G=G,
        S0=S0,
        M=M,
        crank_length=Lc,
        coupler_length=Lr,
        R_C0=R_C0,
        crank_inertia=np.array(f.cranks.inertia_g_mm2) * 1e-9,
        crank_mass=np.array(f.cranks.mass_g) * 1e-3,
        coupler_density=density,
        coupler_area=area,
        coupler_mass=density * area * Lr,
        mandible_mass=f.mandible.mass_g * 1e-3,
        mandible_inertia=I_EE,
        hkp=HKPGeometry(
            p1=h.p1,
            p2=h.p2_mm * mm,
            x_range=np.array(h.x_range_mm) * mm,
            y_left=np.array(h.y_left_mm) * mm,
            y_right=np.array(h.y_right_mm) * mm,
            T_L=np.array(h.T_L_mm) * mm,
            T_R=np.array(h.T_R_mm) * mm,
        ),
        incisor=np.array(f.points.incisor_mm) * mm,
        molar_left=np.array(f.points.molar_left_mm) * mm,
        molar_right=np.array(f.points.molar_right_mm) * mm,
        friction=Friction(
            hkp_coulomb=fr.hkp_coulomb,
            hkp_viscous=fr.hkp_viscous_Ns_per_m,
            actuator_arm=fr.actuator_arm_mm * mm,
            actuator_coulomb=fr.actuator_coulomb,
            actuator_viscous=fr.actuator_viscous_Nms_per_rad,
        ),
        limits=Limits(torque=lim.torque_Nm, power=lim.power_W, axial_load=lim.axial_load_N, radial_load=lim.radial_load_N),
    )
