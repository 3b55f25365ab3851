"""The search for a registration (``chewbot import-motion --fit-registration``): where the tracker sits and where
the markers sit on the mandible, so that the robot reproduces as much of the recording as it can.

The recording, seen by the tracker, is a motion Y_k of the markers (Y_0 = I: the first frame is the rest frame).
A registration places it on the robot: B = (R_B, t_B), the pose of {M} in the tracker's frame at rest (the
markers' placement on the mandible), and X_0 = (R_0, p_0), the rest pose of {M} in {S}; frame k is then
X_k = X_0 B^-1 Y_k B and the tracker sits at T = X_0 B^-1 (what the registration file's ``[tracker]`` holds, with
the markers at R_B^T (c - t_B) in {M}, c their rest positions).

**Share.** The largest uniform scale s <= 1 of the registered motion (displacement of O_M and rotation angle
relative to the rest frame, :func:`chewbot.recordings.rigid.scale_motion`) at which every frame is reached within
``--max-residual`` by an admissible pose (:func:`chewbot.recordings.fit.fit_to_robot`: condyles in their sockets,
every transmission angle at least ``--min-transmission``). Found by bisection (:data:`BISECTIONS`).

**Search.**

1. Physics start (``rest = "first"``: the placement is unknown). The recording's dominant rotation axis (the
   principal direction of the frames' rotation vectors, signed like the largest rotation, which is the opening)
   is put on the model's condylar axis (the line through T_L and T_R, +y of {M}: a positive rotation about it
   opens the mouth), at the point that the frames' rotations leave fixed (least squares over the frames
   rotating more than :data:`AXIS_MIN_DEG`), moved along the axis to the markers' middle. The rotation about the
   axis is the file's, turned by the smallest rotation that aligns the axes. With a ``[markers]`` table the
   placement is the lab's and is kept; only the rest pose is searched. The rest pose starts at the robot's
   admissible pose nearest to the file's rest pose (``rest = "first"``: home), an interior pose.
2. Local refinement (L-BFGS-B, SciPy) of the rest pose and the placement, minimising the fit's mean weighted
   residual 0.5 abs(r)^2 over :data:`SEARCH_FRAMES` frames at the current scale. Its gradient is exact: at a
   fitted pose the derivative of the fit's optimal value with respect to the recorded pose is that of the
   residual (the constraints do not depend on the recording: Danskin's theorem), chained with the Jacobian of
   the registered poses by the unknowns (CasADi, :class:`~chewbot.recordings.robotfit.RegistrationFunctions`).
   Bounds: the rest pose within each coordinate's reachable range (:mod:`chewbot.recordings.reach`), the
   tracker's rotation within :data:`MAX_TRACKER_DEG` of the file's (so that an opening stays an opening) and
   every marker within :data:`PLAUSIBLE_MM` of the model's incisor point (on the teeth, a bite fork or the chin),
   both as quadratic penalties; and a small pull (:data:`PRIOR`) toward the file's tracker rotation, which decides
   where residuals do not. Refined at s = 1, then, if the share falls short of 1, again at the share found;
   the registration with the larger share is kept (the start's among them), and of equal shares the smaller
   residual.

**Identifiability.** On the target the HKPs put both condyles on one plane, p1 x + z + p2 = 0, which every
motion of the robot keeps: moving the tracker by a rotation about the plane's normal or a translation along the
plane changes no residual. A recording identifies the other three components of the tracker's placement (the
plane's tilt, two angles, and its height) and, through the sockets and the chains' reach, bounds the three in
the plane; among those, the search keeps the placement nearest to its start. The 6RSS reaches every pose near
home: there no component is identified by residuals alone.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from chewbot.errors import RecordingError
from chewbot.model import Model
from chewbot.recordings.fit import fit_to_robot, settings_vector
from chewbot.recordings.reach import reach
from chewbot.recordings.rigid import kabsch
from chewbot.recordings.robotfit import fit_functions, registration_functions
from chewbot.units import factor

MAX_TRACKER_DEG = 30.0
PLAUSIBLE_MM = 100.0
# Frames the refinement fits per evaluation (evenly spread, plus the largest rotation and displacement).
SEARCH_FRAMES = 120
# Frames rotating less than this do not locate the rotation axis.
AXIS_MIN_DEG = 1.0
# The share's bisection steps on [0, 1]: resolution 2^-12 = 2.4e-4.
BISECTIONS = 12
# L-BFGS-B iterations per refinement.
ITERATIONS = 60
# Weight of the penalties (residual units per deg^2 beyond the tracker bound, per mm^2 beyond the markers' bound).
PENALTY = 10.0
# Weight of the tracker's rotation away from the file's (residual units per deg^2): where the residual does not
# tell the placements apart (the plane's symmetries, a rotation about a hinge axis), the search keeps the one
# nearest to what the lab measured. Small beside the residual's curvature in the identified directions: on the
# tests' synthetic recording 1e-4 moved the plane's tilt by 0.57 deg, 1e-6 by 0.006 deg, 1e-8 by 2e-4 deg.
PRIOR = 1e-8
MM, DEG = factor("mm"), factor("deg")


@dataclass(frozen=True, eq=False)
class FoundRegistration:
    """What the search found (SI): the tracker ``rotation`` (3, 3) and ``origin`` (3,) (p_S = rotation p_T +
    origin), the ``markers`` {name: position in {M}}, the ``share`` (see the module), the RMS of the weighted
    residual over all frames at that share, the frames (indices) and constraints that limit it (the frames that
    fail just above it), the tracker's rotation away from the file's (deg), the start's rotation axis in {M}
    and the time taken."""

    rotation: np.ndarray
    origin: np.ndarray
    markers: dict[str, np.ndarray]
    share: float
    residual: float
    limiting_frames: np.ndarray
    limiting: str
    tracker_change_deg: float
    evaluations: int
    seconds: float
    notes: tuple[str, ...]


def _flat(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) -> (N, 9) column by column, as the graphs take matrices."""
    return np.swapaxes(R, 1, 2).reshape(len(R), 9)


