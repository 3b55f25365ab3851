"""Write the example inputs of ``examples/`` (their provenance: examples/README.md).

    .venv/bin/python examples/make_examples.py

Every file is synthetic and made here from the default chewing task (chewbot.task.default, one cycle) on the
built-in target robot, with the numbers of this script: a task file, a marker recording (CSV and C3D) with its
registration, a robot log, an incisor path, a sweep SPEC and a gains file. Running the script again writes the
same bytes (the noise has fixed seeds).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from chewbot.dynamics.registry import inverse_dynamics
from chewbot.kinematics.motion import solve_kinematics
from chewbot.model.params import load_model
from chewbot.task.default import ChewingParameters, default_task, lift_to_full

HERE = Path(__file__).resolve().parent
MM, DEG = 1e-3, np.pi / 180

# One chewing cycle after a short rest, at 200 Hz (the default task: 1 s of rest and five cycles at 1 kHz).
CYCLE = ChewingParameters(cycles=1, rest_s=0.2, rate_hz=200.0)

# Markers of the recording: four on a bite fork and the chin, in {M} (mm), as docs/recordings.md's example.
MARKERS_MM = {"M1": [95.0, 20.0, -20.0], "M2": [95.0, -20.0, -20.0], "M3": [70.0, 0.0, -45.0], "M4": [100.0, 0.0, 5.0]}
# The tracker: p_S = rotation . p_T + origin (its axes turned 90 deg about Z, its origin in front of the robot).
TRACKER_ROTATION = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
TRACKER_ORIGIN_MM = [120.0, -35.0, 210.0]
MARKER_NOISE_MM = 0.02  # Gaussian, per coordinate: an optical tracker's order of magnitude
RECORDING_RATE_HZ = 100.0

# The robot of the log: the target with friction and a mandible unlike the assumed values (what identify finds).
LOG_TRUTH = {"friction.hkp_coulomb": 0.15, "friction.hkp_viscous_Ns_per_m": 0.8, "friction.actuator_coulomb": 0.07,
             "friction.actuator_viscous_Nms_per_rad": 0.015, "mandible.mass_g": 380.0}
LOG_RATE_HZ = 250.0
LOG_ANGLE_NOISE_RAD = 1e-5  # encoder noise
LOG_TORQUE_NOISE_NM = 1e-3  # torque sensing noise


def _csv(path: Path, header: list[str], columns: list[np.ndarray], digits: int = 7) -> None:
    data = np.column_stack(columns) + 0.0  # no -0
    rows = [",".join(header)] + [",".join(f"{v:.{digits}g}" for v in row) for row in data]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def task_file(model, task) -> None:
    """chewing.csv: t, X, Y (mm), alpha, beta (deg), the bite force (N); the rates are left to the reader."""
    q = task.q
    _csv(HERE / "chewing.csv", ["t[s]", "X[mm]", "Y[mm]", "alpha[deg]", "beta[deg]", "Fx[N]", "Fy[N]", "Fz[N]"],
         [task.t, q[:, 0] / MM, q[:, 1] / MM, q[:, 2] / DEG, q[:, 3] / DEG, *task.force.T])


def marker_recording(model, task) -> None:
    """markers/chewing.csv and markers/chewing.c3d (the same frames) and markers/subject.toml, their registration."""
    import ezc3d

    folder = HERE / "markers"
    folder.mkdir(exist_ok=True)
    every = int(round(1.0 / (RECORDING_RATE_HZ * (task.t[1] - task.t[0]))))
    full = lift_to_full(model, task)
    t, X = full.t[::every], full.q[::every]  # X, Y, Z, alpha, beta, gamma
    R = Rotation.from_euler("XYZ", X[:, 3:]).as_matrix()  # R = Rx Ry Rz (docs/conventions.md)
    body = np.array(list(MARKERS_MM.values())) * MM
    points_S = np.einsum("nij,kj->nki", R, body) + X[:, None, :3]
    rotation, origin = np.array(TRACKER_ROTATION), np.array(TRACKER_ORIGIN_MM) * MM
    points_T = (points_S - origin) @ rotation  # p_T = rotation^T (p_S - origin)
    points_T += np.random.default_rng(19).normal(0.0, MARKER_NOISE_MM * MM, points_T.shape)
    force = full.force[::every]
    names = [f"{k}_{a}[mm]" for k in MARKERS_MM for a in "xyz"]
    _csv(folder / "chewing.csv", ["t[s]", *names, "Fx[N]", "Fy[N]", "Fz[N]"],
         [t - t[0], *(points_T.reshape(len(t), -1) / MM).T, *force.T])
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [RECORDING_RATE_HZ]
    c["parameters"]["POINT"]["LABELS"]["value"] = list(MARKERS_MM)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    data = np.ones((4, len(MARKERS_MM), len(t)))
    data[:3] = np.transpose(points_T / MM, (2, 1, 0))
    c["data"]["points"] = data
    c.write(str(folder / "chewing.c3d"))
    lines = ['# Registration of examples/markers/chewing.csv and chewing.c3d (docs/recordings.md): where the markers',
             '# sit on the mandible and where the tracker is. Written by examples/make_examples.py.',
             'units = "mm"', "", "[markers]"]
    lines += [f"{k} = {v}" for k, v in MARKERS_MM.items()]
    lines += ["", "# p_S = rotation . p_T + origin", "[tracker]", f"rotation = {TRACKER_ROTATION}",
              f"origin = {TRACKER_ORIGIN_MM}"]
    (folder / "subject.toml").write_text("\n".join(lines) + "\n", encoding="utf-8")


def robot_log() -> None:
    """robot_log.csv: t, theta1..6 (rad), tau1..6 (N m), Fx, Fy, Fz (N) of the robot of LOG_TRUTH along one cycle
    without rest (Newton-Euler with friction, minimum torques), with encoder and torque noise."""
    truth = load_model("target", LOG_TRUTH)
    task = default_task(truth, "left", ChewingParameters(cycles=1, rest_s=0.0, rate_hz=LOG_RATE_HZ))
    kin = solve_kinematics(truth, task, "euler-angles")
    tau = inverse_dynamics(truth, kin, "newton-euler", friction=True).tau
    rng = np.random.default_rng(7)
    theta = kin.theta + rng.normal(0.0, LOG_ANGLE_NOISE_RAD, kin.theta.shape)
    tau = tau + rng.normal(0.0, LOG_TORQUE_NOISE_NM, tau.shape)
    _csv(HERE / "robot_log.csv", ["t", *(f"theta{i}" for i in range(1, 7)), *(f"tau{i}" for i in range(1, 7)), "Fx", "Fy", "Fz"],
         [kin.t, *theta.T, *tau.T, *kin.force.T], digits=9)


def incisor_path(model, task) -> None:
    """incisor.csv: t, the incisor point Ix, Iy, Iz in {S} (mm) along the cycle, and alpha (deg), the coordinate that
    track-incisor pins (--pin alpha, its default): the path then has one solution, the cycle's own motion."""
    full = lift_to_full(model, task)
    R = Rotation.from_euler("XYZ", full.q[:, 3:]).as_matrix()
    incisor = np.einsum("nij,j->ni", R, model.incisor) + full.q[:, :3]
    _csv(HERE / "incisor.csv", ["t[s]", "Ix[mm]", "Iy[mm]", "Iz[mm]", "alpha[deg]", "Fx[N]", "Fy[N]", "Fz[N]"],
         [task.t, *(incisor / MM).T, task.q[:, 2] / DEG, *task.force.T], digits=9)


