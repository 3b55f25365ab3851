"""A food sample between flat teeth: its parameters (read from TOML), its force law and its state.

The law, one normal force along the gap (positive when the sample pushes the teeth apart) and a tangential friction:

* elastic force F_e(delta), delta >= 0 the compression (m):
  cylinder  F_e = E A delta / h0,  A = pi d^2 / 4 (uniaxial compression of a short cylinder, no barrelling);
  sphere    F_e = 4/3 E / (1 - nu^2) sqrt(R) (delta / 2)^1.5,  R = h0 / 2 (Hertz between two rigid flats: each
            contact takes delta / 2);
* broken: F_e is multiplied by ``stiffness_after_fracture`` once delta / h0 has reached ``fracture_strain`` (an
  event of the integrator; the state persists, as a crushed sample does not heal);
* Hunt–Crossley damping: F_d = b F_e (1 + 3/2 alpha d(delta)/dt), b = 1 or the factor after fracture;
* Maxwell branch (stress relaxation): a force F_m with dF_m/dt = rho d(b F_e)/dt - F_m / tau, rho = E_m / E (the
  branch's modulus over the equilibrium modulus). For the cylinder this is the standard linear solid; for the sphere
  the same hereditary integral on the Hertz force (quasi-linear viscoelasticity, Fung). Over a step in which b F_e
  changes linearly in time it is integrated exactly:
  F_m(t) = F_m(0) e^(-t/tau) + rho (b F_e(t) - b F_e(0)) (tau / t)(1 - e^(-t/tau));
* normal force in contact (delta > 0): F_n = max(F_d + F_m, -adhesion_N): a sample never pulls, except through its
  damping and relaxed Maxwell branch while unloading, and then at most ``adhesion_N``. Out of contact F_n = 0;
* the teeth meet at delta = h0: beyond it a stiff linear tooth contact :data:`TOOTH_STIFFNESS` acts besides the food;
* tangential friction of the sample on the upper tooth: F_t = -mu max(F_n, 0) v_t / sqrt(|v_t|^2 + eps^2), v_t the
  bite point's velocity in {S}'s x-y plane. This is the regularised Coulomb law of the plant's joints (below the
  speed :data:`FRICTION_SPEED` it acts as a stiff viscous damper, the regularised "stick"; above it it slides with
  |F_t| -> mu F_n); no stick state is kept.

One source for both engines: :func:`normal_force` and its helpers take the array functions (:data:`NUMPY` for whole
arrays of samples, :data:`CASADI` for the plant's graphs, whose derivatives are then exact by automatic
differentiation), so the law the plant integrates is the law the analysis evaluates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from types import SimpleNamespace
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, StringConstraints

from chewbot.config import Plausible, Strict, key_error, read_text, validate
from chewbot.errors import ChewbotError
from chewbot.units import factor, key_unit

# The teeth's own contact once the sample is flat (delta >= h0): a linear spring of 1 kN/mm, the order of a molar's
# axial stiffness on its periodontal ligament (tenths to a few kN/mm); it only keeps the teeth from passing through
# each other, no protocol here is meant to reach it.
TOOTH_STIFFNESS = 1.0e6  # N/m
# Speed scale of the regularised friction of the sample on the tooth (m/s).
FRICTION_SPEED = 1.0e-3

SHAPES = ("cylinder", "sphere")


class FoodError(ChewbotError):
    """A food file or a food's value is malformed: names the file and the key."""


# The parameter vector of a food, as the plant's graphs take it.
FOOD_PARAMETERS = ("h0", "k", "n", "alpha", "fracture_strain", "broken_factor", "rho", "inv_tau", "adhesion", "mu",
                   "k_tooth")
N_FOOD = len(FOOD_PARAMETERS)
_NO_FRACTURE = 1.0e9  # a strain never reached


