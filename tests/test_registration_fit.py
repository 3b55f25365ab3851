"""The registration search (import-motion --fit-registration), tracker spikes, landmarks and the measures of what
the robot reproduces. Recordings are synthesised here from known motions of the robot, with poses computed from
the conventions (docs/conventions.md), not from chewbot's graphs; the examples' recordings are a human-like
motion (examples/recordings/make_recordings.py)."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from support import model, target_pose
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.errors import RecordingError
from chewbot.files import read_sidecar
from chewbot.recordings.importer import ImportOptions, import_motion
from chewbot.recordings.register import MAX_TURN_DEG
from chewbot.recordings.registration import load_registration
from chewbot.task.default import ChewingParameters, default_task

runner = CliRunner()
MM, DEG = 1e-3, np.pi / 180
BODY = np.array([[95.0, 20.0, -20.0], [95.0, -20.0, -20.0], [70.0, 0.0, -45.0], [100.0, 0.0, 5.0]]) * MM
EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "recordings"


pose = target_pose


def write_csv(path, t, points):
    names = [f"M{k + 1}_{a}[mm]" for k in range(points.shape[1]) for a in "xyz"]
    rows = np.column_stack([t, points.reshape(len(t), -1) / MM])
    path.write_text(",".join(["t[s]"] + names) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")
    return str(path)


def write_registration(path, rotation, origin, markers=True, landmarks=None):
    lines = ['units = "mm"'] + ([] if markers else ['rest = "first"'])
    lines += ["[tracker]", f"rotation = {rotation.tolist()}", f"origin = {(origin / MM).tolist()}"]
    if markers:
        lines += ["[markers]"] + [f"M{k + 1} = {(BODY[k] / MM).tolist()}" for k in range(len(BODY))]
    if landmarks:
        lines += ["[landmarks]"] + [f"{k} = {(v / MM).tolist()}" for k, v in landmarks.items()]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def synthetic(tmp_path, seed=0, offset=(-1.0 * MM, 0.5 * MM, 0.0, 2.0 * DEG)):
    """A known motion of the robot (two chewing cycles at 50 Hz, every frame moved off by ``offset``: by default
    1.1 mm and 2 deg, so that its most closed frame is not at home) seen through a tracker at a random rotation and
    offset; the file's tracker off by 10 deg and 5 mm."""
    m = model("target")
    task = default_task(m, params=ChewingParameters(rate_hz=50.0, cycles=2, rest_s=0.1))
    q = task.q + np.array(offset)
    p, R = pose(m, q)
    rng = np.random.default_rng(seed)
    TR = Rotation.random(random_state=seed + 11).as_matrix()
    TO = rng.uniform(-0.2, 0.2, 3)
    points = (np.einsum("nij,kj->nki", R, BODY) + p[:, None, :] - TO) @ TR
    axis = rng.normal(size=3)
    error = Rotation.from_rotvec(axis / np.linalg.norm(axis) * 10.0 * DEG).as_matrix()
    shift = rng.normal(size=3)
    return task.t, q, points, TR, TO, error @ TR, TO + shift / np.linalg.norm(shift) * 5.0 * MM


def plane_components(m, rotation, origin, TR, TO):
    """The found tracker against the true one, g = T_found T_true^-1, in the components a recording identifies:
    the angle by which g tilts the HKP plane's normal (deg) and the distance by which it moves the plane along
    its normal (mm); and those it does not: the rotation about the normal (deg), the shift along the plane (mm)."""
    g_R = rotation @ TR.T
    g_t = origin - g_R @ TO
    n = np.array([m.hkp.p1, 0.0, 1.0]) / np.hypot(m.hkp.p1, 1.0)
    on_plane = np.array([0.0, 0.0, -m.hkp.p2])
    tilt = np.degrees(np.arccos(np.clip(n @ g_R @ n, -1, 1)))
    height = n @ (g_R @ on_plane + g_t - on_plane) / MM
    about = np.degrees(np.linalg.norm(Rotation.from_matrix(g_R).as_rotvec()))
    along = np.linalg.norm(g_t - n * (n @ g_t)) / MM
    return tilt, height, about, along


