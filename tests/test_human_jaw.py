"""Recordings chewbot did not make: human jaws (tests/human_jaw.py: subjects drawn from published ranges of
anatomy, a mandible turning about its condylar axis while its condyles glide along a curved eminence, from the
start of the opening or after a first pure rotation; Bennett lateral excursions, chewing cycles with an occlusal
phase) seen through a chin cluster and through a jaw-motion analyser's face-bow triangle, by a tracker at an
unknown rotation and position, 0.05 mm of noise, tracker spikes, a rest frame 1.6 deg open. The registration
files give only units, rest and scale. What is checked (docs/recordings.md, "Recordings of a human jaw"):
what was recorded is detected; the registration found from anatomy puts the mandible where the generator's true
registration puts it; the robot plays the recording; the result does not depend on how the tracker is turned;
a recording like issue 28's chin cluster is played whole on the hinge."""

from __future__ import annotations

import json

import functools
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from support import model
from typer.testing import CliRunner

import human_jaw
from chewbot.cli import app
from chewbot.errors import RecordingError
from chewbot.recordings.anatomy import MIN_LEVER_RATIO, detect
from chewbot.recordings.importer import ImportOptions, import_motion, point_path
from chewbot.recordings.register import MAX_SHIFT_MM, MAX_TURN_DEG
from chewbot.recordings.rigid import kabsch, to_base

runner = CliRunner()
MM = 1e-3
FIND = ImportOptions(fit_registration=True, timing="recording")
# The model's points of the mandible whose registered positions are compared (mm in {M}): incisor, condyles, molars.
POINTS = np.array([human_jaw.MODEL_INCISOR, *human_jaw.MODEL_CONDYLES, [45.0, 24.0, -22.0], [45.0, -24.0, -22.0]]) * MM
# Subjects drawn from the published ranges (human_jaw.RANGES) besides the suite's first, by seed: whose condyles
# start translating after a first pure rotation (3.1, 6.1, 3.5 deg; eminences 42.9, 58.0, 33.8 deg), and from the
# start of the opening (eminences 34.2, 58.5 deg).
HINGE_SUBJECTS = (1, 4, 12)
GLIDING_SUBJECTS = (2, 10)


@functools.cache
def recordings(folder, seed=human_jaw.SEED):
    return human_jaw.recordings(folder, seed)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("human")


@pytest.fixture(scope="module")
def written(folder):
    return recordings(folder / "suite")


@pytest.fixture(scope="module")
def issue(folder):
    return human_jaw.issue_recordings(folder / "issue")


@functools.cache
def imported(path, turn=None):
    """The import of a recording (``turn``: a rotation vector (deg) by which its tracker frame is turned, its
    points rewritten in the turned frame)."""
    path = path if turn is None else _turned(path, np.array(turn))
    return import_motion(path, path.with_suffix(".toml"), FIND)


def _turned(path, turn):
    """The same recording seen by the tracker turned by ``turn``: every point p_T becomes G^T p_T."""
    G = Rotation.from_rotvec(np.radians(turn)).as_matrix()
    lines = path.read_text().splitlines()
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    points = rows[:, 1:].reshape(len(rows), -1, 3) @ G
    out = path.with_name(f"{path.stem}_{'_'.join(f'{v:g}' for v in turn)}.csv")
    body = np.column_stack([rows[:, 0], points.reshape(len(rows), -1)])
    out.write_text(lines[0] + "\n" + "\n".join(",".join(f"{v:.12g}" for v in row) for row in body) + "\n")
    out.with_suffix(".toml").write_text(path.with_suffix(".toml").read_text())
    return out


def true_poses(result, w):
    """The prepared recording's frames placed by the generator's true registration (human_jaw.robot_frames): the
    chin cluster's markers at their place on the subject's mandible, seen through the true tracker, turned about
    the condylar axis so that the subject's condylar path lies on the robot's (p (N, 3) m, R (N, 3, 3))."""
    P = to_base(result.recording.positions, w.tracker.rotation, w.tracker.origin * MM)
    R, p = kabsch(human_jaw.chin(w.motion.subject) * MM, P)
    p, R = human_jaw.robot_frames(w.motion, p / MM, R)
    return p * MM, R


