"""A food sample between flat teeth: its parameters (read from TOML), its force law and its state.

The law, one normal force along the gap (positive when the sample pushes the teeth apart) and a tangential friction:

* elastic force of the intact sample F_e(delta), delta the compression h0 - g (m) at the centre of the sample's face:
  cylinder  F_e = E A delta / h0,  A = pi d^2 / 4 (uniaxial compression of a short cylinder, no barrelling);
  sphere    F_e = 4/3 E / (1 - nu^2) sqrt(R) (delta / 2)^1.5,  R = h0 / 2 (Hertz between two rigid flats: each
            contact takes delta / 2);
  written F_e = k delta^n, k the stiffness of a sample of height h0; a sample of height h has k (h / h0)^m, m = -1
  for the cylinder (E A / h) and 1/2 for the sphere (sqrt(R)).
* the sample's own state (:data:`FOOD_STATE`, carried by the plant and by the ideal texture analyser of
  :mod:`chewbot.food.tpa`): ``broken`` (0 or 1), ``F_m`` the Maxwell branch's force (N), ``delta_max``, the
  deepest compression so far at the face's centre (m), and ``tilt_max``, sin of the lower tooth's tilt there (0 with
  parallel teeth). Its permanent set s (m, :func:`permanent_set`, at the face's centre) follows from them:

  - crushed (broken): its unloaded height becomes h_c = h0 - delta_max (1 - r), r = ``recovery_after_fracture``:
    a second bite meets fragments that recovered r of the deepest compression;
  - plastic: past ``yield_strain`` the excess compression becomes permanent in the share ``plastic_fraction`` phi,
    s = phi max(0, delta_max - yield_strain h0);
  - s is the larger of the two; the sample is then a sample of height h0 - s compressed by delta - s, and
    :func:`loaded_force` gives b F_e of that sample, b = 1 intact and ``stiffness_after_fracture`` broken.

  With r = 1 and no yield strain (the neutral values) s = 0 and the law is that of an elastic sample that keeps its
  height, broken or not. Over a tilted face (below) the set is a field over the face: each fibre keeps its share of
  its own deepest compression, delta_max + x tilt_max at x along the face, so the set's slope across the face is
  (1 - r) tilt_max crushed (phi tilt_max plastic, :func:`set_slope`): a crushed sample's top is inclined as the face
  was at its deepest compression, and the next bite to the same depth at the same tilt meets it with its face nearly
  parallel (the spread r a sin theta), r delta_max from the deepest point.
* the face: the lower tooth may be tilted by an angle theta against the upper one. A cylinder's law is then integrated
  over its circular cross-section of radius a (:func:`face_integrals`): the fibre at x along the face, measured from
  its centre towards the side that rises to the upper tooth, is compressed by delta + x sin(theta); each fibre is a
  uniaxial spring, none pulls. In closed form, with u = delta - s and c = a |sin(theta) - set slope| the half-spread
  of the compression beyond the set across the face (c = a sin(theta) with no set), xi = -u / c (the edge of
  contact), F_e = k (h / h0)^m G:
  G = u (full contact, u >= c); 0 (u <= -c); (u (acos xi - xi sqrt(1 - xi^2)) + 2/3 c (1 - xi^2)^1.5) / pi between.
  G is continuously differentiable in u, and G = max(u, 0) at theta = 0: today's law. A sphere has no face
  (a = 0) and sees the centre's compression.
* Hunt-Crossley damping: F_d = b F_e (1 + 3/2 alpha d(delta)/dt);
* Maxwell branch (stress relaxation): dF_m/dt = rho d(b F_e)/dt - F_m / tau, rho = E_m / E. For the cylinder this is
  the standard linear solid; for the sphere the same hereditary integral on the Hertz force (quasi-linear
  viscoelasticity, Fung). Over a step in which b F_e changes linearly in time it is integrated exactly
  (:func:`maxwell_force`): F_m(t) = F_m(0) e^(-t/tau) + rho (b F_e(t) - b F_e(0)) (tau / t)(1 - e^(-t/tau));
* normal force in contact (some fibre compressed: u + c > 0): F_n = max(F_d + F_m, -adhesion_N): a sample never
  pulls, except through its damping and relaxed Maxwell branch while unloading, and then at most ``adhesion_N``. Out
  of contact F_n = 0;
* the teeth meet at delta = h0 (at the bite point, the face's centre): beyond it a stiff linear tooth contact :data:`TOOTH_STIFFNESS` acts besides the food;
* tangential friction of the sample on the upper tooth (the slide): F_t = -mu max(F_n, 0) v_t / sqrt(|v_t|^2 + eps^2),
  v_t the bite point's velocity in {S}'s x-y plane. This is the regularised Coulomb law of the plant's joints (below
  the speed :data:`FRICTION_SPEED` it acts as a stiff viscous damper, the regularised "stick"; above it it slides
  with |F_t| -> mu F_n); no stick state is kept.

How the state changes (:data:`FOOD_EVENTS`, :func:`guards`, :func:`fracture_state`):

* ``F_m`` is continuous: the ODE above;
* ``delta_max`` is continuous: max(delta_max at a step's start, delta) where delta is monotonic in the step, and
  ``tilt_max`` follows sin theta while delta is the deepest so far; they stop where the compression turns (the
  ``turn`` event, a kink of the force of a crushed or plastic sample);
* ``broken`` jumps from 0 to 1 at the ``fracture`` event ((delta + a sin(theta)) / h0 = fracture_strain: the face's
  most compressed fibre, where the sample is strained most), and F_m jumps with it by
  the ratio of b F_e after to F_e before (the factor b when r = 1);
* the law's other kinks, located as events so that no integrator step straddles them: ``contact`` (u + c = 0),
  ``teeth`` (delta = h0), ``adhesion`` (F_d + F_m = -adhesion_N), ``yield`` (delta = yield_strain h0 while it is
  the deepest so far).

One source for both engines: the law's functions take the array functions (:data:`NUMPY` for whole arrays of
samples, :data:`CASADI` for the plant's graphs, whose derivatives are then exact by automatic differentiation), so
the law the plant integrates is the law the analysis evaluates.
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
from chewbot.food.comminution import ComminutionTable
from chewbot.units import factor, key_unit

# The teeth's own contact once the sample is flat (delta >= h0): a linear spring of 1 kN/mm, the order of a molar's
# axial stiffness on its periodontal ligament (tenths to a few kN/mm); it only keeps the teeth from passing through
# each other, no protocol here is meant to reach it.
TOOTH_STIFFNESS = 1.0e6  # N/m
# Speed scale of the regularised friction of the sample on the tooth (m/s).
FRICTION_SPEED = 1.0e-3
# recovery_after_fracture where a food file does not give it: a crushed sample recovers a tenth of its deepest
# compression (a second bite meets fragments).
RECOVERY_AFTER_FRACTURE = 0.1

SHAPES = ("cylinder", "sphere")


class FoodError(ChewbotError):
    """A food file or a food's value is malformed: names the file and the key."""


