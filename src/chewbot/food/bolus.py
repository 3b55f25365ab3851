"""The bolus: a portion of food as a population of particles in size classes, broken down stroke by stroke, and the
particle bed's force between the teeth (docs/bolus.md).

**The state** (:class:`Bolus`): the mass (kg) in each class of :data:`CLASSES`, a fixed grid of sieve sizes x (the
aperture a particle just passes): the eight sieves of :data:`chewbot.food.sieving.SIEVES_MM` and their continuation
by factors of sqrt(2) down to 0.0625 mm and up to 22.4 mm are class edges, each interval cut into
:data:`SUBCLASSES` classes of equal ratio (2^(1/8) wide), and below 0.0625 mm one class of fines (which do not break
further). A particle of class i has the class's geometric-mean size x_i and counts as a sphere of diameter x_i:
n_i = m_i / (rho pi x_i^3 / 6) particles, each covering a_i = pi x_i^2 / 4 of the table. A stroke moves mass only
from a class to the same or smaller ones, and its breakage matrix's columns sum to 1: the total mass is conserved
(to rounding, 1e-15 relative a stroke).

**A stroke** (:func:`stroke`), given what the teeth delivered in it: the closest gap g (m) and the peak force F (N).

* selection, the chance that a particle of size x is caught between the teeth:
  S(x) = placement * (1 - e^-C) / C * R(x, g).
  C = sum(n_i a_i) / A is the bolus's coverage of the occlusal table A (how many layers it would make spread
  over it): with few particles every one can lie on the table, with many only A's worth can, so the chance falls as
  1 / C (the saturation of breakage sites of van der Glas et al. 1992; a Poisson occupancy of the table).
  R(x, g) = min(1, max(0, (x - g) / relief))^w is the share of the table where the teeth come closer than x: the
  table's cusps leave a gap from g (the closest) to g + relief, the area below a gap g + z growing as (z / relief)^w.
  A particle smaller than the closest gap is never caught, small particles are caught on a small share of the table
  (van der Bilt et al. 1987's selection chance rising as a power of size), and larger ones keep the teeth from the
  smaller (the one-way competition of Baragar, van der Bilt & van der Glas 1996).
* breakage: the caught particles share the force over the area they cover, a stress p = F / sum(S_i n_i a_i); a
  particle of size x breaks with Weibull's probability P(x) = 1 - exp(-(p / sigma(x))^m), its strength falling
  with its volume as Weibull's size effect has it, sigma(x) = sigma_1 (x / 1 mm)^(-3/m) (Weibull 1951; smaller
  pieces are stronger, which slows comminution as it proceeds).
* fragments: a broken particle of size y breaks into fragments whose cumulative mass below x is a Rosin-Rammler
  law truncated at y, B(x, y) = (1 - 2^-(x / (beta y))^c) / (1 - 2^-(1 / beta)^c) for x <= y (beta the median
  fragment size as a share of the parent's, c their spread; Lucas & Luke 1983's fragmentation, the same for every
  size).
* the new state: m' = m - k m + B (k m), k = S P (0 for the fines), B the matrix of B(x, y) over the classes.

**The particle bed** (:func:`bed`, :func:`bed_force`): the share of the bolus that lies on the table, V (1 - e^-C) / C
(V its volume), forms a bed of loose height h0 = V (1 - e^-C) / (C A (1 - phi0)), phi0 its loose porosity. Closed to
a gap g < h0 it is compacted by eps = 1 - g / h0 (laterally confined: the volumetric strain), and pushes back with
F = A E eps_c (e^(eps / eps_c) - 1): a modulus E when first loaded, stiffening e-fold every eps_c of strain as
the pores close, and finite when the teeth meet (eps = 1: a thin bed, squeezed out, bounded). The bed softens as the
bolus is comminuted: every fracture opens the food's cells to a depth delta (``paste_depth_mm``) under the new
surface, whose contents and the saliva they take up make a paste, a share f of the bolus's mass
(:func:`paste_fraction`, 1 - (1 - 2 delta / x)^3 of a particle of size x); the dry share 1 - f carries the load, so
E = E0 (1 - f)^n, E0 ``bed_modulus_kPa`` the dry bed's of the first coarse fragments, n ``paste_exponent``. Written
once for NumPy and CasADi (:data:`chewbot.food.law.NUMPY`, :data:`~chewbot.food.law.CASADI`), with its exact inverse
(:func:`bed_gap`).

**The ideal stroke** (:func:`ideal_stroke`): the teeth close on the bed until its force reaches ``closing_force`` or
the gap reaches ``min_gap``, whichever comes first (an ideal chewing stroke, as the ideal texture analyser is an
ideal test); the stroke's gap and peak force are then those of the bed law. :func:`chew` repeats it.

Every law takes the array functions ``xp`` and the parameters as a mapping (the ``[comminution]`` keys, SI values,
:meth:`chewbot.food.comminution.ComminutionTable.si`): NumPy for a chewing sequence, CasADi for the fit's exact
Jacobian (:mod:`chewbot.food.comminution_fit`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from chewbot.food import CLOSING_FORCE_N, MIN_GAP_MM
from chewbot.food.comminution import ComminutionTable
from chewbot.food.law import NUMPY, Food, FoodError
from chewbot.food.sieving import SIEVES_MM, RosinRammler, fit_rosin_rammler, sieve_matrix
from chewbot.units import factor

SUBCLASSES = 4  # classes between two neighbouring sieve sizes (a factor sqrt(2))
_BELOW = 6  # sqrt(2) steps below the finest sieve: 0.5 mm / 8 = 0.0625 mm
_ABOVE = 4  # sqrt(2) steps above the coarsest: 5.6 mm x 4 = 22.4 mm
_REFERENCE_SIZE = 1e-3  # m: the size at which strength_at_1mm_MPa is given
_DRY_FLOOR = 1e-6  # the least dry share 1 - f of a bed (a bolus of fines alone keeps a modulus E0 1e-6^n > 0)
_TINY = 1e-300  # floors that keep logarithms and powers (and their derivatives) finite at zero

# The particle bed as the plant's graphs take it (:func:`bed_force`): loose height h0 (m), table area A (m^2),
# modulus E (Pa, softened: :func:`bed`), compaction strain eps_c, Hunt-Crossley damping alpha (s/m; :func:`bed_normal_force`).
BED_PARAMETERS = ("h0", "area", "modulus", "compaction_strain", "damping")


@dataclass(frozen=True)
class SizeClasses:
    """The size classes (m): ``lower`` and ``upper`` edges, ``size`` the geometric mean (the fines: their upper edge
    over 2^(1/8)), ``breaks`` (False for the fines)."""

    lower: np.ndarray
    upper: np.ndarray
    size: np.ndarray
    breaks: np.ndarray

    @property
    def n(self) -> int:
        return len(self.size)

    def index(self, x: float) -> int:
        """The class of a particle of size ``x`` (m)."""
        if not 0 <= x < self.upper[-1]:
            raise ValueError(f"a particle of {x / factor('mm'):g} mm is outside the size classes (below {self.upper[-1] / factor('mm'):g} mm)")
        return int(np.searchsorted(self.upper, x, side="right"))


def _size_classes() -> SizeClasses:
    finest, coarsest = SIEVES_MM[-1], SIEVES_MM[0]
    steps = ([finest * 2 ** (-k / 2) for k in range(_BELOW, 0, -1)] + sorted(SIEVES_MM)
             + [coarsest * 2 ** (k / 2) for k in range(1, _ABOVE + 1)])
    edges = [steps[0]]
    for a, b in zip(steps[:-1], steps[1:]):
        edges += [a * (b / a) ** (j / SUBCLASSES) for j in range(1, SUBCLASSES + 1)]
    edges = np.array(edges) * factor("mm")
    lower = np.concatenate([[0.0], edges[:-1]])
    upper = edges
    size = np.sqrt(np.where(lower > 0, lower, upper * 2 ** (-1 / SUBCLASSES)) * upper)
    return SizeClasses(lower, upper, size, lower > 0)


CLASSES = _size_classes()
SIEVE = sieve_matrix(CLASSES.lower / factor("mm"))  # the classes' masses onto the sieves and the pan
_AREA = math.pi / 4 * CLASSES.size**2  # m^2 a particle covers
_VOLUME = math.pi / 6 * CLASSES.size**3  # m^3 of a particle
_AT_LEAST = np.triu(np.ones((CLASSES.n, CLASSES.n)))  # row i sums the classes i and larger


def comminution_of(food: Food) -> ComminutionTable:
    """The food's ``[comminution]`` table; a food without one is an error naming it (chewing needs it)."""
    if food.comminution is None:
        raise FoodError(f"{food.name} ({food.source}): no [comminution] table, so it cannot be chewed; add one "
                        "(docs/bolus.md lists its keys) or fit one with chewbot fit-comminution")
    return food.comminution


