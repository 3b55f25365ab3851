"""Recordings to tasks (chewbot import-motion): synthetic recordings built here from known robot motions, markers at
known {M} positions seen through a known tracker transform, written in each format.

The poses that generate the markers are computed here from the conventions (docs/conventions.md: R = Rx Ry Rz
as SciPy's intrinsic "XYZ", the parasitic gamma and Z of the HKP planes), not from chewbot's graphs.
"""

from __future__ import annotations

from dataclasses import replace

import json

import numpy as np
import pytest
from support import model
from recording_support import BODY, DEG, EXACT, MM, chewing, chewing_recording, pose, registration, seen, write_csv
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.commands.common import EXIT_BAD_INPUT, EXIT_OUTPUT, EXIT_UNREACHABLE
from chewbot.errors import RecordingError
from chewbot.recordings.formats import read_artisynth, read_csv, read_recording
from chewbot.recordings.importer import ImportOptions, import_motion
from chewbot.recordings.prepare import low_pass
from chewbot.recordings.registration import registration_from_dict
from chewbot.recordings.rigid import kabsch, scale_motion
from chewbot.task.csvio import read_task_csv

runner = CliRunner()


# ------------------------------------------------------------------ the fit recovers known motions


def test_noise_free_recording_gives_back_the_generating_motion(tmp_path):
    t, q = chewing()
    m = model("target")
    path = write_csv(tmp_path / "rec.csv", t, seen(*pose(m, q)))
    result = import_motion(path, registration(tmp_path), EXACT)
    assert result.passed.all() and np.array_equal(result.task.t, t)
    assert np.abs(result.task.q - q).max() < 1e-9  # m and rad; the fit ends at rounding (measured 1e-15)
    assert np.nanmax(result.fit.position_error_mm) < 1e-9 and result.rigid.max_mm.max() < 1e-9


def test_the_6rss_fits_a_six_dof_motion_exactly_where_it_is_reachable(tmp_path):
    """The 6RSS follows any reachable pose: a motion with its own Z and gamma, off the target's HKP planes. Pushed
    further, chain 4 nears its dead point: there the fit ends where its transmission angle reaches the margin
    (--min-transmission, 10 deg by default)."""
    from chewbot.kinematics.ik import transmission

    margin = np.sin(np.radians(10.0))

    t, q4 = chewing()
    p, R = pose(model("target"), q4)
    for dz_mm, dgamma_deg in ((-0.5, -1.0), (0.8, 2.0)):
        q6 = np.column_stack([p, Rotation.from_matrix(R).as_euler("XYZ")])
        q6[:, 2] += dz_mm * MM * np.sin(np.pi * t / t[-1]) ** 2
        q6[:, 5] += dgamma_deg * DEG * np.sin(2 * np.pi * t / t[-1])
        path = write_csv(tmp_path / "rec.csv", t, seen(*pose(model("6rss"), q6)))
        result = import_motion(path, registration(tmp_path), ImportOptions(model="6rss", cutoff_hz=None, rate_hz=None, max_position_mm=5))
        assert result.task.coords == ("X", "Y", "Z", "alpha", "beta", "gamma")
        out = result.fit.outside.any(axis=1)
        assert np.abs(result.task.q - q6)[~out].max() < 1e-9
        if dz_mm < 0:
            assert not out.any()
        else:
            assert out.sum() > 3 and set(np.array(result.fit.constraint_names)[result.fit.outside.any(axis=0)]) == {"chain 4 reach"}
            sin_tr = transmission(model("6rss"), *pose(model("6rss"), result.fit.q[out]))[:, 3]
            assert np.abs(sin_tr - margin).max() < 1e-9
    # the target cannot follow it: the same recording fails there and names frames
    target = import_motion(path, registration(tmp_path), ImportOptions(cutoff_hz=None, rate_hz=None, max_position_mm=0.1))
    assert target.task is None and target.failures()


def _jacobian_S(m, q0, b, w_p, w_o):
    """The weighted residual's Jacobian at q0 in {S} form: rows w_p dx_b/dq / mm and w_o omega_q / deg, by central
    differences of :func:`pose` (h = 1e-6: error ~1e-10 relative)."""
    h = 1e-6
    cols = []
    p0, R0 = pose(m, q0[None])
    for i in range(len(q0)):
        dq = np.zeros_like(q0)
        dq[i] = h
        (pp, Rp), (pm, Rm) = pose(m, (q0 + dq)[None]), pose(m, (q0 - dq)[None])
        dx = ((pp + Rp @ b) - (pm + Rm @ b))[0] / (2 * h)
        W = (Rp[0] - Rm[0]) @ R0[0].T / (2 * h)  # [omega]x
        cols.append(np.r_[w_p * dx / MM, w_o * np.array([W[2, 1], W[0, 2], W[1, 0]]) / DEG])
    return np.array(cols).T