# The parameter vector of a food, as the plant's graphs take it: h0 (m), k (N/m^n), n, m (k of a sample of height h
# is k (h / h0)^m), alpha (s/m), fracture_strain, broken_factor b, recovery r, yield_strain, plastic_fraction phi,
# rho = E_m / E, inv_tau (1/s), adhesion (N), mu, k_tooth (N/m), radius a of the face (m; 0: a sphere, no face).
FOOD_PARAMETERS = ("h0", "k", "n", "m", "alpha", "fracture_strain", "broken_factor", "recovery", "yield_strain",
                   "plastic_fraction", "rho", "inv_tau", "adhesion", "mu", "k_tooth", "radius")
N_FOOD = len(FOOD_PARAMETERS)
# The food's state, as the plant carries it: broken (0/1), F_m (N), delta_max (m), tilt_max (sin of the tilt there).
FOOD_STATE = ("broken", "F_m", "delta_max", "tilt_max")
# The law's events: the guards of :func:`guards`, in this order.
FOOD_EVENTS = ("contact", "teeth", "fracture", "adhesion", "yield", "turn")
_NEVER = 1.0e9  # a strain never reached
# The edge of contact xi is kept this far inside (-1, 1) so that acos and the square roots keep finite derivatives in
# the branch that is not taken (a relative change of the force below 1e-12).
_EDGE = 1.0e-12