def test_fit_registration_recovers_what_a_recording_identifies(tmp_path):
    """A motion of the robot whose chewing cycles close at home (intercuspal contact), recorded from 2 deg into its
    first opening (the first frame is not at home), with the lab's [markers] and the file's tracker 10 deg and
    5 mm off: the prior (intercuspal contact at home, the markers where the lab put them) is the true
    registration, the share is 1 there and nothing moves it: the tracker comes back to 0.05 deg and 0.05 mm
    whatever the file's tracker said (measured 0.009 deg and 0.03 mm: intercuspal contact is the mean of the frames
    within 0.3 deg of the most closed, which here close smoothly); every frame reproduced (incisor error below
    1e-3 mm)."""
    t, q, points, TR, TO, file_R, file_O = synthetic(tmp_path, offset=(0.0, 0.0, 0.0, 0.0))
    start = np.flatnonzero(q[:, 3] > 2 * DEG)[0]  # the recording starts with the mandible 2 deg open
    rec = write_csv(tmp_path / "rec.csv", t[start:] - t[start], points[start:])
    reg = write_registration(tmp_path / "reg.toml", file_R, file_O)
    out = tmp_path / "task.csv"
    result = runner.invoke(app, ["import-motion", rec, "--registration", reg, "--out", str(out), "--fit-registration",
                                 "--cutoff", "none", "--rate", "recording"])
    assert result.exit_code == 0, result.output
    found = load_registration(tmp_path / "task.registration.toml")
    assert found.scale == 1.0 and found.angle_scale == 1.0  # the share
    assert np.degrees(np.linalg.norm(Rotation.from_matrix(found.rotation @ TR.T).as_rotvec())) < 0.05
    assert np.abs(found.origin - TO).max() < 0.05 * MM
    residuals = pd.read_csv(tmp_path / "task.residuals.csv", comment="#")
    assert residuals["incisor_error [mm]"].max() < 1e-3
    summary = read_sidecar(tmp_path / "task.residuals.csv")["summary"]  # the printed summary, in the sidecar
    assert any(line.startswith("share 1.0000") for line in summary), summary
    assert any(line.startswith("registration: the prior") for line in summary), summary


def test_the_robot_planes_leave_components_unidentified():
    """On the target the HKPs keep both condyles on one plane: a rotation about the plane's normal through a point
    of the plane and a shift along it map every pose of the robot to a pose of the robot (condyles on the plane,
    p1 R12 + R32 = 0), so that no residual tells such registrations apart (docs/recordings.md)."""
    m = model("target")
    task = default_task(m, params=ChewingParameters(rate_hz=50.0, cycles=1, rest_s=0.1))
    n = np.array([m.hkp.p1, 0.0, 1.0]) / np.hypot(m.hkp.p1, 1.0)
    g = Rotation.from_rotvec(n * 3.0 * DEG).as_matrix()
    c = np.array([0.0, 0.0, -m.hkp.p2])
    p, R = pose(m, task.q)
    p2, R2 = (p - c) @ g.T + c + np.cross(n, [0.0, 1.0, 0.0]) * 1.5 * MM, g @ R
    for T in (m.hkp.T_L, m.hkp.T_R):
        ball = p2 + R2 @ T
        assert np.abs(m.hkp.p1 * ball[:, 0] + ball[:, 2] + m.hkp.p2).max() < 1e-12
    assert np.abs(m.hkp.p1 * R2[:, 0, 1] + R2[:, 2, 1]).max() < 1e-12


def test_landmarks_place_the_markers_as_the_lab_digitised_them(tmp_path):
    """rest = "first" with the model's incisor, molars and condyles digitised at the rest frame (in the tracker's
    frame) gives the same task as the markers given in {M}."""
    m = model("target")
    t, q, points, TR, TO, _, _ = synthetic(tmp_path)
    p, R = pose(m, q[:1])
    named = {"incisor": m.incisor, "molar_left": m.molar_left, "molar_right": m.molar_right,
             "condyle_left": m.hkp.T_L, "condyle_right": m.hkp.T_R}
    landmarks = {k: ((R[0] @ v + p[0]) - TO) @ TR for k, v in named.items()}
    rec = write_csv(tmp_path / "rec.csv", t, points)
    exact = ImportOptions(cutoff_hz=None, rate_hz=None)
    by_markers = import_motion(rec, write_registration(tmp_path / "a.toml", TR, TO), exact)
    by_landmarks = import_motion(rec, write_registration(tmp_path / "b.toml", TR, TO, markers=False, landmarks=landmarks), exact)
    assert np.abs(by_landmarks.task.q - by_markers.task.q).max() < 1e-9
    assert np.abs(by_markers.task.q - q).max() < 1e-9