# ------------------------------------------------------------------------------------------- the laws, once


def _coverage(xp, c, mass):
    """(particles per class n, each class's coverage C of the table by the particles of its size or larger, and the
    share (1 - e^-C) / C of the class that lies on the table)."""
    n = mass / (c["density_kg_per_m3"] * xp.asarray(_VOLUME))
    cover = xp.asarray(_AT_LEAST) @ (n * xp.asarray(_AREA)) / c["table_area_mm2"]
    small = cover < 1e-4  # the series where the quotient loses digits
    share = xp.where(small, 1 - cover / 2 + cover**2 / 6, (1 - xp.exp(-cover)) / xp.fmax(cover, 1e-4))
    return n, cover, share


def selection(xp, c, mass, gap):
    """S per class: the chance that a particle of the class is caught in a stroke that closes to ``gap`` (m)."""
    _, _, share = _coverage(xp, c, mass)
    reach = xp.fmin(xp.fmax((xp.asarray(CLASSES.size) - gap) / c["relief_mm"], _TINY), 1.0) ** c["relief_exponent"]
    return c["placement"] * share * reach


def breakage(xp, c, mass, gap, force):
    """P per class: the chance that a caught particle of the class breaks under the stroke's ``force`` (N) shared
    by the caught particles; and the selection S."""
    n, _, _ = _coverage(xp, c, mass)
    S = selection(xp, c, mass, gap)
    stress = force / xp.fmax(xp.sum(S * n * xp.asarray(_AREA)), 1e-12)
    m = c["weibull_modulus"]
    log_strength = xp.log(c["strength_at_1mm_MPa"]) - 3 / m * xp.asarray(np.log(CLASSES.size / _REFERENCE_SIZE))
    z = xp.fmin(m * (xp.log(xp.fmax(stress, _TINY)) - log_strength), 50.0)  # e^50: P = 1 to rounding
    return 1 - xp.exp(-xp.exp(z)), S