@dataclass(frozen=True)
class Food:
    """A food sample (SI inside): ``height`` h0 (m), ``diameter`` d (m, cylinder), ``young_modulus`` E (Pa),
    ``poisson_ratio`` nu (sphere), ``damping`` alpha (s/m, Hunt–Crossley), ``fracture_strain`` (None: it does not
    break), ``stiffness_after_fracture`` (factor on F_e once broken), ``relaxation_time`` tau (s, None: no Maxwell
    branch), ``relaxation_modulus`` E_m (Pa), ``adhesion`` (N), ``tooth_friction`` mu; ``source`` the file it was
    read from."""

    name: str
    shape: str
    height: float
    young_modulus: float
    tooth_friction: float
    diameter: float | None = None
    poisson_ratio: float | None = None
    damping: float = 0.0
    fracture_strain: float | None = None
    stiffness_after_fracture: float = 1.0
    relaxation_time: float | None = None
    relaxation_modulus: float = 0.0
    adhesion: float = 0.0
    source: str = ""

    @property
    def area(self) -> float | None:
        """Cross-section of a cylinder (m^2)."""
        return None if self.diameter is None else math.pi * self.diameter**2 / 4

    @property
    def exponent(self) -> float:
        """n of F_e = k delta^n."""
        return 1.0 if self.shape == "cylinder" else 1.5

    @property
    def stiffness(self) -> float:
        """k of F_e = k delta^n (N/m^n)."""
        if self.shape == "cylinder":
            return self.young_modulus * self.area / self.height
        R = self.height / 2
        return 4 / 3 * self.young_modulus / (1 - self.poisson_ratio**2) * math.sqrt(R) / 2**1.5

    def elastic(self, delta) -> np.ndarray:
        """F_e (N) at compressions ``delta`` (m), intact."""
        return elastic_force(NUMPY, self.vector(), np.asarray(delta, float))

    @property
    def fracture_force(self) -> float | None:
        """F_e at the fracture strain (N): the elastic part of the force at which the sample breaks."""
        return None if self.fracture_strain is None else float(self.elastic(self.fracture_strain * self.height))

    def vector(self) -> np.ndarray:
        """The parameters as the plant's graphs take them (:data:`FOOD_PARAMETERS`)."""
        rho = self.relaxation_modulus / self.young_modulus if self.relaxation_time else 0.0
        values = {"h0": self.height, "k": self.stiffness, "n": self.exponent, "alpha": self.damping,
                  "fracture_strain": _NO_FRACTURE if self.fracture_strain is None else self.fracture_strain,
                  "broken_factor": self.stiffness_after_fracture, "rho": rho,
                  "inv_tau": 1.0 / self.relaxation_time if self.relaxation_time else 0.0,
                  "adhesion": self.adhesion, "mu": self.tooth_friction, "k_tooth": TOOTH_STIFFNESS}
        return np.array([values[k] for k in FOOD_PARAMETERS], float)

    def as_dict(self) -> dict:
        """The food as run.json records it (the file's keys and units)."""
        mm, kPa = factor("mm"), factor("kPa")
        out = {"name": self.name, "shape": self.shape, "height_mm": self.height / mm}
        if self.diameter is not None:
            out["diameter_mm"] = self.diameter / mm
        out["young_modulus_kPa"] = self.young_modulus / kPa
        if self.poisson_ratio is not None:
            out["poisson_ratio"] = self.poisson_ratio
        out["damping_s_per_m"] = self.damping
        if self.fracture_strain is not None:
            out.update(fracture_strain=self.fracture_strain, stiffness_after_fracture=self.stiffness_after_fracture)
        if self.relaxation_time is not None:
            out.update(relaxation_time_s=self.relaxation_time, relaxation_modulus_kPa=self.relaxation_modulus / kPa)
        out.update(adhesion_N=self.adhesion, tooth_friction=self.tooth_friction, source=self.source,
                   tooth_stiffness_N_per_m=TOOTH_STIFFNESS, friction_speed_m_per_s=FRICTION_SPEED)
        return out


# ------------------------------------------------------------------------------------------- the law, twice