@pytest.mark.parametrize("mechanism", ["target", "6rss"])
def test_with_noise_the_error_matches_the_noise_level(tmp_path, mechanism):
    """Markers with Gaussian noise (sigma per coordinate) on a still pose, 1500 frames, --cutoff none.

    The rigid fit's pose error is linear in the noise: with a_k the markers about their centroid, the centroid
    moves by the mean noise (covariance sigma^2 / K) and the rotation by M^-1 sum a_k x n_k (covariance
    sigma^2 M^-1, M = sum(abs(a_k)^2 I - a_k a_k^T)), uncorrelated. The robot's fit is the weighted least-squares
    projection of that error: dq = (J^T J)^-1 J^T W dpose, J the weighted residual's Jacobian. The sum of squared
    marker residuals has expectation sigma^2 (3K - 6). The standard deviations of the fitted coordinates must match
    the prediction within 10 %: their sample estimate over 1500 frames has a relative standard error of
    1 / sqrt(2 * 1500) = 1.8 %, so 10 % is over 5 standard errors.
    """
    m = model("target")
    sigma, n = 0.05 * MM, 1500
    q0 = np.array([2 * MM, 1 * MM, 1 * DEG, 6 * DEG])
    p0, R0 = pose(m, q0[None])
    if mechanism == "6rss":
        q0 = np.r_[p0[0], Rotation.from_matrix(R0[0]).as_euler("XYZ")]
    rng = np.random.default_rng(1)
    t = np.arange(n) / 100.0
    points = seen(np.repeat(p0, n, 0), np.repeat(R0, n, 0)) + sigma * rng.standard_normal((n, len(BODY), 3))
    result = import_motion(write_csv(tmp_path / "rec.csv", t, points), registration(tmp_path),
                           ImportOptions(model=mechanism, cutoff_hz=None, rate_hz=None, max_position_mm=10, max_orientation_deg=10))
    assert result.passed.all()
    err = result.task.q - q0

    a = np.einsum("ij,kj->ki", R0[0], BODY - BODY.mean(axis=0))
    M = sum(ak @ ak * np.eye(3) - np.outer(ak, ak) for ak in a)
    b = m.incisor
    d = R0[0] @ (b - BODY.mean(axis=0))  # measure point about the markers' centroid, in {S}
    cross = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
    A = np.block([[np.eye(3), -cross], [np.zeros((3, 3)), np.eye(3)]])  # (dt, dphi) -> (dx_b, dphi)
    C = sigma**2 * A @ np.block([[np.eye(3) / len(BODY), np.zeros((3, 3))], [np.zeros((3, 3)), np.linalg.inv(M)]]) @ A.T
    W = np.diag([1 / MM] * 3 + [1 / DEG] * 3)  # the registration's weights are 1 per mm and 1 per degree
    J = _jacobian_S(m, q0, b, 1.0, 1.0)
    G = np.linalg.solve(J.T @ J, J.T @ W)
    predicted = np.sqrt(np.diag(G @ C @ G.T))
    assert np.allclose(err.std(axis=0), predicted, rtol=0.1), (err.std(axis=0), predicted)
    assert np.abs(err.mean(axis=0)).max() < 5 * predicted.max() / np.sqrt(n)  # no bias
    ssr = np.mean(np.sum((result.rigid.distances) ** 2, axis=1))
    assert ssr == pytest.approx(sigma**2 * (3 * len(BODY) - 6), rel=0.1)