def fragments(xp, c):
    """The breakage matrix B (classes x classes): B[j, i] the mass fraction of a broken particle of class i that
    lands in class j; each column sums to 1."""
    y = CLASSES.size[None, :]
    beta, spread = c["fragment_size"], c["fragment_spread"]

    def cumulative(ratio):  # B(x, y) of x / y (clipped to 1): the fragments' mass below x
        return (1 - xp.exp(-math.log(2) * (xp.fmax(ratio, _TINY) / beta) ** spread)) / (
            1 - xp.exp(-math.log(2) * (1 / beta) ** spread))

    return (cumulative(xp.asarray(np.fmin(CLASSES.upper[:, None] / y, 1.0)))
            - cumulative(xp.asarray(np.fmin(CLASSES.lower[:, None] / y, 1.0))))


def stroke(xp, c, mass, gap, force, B=None):
    """One stroke: (the new masses, the mass caught, the mass broken), given the closest ``gap`` (m) and the peak
    ``force`` (N). ``B``: :func:`fragments` where it was built once for many strokes."""
    P, S = breakage(xp, c, mass, gap, force)
    broken = S * P * xp.asarray(CLASSES.breaks.astype(float)) * mass
    B = fragments(xp, c) if B is None else B
    return mass - broken + B @ broken, xp.sum(S * mass), xp.sum(broken)