def test_spikes_are_dropped_filled_and_listed(tmp_path):
    """One marker jumps 3 mm for 3 frames and all markers jump 8 mm for 2 frames (400 mm/s at 50 Hz, against a
    median of a few mm/s): both are found, listed with their frames and times and filled; the task then equals
    the one from the clean recording to within what the spline fill leaves (0.05 mm). With --keep-spikes the
    first breaks the rigid body and fails."""
    t, q, points, TR, TO, _, _ = synthetic(tmp_path)
    spiked = points.copy()
    spiked[30:33, 0] += np.array([3.0, -1.0, 0.5]) * MM
    spiked[60:62] += np.array([0.0, 8.0, 0.0]) * MM
    rec = write_csv(tmp_path / "rec.csv", t, spiked)
    reg = write_registration(tmp_path / "reg.toml", TR, TO)
    exact = ImportOptions(cutoff_hz=None, rate_hz=None)
    result = import_motion(rec, reg, exact)
    listed = [n for n in result.notes if "spike" in n]
    assert len(listed) == 2 and "frame 31 (t = 0.6 s" in listed[0] and "rigid body" in listed[0]
    assert "frame 61 (t = 1.2 s" in listed[1] and "jump" in listed[1]
    clean = import_motion(write_csv(tmp_path / "clean.csv", t, points), reg, exact)
    assert np.abs(result.task.q[:, :2] - clean.task.q[:, :2]).max() < 0.05 * MM
    kept = import_motion(rec, reg, ImportOptions(cutoff_hz=None, rate_hz=None, keep_spikes=True))
    assert kept.task is None and not kept.passed[30:33].any()


def test_written_registration_reads_back_to_the_same_task(tmp_path):
    t, q, points, TR, TO, file_R, file_O = synthetic(tmp_path)
    rec = write_csv(tmp_path / "rec.csv", t, points)
    reg = write_registration(tmp_path / "reg.toml", file_R, file_O, markers=False)
    out = tmp_path / "task.csv"
    args = ["import-motion", rec, "--out", str(out), "--cutoff", "none", "--rate", "recording"]
    assert runner.invoke(app, args + ["--registration", reg, "--fit-registration"]).exit_code == 0
    text = (tmp_path / "task.registration.toml").read_text()
    assert text.startswith("# written by chewbot") and "share" in text
    tomllib.loads(text)
    first = out.read_text().splitlines()[2:]
    again = tmp_path / "again.csv"
    result = runner.invoke(app, ["import-motion", rec, "--out", str(again), "--cutoff", "none", "--rate", "recording",
                                 "--registration", str(tmp_path / "task.registration.toml")])
    assert result.exit_code == 0, result.output
    a = np.array([[float(v) for v in line.split(",")] for line in first])
    b = np.array([[float(v) for v in line.split(",")] for line in again.read_text().splitlines()[2:]])
    assert np.abs(a[:, 1:5] - b[:, 1:5]).max() < 1e-9


@pytest.mark.slow
def test_examples_reach_their_targets_in_step(tmp_path):
    """The examples (a human-like motion, not the robot's; docs/recordings.md): >= 90 % of the chewing
    recording's rotation and >= 60 % of the opening's incisal excursion, both in step (r >= 0.95), and of the
    opening recorded as an incisal point (>= 60 % of its excursion, in step); the imported chewing task runs with
    exit 0. (Their times are in docs/recordings.md: no timing is asserted on a shared machine.)"""
    for name, measure, target in (("chewing", "rotation_share", 0.9), ("opening", "excursion_share", 0.6)):
        result = import_motion(EXAMPLES / f"{name}.csv", EXAMPLES / f"{name}.toml", ImportOptions(fit_registration=True))
        m = result.measures()
        assert getattr(m, measure) >= target and m.r_rotation >= 0.95 and m.r_excursion >= 0.95, (name, m.describe())
        if name == "opening":  # the same opening as an incisal point: the search turns and places its path
            point = import_motion(EXAMPLES / "opening_incisor.csv", EXAMPLES / "opening_incisor.toml", ImportOptions(fit_registration=True))
            mp = point.measures()
            assert point.task is not None and mp.excursion_share >= 0.6 and mp.r_excursion >= 0.95, mp.describe()
        if name == "chewing":
            out = tmp_path / "chewing.csv"
            assert runner.invoke(app, ["import-motion", str(EXAMPLES / "chewing.csv"), "--registration",
                                       str(EXAMPLES / "chewing.toml"), "--fit-registration", "--out", str(out)]).exit_code == 0
            assert runner.invoke(app, ["run", "--task", str(out), "--out", str(tmp_path / "run")]).exit_code == 0


