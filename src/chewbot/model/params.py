"""Parameter files: the schema of a robot's TOML file and the loader that turns it into a :class:`Model`.

A parameter file keeps the papers' units, written at the end of every key (``G_mm``, ``mass_g``,
``inertia_g_mm2`` ...). The loader validates it with pydantic (unknown and missing keys, shapes, signs),
checks the physics (rotations, positive masses, positive-definite inertia, lengths that agree with the
printed coordinates) and converts everything to SI. Every error names the file and the key.

Overrides (``chewbot run --set KEY=VALUE``, ``load_model(..., overrides=...)``) change single numbers of a
parsed file before it is validated; the values that follow from them are kept consistent by the rules of
docs/models.md (:func:`apply_overrides`).
"""

from __future__ import annotations

import copy
import math
import re
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal, get_args

import numpy as np
from pydantic import AfterValidator, BaseModel, Field, field_validator

from chewbot.config import Plausible, Strict, key_error, read_text, unknown_key, validate
from chewbot.errors import ParameterError
from chewbot.model.model import Contact, Drive, Friction, HKPGeometry, Limits, Model, Uncertainty
from chewbot.units import factor

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
Six3 = Annotated[list[Vec3], Field(min_length=6, max_length=6)]
Six = Annotated[list[float], Field(min_length=6, max_length=6)]
Range = Annotated[list[float], Field(min_length=2, max_length=2)]
PositiveSix = Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=6, max_length=6)]  # one per chain

# Plausible ranges (config.Plausible): wide enough for any robot of a head's size, narrow enough that a value in
# another unit (m for mm, kg for g, kg m^2 for g mm^2) falls outside.
POSITION = Plausible(-1000.0, 1000.0, "mm", "points of a head-sized robot (within a metre of {S})")
LINK = Plausible(1.0, 1000.0, "mm", "links of a head-sized robot")
COEFFICIENT = Plausible(0.0, 2.0, "1", "Coulomb coefficients of machine contacts")


def _not_nan(value: float) -> float:
    if math.isnan(value):
        raise ValueError("must be a number or +/-inf, not nan")
    return value


# Limits that may be unbounded: +/-inf allowed (TOML writes them inf, -inf), NaN refused.
MaybeInfinite = Annotated[float, Field(allow_inf_nan=True), AfterValidator(_not_nan)]


class ChainsSection(Strict):
    G_mm: Annotated[Six3, POSITION]
    S0_mm: Annotated[Six3, POSITION]
    M_mm: Annotated[Six3, POSITION]
    crank_length_mm: Annotated[PositiveSix, LINK]
    coupler_length_mm: Annotated[PositiveSix, LINK]
    R_C0: Annotated[list[Mat3], Field(min_length=6, max_length=6)]


class CranksSection(Strict):
    inertia_g_mm2: Annotated[PositiveSix, Plausible(1.0, 1e9, "g*mm^2", "axial inertias of cranks")]
    mass_g: Annotated[PositiveSix, Plausible(0.5, 1e4, "g", "masses of cranks")]


class CouplersSection(Strict):
    # up to 10, not 0.025 (tungsten): the papers' printed 7.8 g/mm^3 (the as-printed models) is kept loadable
    density_g_per_mm3: Annotated[float, Field(gt=0), Plausible(1e-4, 10.0, "g/mm^3", "densities of solids (and the papers' printed 7.8)")]
    area_mm2: Annotated[float, Field(gt=0), Plausible(0.1, 1e4, "mm^2", "cross-sections of couplers")]


class MandibleSection(Strict):
    mass_g: Annotated[float, Field(gt=0), Plausible(10.0, 1e4, "g", "masses of a mandible")]
    # the diagonal's magnitude: a negative moment is left to the positive-definiteness check, which names it better
    inertia_g_mm2: Annotated[Mat3, Plausible(100.0, 1e10, "g*mm^2", "moments of inertia of a mandible", diagonal=True)]