def point_errors(p, R, p_true, R_true):
    """The largest distance (mm) of the model's points of the mandible between two sets of poses, and the largest
    rotation between them (deg)."""
    a = np.einsum("nij,kj->nki", R, POINTS) + p[:, None]
    b = np.einsum("nij,kj->nki", R_true, POINTS) + p_true[:, None]
    turn = Rotation.from_matrix(np.einsum("nji,njk->nik", R, R_true)).as_rotvec()
    return float(np.linalg.norm(a - b, axis=2).max() / MM), float(np.degrees(np.linalg.norm(turn, axis=1)).max())


def true_incisor(result, w):
    """The face-bow transfer of the prepared analyser recording (human_jaw.face_bow_incisor): its apex, the
    subject's incisal point, seen through the true tracker, turned so that the subject's Bonwill triangle lies on
    the model's, at the model's incisor at intercuspal contact (N, 3) m."""
    who = w.motion.subject
    apex = to_base(result.recording.positions, w.tracker.rotation, w.tracker.origin * MM)[:, 0] / MM
    return ((apex - who.incisor) @ human_jaw.face_bow_rotation(who).T + human_jaw.MODEL_INCISOR) * MM


def test_what_was_recorded_is_detected(written):
    """The chin cluster rotates with the jaw: rho = L theta / e near 1; the face-bow triangle moves in parallel:
    rho near 0, both far from the threshold 0.25; one marker is a point path."""
    m = model("target")
    cluster = imported(written["cluster"].path).recording.positions
    analyser = imported(written["analyser"].path).recording.positions
    rigid, point, single = detect(m, cluster), detect(m, analyser), detect(m, analyser[:, :1])
    assert rigid.kind == "rigid" and rigid.lever_ratio > 3 * MIN_LEVER_RATIO, rigid
    assert point.kind == "point" and point.lever_ratio < MIN_LEVER_RATIO / 10, point
    assert single.kind == "point" and "one marker" in single.reason
    # the registration written says what was found
    assert imported(written["cluster"].path).registration.tracked == "rigid"
    assert imported(written["analyser"].path).registration.tracked == "incisor"


def _holds_on_the_cluster(w):
    result = imported(w.path)
    mm, deg = point_errors(result.rigid.p, result.rigid.R, *true_poses(result, w))
    m = result.measures()
    assert mm <= 0.5 and deg <= 0.5, (w.motion.subject, mm, deg, result.found.describe())
    assert m.rotation_share >= 0.9 and m.r_rotation >= 0.95 and m.r_excursion >= 0.95, m.describe()
    return result


def test_a_chin_cluster_is_registered_where_the_true_registration_puts_it(written):
    """The suite's first subject (eminence 52 deg, a first pure rotation of 10 deg): the prior alone (share 1 there:
    nothing moves it) puts every point of the mandible within 0.5 mm and 0.5 deg of where the generator's true
    registration puts it, frame by frame; the robot plays >= 90 % of the recorded rotation, in step (r >= 0.95)."""
    result = _holds_on_the_cluster(written["cluster"])
    assert result.found.share == 1.0 and not result.found.refined


@pytest.mark.parametrize("seed", HINGE_SUBJECTS)
def test_a_chin_cluster_holds_on_varied_anatomy(folder, seed):
    """Subjects drawn from the published ranges (eminence 25-60 deg, condylar path 10-15 mm, intercondylar distance
    90-110 mm) whose opening starts with a pure rotation: the registration found puts the mandible within 0.5 mm and
    0.5 deg of the true registration (the subject's motion with its eminence turned onto the robot's plane: that
    turn is the robot's), and the robot plays >= 90 % of the rotation, in step."""
    _holds_on_the_cluster(recordings(folder / f"subject{seed}", seed)["cluster"])


@pytest.mark.parametrize("seed", GLIDING_SUBJECTS)
def test_a_chin_cluster_whose_condyles_glide_from_the_start_is_played_whole(folder, seed):
    """Subjects whose condyles translate from the start of the opening: the recording is played whole (share 1,
    >= 90 % of the rotation, in step) and every pose turned within 0.5 deg of the true registration's; where the
    condylar axis lies across the glide is not fixed by the data (docs/recordings.md: the axis is put at the height
    of the opening's centre of rotation, 14-35 mm below the condyles), so that the positions differ from the true
    registration's by a shift of the axis along the plane's normal (2.5-4.7 mm at the incisor for these two
    subjects), which the robot plays as well and this test does not bound."""
    w = recordings(folder / f"subject{seed}", seed)["cluster"]
    result = imported(w.path)
    deg = point_errors(result.rigid.p, result.rigid.R, *true_poses(result, w))[1]
    m = result.measures()
    assert result.found.share == 1.0 and deg <= 0.5, (w.motion.subject, deg)
    assert m.rotation_share >= 0.9 and m.r_rotation >= 0.95 and m.r_excursion >= 0.95, m.describe()


