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
  that the farthest turn from it opens; then that of the first :data:`HINGE_DEG` of each opening) is the condylar
  axis, +y of {M}. Where it lies (:func:`condylar_axis`): on the plane the condyles glide on (the axis line whose
  path stays nearest to one plane: the robot's condyles slide on one), at the height of the centre of rotation of
  the smallest openings (a Posselt hinge turns about the condylar axis; where the condyles translate from the start
  that height is not seen, and the centre of rotation lies below them by their glide per radian), on the midline
  (the markers' middle: a cluster on the chin, a bite fork). The turn about the axis carries the condyles' glide
  onto the robot's condylar path, its HKP plane's line of steepest descent, forward and down (the subject's
  eminence onto the robot's plane); where the condyles glide less than :data:`MIN_GLIDE_MM` the turn is the file's
  ``[tracker]`` rotation's. The most closed frame (the smallest opening rotation) is intercuspal contact: the
  robot's home pose.
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
# Frames opened from the most closed one by more than 0.5 deg and less than this give the opening axis' direction.
HINGE_DEG = 6.0
MIN_HINGE_DEG = 0.5
# The opening's centre of rotation: the frames opened by MIN_HINGE_DEG to this, in pairs at least SMALL_PAIR_DEG
# apart (0.05 mm of marker noise on a cluster 40 mm wide: about 1 mm per pair, averaged over hundreds of pairs).
SMALL_OPENING_DEG = 2.5
SMALL_PAIR_DEG = 0.5
# ... and turning about an axis within this of the opening axis (not swinging sideways); a band's centre of rotation
# needs MIN_PAIRS such pairs.
PAIR_AXIS_DEG = 5.0
MIN_PAIRS = 20
MIN_GLIDE_MM = 1.0
# The plane of the condyles: alternations at most, and the step of the axis' point (mm) that ends them.
PLANE_ITERATIONS = 50
PLANE_STEP_MM = 1e-4
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
    (mm), how the condylar axis was found, and what was assumed where the data did not say."""

    R_B: np.ndarray
    t_B: np.ndarray
    rotation: np.ndarray
    origin: np.ndarray
    closed: int
    axis: np.ndarray
    condyles: np.ndarray
    glide_mm: float
    how: str
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
        rho = Rotation.from_matrix(np.einsum("nij,kj->nik", R_Y, R_c)).as_rotvec()  # the turns from intercuspal contact
        opening = rho @ a
        # the first part of each opening (the angle growing), where a Posselt hinge turns about the condylar axis
        # (chewing swings sideways while it closes)
        hinge = (opening > MIN_HINGE_DEG * DEG) & (opening < HINGE_DEG * DEG) & (np.gradient(opening) > 0)
        if hinge.sum() < 3:
            break
        a_h = np.linalg.svd(rho[hinge] - rho[hinge].mean(axis=0), full_matrices=False)[2][0]  # their spread, not offset
        a = a_h if a_h @ a > 0 else -a_h
        phi = rho  # the second pass measures openings from intercuspal contact
    opening = rho @ a
    middle = c.mean(axis=0)  # the markers' middle (first frame): a chin cluster or a bite fork sits on the midline
    notes = []
    if body is not None:
        R_B, t_B = (v[0] for v in kabsch(body, c[None]))
        condyles = R_B @ (0.5 * (model.hkp.T_L + model.hkp.T_R)) + t_B
        glide, how = 0.0, "the markers where [markers] puts them"
    else:
        axis = condylar_axis(R_Y, p_Y, a, closed, opening, middle, half_width(model))
        how = axis.how
        glide = axis.glide_mm
        if axis.glide is not None:
            # {M} at the most closed frame, in the tracker's frame: y on the axis, the glide on the condylar path
            M_closed = _frame(axis.glide, a) @ _frame(condylar_path(model), np.array([0.0, 1.0, 0.0])).T
        else:
            turn = _turn_onto(file_rotation.T @ np.array([0.0, 1.0, 0.0]), a)
            M_closed = turn @ file_rotation.T
            notes.append(f"the condyles glide {glide:.2g} mm (< {MIN_GLIDE_MM:g}): the turn about the condylar axis is the file's "
                         "[tracker] rotation's")
        condyles = axis.point  # the condyles' midpoint at the first frame
        # {M} at the first frame; O_M where the condyles' midpoint lies on the axis
        R_B = R_c.T @ M_closed
        t_B = condyles - R_B @ (0.5 * (model.hkp.T_L + model.hkp.T_R))
    # intercuspal contact at home: its pose X = T Y_c B = I
    rotation = (R_c @ R_B).T
    origin = -rotation @ (R_c @ t_B + p_c)
    return RigidPrior(R_B, t_B, rotation, origin, closed, a, condyles, glide, how, tuple(notes))


@dataclass(frozen=True)
class CondylarAxis:
    """Where a rigid-body recording puts the condylar axis (:func:`condylar_axis`): the condyles' midpoint at the
    first frame (m, tracker frame), the direction of their glide at intercuspal contact (unit, tracker frame; None
    where they glide less than :data:`MIN_GLIDE_MM`), how far they glide (mm) and how the axis was found."""

    point: np.ndarray
    glide: np.ndarray | None
    glide_mm: float
    how: str


def condylar_axis(R_Y: np.ndarray, p_Y: np.ndarray, a_s: np.ndarray, closed: int, opening: np.ndarray, middle: np.ndarray,
                  half: float) -> CondylarAxis:
    """The condylar axis of a rigid-body motion (R_Y, p_Y: from the first frame, tracker frame; ``a_s`` the opening
    axis at intercuspal contact, frame ``closed``, in the tracker's frame; ``opening`` (N,) rad from intercuspal
    contact; ``middle``: the markers' middle at the first frame; ``half``: half the model's intercondylar distance).

    1. *The opening's centre of rotation*: the point that the motions between frames opened by
       :data:`MIN_HINGE_DEG` to :data:`SMALL_OPENING_DEG` leave fixed (least squares over the pairs of them at least
       :data:`SMALL_PAIR_DEG` apart that turn about the opening axis, in the opening half of each cycle), on the
       midline. Where the opening starts with a hinge phase (Posselt 1952), it is the condylar axis.
    2. *The plane of the condyles*: the robot's condyles slide on one plane, and so do a subject's on a straight
       eminence, whatever the distance between them. The axis line (through a point P along the axis, sampled at
       +-``half``) whose path over every frame lies nearest to one plane: P and the plane alternately by least squares
       from the centre of rotation (:data:`PLANE_ITERATIONS`). The plane's normal and the axis give the glide's
       direction (forward: where the condyles go as the jaw opens), and the axis' place along the glide (seen at
       first order by the opening's turn: a point off the axis along the glide leaves the plane by the turn times
       its offset).
    3. *The axis' height across the glide* (along the plane's normal) is not seen at first order by any motion that
       keeps the condyles on their plane (turns about the axis or the normal, shifts along the plane): it is kept at
       the opening's centre of rotation. Where the condyles translate from the start of the opening that centre
       lies below them by their glide per radian of opening (14-35 mm in people), and the axis with it.
    """
    Rc = R_Y[closed]
    a = Rc.T @ a_s  # the axis in the first frame's coordinates
    growing = np.gradient(opening) > 0
    centre = None
    for hi, least in ((SMALL_OPENING_DEG, MIN_PAIRS), (HINGE_DEG, MIN_PAIRS), (np.inf, 1)):  # wider where too few frames
        rows = np.flatnonzero(growing & (opening > MIN_HINGE_DEG * DEG) & (opening < hi * DEG))
        centre = _fixed_point(R_Y, p_Y, rows, opening, SMALL_PAIR_DEG * DEG, a, middle, least)
        if centre is not None:
            break
    if centre is None:
        raise RecordingError("the recording never opens from intercuspal contact about one axis: no condylar axis to find")
    point, normal = _plane_axis(R_Y, p_Y, a, centre, middle, half)
    path = _moved(R_Y, p_Y, point) - _moved(R_Y, p_Y, point)[closed]
    path = path - np.outer(path @ a_s, a_s)
    n_s = normal - a_s * (a_s @ normal)
    n_s = n_s / np.linalg.norm(n_s)
    e = np.cross(a_s, n_s)
    e = e if np.corrcoef(path @ e, opening)[0, 1] > 0 else -e  # forward: where the condyles go as the jaw opens
    glide_mm = float(np.linalg.norm(path, axis=1).max() / MM)
    # the axis' height across the glide: the centre of rotation's (step 3)
    up = Rc.T @ np.cross(e, a_s)
    point = point + up * ((centre - point) @ up)
    if glide_mm < MIN_GLIDE_MM:
        return CondylarAxis(_on_midline(centre, a, middle), None, glide_mm, "the condylar axis through the opening's centre "
                            "of rotation (the condyles do not glide)")
    return CondylarAxis(_on_midline(point, a, middle), e, glide_mm, "the condylar axis on the plane its condyles glide on, "
                        "at the height of the centre of rotation of the smallest openings")


def _moved(R_Y: np.ndarray, p_Y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N, 3) where the point x of the first frame is in every frame."""
    return np.einsum("nij,j->ni", R_Y, x) + p_Y


def _on_midline(x: np.ndarray, a: np.ndarray, middle: np.ndarray) -> np.ndarray:
    """x moved along the axis direction a to the markers' middle."""
    return x + a * (a @ (middle - x))


def _fixed_point(R_Y, p_Y, rows, opening, apart, a, middle, least: int = 0) -> np.ndarray | None:
    """The point (first frame's coordinates) that the motions between the frames ``rows`` at least ``apart`` (rad) in
    opening leave fixed, by least squares over every such pair that turns about ``a`` (no frame is the reference), on
    the midline along ``a``; None where fewer than :data:`MIN_PAIRS` pairs (``least`` where given) are left."""
    j, k = (rows[i] for i in np.triu_indices(rows.size, 1))
    keep = np.abs(opening[k] - opening[j]) > apart
    j, k = j[keep], k[keep]
    # in the first frame's coordinates: the motion from frame j to k is x -> R_j^T (R_k x + p_k - p_j) for a body point
    R_jk = np.einsum("nji,njk->nik", R_Y[j], R_Y[k])
    t_jk = np.einsum("nji,nj->ni", R_Y[j], p_Y[k] - p_Y[j])
    # pairs that turn about the opening axis only: a sideways swing has its centre of rotation elsewhere
    turn = Rotation.from_matrix(R_jk).as_rotvec()
    about = np.abs(turn @ a) >= np.cos(np.radians(PAIR_AXIS_DEG)) * np.linalg.norm(turn, axis=1)
    R_jk, t_jk = R_jk[about], t_jk[about]
    if len(R_jk) < (least or MIN_PAIRS):
        return None
    A = np.vstack([(np.eye(3) - R_jk).reshape(-1, 3), a[None]])
    return np.linalg.lstsq(A, np.r_[t_jk.reshape(-1), a @ middle], rcond=None)[0]


def _plane_axis(R_Y, p_Y, a, start, middle, half) -> tuple[np.ndarray, np.ndarray]:
    """The axis line through P along ``a`` (first frame's coordinates) whose two points P +- half a stay nearest to
    one plane over every frame, and that plane's unit normal (tracker frame): alternately the plane (the smallest
    principal direction of the points' paths) and P (linear least squares, on the midline), from ``start``."""
    P = start
    for _ in range(PLANE_ITERATIONS):
        paths = np.concatenate([_moved(R_Y, p_Y, P + s * half * a) for s in (-1.0, 1.0)])
        mean = paths.mean(axis=0)
        n = np.linalg.svd(paths - mean, full_matrices=False)[2][2]
        rows = np.vstack([np.tile(np.einsum("i,nij->nj", n, R_Y), (2, 1)), a[None]])
        rhs = np.r_[np.concatenate([n @ mean - p_Y @ n - s * half * np.einsum("i,nij,j->n", n, R_Y, a) for s in (-1.0, 1.0)]),
                    a @ middle]
        P_new = np.linalg.lstsq(rows, rhs, rcond=None)[0]
        done = np.linalg.norm(P_new - P) < PLANE_STEP_MM * MM
        P = P_new
        if done:
            break
    return P, n


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