class HKPSection(Strict):
    p1: float
    p2_mm: Annotated[float, POSITION]
    x_range_mm: Annotated[Range, POSITION]
    y_left_mm: Annotated[Range, POSITION]
    y_right_mm: Annotated[Range, POSITION]
    T_L_mm: Annotated[Vec3, POSITION]
    T_R_mm: Annotated[Vec3, POSITION]

    @field_validator("x_range_mm", "y_left_mm", "y_right_mm")
    @classmethod
    def _ordered(cls, v: list[float]) -> list[float]:
        return _interval(v)


def _interval(v: list[float]) -> list[float]:
    if not v[0] < v[1]:  # false for NaN as well
        raise ValueError(f"[{v[0]}, {v[1]}] is not an interval [low, high] with low < high")
    return v


class PointsSection(Strict):
    incisor_mm: Annotated[Vec3, POSITION]
    molar_left_mm: Annotated[Vec3, POSITION]
    molar_right_mm: Annotated[Vec3, POSITION]


class FrictionSection(Strict):
    hkp_coulomb: Annotated[float, Field(ge=0), COEFFICIENT]
    hkp_viscous_Ns_per_m: Annotated[float, Field(ge=0), Plausible(0.0, 1e4, "N*s/m", "viscous coefficients of a condyle's joint")]
    actuator_arm_mm: Annotated[float, Field(ge=0), Plausible(0.0, 100.0, "mm", "friction arms of bearings")]
    actuator_coulomb: Annotated[float, Field(ge=0), COEFFICIENT]
    actuator_viscous_Nms_per_rad: Annotated[float, Field(ge=0), Plausible(0.0, 100.0, "N*m*s/rad", "viscous coefficients of actuators")]


class LimitsSection(Strict):
    torque_Nm: Annotated[float, Field(gt=0), Plausible(1e-4, 1000.0, "N*m", "actuator torques (micro motors to a head-sized robot's)")]
    power_W: Annotated[float, Field(gt=0), Plausible(1e-3, 1e5, "W", "actuator powers")]
    axial_load_N: Annotated[float, Field(gt=0), Plausible(0.1, 1e5, "N", "bearing loads")]
    radial_load_N: Annotated[float, Field(gt=0), Plausible(0.1, 1e5, "N", "bearing loads")]
    # optional: the crank angle range, speed and acceleration limits; unbounded when absent
    theta_range_deg: Annotated[list[MaybeInfinite], Field(min_length=2, max_length=2)] = [-math.inf, math.inf]
    speed_rad_per_s: Annotated[MaybeInfinite, Field(gt=0), Plausible(0.01, 1e4, "rad/s", "crank speeds")] = math.inf
    acceleration_rad_per_s2: Annotated[MaybeInfinite, Field(gt=0), Plausible(0.1, 1e6, "rad/s^2", "crank accelerations")] = math.inf

    @field_validator("theta_range_deg")
    @classmethod
    def _ordered(cls, v: list[float]) -> list[float]:
        return _interval(v)


class ContactSection(Strict):
    preload_N: Annotated[float, Field(ge=0), Plausible(0.0, 1000.0, "N", "condyle preloads")] = 0.0


def _whole(value: float) -> float:
    if value != round(value):
        raise ValueError(f"{value:g} is not a whole number of counts")
    return value


class DriveSection(Strict):
    """Each crank's drive train (all six alike): a DC motor on a gearhead, with an encoder at the motor."""

    rotor_inertia_g_mm2: Annotated[float, Field(ge=0), Plausible(1.0, 1e6, "g*mm^2", "rotors of DC motors (0.01 to 10000 g cm^2)")]
    gear_ratio: Annotated[float, Field(gt=0), Plausible(1.0, 1000.0, "1", "gearheads' reductions")]
    # above 0.11 the loss law's motor torque is a monotone function of the crank torque (docs/models.md)
    gear_efficiency: Annotated[float, Field(ge=0.2, le=1.0), Plausible(0.3, 1.0, "1", "gearboxes' efficiencies")]
    torque_constant_mNm_per_A: Annotated[float, Field(gt=0), Plausible(1.0, 1000.0, "mN*m/A", "DC motors' torque constants")]
    encoder_counts_per_rev: Annotated[float, Field(gt=0), AfterValidator(_whole), Plausible(4.0, 1e7, "1", "incremental encoders' counts per revolution")]