def test_a_motion_off_the_hkp_constraints_reports_its_distance_from_them(tmp_path):
    """At each frame of a target motion q0, the recorded pose is moved by a residual rho orthogonal to what the
    target can do (J^T rho = 0, J the weighted residual's Jacobian at q0): q0 stays the nearest pose, and the
    reported errors are rho's parts, abs(rho_p) mm and abs(rho_o) deg. The weights are 2 per mm and 0.5 per
    degree. Exact to first order in the rotation between fitted and recorded orientation (Jacobian at the
    recorded one, 0.3 deg here): the reported errors to a relative 1e-3, q0 to 1e-8."""
    m = model("target")
    t, q = chewing(rate=50.0)
    w_p, w_o = 2.0, 0.5
    p, R = pose(m, q)
    b = np.array([80.0, 10.0, -25.0]) * MM
    rec_p, rec_R, rho_p, rho_o = [], [], [], []
    for i in range(len(t)):  # the construction, per frame (test side)
        J = _jacobian_S(m, q[i], b, w_p, w_o)
        null = np.linalg.svd(J)[0][:, 4:]  # the residuals that no change of q can reduce: J^T rho = 0
        rho = null @ (null.T @ np.ones(6))  # one with both a position and a rotation part
        rho *= 0.4 / np.linalg.norm(rho)
        # the recorded pose: the measure point moved by -rho_p / w_p, the orientation turned by -rho_o / w_o (in {S}),
        # so that the residual at q0 is rho (position fitted minus recorded, rotation from recorded to fitted)
        rp, ro = rho[:3] * MM / w_p, -rho[3:] * DEG / w_o
        x = p[i] + R[i] @ b
        Rr = Rotation.from_rotvec(ro).as_matrix() @ R[i]
        rec_R.append(Rr)
        rec_p.append(x - rp - Rr @ b)
        rho_p.append(np.linalg.norm(rp) / MM)
        rho_o.append(np.linalg.norm(ro) / DEG)
    path = write_csv(tmp_path / "rec.csv", t, seen(np.array(rec_p), np.array(rec_R)))
    reg = registration(tmp_path, fit={"position_weight_per_mm": w_p, "orientation_weight_per_deg": w_o, "point_mm": (b / MM).tolist()})
    result = import_motion(path, reg, ImportOptions(cutoff_hz=None, rate_hz=None))
    assert result.passed.all() and min(rho_p) > 0.02 and min(rho_o) > 0.02  # both parts present in every frame
    assert np.allclose(result.fit.position_error_mm, rho_p, rtol=1e-3)
    assert np.allclose(result.fit.orientation_error_deg, rho_o, rtol=1e-3)
    assert np.abs(result.fit.q - q).max() < 1e-8
    failing = import_motion(path, reg, ImportOptions(cutoff_hz=None, rate_hz=None, max_position_mm=0.5 * max(rho_p)))
    assert failing.task is None and not failing.passed.all() and "position error up to " in failing.failures()[0]


def test_where_the_motion_leaves_the_sockets_the_nearest_admissible_pose_is_on_their_boundary(tmp_path):
    """With all four peaks of the default task together a condyle leaves its socket (docs/tasks.md): there the fit
    ends on the socket's boundary, at the pose that SciPy's SLSQP (a solver of its own, on this file's pose
    formulas) finds nearest."""
    m = model("target")
    t, q = chewing(peak_swing=0.4)
    p, R = pose(m, q)
    result = import_motion(write_csv(tmp_path / "rec.csv", t, seen(p, R)), registration(tmp_path),
                           ImportOptions(cutoff_hz=None, rate_hz=250.0, max_position_mm=5, max_orientation_deg=5))
    out = result.fit.outside.any(axis=1)
    assert out.sum() > 5 and result.passed.all() and result.task is not None  # and the task passed the kinematics
    fp, fR = pose(m, result.fit.q)
    condyles = fp[:, None, :] + np.einsum("nij,kj->nki", fR, np.array([m.hkp.T_L, m.hkp.T_R]))
    x_max = m.hkp.x_range[1]
    assert condyles[:, :, 0].max() <= x_max + 1e-12
    assert np.abs(condyles[out, :, 0].max(axis=1) - x_max).max() < 1e-12  # on the boundary where it left

    b = m.incisor
    checked = 0
    for i in np.flatnonzero(out):
        def cost(x, i=i):
            pp, RR = pose(m, x[None])
            e = (pp[0] + RR[0] @ b - p[i] - R[i] @ b) / MM
            return e @ e + (Rotation.from_matrix(RR[0].T @ R[i]).magnitude() / DEG) ** 2

        def inside(x):  # both condyles within their sockets' x and y bounds, in mm (>= 0)
            pp, RR = pose(m, x[None])
            h = m.hkp
            (xl, yl, _), (xr, yr, _) = pp[0][None] + (RR[0] @ np.array([h.T_L, h.T_R]).T).T
            return np.array([xl - h.x_range[0], h.x_range[1] - xl, xr - h.x_range[0], h.x_range[1] - xr,
                             yl - h.y_left[0], h.y_left[1] - yl, yr - h.y_right[0], h.y_right[1] - yr]) / MM

        ref = minimize(cost, q[i], method="SLSQP", constraints=[{"type": "ineq", "fun": inside}], options={"ftol": 1e-15, "maxiter": 200})
        assert inside(result.fit.q[i]).min() > -1e-12
        # SLSQP's line search often stalls here (status 8) a micrometre outside; where it converges, it ends on
        # chewbot's pose: the costs agree to SLSQP's own accuracy (about 1e-9 relative)
        if ref.status == 0 and inside(ref.x).min() > -1e-9:
            assert cost(result.fit.q[i]) == pytest.approx(ref.fun, rel=1e-8)
            checked += 1
            if checked == 3:
                break
    assert checked == 3