def paste_fraction(xp, c, mass):
    """f, the share of the bolus's mass within ``paste_depth_mm`` of its particles' surfaces: the cells a fracture
    opened, whose contents (a peanut's oil, a carrot's juice) and the saliva they take up make a paste. A sphere of size
    x holds 1 - max(0, 1 - 2 delta / x)^3 of it; the fines below 2 delta are paste throughout."""
    core = xp.fmax(1 - 2 * c["paste_depth_mm"] / xp.asarray(CLASSES.size), 0.0) ** 3
    return xp.sum(mass * (1 - core)) / xp.sum(mass)


def bed(xp, c, mass):
    """The particle bed on the table: the values of :data:`BED_PARAMETERS` (h0 m, A m^2, E Pa, eps_c, alpha s/m), its
    modulus E = E0 (1 - f)^n softened by the paste fraction f (:func:`paste_fraction`)."""
    _, _, share = _coverage(xp, c, mass)
    area = c["table_area_mm2"]
    layer = share[0]  # the smallest class's share counts all the particles: the bed is one layer of the mixture
    h0 = xp.sum(mass) * layer / c["density_kg_per_m3"] / (area * (1 - c["bed_porosity"]))
    dry = xp.fmax(1 - paste_fraction(xp, c, mass), _DRY_FLOOR)
    return h0, area, c["bed_modulus_kPa"] * dry ** c["paste_exponent"], c["bed_compaction_strain"], c["bed_damping_s_per_m"]


def _named(b) -> SimpleNamespace:
    """The bed's values by their names in :data:`BED_PARAMETERS` (``b`` a sequence, a NumPy or a CasADi vector)."""
    return SimpleNamespace(**{name: b[i] for i, name in enumerate(BED_PARAMETERS)})


def bed_force(xp, b, gap):
    """The bed's force (N, pushing the teeth apart) at ``gap`` (m); ``b`` the values of :data:`BED_PARAMETERS`."""
    p = _named(b)
    eps = xp.fmax(1 - gap / p.h0, 0.0)
    return p.area * p.modulus * p.compaction_strain * (xp.exp(eps / p.compaction_strain) - 1)


def bed_normal_force(xp, b, gap, rate):
    """The bed's force (N) at ``gap`` (m) closing at ``rate`` = -dg/dt (m/s), with its Hunt-Crossley damping:
    max(0, F(g) (1 + 3/2 alpha rate)), F :func:`bed_force` (a bed pushes, never pulls). The robot's plant uses it; the
    ideal stroke is quasi-static (:func:`bed_force`)."""
    return xp.fmax(bed_force(xp, b, gap) * (1 + 1.5 * _named(b).damping * rate), 0.0)


def bed_gap(xp, b, force):
    """The gap (m) at which the bed pushes with ``force`` (N > 0): the inverse of :func:`bed_force` (negative where
    the force is beyond the bed's at g = 0)."""
    p = _named(b)
    return p.h0 * (1 - p.compaction_strain * xp.log(1 + force / (p.area * p.modulus * p.compaction_strain)))


def bed_work(xp, b, gap):
    """The work (J) of closing the bed from its loose height to ``gap``: the integral of :func:`bed_force`."""
    p = _named(b)
    eps = xp.fmax(1 - gap / p.h0, 0.0)
    strain = p.compaction_strain
    return p.area * p.modulus * strain * p.h0 * (strain * (xp.exp(eps / strain) - 1) - eps)


def ideal_stroke(xp, c, mass, closing_force, min_gap):
    """The ideal stroke's (closest gap m, peak force N, work J): closing until the bed's force is ``closing_force``
    (N) or the gap ``min_gap`` (m), whichever comes first."""
    b = bed(xp, c, mass)
    gap = xp.fmax(bed_gap(xp, b, closing_force), min_gap)
    return gap, bed_force(xp, b, gap), bed_work(xp, b, gap)


# ------------------------------------------------------------------------------------------- the state


@dataclass(frozen=True)
class StrokeRecord:
    """What a stroke did: the closest ``gap`` (m), the peak ``force`` (N), ``work`` (J, the ideal stroke's; None for a
    stroke given by the plant), the mass ``caught`` and ``broken`` (kg)."""

    gap: float
    force: float
    caught: float
    broken: float
    work: float | None = None