class UncertaintySection(Strict):
    """How well the identified values are known (``chewbot identify`` writes it): ``keys``, parameter-file keys with
    1-based entries; ``standard_error``, one per key in that key's unit; ``correlation``, their correlation matrix
    (1); optionally the torque error the model leaves, ``torque_error_Nm`` (its standard deviation per actuator)
    with ``torque_error_correlation`` (6 x 6, 1)."""

    keys: list[str] = Field(min_length=1)
    standard_error: list[Annotated[float, Field(ge=0)]]
    correlation: list[list[float]]
    torque_error_Nm: Annotated[list[Annotated[float, Field(ge=0)]], Field(min_length=6, max_length=6)] | None = None
    torque_error_correlation: Annotated[list[Six], Field(min_length=6, max_length=6)] | None = None


class ParameterFile(Strict):
    """The whole TOML file, as written (papers' units)."""

    DOCS = "docs/models.md"

    schema_: Literal[1] = Field(alias="schema")
    name: str = Field(min_length=1)
    mechanism: Literal["target", "6rss"]
    description: str = ""
    gravity_m_per_s2: Annotated[float, Field(gt=0), Plausible(0.1, 100.0, "m/s^2", "gravities a robot works in")]
    assumed: list[str] = []
    identified: list[str] = []  # keys estimated from robot logs (chewbot identify); none of them is also assumed
    chains: ChainsSection
    cranks: CranksSection
    couplers: CouplersSection
    mandible: MandibleSection
    hkp: HKPSection
    points: PointsSection
    friction: FrictionSection
    limits: LimitsSection
    contact: ContactSection = ContactSection()
    drive: DriveSection | None = None
    uncertainty: UncertaintySection | None = None


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


def load_model(name_or_path: str | Path = "target", overrides: dict[str, float] | None = None) -> Model:
    """Load a built-in model by name or a parameter file by path, validated and converted to SI.

    ``overrides``: parameter-file keys (file units, 1-based indices, e.g. ``{"chains.crank_length_mm[3]": 12.0}``)
    applied by :func:`apply_overrides` before validation; the model records them (``Model.overrides``).
    """
    path = resolve_model_path(name_or_path)
    raw = read_parameter_file(path)
    sha256 = raw.pop("__sha256__")
    if overrides:
        return model_from_dict(apply_overrides(raw, overrides), source=str(path), sha256=sha256,
                               label=f"{path} (with {_set_arguments(overrides)})", overrides=overrides)
    return model_from_dict(raw, source=str(path), sha256=sha256)


def read_parameter_file(path: Path) -> dict:
    """The parsed TOML of a parameter file (not validated), with its SHA-256 under ``"__sha256__"``."""
    text = read_text(path, "parameter file", ParameterError)
    return {**text.data, "__sha256__": text.sha256}


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