def test_frames_far_outside_the_workspace_fail(tmp_path):
    """The motion 10 cm above the robot: the SQP finds no admissible pose from most frames' unconstrained optimum
    (a pose that no chain reaches); started again from its neighbours' answers it ends on the workspace's boundary,
    far from the recorded pose: the robot's incisor rises at most 5.3 mm above home (docs/recordings.md), the
    recorded one is 100 mm above the motion's, whose own incisor stays within 25 mm of home, so that every frame is
    at least 60 mm off. Those frames fail and are named, with the constraints the motion breaks; where no admissible
    pose was found the errors are not numbers."""
    m = model("target")
    t, q = chewing()
    p, R = pose(m, q)
    result = import_motion(write_csv(tmp_path / "rec.csv", t, seen(p + np.array([0.0, 0.0, 0.1]), R)), registration(tmp_path), EXACT)
    assert result.task is None and not result.passed.any()
    ok = result.fit.admissible
    assert (result.fit.position_error_mm[ok] > 60.0).all() and np.isnan(result.fit.position_error_mm[~ok]).all()
    assert all("position error" in line or "no admissible pose near it" in line for line in result.failures())
    assert any("the motion leaves the workspace: " in line and "reach" in line for line in result.failures()) or ok.all()
    table = result.residuals()
    assert np.array_equal(table["admissible"], result.fit.admissible)


# ------------------------------------------------------------------ preparation


def test_gaps_are_filled_and_too_long_ones_named(tmp_path):
    m = model("target")
    t, q = chewing()
    points = seen(*pose(m, q))
    points[:3, 1] = np.nan  # M2 missing at the start: those frames go
    points[40:45, 2] = np.nan  # M3 missing for 5 frames = 0.05 s: filled
    result = import_motion(write_csv(tmp_path / "rec.csv", t, points), registration(tmp_path), EXACT)
    assert result.recording.first_frame == 4 and np.array_equal(result.task.t, t[3:])
    assert any("filled 1 gap" in n for n in result.notes)
    spline = CubicSpline(np.r_[t[3:40], t[45:]], np.r_[points[3:40, 2], points[45:, 2]], axis=0)
    filled = result.recording.positions[37:42, 2]  # the recording now starts at frame 4
    assert np.abs(filled - spline(t[40:45])).max() < 1e-15  # the spline through that marker's seen frames
    # which is within 6 micrometres of the marker's true path here (measured 5.8e-6 m over a 5-frame gap in the
    # 0.8 s cycle), and so is O_M (the fit spreads one marker's error over the four)
    assert np.abs(filled - seen(*pose(m, q))[40:45, 2]).max() < 1e-5
    assert np.abs(result.task.q - q[3:])[:, :2].max() < 1e-5
    points[60:75, 0] = np.nan  # M1 missing for 0.15 s
    with pytest.raises(RecordingError, match=r"marker M1 missing from frame 61 \(t = 0\.6 s, line 62\) to frame 75 .*0\.15 s"):
        import_motion(write_csv(tmp_path / "rec.csv", t, points), registration(tmp_path), EXACT)


def test_a_marker_moving_relative_to_the_others_fails_the_frames_it_moves_in(tmp_path):
    m = model("target")
    t, q = chewing()
    points = seen(*pose(m, q))
    points[50:60, 3, 2] += 2 * MM  # M4 slips 2 mm along the tracker's z
    path = write_csv(tmp_path / "rec.csv", t, points)
    # by default a short slip is a tracker spike: dropped, filled like a gap, listed
    spiked = import_motion(path, registration(tmp_path), EXACT)
    assert spiked.passed.all() and any("frame 51 (t = 0.5 s, line 52) to frame 60" in n for n in spiked.notes)
    result = import_motion(path, registration(tmp_path), ImportOptions(cutoff_hz=None, rate_hz=None, keep_spikes=True))
    assert not result.passed[50:60].any() and result.passed[:50].all() and result.passed[60:].all()
    assert result.failures() == ["frame 51 (t = 0.5 s, line 52) to frame 60 (t = 0.59 s, line 61): marker M4 moves relative to "
                                 f"the others (up to {result.rigid.max_mm[50:60].max():.3g} mm > --max-rigid 1 mm)"]
    assert import_motion(path, registration(tmp_path), ImportOptions(cutoff_hz=None, rate_hz=None, max_rigid_mm=2, max_position_mm=3,
                                                                     keep_spikes=True)).passed.all()


