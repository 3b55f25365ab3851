"""An independent human jaw model, and the jaw-tracking recordings it is seen through (not chewbot's kinematics).

Nothing here imports chewbot: the mandible's motion is written from published human jaw kinematics, in the
robot's frames only so that its true registration is known ({M} at the mandible, {S} on the maxilla, the
mandible at home when the teeth are in intercuspal contact; the model's condyles and incisor point, mm):

* **Opening** is a rotation about the condylar (hinge) axis while both condyles slide forward and down along
  the articular eminence. Posselt (1952): the first part of an opening is nearly a pure rotation, the condyles
  then translate; at maximal opening the incisor has moved 40-50 mm, the mandible has turned 25-40 deg and the
  condyles have moved 10-20 mm (Muto and Kanazawa 1996: 18-20 mm and 36-39 deg of ramus rotation, cephalometry).
  The condyle's path is curved: the eminence is S-shaped, steep on its posterior slope and flattening toward the
  crest; its sagittal inclination is 33 deg to Camper's plane and 40-45 deg to the Frankfort horizontal, with a
  wide spread between subjects. Here the path's slope turns from :data:`SLOPE_START_DEG` to
  :data:`SLOPE_END_DEG` below the occlusal plane over its length (a subject with a steep eminence, so that
  the robot, whose condyles slide on a plane at 47.7 deg, can follow it), so that the path leaves its chord by
  about 0.2 mm: a curve, not a line.
* **Lateral excursions** (Bennett movement): the mandible turns about a vertical axis through the working-side
  condyle, while the balancing condyle slides forward, inward and down its eminence (the mandible rolls so that
  it follows the eminence's slope).
* **Chewing cycles** (Throckmorton et al. 2001; Pasinato et al. 2016): 1-1.5 Hz, 15-20 mm of incisal opening,
  the jaw swinging toward the working side while it closes and returning to intercuspal contact at the end of
  each cycle (a tear-drop in the frontal plane).

A recording starts at the postural rest position (the teeth apart by 2-3 mm: not at occlusion), and is seen by
(a) a rigid cluster of three markers on the chin, or (b) a jaw-motion analyser that reports three points of the
face-bow (Bonwill) triangle, the incisal point and the two condylar points as they are at occlusion, moved in
parallel with the incisal point; through a tracker at a random rotation and position, with 0.05 mm of noise
and tracker spikes (one point jumping millimetres for a few frames).

Run as a script to write the recordings of the tests as CSV: ``python tests/human_jaw.py OUTDIR``.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

# The model's condyle centres and incisal point in {M}, mm (MODEL.md): the human jaw is placed on them.
CONDYLE_L = np.array([-2.5, 72.0, 15.965])
CONDYLE_R = np.array([-2.5, -72.0, 15.965])
INCISOR = np.array([80.0, 0.0, -25.0])
SLOPE_START_DEG = 56.0
SLOPE_END_DEG = 48.0
EMINENCE_MM = 14.0  # the path's length, over which its slope turns
REST_DEG = 1.6
OCCLUSAL = 0.85  # a chewing cycle's share before its occlusal phase (the teeth in contact, 0.12 s at 1.2 Hz)  # postural rest: the incisor about 2.5 mm below intercuspal contact
# Three markers of a chin cluster in {M} (mm): 39-50 mm apart, centred on the midline below the incisors.
CHIN = np.array([[72.0, 22.0, -52.0], [72.0, -22.0, -52.0], [98.0, 0.0, -32.0]])
SEED = 20261127


def eminence(s: np.ndarray) -> np.ndarray:
    """The condyle's displacement (N, 3) mm along the curved eminence after an arc length s (N,) mm: forward (+x)
    and down (-z), the slope turning linearly from SLOPE_START_DEG to SLOPE_END_DEG over EMINENCE_MM."""
    a0, a1 = np.radians(SLOPE_START_DEG), np.radians(SLOPE_END_DEG)
    k = (a1 - a0) / EMINENCE_MM
    # integral of (cos, -sin)(a0 + k u) du from 0 to s
    x = (np.sin(a0 + k * s) - np.sin(a0)) / k
    z = (np.cos(a0 + k * s) - np.cos(a0)) / k
    return np.column_stack([x, np.zeros_like(s), z])


def pose(opening_deg: np.ndarray, glide_mm: np.ndarray, lateral_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Poses of the mandible in {S} (p (N, 3) mm, R (N, 3, 3)) from the opening rotation about the condylar axis
    (deg, positive opens), the glide of the condyles along the eminence (mm) and the lateral turn (deg, positive:
    toward the left, the left condyle working, about a vertical axis through it; negative: toward the right)."""
    n = len(opening_deg)
    mid = 0.5 * (CONDYLE_L + CONDYLE_R)
    hinge = Rotation.from_euler("y", opening_deg[:, None], degrees=True).as_matrix()
    p = mid - np.einsum("nij,j->ni", hinge, mid)  # about the condylar axis, through the condyles
    R = hinge
    # lateral: yaw about the working condyle's vertical axis, and the roll that drops the balancing condyle along
    # the eminence as far as it slid forward
    working = np.where(lateral_deg[:, None] >= 0, CONDYLE_L, CONDYLE_R)
    yaw = Rotation.from_euler("z", lateral_deg[:, None], degrees=True).as_matrix()
    forward = np.abs(np.radians(lateral_deg)) * (CONDYLE_L[1] - CONDYLE_R[1])
    drop = eminence(forward)[:, 2]
    roll = np.arctan2(drop, CONDYLE_L[1] - CONDYLE_R[1]) * np.sign(lateral_deg)  # balancing side goes down
    roll_R = Rotation.from_euler("x", -roll[:, None]).as_matrix()
    turn = np.einsum("nij,njk->nik", roll_R, yaw)
    p = np.einsum("nij,nj->ni", turn, p - working) + working
    R = np.einsum("nij,njk->nik", turn, R)
    p = p + eminence(glide_mm)
    assert p.shape == (n, 3)
    return p, R


