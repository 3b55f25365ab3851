"""The mandible's pose in each frame from its markers, and the scaling of the motion (batched, frames first).

:func:`kabsch` fits, in every frame at once, the rotation R and position p that carry the markers' positions
in {M} onto the measured ones in the least-squares sense (the Kabsch algorithm: the SVD of the 3 x 3
cross-covariance of the centred point sets, with the sign that keeps det R = +1). It solves the same problem as
SciPy's ``Rotation.align_vectors`` for one frame, which is not batched: NumPy's SVD runs on all the frames'
matrices in one call.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from chewbot.units import factor

MM = factor("mm")


@dataclass(frozen=True, eq=False)
class RigidFit:
    """The pose of {M} in {S} per frame: ``p`` (N, 3) m (O_M), ``R`` (N, 3, 3); the distance of each marker from
    where the fitted pose puts it, ``distances`` (N, K) m, and the markers' names."""

    p: np.ndarray
    R: np.ndarray
    distances: np.ndarray
    markers: tuple[str, ...]

    @property
    def rms_mm(self) -> np.ndarray:
        """(N,) root mean square of the markers' distances, mm."""
        return np.sqrt(np.mean(self.distances**2, axis=1)) / MM

    @property
    def max_mm(self) -> np.ndarray:
        """(N,) the largest marker distance, mm."""
        return self.distances.max(axis=1) / MM


def to_base(points: np.ndarray, rotation: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Tracker coordinates (..., 3) to {S}: p_S = rotation p_T + origin."""
    return points @ rotation.T + origin


def kabsch(body: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R (N, 3, 3) and p (N, 3) minimising sum_k abs(R body_k + p - points_k)^2 in every frame.

    ``body`` (K, 3): the markers in {M}; ``points`` (N, K, 3): where they were measured, in {S}.
    """
    b0 = body.mean(axis=0)
    c = points.mean(axis=1)
    H = np.einsum("ki,nkj->nij", body - b0, points - c[:, None, :])  # sum_k b_k y_k^T
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))  # det(V U^T): -1 would be a reflection
    D = np.zeros_like(H)
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = np.where(d == 0, 1.0, d)
    R = np.einsum("nji,njk,nlk->nil", Vt, D, U)  # V D U^T
    return R, c - np.einsum("nij,j->ni", R, b0)


def rigid_fit(body: np.ndarray, points: np.ndarray, markers: tuple[str, ...]) -> RigidFit:
    """:func:`kabsch` and the markers' distances from the fitted body."""
    R, p = kabsch(body, points)
    fitted = np.einsum("nij,kj->nki", R, body) + p[:, None, :]
    return RigidFit(p, R, np.linalg.norm(points - fitted, axis=2), markers)


def scale_motion(p: np.ndarray, R: np.ndarray, scale: float, angle_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The motion relative to the first frame, scaled: the displacement of O_M by ``scale``, and the rotation
    angle by ``angle_scale`` about the same axis: p' = p_0 + scale (p - p_0), R' = exp(angle_scale log(R R_0^T)) R_0."""
    relative = Rotation.from_matrix(R @ R[0].T)
    turned = Rotation.from_rotvec(angle_scale * relative.as_rotvec()).as_matrix() @ R[0]
    return p[0] + scale * (p - p[0]), turned