def model_from_dict(raw: dict, source: str = "<dict>", sha256: str = "", label: str | None = None,
                    overrides: dict[str, float] | None = None) -> Model:
    """Validate a parsed parameter file (papers' units) and build the SI :class:`Model`.

    ``label`` names the input in error messages (default ``source``); ``overrides`` are recorded on the model.
    """
    label = label or source
    f = validate(ParameterFile, raw, label, ParameterError)

    def fail(key: str, reason: str) -> None:
        raise key_error(label, key, reason, ParameterError)

    mm, g_mm2 = factor("mm"), factor("g*mm^2")
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

    I_EE = np.array(f.mandible.inertia_g_mm2) * g_mm2
    if np.abs(I_EE - I_EE.T).max() > 1e-12 * np.abs(I_EE).max():
        fail("mandible.inertia_g_mm2", "not symmetric")
    eig = np.linalg.eigvalsh(I_EE)
    if eig.min() <= 0:
        fail("mandible.inertia_g_mm2", f"not positive definite (eigenvalues {np.round(eig / g_mm2, 3).tolist()} g mm^2)")
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
    for list_name in ("assumed", "identified"):
        for key in getattr(f, list_name):
            if key not in known:
                fail(list_name, f"{key!r} is not a key of this file")
    for key in sorted(set(f.assumed) & set(f.identified)):
        fail("identified", f"{key!r} is listed as assumed too: an identified value is no longer assumed")
    for key in sorted({k for k in f.identified if f.identified.count(k) > 1}):
        fail("identified", f"{key!r} is listed twice")

    uncertainty = None if f.uncertainty is None else _uncertainty(f.uncertainty, fail)
    density = f.couplers.density_g_per_mm3 * factor("g/mm^3")
    area = f.couplers.area_mm2 * factor("mm^2")
    fr, lim = f.friction, f.limits
    return Model(
        name=f.name,
        mechanism=f.mechanism,
        description=f.description,
        source=source,
        sha256=sha256,
        assumed=tuple(f.assumed),
        identified=tuple(f.identified),
        g=f.gravity_m_per_s2,
        G=G,
        S0=S0,
        M=M,
        crank_length=Lc,
        coupler_length=Lr,
        R_C0=R_C0,
        crank_inertia=np.array(f.cranks.inertia_g_mm2) * g_mm2,
        crank_mass=np.array(f.cranks.mass_g) * factor("g"),
        coupler_density=density,
        coupler_area=area,
        coupler_mass=density * area * Lr,
        mandible_mass=f.mandible.mass_g * factor("g"),
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
        limits=Limits(torque=lim.torque_Nm, power=lim.power_W, axial_load=lim.axial_load_N, radial_load=lim.radial_load_N,
                      theta_range=np.array(lim.theta_range_deg) * factor("deg"), speed=lim.speed_rad_per_s,
                      acceleration=lim.acceleration_rad_per_s2),
        contact=Contact(preload=f.contact.preload_N),
        overrides=dict(overrides or {}),
        drive=None if f.drive is None else Drive(
            rotor_inertia=f.drive.rotor_inertia_g_mm2 * g_mm2,
            gear_ratio=f.drive.gear_ratio,
            efficiency=f.drive.gear_efficiency,
            torque_constant=f.drive.torque_constant_mNm_per_A * factor("mN*m/A"),
            encoder_counts=f.drive.encoder_counts_per_rev,
        ),
        uncertainty=uncertainty,
    )


# A correlation matrix as written (10 significant digits) is symmetric, has a unit diagonal and is positive
# semidefinite to this tolerance.
CORRELATION_TOLERANCE = 1e-8


def _correlation(C: list[list[float]], k: int, key: str, fail) -> np.ndarray:
    """A k x k correlation matrix, checked (symmetric, unit diagonal, entries in [-1, 1], positive semidefinite)."""
    if len(C) != k or any(len(row) != k for row in C):
        fail(key, f"must be {k} x {k} (one row and column per key), not {len(C)} rows of {[len(r) for r in C]}")
    R = np.array(C, dtype=float)
    if not np.isfinite(R).all():
        fail(key, "must be finite numbers")
    if np.abs(R - R.T).max() > CORRELATION_TOLERANCE:
        fail(key, "not symmetric")
    if np.abs(np.diag(R) - 1).max() > CORRELATION_TOLERANCE:
        fail(key, "its diagonal must be 1 (a key's correlation with itself)")
    if np.abs(R).max() > 1 + CORRELATION_TOLERANCE:
        fail(key, "a correlation lies in [-1, 1]")
    if np.linalg.eigvalsh((R + R.T) / 2).min() < -CORRELATION_TOLERANCE * k:
        fail(key, "not positive semidefinite: no covariance has these correlations")
    return (R + R.T) / 2