def test_a_glitch_fails_its_own_frame_and_no_other(tmp_path):
    """The bite fork's markers M1 and M2 swapped by the tracker in one frame: that frame's pose is far off (a rigid
    residual of 1 cm). Warm-started from it alone, every later frame of this recording ends in another local
    minimum; with each frame also solved from its own coordinates they come back to the motion exactly."""
    m = model("target")
    t, q = chewing()
    points = seen(*pose(m, q))
    points[30, [0, 1]] = points[30, [1, 0]]
    result = import_motion(write_csv(tmp_path / "rec.csv", t, points), registration(tmp_path),
                           ImportOptions(cutoff_hz=None, rate_hz=None, keep_spikes=True))
    assert np.flatnonzero(~result.passed).tolist() == [30] and result.rigid.max_mm[30] > 5
    assert np.abs(np.delete(result.fit.q - q, 30, axis=0)).max() < 1e-9


def test_low_pass_is_zero_phase_and_minus_3_db_at_the_cutoff():
    """A sine at the cutoff comes out with amplitude 1/sqrt(2) and no delay; one at a tenth of it unchanged."""
    from chewbot.recordings.formats import Recording

    t = np.arange(4000) / 500.0
    for f, gain in ((6.0, 2**-0.5), (0.6, 1.0)):
        x = np.sin(2 * np.pi * f * t)
        rec = Recording("sine", "csv", t, ("M",), np.repeat(x[:, None, None], 3, axis=2))
        y = low_pass(rec, 6.0).positions[1000:3000, 0, 0]
        fit = np.linalg.lstsq(np.column_stack([np.sin(2 * np.pi * f * t[1000:3000]), np.cos(2 * np.pi * f * t[1000:3000])]), y, rcond=None)[0]
        assert fit[0] == pytest.approx(gain, abs=2e-3) and abs(fit[1]) < 1e-3  # in phase


def test_batched_kabsch_agrees_with_scipy_align_vectors():
    rng = np.random.default_rng(3)
    R = Rotation.random(20, random_state=4).as_matrix()
    p = rng.normal(size=(20, 3))
    points = np.einsum("nij,kj->nki", R, BODY) + p[:, None] + 1e-4 * rng.normal(size=(20, len(BODY), 3))
    R_fit, p_fit = kabsch(BODY, points)
    for i in range(20):
        ref, _ = Rotation.align_vectors(points[i] - points[i].mean(axis=0), BODY - BODY.mean(axis=0))
        assert np.abs(ref.as_matrix() - R_fit[i]).max() < 1e-12
        assert np.abs(points[i].mean(axis=0) - R_fit[i] @ BODY.mean(axis=0) - p_fit[i]).max() < 1e-15


def test_scaling_scales_displacement_and_rotation_angle_about_the_same_axis():
    R0 = Rotation.from_rotvec([0.1, 0.2, -0.1])
    turn = Rotation.from_rotvec([0.0, 0.3, 0.1])
    p = np.array([[1.0, 2.0, 3.0], [1.4, 1.0, 3.5]])
    R = np.stack([R0.as_matrix(), (turn * R0).as_matrix()])
    ps, Rs = scale_motion(p, R, 0.5, 0.25)
    assert np.allclose(ps[1] - ps[0], 0.5 * (p[1] - p[0]))
    rel = Rotation.from_matrix(Rs[1] @ Rs[0].T).as_rotvec()
    assert np.allclose(rel, 0.25 * turn.as_rotvec(), atol=1e-15) and np.allclose(Rs[0], R[0])


# ------------------------------------------------------------------ formats, units, registration


def _reference(tmp_path):
    m = model("target")
    t, q = chewing()
    return t, q, seen(*pose(m, q))


def test_units_in_the_csv_headers_and_from_the_registration(tmp_path):
    t, q, points = _reference(tmp_path)
    reg = registration(tmp_path)
    cols = {"t[ms]": t * 1e3}
    for k in range(len(BODY)):
        for j, a in enumerate("xyz"):
            unit, factor = (("[cm]", 1e2), ("[m]", 1.0), ("", 1e3))[(k + j) % 3]  # no unit: the registration's mm
            cols[f"M{k + 1}_{a}{unit}"] = points[:, k, j] * factor
    path = tmp_path / "units.csv"
    path.write_text("# a comment line\n" + ",".join(cols) + "\n" + "\n".join(",".join(repr(float(v)) for v in row) for row in np.column_stack(list(cols.values()))) + "\n")
    result = import_motion(path, reg, EXACT)
    assert np.abs(result.task.q - q).max() < 1e-9


