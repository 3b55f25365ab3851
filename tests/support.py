"""What several test modules share and that is not a fixture: the built-in models and the default task's kinematics,
built once per session and called with arguments (a mechanism, a side, an orientation), and states of the robot
near the default task. Not a test module: nothing is collected from it."""

from __future__ import annotations

import functools

import numpy as np

from chewbot.kinematics.motion import solve_kinematics
from chewbot.model.params import load_model, model_from_dict, read_parameter_file, resolve_model_path
from chewbot.simulation.forward import n_coordinates
from chewbot.simulation.reference import Reference
from chewbot.task.default import default_task


@functools.cache
def model(name: str):
    return load_model(name)


@functools.cache
def without_drive(name: str):
    """The built-in robot ``name`` without its [drive] section: the robot of the papers, with the cranks' own inertia
    (read from the file, not made by the code under test)."""
    raw = read_parameter_file(resolve_model_path(name))
    raw.pop("__sha256__")
    raw.pop("drive")
    raw["assumed"] = [k for k in raw["assumed"] if not k.startswith("drive.")]
    return model_from_dict(raw, source=f"{name} without [drive]")


@functools.cache
def default_kinematics(name: str = "target", side: str = "left", orientation: str = "euler-angles"):
    m = model(name)
    return solve_kinematics(m, default_task(m, side), orientation)


def random_states(name: str, count: int, seed: int):
    """States near the default task's poses (random samples of it) with random rates and torques around those of
    the task: q (count, n), dq, tau (count, 6), bite forces of the task."""
    rng = np.random.default_rng(seed)
    m = model(name)
    ref = Reference.from_task(m, default_task(m))
    k = rng.choice(ref.t.size, count, replace=False)
    n = n_coordinates(name)
    scale = np.where(np.arange(n) < (2 if n == 4 else 3), 0.02, 0.3)  # m/s and rad/s
    dq = ref.dq[k] + rng.normal(0, 1, (count, n)) * scale
    tau = rng.normal(0, 0.2, (count, 6))
    return m, ref.q[k], dq, tau, ref.force[k]


def target_pose(m, q):
    """p (N, 3), R (N, 3, 3) of target poses q (N, 4) (X, Y, alpha, beta in m and rad), gamma and Z from the HKP
    planes, computed from the conventions (docs/conventions.md: R = Rx Ry Rz as SciPy's intrinsic "XYZ";
    p1 R12 + R32 = 0 and the planes' sum), not from chewbot's graphs."""
    from scipy.spatial.transform import Rotation

    X, Y, a, b = q.T
    h = m.hkp
    g = np.arctan2(np.sin(a), h.p1 * np.cos(b) - np.cos(a) * np.sin(b))
    R = Rotation.from_euler("XYZ", np.column_stack([a, b, g])).as_matrix()
    Z = -(h.p1 * X + h.p2 + (h.p1 * R[:, 0, :] + R[:, 2, :]) @ np.array([h.T_L[0], 0.0, h.T_L[2]]))
    return np.column_stack([X, Y, Z]), R
