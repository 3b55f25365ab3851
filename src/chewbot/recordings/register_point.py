"""The registration search for an incisal-point recording (``tracked = "incisor"`` with ``--fit-registration``):
where the tracker sits, so that the robot's incisor follows as much of the recorded point's path as it can.

The recording is a path of one point, the incisor (the markers' mean: they move in parallel), d_k relative to the
first frame in the tracker's frame. A registration places it in {S}: the tracker's rotation A and the rest
incisor Q_0 (the first frame's point; the tracker's origin follows, Q_0 - A times the first frame's point). At the
scale s frame k's point is Q_k = Q_0 + s A d_k, and the pose the fit is given is the hinge guess of
:func:`chewbot.recordings.importer.hinge_angle` (the orientation that lowers the incisor by as much about the
condylar axis, weighed 0.1 per degree in the import's fit: it only chooses among the poses that put the incisor on
the point).

**What a point path leaves free.** The robot moves its incisor in 3 dimensions with 4 coordinates: any path inside
the set its incisor reaches (condyles in their sockets, transmission angles at least ``--min-transmission``) is
followed, whatever the rotation and rest that put it there. Residuals identify the placement only where the path
meets that set's boundary; what decides is the share, the largest uniform scale s <= 1 of the registered path at
which every frame is reached within ``--max-residual`` (as for a rigid-body recording,
:mod:`chewbot.recordings.register`).

**Search.**

1. Physics starts. The recording's principal direction (the largest-moment direction of d_k about the rest
   point, signed toward the farthest frame: the opening) is turned onto the robot's opening direction, by the
   smallest rotation from the file's (at most :data:`MAX_TRACKER_DEG`); two directions are tried, the incisor's
   velocity when the mandible turns about the condylar axis at home, and the chord from the home incisor to the
   lowest incisor the robot reaches (:mod:`chewbot.recordings.reach`). The rest incisor is the home incisor. The
   file's own placement is a third start; the one with the largest share is refined.
2. Refinement: the share is bisected (:data:`SCALE_BISECTIONS` steps between the start's share and 1); at each
   trial scale the placement is refined (L-BFGS-B, SciPy) to bring every frame within the tolerance, minimising the
   mean of 0.5 max(0, e_k - tau)^2 over :data:`SEARCH_FRAMES` frames (tau = :data:`MARGIN` x the tolerance): e_k
   is the incisor's distance from the reachable set, sqrt(2 V_k) / w_p with V_k the optimal value of a fit
   weighing the hinge guess only :data:`SEARCH_ORIENTATION_WEIGHT` per degree. Its gradient is exact: V_k's
   derivative by the recorded pose is that of the residual at the fitted pose (Danskin's theorem; the
   constraints do not depend on the recording), chained with the Jacobian of the registered poses by the unknowns
   (CasADi, :class:`~chewbot.recordings.robotfit.PointRegistrationFunctions`), and d(0.5 (e - tau)^2)/dV =
   (e - tau) / (w_p^2 e). Bounds: the rest incisor within the robot's incisor reach from home along each axis
   of {S}, the tracker's rotation within :data:`MAX_TRACKER_DEG` of the file's (a quadratic penalty). A trial
   scale is kept when every frame passes with the import's own fit.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from chewbot.errors import RecordingError
from chewbot.model import Model
from chewbot.recordings.fit import fit_to_robot
from chewbot.recordings.reach import reach
from chewbot.recordings.register import BISECTIONS, MAX_TRACKER_DEG, PENALTY, FoundRegistration
from chewbot.recordings.robotfit import fit_functions, point_registration_functions
from chewbot.units import factor

MM, DEG = factor("mm"), factor("deg")
# The search's fit weighs the hinge guess this little per degree (against 1 per mm at the incisor): its optimal
# value is then the incisor's squared distance from the reachable set, the guess only choosing among the poses
# that reach it.
SEARCH_ORIENTATION_WEIGHT = 0.01
# The refinement brings every frame within MARGIN x --max-residual (the import's fit, weighing the guess more, may
# end a little farther).
MARGIN = 0.8
# Bisection steps of the share between the start's and 1 (each one refinement).
SCALE_BISECTIONS = 6
# L-BFGS-B iterations per refinement.
ITERATIONS = 40
# Frames the refinement fits per evaluation (evenly spread, plus the farthest from the rest).
SEARCH_FRAMES = 120


def _unflat(v: np.ndarray) -> np.ndarray:
    return v.reshape(-1, 3, 3).transpose(0, 2, 1)


def _turn_onto(a: np.ndarray, b: np.ndarray, limit_deg: float) -> np.ndarray:
    """The smallest rotation carrying the unit vector a onto b, its angle limited to ``limit_deg``."""
    cross = np.cross(a, b)
    angle = min(np.arctan2(np.linalg.norm(cross), a @ b), limit_deg * DEG)
    return Rotation.from_rotvec(cross / max(np.linalg.norm(cross), 1e-300) * angle).as_matrix()


def opening_directions(model: Model, lowest: np.ndarray) -> list[np.ndarray]:
    """The robot's opening directions in {S} (unit): the incisor's velocity for a turn about the condylar axis
    (+y of {M}, positive opens) at home, and the chord from the home incisor to ``lowest`` (the lowest incisor the
    robot reaches)."""
    r = model.incisor - 0.5 * (model.hkp.T_L + model.hkp.T_R)
    hinge = np.cross([0.0, 1.0, 0.0], r)
    chord = lowest - model.incisor
    return [hinge / np.linalg.norm(hinge), chord / np.linalg.norm(chord)]


def fit_point_registration(model: Model, positions: np.ndarray, rotation: np.ndarray, origin: np.ndarray,
                           position_weight_per_mm: float, orientation_weight_per_deg: float, tolerance_mm: float,
                           min_transmission_deg: float, progress=None) -> FoundRegistration:
    """Search the registration of an incisal-point recording: ``positions`` (N, K, 3) m in the tracker's frame
    (markers moving in parallel), starting from the file's tracker ``rotation`` and ``origin``; the import's fit
    weights; ``tolerance_mm``: ``--max-residual``'s position (see the module)."""
    started = time.perf_counter()
    step = progress or (lambda message: None)
    fns = fit_functions(model, min_transmission_deg)
    graphs = point_registration_functions(model)
    point = positions.mean(axis=1)
    d = point - point[0]
    N = len(d)
    far = np.linalg.norm(d, axis=1)
    if far.max() < 1 * MM:
        raise RecordingError(f"the tracked point moves at most {far.max() / MM:.3g} mm: no opening direction to register")
    u = np.linalg.svd(d, full_matrices=False)[2][0]
    u = u if u @ d[int(np.argmax(far))] > 0 else -u
    ranges = reach(model, min_transmission_deg)
    lowest_pose = ranges.incisor_poses.get("down, opening (-z)")
    home_p, home_R = fns.pose(np.zeros((1, fns.n)))
    home = home_p[0] + home_R[0] @ model.incisor
    if lowest_pose is not None:
        p, R = fns.pose((lowest_pose / fns.scale)[None])
        directions = opening_directions(model, p[0] + R[0] @ model.incisor)
    else:
        directions = opening_directions(model, home + np.array([0.0, 0.0, -1.0]))[:1]
    inc = ranges.incisor
    box = [(-inc["backward (-x)"], inc["forward (+x)"]), (-inc["right (-y)"], inc["left (+y)"]),
           (-inc["down, opening (-z)"], inc["up (+z)"])]
    bounds = [(-2 * MAX_TRACKER_DEG, 2 * MAX_TRACKER_DEG)] * 3 + [(lo, hi) for lo, hi in box]
    weights_import = (position_weight_per_mm, orientation_weight_per_deg)
    weights_search = (position_weight_per_mm, SEARCH_ORIENTATION_WEIGHT)
    tau = MARGIN * tolerance_mm
    search = np.unique(np.r_[np.linspace(0, N - 1, min(N, SEARCH_FRAMES)).round().astype(int), np.argmax(far)])
    counter = [0]

    def const_of(A_start, s):
        return np.r_[A_start.T.ravel(), s, home, rotation.T.ravel()]

    def verdict(x, A_start, s):
        target, _ = graphs.targets(x, d, const_of(A_start, s))
        fit = fit_to_robot(model, target[:, :3], _unflat(target[:, 3:]), None, *weights_import, min_transmission_deg)
        return fit.admissible & (fit.position_error_mm <= tolerance_mm), fit

    def share_of(x, A_start, lo=0.0):
        ok, fit = verdict(x, A_start, 1.0)
        if ok.all():
            return 1.0, fit
        hi, best = 1.0, None
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            ok_mid, fit_mid = verdict(x, A_start, mid)
            if ok_mid.all():
                lo, best = mid, fit_mid
            else:
                hi = mid
        return lo, best

    def objective(x, A_start, s):
        counter[0] += 1
        const = const_of(A_start, s)
        target, J = graphs.targets(x, d[search], const)
        fit = fit_to_robot(model, target[:, :3], _unflat(target[:, 3:]), None, *weights_search, min_transmission_deg)
        ok = fit.admissible
        settings = np.r_[model.incisor, weights_search]
        z = np.where(ok[:, None], fit.q / fns.scale, 0.0)
        r = fns.errors(z, target, settings)[2]
        e = np.sqrt(np.sum(r**2, axis=1)) / weights_search[0]
        excess = np.where(ok, np.maximum(0.0, e - tau), 0.0)
        missing = (~ok).sum()  # no admissible pose near the frame: a constant penalty, no gradient
        factor = np.where(excess > 0, excess / (weights_search[0] ** 2 * np.maximum(e, 1e-300)), 0.0)
        g = factor[:, None] * fns.cost_gradient(z, target, settings)
        value = 0.5 * np.mean(excess**2) + 1e3 * missing / len(search)
        grad = np.einsum("ka,kab->b", g, J) / len(search)
        _, angle, dangle = graphs.turn(x, const)
        if angle > MAX_TRACKER_DEG:
            value += PENALTY * (angle - MAX_TRACKER_DEG) ** 2
            grad = grad + 2 * PENALTY * (angle - MAX_TRACKER_DEG) * dangle
        return value, grad

    def refine(x, A_start, s):
        step(f"refining the incisal registration at scale {s:.4g}")
        res = minimize(objective, x, args=(A_start, s), jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": ITERATIONS, "ftol": 1e-15, "gtol": 1e-12})
        return res.x

    # starts: the principal direction on each opening direction, rest at home; and the file's own placement
    starts = [(np.zeros(6), _turn_onto(rotation @ u, v, MAX_TRACKER_DEG) @ rotation) for v in directions]
    rest_file = (rotation @ point[0] + origin - home) / MM
    starts.append((np.r_[0.0, 0.0, 0.0, np.clip(rest_file, [b[0] for b in box], [b[1] for b in box])], rotation))
    scored = [(share_of(x, A)[0], k) for k, (x, A) in enumerate(starts)]
    start_share, best = max(scored)
    x, A_start = starts[best]
    notes = [f"start: the recording's principal direction {np.round(u, 3).tolist()} (tracker frame) on the robot's "
             f"{('hinge opening direction', 'opening chord', 'file placement')[best]}; share at the start {start_share:.4f}"]
    lo, hi = start_share, 1.0
    x1 = refine(x, A_start, 1.0)
    if verdict(x1, A_start, 1.0)[0].all():
        lo, x = 1.0, x1
    else:
        for _ in range(SCALE_BISECTIONS):
            mid = 0.5 * (lo + hi)
            xm = refine(x, A_start, mid)
            if verdict(xm, A_start, mid)[0].all():
                lo, x = mid, xm
            else:
                hi = mid
    share, fit = share_of(x, A_start, lo)
    const = const_of(A_start, share)
    A, angle, _ = graphs.turn(x, const)
    rest = home + x[3:6] * MM
    limiting_frames, limiting = np.zeros(0, dtype=int), ""
    if share < 1.0:
        ok_above, fit_above = verdict(x, A_start, min(1.0, share + 2.0**-BISECTIONS))
        limiting_frames = np.flatnonzero(~ok_above)
        broken = [nm for nm, b in zip(fit_above.constraint_names, fit_above.outside[~ok_above].any(axis=0)) if b]
        limiting = ", ".join(broken) if broken else "the residual tolerance (--max-residual)"
    rms = float(np.sqrt(np.nanmean(fit.position_error_mm**2 * weights_import[0] ** 2
                                   + fit.orientation_error_deg**2 * weights_import[1] ** 2))) if fit is not None else np.inf
    return FoundRegistration(A, rest - A @ point[0], {}, share, rms, limiting_frames, limiting, angle, counter[0],
                             time.perf_counter() - started, tuple(notes))