def test_examples_are_what_their_generator_writes(tmp_path):
    """The committed examples are reproduced by make_recordings.py (fixed seed)."""
    script = EXAMPLES / "make_recordings.py"
    copy = tmp_path / "make_recordings.py"
    copy.write_text(script.read_text())
    subprocess.run([sys.executable, str(copy)], check=True, cwd=tmp_path)
    for name in ("chewing.csv", "opening.csv", "opening_incisor.csv", "chewing.toml", "opening.toml", "opening_incisor.toml"):
        assert (tmp_path / name).read_text() == (EXAMPLES / name).read_text(), name


def test_clip_keeps_the_full_motion_where_the_robot_can_follow_it(tmp_path):
    """A motion of the robot's kind opening 34 deg (the workspace ends near 26 deg): with --clip the task is
    written, the frames inside the workspace are reproduced exactly (errors below 1e-9 mm and deg, the task passing
    through the recorded poses there), the others are clipped to the boundary with the limiting constraint named
    (a column of the residuals and the note), and the task starts and ends at rest at home."""
    m = model("target")
    task = default_task(m, params=ChewingParameters(rate_hz=50.0, cycles=1, rest_s=0.2, beta_deg=34.0, X_mm=2.0))
    p, R = pose(m, task.q)
    TR, TO = Rotation.from_euler("xyz", [20.0, -10.0, 70.0], degrees=True).as_matrix(), np.array([0.1, -0.05, 0.2])
    rec = write_csv(tmp_path / "rec.csv", task.t, (np.einsum("nij,kj->nki", R, BODY) + p[:, None, :] - TO) @ TR)
    reg = write_registration(tmp_path / "reg.toml", TR, TO)
    refused = import_motion(rec, reg, ImportOptions(cutoff_hz=None, rate_hz=None))
    assert refused.task is None
    result = import_motion(rec, reg, ImportOptions(cutoff_hz=None, rate_hz=None, clip=True, timing="recording"))
    inside = ~result.fit.outside.any(axis=1)
    assert 0 < (~inside).sum() < len(inside) // 2
    assert np.nanmax(result.fit.position_error_mm[inside]) < 1e-9 and np.nanmax(result.fit.orientation_error_deg[inside]) < 1e-9
    assert np.all(result.fit.position_error_mm[~inside] > 1e-6)
    table = result.residuals()
    named = [c for c in table.columns if c.startswith("outside_") and np.asarray(table[c]).any()]
    note = next(n for n in result.notes if "limited by" in n)
    assert named and all(c[len("outside_"):].replace("_", " ") in note for c in named)  # each named, in both
    # and independently: where the recorded pose breaks a socket bound or a transmission angle of 10 deg
    from chewbot.kinematics.ik import transmission
    with np.errstate(invalid="ignore"):
        sin_mu = np.nan_to_num(transmission(m, p, R), nan=-1.0)
    x_balls = np.column_stack([(p + R @ T)[:, 0] for T in (m.hkp.T_L, m.hkp.T_R)])
    broken = (sin_mu < np.sin(np.radians(10.0))).any(axis=1) | (x_balls > m.hkp.x_range[1]).any(axis=1)
    assert np.array_equal(broken, ~inside), (np.flatnonzero(broken), np.flatnonzero(~inside))
    assert np.asarray(table["clipped"]).sum() == (~result.passed).sum() > 0
    played = result.task
    assert np.abs(played.q[0]).max() == 0 and np.abs(played.q[-1]).max() == 0
    assert np.abs(played.dq[0]).max() < 1e-12 and np.abs(played.dq[-1]).max() < 1e-12
    start = np.flatnonzero(np.isclose(played.t, 1.2))[0]  # 0.2 s hold + 1 s ramp, then the recording's frames
    frames = start + np.arange(len(task.t))
    assert np.abs(played.q[frames][inside] - task.q[inside]).max() < 1e-9