def _unflat(v: np.ndarray) -> np.ndarray:
    return v.reshape(-1, 3, 3).transpose(0, 2, 1)


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


def _physics_start(R_Y, p_Y, c, R_B_file):
    """R_B, t_B putting the recording's dominant rotation axis on the condylar axis (see the module)."""
    phi = Rotation.from_matrix(R_Y).as_rotvec()
    k = int(np.argmax(np.linalg.norm(phi, axis=1)))
    if np.linalg.norm(phi[k]) < AXIS_MIN_DEG * DEG:
        raise RecordingError(f"the recording rotates at most {np.degrees(np.linalg.norm(phi[k])):.3g} deg: no rotation axis "
                             "to put on the condylar axis; give the markers in {M} ([markers])")
    a = np.linalg.svd(phi, full_matrices=False)[2][0]
    a = a if a @ phi[k] > 0 else -a
    current = R_B_file @ np.array([0.0, 1.0, 0.0])
    cross = np.cross(current, a)
    turn = Rotation.from_rotvec(cross / max(np.linalg.norm(cross), 1e-300) * np.arctan2(np.linalg.norm(cross), current @ a))
    R_B = turn.as_matrix() @ R_B_file
    use = np.linalg.norm(phi, axis=1) > AXIS_MIN_DEG * DEG
    lhs = (np.eye(3) - R_Y[use]).reshape(-1, 3)
    point = np.linalg.lstsq(lhs, p_Y[use].reshape(-1), rcond=None)[0]
    point += a * (a @ (c.mean(axis=0) - point))
    return R_B, point, a


