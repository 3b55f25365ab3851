"""What the robot reproduces of a recording: per frame, the error between the recorded motion (registered, at
scale 1) and the robot's fitted pose, for the incisor point and for the whole mandible; over time, whether the
reproduced motion is in step with the recorded one.

* Incisor: the distance between the recorded and the reproduced incisor point (the model's), mm.
* Whole mandible: the largest distance over the model's named points of the mandible (incisor, both molars, both
  condyles), mm, and the rotation angle between the two orientations, deg.
* Rotation and incisal excursion, each relative to the first frame: the angle of R_k R_0^T (deg) and the distance
  of the incisor from where it was at the first frame (mm), recorded and reproduced. Their ratio of peaks is the
  share of the recorded rotation (excursion) that the robot reproduces; "in step": the Pearson correlation over
  time of the reproduced with the recorded one, r >= :data:`IN_STEP_R`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chewbot.model import Model
from chewbot.recordings.fit import RobotFit, fitted_pose
from chewbot.units import factor

IN_STEP_R = 0.95
MM = factor("mm")


def _angle_deg(R: np.ndarray) -> np.ndarray:
    """Rotation angles (N,) deg of rotation matrices (N, 3, 3)."""
    return np.degrees(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)))


def _pearson(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


@dataclass(frozen=True, eq=False)
class Measures:
    """Per frame (N,): ``incisor_error`` mm, ``mandible_error`` mm, ``mandible_rotation_error`` deg, recorded and
    reproduced rotation (deg) and incisal excursion (mm) from the first frame; NaN where the robot has no pose."""

    incisor_error: np.ndarray
    mandible_error: np.ndarray
    mandible_rotation_error: np.ndarray
    recorded_angle: np.ndarray
    reproduced_angle: np.ndarray
    recorded_excursion: np.ndarray
    reproduced_excursion: np.ndarray
    recorded_incisor: np.ndarray  # (N, 3) m in {S}
    reproduced_incisor: np.ndarray

    @property
    def rotation_share(self) -> float:
        """Peak reproduced rotation over peak recorded rotation."""
        return float(np.nanmax(self.reproduced_angle) / max(np.nanmax(self.recorded_angle), 1e-300))

    @property
    def excursion_share(self) -> float:
        return float(np.nanmax(self.reproduced_excursion) / max(np.nanmax(self.recorded_excursion), 1e-300))

    @property
    def r_rotation(self) -> float:
        return _pearson(self.recorded_angle, self.reproduced_angle)

    @property
    def r_excursion(self) -> float:
        return _pearson(self.recorded_excursion, self.reproduced_excursion)

    def columns(self):
        """(name, values, unit, description) of the residuals file's measure columns."""
        return [
            ("incisor_error", self.incisor_error, "mm", "distance of the reproduced incisor point from the recorded one (scale 1)"),
            ("mandible_error", self.mandible_error, "mm", "largest distance over incisor, molars and condyles, reproduced vs recorded (scale 1)"),
            ("mandible_rotation_error", self.mandible_rotation_error, "deg", "rotation angle between the reproduced and the recorded orientation (scale 1)"),
            ("recorded_rotation", self.recorded_angle, "deg", "recorded rotation angle from the first frame"),
            ("reproduced_rotation", self.reproduced_angle, "deg", "reproduced rotation angle from the first frame"),
            ("recorded_excursion", self.recorded_excursion, "mm", "recorded incisor distance from the first frame"),
            ("reproduced_excursion", self.reproduced_excursion, "mm", "reproduced incisor distance from the first frame"),
        ]

    def describe(self) -> str:
        def step(r):
            return "in step" if r >= IN_STEP_R else "NOT in step"

        return (f"reproduced: {100 * self.rotation_share:.1f} % of the recorded rotation (peak {np.nanmax(self.recorded_angle):.3g} deg), "
                f"r = {self.r_rotation:.4f} ({step(self.r_rotation)}, r >= {IN_STEP_R:g}); {100 * self.excursion_share:.1f} % of the "
                f"incisal excursion (peak {np.nanmax(self.recorded_excursion):.3g} mm), r = {self.r_excursion:.4f} "
                f"({step(self.r_excursion)}); errors at scale 1: incisor up to {np.nanmax(self.incisor_error):.3g} mm, "
                f"mandible up to {np.nanmax(self.mandible_error):.3g} mm and {np.nanmax(self.mandible_rotation_error):.3g} deg")


def measure(model: Model, p_rec: np.ndarray, R_rec: np.ndarray, fit: RobotFit, t: np.ndarray, point=None) -> Measures:
    """The :class:`Measures` of the recorded poses (``p_rec`` (N, 3) m, ``R_rec`` (N, 3, 3), registered, scale 1)
    against the fitted ones; ``point``: the point of {M} measured as the incisor (a point path's tracked point;
    default the incisal point)."""
    p_fit, R_fit = fitted_pose(model, fit.q)
    points = np.array([model.incisor if point is None else point, model.molar_left, model.molar_right, model.hkp.T_L,
                       model.hkp.T_R])
    rec_pts = np.einsum("nij,kj->nki", R_rec, points) + p_rec[:, None]
    fit_pts = np.einsum("nij,kj->nki", R_fit, points) + p_fit[:, None]
    dist = np.linalg.norm(rec_pts - fit_pts, axis=2) / MM
    rot_err = _angle_deg(np.einsum("nji,njk->nik", R_fit, R_rec))
    rec_angle = _angle_deg(R_rec @ R_rec[0].T)
    first = int(np.flatnonzero(np.isfinite(p_fit[:, 0]))[0]) if np.isfinite(p_fit[:, 0]).any() else 0
    fit_angle = _angle_deg(R_fit @ R_fit[first].T)
    rec_exc = np.linalg.norm(rec_pts[:, 0] - rec_pts[0, 0], axis=1) / MM
    fit_exc = np.linalg.norm(fit_pts[:, 0] - fit_pts[first, 0], axis=1) / MM
    return Measures(dist[:, 0], dist.max(axis=1), rot_err, rec_angle, fit_angle, rec_exc, fit_exc, rec_pts[:, 0], fit_pts[:, 0])