def _uncertainty(u: UncertaintySection, fail) -> Uncertainty:
    """The SI :class:`Uncertainty` of a file's [uncertainty] (errors name the key and entry)."""
    from chewbot.model.vector import file_key_entries

    k = len(u.keys)
    if len(u.standard_error) != k:
        fail("uncertainty.standard_error", f"has {len(u.standard_error)} entries for {k} keys: one per key")
    entries, scales = [], []
    for i, key in enumerate(u.keys):
        try:
            e, scale = file_key_entries(key)
        except KeyError:
            fail(f"uncertainty.keys[{i + 1}]", f"{key!r} is not a numeric key of the parameter file (write section.key, "
                 "with 1-based [i] for array entries, e.g. cranks.inertia_g_mm2[3])")
        if e in entries:
            fail(f"uncertainty.keys[{i + 1}]", f"{key!r} is listed twice")
        entries.append(e)
        scales.append(scale)
    if not all(math.isfinite(v) for v in u.standard_error):
        fail("uncertainty.standard_error", "must be finite numbers")
    R = _correlation(u.correlation, k, "uncertainty.correlation", fail)
    se = np.array(u.standard_error) * np.array(scales)
    torque = None
    if (u.torque_error_Nm is None) != (u.torque_error_correlation is None):
        fail("uncertainty.torque_error_Nm", "comes with uncertainty.torque_error_correlation: give both or neither")
    if u.torque_error_Nm is not None:
        sd = np.array(u.torque_error_Nm, dtype=float)
        if not np.isfinite(sd).all():
            fail("uncertainty.torque_error_Nm", "must be finite numbers")
        torque = sd[:, None] * _correlation(u.torque_error_correlation, 6, "uncertainty.torque_error_correlation", fail) * sd
    return Uncertainty(tuple(u.keys), tuple(entries), se[:, None] * R * se, torque)


# ------------------------------------------------------------------------------------------ overrides

_KEY = re.compile(r"^(?P<path>[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)?)(?P<index>(\[\s*-?\d+\s*\])*)$")
# Per chain, the keys whose change moves the chain's geometry, and the lengths that follow from it.
_CHAIN_POINTS = ("G_mm", "S0_mm", "M_mm")


def parse_override(argument: str, option: str = "--set") -> tuple[str, float]:
    """``"KEY=VALUE"`` (a ``--set`` argument; ``option`` names the option in errors) -> (KEY, float VALUE); a
    ParameterError names the argument. NaN and infinities are refused: no key of chewbot takes them from the command
    line (a limit the file leaves out is already unbounded)."""
    key, sep, value = argument.partition("=")
    key, value = key.strip(), value.strip()
    if not sep or not key:
        raise ParameterError(f"{option} {argument!r}: expected KEY=VALUE, e.g. --set friction.hkp_coulomb=0.2")
    try:
        number = float(value)
    except ValueError:
        raise ParameterError(f"{option} {argument}: {value!r} is not a number") from None
    if not math.isfinite(number):
        raise ParameterError(f"{option} {argument}: {value!r} is not a finite number (NaN and infinities are not values of {key})")
    return key, number


def split_overrides(overrides: dict[str, float]) -> tuple[dict[str, float], dict[str, float]]:
    """(the model's overrides, the default task's overrides without their ``task.`` prefix)."""
    model = {k: v for k, v in overrides.items() if not k.startswith("task.")}
    task = {k.removeprefix("task."): v for k, v in overrides.items() if k.startswith("task.")}
    return model, task


def _set_arguments(overrides: dict[str, float]) -> str:
    return ", ".join(f"--set {k}={v:g}" for k, v in overrides.items())


def _numeric_keys() -> dict[str, object]:
    """Every numeric key of the schema ("section.key" or a top-level key) with its default (None: required)."""
    out = {}
    for name, info in ParameterFile.model_fields.items():
        ann = next((a for a in get_args(info.annotation) if a is not type(None)), info.annotation)  # an optional section's
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            for sub, sub_info in ann.model_fields.items():
                out[f"{name}.{sub}"] = None if sub_info.is_required() else sub_info.default
        elif name == "gravity_m_per_s2":
            out[name] = None
    return out