def _casadi_backend():
    import casadi as ca

    return SimpleNamespace(fmax=ca.fmax, where=ca.if_else, sqrt=ca.sqrt, exp=ca.exp, fabs=ca.fabs)


NUMPY = SimpleNamespace(fmax=np.maximum, where=np.where, sqrt=np.sqrt, exp=np.exp, fabs=np.abs)


class _Casadi:
    """The CasADi array functions, loaded on first use (the command line reads foods without CasADi)."""

    def __getattr__(self, name):
        return getattr(_casadi_backend(), name)


CASADI = _Casadi()


def _p(f, name: str):
    return f[FOOD_PARAMETERS.index(name)]


def elastic_force(xp, f, delta):
    """F_e = k max(delta, 0)^n (N), intact; ``f`` the food's vector."""
    d = xp.fmax(delta, 0.0)
    return _p(f, "k") * d ** _p(f, "n")


def breaking(f, broken):
    """b: 1 intact, ``stiffness_after_fracture`` broken (``broken`` 0 or 1)."""
    return 1.0 - broken * (1.0 - _p(f, "broken_factor"))


def maxwell_force(xp, f, F_m0, bFe0, bFe, t):
    """The Maxwell branch's force t seconds after a step's start, where it was F_m0 and b F_e was bFe0, with b F_e
    now bFe and changing linearly in between (exact for that; t >= 0)."""
    x = _p(f, "inv_tau") * t
    decay = xp.exp(-x)
    phi = xp.where(x > 1e-8, (1.0 - decay) / xp.fmax(x, 1e-8), 1.0 - x / 2)
    return F_m0 * decay + _p(f, "rho") * (bFe - bFe0) * phi


def normal_force(xp, f, delta, ddelta, broken, F_m):
    """The normal force F_n (N, positive pushing the teeth apart) at compression ``delta`` (m), its rate ``ddelta``
    (m/s), the state ``broken`` (0/1) and the Maxwell branch's force ``F_m`` (N); and F_v = F_d + F_m before the
    clamp (the clamp's guard). The tooth contact beyond delta = h0 included."""
    b = breaking(f, broken)
    F_v = b * elastic_force(xp, f, delta) * (1.0 + 1.5 * _p(f, "alpha") * ddelta) + F_m
    food = xp.where(delta > 0, xp.fmax(F_v, -_p(f, "adhesion")), 0.0)
    tooth = _p(f, "k_tooth") * xp.fmax(delta - _p(f, "h0"), 0.0)
    return food + tooth, F_v


def tangential_force(xp, f, F_n, vx, vy):
    """The friction of the sample on the tooth (N, two components in {S}'s x and y), regularised Coulomb."""
    scale = -_p(f, "mu") * xp.fmax(F_n, 0.0) / xp.sqrt(vx**2 + vy**2 + FRICTION_SPEED**2)
    return scale * vx, scale * vy


# ------------------------------------------------------------------------------------------- files


class FoodTable(Strict):
    """The ``[food]`` table of a food file (docs/food.md), as written: one field per key, in the unit its key ends
    with, with its limits and its plausible range. A key the file leaves out takes :class:`Food`'s default."""

    DOCS = "docs/food.md"

    name: Annotated[str, StringConstraints(strip_whitespace=True, min_length=1)]
    shape: Literal[SHAPES]
    height_mm: Annotated[float, Field(gt=0), Plausible(0.5, 100.0, "mm", "heights of a sample between molars")]
    diameter_mm: Annotated[float, Field(gt=0), Plausible(0.5, 100.0, "mm", "diameters of a sample between molars")] | None = None
    young_modulus_kPa: Annotated[float, Field(gt=0), Plausible(0.1, 1e6, "kPa", "Young's moduli of foods (jellies about 1 kPa, hard candy about 1 GPa)")]
    poisson_ratio: Annotated[float, Field(ge=0, le=0.5)] | None = None
    damping_s_per_m: Annotated[float, Field(ge=0), Plausible(0.0, 1000.0, "s/m", "Hunt-Crossley damping factors of foods")] | None = None
    fracture_strain: Annotated[float, Field(gt=0, le=1)] | None = None
    stiffness_after_fracture: Annotated[float, Field(ge=0, le=1)] | None = None
    relaxation_time_s: Annotated[float, Field(gt=0), Plausible(1e-3, 1e5, "s", "relaxation times of foods")] | None = None
    relaxation_modulus_kPa: Annotated[float, Field(ge=0), Plausible(0.0, 1e6, "kPa", "relaxation moduli of foods")] | None = None
    adhesion_N: Annotated[float, Field(ge=0), Plausible(0.0, 100.0, "N", "pulls of a sticky sample")] | None = None
    tooth_friction: Annotated[float, Field(ge=0), Plausible(0.0, 2.0, "1", "friction coefficients of food on a tooth")]


