"""Synthesise the example recordings of this folder (README.md says what they are and how they were made).

Run from the repository: ``python examples/recordings/make_recordings.py`` (writes the files beside itself; the
same files every time: the noise and the spikes come from a fixed seed).

The mandible's motion is a human-like chewing cycle, not a motion of the robot: the mandible turns about the
axis through its condyles while the condyles glide forward and down along an articular eminence inclined at
40 deg (the robot's HKP plane is inclined at 47.7 deg), with a lateral swing and roll toward the working side
that peak while the jaw closes. It is written in the model's frames ({M} with the model's condyles), with the rest
frame away from the robot's home pose, and seen by a tracker at a known rotation and offset, with 0.05 mm of
marker noise and three short tracker spikes. The registration files give the tracker's placement off by a few
degrees and millimetres (as a lab would know it) and ``rest = "first"``: the search must find the rest.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

HERE = Path(__file__).resolve().parent
RATE_HZ = 50.0
MM, DEG = 1e-3, np.pi / 180
# Condyle centres in {M} (the model's T_L, T_R) and the incisor point (the model's I), mm.
CONDYLE = np.array([-2.5, 0.0, 15.965])
INCISOR = np.array([80.0, 0.0, -25.0])
# Markers on a bite fork in front of the incisors and on the chin, in {M}, mm.
BODY = np.array([[95.0, 20.0, -20.0], [95.0, -20.0, -20.0], [70.0, 0.0, -45.0], [100.0, 0.0, 5.0]])
# The tracker's true placement (p_S = TRACKER_R p_T + TRACKER_O) and the rest frame's pose (not home).
TRACKER_R = Rotation.from_euler("xyz", [12.0, -25.0, 100.0], degrees=True).as_matrix()
TRACKER_O = np.array([150.0, -40.0, 180.0])
REST = {"X": 0.8, "beta": 1.5}  # mm, deg
# What the registration files say: the tracker rotated 6 deg and moved 4 mm from where it is.
FILE_ERROR_R = Rotation.from_rotvec(np.array([3.0, -4.0, 2.5]) * DEG).as_matrix()
FILE_ERROR_O = np.array([2.0, -3.0, 1.5])
SPIKES = ((1.30, 0.06, [3.0, -2.0, 2.5]), (3.72, 0.10, [-2.5, 1.5, 3.0]), (6.05, 0.04, [2.0, 2.0, -2.0]))  # t, s, mm


def smooth_pulse(phase: np.ndarray, peak: float) -> np.ndarray:
    """0 -> 1 at ``peak`` -> 0 over a cycle, C2 (zero rate and acceleration at both ends)."""
    u = np.where(phase < peak, phase / peak, (1 - phase) / (1 - peak))
    return u**3 * (10 - 15 * u + 6 * u**2)


def chewing(t: np.ndarray, opening_deg: float, glide_mm: float, swing_mm: float, roll_deg: float, period: float,
            start: float) -> tuple[np.ndarray, np.ndarray]:
    """Poses (p (N, 3) mm, R (N, 3, 3)) of {M}: chewing cycles after ``start`` s at rest."""
    phase = np.clip((t - start) / period, 0, None) % 1.0
    moving = t >= start
    open_ = np.where(moving, smooth_pulse(phase, 0.4), 0.0)
    swing = np.where(moving, smooth_pulse(phase, 0.65), 0.0)
    beta = REST["beta"] * DEG + opening_deg * DEG * open_
    alpha = roll_deg * DEG * swing
    R = Rotation.from_euler("XYZ", np.column_stack([alpha, beta, np.zeros_like(t)])).as_matrix()
    eminence = np.radians(40.0)
    glide = REST["X"] + glide_mm * open_
    condyle_at = CONDYLE + np.column_stack([glide * np.cos(eminence), swing_mm * swing, -glide * np.sin(eminence)])
    p = condyle_at - np.einsum("nij,j->ni", R, CONDYLE)  # the condyles' midpoint where the glide puts it
    return p, R


def opening(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One maximal opening and closing (5 s): 30 deg about the condyles while they glide 12 mm."""
    return chewing(t, 30.0, 12.0, 0.0, 0.0, period=4.0, start=0.5)