def smooth(u: np.ndarray) -> np.ndarray:
    """0 -> 1 on u in [0, 1], C2 (quintic), clipped outside."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def pulse(phase: np.ndarray, peak: float) -> np.ndarray:
    """0 -> 1 at ``peak`` -> 0 over a phase in [0, 1), C2."""
    return np.where(phase < peak, smooth(phase / peak), smooth((1 - phase) / (1 - peak)))


def sideways(phase: np.ndarray) -> np.ndarray:
    """The lateral swing of a chewing cycle: none while the jaw opens (the opening path runs down near the
    midline), toward the working side from 30 % of the cycle, largest at 60 % while it closes, back at contact."""
    return np.where(phase > 0.3, pulse(np.clip((phase - 0.3) / (OCCLUSAL - 0.3), 0.0, 0.999), 0.55), 0.0)


def cycle(phase: np.ndarray) -> np.ndarray:
    """The opening of a chewing cycle (0 -> 1 -> 0): open until 40 % of the cycle, closed again at
    :data:`OCCLUSAL`, then the teeth in intercuspal contact until the next cycle (the occlusal phase)."""
    return np.where(phase < OCCLUSAL, pulse(np.clip(phase / OCCLUSAL, 0.0, 0.999), 0.4 / OCCLUSAL), 0.0)


def glide_for(opening_deg: np.ndarray, pure_rotation_deg: float, per_deg: float) -> np.ndarray:
    """The condyles' glide (mm) that goes with an opening: none for the first ``pure_rotation_deg`` (Posselt's
    initial rotation), then ``per_deg`` mm per degree, blended in smoothly."""
    over = opening_deg - pure_rotation_deg
    return per_deg * np.where(over > 0, over, 0.0) * smooth(over / 3.0)


@dataclass(frozen=True)
class Motion:
    """A motion of the mandible: times (N,) s, poses in {S} (p (N, 3) mm, R (N, 3, 3))."""

    t: np.ndarray
    p: np.ndarray
    R: np.ndarray

    def point(self, b: np.ndarray) -> np.ndarray:
        """Where the point b (3,) of {M} is, (N, 3) mm."""
        return np.einsum("nij,j->ni", self.R, b) + self.p


def chewing(rate_hz: float = 50.0, duration_s: float = 13.0, opening_deg: float = 14.0, lateral_deg: float = 2.0,
            cycle_hz: float = 1.2, rest_s: float = 1.2) -> Motion:
    """Chewing on the left: the rest position for ``rest_s``, closing to intercuspal contact, then cycles of
    ``opening_deg`` (about 17 mm at the incisor with the glide) at ``cycle_hz``, the jaw swinging toward the left
    while it closes (:func:`cycle`, :func:`sideways`)."""
    t = np.arange(int(round(duration_s * rate_hz))) / rate_hz
    start = rest_s + 0.4
    phase = np.clip((t - start) * cycle_hz, 0, None) % 1.0
    moving = t >= start
    close = REST_DEG * (1 - smooth((t - rest_s) / 0.4))
    opening = close + np.where(moving, opening_deg * cycle(phase), 0.0)
    lateral = np.where(moving, lateral_deg * sideways(phase), 0.0)
    glide = glide_for(opening, 10.0, 0.9)
    return Motion(t, *pose(opening, glide, lateral))


def border(rate_hz: float = 100.0, duration_s: float = 13.0, opening_deg: float = 23.0, lateral_deg: float = 4.0) -> Motion:
    """Border movements and chewing (Posselt's envelope, scaled): from rest, close; a maximal opening and back;
    a left and a right lateral excursion (about 10 mm at the incisor); then chewing cycles on the left."""
    t = np.arange(int(round(duration_s * rate_hz))) / rate_hz
    opening = REST_DEG * (1 - smooth((t - 0.8) / 0.4))
    opening = opening + opening_deg * pulse(np.clip((t - 1.5) / 3.0, 0, 0.999), 0.5) * (t >= 1.5) * (t < 4.5)
    lateral = lateral_deg * pulse(np.clip((t - 5.0) / 1.6, 0, 0.999), 0.5) * (t >= 5.0) * (t < 6.6)
    lateral -= lateral_deg * pulse(np.clip((t - 7.0) / 1.6, 0, 0.999), 0.5) * (t >= 7.0) * (t < 8.6)
    phase = np.clip((t - 9.0) * 1.2, 0, None) % 1.0
    chew = t >= 9.0
    opening = opening + np.where(chew, 11.0 * cycle(phase), 0.0)
    lateral = lateral + np.where(chew, 2.0 * sideways(phase), 0.0)
    glide = glide_for(opening, 6.0, 0.6)
    return Motion(t, *pose(opening, glide, lateral))


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


def chin_cluster(motion: Motion, seen_by: Tracker, rng) -> np.ndarray:
    """(N, 3, 3) the chin cluster's markers in the tracker's frame (mm)."""
    points = np.einsum("nij,kj->nki", motion.R, CHIN) + motion.p[:, None]
    return observe(seen_by.see(points), rng)


def face_bow(motion: Motion, seen_by: Tracker, rng) -> np.ndarray:
    """(N, 3, 3) a jaw-motion analyser's output: the face-bow triangle (incisal point, left and right condylar
    points at intercuspal contact) moved in parallel with the incisal point, in the tracker's frame (mm)."""
    incisor = motion.point(INCISOR)
    triangle = np.array([INCISOR, CONDYLE_L, CONDYLE_R]) - INCISOR
    return observe(seen_by.see(incisor[:, None] + triangle[None]), rng)


