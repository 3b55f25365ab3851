"""The search for a registration (``chewbot import-motion --fit-registration``): where the tracker sits and where
the markers sit on the mandible, so that the robot reproduces as much of the recording as it can, starting from
anatomy and never far from it.

The recording, seen by the tracker, is a motion Y_k of the markers (Y_0 = I: the first frame is the rest frame).
A registration places it on the robot: B = (R_B, t_B), the pose of {M} in the tracker's frame at the first frame
(the markers' placement on the mandible), and the tracker T = (A, o), p_S = A p_T + o; frame k is then
X_k = T Y_k B (what the registration file's ``[tracker]`` holds, with the markers at R_B^T (c - t_B) in {M}, c their
first positions).

**Prior** (:mod:`chewbot.recordings.anatomy`): the opening axis on the condylar axis, the condyles' glide on the
robot's condylar path, the most closed frame at home; with a ``[markers]`` table the placement is the lab's.

**Share.** The largest uniform scale s <= 1 of the registered motion (displacement of O_M and rotation angle
relative to the first frame, :func:`chewbot.recordings.rigid.scale_motion`) at which every frame is reached within
``--max-residual`` by an admissible pose (:func:`chewbot.recordings.fit.fit_to_robot`: condyles in their sockets,
every transmission angle at least ``--min-transmission``). Found by bisection (:data:`BISECTIONS`); at each step the
frames that failed at the last failing scale are fitted first, alone, and the whole recording only where they all
pass (a failing step then costs the fit of a few frames, not of all).

**Search** (:func:`search`, shared with the point paths' :mod:`chewbot.recordings.register_point`). The share at
the prior comes first: where it is 1 the prior is the registration, nothing the data say moves it. Otherwise the
registration is refined around the prior, within hard bounds (box bounds of L-BFGS-B, SciPy): the tracker turned by
at most :data:`MAX_TURN_DEG` (each component of its rotation vector within MAX_TURN_DEG / sqrt(3)) and shifted by
at most :data:`MAX_SHIFT_MM` along each axis about the prior's rest position of O_M; the markers' placement
likewise (rest = "first" only). The refinement minimises the mean over :data:`SEARCH_FRAMES` frames of
0.5 max(0, e_k - :data:`MARGIN`)^2, e_k the fit's residual in tolerances (position over ``--max-residual``'s MM,
orientation over its DEG), plus :data:`PULL` |x|^2 toward the prior: frames within the tolerance do not pull,
and what the data do not fix stays where the prior put it. Its gradient is exact: the derivative of the fit's
optimal value by the recorded pose is that of the residual at the fitted pose (the constraints do not depend on
the recording: Danskin's theorem), chained with the Jacobian of the registered poses by the unknowns (CasADi,
:class:`~chewbot.recordings.robotfit.RegistrationFunctions`). It runs at s = 1; if not every frame then passes,
the share is bisected (:data:`SCALE_BISECTIONS` refinements) between the prior's and 1.

**What a recording identifies.** On the target the HKPs put both condyles on one plane, p1 x + z + p2 = 0, which
every motion of the robot keeps: moving the registration by a rotation about the plane's normal or a translation
along the plane changes no residual, and those components keep the prior's values. A turn of the placement about
the condylar axis moves only the glide's direction, and a shift of the axis perpendicular to the glide moves the
condyles, to first order, along the plane: neither is seen by residuals either.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from chewbot.errors import RecordingError
from chewbot.model import Model
from chewbot.progress import SILENT, Progress
from chewbot.recordings.anatomy import RigidPrior, rigid_prior
from chewbot.recordings.fit import fit_to_robot, screened_fit, settings_vector, within
from chewbot.recordings.rigid import kabsch
from chewbot.recordings.robotfit import REGISTRATION_CONST, REGISTRATION_X, fit_functions, registration_functions
from chewbot.units import factor

# Hard bounds of the search around the prior: the tracker's (and the placement's) turn, deg, and shift per axis, mm.
MAX_TURN_DEG = 10.0
MAX_SHIFT_MM = 5.0
# Frames the refinement fits per evaluation (evenly spread, plus the largest rotation and displacement).
SEARCH_FRAMES = 120
# The share's bisection steps on [0, 1]: resolution 2^-12 = 2.4e-4.
BISECTIONS = 12
# Refinements while bisecting the share between the prior's and 1.
SCALE_BISECTIONS = 5
# L-BFGS-B iterations per refinement.
ITERATIONS = 40
# The refinement brings every frame within MARGIN of the tolerance (in tolerances; the import's fit may end a
# little farther).
MARGIN = 0.8
# Poses whose positions (m) and rotation matrices differ by less than this are the same to rounding.
SAME_POSE = 1e-12
# Pull toward the prior (per deg^2 and mm^2 of the unknowns): decides where the residuals do not.
PULL = 1e-6
MM, DEG = factor("mm"), factor("deg")


@dataclass(frozen=True, eq=False)
class FoundRegistration:
    """What the search found (SI): the tracker ``rotation`` (3, 3) and ``origin`` (3,) (p_S = rotation p_T +
    origin), the ``markers`` {name: position in {M}} (none for a point path), the ``share`` (see the module), the
    RMS of the weighted residual over all frames at that share, the frames (indices) and constraints that limit it
    (the frames that fail just above it); the prior's tracker, and how far the registration moved from it: the
    tracker's turn (deg) and the shift of the rest pose (mm), the placement's turn (deg) and shift (mm); whether
    the search refined the prior at all, evaluations, the time taken and notes."""

    rotation: np.ndarray
    origin: np.ndarray
    markers: dict[str, np.ndarray]
    share: float
    residual: float
    limiting_frames: np.ndarray
    limiting: str
    prior_rotation: np.ndarray
    prior_origin: np.ndarray
    turn_deg: float
    shift_mm: float
    placement_turn_deg: float
    placement_shift_mm: float
    refined: bool
    evaluations: int
    seconds: float
    notes: tuple[str, ...]
    fit: object = None  # the fit (RobotFit) of every frame registered at the share, and those poses (p (N, 3), R (N, 3, 3))
    poses: tuple[np.ndarray, np.ndarray] | None = None

    def fit_of(self, p: np.ndarray, R: np.ndarray):
        """The search's fit of these poses where they are the ones it fitted (to rounding), else None: the import
        need not fit them again."""
        if self.poses is None or self.fit is None or len(p) != len(self.poses[0]):
            return None
        same = np.abs(p - self.poses[0]).max() <= SAME_POSE and np.abs(R - self.poses[1]).max() <= SAME_POSE
        return self.fit if same else None

    def describe(self) -> str:
        """How far the registration found lies from the prior, in a line."""
        if not self.refined:
            return "registration: the prior (every frame reached at scale 1 there; nothing moved it)"
        text = (f"registration: refined from the prior within its bounds ({MAX_TURN_DEG:g} deg, {MAX_SHIFT_MM:g} mm per axis): "
                f"tracker turned {self.turn_deg:.3g} deg, rest pose moved {self.shift_mm:.3g} mm")
        if self.markers:
            text += f"; markers' placement turned {self.placement_turn_deg:.3g} deg and moved {self.placement_shift_mm:.3g} mm"
        return text


def angle_deg(R: np.ndarray) -> float:
    """The rotation angle of R (3, 3), deg."""
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


def box(n_turn: int, n_shift: int, free: bool = True) -> list[tuple[float, float]]:
    """L-BFGS-B bounds: turns (deg) within MAX_TURN_DEG / sqrt(3) per component (so within MAX_TURN_DEG in all),
    shifts (mm) within MAX_SHIFT_MM; fixed at 0 where not ``free``."""
    t, s = (MAX_TURN_DEG / np.sqrt(3), MAX_SHIFT_MM) if free else (0.0, 0.0)
    return [(-t, t)] * n_turn + [(-s, s)] * n_shift


def search(verdict, fitted, objective, bounds, progress: Progress) -> tuple[np.ndarray, float, object, bool]:
    """The search of the module docstring, for any registration: ``verdict(x, s, rows=None)`` -> whether each frame
    passes (N,) (or each of ``rows``) at the unknowns x (0: the prior) and the scale s, which needs no pose
    (:func:`chewbot.recordings.fit.within`); ``fitted(x, s)`` -> the fit of every frame (RobotFit), computed once,
    at the share found; ``objective(x, s)`` -> (value, gradient); ``bounds`` of x (L-BFGS-B). Returns x, the share,
    its fit and whether the prior was refined."""
    n = len(bounds)

    def share_of(x, lo=0.0):
        ok = verdict(x, 1.0)
        if ok.all():
            return 1.0
        hi, failing = 1.0, np.flatnonzero(~ok)
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            ok_few = verdict(x, mid, failing)  # the frames that failed last first: one failing decides
            if not ok_few.all():
                hi, failing = mid, failing[~ok_few]
                continue
            ok_mid = verdict(x, mid)
            if ok_mid.all():
                lo = mid
            else:
                hi, failing = mid, np.flatnonzero(~ok_mid)
        return lo

    def refine(x, s):
        progress(f"refining the registration around its prior at scale {s:.4g}")
        res = minimize(objective, x, args=(s,), jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": ITERATIONS, "ftol": 1e-15, "gtol": 1e-12})
        return res.x

    x = np.zeros(n)
    prior_share = share_of(x)
    if prior_share == 1.0:
        return x, 1.0, fitted(x, 1.0), False
    lo, hi = prior_share, 1.0
    x1 = refine(x, 1.0)
    if verdict(x1, 1.0).all():
        x, lo = x1, 1.0
    else:
        for _ in range(SCALE_BISECTIONS):
            mid = 0.5 * (lo + hi)
            xm = refine(x, mid)
            if verdict(xm, mid).all():
                lo, x = mid, xm
            else:
                hi = mid
    share = share_of(x, lo)
    if share == 0.0:
        raise RecordingError("--fit-registration: the robot reaches no scale of the recording registered at its prior, not "
                             "even its first frame within --max-residual (is it a motion of the jaw, and does tracked "
                             "name the point it gives?)")
    if share < prior_share:  # never below the prior
        return np.zeros(n), prior_share, fitted(np.zeros(n), prior_share), False
    return x, share, fitted(x, share), True


def limited_by(verdict, fitted, x, share) -> tuple[np.ndarray, str]:
    """The frames that fail just above the share, and the constraints they break."""
    if share >= 1.0:
        return np.zeros(0, dtype=int), ""
    above = min(1.0, share + 2.0**-BISECTIONS)
    ok_above = verdict(x, above)
    frames = np.flatnonzero(~ok_above)
    fit_above = fitted(x, above)
    broken = [nm for nm, b in zip(fit_above.constraint_names, fit_above.outside[~ok_above].any(axis=0)) if b]
    return frames, ", ".join(broken) if broken else "the residual tolerance (--max-residual)"


def fit_registration(model: Model, positions: np.ndarray, names: tuple[str, ...], rotation: np.ndarray,
                     markers: dict[str, np.ndarray] | None, point, weights: tuple[float, float],
                     tolerances: tuple[float, float], min_transmission_deg: float, progress: Progress = SILENT) -> FoundRegistration:
    """Search the registration of the marker paths ``positions`` (N, K, 3) m in the tracker's frame (named
    ``names``) from its anatomical prior; ``rotation``: the file's tracker rotation (used only where the condyles
    do not glide); ``markers`` in {M} (None: ``rest = "first"``, the placement is searched). ``weights``: the
    fit's (per mm, per deg); ``tolerances``: ``--max-residual`` (mm, deg)."""
    started = time.perf_counter()
    fns = fit_functions(model, min_transmission_deg)
    reg = registration_functions(model)
    N = len(positions)
    c = positions[0]
    body = None if markers is None else np.array([markers[name] for name in names])
    prior: RigidPrior = rigid_prior(model, positions, rotation, body)
    R_Y, p_Y = kabsch(c, positions)
    phi = Rotation.from_matrix(R_Y).as_rotvec()
    D = np.swapaxes(R_Y - np.eye(3), 1, 2).reshape(N, 9)
    centre = prior.rotation @ prior.t_B + prior.origin  # the prior's rest position of O_M
    search_rows = np.unique(np.r_[np.linspace(0, N - 1, min(N, SEARCH_FRAMES)).round().astype(int),
                                  np.argmax(np.linalg.norm(phi, axis=1)), np.argmax(np.linalg.norm(p_Y, axis=1))])
    # the search's fit weighs errors in tolerances: its residual's length is 1 where a frame is at its tolerance
    settings = settings_vector(model, point, 1.0 / tolerances[0], 1.0 / tolerances[1])
    counter = [0]

    def const(s):
        return REGISTRATION_CONST.pack(rotation=prior.rotation, origin=prior.origin, centre=centre, R_B=prior.R_B,
                                       t_B=prior.t_B, scale=s)

    def frames(s, rows):  # rows laid out as robotfit.REGISTRATION_FRAME: [exp(s phi_k); R_Y,k - I; p_Y,k]
        turned = Rotation.from_rotvec(s * phi[rows]).as_matrix()
        return np.hstack([np.swapaxes(turned, 1, 2).reshape(len(rows), 9), D[rows], p_Y[rows]])

    def poses(x, s, rows):
        target, J = reg.targets(x, frames(s, rows), const(s))
        return target, J

    def verdict(x, s, rows=None):
        target, _ = poses(x, s, np.arange(N) if rows is None else rows)
        return within(model, target[:, :3], _unflat(target[:, 3:]), point, *weights, min_transmission_deg, tolerances)

    def fitted(x, s):
        target, _ = poses(x, s, np.arange(N))
        return fit_to_robot(model, target[:, :3], _unflat(target[:, 3:]), point, *weights, min_transmission_deg)

    def objective(x, s):
        counter[0] += 1
        target, J = poses(x, s, search_rows)
        z, ok = screened_fit(model, target[:, :3], _unflat(target[:, 3:]), point, 1.0 / tolerances[0], 1.0 / tolerances[1],
                             min_transmission_deg, MARGIN)
        r = fns.errors(z, target, settings)[2]
        e = np.sqrt(np.sum(r**2, axis=1))
        excess = np.where(ok, np.maximum(0.0, e - MARGIN), 0.0)
        factor = np.where(excess > 0, excess / np.maximum(e, 1e-300), 0.0)
        g = factor[:, None] * fns.cost_gradient(z, target, settings)
        value = 0.5 * np.mean(excess**2) + (~ok).sum() / len(search_rows) + PULL * x @ x
        return value, np.einsum("ka,kab->b", g, J) / len(search_rows) + 2 * PULL * x

    bounds = box(3, 3) + box(3, 3, free=markers is None)
    x, share, fit, refined = search(verdict, fitted, objective, bounds, progress)
    limiting_frames, limiting = limited_by(verdict, fitted, x, share)
    u = REGISTRATION_X.split(x)
    turn = Rotation.from_rotvec(u["turn"] * DEG).as_matrix()
    A = turn @ prior.rotation
    origin = turn @ (prior.origin - centre) + centre + u["shift"] * MM
    R_B = prior.R_B @ Rotation.from_rotvec(u["placement_turn"] * DEG).as_matrix()
    t_B = prior.t_B + prior.R_B @ u["placement_shift"] * MM
    found_markers = {name: R_B.T @ (c[k] - t_B) for k, name in enumerate(names)}
    target, _ = poses(x, share, np.arange(N))
    rest = A @ t_B + origin
    rms = float(np.sqrt(np.nanmean(fit.position_error_mm**2 * weights[0] ** 2 + fit.orientation_error_deg**2 * weights[1] ** 2)))
    notes = list(prior.notes)
    if markers is None:
        notes.append(f"prior: the opening axis {np.round(prior.axis, 3).tolist()} (tracker frame) on the condylar axis ({prior.how}), "
                     f"the condyles gliding {prior.glide_mm:.3g} mm on the robot's condylar path, frame {prior.closed + 1} (the most "
                     "closed) at home")
    else:
        notes.append(f"prior: the markers where [markers] puts them, frame {prior.closed + 1} (the most closed) at home")
    return FoundRegistration(A, origin, found_markers, share, rms, limiting_frames, limiting, prior.rotation, prior.origin,
                             angle_deg(turn), float(np.linalg.norm(rest - centre) / MM),
                             float(np.linalg.norm(u["placement_turn"])), float(np.linalg.norm(u["placement_shift"])), refined,
                             counter[0], time.perf_counter() - started, tuple(notes), fit, (target[:, :3], _unflat(target[:, 3:])))


def _unflat(v: np.ndarray) -> np.ndarray:
    """(N, 9) column by column -> (N, 3, 3)."""
    return v.reshape(-1, 3, 3).transpose(0, 2, 1)