@dataclass(frozen=True)
class Food:
    """A food sample (SI inside): ``height`` h0 (m), ``diameter`` d (m, cylinder), ``young_modulus`` E (Pa),
    ``poisson_ratio`` nu (sphere), ``damping`` alpha (s/m, Hunt–Crossley), ``fracture_strain`` (None: it does not
    break), ``stiffness_after_fracture`` (factor b on the elastic force once broken), ``recovery_after_fracture`` r
    (the share of its deepest compression a crushed sample recovers), ``yield_strain`` (None: no permanent set before
    a fracture) and ``plastic_fraction`` phi, ``relaxation_time`` tau (s, None: no Maxwell branch),
    ``relaxation_modulus`` E_m (Pa), ``adhesion`` (N), ``tooth_friction`` mu; ``source`` the file it was read from."""

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
    recovery_after_fracture: float = RECOVERY_AFTER_FRACTURE
    yield_strain: float | None = None
    plastic_fraction: float = 0.0
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
    def height_exponent(self) -> float:
        """m of k(h) = k (h / h0)^m: E A / h for the cylinder, sqrt(R) = sqrt(h / 2) for the sphere."""
        return -1.0 if self.shape == "cylinder" else 0.5

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
        values = {"h0": self.height, "k": self.stiffness, "n": self.exponent, "m": self.height_exponent,
                  "alpha": self.damping,
                  "fracture_strain": _NEVER if self.fracture_strain is None else self.fracture_strain,
                  "broken_factor": self.stiffness_after_fracture, "recovery": self.recovery_after_fracture,
                  "yield_strain": _NEVER if self.yield_strain is None else self.yield_strain,
                  "plastic_fraction": self.plastic_fraction, "rho": rho,
                  "inv_tau": 1.0 / self.relaxation_time if self.relaxation_time else 0.0,
                  "adhesion": self.adhesion, "mu": self.tooth_friction, "k_tooth": TOOTH_STIFFNESS,
                  "radius": 0.0 if self.diameter is None else self.diameter / 2}
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
            out.update(fracture_strain=self.fracture_strain, stiffness_after_fracture=self.stiffness_after_fracture,
                       recovery_after_fracture=self.recovery_after_fracture)
        if self.yield_strain is not None:
            out.update(yield_strain=self.yield_strain, plastic_fraction=self.plastic_fraction)
        if self.relaxation_time is not None:
            out.update(relaxation_time_s=self.relaxation_time, relaxation_modulus_kPa=self.relaxation_modulus / kPa)
        out.update(adhesion_N=self.adhesion, tooth_friction=self.tooth_friction, source=self.source,
                   tooth_stiffness_N_per_m=TOOTH_STIFFNESS, friction_speed_m_per_s=FRICTION_SPEED)
        if self.comminution is not None:
            out["comminution"] = self.comminution.model_dump()
        return out


# ------------------------------------------------------------------------------------------- the law, twice


def _casadi_backend():
    import casadi as ca

    return SimpleNamespace(fmax=ca.fmax, fmin=ca.fmin, where=ca.if_else, sqrt=ca.sqrt, exp=ca.exp, log=ca.log,
                           fabs=ca.fabs, arccos=ca.acos, sum=ca.sum1, asarray=ca.DM)


NUMPY = SimpleNamespace(fmax=np.maximum, fmin=np.minimum, where=np.where, sqrt=np.sqrt, exp=np.exp, log=np.log,
                        fabs=np.abs, arccos=np.arccos, sum=np.sum, asarray=np.asarray)


class _Casadi:
    """The CasADi array functions, loaded on first use (the command line reads foods without CasADi)."""

    def __getattr__(self, name):
        return getattr(_casadi_backend(), name)


CASADI = _Casadi()


def _p(f, name: str):
    return f[FOOD_PARAMETERS.index(name)]


def elastic_force(xp, f, delta):
    """F_e = k max(delta, 0)^n (N), intact, at the face's centre; ``f`` the food's vector."""
    d = xp.fmax(delta, 0.0)
    return _p(f, "k") * d ** _p(f, "n")


def breaking(f, broken):
    """b: 1 intact, ``stiffness_after_fracture`` broken (``broken`` 0 or 1)."""
    return 1.0 - broken * (1.0 - _p(f, "broken_factor"))


def permanent_set(xp, f, broken, delta_max):
    """s (m): the compression the sample keeps unloaded, the larger of its plastic set phi max(0, delta_max -
    yield_strain h0) and, broken, its crushed set delta_max (1 - r)."""
    h0 = _p(f, "h0")
    plastic = _p(f, "plastic_fraction") * xp.fmax(delta_max - _p(f, "yield_strain") * h0, 0.0)
    return xp.fmax(plastic, broken * delta_max * (1.0 - _p(f, "recovery")))


