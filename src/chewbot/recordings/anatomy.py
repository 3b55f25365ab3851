"""What a recording tracks, and where anatomy puts it on the robot before any search (the prior of
``--fit-registration``).

**What was recorded** (:func:`detect`), from the prepared marker paths in the tracker's frame:

* one marker, two, or markers on one line: the path of **one point** (their mean);
* three or more: the rigid body they form is fitted to every frame (Kabsch, from the first frame). Its largest
  rotation theta (deg) and the largest displacement e of the markers' mean (mm) are compared through the
  mandible's lever L, the distance from the condyles' midpoint to the model's incisal point (92 mm on the
  built-in models): a mandible that opens turns, and moves a point near its teeth by about L theta, so
  rho = L theta / e is near 1 for a rigid body on the jaw (0.8-1.1 on the tests' human jaw, 0.9 on a recorded
  chin cluster) and near 0 for points that move in parallel (a jaw-motion analyser's face-bow triangle moved by
  the incisal point: 0.05). The recording is a **rigid body** when theta >= :data:`MIN_ROTATION_DEG` and
  rho >= :data:`MIN_LEVER_RATIO`, and otherwise **points moving in parallel**: the path of one point.

**The prior** puts the recording on the robot by anatomy alone; every direction and point of it is found from the
recording itself, so that the prior (and the search from it) does not depend on how the tracker is turned.

* Rigid body (:func:`rigid_prior`): the opening rotation axis (the principal direction of the frames' rotation
  vectors, signed like the largest rotation from the first frame: the rest frame is at or near the closed end, so
  that the farthest turn from it opens) is the condylar axis, +y of {M}; it passes through the point that
  the motions from the most closed frame to the frames opened by less than :data:`HINGE_DEG` leave fixed (least
  squares: the initial opening is a rotation about the condylar axis, Posselt 1952), moved along the axis to the
  markers' middle (a cluster on the chin, a bite fork: on the midline). The turn about that axis carries the
  condyles' glide (the principal direction of that point's path) onto the robot's condylar path, its HKP plane's
  line of steepest descent, forward and down; where the condyles glide less than :data:`MIN_GLIDE_MM` the turn is
  the file's ``[tracker]`` rotation's. The most closed frame (the smallest opening rotation) is intercuspal
  contact: the robot's home pose.
* Point path (:func:`point_prior`): with three points or more, they are a face-bow triangle (the incisal point
  and the two condylar points, Bonwill's triangle, moved in parallel): its apex (the vertex whose two edges are
  most nearly equal) is the incisal point, the opposite edge is the condylar axis, and the triangle is turned
  onto the model's (incisal point and condyles at home): the edge on +y of {S}, the direction from its middle to
  the apex on the direction from the model's condyles to its incisor. With one or two points, or more than three,
  the path's principal direction (signed toward the frame farthest from the first) is carried onto the
  robot's opening direction (the tracked point's velocity when the mandible turns about the condylar axis at
  home; for a condyle, the line of steepest descent of its plane) by the smallest turn from the file's
  ``[tracker]`` rotation. The frame where the point is highest along the robot's up (+z of {S}) is intercuspal
  contact: the point is where the model's point is at home.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from chewbot.errors import RecordingError
from chewbot.model import Model
from chewbot.recordings.rigid import kabsch
from chewbot.recordings.robotfit import MIN_LEVER_MM
from chewbot.units import factor

MM, DEG = factor("mm"), factor("deg")
MIN_ROTATION_DEG = 2.0
MIN_LEVER_RATIO = 0.25
# Frames turned by at most CLOSED_DEG and moved by at most CLOSED_MM (the markers' middle) from the most closed
# one are intercuspal contact (their mean pose).
CLOSED_DEG = 0.3
CLOSED_MM = 0.3
# Frames opened from the most closed one by more than 0.5 deg and less than this locate the hinge axis.
HINGE_DEG = 9.5
MIN_HINGE_DEG = 0.5
# Hinge frames at least this far apart in opening make a pair (small turns give noisy fixed points).
PAIR_DEG = 3.0
MIN_GLIDE_MM = 1.0
# The share of the frames farthest from the glide's line left out of its second fit.
TRIM = 0.1
# Two vertices' pairs of edges differing by less than this share of the edges are equally isosceles.
ISOSCELES = 0.02


@dataclass(frozen=True)
class Detected:
    """What a recording tracks: ``kind`` "rigid" or "point"; the largest rotation of the markers' rigid body
    (deg, NaN where they do not form one), the largest displacement of their mean (mm), rho and why."""

    kind: str
    rotation_deg: float
    excursion_mm: float
    lever_ratio: float
    reason: str

    def describe(self) -> str:
        what = "a rigid body that rotates" if self.kind == "rigid" else "the path of one point"
        return f"detected: {what} ({self.reason})"


def lever_mm(model: Model) -> float:
    """The distance from the condyles' midpoint to the model's incisal point, mm."""
    return float(np.linalg.norm(model.incisor - 0.5 * (model.hkp.T_L + model.hkp.T_R)) / MM)


def detect(model: Model, positions: np.ndarray) -> Detected:
    """What the marker paths ``positions`` (N, K, 3) m track (the module's rule)."""
    from chewbot.recordings.registration import collinear

    mean = positions.mean(axis=1)
    excursion = float(np.linalg.norm(mean - mean[0], axis=1).max() / MM)
    K = positions.shape[1]
    if K < 3 or collinear(positions[0]):
        why = "one marker" if K == 1 else f"{K} markers on one line" if K > 2 else "two markers"
        return Detected("point", float("nan"), excursion, float("nan"), f"{why}: no rotation to measure")
    R, _ = kabsch(positions[0], positions)
    theta = float(np.degrees(np.linalg.norm(Rotation.from_matrix(R).as_rotvec(), axis=1).max()))
    ratio = lever_mm(model) * np.radians(theta) / max(excursion, 1e-9)
    rule = (f"largest rotation {theta:.3g} deg, largest excursion {excursion:.3g} mm: rho = L theta / e = {ratio:.3g} "
            f"with L = {lever_mm(model):.3g} mm")
    if theta >= MIN_ROTATION_DEG and ratio >= MIN_LEVER_RATIO:
        return Detected("rigid", theta, excursion, ratio, f"{rule} >= {MIN_LEVER_RATIO:g}, theta >= {MIN_ROTATION_DEG:g} deg")
    return Detected("point", theta, excursion, ratio, f"{K} markers moving in parallel: {rule}, below "
                    f"{MIN_LEVER_RATIO:g} or theta below {MIN_ROTATION_DEG:g} deg")


def _turn_onto(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation carrying the unit vector a onto the unit vector b."""
    cross = np.cross(a, b)
    return Rotation.from_rotvec(cross / max(np.linalg.norm(cross), 1e-300) * np.arctan2(np.linalg.norm(cross), a @ b)).as_matrix()


def _principal(v: np.ndarray) -> np.ndarray:
    """The principal direction (unit) of the vectors v (N, 3) about 0, robustly: fitted again without the
    :data:`TRIM` share of them farthest from the first fit's line (frames filled across a spike, a glitch)."""
    g = np.linalg.svd(v, full_matrices=False)[2][0]
    off = np.linalg.norm(v - np.outer(v @ g, g), axis=1)
    keep = off <= np.quantile(off, 1 - TRIM)
    return np.linalg.svd(v[keep], full_matrices=False)[2][0]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _frame(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The rotation whose columns are x (made perpendicular to y), y and x cross y; y is kept."""
    y = y / np.linalg.norm(y)
    x = x - y * (y @ x)
    x = x / np.linalg.norm(x)
    return np.column_stack([x, y, np.cross(x, y)])


def condylar_path(model: Model) -> np.ndarray:
    """The robot's condylar path in {S}: its HKP plane's line of steepest descent, forward and down (unit)."""
    d = np.array([1.0, 0.0, -model.hkp.p1])
    return d / np.linalg.norm(d)


@dataclass(frozen=True)
class RigidPrior:
    """The anatomical registration of a rigid-body recording: ``R_B``, ``t_B`` the pose of {M} in the tracker's
    frame at the first frame; the tracker ``rotation``, ``origin`` (p_S = rotation p_T + origin); the most closed
    frame (at home), the axis (tracker frame), the condylar point on it (m, tracker frame, first frame), the glide
    (mm) and what was assumed where the data did not say."""

    R_B: np.ndarray
    t_B: np.ndarray
    rotation: np.ndarray
    origin: np.ndarray
    closed: int
    axis: np.ndarray
    condyles: np.ndarray
    glide_mm: float
    notes: tuple[str, ...]


def rigid_prior(model: Model, positions: np.ndarray, file_rotation: np.ndarray, body: np.ndarray | None = None) -> RigidPrior:
    """The prior of a rigid-body recording ``positions`` (N, K, 3) m in the tracker's frame (module docstring).
    ``body`` (K, 3): the markers in {M} where the lab gave them (their placement is then the lab's: only the most
    closed frame is put at home); ``file_rotation``: the file's tracker rotation, used only where the condyles do
    not glide."""
    c = positions[0]
    R_Y, p_Y = kabsch(c, positions)
    phi = Rotation.from_matrix(R_Y).as_rotvec()
    norms = np.linalg.norm(phi, axis=1)
    k = int(np.argmax(norms))
    if norms[k] < MIN_ROTATION_DEG * DEG:
        raise RecordingError(f"the recording rotates at most {np.degrees(norms[k]):.3g} deg: no opening axis to put on the "
                             "condylar axis (tracked = \"incisor\" registers it as a point path)")
    a = np.linalg.svd(phi, full_matrices=False)[2][0]
    a = a if a @ phi[k] > 0 else -a  # the rest frame is at or near the closed end: the farthest turn from it opens
    for _ in range(2):  # the axis of all frames first (chewing's sideways swing tilts it), then the hinge's
        R_c, p_c, closed = _intercuspal(R_Y, p_Y, phi @ a)
        # the motions from intercuspal contact: rotation R_Y[k] R_c^T, translation p_k - R p_c
        Rr = np.einsum("nij,kj->nik", R_Y, R_c)
        tr = p_Y - np.einsum("nij,j->ni", Rr, p_c)
        rho = Rotation.from_matrix(Rr).as_rotvec()
        opening = rho @ a
        # the hinge: frames opening (the angle growing) from intercuspal contact by MIN_HINGE_DEG to HINGE_DEG, where
        # a mandible turns about its condylar axis (chewing swings sideways while it closes)
        hinge = (opening > MIN_HINGE_DEG * DEG) & (opening < HINGE_DEG * DEG) & (np.gradient(opening) > 0)
        if hinge.sum() < 3:
            hinge = opening > MIN_HINGE_DEG * DEG
            break
        a_h = np.linalg.svd(rho[hinge] - rho[hinge].mean(axis=0), full_matrices=False)[2][0]  # their spread, not offset
        a = a_h if a_h @ a > 0 else -a_h
        phi = rho  # the second pass measures openings from intercuspal contact
    opening = rho @ a
    notes = []
    if body is not None:
        R_B, t_B = (v[0] for v in kabsch(body, c[None]))
        condyles = R_B @ (0.5 * (model.hkp.T_L + model.hkp.T_R)) + t_B
        glide = 0.0
    else:
        # the point that the motions between hinge frames (opened at least MIN_HINGE_DEG apart) leave fixed:
        # R_jk x + t_jk = x, R_jk = R_k R_j^T, t_jk = p_k - R_jk p_j (all pairs: no frame is the reference)
        rows = np.flatnonzero(hinge)
        j, k2 = (rows[i] for i in np.triu_indices(rows.size, 1))
        keep = np.abs(opening[k2] - opening[j]) > PAIR_DEG * DEG
        j, k2 = j[keep], k2[keep]
        R_jk = np.einsum("nij,nkj->nik", R_Y[k2], R_Y[j])
        t_jk = p_Y[k2] - np.einsum("nij,nj->ni", R_jk, p_Y[j])
        point = np.linalg.lstsq((np.eye(3) - R_jk).reshape(-1, 3), t_jk.reshape(-1), rcond=None)[0]
        middle = R_c @ c.mean(axis=0) + p_c  # the markers' middle at intercuspal contact
        point = point + a * (a @ (middle - point))  # on the midline
        path = np.einsum("nij,j->ni", Rr, point) + tr - point
        path = path - a * (path @ a)[:, None]
        glide = float(np.linalg.norm(path, axis=1).max() / MM)
        if glide >= MIN_GLIDE_MM:
            g = _principal(path[~hinge])
            g = g if g @ path[int(np.argmax(opening))] > 0 else -g
            # {M} at the most closed frame, in the tracker's frame: y on the axis, the glide on the condylar path
            M_closed = _frame(g, a) @ _frame(condylar_path(model), np.array([0.0, 1.0, 0.0])).T
        else:
            turn = _turn_onto(file_rotation.T @ np.array([0.0, 1.0, 0.0]), a)
            M_closed = turn @ file_rotation.T
            notes.append(f"the condyles glide {glide:.2g} mm (< {MIN_GLIDE_MM:g}): the turn about the condylar axis is the file's "
                         "[tracker] rotation's")
        condyles = R_c.T @ (point - p_c)  # the condyles' midpoint at the first frame
        # {M} at the first frame; O_M where the condyles' midpoint lies on the axis
        R_B = R_c.T @ M_closed
        t_B = condyles - R_B @ (0.5 * (model.hkp.T_L + model.hkp.T_R))
    # intercuspal contact at home: its pose X = T Y_c B = I
    rotation = (R_c @ R_B).T
    origin = -rotation @ (R_c @ t_B + p_c)
    return RigidPrior(R_B, t_B, rotation, origin, closed, a, condyles, glide, tuple(notes))


def _intercuspal(R_Y: np.ndarray, p_Y: np.ndarray, opening: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Intercuspal contact: the mean pose (R, p) of the frames opened by at most :data:`CLOSED_DEG` more than the
    most closed, and within CLOSED_DEG and :data:`CLOSED_MM` (O of the markers' frame) of the one nearest to the
    others among them (each chewing cycle returns there: their mean, not one frame, which may be a filled spike or
    still swung sideways); and the frame nearest to it."""
    candidates = np.flatnonzero(opening <= opening.min() + CLOSED_DEG * DEG)
    Rc, pc = R_Y[candidates], p_Y[candidates]
    turned = np.linalg.norm(Rotation.from_matrix(np.einsum("nij,mkj->nmik", Rc, Rc).reshape(-1, 3, 3)).as_rotvec(),
                            axis=1).reshape(len(candidates), -1)
    moved = np.linalg.norm(pc[:, None] - pc[None], axis=2)
    close = (turned <= CLOSED_DEG * DEG) & (moved <= CLOSED_MM * MM)
    near = candidates[close[int(np.argmax(close.sum(axis=1)))]]
    u, _, vt = np.linalg.svd(R_Y[near].sum(axis=0))
    R = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    p = p_Y[near].mean(axis=0)
    return R, p, int(near[np.argmin(np.linalg.norm(p_Y[near] - p, axis=1))])


def half_width(model: Model) -> float:
    """Half the distance between the model's condyles (m)."""
    return float(0.5 * np.linalg.norm(model.hkp.T_L - model.hkp.T_R))


@dataclass(frozen=True)
class PointPrior:
    """The anatomical registration of a point path: the tracker ``rotation`` and ``origin``, the most closed frame
    (where the point is at the model's point at home), how the rotation was found."""

    rotation: np.ndarray
    origin: np.ndarray
    closed: int
    how: str


def opening_direction(model: Model, b: np.ndarray) -> np.ndarray:
    """The direction (unit, {S}) in which the point b (3,) of {M} moves when the mandible opens from home: its
    velocity for a turn about the condylar axis; a point within :data:`MIN_LEVER_MM` of the axis (a condyle)
    glides along the condylar path instead."""
    r = b - 0.5 * (model.hkp.T_L + model.hkp.T_R)
    r[1] = 0.0
    if np.linalg.norm(r) < MIN_LEVER_MM * MM:
        return condylar_path(model)
    v = np.cross([0.0, 1.0, 0.0], r)
    return v / np.linalg.norm(v)


def point_prior(model: Model, positions: np.ndarray, b: np.ndarray, file_rotation: np.ndarray) -> PointPrior:
    """The prior of a point path (module docstring): ``positions`` (N, K, 3) m in the tracker's frame, ``b`` the
    tracked point of {M} (m)."""
    point = positions.mean(axis=1)
    d = point - point[0]
    far = np.linalg.norm(d, axis=1)
    if far.max() < 1 * MM:
        raise RecordingError(f"the tracked point moves at most {far.max() / MM:.3g} mm: no opening direction to register")
    u = np.linalg.svd(d - d.mean(axis=0), full_matrices=False)[2][0]
    u = u if u @ d[int(np.argmax(far))] > 0 else -u
    how = None
    K = positions.shape[1]
    from chewbot.recordings.registration import collinear

    if K == 3 and not collinear(positions[0]):
        tri = positions[0]
        # the apex (the incisal point) is the vertex whose two edges are most nearly equal (Bonwill's triangle is
        # isosceles); where two vertices are as good, the lateral edge is the one most nearly perpendicular to the path
        sides = [(abs(np.linalg.norm(tri[k] - tri[(k + 1) % 3]) - np.linalg.norm(tri[k] - tri[(k + 2) % 3])), k) for k in range(3)]
        sides.sort()
        scale = np.mean([np.linalg.norm(tri[k] - tri[(k + 1) % 3]) for k in range(3)])
        if sides[1][0] - sides[0][0] < ISOSCELES * scale:
            apex = max((sides[0][1], sides[1][1]), key=lambda k: 1 - abs(u @ _unit(tri[(k + 2) % 3] - tri[(k + 1) % 3])))
        else:
            apex = sides[0][1]
        i, j = (apex + 1) % 3, (apex + 2) % 3
        forward = tri[apex] - 0.5 * (tri[i] + tri[j])
        y = tri[j] - tri[i]
        y = y if np.cross(forward, y) @ -u > 0 else -y  # x forward, y left, z up: the path opens down
        C = 0.5 * (model.hkp.T_L + model.hkp.T_R)
        model_frame = _frame(model.incisor - C, model.hkp.T_L - model.hkp.T_R)
        rotation = model_frame @ _frame(forward, y).T
        how = f"the face-bow triangle: point {apex + 1} the incisal point, points {i + 1} and {j + 1} the condylar points"
    if how is None:
        rotation = _turn_onto(file_rotation @ u, opening_direction(model, b)) @ file_rotation
        how = "the path's principal direction on the robot's opening direction, turned least from the file's [tracker] rotation"
    closed = int(np.argmax(point @ rotation.T[:, 2]))  # highest along +z of {S}
    origin = b - rotation @ point[closed]
    return PointPrior(rotation, origin, closed, how)
