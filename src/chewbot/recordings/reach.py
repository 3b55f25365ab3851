"""What the robot can play, from its home pose: the reachable range of each coordinate and of the incisor point.

Admissible is what the fit to a recording admits (:mod:`chewbot.recordings.robotfit`): both condyles in their
sockets (target) and every transmission angle at least ``min_transmission_deg``.

* Per coordinate: moving that coordinate alone from home (the others held at 0), the interval of values around 0
  that stays admissible. All candidate values are evaluated at once on a grid of :data:`GRID_STEPS` per side, the
  first inadmissible grid point bracketing the edge, then :data:`BISECTIONS` bisections (vectorised over the
  coordinates' edges) place it to 1e-6 of the searched span.
* Incisor point: the farthest its position moves from home along +-x, +-y and +-z of {S} (forward/back, left/right,
  up/down; opening is -z) over all admissible poses, each an NLP solved by IPOPT with exact derivatives
  (:meth:`~chewbot.recordings.robotfit.FitFunctions.extreme`), started from home.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chewbot.model import Model
from chewbot.recordings.robotfit import MIN_TRANSMISSION_DEG, fit_functions
from chewbot.units import factor

# Searched span per side of home: mm for lengths, deg for angles (the fit's units), beyond any pose of the robot.
SPAN = 60.0
GRID_STEPS = 600
BISECTIONS = 30
# Directions of {S} for the incisor point, named as a user reads them.
DIRECTIONS = (("forward (+x)", (1, 0, 0)), ("backward (-x)", (-1, 0, 0)), ("left (+y)", (0, 1, 0)),
              ("right (-y)", (0, -1, 0)), ("up (+z)", (0, 0, 1)), ("down, opening (-z)", (0, 0, -1)))


@dataclass(frozen=True)
class Reach:
    """``coordinates``: {name: (low, high)} in mm or deg (``units``); ``incisor``: {direction: distance in mm} and
    the pose q_EE (m, rad) reaching it, ``incisor_poses``; ``limiting``: {name or direction: the constraint that
    ends it}; the margin used."""

    coordinates: dict[str, tuple[float, float]]
    units: dict[str, str]
    incisor: dict[str, float]
    incisor_poses: dict[str, np.ndarray]
    limiting: dict[str, str]
    min_transmission_deg: float


# Slack of an interior point solution at its bounds (mm in the sockets, sine squared of a transmission angle: 1e-8
# of sin^2(10 deg) = 0.03 moves the angle by 1e-6 deg).
TOLERANCE = 1e-8


def _admissible(fns, z: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    g = fns.constraints(z)
    with np.errstate(invalid="ignore"):
        return ((g >= fns.lbg - tolerance) & (g <= fns.ubg + tolerance)).all(axis=1)


def _limiting(fns, z: np.ndarray) -> str:
    """The constraint nearest to (or beyond) its bound at z (n,), relative to the bound's size."""
    g = fns.constraints(z[None])[0]
    slack = np.minimum(g - fns.lbg, fns.ubg - g) / np.maximum(1e-3, np.abs(fns.lbg))
    return fns.constraint_names[int(np.nanargmin(slack))]


def reach(model: Model, min_transmission_deg: float = MIN_TRANSMISSION_DEG) -> Reach:
    """The reachable ranges of ``model`` from home (see the module docstring)."""
    fns = fit_functions(model, min_transmission_deg)
    n = fns.n
    coords, units, limiting = {}, {}, {}
    steps = np.linspace(0.0, SPAN, GRID_STEPS + 1)[1:]
    for j, name in enumerate(fns.coords):
        ends = []
        for sign in (-1.0, 1.0):
            z = np.zeros((steps.size, n))
            z[:, j] = sign * steps
            ok = _admissible(fns, z)
            first_bad = int(np.argmin(ok)) if not ok.all() else steps.size
            lo = steps[first_bad - 1] if first_bad > 0 else 0.0
            hi = steps[first_bad] if first_bad < steps.size else steps[-1]
            for _ in range(BISECTIONS):
                mid = 0.5 * (lo + hi)
                zm = np.zeros((1, n))
                zm[0, j] = sign * mid
                lo, hi = (mid, hi) if _admissible(fns, zm)[0] else (lo, mid)
            ends.append(sign * lo)
            z_edge = np.zeros(n)
            z_edge[j] = sign * hi
            limiting[f"{name} {'high' if sign > 0 else 'low'}"] = _limiting(fns, z_edge)
        coords[name] = (ends[0], ends[1])
        units[name] = "mm" if fns.scale[j] == factor("mm") else "deg"
    incisor, poses = {}, {}
    home = fns.pose(np.zeros((1, n)))
    start = home[0][0] + home[1][0] @ model.incisor
    for label, d in DIRECTIONS:
        d = np.array(d, dtype=float)
        z, _ = fns.extreme(np.zeros(n), d, model.incisor)
        if not _admissible(fns, z[None], TOLERANCE)[0]:
            incisor[label], limiting[f"incisor {label}"] = float("nan"), "no admissible solution found"
            continue
        p, R = fns.pose(z[None])
        poses[label] = z * fns.scale
        incisor[label] = float(d @ (p[0] + R[0] @ model.incisor - start) / factor("mm"))
        limiting[f"incisor {label}"] = _limiting(fns, z)
    return Reach(coords, units, incisor, poses, limiting, min_transmission_deg)