def set_slope(xp, f, broken, delta_max, tilt_max):
    """The slope of the permanent set across the face (sin of an angle): the set is a field s + x slope over the face,
    each fibre keeping its share of its own deepest compression delta_max + x tilt_max (``tilt_max`` sin of the tilt
    where the centre was compressed deepest): (1 - r) tilt_max where the crushed set is the larger, phi tilt_max where
    the plastic one is (past the yield), 0 with no set."""
    h0 = _p(f, "h0")
    plastic = _p(f, "plastic_fraction") * xp.fmax(delta_max - _p(f, "yield_strain") * h0, 0.0)
    crushed = broken * delta_max * (1.0 - _p(f, "recovery"))
    return xp.where(crushed >= plastic, broken * (1.0 - _p(f, "recovery")),
                    xp.where(plastic > 0, _p(f, "plastic_fraction"), 0.0)) * tilt_max


def _spread(xp, f, broken, delta_max, sin_tilt, tilt_max):
    """c = a (sin theta - set slope) (m): the half-spread across the face of the compression less the set; its sign
    says which side is compressed more."""
    return _p(f, "radius") * (sin_tilt - set_slope(xp, f, broken, delta_max, tilt_max))


def face_integrals(xp, u, c):
    """(G, M) of a linear field of compression over a circular face of radius a: G = (1/A) int max(0, u + x sin(theta))
    dA (m), the compression of the face's fibres averaged over the whole face, and M = (1/(A a)) int x max(0, u + x
    sin(theta)) dA (m), its first moment along x over a; u the compression at the centre, c = a sin(theta) >= 0 its
    half-spread (module docstring). At c = 0: G = max(u, 0), M = 0; in full contact G = u, M = c / 4."""
    xi = xp.fmin(xp.fmax(-u / xp.fmax(c, 1e-300), -1.0 + _EDGE), 1.0 - _EDGE)
    root = xp.sqrt(1.0 - xi**2)
    segment = xp.arccos(xi) - xi * root  # pi A_segment / A
    G_part = (u * segment + 2.0 / 3.0 * c * root**3) / math.pi
    # int x^2 over the segment / (A a^2) = (acos xi - xi sqrt(1 - xi^2)(2 xi^2 - 1)) / (4 pi)
    M_part = (u * 2.0 / 3.0 * root**3 + c * (xp.arccos(xi) - xi * root * (2 * xi**2 - 1)) / 4.0) / math.pi
    full = u >= c
    none = u <= -c
    G = xp.where(full, u, xp.where(none, 0.0, G_part))
    M = xp.where(full, c / 4.0, xp.where(none, 0.0, M_part))
    return G, M


def loaded_force(xp, f, delta, broken=0.0, delta_max=0.0, sin_tilt=0.0, tilt_max=0.0):
    """b F_e (N): the elastic force of the sample in its state (broken, deepest compression so far and the tilt there:
    its permanent set and height), at the compression ``delta`` (m) of its face's centre and the face's tilt (sin
    theta), integrated over the face for a cylinder (module docstring)."""
    s = permanent_set(xp, f, broken, delta_max)
    height = _p(f, "h0") - s
    k = _p(f, "k") * (height / _p(f, "h0")) ** _p(f, "m")
    u = delta - s
    c = xp.fabs(_spread(xp, f, broken, delta_max, sin_tilt, tilt_max))
    G, _ = face_integrals(xp, u, c)
    spread = xp.where(c > 0, G, xp.fmax(u, 0.0) ** _p(f, "n"))
    return breaking(f, broken) * k * spread


def pressure_centre(xp, f, delta, broken=0.0, delta_max=0.0, sin_tilt=0.0, tilt_max=0.0):
    """Where the elastic force acts (m): its offset from the face's centre along the tilt's direction, positive towards
    the side that rises (0 with no tilt or no face; a^2 sin(theta) / (4 u) in full contact with no set, a the face's
    radius, u the compression at the centre less the permanent set)."""
    s = permanent_set(xp, f, broken, delta_max)
    a = _p(f, "radius")
    c = _spread(xp, f, broken, delta_max, sin_tilt, tilt_max)
    G, M = face_integrals(xp, delta - s, xp.fabs(c))
    return xp.where((c != 0) & (G > 0), xp.where(c > 0, 1.0, -1.0) * a * M / xp.fmax(G, 1e-300), 0.0)