def _holds_on_the_analyser(w):
    result = imported(w.path)
    m = result.measures()
    assert np.linalg.norm(m.recorded_incisor - true_incisor(result, w), axis=1).max() <= 0.5 * MM
    assert m.excursion_share >= 0.6 and m.r_excursion >= 0.95, m.describe()
    return result


def test_a_jaw_motion_analyser_path_is_registered_on_the_incisor(written):
    """The face-bow triangle (incisal point and condylar points, moved in parallel) turned onto the model's: the
    registered incisal path lies within 0.5 mm of the face-bow transfer of the generator's incisal point in every
    frame, and the robot's incisor plays >= 60 % of its excursion, in step."""
    _holds_on_the_analyser(written["analyser"])


@pytest.mark.parametrize("seed", HINGE_SUBJECTS + GLIDING_SUBJECTS)
def test_a_jaw_motion_analyser_holds_on_varied_anatomy(folder, seed):
    _holds_on_the_analyser(recordings(folder / f"subject{seed}", seed)["analyser"])


def _same_under_turn(written, name, turn):
    path = written[name].path
    a, b = imported(path), imported(path, tuple(turn))
    assert b.found.share == a.found.share
    if a.registration.point_path:
        assert np.linalg.norm(a.measures().recorded_incisor - b.measures().recorded_incisor, axis=1).max() <= 0.1 * MM
    else:
        mm, deg = point_errors(b.rigid.p, b.rigid.R, a.rigid.p, a.rigid.R)
        assert mm <= 0.1 and deg <= 0.1, (mm, deg)


TURNS = [(90, 0, 0), (180, 0, 0), (0, 90, 0), (0, 180, 0), (0, 0, 90), (0, 0, 180)]


@pytest.mark.parametrize("name, turn", [("cluster", t) for t in TURNS] + [("analyser", TURNS[1]), ("analyser", TURNS[4])])
def test_the_tracker_frame_turned_changes_nothing(written, name, turn):
    """The same recording with the tracker's frame turned by 90 or 180 deg about each axis: the same poses of the
    mandible in {S} (0.1 mm, 0.1 deg; measured to rounding) and the same share: the prior is built from the
    recording alone (directions and points found in it, no axis of the tracker's frame used). The face-bow
    triangle's here turned 180 deg about x and 90 deg about z, about every axis in the slow run."""
    _same_under_turn(written, name, turn)


@pytest.mark.slow
@pytest.mark.parametrize("turn", [t for t in TURNS if t not in (TURNS[1], TURNS[4])])
def test_the_analysers_tracker_frame_turned_about_every_axis_changes_nothing(written, turn):
    _same_under_turn(written, "analyser", turn)


def test_tracked_overrides_the_detection(written, tmp_path):
    """tracked = "incisor" registers the chin cluster's markers' mean as an incisal path (the hinge guess for the
    orientation); tracked = "rigid" on the face-bow triangle, which does not turn, is refused: no opening axis."""
    cluster, analyser = written["cluster"].path, written["analyser"].path
    reg = tmp_path / "incisor.toml"
    reg.write_text('units = "mm"\ntracked = "incisor"\n')
    as_point = import_motion(cluster, reg, ImportOptions(timing="recording"))
    assert as_point.registration.point_path and as_point.detected is None
    rigid = tmp_path / "rigid.toml"
    rigid.write_text('units = "mm"\nrest = "first"\ntracked = "rigid"\n')
    with pytest.raises(RecordingError, match="no opening axis"):
        import_motion(analyser, rigid, FIND)


