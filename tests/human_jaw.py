"""An independent human jaw model, its anatomy drawn from published ranges, and the jaw-tracking recordings it is
seen through (not chewbot's kinematics).

Nothing here imports chewbot. The mandible's motion is written from published human jaw kinematics, in the robot's
frames only so that its true registration is known: {M} on the mandible with its origin and axes where the model
has them, {S} on the maxilla, the mandible at home (X = identity) when the teeth are in intercuspal contact, the
subject's condylar axis on the model's (+y of {M} through the model's condyles' midpoint ``MID``) and its occlusal
plane on x-y of {S}.

**A subject** (:class:`Subject`, drawn by :func:`subject` from :data:`RANGES` with a seed) differs from the robot
and from other subjects where people differ:

* the articular eminence's inclination to the occlusal plane, 25-60 deg (mean about 40): the slope of the condylar
  path, which is curved (S-shaped, steep behind the crest and flattening toward it), so that its slope falls by
  5-15 deg over its length;
* the condylar path's length at maximal opening, 10-15 mm, with the mandible turned 30-40 deg;
* whether the condyles start translating at once (half of the subjects) or after a first pure rotation of up to
  10 deg (Posselt 1952's hinge opening, found in others);
* the intercondylar distance, 90-110 mm, and Bonwill's triangle (the condyles and the incisal point, sides of
  100-110 mm), inclined to the occlusal plane by Balkwill's angle, 20-25 deg.

**Motions.** An opening turns the mandible about its condylar axis while both condyles slide forward and down the
eminence (:meth:`Subject.glide`); a lateral excursion (Bennett movement) turns it about a vertical axis through the
working condyle while the balancing condyle slides forward and down its eminence; chewing cycles
(Throckmorton et al. 2001; Pasinato et al. 2016: 1-1.5 Hz, 15-20 mm of incisal opening) open near the midline,
swing toward the working side while they close, and rest at intercuspal contact for an occlusal phase. Every
recording starts at the postural rest position, 1.6 deg open (the teeth 2-3 mm apart), not at occlusion.

**Seen by** (a) a rigid cluster of three markers on the chin (39-50 mm apart), or (b) a jaw-motion analyser that
reports the subject's face-bow (Bonwill) triangle, its incisal point and condylar points as they are at occlusion,
moved in parallel with the incisal point; through a tracker at a random rotation and position, with 0.05 mm of
noise and tracker spikes (one point jumping millimetres for a few frames).

**The true registration.** The robot's condyles slide on one plane inclined at :data:`ROBOT_PATH_DEG`; a subject's
eminence is inclined otherwise. For a rigid body the true registration is the generator's frames turned about the
condylar axis by the angle that carries this recording's condylar path (its principal direction from intercuspal
contact) onto the robot's path (:func:`robot_frames`): the subject's motion exactly, relative to the first frame,
with the skull turned so that its eminence lies along the robot's plane. That turn is the robot's, not the
registration's: the robot cannot hold a subject's occlusal plane and eminence both where the subject has them
(:func:`anatomical_turn_deg` says how far it moves the mandible's pose). For a point path it is the face-bow
transfer (:func:`face_bow_incisor`): the subject's Bonwill triangle on the model's, as a face-bow mounts casts on an
articulator.

Run as a script to write the recordings of the tests as CSV: ``python tests/human_jaw.py OUTDIR``.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

# The model's condyles' midpoint and its incisal point in {M}, mm (MODEL.md); the model's condyles at MID +- 72 y.
MID = np.array([-2.5, 0.0, 15.965])
MODEL_INCISOR = np.array([80.0, 0.0, -25.0])
MODEL_CONDYLES = np.array([[-2.5, 72.0, 15.965], [-2.5, -72.0, 15.965]])
# The robot's condyles slide on the plane 1.1 x + z - 13.215 = 0 (MODEL.md): inclined at atan(1.1).
ROBOT_PATH_DEG = float(np.degrees(np.arctan(1.1)))
REST_DEG = 1.6  # the postural rest position: the incisors 2-3 mm apart
OCCLUSAL = 0.85  # a chewing cycle's share before its occlusal phase (the teeth in contact, 0.12 s at 1.2 Hz)
SEED = 20261127


@dataclass(frozen=True)
class Range:
    """A published range of an anatomical quantity, drawn uniformly."""

    low: float
    high: float
    unit: str
    source: str


RANGES = {
    "eminence_deg": Range(25.0, 60.0, "deg",
                          "inclination of the articular eminence: means of 31.6-38.7 deg (top-roof line) and 44.1-58.4 deg "
                          "(best-fit tangent) in four populations (Katsavrias-type measures on 120 skulls, PMC8734448); "
                          "60.3 +- 10.2 deg on central slices of 64 skulls (Bilgin et al., Cranio 18 (2000) 220); "
                          "CBCT: Sumbullu et al., Dentomaxillofac Radiol 41 (2012) 234"),
    "flattening_deg": Range(5.0, 15.0, "deg",
                            "the eminence's curvature: the slope falls along the path (the tangent of the posterior slope "
                            "and the top-roof line differ by 12-20 deg in PMC8734448)"),
    "path_mm": Range(10.0, 15.0, "mm",
                     "the condylar path at maximal opening: 11.9 mm straight-line, 14 mm along the curve (Travers et al., "
                     "Arch Oral Biol 45 (2000) 267); 12.8 +- 2.8 mm (Eur J Orthod 24 (2002) 327); 14.5-15.1 +- 4.2-4.8 mm "
                     "(Kordass et al., Int J Comput Dent 17 (2014) 9)"),
    "max_opening_deg": Range(30.0, 40.0, "deg",
                             "the mandible's rotation at maximal opening: 36-39 deg (Muto and Kanazawa, J Oral Maxillofac "
                             "Surg 54 (1996) 970); 32.2 +- 6.0 deg (Kordass et al. 2014)"),
    "hinge_deg": Range(0.0, 10.0, "deg",
                       "a first pure rotation before the condyles translate: Posselt (1952); translation from the first "
                       "millimetre of opening in others (Research Square rs-3913755, Zebris JMA; the centre of rotation "
                       "of a full opening 32 +- 7 mm below the condyle: Mehl et al., Clin Oral Investig 2025, PMC12553608)"),
    "intercondylar_mm": Range(90.0, 110.0, "mm",
                              "the distance between the condyles' centres: 97-98 mm in South Indian mandibles; Bonwill's "
                              "equilateral triangle of about 100 mm"),
    "bonwill_mm": Range(100.0, 110.0, "mm",
                        "the sides from the incisal point to the condyles: 4 inches (Bonwill 1858), 10.5 cm (Korber, "
                        "Zahnarztliche Prothetik, 1985), 105-110 mm"),
    "balkwill_deg": Range(20.0, 25.0, "deg", "Balkwill's angle between Bonwill's triangle and the occlusal plane (Korber 1985)"),
}
# The share of subjects whose condyles translate from the start of the opening (hinge_deg 0).
EARLY_TRANSLATION = 0.5


@dataclass(frozen=True)
class Subject:
    """A human subject's jaw (:data:`RANGES`): the eminence's inclination at the middle of the condylar path and
    how much its slope falls along it (deg), the path's length and the rotation at maximal opening, the pure
    rotation before the condyles translate, the intercondylar distance, Bonwill's side and Balkwill's angle."""

    eminence_deg: float = 47.7
    flattening_deg: float = 8.0
    path_mm: float = 12.0
    max_opening_deg: float = 35.0
    hinge_deg: float = 0.0
    intercondylar_mm: float = 100.0
    bonwill_mm: float = 105.0
    balkwill_deg: float = 22.5

    @property
    def condyles(self) -> np.ndarray:
        """(2, 3) the left and right condyles' centres in {M}, mm."""
        half = np.array([0.0, 0.5 * self.intercondylar_mm, 0.0])
        return np.array([MID + half, MID - half])

    @property
    def incisor(self) -> np.ndarray:
        """The incisal point in {M}, mm: in the midplane, Bonwill's side from each condyle, Balkwill's angle below
        the condylar axis."""
        reach = np.sqrt(self.bonwill_mm**2 - (0.5 * self.intercondylar_mm) ** 2)
        b = np.radians(self.balkwill_deg)
        return MID + reach * np.array([np.cos(b), 0.0, -np.sin(b)])

    def eminence(self, s: np.ndarray) -> np.ndarray:
        """The condyle's displacement (N, 3) mm after an arc length s (N,) mm along the eminence, forward (+x) and
        down (-z): the slope falls linearly from eminence + flattening / 2 to eminence - flattening / 2 over the
        path's length."""
        a0 = np.radians(self.eminence_deg + 0.5 * self.flattening_deg)
        k = -np.radians(self.flattening_deg) / self.path_mm
        x = (np.sin(a0 + k * s) - np.sin(a0)) / k
        z = (np.cos(a0 + k * s) - np.cos(a0)) / k
        return np.column_stack([x, np.zeros_like(s), z])

    def glide(self, opening_deg: np.ndarray) -> np.ndarray:
        """The condyles' glide (mm along the eminence) with an opening (deg): none for the first ``hinge_deg``,
        then in proportion up to ``path_mm`` at ``max_opening_deg``, blended in over 3 deg."""
        over = opening_deg - self.hinge_deg
        rate = self.path_mm / (self.max_opening_deg - self.hinge_deg)
        return rate * np.where(over > 0, over, 0.0) * smooth(over / 3.0 if self.hinge_deg > 0 else np.ones_like(over))

    def pose(self, opening_deg: np.ndarray, lateral_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses of the mandible in {S} (p (N, 3) mm, R (N, 3, 3)) from the opening rotation about the condylar axis
        (deg, positive opens; the condyles glide with it) and the lateral turn (deg, positive: toward the left, the
        left condyle working, about a vertical axis through it; negative: toward the right)."""
        hinge = Rotation.from_euler("y", opening_deg[:, None], degrees=True).as_matrix()
        p = MID - np.einsum("nij,j->ni", hinge, MID)  # about the condylar axis, through the condyles
        left, right = self.condyles
        working = np.where(lateral_deg[:, None] >= 0, left, right)
        yaw = Rotation.from_euler("z", lateral_deg[:, None], degrees=True).as_matrix()
        # the balancing condyle slides forward as far as the turn carries it, and down its eminence
        forward = np.sin(np.abs(np.radians(lateral_deg))) * self.intercondylar_mm
        along = self.eminence(np.linspace(0.0, 2.0 * self.path_mm, 401))
        drop = np.interp(forward, along[:, 0], along[:, 2])  # the eminence's height where the condyle is
        roll = np.arctan2(drop, self.intercondylar_mm) * np.sign(lateral_deg)  # the balancing side goes down
        turn = np.einsum("nij,njk->nik", Rotation.from_euler("x", -roll[:, None]).as_matrix(), yaw)
        p = np.einsum("nij,nj->ni", turn, p - working) + working + self.eminence(self.glide(opening_deg))
        return p, np.einsum("nij,njk->nik", turn, hinge)

    def lateral_for(self, incisal_mm: float) -> float:
        """The lateral turn (deg, toward the left) that moves the incisal point ``incisal_mm`` sideways."""
        grid = np.linspace(0.0, 15.0, 1501)
        p, R = self.pose(np.zeros_like(grid), grid)
        return float(np.interp(incisal_mm, (np.einsum("nij,j->ni", R, self.incisor) + p)[:, 1] - self.incisor[1], grid))

    def opening_for(self, incisal_mm: float) -> float:
        """The opening (deg) that lowers the incisal point by ``incisal_mm`` from intercuspal contact."""
        grid = np.linspace(0.0, self.max_opening_deg, 2001)
        p, R = self.pose(grid, np.zeros_like(grid))
        drop = self.incisor[2] - (np.einsum("nij,j->ni", R, self.incisor) + p)[:, 2]
        return float(np.interp(incisal_mm, drop, grid))


def subject(seed: int) -> Subject:
    """A subject drawn from :data:`RANGES` (uniform; hinge_deg 0 for a share :data:`EARLY_TRANSLATION`)."""
    rng = np.random.default_rng(seed)
    values = {name: float(rng.uniform(r.low, r.high)) for name, r in RANGES.items()}
    if rng.uniform() < EARLY_TRANSLATION:
        values["hinge_deg"] = 0.0
    return Subject(**values)


def smooth(u: np.ndarray) -> np.ndarray:
    """0 -> 1 on u in [0, 1], C2 (quintic), clipped outside."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def pulse(phase: np.ndarray, peak: float) -> np.ndarray:
    """0 -> 1 at ``peak`` -> 0 over a phase in [0, 1), C2."""
    return np.where(phase < peak, smooth(phase / peak), smooth((1 - phase) / (1 - peak)))


def window(t: np.ndarray, start: float, length: float, peak: float = 0.5) -> np.ndarray:
    """A C2 pulse 0 -> 1 -> 0 from ``start`` over ``length`` s, largest at ``peak`` of it; 0 outside."""
    inside = (t >= start) & (t < start + length)
    return np.where(inside, pulse(np.clip((t - start) / length, 0.0, 0.999), peak), 0.0)


def sideways(phase: np.ndarray) -> np.ndarray:
    """The lateral swing of a chewing cycle: none while the jaw opens (the opening path runs down near the
    midline), toward the working side from 30 % of the cycle, largest at 60 % while it closes, back at contact."""
    return np.where(phase > 0.3, pulse(np.clip((phase - 0.3) / (OCCLUSAL - 0.3), 0.0, 0.999), 0.55), 0.0)


def cycle(phase: np.ndarray) -> np.ndarray:
    """The opening of a chewing cycle (0 -> 1 -> 0): open until 40 % of the cycle, closed again at
    :data:`OCCLUSAL`, then the teeth in intercuspal contact until the next cycle (the occlusal phase)."""
    return np.where(phase < OCCLUSAL, pulse(np.clip(phase / OCCLUSAL, 0.0, 0.999), 0.4 / OCCLUSAL), 0.0)


@dataclass(frozen=True)
class Motion:
    """A motion of a subject's mandible: times (N,) s, poses in {S} (p (N, 3) mm, R (N, 3, 3)), the subject."""

    t: np.ndarray
    p: np.ndarray
    R: np.ndarray
    subject: Subject

    def point(self, b: np.ndarray) -> np.ndarray:
        """Where the point b (3,) of {M} is, (N, 3) mm."""
        return np.einsum("nij,j->ni", self.R, b) + self.p


def _times(rate_hz: float, duration_s: float) -> np.ndarray:
    return np.arange(int(round(duration_s * rate_hz))) / rate_hz


def _closing(t: np.ndarray, at: float) -> np.ndarray:
    """From the postural rest (REST_DEG open) to intercuspal contact in 0.4 s from ``at``."""
    return REST_DEG * (1 - smooth((t - at) / 0.4))


def chewing(who: Subject, rate_hz: float = 50.0, duration_s: float = 13.0, opening_mm: float = 17.0,
            lateral_mm: float = 4.0, cycle_hz: float = 1.2, rest_s: float = 1.2) -> Motion:
    """Chewing on the left: the rest position for ``rest_s``, closing to intercuspal contact, then cycles opening
    the incisors by ``opening_mm`` at ``cycle_hz``, the jaw swinging about ``lateral_mm`` toward the left while it
    closes (:func:`cycle`, :func:`sideways`)."""
    t = _times(rate_hz, duration_s)
    start = rest_s + 0.4
    phase = np.clip((t - start) * cycle_hz, 0, None) % 1.0
    moving = t >= start
    opening = _closing(t, rest_s) + np.where(moving, who.opening_for(opening_mm) * cycle(phase), 0.0)
    lateral = np.where(moving, who.lateral_for(lateral_mm) * sideways(phase), 0.0)
    return Motion(t, *who.pose(opening, lateral), who)


def border(who: Subject, rate_hz: float = 50.0, duration_s: float = 13.0, opening_mm: float = 36.0,
           lateral_mm: float = 9.0) -> Motion:
    """Border movements and chewing (Posselt's envelope, scaled into the robot's reach): from rest, close; an
    opening of the incisors by ``opening_mm`` (a human's maximal 40-50 mm, scaled) and back; a left and a right
    lateral excursion of about ``lateral_mm`` at the incisor; then chewing cycles on the left."""
    t = _times(rate_hz, duration_s)
    opening = _closing(t, 0.8) + who.opening_for(opening_mm) * window(t, 1.5, 3.0)
    yaw = who.lateral_for(lateral_mm)
    lateral = yaw * (window(t, 5.0, 1.6) - window(t, 7.0, 1.6))
    phase = np.clip((t - 9.0) * 1.2, 0, None) % 1.0
    chew = t >= 9.0
    opening = opening + np.where(chew, who.opening_for(14.0) * cycle(phase), 0.0)
    lateral = lateral + np.where(chew, 0.5 * yaw * sideways(phase), 0.0)
    return Motion(t, *who.pose(opening, lateral), who)


def tapping(who: Subject, rate_hz: float = 50.0, duration_s: float = 8.0, opening_deg: float = 5.0) -> Motion:
    """Small openings, as a chin cluster recorded them (issue 28's first recording: rotation up to about 5 deg,
    its markers moving up to 9 mm, settling after 6 s): from rest, three openings by up to ``opening_deg`` more, with
    a slight sideways swing, then the teeth closed and still."""
    t = _times(rate_hz, duration_s)
    opening = REST_DEG * (1 - smooth((t - 5.6) / 0.6))
    opening = opening + sum(a * window(t, s, 1.5) for a, s in ((opening_deg, 0.6), (0.5 * opening_deg, 2.3), (0.7 * opening_deg, 4.0)))
    lateral = 0.6 * window(t, 2.3, 1.5, 0.6)
    return Motion(t, *who.pose(opening, lateral), who)


def wide_opening(who: Subject, rate_hz: float = 50.0, duration_s: float = 12.7, incisal_mm: float = 44.0) -> Motion:
    """Two maximal openings, as a jaw-motion analyser recorded them (issue 28's second recording: the incisal point
    44 mm down and about 34 mm back, 12.7 s at 50 Hz): from rest, close, open until the incisor is ``incisal_mm``
    below intercuspal contact and close, twice, then rest. Not scaled into the robot's reach."""
    t = _times(rate_hz, duration_s)
    peak = who.opening_for(incisal_mm)
    opening = _closing(t, 0.6) + peak * (window(t, 1.4, 4.4) + window(t, 6.6, 4.4))
    return Motion(t, *who.pose(opening, np.zeros_like(t)), who)


# ------------------------------------------------------------------------------------------------- the truth

def condylar_path(motion: Motion) -> np.ndarray:
    """The principal direction (unit, sagittal, forward and down) of the condyles' midpoint's path from
    intercuspal contact (home), over the motion."""
    path = motion.point(MID) - MID
    path[:, 1] = 0.0
    d = np.linalg.svd(path, full_matrices=False)[2][0]
    return d if d[0] > 0 else -d


def anatomical_turn_deg(motion: Motion) -> float:
    """The turn about the condylar axis (deg, positive about +y) that carries the motion's condylar path onto the
    robot's: the part of the difference between the subject's anatomy and the robot's pose that is the robot's."""
    d = condylar_path(motion)
    return ROBOT_PATH_DEG - float(np.degrees(np.arctan2(-d[2], d[0])))  # a turn about +y steepens a path forward


def robot_frames(motion: Motion, p: np.ndarray | None = None, R: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The true registration of a rigid-body recording (module docstring): the poses (p (N, 3) mm, R (N, 3, 3)) of
    the motion (or the poses given, of the same subject, e.g. seen through a filter) turned about the condylar axis
    by :func:`anatomical_turn_deg`: X' = G X G^-1, G the turn about MID."""
    p, R = (motion.p, motion.R) if p is None else (p, R)
    G = Rotation.from_euler("y", anatomical_turn_deg(motion), degrees=True).as_matrix()
    turned = np.einsum("ij,njk,lk->nil", G, R, G)
    mid = np.einsum("ij,nj->ni", G, np.einsum("nij,j->ni", R, MID) + p - MID) + MID  # the condyles' midpoint, turned
    return mid - np.einsum("nij,j->ni", turned, MID), turned


def face_bow_rotation(who: Subject) -> np.ndarray:
    """The rotation carrying the subject's Bonwill triangle onto the model's (the face-bow transfer): the condylar
    axis on +y, the direction from the condyles' midpoint to the incisal point on the model's."""
    def frame(incisor):
        x = incisor - MID
        x = x / np.linalg.norm(x)
        return np.column_stack([x, [0.0, 1.0, 0.0], np.cross(x, [0.0, 1.0, 0.0])])

    return frame(MODEL_INCISOR) @ frame(who.incisor).T


def face_bow_incisor(motion: Motion) -> np.ndarray:
    """The true registration of a point path (the face-bow transfer): the subject's incisal path (N, 3) mm,
    turned so that its triangle lies on the model's, at the model's incisor at intercuspal contact."""
    return (motion.point(motion.subject.incisor) - motion.subject.incisor) @ face_bow_rotation(motion.subject).T + MODEL_INCISOR


# ------------------------------------------------------------------------------------------ seen by a tracker

@dataclass(frozen=True)
class Tracker:
    """Where the tracker is: p_S = rotation p_T + origin (mm)."""

    rotation: np.ndarray
    origin: np.ndarray

    def see(self, points_S: np.ndarray) -> np.ndarray:
        return (points_S - self.origin) @ self.rotation


def tracker(seed: int) -> Tracker:
    rng = np.random.default_rng(seed)
    return Tracker(Rotation.random(random_state=rng).as_matrix(), rng.uniform(-400.0, 400.0, 3))


def observe(points_T: np.ndarray, rng, noise_mm: float = 0.05, spikes=((0.31, 3), (0.67, 2)), spike_mm: float = 3.0) -> np.ndarray:
    """Noise on every coordinate and tracker spikes: at each (fraction of the recording, frames) one point jumps."""
    out = points_T + rng.normal(scale=noise_mm, size=points_T.shape)
    n = len(out)
    for k, (where, frames) in enumerate(spikes):
        first = int(where * n)
        jump = rng.normal(size=3)
        out[first:first + frames, k % out.shape[1]] += spike_mm * jump / np.linalg.norm(jump)
    return out


def chin(who: Subject) -> np.ndarray:
    """(3, 3) a chin cluster's markers in {M} (mm): 39-50 mm apart, on the midline below the incisors."""
    return who.incisor + np.array([[-8.0, 22.0, -27.0], [-8.0, -22.0, -27.0], [18.0, 0.0, -7.0]])


def chin_cluster(motion: Motion, seen_by: Tracker, rng, **noise) -> np.ndarray:
    """(N, 3, 3) the chin cluster's markers in the tracker's frame (mm)."""
    points = np.einsum("nij,kj->nki", motion.R, chin(motion.subject)) + motion.p[:, None]
    return observe(seen_by.see(points), rng, **noise)


def face_bow(motion: Motion, seen_by: Tracker, rng, turn_deg: float = 0.0, **noise) -> np.ndarray:
    """(N, 3, 3) a jaw-motion analyser's output: the subject's face-bow triangle (incisal point, left and right
    condylar points at intercuspal contact) moved in parallel with the incisal point, in the tracker's frame (mm);
    ``turn_deg``: the triangle also turns, in proportion to the incisor's drop, by up to this about its base (an
    analyser's imperfect parallel transport)."""
    who = motion.subject
    incisor = motion.point(who.incisor)
    triangle = np.vstack([who.incisor, who.condyles]) - who.incisor
    drop = who.incisor[2] - incisor[:, 2]
    tilt = Rotation.from_euler("y", turn_deg * drop[:, None] / max(drop.max(), 1e-9), degrees=True).as_matrix()
    return observe(seen_by.see(incisor[:, None] + np.einsum("nij,kj->nki", tilt, triangle)), rng, **noise)


def write_csv(path: Path, t: np.ndarray, points: np.ndarray, names=("P1", "P2", "P3")) -> Path:
    head = ["t [s]"] + [f"{n}_{a} [mm]" for n in names[: points.shape[1]] for a in "xyz"]
    rows = np.column_stack([t, points.reshape(len(t), -1)])
    path.write_text(",".join(head) + "\n" + "\n".join(",".join(f"{v:.4f}" for v in row) for row in rows) + "\n")
    return path


REGISTRATION = 'units = "mm"\nrest = "first"\nscale = 1.0\n'


@dataclass(frozen=True)
class Written:
    """A recording written to ``path`` (its registration beside it, ``.toml``), the motion seen, the tracker."""

    path: Path
    motion: Motion
    tracker: Tracker


def recordings(out: Path, seed: int = SEED) -> dict[str, Written]:
    """Write the recordings of one subject (:func:`subject` of ``seed``; the seed itself the robot-like subject
    of the first suite, :data:`SEED`): the chin cluster chewing (13 s at 50 Hz) and the jaw-motion analyser's
    border movements and chewing (13 s at 50 Hz), with registration files that give only units, rest and scale
    (as a lab with a new tracker writes them)."""
    rng = np.random.default_rng(seed)
    who = Subject(eminence_deg=52.0, hinge_deg=10.0, path_mm=14.0, max_opening_deg=40.0) if seed == SEED else subject(seed)
    out.mkdir(parents=True, exist_ok=True)
    found = {}
    for name, motion, view in (("cluster", chewing(who), chin_cluster), ("analyser", border(who), face_bow)):
        where = tracker(int(rng.integers(1 << 30)))
        path = write_csv(out / f"{name}.csv", motion.t, view(motion, where, rng))
        path.with_suffix(".toml").write_text(REGISTRATION)
        found[name] = Written(path, motion, where)
    return found


# The subject of issue 28's two recordings (a long mandible that turns far and glides little: the analyser's
# incisal point goes 44 mm down and 33 mm back) and their seed.
ISSUE_SUBJECT = Subject(eminence_deg=40.0, flattening_deg=10.0, path_mm=10.0, max_opening_deg=40.0, hinge_deg=8.0,
                        intercondylar_mm=92.0, bonwill_mm=110.0, balkwill_deg=25.0)
ISSUE_SEED = 28


def issue_recordings(out: Path, seed: int = ISSUE_SEED) -> dict[str, Written]:
    """Write recordings like issue 28's two real ones: a chin cluster's small openings (8 s at 50 Hz, two tracker
    spikes) and a jaw-motion analyser's maximal openings (12.7 s at 50 Hz, the triangle turning up to 1.4 deg, the
    incisal point 44 mm down), with registration files that give only units, rest and scale."""
    rng = np.random.default_rng(seed)
    out.mkdir(parents=True, exist_ok=True)
    found = {}
    cluster = tapping(ISSUE_SUBJECT)
    analyser = wide_opening(ISSUE_SUBJECT)
    for name, motion, view in (("tapping", cluster, lambda m, w, r: chin_cluster(m, w, r, spikes=((0.3, 2), (0.55, 3)))),
                               ("wide_opening", analyser, lambda m, w, r: face_bow(m, w, r, turn_deg=1.4, spikes=()))):
        where = tracker(int(rng.integers(1 << 30)))
        path = write_csv(out / f"{name}.csv", motion.t, view(motion, where, rng))
        path.with_suffix(".toml").write_text(REGISTRATION)
        found[name] = Written(path, motion, where)
    return found


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(".")
    recordings(folder)
    issue_recordings(folder)