def _write_probe(path, t, points, explicit, start="0.0", scale=1.0):
    flat = points.reshape(len(t), -1) / MM
    lines = [f"{start} {float(t[-1] + 1)} {scale}  # start stop scale", f"linear {flat.shape[1]} {'explicit' if explicit else repr(float(t[1] - t[0]) / scale)}"]
    lines += [" ".join(repr(float(v)) for v in ([tt / scale] if explicit else []) + list(row)) for tt, row in zip(t - t[0], flat)]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


@pytest.mark.parametrize("explicit", [False, True])
def test_artisynth_probe_files(tmp_path, explicit):
    t, q, points = _reference(tmp_path)
    points[20, 1] = np.nan  # NaN is a dropped frame
    # start written as an integer is nanoseconds (1 s); scale 2 stretches the probe's time
    path = _write_probe(tmp_path / "probe.txt", t, points, explicit, start="1000000000", scale=2.0)
    rec = read_recording(path, "mm")
    assert rec.markers == ("M1", "M2", "M3", "M4") and np.allclose(rec.t, 1.0 + t - t[0], atol=1e-12)
    assert rec.lines[0] == 3 and np.isnan(rec.positions[20, 1]).all()
    result = import_motion(path, registration(tmp_path), EXACT)
    assert np.abs(np.delete(result.task.q - q, 20, axis=0)).max() < 1e-9  # frame 21 filled by a spline, the others exact


def test_c3d_through_ezc3d(tmp_path):
    import ezc3d

    t, q, points = _reference(tmp_path)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = [f"M{k + 1}" for k in range(len(BODY))]
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    data = np.ones((4, len(BODY), len(t)))
    data[:3] = np.transpose(points, (2, 1, 0))
    c["data"]["points"] = data
    path = tmp_path / "rec.c3d"
    c.write(str(path))
    rec = read_recording(path, "mm")  # the file's own unit (m) wins over the registration's
    assert rec.meta["units"] == "m" and np.allclose(rec.t, t - t[0])
    result = import_motion(path, registration(tmp_path), EXACT)
    assert np.abs(result.task.q - q).max() < 1e-6  # C3D stores single precision: 4e-8 m of 0.1 m marker coordinates


def test_rest_first_makes_the_first_frame_home(tmp_path):
    m = model("target")
    t, q = chewing()
    assert not q[0].any()  # the default task starts at home
    points = seen(*pose(m, q), body=BODY + np.array([5.0, 0.0, 3.0]) * MM)  # the markers need not be known
    result = import_motion(write_csv(tmp_path / "rec.csv", t, points), registration(tmp_path, markers=False), EXACT)
    assert np.abs(result.task.q - q).max() < 1e-9 and np.abs(result.rigid.R[0] - np.eye(3)).max() < 1e-14


def test_scale_auto_finds_the_largest_factor_that_passes(tmp_path):
    m = model("target")
    t, q = chewing(X_mm=8.0, beta_deg=15.0)  # too far forward for the sockets
    path = write_csv(tmp_path / "rec.csv", t, seen(*pose(m, q)))
    reg = registration(tmp_path, markers=False)
    strict = ImportOptions(cutoff_hz=None, rate_hz=None, max_position_mm=0.2, max_orientation_deg=0.5)
    assert not import_motion(path, reg, strict).passed.all()
    auto = import_motion(path, reg, replace(strict, scale="auto"))
    f = auto.factor
    assert 0.2 < f < 1 and auto.passed.all() and auto.scale == f and auto.angle_scale == f
    above = import_motion(path, reg, replace(strict, scale=f + 2e-3, angle_scale=f + 2e-3))
    assert not above.passed.all()  # the factor is the largest to the bisection's resolution (6e-5)
    # monotone: every factor below it passes too, frames and resampled task (a grid other than the search's)
    for g in np.linspace(0.0, f, 8)[1:]:
        below = import_motion(path, reg, replace(strict, scale=float(g), angle_scale=float(g)))
        assert below.passed.all() and below.task is not None, g


