"""Recordings chewbot did not make: a human jaw (tests/human_jaw.py: a mandible turning about its condylar axis
while its condyles glide along a curved eminence, Bennett lateral excursions, chewing cycles with an occlusal
phase) seen through a chin cluster and through a jaw-motion analyser's face-bow triangle, by a tracker at an
unknown rotation and position, 0.05 mm of noise, tracker spikes, a rest frame 1.6 deg open. The registration
files give only units, rest and scale. What is checked (docs/recordings.md, "Recordings of a human jaw"):
what was recorded is detected; the registration found from anatomy puts the mandible where the generator's true
registration puts it; the robot plays the recording; the result does not depend on how the tracker is turned."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from support import model
from typer.testing import CliRunner

import human_jaw
from chewbot.cli import app
from chewbot.errors import RecordingError
from chewbot.recordings.anatomy import MIN_LEVER_RATIO, detect
from chewbot.recordings.importer import ImportOptions, import_motion
from chewbot.recordings.register import MAX_SHIFT_MM, MAX_TURN_DEG
from chewbot.recordings.rigid import kabsch, to_base

runner = CliRunner()
MM = 1e-3
FIND = ImportOptions(fit_registration=True, timing="recording")
# The model's points of the mandible whose registered positions are compared (mm in {M}): incisor, condyles, molars.
POINTS = np.array([human_jaw.INCISOR, human_jaw.CONDYLE_L, human_jaw.CONDYLE_R, [45.0, 24.0, -22.0], [45.0, -24.0, -22.0]]) * MM


@functools.cache
def recordings(folder):
    return human_jaw.recordings(folder)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    return recordings(tmp_path_factory.mktemp("human"))


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


def true_poses(result, tracker):
    """The prepared recording's frames placed by the generator's true registration: the chin cluster's markers at
    their place in {M}, seen through the true tracker (p (N, 3) m, R (N, 3, 3))."""
    P = to_base(result.recording.positions, tracker.rotation, tracker.origin * MM)
    R, p = kabsch(human_jaw.CHIN * MM, P)
    return p, R


def point_errors(p, R, p_true, R_true):
    """The largest distance (mm) of the model's points of the mandible between two sets of poses, and the largest
    rotation between them (deg)."""
    a = np.einsum("nij,kj->nki", R, POINTS) + p[:, None]
    b = np.einsum("nij,kj->nki", R_true, POINTS) + p_true[:, None]
    turn = Rotation.from_matrix(np.einsum("nji,njk->nik", R, R_true)).as_rotvec()
    return float(np.linalg.norm(a - b, axis=2).max() / MM), float(np.degrees(np.linalg.norm(turn, axis=1)).max())


def test_what_was_recorded_is_detected(written):
    """The chin cluster rotates with the jaw: rho = L theta / e near 1 (measured 0.86); the face-bow triangle moves
    in parallel: rho near 0 (measured 0.004), both far from the threshold 0.25; one marker is a point path."""
    m = model("target")
    cluster = imported(written["cluster"][0]).recording.positions
    analyser = imported(written["analyser"][0]).recording.positions
    rigid, point, single = detect(m, cluster), detect(m, analyser), detect(m, analyser[:, :1])
    assert rigid.kind == "rigid" and rigid.lever_ratio > 3 * MIN_LEVER_RATIO, rigid
    assert point.kind == "point" and point.lever_ratio < MIN_LEVER_RATIO / 10, point
    assert single.kind == "point" and "one marker" in single.reason
    # the registration written says what was found
    assert imported(written["cluster"][0]).registration.tracked == "rigid"
    assert imported(written["analyser"][0]).registration.tracked == "incisor"


def test_a_chin_cluster_is_registered_where_the_true_registration_puts_it(written):
    """The prior alone (share 1 there: nothing moves it) puts every point of the mandible within 0.5 mm and 0.5 deg
    of where the generator's true registration puts it, frame by frame (measured 0.33 mm, 0.14 deg); the robot plays
    >= 90 % of the recorded rotation (measured 101.7 %: the fit's errors at the peak add to it) and >= 90 % of the
    incisal excursion, in step (r >= 0.95)."""
    path, motion, tracker = written["cluster"]
    result = imported(path)
    assert result.found.share == 1.0 and not result.found.refined
    mm, deg = point_errors(result.rigid.p, result.rigid.R, *true_poses(result, tracker))
    assert mm <= 0.5 and deg <= 0.5, (mm, deg)
    m = result.measures()
    assert m.rotation_share >= 0.9 and m.excursion_share >= 0.9 and m.r_rotation >= 0.95 and m.r_excursion >= 0.95, m.describe()


def test_a_jaw_motion_analyser_path_is_registered_on_the_incisor(written):
    """The face-bow triangle (incisal point and condylar points, moved in parallel) turned onto the model's: the
    registered incisal path lies within 0.5 mm of the generator's incisal point in every frame (measured 0.09 mm),
    and the robot's incisor plays >= 60 % of its excursion (measured 100.1 %, share 1), in step."""
    path, motion, tracker = written["analyser"]
    result = imported(path)
    offset = human_jaw.INCISOR - np.mean([human_jaw.INCISOR, human_jaw.CONDYLE_L, human_jaw.CONDYLE_R], axis=0)
    truth = to_base(result.recording.positions, tracker.rotation, tracker.origin * MM).mean(axis=1) + offset * MM
    m = result.measures()
    assert np.linalg.norm(m.recorded_incisor - truth, axis=1).max() <= 0.5 * MM
    assert m.excursion_share >= 0.6 and m.r_excursion >= 0.95, m.describe()


def _same_under_turn(written, name, turn):
    path = written[name][0]
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
    triangle's here turned 180 deg about x and 90 deg about z (25 s each), about every axis in the slow run."""
    _same_under_turn(written, name, turn)


@pytest.mark.slow
@pytest.mark.parametrize("turn", [t for t in TURNS if t not in (TURNS[1], TURNS[4])])
def test_the_analysers_tracker_frame_turned_about_every_axis_changes_nothing(written, turn):
    _same_under_turn(written, "analyser", turn)


def test_tracked_overrides_the_detection(written, tmp_path):
    """tracked = "incisor" registers the chin cluster's markers' mean as an incisal path (the hinge guess for the
    orientation); tracked = "rigid" on the face-bow triangle, which turns 0.1 deg, is refused: no opening axis."""
    cluster, analyser = written["cluster"][0], written["analyser"][0]
    reg = tmp_path / "incisor.toml"
    reg.write_text('units = "mm"\ntracked = "incisor"\n')
    as_point = import_motion(cluster, reg, ImportOptions(timing="recording"))
    assert as_point.registration.point_path and as_point.detected is None
    rigid = tmp_path / "rigid.toml"
    rigid.write_text('units = "mm"\nrest = "first"\ntracked = "rigid"\n')
    with pytest.raises(RecordingError, match="no opening axis"):
        import_motion(analyser, rigid, FIND)


def test_the_search_never_leaves_its_bounds(written, tmp_path):
    """A recording the robot cannot play whole (the chin cluster's first 3.4 s, two chewing cycles, at 1.6 times its
    size, turning 20 deg): at the prior some frames are beyond the tolerance, and the search refines it, within
    MAX_TURN_DEG and MAX_SHIFT_MM per axis, until every frame passes (measured: the tracker turned 0.9 deg and the
    placement 0.9 deg, share 1)."""
    path = written["cluster"][0]
    lines = path.read_text().splitlines()[:171]
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    points = rows[:, 1:].reshape(len(rows), -1, 3)
    R, p = kabsch(points[0], points)  # the motion from the first frame, larger: rotation angle and displacement
    larger = Rotation.from_rotvec(1.6 * Rotation.from_matrix(R).as_rotvec()).as_matrix()
    big = np.einsum("nij,kj->nki", larger, points[0]) + 1.6 * p[:, None]
    out = tmp_path / "big.csv"
    out.write_text(lines[0] + "\n" + "\n".join(",".join(f"{v:.6f}" for v in np.r_[row[0], b.ravel()]) for row, b in zip(rows, big)) + "\n")
    out.with_suffix(".toml").write_text(path.with_suffix(".toml").read_text())
    result = import_motion(out, out.with_suffix(".toml"), FIND)
    f = result.found
    assert f.refined and f.share == 1.0 and f.turn_deg <= MAX_TURN_DEG + 1e-9
    assert f.placement_turn_deg <= MAX_TURN_DEG + 1e-9 and f.placement_shift_mm <= np.sqrt(3) * MAX_SHIFT_MM + 1e-9


def test_the_written_task_runs(written, tmp_path):
    """The command on the chin cluster (default --timing limits): the task, the registration (what was detected,
    the prior, the share) and the report (detection, prior, the registration and how far it moved, the incisal path
    in {S} and in the tracker's frame) are written, and `chewbot run` on the task exits 0 with no failed check."""
    path = written["cluster"][0]
    out = tmp_path / "task.csv"
    result = runner.invoke(app, ["import-motion", str(path), "--registration", str(path.with_suffix(".toml")),
                                 "--fit-registration", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "detected: a rigid body that rotates" in result.output and "registration: the prior" in result.output
    text = (tmp_path / "task.registration.toml").read_text()
    assert 'tracked = "rigid"' in text and "# detected: a rigid body" in text and "# prior: the opening axis" in text
    page = (tmp_path / "task.report.html").read_text()
    assert "What was recorded and how it was registered" in page and "tracker of the prior" in page
    assert "in the tracker" in page.split("<h2>Incisor path</h2>")[1].split("<h2>")[0]  # the second row of the figure
    run = runner.invoke(app, ["run", "--task", str(out), "--out", str(tmp_path / "run")])
    assert run.exit_code == 0 and "0 failed" in run.output, run.output