SWEEP = """\
# A small Monte Carlo sweep (docs/sweeps.md): how the coupler density and the bite force move the peak torque and
# the coupling over one chewing cycle. Written by examples/make_examples.py.
#
#   chewbot sweep examples/sweep.toml --out runs/study
kind = "monte-carlo"
samples = 8
seed = 1
chunk = 4
model = "target"
method = "hessian"
outputs = ["peak_tau_Nm", "rms_tau_Nm", "mean_MCI", "min_mu_deg", "failed_checks"]

[set]
"task.cycles" = 1
"task.rest_s" = 0.2

[parameters]
"couplers.density_g_per_mm3" = { uniform = [2.7e-3, 7.8e-3] }   # aluminium to steel
"task.force_z_N" = { uniform = [-120.0, -40.0] }                  # bite force, downward
"""


def bite_file(model) -> None:
    """bite.csv: a bite on the mild cheddar cube (h0 = 10 mm) for ``simulate --controller hybrid --food cheddar``: the
    left molar point 12 mm from occlusion (2 mm above the sample), closing in 0.3 s to 8 mm (2 mm into it), holding,
    opening again at 0.9 s; alpha pinned at 0; its Fz the hybrid controller's force reference: 0 until 0.35 s, a
    ramp to 5 N in 0.1 s (the cube gives about 5 N at 4.4 mm), held 0.3 s, released in 0.1 s. 1 kHz, 1.2 s."""
    from chewbot.food.geometry import molar_path_task

    h0, press, peak = 10e-3, 2e-3, 5.0
    t = np.arange(0.0, 1.2 + 1e-9, 1e-3)
    g, dg, ddg = np.full_like(t, h0 + 2e-3), np.zeros_like(t), np.zeros_like(t)
    for t0, t1, a, b in ((0.05, 0.35, h0 + 2e-3, h0 - press), (0.9, 1.15, h0 - press, h0 + 2e-3)):
        s = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)  # quintic smoothstep: rest to rest
        f, df, ddf = 10 * s**3 - 15 * s**4 + 6 * s**5, 30 * s**2 - 60 * s**3 + 30 * s**4, 60 * s - 180 * s**2 + 120 * s**3
        on, inside = t >= t0, (t >= t0) & (t <= t1)
        g = np.where(on, a + (b - a) * f, g)
        dg = np.where(inside, (b - a) * df / (t1 - t0), np.where(on, 0.0, dg))
        ddg = np.where(inside, (b - a) * ddf / (t1 - t0) ** 2, np.where(on, 0.0, ddg))
    task = molar_path_task(model, "left", t, g, dg, ddg, name="bite")
    Fz = -np.interp(t, [0.0, 0.35, 0.45, 0.75, 0.85, 10.0], [0.0, 0.0, peak, peak, 0.0, 0.0])
    q = task.q
    _csv(HERE / "bite.csv", ["t[s]", "X[mm]", "Y[mm]", "alpha[deg]", "beta[deg]", "Fx[N]", "Fy[N]", "Fz[N]"],
         [t, q[:, 0] / MM, q[:, 1] / MM, q[:, 2] / DEG, q[:, 3] / DEG, 0 * t, 0 * t, Fz], digits=10)