def _locate(raw: dict, key: str, argument: str):
    """(container, leaf name, indices) of ``key`` in the parsed file ``raw``; errors name ``argument``."""
    m = _KEY.match(key.replace(" ", ""))
    known = _numeric_keys()
    if m is None:
        raise ParameterError(f"{argument}: {key!r} is not a key (write section.key, with 1-based [i] for array entries)")
    path = m.group("path")
    if path not in known:
        reason = unknown_key(path, known, docs="docs/models.md").removeprefix("unknown key")
        raise ParameterError(f"{argument}: unknown key {path!r}{reason}; --set takes the numeric keys of the parameter file")
    indices = [int(i) for i in re.findall(r"-?\d+", m.group("index"))]
    *sections, leaf = path.split(".")
    container = raw
    for section in sections:
        container = container.setdefault(section, {})
        if not isinstance(container, dict):
            raise ParameterError(f"{argument}: {section!r} is not a section of the file")
    if leaf not in container:
        if known[path] is None:
            raise ParameterError(f"{argument}: key {path!r} is missing from the file")
        container[leaf] = copy.deepcopy(known[path])  # an optional key the file leaves out: start from its default
    value = container[leaf]
    shape = []
    probe = value
    while isinstance(probe, list):
        shape.append(len(probe))
        probe = probe[0] if probe else None
    if len(indices) != len(shape):
        what = "a number" if not shape else f"an array of shape {'x'.join(map(str, shape))}"
        raise ParameterError(f"{argument}: {path} is {what}: give {len(shape)} index(es) (1-based), e.g. "
                             f"{path}{''.join('[1]' for _ in shape)}")
    for depth, (i, n) in enumerate(zip(indices, shape)):
        if not 1 <= i <= n:
            raise ParameterError(f"{argument}: index {i} of {path} is out of range: it has {n} entries at level {depth + 1} (1-based)")
    return container, leaf, [i - 1 for i in indices]


def _put(container: dict, leaf: str, indices: list[int], value: float) -> None:
    if not indices:
        container[leaf] = value
        return
    target = container[leaf]
    for i in indices[:-1]:
        target = target[i]
    target[indices[-1]] = value


def apply_overrides(raw: dict, overrides: dict[str, float]) -> dict:
    """A copy of the parsed parameter file ``raw`` (papers' units) with ``overrides`` applied and the values that
    follow from them kept consistent (docs/models.md):

    * chains.G_mm, chains.S0_mm of chain i: the crank stays perpendicular to its shaft (the shaft axis, third
      column of R_C0,i, is kept): moving G_i along the shaft moves S0_i with it, moving S0_i along the shaft
      moves G_i with it; the crank length is the distance of S0_i from G_i across the shaft, the first two columns
      of R_C0,i the new crank direction and shaft x crank;
    * chains.crank_length_mm[i] moves S0_i along its crank; chains.coupler_length_mm[i] moves M_i along the
      coupler; otherwise the coupler length follows, |M_i - S0_i| (also when M_i moves). A chain touched by an
      override closes exactly at home: S0_i is rewritten as G_i + L_c,i times the crank direction of R_C0,i;
    * hkp.T_L_mm sets hkp.T_R_mm (its mirror in y); the condyles stay on their plane at home: hkp.p1,
      hkp.p2_mm or hkp.T_L_mm[1] move the condyles' z onto it, hkp.T_L_mm[3] moves the plane (p2);
    * an off-diagonal entry of mandible.inertia_g_mm2 sets its symmetric entry too.

    The result is validated by :func:`model_from_dict` like a file. Errors name the ``--set`` argument. Cheap
    (no graph is built): a sweep calls it once per parameter set.
    """
    before = raw
    raw = copy.deepcopy(raw)
    raw.pop("__sha256__", None)
    given: dict[str, list] = {}  # path -> list of indices set
    for key, value in overrides.items():
        argument = f"--set {key}={value:g}"
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ParameterError(f"{argument}: the value must be a number, not {type(value).__name__}")
        container, leaf, indices = _locate(raw, key, argument)
        path = _KEY.match(key.replace(" ", "")).group("path")
        if path == "hkp.T_R_mm":
            raise ParameterError(f"{argument}: hkp.T_R_mm mirrors hkp.T_L_mm (the parasitic motions assume left-right "
                                 "symmetry): set hkp.T_L_mm instead")
        _put(container, leaf, indices, float(value))
        if path == "mandible.inertia_g_mm2" and indices[0] != indices[1]:
            _put(container, leaf, indices[::-1], float(value))
        given.setdefault(path, []).append(indices)
    _chains_follow(raw, before, given)
    _hkp_follows(raw, given)
    return raw