def maxwell_force(xp, f, F_m0, bFe0, bFe, t):
    """The Maxwell branch's force t seconds after a step's start, where it was F_m0 and b F_e was bFe0, with b F_e
    now bFe and changing linearly in between (exact for that; t >= 0)."""
    x = _p(f, "inv_tau") * t
    decay = xp.exp(-x)
    phi = xp.where(x > 1e-8, (1.0 - decay) / xp.fmax(x, 1e-8), 1.0 - x / 2)
    return F_m0 * decay + _p(f, "rho") * (bFe - bFe0) * phi


def in_contact(xp, f, delta, broken=0.0, delta_max=0.0, sin_tilt=0.0, tilt_max=0.0):
    """The contact guard u + |c| (m): positive where some fibre of the face is compressed beyond its set."""
    return delta - permanent_set(xp, f, broken, delta_max) + xp.fabs(_spread(xp, f, broken, delta_max, sin_tilt, tilt_max))


def normal_force(xp, f, delta, ddelta, broken, F_m, delta_max=0.0, sin_tilt=0.0, tilt_max=0.0):
    """The normal force F_n (N, positive pushing the teeth apart) at compression ``delta`` (m) of the face's centre,
    its rate ``ddelta`` (m/s), the state (``broken`` 0/1, the Maxwell branch's force ``F_m`` (N), the deepest
    compression so far ``delta_max`` (m) and sin of the tilt there ``tilt_max``) and the face's tilt ``sin_tilt``; and
    F_v = F_d + F_m before the clamp (the clamp's guard). The tooth contact beyond delta = h0 included. With
    ``delta_max`` = 0 the sample has its full height (no permanent set)."""
    bFe = loaded_force(xp, f, delta, broken, delta_max, sin_tilt, tilt_max)
    F_v = bFe * (1.0 + 1.5 * _p(f, "alpha") * ddelta) + F_m
    food = xp.where(in_contact(xp, f, delta, broken, delta_max, sin_tilt, tilt_max) > 0, xp.fmax(F_v, -_p(f, "adhesion")),
                    0.0)
    tooth = _p(f, "k_tooth") * xp.fmax(delta - _p(f, "h0"), 0.0)
    return food + tooth, F_v


def tangential_force(xp, f, F_n, vx, vy):
    """The friction of the sample on the tooth (N, two components in {S}'s x and y), regularised Coulomb."""
    scale = -_p(f, "mu") * xp.fmax(F_n, 0.0) / xp.sqrt(vx**2 + vy**2 + FRICTION_SPEED**2)
    return scale * vx, scale * vy


def fracture_state(xp, f, delta, F_m, delta_max, sin_tilt=0.0, tilt_max=0.0):
    """The state just after the fracture at compression ``delta``: (broken = 1, F_m times the ratio of b F_e after to
    F_e before, delta_max), the sample crushed to its new height at once (its tilt_max unchanged)."""
    before = loaded_force(xp, f, delta, 0.0, delta_max, sin_tilt, tilt_max)
    after = loaded_force(xp, f, delta, 1.0, delta_max, sin_tilt, tilt_max)
    return 1.0, F_m * after / xp.fmax(before, 1e-300), delta_max


def guards(xp, f, delta, ddelta, broken, F_m, delta_max, sin_tilt=0.0, tilt_max=0.0):
    """The guard functions of :data:`FOOD_EVENTS` at a state, in that order (NaN: not armed there): an event is where
    its guard changes sign. ``fracture`` is read on the face's most compressed fibre, delta + a sin(theta) (the sample
    breaks where it is strained most; delta itself with parallel faces), armed while intact; ``yield`` and ``turn``
    at the centre, armed only where the compression is the deepest so far (they change the permanent set);
    ``adhesion`` in contact. ``xp``: :data:`NUMPY` (a list of the six, each an array of the samples) or
    :data:`CASADI` (the plant's compiled step evaluates them)."""
    h0, yield_depth = _p(f, "h0"), _p(f, "yield_strain") * _p(f, "h0")
    strained = delta + _p(f, "radius") * sin_tilt
    _, F_v = normal_force(xp, f, delta, ddelta, broken, F_m, delta_max, sin_tilt, tilt_max)
    contact = in_contact(xp, f, delta, broken, delta_max, sin_tilt, tilt_max)
    deepest = delta >= delta_max
    plastic = _p(f, "plastic_fraction") > 0
    sets = xp.fmax(broken, plastic * (delta_max >= yield_depth)) > 0.5
    return [contact, delta - h0,
            xp.where(broken < 0.5, strained / h0 - _p(f, "fracture_strain"), math.nan),
            xp.where(contact > 0, F_v + _p(f, "adhesion"), math.nan),
            xp.where(plastic * deepest > 0.5, delta - yield_depth, math.nan),
            xp.where(sets * deepest > 0.5, ddelta, math.nan)]


