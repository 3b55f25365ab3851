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
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from chewbot.config import validate
from chewbot.errors import ChewbotError
from chewbot.food.comminution import ComminutionSection, ComminutionTable

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
    comminution: ComminutionTable | None = None  # the file's [comminution] table (chewbot.food.bolus), if any

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
        out = {"name": self.name, "shape": self.shape, "height_mm": self.height * 1e3}
        if self.diameter is not None:
            out["diameter_mm"] = self.diameter * 1e3
        out["young_modulus_kPa"] = self.young_modulus / 1e3
        if self.poisson_ratio is not None:
            out["poisson_ratio"] = self.poisson_ratio
        out["damping_s_per_m"] = self.damping
        if self.fracture_strain is not None:
            out.update(fracture_strain=self.fracture_strain, stiffness_after_fracture=self.stiffness_after_fracture)
        if self.relaxation_time is not None:
            out.update(relaxation_time_s=self.relaxation_time, relaxation_modulus_kPa=self.relaxation_modulus / 1e3)
        out.update(adhesion_N=self.adhesion, tooth_friction=self.tooth_friction, source=self.source,
                   tooth_stiffness_N_per_m=TOOTH_STIFFNESS, friction_speed_m_per_s=FRICTION_SPEED)
        if self.comminution is not None:
            out["comminution"] = self.comminution.model_dump()
        return out


# ------------------------------------------------------------------------------------------- the law, twice


def _casadi_backend():
    import casadi as ca

    return SimpleNamespace(fmax=ca.fmax, fmin=ca.fmin, where=ca.if_else, sqrt=ca.sqrt, exp=ca.exp, log=ca.log,
                           fabs=ca.fabs, sum=ca.sum1, asarray=ca.DM)


NUMPY = SimpleNamespace(fmax=np.maximum, fmin=np.minimum, where=np.where, sqrt=np.sqrt, exp=np.exp, log=np.log,
                        fabs=np.abs, sum=np.sum, asarray=np.asarray)


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


# key: (attribute, factor to SI, required for which shapes (None: optional), lower bound, open bound, upper bound)
_KEYS = {
    "name": ("name", None),
    "shape": ("shape", None),
    "height_mm": ("height", 1e-3),
    "diameter_mm": ("diameter", 1e-3),
    "young_modulus_kPa": ("young_modulus", 1e3),
    "poisson_ratio": ("poisson_ratio", 1.0),
    "damping_s_per_m": ("damping", 1.0),
    "fracture_strain": ("fracture_strain", 1.0),
    "stiffness_after_fracture": ("stiffness_after_fracture", 1.0),
    "relaxation_time_s": ("relaxation_time", 1.0),
    "relaxation_modulus_kPa": ("relaxation_modulus", 1e3),
    "adhesion_N": ("adhesion", 1.0),
    "tooth_friction": ("tooth_friction", 1.0),
}
# (lowest, whether the lowest is excluded, highest or None)
_RANGES = {
    "height_mm": (0.0, True, None), "diameter_mm": (0.0, True, None), "young_modulus_kPa": (0.0, True, None),
    "poisson_ratio": (0.0, False, 0.5), "damping_s_per_m": (0.0, False, None), "fracture_strain": (0.0, True, 1.0),
    "stiffness_after_fracture": (0.0, False, 1.0), "relaxation_time_s": (0.0, True, None),
    "relaxation_modulus_kPa": (0.0, False, None), "adhesion_N": (0.0, False, None), "tooth_friction": (0.0, False, None),
}
_REQUIRED = ("name", "shape", "height_mm", "young_modulus_kPa", "tooth_friction")
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
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise FoodError(f"{path}: cannot read it ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise FoodError(f"{path}: not valid TOML ({exc})") from None
    return food_from_dict(raw, str(path))


def food_from_dict(raw: dict, source: str = "<dict>") -> Food:
    """A food from the content of a food file (a table ``[food]`` with the keys of docs/food.md)."""
    extra = set(raw) - {"food", "comminution"}
    if extra:
        raise FoodError(f"{source}: unknown table or key {sorted(extra)[0]!r}; a food file has a table [food] and "
                        "may have a table [comminution]")
    comminution = None
    if "comminution" in raw:
        comminution = validate(ComminutionSection, {"comminution": raw["comminution"]}, source, FoodError).comminution
    table = raw.get("food")
    if not isinstance(table, dict):
        raise FoodError(f"{source}: no [food] table")
    for key in table:
        if key not in _KEYS:
            hint = _unit_hint(key)
            raise FoodError(f"{source}: food.{key}: unknown key{hint}; the keys are {', '.join(_KEYS)}")
    for key in _REQUIRED:
        if key not in table:
            raise FoodError(f"{source}: food.{key}: missing")
    values: dict = {}
    for key in ("name", "shape"):
        if not isinstance(table[key], str) or not table[key].strip():
            raise FoodError(f"{source}: food.{key}: expected a non-empty string, not {table[key]!r}")
    shape = table["shape"]
    if shape not in SHAPES:
        raise FoodError(f"{source}: food.shape: {shape!r} is not a shape; choose {' or '.join(SHAPES)}")
    for key, only in _ONLY.items():
        if key in table and shape != only:
            raise FoodError(f"{source}: food.{key}: does not apply to a {shape} (only to a {only})")
        if key not in table and shape == only:
            raise FoodError(f"{source}: food.{key}: missing (a {shape} needs it)")
    for key, value in table.items():
        attr, factor = _KEYS[key]
        if factor is None:
            values[attr] = value.strip()
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise FoodError(f"{source}: food.{key}: expected a finite number, not {value!r}")
        low, open_low, high = _RANGES[key]
        if value < low or (open_low and value == low) or (high is not None and value > high):
            bound = f"{'>' if open_low else '>='} {low:g}" + (f" and <= {high:g}" if high is not None else "")
            raise FoodError(f"{source}: food.{key}: {value!r} out of range (must be {bound})")
        values[attr] = float(value) * factor
    if "stiffness_after_fracture" in table and "fracture_strain" not in table:
        raise FoodError(f"{source}: food.stiffness_after_fracture: given without food.fracture_strain")
    if "fracture_strain" in table and "stiffness_after_fracture" not in table:
        raise FoodError(f"{source}: food.fracture_strain: needs food.stiffness_after_fracture (the factor on the "
                        "elastic force once broken)")
    if ("relaxation_time_s" in table) != ("relaxation_modulus_kPa" in table):
        given, missing = (("relaxation_time_s", "relaxation_modulus_kPa") if "relaxation_time_s" in table
                          else ("relaxation_modulus_kPa", "relaxation_time_s"))
        raise FoodError(f"{source}: food.{given}: the Maxwell branch needs food.{missing} too")
    return Food(source=source, comminution=comminution, **values)


def _unit_hint(key: str) -> str:
    """' (the unit ...)' where a key names a known quantity in another unit."""
    stem = key.rsplit("_", 1)[0] if "_" in key else key
    for known in _KEYS:
        if known != key and known.startswith(stem + "_"):
            return f" (did you mean {known!r}? the unit is part of the key)"
    return ""


__all__ = ["CASADI", "FOOD_PARAMETERS", "FRICTION_SPEED", "Food", "FoodError", "N_FOOD", "NUMPY", "SHAPES", "TOOTH_STIFFNESS",
           "breaking", "builtin_foods", "elastic_force", "food_from_dict", "load_food", "maxwell_force", "normal_force",
           "tangential_force"]