def _chains_follow(raw: dict, before: dict, given: dict[str, list]) -> None:
    """The chain rules of :func:`apply_overrides` on ``raw`` (overridden); ``before``: the file as read.

    A chain touched by an override is written so that it closes exactly at home: S0_i = G_i + L_c,i x_i with x_i
    the crank direction of R_C0,i (the printed coordinates agree with the lengths and matrices to 4 digits only).
    """
    def chains(key: str) -> set[int]:
        return {idx[0] for idx in given.get(f"chains.{key}", [])}

    if not any(path.startswith("chains.") for path in given):
        return
    try:
        ch = raw["chains"]
        G, S0, M = (np.array(ch[k], dtype=float).reshape(6, 3) for k in _CHAIN_POINTS)
        G_before, S0_before = (np.array(before["chains"][k], dtype=float).reshape(6, 3) for k in ("G_mm", "S0_mm"))
        Lc, Lr = (np.array(ch[k], dtype=float).reshape(6) for k in ("crank_length_mm", "coupler_length_mm"))
        R = np.array([_nearest_rotation(r) for r in np.array(ch["R_C0"], dtype=float).reshape(6, 3, 3)])
    except (KeyError, ValueError, TypeError, np.linalg.LinAlgError):
        return  # a malformed chains section: validation reports it, naming the key
    touched = chains("G_mm") | chains("S0_mm") | chains("M_mm") | chains("crank_length_mm") | chains("coupler_length_mm")
    for i in sorted(chains("G_mm") | chains("S0_mm")):
        z = R[i][:, 2]  # the shaft, kept
        if i not in chains("S0_mm"):
            S0[i] += np.dot(G[i] - G_before[i], z) * z
        if i not in chains("G_mm"):
            G[i] += np.dot(S0[i] - S0_before[i], z) * z
        arm = S0[i] - G[i]
        arm -= np.dot(arm, z) * z  # the crank's plane through G_i
        Lc[i] = np.linalg.norm(arm)
        if Lc[i] > 0:
            R[i] = np.column_stack([arm / Lc[i], np.cross(z, arm / Lc[i]), z])
    for i in sorted(touched):
        S0[i] = G[i] + Lc[i] * R[i][:, 0]
        if i in chains("coupler_length_mm"):
            rod = M[i] - S0[i]
            M[i] = S0[i] + Lr[i] * rod / np.linalg.norm(rod)
        else:
            Lr[i] = np.linalg.norm(M[i] - S0[i])
    rotations = np.array(ch["R_C0"], dtype=float).reshape(6, 3, 3)
    for i in sorted(chains("G_mm") | chains("S0_mm")):
        if i not in chains("R_C0"):
            rotations[i] = R[i]
    ch.update(G_mm=G.tolist(), S0_mm=S0.tolist(), M_mm=M.tolist(), crank_length_mm=Lc.tolist(),
              coupler_length_mm=Lr.tolist(), R_C0=rotations.tolist())


def _hkp_follows(raw: dict, given: dict[str, list]) -> None:
    """The condyle rules of :func:`apply_overrides`: T_R mirrors T_L, both on the plane at home."""
    if not any(path.startswith("hkp.") for path in given):
        return
    h = raw.get("hkp")
    try:
        p1, p2 = float(h["p1"]), float(h["p2_mm"])
        T = [float(v) for v in h["T_L_mm"]]
        assert len(T) == 3
    except (KeyError, ValueError, TypeError, AssertionError):
        return
    z_given = [2] in given.get("hkp.T_L_mm", [])
    if z_given and "hkp.p2_mm" not in given:
        p2 = -(p1 * T[0] + T[2])  # the plane moves to the condyle
    elif not z_given and ("hkp.p1" in given or "hkp.p2_mm" in given or [0] in given.get("hkp.T_L_mm", [])):
        T[2] = -(p1 * T[0] + p2)  # the condyle moves onto the plane
    h.update(p2_mm=p2, T_L_mm=T, T_R_mm=[T[0], -T[1], T[2]])