def test_retimed_motion_holds_every_limit_and_is_no_slower_than_needed(tmp_path):
    """The default chewing motion played three times too fast (crank speeds 18 rad/s > 17, accelerations 720
    rad/s^2 > 200): --timing limits writes a task that `chewbot run` passes (exit 0), never faster than recorded;
    its duration is below that of the slowest-needed uniform slow-down (a feasible timing: speeds scale with 1/k,
    accelerations and the motion's share of the torques with 1/k^2, from the run of the fast task), and it is
    time-optimal in the sense a run can check: at all but 2 % of the samples (the switches between accelerating
    and braking) a crank speed, acceleration or torque is within 2 % of its limit or the motion plays at the
    recorded speed."""
    m = model("target")
    task = default_task(m, params=ChewingParameters(rate_hz=150.0, cycles=2, rest_s=0.3))
    p, R = pose(m, task.q)
    TR, TO = Rotation.from_euler("xyz", [20.0, -10.0, 70.0], degrees=True).as_matrix(), np.array([0.1, -0.05, 0.2])
    fast = task.t / 3
    rec = write_csv(tmp_path / "rec.csv", fast, (np.einsum("nij,kj->nki", R, BODY) + p[:, None, :] - TO) @ TR)
    reg = write_registration(tmp_path / "reg.toml", TR, TO)
    base = ["import-motion", rec, "--registration", reg, "--cutoff", "none"]
    recorded = runner.invoke(app, base + ["--out", str(tmp_path / "fast.csv"), "--timing", "recording"])
    assert recorded.exit_code == 0 and "--timing recording: crank speed up to" in recorded.output, recorded.output
    assert "crank acceleration up to" in recorded.output  # which limit fails, and where
    assert runner.invoke(app, ["run", "--task", str(tmp_path / "fast.csv"), "--out", str(tmp_path / "run_fast")]).exit_code == 4
    result = runner.invoke(app, base + ["--out", str(tmp_path / "slow.csv")])  # the default: --timing limits
    assert result.exit_code == 0 and "re-timed from" in result.output, result.output
    assert runner.invoke(app, ["run", "--task", str(tmp_path / "slow.csv"), "--out", str(tmp_path / "run_slow")]).exit_code == 0

    def columns(folder):
        d = pd.read_csv(tmp_path / folder / "results.csv", comment="#")
        pick = lambda prefix: d[[c for c in d.columns if c.split(" [")[0] in [f"{prefix}{i}" for i in range(1, 7)]]].to_numpy()
        return d["t [s]"].to_numpy(), pick("dtheta"), pick("ddtheta"), pick("tau")

    t_fast, v_fast, a_fast, _ = columns("run_fast")
    t_slow, v_slow, a_slow, tau_slow = columns("run_slow")
    lim = m.limits
    k = max(1.0, np.abs(v_fast).max() / lim.speed, np.sqrt(np.abs(a_fast).max() / lim.acceleration))
    duration, recorded = t_slow[-1] - t_slow[0], t_fast[-1] - t_fast[0]
    assert recorded < duration <= k * recorded, (duration, k * recorded)
    # the re-timed task's samples are the fast one's poses in order: its path speed is the ratio of their rates
    slow_task = pd.read_csv(tmp_path / "slow.csv", comment="#")
    fast_task = pd.read_csv(tmp_path / "fast.csv", comment="#")
    names = ["X [m]", "Y [m]", "alpha [rad]", "beta [rad]"]
    assert np.abs(slow_task[names].to_numpy() - fast_task[names].to_numpy()).max() < 1e-9
    rates = ["dX [m/s]", "dY [m/s]", "dalpha [rad/s]", "dbeta [rad/s]"]
    v_rec = np.linalg.norm(fast_task[rates].to_numpy() * [1e3, 1e3, 180 / np.pi, 180 / np.pi], axis=1)
    v_new = np.linalg.norm(slow_task[rates].to_numpy() * [1e3, 1e3, 180 / np.pi, 180 / np.pi], axis=1)
    moving = v_rec > 1e-3 * v_rec.max()
    s_dot = v_new[moving] / v_rec[moving]
    assert s_dot.max() <= 1 + 1e-6  # never faster than recorded
    active = ((np.abs(v_slow).max(axis=1) >= 0.98 * lim.speed) | (np.abs(a_slow).max(axis=1) >= 0.98 * lim.acceleration)
              | (np.abs(tau_slow).max(axis=1) >= 0.98 * lim.torque))[moving] | (s_dot >= 0.98)
    assert active.mean() >= 0.98, active.mean()