def write_csv(path: Path, t: np.ndarray, points: np.ndarray, names=("P1", "P2", "P3")) -> Path:
    head = ["t [s]"] + [f"{n}_{a} [mm]" for n in names[: points.shape[1]] for a in "xyz"]
    rows = np.column_stack([t, points.reshape(len(t), -1)])
    path.write_text(",".join(head) + "\n" + "\n".join(",".join(f"{v:.4f}" for v in row) for row in rows) + "\n")
    return path


def recordings(out: Path, seed: int = SEED) -> dict[str, tuple[Path, Motion, Tracker]]:
    """Write the chin-cluster chewing recording (13 s at 50 Hz) and the jaw-motion analyser's border movements
    (13 s at 50 Hz) with their registration files (units and rest only, as a lab with a new tracker writes them);
    return {name: (csv, motion, tracker)}."""
    rng = np.random.default_rng(seed)
    out.mkdir(parents=True, exist_ok=True)
    found = {}
    for name, motion, view in (("cluster", chewing(), chin_cluster), ("analyser", border(rate_hz=50.0), face_bow)):
        where = tracker(int(rng.integers(1 << 30)))
        path = write_csv(out / f"{name}.csv", motion.t, view(motion, where, rng))
        (out / f"{name}.toml").write_text('units = "mm"\nrest = "first"\nscale = 1.0\n')
        found[name] = (path, motion, where)
    return found


if __name__ == "__main__":
    recordings(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("."))