@dataclass(frozen=True)
class Bolus:
    """The mass (kg) in each class of :data:`CLASSES` (the state; never negative, its sum the portion's)."""

    mass: np.ndarray

    @classmethod
    def portion(cls, c: ComminutionTable) -> Bolus:
        """The intact portion: ``portion_g`` of pieces of ``piece_size_mm``."""
        si = c.si()
        mass = np.zeros(CLASSES.n)
        mass[CLASSES.index(si["piece_size_mm"])] = si["portion_g"]
        return cls(mass)

    @property
    def total(self) -> float:
        """The bolus's mass (kg)."""
        return float(self.mass.sum())

    def count(self, c: ComminutionTable) -> float:
        """The number of particles (as spheres of their class's size)."""
        return float(np.sum(self.mass / (c.si()["density_kg_per_m3"] * _VOLUME)))

    def sieving(self) -> np.ndarray:
        """The mass fractions retained on the sieves and the pan (:data:`chewbot.food.sieving.SIEVING_MM`)."""
        return SIEVE @ self.mass / self.total

    def rosin_rammler(self) -> RosinRammler:
        """X50 and b of the sieving (:func:`chewbot.food.sieving.fit_rosin_rammler`)."""
        return fit_rosin_rammler(self.sieving())

    def bed(self, c: ComminutionTable) -> np.ndarray:
        """The particle bed's :data:`BED_PARAMETERS` for :func:`bed_force` (the plant's force law after the first
        fracture)."""
        return np.array([float(v) for v in bed(NUMPY, c.si(), self.mass)])

    def stroke(self, c: ComminutionTable, gap: float, force: float) -> tuple[Bolus, StrokeRecord]:
        """The bolus after a stroke that closed to ``gap`` (m) with peak ``force`` (N), and what it did."""
        if not (math.isfinite(gap) and math.isfinite(force)) or gap < 0 or force < 0:
            raise ValueError(f"a stroke needs a gap >= 0 m and a force >= 0 N, not {gap!r} m and {force!r} N")
        new, caught, broken = stroke(NUMPY, c.si(), self.mass, gap, force)
        return Bolus(new), StrokeRecord(gap, force, float(caught), float(broken))

    def ideal_stroke(self, c: ComminutionTable, closing_force: float = CLOSING_FORCE_N,
                     min_gap: float = MIN_GAP_MM * factor("mm")) -> tuple[Bolus, StrokeRecord]:
        """The bolus after an ideal stroke (:func:`ideal_stroke`), and what it did."""
        gap, force, work = (float(v) for v in ideal_stroke(NUMPY, c.si(), self.mass, closing_force, min_gap))
        after, record = self.stroke(c, gap, force)
        return after, StrokeRecord(gap, force, record.caught, record.broken, work)


@dataclass(frozen=True)
class Chewing:
    """A sequence of ideal strokes: ``boluses[k]`` after k strokes (0: the intact portion), ``strokes[k]`` the
    (k+1)-th stroke."""

    boluses: list[Bolus]
    strokes: list[StrokeRecord]

    def rosin_rammler(self) -> list[RosinRammler]:
        """X50 and b after each number of strokes (:meth:`Bolus.rosin_rammler`)."""
        return [b.rosin_rammler() for b in self.boluses]


def chew(c: ComminutionTable, cycles: int, closing_force: float = CLOSING_FORCE_N,
         min_gap: float = MIN_GAP_MM * factor("mm")) -> Chewing:
    """``cycles`` ideal strokes on the intact portion."""
    boluses, strokes = [Bolus.portion(c)], []
    for _ in range(cycles):
        after, record = boluses[-1].ideal_stroke(c, closing_force, min_gap)
        boluses.append(after)
        strokes.append(record)
    return Chewing(boluses, strokes)


__all__ = ["BED_PARAMETERS", "CLASSES", "CLOSING_FORCE_N", "MIN_GAP_MM", "SIEVE", "SUBCLASSES", "Bolus", "Chewing", "SizeClasses",
           "StrokeRecord", "bed", "bed_force", "bed_gap", "bed_normal_force", "bed_work", "breakage", "chew", "comminution_of", "fragments",
           "ideal_stroke", "paste_fraction", "selection", "stroke"]
