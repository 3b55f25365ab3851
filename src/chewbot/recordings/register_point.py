"""The registration search for a point path (a recording of one point of the mandible, ``tracked`` a landmark's
name or detected, with ``--fit-registration``): where the tracker sits, so that the robot's point follows as much
of the recorded path as it can, starting from anatomy and never far from it.

The recording is a path of one point b of the mandible (the markers' mean: they move in parallel), d_k relative
to the first frame in the tracker's frame. A registration places it in {S}: the tracker's rotation A and the first
frame's point Q_0 (the tracker's origin follows, Q_0 - A times the first frame's point). At the scale s frame k's
point is Q_k = Q_0 + s A d_k, and the pose the fit is given is the hinge guess of
:func:`chewbot.recordings.robotfit.hinge_beta` (the orientation that lowers b by as much about the condylar axis,
weighed 0.1 per degree in the import's fit: it only chooses among the poses that put b on the point).

**Prior** (:func:`chewbot.recordings.anatomy.point_prior`): the face-bow triangle on the model's (three points), or
the path's principal direction on the robot's opening direction; the most closed frame at home.

**What a point path leaves free.** The robot moves a point in 3 dimensions with 4 coordinates: any path inside the
set that point reaches (condyles in their sockets, transmission angles at least ``--min-transmission``) is followed,
whatever the rotation and rest that put it there. Residuals identify the placement only where the path meets that
set's boundary; what decides is the share, the largest uniform scale s <= 1 of the registered path at which every
frame is reached within ``--max-residual`` (:mod:`chewbot.recordings.register`). Where the share at the prior is 1
the prior is the registration.

**Refinement** (:func:`chewbot.recordings.register.search`): the turn of A from the prior's within
:data:`~chewbot.recordings.register.MAX_TURN_DEG` and the first frame's point within
:data:`~chewbot.recordings.register.MAX_SHIFT_MM` per axis of the prior's (hard bounds), minimising the mean of
0.5 max(0, e_k - tau)^2 over :data:`SEARCH_FRAMES` frames (tau = :data:`MARGIN` x the tolerance): e_k is the point's
distance from the reachable set, sqrt(2 V_k) / w_p with V_k the optimal value of a fit weighing the hinge guess
only :data:`SEARCH_ORIENTATION_WEIGHT` per degree. Its gradient is exact: V_k's derivative by the recorded pose is
that of the residual at the fitted pose (Danskin's theorem; the constraints do not depend on the recording),
chained with the Jacobian of the registered poses by the unknowns (CasADi,
:class:`~chewbot.recordings.robotfit.PointRegistrationFunctions`), and d(0.5 (e - tau)^2)/dV = (e - tau) / (w_p^2 e).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial.transform import Rotation

from chewbot.model import Model
from chewbot.progress import SILENT, Progress
from chewbot.recordings.anatomy import point_prior
from chewbot.recordings.fit import fit_to_robot, screened_fit, within
from chewbot.recordings.register import PULL, FoundRegistration, angle_deg, box, limited_by, search
from chewbot.recordings.robotfit import POINT_CONST, POINT_X, fit_functions, point_registration_functions
from chewbot.units import factor

MM, DEG = factor("mm"), factor("deg")
# The search's fit weighs the hinge guess this little per degree (against 1 per mm at the point): its optimal value
# is then the point's squared distance from the reachable set, the guess only choosing among the poses that reach it.
SEARCH_ORIENTATION_WEIGHT = 0.01
# The refinement brings every frame within MARGIN x --max-residual (the import's fit, weighing the guess more, may
# end a little farther).
MARGIN = 0.8
# Frames the refinement fits per evaluation (evenly spread, plus the farthest from the rest).
SEARCH_FRAMES = 120


def _unflat(v: np.ndarray) -> np.ndarray:
    return v.reshape(-1, 3, 3).transpose(0, 2, 1)


def fit_point_registration(model: Model, positions: np.ndarray, b: np.ndarray, rotation: np.ndarray,
                           position_weight_per_mm: float, orientation_weight_per_deg: float, tolerance_mm: float,
                           min_transmission_deg: float, progress: Progress = SILENT) -> FoundRegistration:
    """Search the registration of a point path: ``positions`` (N, K, 3) m in the tracker's frame (markers moving in
    parallel), ``b`` the tracked point of {M} (m); ``rotation``: the file's tracker rotation (used only where the
    data do not fix the turn about the opening direction); the import's fit weights; ``tolerance_mm``:
    ``--max-residual``'s position (see the module)."""
    started = time.perf_counter()
    fns = fit_functions(model, min_transmission_deg)
    graphs = point_registration_functions(model)
    prior = point_prior(model, positions, b, rotation)
    point = positions.mean(axis=1)
    d = point - point[0]
    N = len(d)
    home = b  # where b is at home ({M} = {S})
    rest = (prior.rotation @ point[0] + prior.origin - home) / MM  # the prior's first-frame point from home, mm
    weights_import = (position_weight_per_mm, orientation_weight_per_deg)
    weights_search = (position_weight_per_mm, SEARCH_ORIENTATION_WEIGHT)
    settings = np.r_[b, weights_search]
    tau = MARGIN * tolerance_mm
    far = np.linalg.norm(d, axis=1)
    search_rows = np.unique(np.r_[np.linspace(0, N - 1, min(N, SEARCH_FRAMES)).round().astype(int), np.argmax(far)])
    counter = [0]

    def const(s):
        return POINT_CONST.pack(rotation=prior.rotation, scale=s, home=home, point=b)

    def unknowns(x):
        return np.r_[x[:3], rest + x[3:]]

    def verdict(x, s, rows=None):
        target, _ = graphs.targets(unknowns(x), d if rows is None else d[rows], const(s))
        return within(model, target[:, :3], _unflat(target[:, 3:]), b, *weights_import, min_transmission_deg,
                      (tolerance_mm, np.inf))

    def fitted(x, s):
        target, _ = graphs.targets(unknowns(x), d, const(s))
        return fit_to_robot(model, target[:, :3], _unflat(target[:, 3:]), b, *weights_import, min_transmission_deg)

    def objective(x, s):
        counter[0] += 1
        target, J = graphs.targets(unknowns(x), d[search_rows], const(s))
        z, ok = screened_fit(model, target[:, :3], _unflat(target[:, 3:]), b, *weights_search, min_transmission_deg,
                             tau * weights_search[0])
        r = fns.errors(z, target, settings)[2]
        e = np.sqrt(np.sum(r**2, axis=1)) / weights_search[0]
        excess = np.where(ok, np.maximum(0.0, e - tau), 0.0)
        factor = np.where(excess > 0, excess / (weights_search[0] ** 2 * np.maximum(e, 1e-300)), 0.0)
        g = factor[:, None] * fns.cost_gradient(z, target, settings)
        value = 0.5 * np.mean(excess**2) + (~ok).sum() / len(search_rows) + PULL * x @ x
        return value, np.einsum("ka,kab->b", g, J) / len(search_rows) + 2 * PULL * x

    x, share, fit, refined = search(verdict, fitted, objective, box(3, 3), progress)
    limiting_frames, limiting = limited_by(verdict, fitted, x, share)
    u = POINT_X.split(unknowns(x))
    turn = Rotation.from_rotvec(u["turn"] * DEG).as_matrix()
    A = turn @ prior.rotation
    first = home + u["rest"] * MM
    rms = float(np.sqrt(np.nanmean(fit.position_error_mm**2 * weights_import[0] ** 2
                                   + fit.orientation_error_deg**2 * weights_import[1] ** 2)))
    notes = (f"prior: {prior.how}; frame {prior.closed + 1} (the point highest) at home",)
    target, _ = graphs.targets(unknowns(x), d, const(share))
    return FoundRegistration(A, first - A @ point[0], {}, share, rms, limiting_frames, limiting, prior.rotation, prior.origin,
                             angle_deg(turn), float(np.linalg.norm(x[3:])), 0.0, 0.0, refined, counter[0],
                             time.perf_counter() - started, notes, fit, (target[:, :3], _unflat(target[:, 3:])))
