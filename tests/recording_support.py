"""Synthetic marker recordings shared by the recording and exported-controller tests: markers at known {M}
positions on the target, seen through a known tracker transform, written as CSV. The poses that generate the
markers are computed here from the conventions (docs/conventions.md: R = Rx Ry Rz as SciPy's intrinsic "XYZ", the
parasitic gamma and Z of the HKP planes), not from chewbot's graphs. Not a test module: nothing is collected from it."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from chewbot.recordings.importer import ImportOptions
from chewbot.task.default import ChewingParameters, default_task
from support import model

MM, DEG = 1e-3, np.pi / 180
# Four markers on a bite fork in front of the incisors and on the chin, in {M} (m).
BODY = np.array([[95.0, 20.0, -20.0], [95.0, -20.0, -20.0], [70.0, 0.0, -45.0], [100.0, 0.0, 5.0]]) * MM
TRACKER_R = Rotation.from_euler("xyz", [10.0, -20.0, 30.0], degrees=True).as_matrix()
TRACKER_O = np.array([100.0, -50.0, 200.0]) * MM
EXACT = ImportOptions(cutoff_hz=None, rate_hz=None)


def pose(m, q):
    """p (N, 3), R (N, 3, 3) of q: X, Y, alpha, beta (target: gamma and Z from the HKP planes) or all six."""
    if q.shape[1] == 6:
        return q[:, :3], Rotation.from_euler("XYZ", q[:, 3:]).as_matrix()
    X, Y, a, b = q.T
    h = m.hkp
    g = np.arctan2(np.sin(a), h.p1 * np.cos(b) - np.cos(a) * np.sin(b))  # p1 R12 + R32 = 0
    R = Rotation.from_euler("XYZ", np.column_stack([a, b, g])).as_matrix()
    Z = -(h.p1 * X + h.p2 + (h.p1 * R[:, 0, :] + R[:, 2, :]) @ np.array([h.T_L[0], 0.0, h.T_L[2]]))  # plane sum
    return np.column_stack([X, Y, Z]), R


def seen(p, R, body=BODY):
    """Marker positions (N, K, 3) in the tracker's frame: p_S = TRACKER_R p_T + TRACKER_O."""
    points_S = np.einsum("nij,kj->nki", R, body) + p[:, None, :]
    return (points_S - TRACKER_O) @ TRACKER_R


def registration(tmp_path, markers=True, **extra) -> str:
    lines = ['units = "mm"']
    lines += [f"{k} = {v}" for k, v in extra.items() if not isinstance(v, dict)]
    lines += ["[tracker]", f"rotation = {TRACKER_R.tolist()}", f"origin = {(TRACKER_O / MM).tolist()}"]
    for section, table in ((k, v) for k, v in extra.items() if isinstance(v, dict)):
        lines += [f"[{section}]"] + [f"{k} = {v}" for k, v in table.items()]
    if markers:
        lines += ["[markers]"] + [f"M{k + 1} = {(BODY[k] / MM).tolist()}" for k in range(len(BODY))]
    else:
        lines.insert(1, 'rest = "first"')
    path = tmp_path / "reg.toml"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def write_csv(path, t, points, force=None, t_unit="s", unit="mm"):
    names = [f"M{k + 1}_{a}[{unit}]" for k in range(points.shape[1]) for a in "xyz"]
    head = [f"t[{t_unit}]"] + names + (["Fx[N]", "Fy[N]", "Fz[N]"] if force is not None else [])
    scale_t = {"s": 1.0, "ms": 1e3}[t_unit]
    scale_x = {"mm": 1e3, "m": 1.0, "cm": 1e2}[unit]
    cols = [t[:, None] * scale_t, points.reshape(len(t), -1) * scale_x] + ([force] if force is not None else [])
    rows = ["" if np.isnan(v) else repr(float(v)) for v in np.hstack(cols).ravel()]
    width = sum(c.shape[1] for c in cols)
    path.write_text("\n".join([",".join(head)] + [",".join(rows[i:i + width]) for i in range(0, len(rows), width)]) + "\n")
    return str(path)


def chewing(cycles=1, rate=100.0, **kw):
    task = default_task(model("target"), params=ChewingParameters(rate_hz=rate, cycles=cycles, rest_s=0.1, **kw))
    return task.t, task.q


def chewing_recording(tmp_path, peak_force_N: float = 40.0):
    """A recording of one chewing cycle of the target (markers, a bite force of up to ``peak_force_N`` down):
    its path, the times and the forces."""
    t, q = chewing()
    force = np.zeros((len(t), 3))
    force[:, 2] = -peak_force_N * np.sin(np.pi * t / t[-1]) ** 2
    return write_csv(tmp_path / "rec.csv", t, seen(*pose(model("target"), q)), force=force), t, force