def test_registration_errors_name_the_file_and_key(tmp_path):
    good = {"units": "mm", "rest": "first"}
    registration_from_dict(good)
    for raw, pattern in [
        ({"rest": "first"}, r"key 'units': missing key"),
        ({**good, "unit": "mm"}, r"key 'unit': unknown key"),
        ({**good, "units": "inch"}, r"key 'units': .*'inch' is not a length unit"),
        ({"units": "mm"}, r"key 'markers': give either"),
        ({**good, "markers": {"A": [0, 0, 0], "B": [1, 0, 0], "C": [2, 0, 0]}}, r"key 'rest': give either"),
        ({"units": "mm", "markers": {"A": [0, 0, 0], "B": [1, 0, 0], "C": [2, 0, 0]}}, r"key 'markers': the markers lie on one line"),
        ({"units": "mm", "markers": {"A": [0, 0], "B": [1, 0, 0], "C": [0, 1, 0]}}, r"key 'markers.A': must be a list of 3 numbers, not 2"),
        ({**good, "tracker": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}}, r"key 'tracker.rotation': not a rotation"),
        ({**good, "fit": {"position_weight_per_mm": 0}}, r"key 'fit.position_weight_per_mm': must be greater than 0"),
        ({**good, "scale": -1.0}, r"key 'scale': must be greater than 0"),
    ]:
        with pytest.raises(RecordingError, match=r"^reg\.toml: " + pattern):
            registration_from_dict(raw, "reg.toml")


def test_the_documented_examples_read(tmp_path):
    """The registration, CSV and probe examples of docs/recordings.md are valid as printed."""
    import tomllib
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "recordings.md").read_text()
    blocks = {kind: text.split(f"```{kind}\n", 1)[1].split("```", 1)[0] for kind in ("toml", "csv", "text")}
    reg = registration_from_dict(tomllib.loads(blocks["toml"]), "example")
    assert list(reg.markers) == ["M1", "M2", "M3", "M4"] and reg.scale == 0.8 and reg.point[0] == pytest.approx(0.08)
    (tmp_path / "example.csv").write_text(blocks["csv"])
    (tmp_path / "example.txt").write_text(blocks["text"])
    csv_rec = read_csv(tmp_path / "example.csv", "mm")  # the readers themselves: the examples are 2 or 3 frames long
    assert np.isnan(csv_rec.positions[2, 0, 2]) and csv_rec.force[2, 2] == -1.5
    probe = read_artisynth(tmp_path / "example.txt", "mm")
    assert probe.markers == ("M1", "M2", "M3") and np.allclose(probe.positions[:, 0, 0], [0.09502, 0.09510])


@pytest.mark.parametrize("name, text, pattern", [
    ("cell.csv", "t,M1_x,M1_y,M1_z\n0,1,2,3\n0.1,1,x2,3\n", r"cell\.csv: line 3, column 'M1_y': 'x2' is not a number"),
    ("unit.csv", "t,M1_x[deg],M1_y,M1_z\n0,1,2,3\n", r"unit\.csv: line 1, column 'M1_x\[deg\]': 'deg' is a unit of angle"),
    ("col.csv", "t,M1_x,M1_y,M1_z,M1_w\n0,1,2,3,4\n", r"col\.csv: line 1, column 5: 'M1_w' is not a column"),
    ("axes.csv", "t,M1_x,M1_y\n" + "".join(f"{i},1,2\n" for i in range(12)), r"axes\.csv: marker 'M1' lacks column\(s\) M1_z"),
    ("time.csv", "t,M1_x,M1_y,M1_z\n" + "".join(f"{i % 5},1,2,3\n" for i in range(12)), r"time\.csv: frame 6 \(t = 0 s, line 7\): time does not increase"),
    ("cells.csv", "t,M1_x,M1_y,M1_z\n0,1,2\n", r"cells\.csv: line 2: 3 cells, the header has 4 columns"),
    ("short.txt", "0.0 1.0 1.0\nlinear 6 0.01\n1 2 3 4 5 6\n1 2 3 4 5\n", r"short\.txt: line 4: 5 value\(s\), expected 6"),
    ("vsize.txt", "0.0 1.0 1.0\nlinear 5 0.01\n1 2 3 4 5\n", r"vsize\.txt: line 2: vsize '5' must be a positive multiple of 3"),
    ("interp.txt", "0.0 1.0 1.0\nspline 6 explicit\n0 1 2 3 4 5 6\n", r"interp\.txt: line 2: expected 'interpolation vsize timestep'"),
    ("word.txt", "0.0 1.0 1.0\nlinear 3 explicit\n0 1 2 3\n0.1 1 two 3\n", r"word\.txt: line 4, column 3: 'two' is not a number"),
    ("bad.c3d", "not a c3d file", r"bad\.c3d: not a readable C3D file"),
])
def test_bad_recordings_name_file_line_and_column(tmp_path, name, text, pattern):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(RecordingError, match=pattern):
        read_recording(path, "mm")