class FoodFile(Strict):
    """A food file: one table ``[food]``."""

    DOCS = "docs/food.md"

    food: FoodTable


# Keys that apply to one shape only, and are required for it.
_ONLY = {"diameter_mm": "cylinder", "poisson_ratio": "sphere"}


def builtin_foods() -> dict[str, Path]:
    """The built-in foods: file stem -> file (``src/chewbot/food/foods/*.toml``)."""
    folder = resources.files("chewbot") / "food" / "foods"
    return {Path(str(p)).stem: Path(str(p)) for p in sorted(folder.iterdir(), key=lambda p: p.name)
            if str(p).endswith(".toml")}


def load_food(name_or_path: str | Path) -> Food:
    """A built-in food by name (:func:`builtin_foods`) or a TOML food file. Errors name the file and the key."""
    builtins = builtin_foods()
    text = str(name_or_path)
    if text in builtins:
        path = builtins[text]
    else:
        path = Path(text)
        if not path.exists():
            raise FoodError(f"{text}: neither a built-in food ({', '.join(builtins)}) nor a food file")
    return food_from_dict(read_text(path, "food file", FoodError).data, str(path))


def food_from_dict(raw: dict, source: str = "<dict>") -> Food:
    """A food from the content of a food file (a table ``[food]`` with the keys of docs/food.md)."""
    table = validate(FoodFile, raw, source, FoodError).food
    given = table.model_dump(exclude_none=True)

    def fail(key: str, reason: str):
        raise key_error(source, f"food.{key}", reason, FoodError)

    for key, only in _ONLY.items():
        if key in given and table.shape != only:
            fail(key, f"does not apply to a {table.shape} (only to a {only})")
        if key not in given and table.shape == only:
            fail(key, f"missing key (a {table.shape} needs it)")
    if "stiffness_after_fracture" in given and "fracture_strain" not in given:
        fail("stiffness_after_fracture", "given without food.fracture_strain")
    if "fracture_strain" in given and "stiffness_after_fracture" not in given:
        fail("fracture_strain", "needs food.stiffness_after_fracture (the factor on the elastic force once broken)")
    if ("relaxation_time_s" in given) != ("relaxation_modulus_kPa" in given):
        present, missing = (("relaxation_time_s", "relaxation_modulus_kPa") if "relaxation_time_s" in given
                            else ("relaxation_modulus_kPa", "relaxation_time_s"))
        fail(present, f"the Maxwell branch needs food.{missing} too")
    values = {}
    for key, value in given.items():  # SI: each key's value times the factor of the unit it ends with
        attribute, unit = key_unit(key)
        values[attribute] = value * factor(unit) if unit else value
    return Food(source=source, **values)


__all__ = ["CASADI", "FOOD_PARAMETERS", "FRICTION_SPEED", "Food", "FoodError", "N_FOOD", "NUMPY", "SHAPES", "TOOTH_STIFFNESS",
           "breaking", "builtin_foods", "elastic_force", "food_from_dict", "load_food", "maxwell_force", "normal_force",
           "tangential_force"]