def test_an_incisal_point_recording_is_registered_on_the_model_incisor(tmp_path):
    """tracked = "incisor": one tracked point, the incisor of a known motion of the robot seen through a known
    tracker. The robot puts its incisor on every recorded point within 0.05 mm (the hinge guess of the
    orientation, weighed 0.1 per degree, pulls it by up to 0.04 mm: measured 0.038), and the opening is
    reproduced in step; the orientation is a guess (the hinge about the condylar axis), weighed
    little, and no tolerance. Checked against a hinge computed here: a rotation about the condyles' axis by the
    returned angle drops the incisor by the asked amount. --fit-registration refuses such a recording."""
    from chewbot.recordings.robotfit import hinge_beta

    m = model("target")
    task = default_task(m, params=ChewingParameters(rate_hz=50.0, cycles=2, rest_s=0.1))
    p, R = pose(m, task.q)
    TR, TO = Rotation.from_euler("xyz", [20.0, -10.0, 70.0], degrees=True).as_matrix(), np.array([0.1, -0.05, 0.2])
    incisor = (p + R @ m.incisor - TO) @ TR
    rec = write_csv(tmp_path / "rec.csv", task.t, incisor[:, None, :])
    reg = tmp_path / "reg.toml"
    reg.write_text(f'units = "mm"\ntracked = "incisor"\n[tracker]\nrotation = {TR.tolist()}\norigin = {(TO / MM).tolist()}\n')
    result = import_motion(rec, reg, ImportOptions(cutoff_hz=None, rate_hz=None))
    assert result.task is not None and np.nanmax(result.fit.position_error_mm) < 0.05
    measures = result.measures()
    assert measures.excursion_share > 0.999 and measures.r_excursion > 0.999
    drops = np.array([-1e-3, -10e-3, -30e-3])
    beta = hinge_beta(m, m.incisor, drops)
    C = 0.5 * (m.hkp.T_L + m.hkp.T_R)
    turned = np.array([C + Rotation.from_euler("y", b).as_matrix() @ (m.incisor - C) for b in beta])
    assert np.allclose(turned[:, 2] - m.incisor[2], drops, atol=1e-12)
    with pytest.raises(RecordingError, match="no rotation to scale"):
        import_motion(rec, reg, ImportOptions(angle_scale=0.5))


def test_fit_registration_of_an_incisal_point_reaches_a_reachable_motion(tmp_path):
    """tracked = "incisor" with --fit-registration: the incisor of a known motion of the robot (opening 24 deg,
    near the workspace's edge at 26 deg) seen through a known tracker, the file's tracker 10 deg and 5 mm off, so
    that at the file's placement the rest point is not where the robot's incisor can follow the path. The search
    finds a placement at which the robot reproduces >= 90 % of the incisal excursion (measured: 100.1 %, r = 1.0000,
    share 1, against 65.9 % and no task at the file's placement), in step (r >= 0.95), every frame within --max-residual (1 mm), with the tracker within 30 deg of
    the file's. A point path identifies the placement only where it meets the reachable set's boundary, so the
    true placement is not asserted; what is checked independently is that the found registration is a rigid
    placement of the recorded path (distances between frames kept, times the scale) and that the robot's fitted
    poses, recomputed here from the conventions, put the incisor within 1 mm of the registered points."""
    m = model("target")
    task = default_task(m, params=ChewingParameters(rate_hz=50.0, cycles=2, rest_s=0.1, beta_deg=24.0))
    p, R = pose(m, task.q)
    t, _, _, TR, TO, file_R, file_O = synthetic(tmp_path)
    incisor = (p + R @ m.incisor - TO) @ TR
    rec = write_csv(tmp_path / "rec.csv", task.t, incisor[:, None, :])
    reg = tmp_path / "reg.toml"
    reg.write_text(f'units = "mm"\ntracked = "incisor"\n[tracker]\nrotation = {file_R.tolist()}\norigin = {(file_O / MM).tolist()}\n')
    plain = import_motion(rec, reg, ImportOptions(cutoff_hz=None, rate_hz=None))
    result = import_motion(rec, reg, ImportOptions(cutoff_hz=None, rate_hz=None, fit_registration=True))
    measures = result.measures()
    assert result.task is not None
    assert measures.excursion_share >= 0.9 and measures.r_excursion >= 0.95, (measures.describe(), plain.measures().describe())
    assert result.found.turn_deg <= MAX_TURN_DEG + 1e-9  # the hard bound around the prior
    registered = incisor @ result.registration.rotation.T + result.registration.origin
    between = lambda a: np.linalg.norm(a[:, None] - a[None], axis=2)
    assert np.allclose(between(registered), between(incisor), atol=1e-12)
    scaled = registered[0] + result.scale * (registered - registered[0])
    p_fit, R_fit = pose(m, result.fit.q)
    assert np.linalg.norm(p_fit + R_fit @ m.incisor - scaled, axis=1).max() <= 1.0 * MM