def test_a_condyle_path_is_registered_on_the_condyle(written, tmp_path):
    """A landmark other than the incisor: the path of the subject's left condyle alone (one marker, the chin
    cluster's subject chewing), tracked = "condyle_left": its glide is carried onto the robot's condylar path (the
    line of steepest descent of the left HKP plane) and the robot's left condyle plays >= 60 % of its excursion,
    in step; the registered path goes down that line within 1 deg (the prior's defining direction: the path's
    principal direction on it)."""
    w = written["cluster"]
    rng = np.random.default_rng(human_jaw.SEED)
    seen = human_jaw.observe(w.tracker.see(w.motion.point(w.motion.subject.condyles[0])[:, None]), rng)
    path = human_jaw.write_csv(tmp_path / "condyle.csv", w.motion.t, seen, names=("C",))
    path.with_suffix(".toml").write_text(human_jaw.REGISTRATION + 'tracked = "condyle_left"\n')
    result = import_motion(path, path.with_suffix(".toml"), FIND)
    assert result.registration.tracked == "condyle_left"
    m = result.measures()
    assert m.excursion_share >= 0.6 and m.r_excursion >= 0.95, m.describe()
    d = m.recorded_incisor - m.recorded_incisor[np.argmax(m.recorded_incisor[:, 2])]
    u = np.linalg.svd(d - d.mean(axis=0), full_matrices=False)[2][0]
    plane = np.array([1.0, 0.0, -1.1]) / np.hypot(1.0, 1.1)  # forward and down along 1.1 x + z = const
    assert np.degrees(np.arccos(min(1.0, abs(u @ plane)))) <= 1.0, u


LARGER = 2.0


def test_the_search_never_leaves_its_bounds(written, tmp_path):
    """A recording the robot cannot play whole (the chin cluster's first 3.4 s, two chewing cycles, at twice its
    size): at the prior some frames are beyond the tolerance, and the search refines it, within MAX_TURN_DEG and
    MAX_SHIFT_MM per axis, until every frame passes."""
    path = written["cluster"].path
    lines = path.read_text().splitlines()[:171]
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    points = rows[:, 1:].reshape(len(rows), -1, 3)
    R, p = kabsch(points[0], points)  # the motion from the first frame, larger: rotation angle and displacement
    larger = Rotation.from_rotvec(LARGER * Rotation.from_matrix(R).as_rotvec()).as_matrix()
    big = np.einsum("nij,kj->nki", larger, points[0]) + LARGER * p[:, None]
    out = tmp_path / "big.csv"
    out.write_text(lines[0] + "\n" + "\n".join(",".join(f"{v:.6f}" for v in np.r_[row[0], b.ravel()]) for row, b in zip(rows, big)) + "\n")
    out.with_suffix(".toml").write_text(path.with_suffix(".toml").read_text())
    result = import_motion(out, out.with_suffix(".toml"), FIND)
    f = result.found
    assert f.refined and f.share == 1.0 and f.turn_deg <= MAX_TURN_DEG + 1e-9
    assert f.placement_turn_deg <= MAX_TURN_DEG + 1e-9 and f.placement_shift_mm <= np.sqrt(3) * MAX_SHIFT_MM + 1e-9


def _runs(path, tmp_path, *expected, options=(), warnings=False):
    out = tmp_path / f"{path.stem}_task.csv"
    result = runner.invoke(app, ["import-motion", str(path), "--registration", str(path.with_suffix(".toml")),
                                 "--fit-registration", "--out", str(out), *options])
    assert result.exit_code == 0, result.output
    for text in expected:
        assert text in result.output, result.output
    run = runner.invoke(app, ["run", "--task", str(out), "--out", str(tmp_path / f"{path.stem}_run")])
    assert run.exit_code == 0, run.output
    record = json.loads((tmp_path / f"{path.stem}_run" / "run.json").read_text())
    failed = {c["name"]: c["severity"] for c in record["checks"] if c["passed"] is False}
    if warnings:  # checks that failed only as warnings
        assert all(v == "warning" for v in failed.values()), failed
    else:
        # no failed check but contact-pull, a warning: with the drive's rotors the minimum-norm torques pull a condyle
        # (as on the default task: CHANGELOG)
        assert set(failed) <= {"contact-pull"}, failed
    return out, result.output


def test_the_written_task_runs(written, tmp_path):
    """The command on the chin cluster (default --timing limits): the task, the registration (what was detected,
    the prior, the share) and the report (detection, prior, the registration and how far it moved, the incisal path
    in {S} and in the tracker's frame) are written, and `chewbot run` on the task exits 0 with no failed check."""
    out = _runs(written["cluster"].path, tmp_path, "detected: a rigid body that rotates", "registration: the prior")[0]
    text = out.with_name(f"{out.stem}.registration.toml").read_text()
    assert 'tracked = "rigid"' in text and "# detected: a rigid body" in text and "# prior: the opening axis" in text
    page = out.with_name(f"{out.stem}.report.html").read_text()
    assert "What was recorded and how it was registered" in page and "tracker of the prior" in page
    assert "in the tracker" in page.split("<h2>Incisor path</h2>")[1].split("<h2>")[0]  # the second row of the figure