# ------------------------------------------------------------------------------------------- files


class FoodTable(Strict):
    """The ``[food]`` table of a food file (docs/food.md), as written: one field per key, in the unit its key ends
    with, with its limits and its plausible range. A key the file leaves out takes :class:`Food`'s default."""

    DOCS = "docs/food.md"

    name: Annotated[str, StringConstraints(strip_whitespace=True, min_length=1)]
    shape: Literal[SHAPES]
    height_mm: Annotated[float, Field(gt=0), Plausible(0.5, 100.0, "mm", "heights of a sample between molars")]
    diameter_mm: Annotated[float, Field(gt=0), Plausible(0.5, 100.0, "mm", "diameters of a sample between molars")] | None = None
    young_modulus_kPa: Annotated[float, Field(gt=0), Plausible(1e-3, 1e6, "kPa", "Young's moduli of foods (creams tens of Pa, hard candy about 1 GPa)")]
    poisson_ratio: Annotated[float, Field(ge=0, le=0.5)] | None = None
    damping_s_per_m: Annotated[float, Field(ge=0), Plausible(0.0, 1000.0, "s/m", "Hunt-Crossley damping factors of foods")] | None = None
    fracture_strain: Annotated[float, Field(gt=0, le=1)] | None = None
    stiffness_after_fracture: Annotated[float, Field(ge=0, le=1)] | None = None
    recovery_after_fracture: Annotated[float, Field(ge=0, le=1)] | None = None
    yield_strain: Annotated[float, Field(gt=0, le=1)] | None = None
    plastic_fraction: Annotated[float, Field(ge=0, le=1)] | None = None
    relaxation_time_s: Annotated[float, Field(gt=0), Plausible(1e-3, 1e5, "s", "relaxation times of foods")] | None = None
    relaxation_modulus_kPa: Annotated[float, Field(ge=0), Plausible(0.0, 1e6, "kPa", "relaxation moduli of foods")] | None = None
    adhesion_N: Annotated[float, Field(ge=0), Plausible(0.0, 100.0, "N", "pulls of a sticky sample")] | None = None
    tooth_friction: Annotated[float, Field(ge=0), Plausible(0.0, 2.0, "1", "friction coefficients of food on a tooth")]


class FoodFile(Strict):
    """A food file: a table ``[food]`` and, optionally, a table ``[comminution]`` (:mod:`chewbot.food.comminution`)."""

    DOCS = "docs/food.md"

    food: FoodTable
    comminution: ComminutionTable | None = None


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
    f = validate(FoodFile, raw, source, FoodError)
    table = f.food
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
    if "recovery_after_fracture" in given and "fracture_strain" not in given:
        fail("recovery_after_fracture", "given without food.fracture_strain (it is the share of its deepest compression "
             "a crushed sample recovers)")
    for pair, what in ((("yield_strain", "plastic_fraction"), "the permanent set"),
                       (("relaxation_time_s", "relaxation_modulus_kPa"), "the Maxwell branch")):
        if (pair[0] in given) != (pair[1] in given):
            present, missing = pair if pair[0] in given else pair[::-1]
            fail(present, f"{what} needs food.{missing} too")
    values = {}
    for key, value in given.items():  # SI: each key's value times the factor of the unit it ends with
        attribute, unit = key_unit(key)
        values[attribute] = value * factor(unit) if unit else value
    return Food(source=source, comminution=f.comminution, **values)


__all__ = ["CASADI", "FOOD_EVENTS", "FOOD_PARAMETERS", "FOOD_STATE", "FRICTION_SPEED", "Food", "FoodError", "N_FOOD", "NUMPY",
           "RECOVERY_AFTER_FRACTURE", "SHAPES", "TOOTH_STIFFNESS", "breaking", "builtin_foods", "elastic_force",
           "face_integrals", "food_from_dict", "fracture_state", "guards", "in_contact", "load_food", "loaded_force",
           "maxwell_force", "normal_force", "permanent_set", "pressure_centre", "set_slope", "tangential_force"]