# Peanuts chewed to the swallow point in four food matrices (Hutchings et al., J. Food Eng. 109 (2012) 736, and
# Hutchings' thesis, Massey University, Table 7-5): mean chews (rounded) and the Rosin-Rammler X50 (mm) and b.
PEANUT_SWALLOW = {"scone": (26, 1.22, 1.17), "gelatine gel": (24, 1.18, 1.22), "brownie": (20, 1.20, 1.28),
                  "chocolate": (23, 1.26, 1.26)}


def peanut_sieving() -> None:
    """SIEVING.csv of the four published distributions: each the Rosin-Rammler law's mass on the sieves."""
    from chewbot.food.sieving import SIEVING_MM, passing, rosin_rammler

    lines = ["subject,chews [1],sieve [mm],mass_fraction [1]"]
    for subject, (chews, x50, b) in PEANUT_SWALLOW.items():
        q = np.concatenate([[1.0], rosin_rammler(np.array(SIEVING_MM[:-1]), x50, b), [0.0]])
        fractions = np.round(q[:-1] - q[1:], 4)
        fractions[-1] = round(1 - fractions[:-1].sum(), 4)  # rounded, still summing to 1
        assert np.allclose(passing(fractions), rosin_rammler(np.array(SIEVING_MM[:-1]), x50, b), atol=1e-3)
        lines += [f"{subject},{chews},{s:g},{f:.4f}" for s, f in zip(SIEVING_MM, fractions)]
    (HERE / "peanut_sieving.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")


def main() -> None:
    model = load_model("target")
    task = default_task(model, "left", CYCLE)
    task_file(model, task)
    marker_recording(model, task)
    robot_log()
    incisor_path(model, task)
    bite_file(model)
    peanut_sieving()
    (HERE / "sweep.toml").write_text(SWEEP, encoding="utf-8")
    shutil.copyfile(HERE.parent / "src" / "chewbot" / "simulation" / "gains.toml", HERE / "gains.toml")


if __name__ == "__main__":
    main()