def test_markers_of_the_registration_must_be_in_the_recording(tmp_path):
    t, q, points = _reference(tmp_path)
    path = write_csv(tmp_path / "rec.csv", t, points[:, :3])
    with pytest.raises(RecordingError, match=r"rec\.csv: marker\(s\) M4 of the registration .*reg\.toml are not in the recording"):
        import_motion(path, registration(tmp_path), EXACT)


# ------------------------------------------------------------------ the command


def test_command_writes_a_task_that_runs_to_torques(tmp_path):
    help_text = runner.invoke(app, ["import-motion", "--help"])
    assert help_text.exit_code == 0 and "Examples" in help_text.output
    rec, t, force = chewing_recording(tmp_path)
    out = tmp_path / "task.csv"
    result = runner.invoke(app, ["import-motion", rec, "--registration", registration(tmp_path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "robot fit: position error up to" in result.output and "wrote" in result.output
    for path in (out, tmp_path / "task.residuals.csv"):  # plain CSV; the marker is the sidecar, with the command
        side = json.loads((tmp_path / (path.name + ".chewbot.json")).read_text())
        assert side["chewbot_file"] == 1 and "chewbot import-motion " in side["about"]
    header = out.read_text().splitlines()[0]
    assert header.startswith("t [s],X [m],Y [m],alpha [rad],beta [rad],dX [m/s]") and header.endswith("Fz [N]")
    assert "position_error [mm],orientation_error [deg]" in (tmp_path / "task.residuals.csv").read_text()
    task = read_task_csv(out)
    assert task.n == 901 and task.t[1] - task.t[0] == pytest.approx(1e-3)  # 1000 Hz over the 0.9 s recorded
    assert np.allclose(task.force[:, 2], np.interp(task.t, t, force[:, 2]), atol=1e-12)
    run = runner.invoke(app, ["run", "--task", str(out), "--out", str(tmp_path / "run")])
    assert run.exit_code == 0, run.output
    results = (tmp_path / "run" / "results.csv").read_text().splitlines()
    assert "tau1" in results[0] and len(results) == 902
    # never over a file without --force
    again = runner.invoke(app, ["import-motion", rec, "--registration", registration(tmp_path), "--out", str(out)])
    assert again.exit_code == EXIT_OUTPUT and "exists" in again.output
    assert runner.invoke(app, ["import-motion", rec, "--registration", registration(tmp_path), "--out", rec]).exit_code == EXIT_OUTPUT


def test_command_force_file_scale_auto_and_failures(tmp_path):
    m = model("target")
    t, q = chewing(X_mm=8.0, beta_deg=15.0)
    rec = write_csv(tmp_path / "rec.csv", t, seen(*pose(m, q)))
    reg = registration(tmp_path)
    forces = tmp_path / "bite.csv"
    forces.write_text("t[ms],Fx[N],Fy[N],Fz[kN]\n" + "".join(f"{1e3 * s!r},0,0,{-0.05 * s!r}\n" for s in (0.0, 0.5, 0.9)))
    out = tmp_path / "task.csv"
    common = ["import-motion", rec, "--registration", reg, "--out", str(out), "--cutoff", "none", "--max-residual", "0.2", "0.5"]
    failed = runner.invoke(app, common)
    assert failed.exit_code == EXIT_UNREACHABLE and "frame(s) fail" in failed.output and "frame " in failed.output
    assert not out.exists() and (tmp_path / "task.residuals.csv").exists()
    auto = runner.invoke(app, common + ["--scale", "auto", "--force-file", str(forces), "--rate", "recording", "--force",
                                       "--timing", "recording"])  # the force at the recorded times
    assert auto.exit_code == 0, auto.output
    assert "--scale auto: factor 0." in auto.output
    task = read_task_csv(out)
    assert np.allclose(task.force[:, 2], -50 * task.t, atol=1e-12)  # 0.05 kN/s, linear between the file's rows
    bad = runner.invoke(app, ["import-motion", rec, "--registration", reg, "--out", str(tmp_path / "x.csv"), "--cutoff", "fast"])
    assert bad.exit_code == EXIT_BAD_INPUT and "neither a number nor 'none'" in bad.output
    missing = runner.invoke(app, ["import-motion", str(tmp_path / "nothing.csv"), "--registration", reg, "--out", str(tmp_path / "y.csv")])
    assert missing.exit_code == EXIT_BAD_INPUT and "nothing.csv: no such recording" in missing.output