def fit_registration(model: Model, positions: np.ndarray, names: tuple[str, ...], rotation: np.ndarray,
                     origin: np.ndarray, markers: dict[str, np.ndarray] | None, point, weights: tuple[float, float],
                     tolerances: tuple[float, float], min_transmission_deg: float, progress=None) -> FoundRegistration:
    """Search the registration of the marker paths ``positions`` (N, K, 3) m in the tracker's frame (named
    ``names``), starting from the file's tracker ``rotation``, ``origin`` and ``markers`` in {M} (None:
    ``rest = "first"``). ``weights``: the fit's (per mm, per deg); ``tolerances``: ``--max-residual`` (mm, deg)."""
    started = time.perf_counter()
    step = progress or (lambda message: None)
    fns = fit_functions(model, min_transmission_deg)
    reg = registration_functions(model)
    settings = settings_vector(model, point, *weights)
    n, N = fns.n, len(positions)
    c = positions[0]
    R_Y, p_Y = kabsch(c, positions)
    notes = []
    if markers is not None:
        body = np.array([markers[name] for name in names])
        R_B, t_B = (v[0] for v in kabsch(body, c[None]))
        X0_p, X0_R = rotation @ t_B + origin, rotation @ R_B
        fixed = True
    else:
        R_B, point_axis, axis = _physics_start(R_Y, p_Y, c, rotation.T)
        hkp = model.hkp
        t_B = point_axis - R_B @ (0.5 * (hkp.T_L + hkp.T_R))
        X0_p, X0_R = np.zeros(3), np.eye(3)
        fixed = False
        notes.append(f"start: the recording's rotation axis {np.round(axis, 3).tolist()} (tracker frame) on the condylar "
                     f"axis, through {np.round(point_axis / MM, 2).tolist()} mm (tracker frame)")
    rest = fit_to_robot(model, X0_p[None], X0_R[None], point, *weights, min_transmission_deg)
    z0 = rest.q[0] / fns.scale if rest.admissible[0] else np.zeros(n)
    const = np.r_[_flat(R_B[None])[0], t_B, 1.0]

    ranges = reach(model, min_transmission_deg).coordinates
    bounds = [ranges[name] for name in fns.coords] + [(-10.0, 10.0)] * (6 - n)
    bounds += [(0.0, 0.0)] * 6 if fixed else [(-45.0, 45.0)] * 3 + [(-30.0, 30.0)] * 3
    x0 = np.r_[np.clip(z0, [b[0] for b in bounds[:n]], [b[1] for b in bounds[:n]]), np.zeros(12 - n)]

    phi = Rotation.from_matrix(R_Y).as_rotvec()
    search = np.unique(np.r_[np.linspace(0, N - 1, min(N, SEARCH_FRAMES)).round().astype(int),
                             np.argmax(np.linalg.norm(phi, axis=1)), np.argmax(np.linalg.norm(p_Y, axis=1))])
    D = _flat(R_Y - np.eye(3))
    counter = [0]

    def frames_at(s, rows):
        return np.hstack([_flat(Rotation.from_rotvec(s * phi[rows]).as_matrix()), D[rows], p_Y[rows]])

    def penalty(x):
        v, J = reg.placement(x, const)
        A, dA = _unflat(v[None, :9])[0], J[:9].reshape(3, 3, 12).transpose(1, 0, 2)
        t_b, dt = v[9:12], J[9:12]
        Rb, dRb = _unflat(v[None, 12:21])[0], J[12:21].reshape(3, 3, 12).transpose(1, 0, 2)
        # 2 (1 - cos theta) ~ theta^2 (rad^2), smooth at theta = 0
        k = np.degrees(1.0) ** 2
        value = PRIOR * k * (3.0 - np.trace(rotation.T @ A))
        grad = -PRIOR * k * np.einsum("ij,ijk->k", rotation, dA)
        cos = np.clip((np.trace(rotation.T @ A) - 1) / 2, -1.0, 1.0)
        angle = np.degrees(np.arccos(cos))
        if angle > MAX_TRACKER_DEG:
            dangle = -np.degrees(1.0) / np.sqrt(max(1 - cos**2, 1e-300)) * 0.5 * np.einsum("ij,ijk->k", rotation, dA)
            value += PENALTY * (angle - MAX_TRACKER_DEG) ** 2
            grad += 2 * PENALTY * (angle - MAX_TRACKER_DEG) * dangle
        if not fixed:
            rel = c - t_b  # (K, 3)
            m = rel @ Rb  # R_B^T (c - t_B), rows
            dm = np.einsum("kj,jil->kil", rel, dRb) - np.einsum("ji,jl->il", Rb, dt)[None]
            off = m - model.incisor
            dist = np.linalg.norm(off, axis=1) / MM
            over = dist > PLAUSIBLE_MM
            if over.any():
                ddist = np.einsum("ki,kil->kl", off[over], dm[over]) / (np.linalg.norm(off[over], axis=1)[:, None] * MM) / MM
                value += PENALTY * np.sum((dist[over] - PLAUSIBLE_MM) ** 2)
                grad += 2 * PENALTY * np.einsum("k,kl->l", dist[over] - PLAUSIBLE_MM, ddist)
        return value, grad

    def objective(x, s):
        counter[0] += 1
        const[12] = s
        target, J = reg.targets(x, frames_at(s, search), const)
        fit = fit_to_robot(model, target[:, :3], _unflat(target[:, 3:]), point, *weights, min_transmission_deg)
        ok = fit.admissible
        z = np.where(ok[:, None], fit.q / fns.scale, 0.0)
        r = fns.errors(z, target, settings)[2]
        cost = np.where(ok, 0.5 * np.sum(r**2, axis=1), 1e6)
        g = np.where(ok[:, None], fns.cost_gradient(z, target, settings), 0.0)
        value, grad = penalty(x)
        return cost.mean() + value, np.einsum("ka,kab->b", g, J) / len(search) + grad

    def registered(x, s):
        const[12] = s
        target, _ = reg.targets(x, frames_at(s, np.arange(N)), const)
        return target[:, :3], _unflat(target[:, 3:])

    def verdict(x, s):
        p, R = registered(x, s)
        fit = fit_to_robot(model, p, R, point, *weights, min_transmission_deg)
        ok = fit.admissible & (fit.position_error_mm <= tolerances[0]) & (fit.orientation_error_deg <= tolerances[1])
        return ok, fit

    def share_of(x):
        ok, fit = verdict(x, 1.0)
        if ok.all():
            return 1.0, fit, ok
        lo, hi, best = 0.0, 1.0, (None, None)
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            ok_mid, fit_mid = verdict(x, mid)
            if ok_mid.all():
                lo, best = mid, (fit_mid, ok_mid)
            else:
                hi = mid
        return lo, best[0], best[1]

    def refine(x, s):
        step(f"refining the registration at scale {s:.4g}")
        res = minimize(objective, x, args=(s,), jac=True, method="L-BFGS-B", bounds=bounds, options={"maxiter": ITERATIONS, "ftol": 1e-15, "gtol": 1e-9})
        return res.x

    start_share, start_fit, _ = share_of(x0)
    candidates = [(start_share, x0, start_fit)]  # the start itself: the search never ends below it
    x = refine(x0, 1.0)
    share, fit, ok = share_of(x)
    candidates.append((share, x, fit))
    if share < 1.0 and share > 0.0:
        x2 = refine(x, share)
        share2, fit2, ok2 = share_of(x2)
        candidates.append((share2, x2, fit2))

    def rms(fit):
        if fit is None:
            return np.inf
        return float(np.sqrt(np.nanmean(fit.position_error_mm**2 * weights[0] ** 2 + fit.orientation_error_deg**2 * weights[1] ** 2)))

    share, x, fit = max(candidates, key=lambda cand: (round(cand[0], 6), -rms(cand[2])))
    limiting_frames, limiting = np.zeros(0, dtype=int), ""
    if share < 1.0:
        above = min(1.0, share + 2.0**-BISECTIONS)
        ok_above, fit_above = verdict(x, above)
        limiting_frames = np.flatnonzero(~ok_above)
        broken = [nm for nm, b in zip(fit_above.constraint_names, fit_above.outside[~ok_above].any(axis=0)) if b]
        limiting = ", ".join(broken) if broken else "the residual tolerance (--max-residual)"
    v, _ = reg.placement(x, const)
    A, t_b, Rb = _unflat(v[None, :9])[0], v[9:12], _unflat(v[None, 12:21])[0]
    p_rest = registered(x, 1.0)[0][0]  # p_0: the rest frame does not move (Y_0 = I)
    origin_found = p_rest - A @ t_b
    found_markers = {name: Rb.T @ (c[k] - t_b) for k, name in enumerate(names)}
    return FoundRegistration(A, origin_found, found_markers, share, rms(fit), limiting_frames, limiting,
                             _angle_deg(rotation.T @ A), counter[0], time.perf_counter() - started, tuple(notes))