def test_issue_28s_chin_cluster_is_played_whole_on_the_hinge(issue, tmp_path):
    """Like issue 28's first real recording (a chin cluster, 8 s at 50 Hz, up to about 5 deg and 9 mm, settling
    after 6 s, two tracker spikes): the two spikes are dropped, the recording is registered on the condylar axis
    and played whole (share 1, >= 90 % of the rotation, in step), every pose turned by the true registration's
    angle within 0.5 deg, and `chewbot run` on the written task exits 0 with no failed
    check. Its condyles do not glide (the openings stay within the subject's 8 deg of pure rotation): the turn of
    the placement about the condylar axis is not fixed by the data, nor the true registration's (no condylar path
    to put on the robot's), and a pose's angle does not change with it. Not bounded here: the opening axis is found
    2.6 deg off the condylar axis (the 0.6 deg sideways swing of the second opening tilts the principal direction
    of turns of 5 deg), which puts the condyles 3.2 mm from the true registration's (docs/recordings.md)."""
    w = issue["tapping"]
    result = imported(w.path)
    R = true_poses(result, w)[1]
    angle = [np.linalg.norm(Rotation.from_matrix(r).as_rotvec(), axis=1) for r in (result.rigid.R, R)]
    assert np.degrees(np.abs(angle[0] - angle[1])).max() <= 0.5
    m = result.measures()
    assert result.found.share == 1.0 and m.rotation_share >= 0.9 and m.r_rotation >= 0.95, m.describe()
    assert sum("tracker spike dropped" in n for n in result.notes) == 2, result.notes
    _runs(w.path, tmp_path, "detected: a rigid body that rotates")


def test_a_triangle_that_turns_little_is_a_point_path_within_max_rigid(issue):
    """The point-path rule is the rotation against the excursion: issue 28's analyser, whose face-bow triangle turns
    up to 1.4 deg while its incisal point moves 44 mm down and 33 mm back, is a point path (rho below MIN_LEVER_RATIO), and its
    rigid-fit residual is the markers' distance from the rigid body they form, the tracker's noise (0.05 mm per
    coordinate: 0.3 mm is 6 of its standard deviations), within --max-rigid's default 1 mm. Their distance from
    moving in parallel with their mean, the residual before, exceeds it (about 1.65 mm)."""
    path = issue["wide_opening"].path
    rows = np.loadtxt(path, delimiter=",", skiprows=1)
    points = rows[:, 1:].reshape(len(rows), -1, 3) * MM
    m = model("target")
    assert detect(m, points).kind == "point"
    residual = point_path(m, m.incisor, points, ("P1", "P2", "P3")).max_mm.max()
    assert residual <= 0.3 < ImportOptions().max_rigid_mm, residual
    offsets = points - points.mean(axis=1, keepdims=True)
    assert np.linalg.norm(offsets - offsets[:1], axis=2).max() / MM > ImportOptions().max_rigid_mm


@pytest.mark.slow  # the import about 25 s of CPU time, mostly the registration search (docs/recordings.md), then a run
def test_issue_28s_jaw_motion_analyser_is_registered_on_the_incisor(issue, tmp_path):
    """Like issue 28's second real recording (a jaw-motion analyser's face-bow triangle moved in parallel, the
    incisal point 44 mm down and 34 mm back, 12.7 s at 50 Hz, not scaled into the robot's reach, which opens the
    incisor 40.5 mm): detected as a point path, registered on the incisor, its share reported, and the robot plays
    >= 60 % of the incisal excursion (the issue's bound for point paths) in step (r >= 0.95); the issue found 73-85 %
    reachable on the real one (docs/recordings.md gives this one's). `chewbot run` on the written task (default
    --timing limits) exits 0, its only failed checks warnings (the openings ride the fit's 10 deg transmission margin
    at their widest: near-singular, a warning). With the default --max-rigid: the triangle turns up to 1.4 deg as a
    whole, which is no marker moving relative to the others."""
    w = issue["wide_opening"]
    out, output = _runs(w.path, tmp_path, "detected: the path of one point", warnings=True)
    played = re.search(r"([0-9.]+) % of the incisal excursion \(peak [0-9.]+ mm\), r = ([0-9.]+)", output)
    assert float(played.group(1)) >= 60 and float(played.group(2)) >= 0.95, output
    text = out.with_name(f"{out.stem}.registration.toml").read_text()
    assert 'tracked = "incisor"' in text
    share = float(re.search(r"# share ([0-9.]+)", text).group(1))
    assert 0.6 <= share <= 1.0, text
