"""The fit to the robot: in every frame, the admissible pose nearest to the recorded one.

The target robot moves in 4 DOF (X, Y, alpha, beta; Z and gamma follow from its HKPs), the 6RSS in 6; a
recorded pose has 6. For each frame, q_EE minimises the weighted pose error of
:mod:`chewbot.recordings.robotfit` (position of the measure point in mm times ``position_weight_per_mm``,
rotation angle between the fitted and the recorded orientation in degrees times ``orientation_weight_per_deg``,
in the least-squares sense) over the admissible poses (condyles inside their sockets, every chain reachable).

1. Without the constraints, frame after frame in time order: a compiled Gauss-Newton kernel (exact Jacobians
   by CasADi's automatic differentiation) runs over the frames in one loop, each frame starting from the
   previous frame's result (the first from the recorded pose's own coordinates). The same kernel also runs on
   every frame from its own recorded coordinates, all at once, and each frame keeps the better answer (a tie
   goes to the recorded coordinates' branch of the Euler angles), so that a frame after one that went astray
   does not inherit it. Frames whose last step is not yet below :data:`STEP_TOL` get more iterations, all at
   once.
2. Where that optimum is not admissible, the nearest admissible pose lies on the boundary: those frames are
   solved as constrained problems (SQP, CasADi ``sqpmethod``, exact Hessian), all in one mapped call, each
   starting from the penalised projection of its unconstrained optimum (:meth:`FitFunctions.projected`, one
   compiled call over those frames). A frame where the SQP does not end at an admissible,
   stationary point has no admissible pose near it.

For the 6RSS the fit is exact (zero error) wherever the recorded pose is reachable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chewbot.model import Model
from chewbot.recordings.robotfit import DEG, MIN_TRANSMISSION_DEG, FitFunctions, fit_functions
from chewbot.rotation import euler_angles_from_matrix

# A frame has converged when the last Gauss-Newton step is below this (mm and deg: 1e-12 m, 2e-11 rad).
STEP_TOL = 1e-9
MORE_ROUNDS = 5
# Two answers whose abs(r)^2 differ by less than this (and 1e-9 relative) tie: (1e-9 mm)^2, far above rounding.
TIE = 1e-18
# An admissible pose may break a socket bound by this much (mm; the kinematics' own slack is 1e-12 m = 1e-9 mm).
BOUND_TOL = 1e-10
# The SQP's answer counts as a solution when the gradient of its Lagrangian is below this (weighted error^2 per
# mm or deg; the SQP stops at 1e-10).
STATIONARITY_TOL = 1e-6
# A frame of the penalised fit is inside the admissible set when it breaks no bound by more than this (mm in a
# socket, robotfit.REACH_UNIT of sine squared on a chain; the penalty's optimum lies about 1e-5 outside).
PROJECTED_TOL = 1e-3
# A frame whose penalised fit is inside with errors this far (mm, deg) within the tolerances passes without the SQP
# (:func:`within`).
SCREEN_MARGIN = 1e-2


@dataclass(frozen=True, eq=False)
class RobotFit:
    """The fit in every frame (arrays frames first).

    ``q`` (N, n): q_EE in Euler angles (``coords``; m and rad), NaN where no admissible pose was found;
    ``position_error_mm``, ``orientation_error_deg`` (N,): the errors of the fitted pose (NaN where none);
    ``admissible`` (N,): an admissible pose was found; ``outside`` (N, n_g): the constraints that the
    unconstrained optimum breaks (the recorded motion leaves the workspace there), named by ``constraint_names``.
    """

    coords: tuple[str, ...]
    q: np.ndarray
    position_error_mm: np.ndarray
    orientation_error_deg: np.ndarray
    admissible: np.ndarray
    outside: np.ndarray
    constraint_names: tuple[str, ...]


def settings_vector(model: Model, point, position_weight_per_mm: float, orientation_weight_per_deg: float) -> np.ndarray:
    """[measure point in {M} (m); w_p; w_o] (the point defaults to the model's incisor)."""
    b = model.incisor if point is None else np.asarray(point, dtype=float)
    return np.r_[b, position_weight_per_mm, orientation_weight_per_deg]


def targets(p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(N, 12) recorded poses as the kernels take them: [p; R column by column]."""
    return np.hstack([p, np.swapaxes(R, 1, 2).reshape(-1, 9)])


def own_coordinates(fns: FitFunctions, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The recorded poses' own coordinates in the fit's scaled unknowns (X, Y (, Z) and the Euler angles it has)."""
    angles = euler_angles_from_matrix(R)
    q = np.hstack([p[:, :2], angles[:, :2]]) if fns.n == 4 else np.hstack([p, angles])
    return q / fns.scale


def fit_to_robot(model: Model, p: np.ndarray, R: np.ndarray, point=None, position_weight_per_mm: float = 1.0,
                 orientation_weight_per_deg: float = 1.0, min_transmission_deg: float = MIN_TRANSMISSION_DEG) -> RobotFit:
    """The admissible poses of ``model`` nearest to the recorded ones (``p`` (N, 3) m, ``R`` (N, 3, 3) in {S}),
    every transmission angle at least ``min_transmission_deg``."""
    fns = fit_functions(model, min_transmission_deg)
    settings = settings_vector(model, point, position_weight_per_mm, orientation_weight_per_deg)
    target = targets(p, R)
    z, last, outside = _unconstrained(fns, p, R, target, settings)
    rows = np.flatnonzero(outside.any(axis=1) | ~(last <= STEP_TOL))
    admissible = np.ones(len(z), dtype=bool)
    if rows.size:
        start = fns.projected(z[rows], target[rows], settings)[0]
        z[rows], admissible[rows] = _constrained(fns, start, target[rows], settings)
    return _result(fns, z, admissible, outside, target, settings)


def screened_fit(model: Model, p: np.ndarray, R: np.ndarray, point, position_weight_per_mm: float,
                 orientation_weight_per_deg: float, min_transmission_deg: float, enough: float) -> tuple[np.ndarray, np.ndarray]:
    """The registration search's fit, where only the frames whose weighted residual abs(r) exceeds ``enough`` count
    (:func:`_screened`, good: abs(r) <= ``enough``). Returns the scaled unknowns z (N, n) (the SQP's optimum where
    it ran, 0 where no admissible pose was found) and whether each frame has an admissible pose."""
    fns = fit_functions(model, min_transmission_deg)
    settings = settings_vector(model, point, position_weight_per_mm, orientation_weight_per_deg)
    z, ok = _screened(fns, p, R, targets(p, R), settings, lambda z, target: _cost(fns, z, target, settings) <= enough**2)
    return np.where(ok[:, None], z, 0.0), ok


def within(model: Model, p: np.ndarray, R: np.ndarray, point, position_weight_per_mm: float, orientation_weight_per_deg: float,
           min_transmission_deg: float, tolerances: tuple[float, float]) -> np.ndarray:
    """Whether each frame's admissible pose nearest to the recorded one (:func:`fit_to_robot`) has its position and
    orientation errors within ``tolerances`` (mm, deg): :func:`_screened`, good where the penalised fit's errors are
    within the tolerances less :data:`SCREEN_MARGIN` (far above how far it may lie outside: an admissible pose
    that near is as good to 1e-3 mm), the others judged by the SQP's optimum. The verdict of the share's
    bisection, which needs no pose."""
    fns = fit_functions(model, min_transmission_deg)
    settings = settings_vector(model, point, position_weight_per_mm, orientation_weight_per_deg)

    def good(z, target):
        pos, ori, _ = fns.errors(z, target, settings)
        return (pos <= tolerances[0] - SCREEN_MARGIN) & (ori <= tolerances[1] - SCREEN_MARGIN)

    target = targets(p, R)
    z, ok = _screened(fns, p, R, target, settings, good)
    pos, ori = np.full(len(z), np.inf), np.full(len(z), np.inf)
    if ok.any():
        pos[ok], ori[ok], _ = fns.errors(z[ok], target[ok], settings)
    return ok & (pos <= tolerances[0]) & (ori <= tolerances[1])


def _screened(fns: FitFunctions, p, R, target, settings, good) -> tuple[np.ndarray, np.ndarray]:
    """Step 1 of the module, then the penalised fit (:meth:`~chewbot.recordings.robotfit.FitFunctions.projected`)
    of the frames whose optimum is not admissible, in one compiled call; a frame that the penalised fit brings
    inside (to :data:`PROJECTED_TOL`) where ``good(z, target)`` (rows) holds keeps it: an admissible pose that good
    exists, so the constrained optimum is no worse. The others are solved by the SQP of step 2, started from the
    penalised fit. Returns z (N, n) and whether each frame has an admissible pose."""
    z, last, outside = _unconstrained(fns, p, R, target, settings)
    ok = np.ones(len(z), dtype=bool)
    rows = np.flatnonzero(outside.any(axis=1) | ~(last <= STEP_TOL))
    if rows.size:
        start, off = fns.projected(z[rows], target[rows], settings)
        kept = (off <= PROJECTED_TOL) & good(start, target[rows])
        z[rows] = start
        polish = rows[~kept]
        if polish.size:
            z[polish], ok[polish] = _constrained(fns, start[~kept], target[polish], settings)
    return z, ok


def _unconstrained(fns: FitFunctions, p, R, target, settings):
    """Step 1 of the module: the unconstrained optimum z (N, n), its last step (N,) and the constraints it breaks
    (N, n_g)."""
    own = own_coordinates(fns, p, R)
    z, last = _converge(fns, *fns.sequential(own[0], target, settings), target, settings)
    # Each frame again from its own recorded coordinates, all at once: a frame after one that went astray (a
    # swapped marker, a tracker glitch) must not inherit its answer. The better of the two is kept, a tie going
    # to the recorded coordinates' Euler angles (beta within +-90 deg: (alpha + pi, pi - beta, gamma + pi) is the
    # same pose); where the recording is sound the two agree to rounding.
    z_own, last_own = _converge(fns, *fns.gauss_newton(own, target, settings), target, settings)
    keep = _cost(fns, z, target, settings) < _cost(fns, z_own, target, settings) * (1 - 1e-9) - TIE
    z[~keep], last[~keep] = z_own[~keep], last_own[~keep]
    z -= np.round((z - own) * fns.scale / (2 * np.pi)) * (fns.scale == DEG) * 2 * np.pi / fns.scale  # within half a turn
    g = fns.constraints(z)
    return z, last, (g < fns.lbg - BOUND_TOL) | (g > fns.ubg + BOUND_TOL)


def fitted_pose(model: Model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """p (N, 3) m and R (N, 3, 3) of fitted poses q (N, n) (m, rad; NaN rows give NaN)."""
    fns = fit_functions(model)
    ok = np.isfinite(q).all(axis=1)
    p, R = np.full((len(q), 3), np.nan), np.full((len(q), 3, 3), np.nan)
    if ok.any():
        p[ok], R[ok] = fns.pose(q[ok] / fns.scale)
    return p, R


def nearest_admissible(model: Model, q: np.ndarray, point=None, position_weight_per_mm: float = 1.0,
                       orientation_weight_per_deg: float = 1.0, min_transmission_deg: float = MIN_TRANSMISSION_DEG):
    """Poses q (N, n) of ``model`` (m, rad) moved to the nearest admissible ones where they are not admissible.

    Returns the poses (the others unchanged), the rows that were moved, whether each of those is admissible now,
    and a description of the largest violation that was removed (None if nothing moved).
    """
    fns = fit_functions(model, min_transmission_deg)
    g = fns.constraints(q / fns.scale)
    excess = np.maximum(fns.lbg - g, g - fns.ubg)
    rows = np.flatnonzero((excess > BOUND_TOL).any(axis=1))
    q = q.copy()
    ok = np.ones(rows.size, dtype=bool)
    worst = None
    if rows.size:
        z = q[rows] / fns.scale
        p, R = fns.pose(z)
        settings = settings_vector(model, point, position_weight_per_mm, orientation_weight_per_deg)
        z, ok = _constrained(fns, z, targets(p, R), settings)
        q[rows] = z * fns.scale
        j = int(np.argmax(excess.max(axis=0)))
        worst = f"{fns.constraint_names[j]} by {excess[:, j].max():.3g}{' mm' if 'condyle' in fns.constraint_names[j] else ' (sine squared)'}"
    return q, rows, ok, worst


def _cost(fns: FitFunctions, z, target, settings) -> np.ndarray:
    """abs(r)^2 per frame, infinite where z is not finite."""
    r = fns.errors(z, target, settings)[2]
    cost = np.sum(r**2, axis=1)
    return np.where(np.isfinite(cost), cost, np.inf)


def _converge(fns: FitFunctions, z, last, target, settings):
    """More Gauss-Newton iterations, all at once, on the frames whose last step is still above STEP_TOL."""
    z, last = z.copy(), last.copy()
    for _ in range(MORE_ROUNDS):
        rows = np.flatnonzero(~(last <= STEP_TOL))
        if rows.size == 0:
            break
        z[rows], last[rows] = fns.gauss_newton(z[rows], target[rows], settings)
    return z, last


def _constrained(fns: FitFunctions, z0, target, settings):
    """The constrained problem on some frames; (z, admissible) with NaN rows where no admissible pose was found.

    A frame whose SQP does not end at a stationary admissible point from its own start (an unconstrained optimum far
    outside the workspace, where the SQP's steps leave the chains' closure, or a stall on the boundary) is tried
    again from the solutions of the frames before and after it (the rows are in time order), then from the home
    pose (an interior one), keeping the
    admissible answer of smaller error; one that ends admissible but not stationary keeps that pose (its errors are
    then an upper bound of the nearest pose's); one that never ends admissible has no admissible pose near it."""
    z, lam = fns.constrained(z0, target, settings)
    feasible, stationary = _status(fns, z, lam, target, settings)
    for neighbour in (-1, 1, None):
        again = np.flatnonzero(~stationary)
        if again.size == 0:
            break
        if neighbour is None:
            start = np.zeros((again.size, fns.n))
        elif stationary.any():
            solved = np.flatnonzero(stationary)
            start = z[solved[np.clip(np.searchsorted(solved, again) - (neighbour < 0), 0, solved.size - 1)]]
        else:
            continue
        z2, lam2 = fns.constrained(start, target[again], settings)
        f2, s2 = _status(fns, z2, lam2, target[again], settings)
        better = f2 & (~feasible[again] | s2 | (_cost(fns, z2, target[again], settings) < _cost(fns, z[again], target[again], settings)))
        rows = again[better]
        z[rows], feasible[rows], stationary[rows] = z2[better], True, s2[better]
    z[~feasible] = np.nan
    return z, feasible


def _status(fns: FitFunctions, z, lam, target, settings):
    """Whether each SQP answer is admissible (sockets to BOUND_TOL) and whether it is also stationary."""
    g = fns.constraints(z)
    with np.errstate(invalid="ignore"):
        feasible = ((g >= fns.lbg - BOUND_TOL) & (g <= fns.ubg + BOUND_TOL)).all(axis=1) & np.isfinite(z).all(axis=1)
        grad = fns.stationarity(z, lam, target, settings)
        return feasible, feasible & (np.abs(grad).max(axis=1) <= STATIONARITY_TOL)


def _result(fns: FitFunctions, z, admissible, outside, target, settings) -> RobotFit:
    pos, ori = np.full(len(z), np.nan), np.full(len(z), np.nan)
    if admissible.any():
        pos[admissible], ori[admissible], _ = fns.errors(z[admissible], target[admissible], settings)
    return RobotFit(fns.coords, z * fns.scale, pos, ori, admissible, outside, fns.constraint_names)
