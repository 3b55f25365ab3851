"""Sieving a bolus and the Rosin-Rammler law of its particle sizes.

The sieves mastication studies use (:data:`SIEVES_MM`: 5.6, 4, 2.8, 2, 1.4, 1, 0.71 and 0.5 mm) and the pan, sieve 0.
A particle of size x is retained on the finest sieve it cannot pass: the mass fraction on sieve s_k is the mass of
the sizes s_k <= x < s_(k-1) (the top sieve keeps everything from 5.6 mm up, the pan everything below 0.5 mm); the
fractions sum to 1.

Rosin-Rammler (Olthoff et al. 1984): the cumulative mass fraction passing a sieve of aperture X is
Q(X) = 1 - 2^(-(X / X50)^b), X50 the median size, b the spread (a larger b, a narrower distribution).
:func:`fit_rosin_rammler` finds X50 and b by least squares on Q at every sieve (the pan's mass counts in Q: it is
what passes the finest sieve), with SciPy's ``least_squares`` in (log X50, log b) and the exact Jacobian. Where
X50 lies beyond the top sieve it is an extrapolation, flagged; where fewer than two sieves hold a cumulative
fraction strictly between 0 and 1 the two numbers are not determined by the sieving (NaN, flagged).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# The sieves' apertures (mm), coarsest first; the pan, sieve 0, follows the last.
SIEVES_MM = (5.6, 4.0, 2.8, 2.0, 1.4, 1.0, 0.71, 0.5)
# The rows of a sieving: the sieves and the pan (0 mm), coarsest first.
SIEVING_MM = SIEVES_MM + (0.0,)
# A cumulative fraction within this of 0 or 1 carries no information on X50 and b.
_EDGE = 1e-9


def sieve_matrix(lower_mm: np.ndarray) -> np.ndarray:
    """The 0/1 matrix (sieves and pan) x (size classes) that sums each class's mass onto the sieve that retains it;
    ``lower_mm`` the classes' lower edges (mm), every sieve aperture among them."""
    lower_mm = np.asarray(lower_mm, float)
    missing = [s for s in SIEVES_MM if not np.any(np.isclose(lower_mm, s, rtol=0, atol=1e-12))]
    if missing:
        raise ValueError(f"the size classes need the sieves' apertures among their edges; missing {missing}")
    tops = (math.inf,) + SIEVES_MM
    return np.array([(lower_mm >= s - 1e-12) & (lower_mm < top - 1e-12) for s, top in zip(SIEVING_MM, tops)], float)


def passing(fractions) -> np.ndarray:
    """Q at each sieve (coarsest first): the mass fraction passing it, i.e. on the finer sieves and the pan."""
    f = np.asarray(fractions, float)
    retained_at_or_above = np.cumsum(f[..., :-1], axis=-1)
    return 1.0 - retained_at_or_above


def rosin_rammler(x, x50, b):
    """Q(X) = 1 - 2^(-(X / X50)^b) (X and X50 in one unit)."""
    return 1.0 - np.exp2(-(np.asarray(x, float) / x50) ** b)


@dataclass(frozen=True)
class RosinRammler:
    """A least-squares Rosin-Rammler fit: ``x50_mm``, ``b``, the root-mean-square residual in Q, and the status:
    ``extrapolated`` (X50 beyond the top sieve), ``determined`` (False: too few sieves hold a fraction between 0 and
    1, X50 and b are NaN)."""

    x50_mm: float
    b: float
    rms: float
    extrapolated: bool
    determined: bool

    @property
    def flag(self) -> str:
        """'' or why the numbers need care, as a table writes it."""
        if not self.determined:
            return "undetermined: fewer than two sieves pass a fraction strictly between 0 and 1"
        return f"extrapolated: X50 beyond the top sieve ({SIEVES_MM[0]:g} mm)" if self.extrapolated else ""


def fit_rosin_rammler(fractions) -> RosinRammler:
    """X50 (mm) and b of the mass fractions retained on :data:`SIEVING_MM` (the sieves, then the pan)."""
    from scipy.optimize import least_squares

    f = np.asarray(fractions, float)
    if f.shape != (len(SIEVING_MM),):
        raise ValueError(f"a sieving has {len(SIEVING_MM)} fractions (the sieves and the pan), not {f.shape}")
    x = np.array(SIEVES_MM)
    q = passing(f)
    inner = (q > _EDGE) & (q < 1 - _EDGE)
    if inner.sum() < 2:
        return RosinRammler(math.nan, math.nan, math.nan, False, False)

    def model(p):
        x50, b = np.exp(p)
        t = (x / x50) ** b
        return 1.0 - np.exp2(-t), t

    def residual(p):
        return model(p)[0] - q

    def jacobian(p):
        b = math.exp(p[1])
        _, t = model(p)
        dq_dt = math.log(2) * np.exp2(-t)  # dQ/dt
        # t = (x / x50)^b: dt/dlog x50 = -b t, dt/dlog b = b t log(x / x50)
        return np.column_stack([dq_dt * (-b * t), dq_dt * (b * t * np.log(x / math.exp(p[0])))])

    # start: a straight line through the linearised law, log(-log2(1 - Q)) = b log X - b log X50
    y = np.log(-np.log2(1 - q[inner]))
    slope, intercept = np.polyfit(np.log(x[inner]), y, 1)
    b0 = min(max(slope, 0.2), 10.0)
    start = np.array([-intercept / b0, math.log(b0)])
    sol = least_squares(residual, start, jac=jacobian, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    x50, b = np.exp(sol.x)
    return RosinRammler(float(x50), float(b), float(np.sqrt(np.mean(sol.fun**2))), bool(x50 > SIEVES_MM[0]), True)


__all__ = ["RosinRammler", "SIEVES_MM", "SIEVING_MM", "fit_rosin_rammler", "passing", "rosin_rammler", "sieve_matrix"]