def test_import_writes_a_report_page_with_the_measures_and_figures_with_units(tmp_path):
    """import-motion writes TASK.report.html beside the task: chewbot's marker line first, the share, the in-step
    r and the largest errors as the residuals file holds them (read back from the CSV, printed to 4 significant
    digits), the two figures inline, every axis labelled with its unit; an existing page is not replaced without
    --force (exit 5)."""
    from chewbot.report.recording_figures import errors_over_time, incisor_paths

    t, q, points, TR, TO, file_R, file_O = synthetic(tmp_path)
    rec = write_csv(tmp_path / "rec.csv", t, points)
    reg = write_registration(tmp_path / "reg.toml", file_R, file_O, markers=False)
    out = tmp_path / "task.csv"
    args = ["import-motion", rec, "--registration", reg, "--out", str(out), "--fit-registration", "--cutoff", "none", "--rate", "recording"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    page = (tmp_path / "task.report.html").read_text()
    assert page.startswith("<!-- written by chewbot") and "<!DOCTYPE html>" in page and "<script" not in page
    residuals = pd.read_csv(tmp_path / "task.residuals.csv")
    summary = read_sidecar(tmp_path / "task.residuals.csv")["summary"]
    share = next(line for line in summary if line.startswith("share ")).split()[1]  # "share 1.0000 ..."
    assert f"<td>{float(share):.4g}</td>" in page
    for column, unit in (("incisor_error", "mm"), ("mandible_error", "mm"), ("mandible_rotation_error", "deg")):
        values = residuals[f"{column} [{unit}]"].to_numpy()
        assert f"{round(values.max(), 9) + 0.0:.4g} / {round(np.sqrt(np.mean(values**2)), 9) + 0.0:.4g} {unit}" in page, column
    rec_exc, rep_exc = residuals["recorded_excursion [mm]"].to_numpy(), residuals["reproduced_excursion [mm]"].to_numpy()
    assert f"<td>{round(np.corrcoef(rec_exc, rep_exc)[0, 1], 9):.4g}</td>" in page
    assert page.count("<svg") == 2 and "t [s]" in page and "error [mm]" in page and "rotation error [deg]" in page
    path, e = np.column_stack([t, 0 * t, -t]) * MM, np.abs(np.sin(t))
    for fig in (incisor_paths(t, path, path, "x"), errors_over_time(t, e, e, e, t[:2], 1.0, "x")):
        for ax in fig.axes:  # every y axis with its unit; every x axis with its unit where it has a label
            assert ax.get_ylabel().endswith("]") and "[" in ax.get_ylabel(), ax.get_ylabel()
            assert ax.get_xlabel() == "" or (ax.get_xlabel().endswith("]") and "[" in ax.get_xlabel()), ax.get_xlabel()
        assert all(ax.get_xlabel() for ax in fig.axes if ax.get_subplotspec().is_last_row())
    assert runner.invoke(app, args).exit_code == 5  # the outputs exist: not replaced without --force