def seen(p, R, rng, spikes=True) -> np.ndarray:
    """Marker positions (N, K, 3) mm in the tracker's frame, with noise and the spikes."""
    points = np.einsum("nij,kj->nki", R, BODY) + p[:, None, :]
    tracked = (points - TRACKER_O) @ TRACKER_R
    tracked += rng.normal(scale=0.05, size=tracked.shape)
    if spikes:
        for t0, dur, jump in SPIKES:
            first = int(round(t0 * RATE_HZ))
            tracked[first : first + int(round(dur * RATE_HZ)), 0] += jump  # one marker jumps: the rigid body breaks
    return tracked


def write_csv(path: Path, t: np.ndarray, points: np.ndarray, names: list[str]) -> None:
    head = ["t [s]"] + [f"{n}_{a} [mm]" for n in names for a in "xyz"]
    rows = np.column_stack([t, points.reshape(len(t), -1)])
    path.write_text(",".join(head) + "\n" + "\n".join(",".join(f"{v:.4f}" for v in row) for row in rows) + "\n")


def write_c3d(path: Path, points: np.ndarray, names: list[str]) -> None:
    import ezc3d

    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [RATE_HZ]
    c["parameters"]["POINT"]["LABELS"]["value"] = names
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    data = np.ones((4, points.shape[1], points.shape[0]))
    data[:3] = np.transpose(points, (2, 1, 0))
    c["data"]["points"] = data
    c.write(str(path))


def registration_text(about: str, point: bool = False) -> str:
    R = FILE_ERROR_R @ TRACKER_R
    o = TRACKER_O + FILE_ERROR_O
    rows = ",\n            ".join("[" + ", ".join(f"{v:.4f}" for v in row) + "]" for row in R)
    how = ('tracked = "incisor"', "the recorded point is the incisor") if point else ('rest = "first"', "the rest frame is the first")
    return (f"# {about}\n# The tracker's placement as the lab measured it (a few degrees and millimetres off); {how[1]},\n"
            "# and the search finds where it sits on the robot (--fit-registration).\n"
            f'units = "mm"\n{how[0]}\n\n[tracker]\nrotation = [{rows}]\norigin = [{", ".join(f"{v:.2f}" for v in o)}]\n')


def main() -> None:
    rng = np.random.default_rng(2024)
    names = [f"M{k + 1}" for k in range(len(BODY))]
    t = np.arange(int(8.0 * RATE_HZ)) / RATE_HZ
    p, R = chewing(t, 16.0, 5.0, 2.5, 2.5, period=0.8, start=0.6)
    points = seen(p, R, rng)
    write_csv(HERE / "chewing.csv", t, points, names)
    write_c3d(HERE / "chewing.c3d", points, names)
    (HERE / "chewing.toml").write_text(registration_text("chewing.csv, chewing.c3d: rigid-body chewing recording, 8 s at 50 Hz"))
    t = np.arange(int(5.0 * RATE_HZ)) / RATE_HZ
    p, R = opening(t)
    write_csv(HERE / "opening.csv", t, seen(p, R, rng, spikes=False), names)
    (HERE / "opening.toml").write_text(registration_text("opening.csv: one maximal opening, 5 s at 50 Hz"))
    # the same opening as an incisal-point recording: the incisor point alone, as a jaw tracker reports it
    incisor = (np.einsum("nij,j->ni", R, INCISOR) + p - TRACKER_O) @ TRACKER_R + rng.normal(scale=0.05, size=p.shape)
    write_csv(HERE / "opening_incisor.csv", t, incisor[:, None, :], ["I"])
    (HERE / "opening_incisor.toml").write_text(registration_text("opening_incisor.csv: the incisal point of the maximal opening, 5 s at 50 Hz", point=True))


if __name__ == "__main__":
    main()
