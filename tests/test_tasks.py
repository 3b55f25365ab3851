"""Task inputs: CSV files (units, derivative estimates, every defect named), and incisor-path tracking."""

from __future__ import annotations

import re

import numpy as np
import pytest
from support import default_kinematics, model

from chewbot.errors import KinematicsError, TaskError
from chewbot.kinematics.motion import solve_kinematics
from chewbot.task import smoothing
from chewbot.task.csvio import read_task_csv
from chewbot.task.default import default_task
from chewbot.task.incisor import incisor_path, track_incisor

# ------------------------------------------------------------------ CSV files


def _write(path, header, rows):
    path.write_text(header + "\n" + "\n".join(",".join(repr(float(x)) for x in row) for row in rows) + "\n")
    return path


def _default_rows(task, scale, rows=slice(None)):
    return np.column_stack([task.t[:, None] * scale[0], task.q * scale[1:5]])[rows]


def test_csv_with_units_reads_back_the_default_task(tmp_path):
    task = default_task(model("target"))
    scale = np.array([1e3, 1e3, 1e3, 180 / np.pi, 180 / np.pi])
    data = np.column_stack([_default_rows(task, scale), task.dq[:, 3] * 180 / np.pi, task.force[:, 2] / 1e3])
    path = _write(tmp_path / "task.csv", "t[ms],X[mm],Y[mm],alpha[deg],beta[deg],dbeta[deg/s],Fz[kN]", data)
    read = read_task_csv(path)
    # only the unit conversions' rounding separates the two (a few ulp)
    assert np.abs(read.t - task.t).max() < 1e-14
    assert np.abs(read.q - task.q).max() < 1e-14
    assert np.abs(read.dq[:, 3] - task.dq[:, 3]).max() < 1e-14  # given in the file: used as it is
    assert np.abs(read.force[:, 2] - task.force[:, 2]).max() < 1e-13 and not read.force[:, :2].any()
    assert read.meta["derivatives_estimated"] == ["dX", "dY", "dalpha", "ddX", "ddY", "ddalpha", "ddbeta"]
    # the estimated rates follow the exact ones: inside the cycles to the filter's bias (measured 2.5e-7 and 2.0e-4
    # of the peaks, docs/tasks.md; bounds 4x); near the joins, where the task is only C^2 and the window rounds the
    # jerk's jumps, to 1.6e-3 and 9.4e-2 (bounds 5e-3 and 0.15)
    joins = 1.0 + 0.8 * np.arange(6)
    inside = np.abs(task.t[:, None] - joins[None]).min(axis=1) > 0.026
    for est, exact, tol_in, tol_all in ((read.dq, task.dq, 1e-6, 5e-3), (read.ddq, task.ddq, 8e-4, 0.15)):
        peak = np.abs(exact).max(axis=0)
        assert (np.abs(est - exact)[inside].max(axis=0) <= tol_in * peak).all()
        assert (np.abs(est - exact).max(axis=0) <= tol_all * peak).all()
    solve_kinematics(model("target"), read)  # a usable task


def test_csv_for_the_6rss_and_a_target_file_with_parasitic_columns(tmp_path):
    full = default_kinematics("6rss").X
    t = default_kinematics("6rss").t
    path = _write(tmp_path / "full.csv", "t,X,Y,Z,alpha,beta,gamma", np.column_stack([t, full]))
    task = read_task_csv(path, mechanism="6rss", side="right")
    assert task.coords == ("X", "Y", "Z", "alpha", "beta", "gamma") and task.side == "right"
    # the target keeps Z and gamma and checks them against its sockets: consistent values pass ...
    solve_kinematics(model("target"), read_task_csv(path, mechanism="target"))
    # ... and a Z 1 mm off is refused with the sample named
    bad = full.copy()
    bad[:, 2] += 1e-3
    path = _write(tmp_path / "bad.csv", "t,X,Y,Z,alpha,beta,gamma", np.column_stack([t, bad]))
    with pytest.raises(KinematicsError, match=r"sample 0.*Z and gamma do not satisfy"):
        solve_kinematics(model("target"), read_task_csv(path))


GOOD = "t,X,Y,alpha,beta"
ROWS = [f"{0.001 * i!r},0,0,0,{0.001 * i!r}" for i in range(10)]


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("", r"empty file \(expected a target task"),
        ("\n# only a comment\n", r"empty file \(expected a target task"),
        (GOOD + "\n" + "\n".join(ROWS[:3]), r"3 data row\(s\); a target task needs at least 7"),
        ("t,X,Y,alpha\n" + "\n".join(r.rsplit(",", 1)[0] for r in ROWS), r"missing column\(s\) beta"),
        (GOOD + ",foo\n" + "\n".join(r + ",0" for r in ROWS), r"line 1: unknown column 'foo'"),
        (GOOD + ",X\n" + "\n".join(r + ",0" for r in ROWS), r"line 1: column 'X' appears twice"),
        ("t,X[furlong],Y,alpha,beta\n" + "\n".join(ROWS), r"line 1: column 'X\[furlong\]': unknown unit 'furlong'"),
        ("t,X[deg],Y,alpha,beta\n" + "\n".join(ROWS), r"'deg' is a unit of angle, the column is a length"),
        ("t,X,Y,alpha,beta,dX[mm/s^2]\n" + "\n".join(r + ",0" for r in ROWS), r"column 'dX\[mm/s\^2\]'.*order 1"),
        ("t,X,Y,alpha,beta,dZ\n" + "\n".join(r + ",0" for r in ROWS), r"'dZ' is a rate of 'Z', which the file does not give"),
        ("t,X,Y,Z,alpha,beta\n" + "\n".join(r + ",0" for r in ROWS), r"Z and gamma come together"),
        (GOOD + "\n" + "\n".join(ROWS[:4] + ["0.004,0,zero,0,0"] + ROWS[5:]), r"line 6, column 'Y': 'zero' is not a number"),
        (GOOD + "\n" + "\n".join(ROWS[:4] + ["0.004,0,nan,0,0"] + ROWS[5:]), r"line 6, column 'Y': nan is not a finite number"),
        (GOOD + "\n" + "\n".join(ROWS[:4] + ["0.004,0,0,inf,0"] + ROWS[5:]), r"line 6, column 'alpha': inf is not a finite number"),
        (GOOD + "\n" + "\n".join(ROWS[:4] + ["0.003,0,0,0,0"] + ROWS[5:]), r"line 6, column 't': time 0.003 s does not increase"),
        (GOOD + "\n" + "\n".join(ROWS[:4] + ["0.002,0,0,0,0"] + ROWS[5:]), r"line 6, column 't'"),
        (GOOD + "\n" + "\n".join(ROWS[:4] + ["0.004,0,0,0"] + ROWS[5:]), r"line 6: 4 cells, the header has 5 columns"),
        (GOOD + "\n" + "\n".join(ROWS[:4] + ["0.0042,0,0,0,0"] + ROWS[5:]), r"line 6: time step .* differs from the median"),
    ],
)
def test_csv_defects_name_file_line_or_column(tmp_path, text, pattern):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(TaskError, match=pattern) as err:
        read_task_csv(path)
    assert str(path) in str(err.value)


def _decimal_texts(rng, n: int) -> list[str]:
    """Decimal numbers as people and programs write them: 1 to 25 significant digits, exponents from -330 to 280 (the
    subnormals and the underflow to zero among them, no overflow), with or without a sign, a dot, leading or trailing digits."""
    out = []
    for _ in range(n):
        digits = "".join(rng.choice(list("0123456789"), rng.integers(1, 26)))
        point = rng.integers(0, len(digits) + 1)
        mantissa = digits[:point] + "." + digits[point:] if rng.random() < 0.8 else digits
        exponent = f"{'eE'[rng.integers(2)]}{rng.integers(-330, 281)}" if rng.random() < 0.6 else ""
        sign = ["", "-", "+"][rng.integers(3)]
        out.append(f"{sign}{mantissa}{exponent}")
    return out


def test_each_cell_is_the_float_nearest_its_text_and_each_row_keeps_its_line(tmp_path):
    """pyarrow's CSV reader gives every cell the float nearest to its decimal text, as Python's float() does (compared
    bit for bit on 6,000 cells of random decimal texts, spaces around some), and each row the line an editor shows it
    on, with blank lines, comments (one indented) and a byte-order mark around the rows; CRLF and lone-CR line ends
    give the same."""
    from chewbot.task.csvio import COLUMNS, read_signals

    rng = np.random.default_rng(7)
    rows, names = 1000, ("X", "Y", "alpha", "beta", "Fz")
    texts = [_decimal_texts(rng, rows) for _ in names]
    times = [f"{k}.{rng.integers(0, 10**9):09d}" for k in range(rows)]
    lines = ["# a comment above the header", "t [s]," + ",".join(names)]
    expected_lines = []
    for k in range(rows):
        if k % 97 == 5:
            lines.append("")
        if k % 113 == 7:
            lines.append("  # an indented comment, 1,2,3")
        if k % 131 == 9:
            lines.append(" , ,")
        cells = [times[k]] + [c[k] if k % 3 else f" {c[k]} " for c in texts]
        lines.append(",".join(cells))
        expected_lines.append(len(lines))
    want = np.array([[float(x) for x in row] for row in zip(times, *texts)])
    for end, bom in (("\n", ""), ("\r\n", "\ufeff"), ("\r", "")):
        path = tmp_path / f"cells{len(end)}{len(bom)}.csv"
        path.write_bytes((bom + end.join(lines) + end).encode("utf-8"))
        read_names, _, read_lines, col = read_signals(path, COLUMNS, ("t",), "signals")
        assert read_names == ["t", *names]
        got = np.column_stack([col[name] for name in read_names])
        assert np.array_equal(got.view(np.int64), want.view(np.int64)), (end, np.argwhere(got != want)[:3])
        assert read_lines.tolist() == expected_lines


def test_a_refused_row_after_blank_and_comment_lines_is_named_by_its_line(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text(GOOD + "\n" + "\n".join(ROWS[:3] + ["", "# note"] + ["0.003,0,0,oops,0"] + ROWS[4:]) + "\n")
    with pytest.raises(TaskError, match=r"bad.csv: line 7, column 'alpha': 'oops' is not a number"):
        read_task_csv(path)
    path.write_text(GOOD + "\n" + "\n".join(ROWS[:3] + ["# note"] + ["0.003,0,0"] + ROWS[4:]) + "\n")
    with pytest.raises(TaskError, match=r"bad.csv: line 6: 3 cells, the header has 5 columns"):
        read_task_csv(path)


def test_missing_csv_file(tmp_path):
    with pytest.raises(TaskError, match=r"absent.csv: no such file \(expected a"):
        read_task_csv(tmp_path / "absent.csv")


def test_irregular_times_are_fine_when_all_rates_are_given(tmp_path):
    t = np.array([0, 0.001, 0.003, 0.004, 0.006, 0.007, 0.01])
    rows = np.column_stack([t, np.zeros((7, 4)), np.zeros((7, 8))])
    names = ",".join(p + c for p in ("d", "dd") for c in ("X", "Y", "alpha", "beta"))
    task = read_task_csv(_write(tmp_path / "irregular.csv", GOOD + "," + names, rows))
    assert task.meta["derivatives_estimated"] == []


# ------------------------------------------------------------------ smoothing


@pytest.mark.parametrize("noise, tol_v, tol_a", [(0.0, 1e-4, 2e-3), (1e-5, 5e-3, 5e-2)])
def test_smoothing_against_an_analytic_signal(noise, tol_v, tol_a):
    """y = A sin^2(w t) + noise: the error is the filter's bias (noise-free) plus the filtered noise.

    Tolerances: about 4x the errors docs/tasks.md reports, relative to the peak velocity and acceleration.
    """
    t = np.arange(2001) / 1000.0
    A, w = np.radians(10), 2 * np.pi * 1.25
    y = A * np.sin(w * t) ** 2 + noise * np.random.default_rng(3).standard_normal(t.size)
    d1, d2 = smoothing.derivatives(t, np.column_stack([y, 2 * y]))
    assert np.abs(d1[:, 0] - A * w * np.sin(2 * w * t)).max() <= tol_v * A * w
    assert np.abs(d2[:, 0] - 2 * A * w**2 * np.cos(2 * w * t)).max() <= tol_a * 2 * A * w**2
    assert np.allclose(d1[:, 1], 2 * d1[:, 0], rtol=1e-12, atol=0)  # columns filtered independently and linearly


def test_smoothing_is_exact_for_polynomials_of_its_degree():
    t = np.arange(101) * 0.01
    c = np.array([0.3, -1.0, 2.0, 0.5, -0.7, 0.2])  # a quintic
    y = np.polynomial.Polynomial(c)
    d1, d2 = smoothing.derivatives(t, y(t))
    assert np.abs(d1 - y.deriv(1)(t)).max() < 1e-9 and np.abs(d2 - y.deriv(2)(t)).max() < 1e-7


# ------------------------------------------------------------------ incisor tracking

ROWS_TRACKED = slice(1000, 1801, 8)  # one chewing cycle, every 8th sample: enough to follow the branch


@pytest.mark.parametrize("orientation", ["euler-angles", "euler-parameters"])
def test_incisor_tracking_recovers_a_motion_generated_from_known_coordinates(orientation):
    """With the pinned coordinate's own trajectory the problems are square: the known motion comes back."""
    kin = default_kinematics("target", "left", orientation)
    ang = default_kinematics("target", "left", "euler-angles")
    m = model("target")
    r = ROWS_TRACKED
    p, v, a = incisor_path(m, kin.q[r], kin.dq[r], kin.ddq[r], orientation)
    alpha = (ang.X[r, 3], ang.dX[r, 3], ang.ddX[r, 3])
    track = track_incisor(m, kin.t[r], p, v, a, orientation=orientation, pin="alpha", pinned=alpha)
    # residuals: the solvers converge to rounding of mm-scaled problems
    assert np.abs(track.f_D).max() < 1e-12 and np.abs(track.f_V).max() < 1e-12 and np.abs(track.f_A).max() < 1e-11
    # recovered: q_EE to 1e-11 (m, rad), rates to 1e-10, accelerations to 1e-9 (conditioning of M_I)
    for got, want, tol in ((track.q, kin.q[r], 1e-11), (track.dq, kin.dq[r], 1e-10), (track.ddq, kin.ddq[r], 1e-9)):
        assert np.abs(got - want).max() < tol
    for got, want in ((track.task.q, ang.q[r]), (track.task.dq, ang.dq[r]), (track.task.ddq, ang.ddq[r])):
        assert np.abs(got - want).max() < 1e-9


def test_incisor_path_is_the_incisor_of_the_kinematics():
    kin = default_kinematics("target")
    r = slice(1010, 1400)  # inside the first cycle: the motion is a polynomial there (no C^2 joins in the stencils)
    p, v, a = incisor_path(model("target"), kin.q[r], kin.dq[r], kin.ddq[r])
    assert np.abs(p - kin.points["I"][r]).max() < 1e-15
    h = kin.t[1] - kin.t[0]
    fd_v = (kin.points["I"][r.start + 1:r.stop + 1] - kin.points["I"][r.start - 1:r.stop - 1]) / (2 * h)
    fd_a = (v[2:] - v[:-2]) / (2 * h)
    # truncation of a central difference: h^2/6 max abs(third derivative), the third derivative bounded from the data
    jerk = np.abs(np.diff(a, axis=0)).max() / h
    snap = np.abs(np.diff(a, 2, axis=0)).max() / h**2
    assert np.abs(fd_v - v).max() <= 1.5 * h**2 / 6 * jerk
    assert np.abs(fd_a - a[1:-1]).max() <= 1.5 * h**2 / 6 * snap + 1e-12


def test_incisor_path_does_not_fix_the_motion():
    """Another trajectory of the pinned alpha follows the same incisor path just as well, with other X, Y, beta:
    the incisor alone cannot tell them apart (what is and is not recoverable, docs/tasks.md)."""
    kin = default_kinematics("target")
    m = model("target")
    r = ROWS_TRACKED
    p, v, a = incisor_path(m, kin.q[r], kin.dq[r], kin.ddq[r])
    track = track_incisor(m, kin.t[r], p, v, a, pinned=tuple(0.8 * x for x in (kin.q[r, 2], kin.dq[r, 2], kin.ddq[r, 2])))
    assert np.abs(track.f_D).max() < 1e-12 and np.abs(track.f_V).max() < 1e-12 and np.abs(track.f_A).max() < 1e-11
    assert np.abs(track.q[:, 1] - kin.q[r, 1]).max() > 1e-4  # Y differs by more than 0.1 mm


def test_unreachable_incisor_path_is_reported():
    kin = default_kinematics("target")
    m = model("target")
    r = ROWS_TRACKED
    p, v, a = incisor_path(m, kin.q[r], kin.dq[r], kin.ddq[r])
    # alpha held at 0 (the default pin): the lateral swing must come from Y alone and a condyle hits its socket
    with pytest.raises(KinematicsError, match=r"sample \d+.*cannot be reached within the sockets"):
        track_incisor(m, kin.t[r], p, v, a)
    with pytest.raises(TaskError, match="incisor tracking resolves the motion through the target's sockets"):
        track_incisor(model("6rss"), kin.t[r], p, v, a)


def test_track_incisor_command_recovers_a_motion_and_writes_a_runnable_task(tmp_path):
    """An incisor path (in mm, rates in the file) generated from a known motion with no roll; the command with
    alpha pinned at 0 writes a task that reproduces the motion (the problem is square and well-posed) and a
    residuals file, and `chewbot run` accepts the task."""
    from typer.testing import CliRunner

    from chewbot.cli import app
    from chewbot.task.default import ChewingParameters

    m = model("target")
    known = default_task(m, "left", ChewingParameters(cycles=1, rest_s=0.1, rate_hz=200.0, alpha_deg=0.0))
    p, v, a = incisor_path(m, known.q, known.dq, known.ddq)
    rows = ["t,Ix[mm],Iy[mm],Iz[mm],dIx[mm/s],dIy[mm/s],dIz[mm/s],ddIx[mm/s^2],ddIy[mm/s^2],ddIz[mm/s^2],Fz"]
    rows += [",".join(repr(float(x)) for x in (t, *(1e3 * p[k]), *(1e3 * v[k]), *(1e3 * a[k]), known.force[k, 2]))
             for k, t in enumerate(known.t)]
    src = tmp_path / "incisor.csv"
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "tracked.csv"
    runner = CliRunner()
    result = runner.invoke(app, ["track-incisor", str(src), "--out", str(out), "--pin", "alpha"])
    assert result.exit_code == 0, result.output
    task = read_task_csv(out)
    assert task.meta["derivatives_estimated"] == []  # all rates written, none re-estimated
    # mm -> m round trip and the SQP tolerances: 1e-9 m, 1e-9 rad and their rates relative to their peaks
    for got, want in ((task.q, known.q), (task.dq, known.dq), (task.ddq, known.ddq)):
        assert np.abs(got - want).max() <= 1e-9 * max(1.0, np.abs(want).max())
    assert np.array_equal(task.force[:, 2], known.force[:, 2])
    residuals = np.loadtxt(tmp_path / "tracked.residuals.csv", delimiter=",", skiprows=2)  # chewbot's line, the header
    assert np.abs(residuals[:, 1:4]).max() <= 1e-9  # f_D, m
    again = runner.invoke(app, ["track-incisor", str(src), "--out", str(out)])
    assert again.exit_code == 5 and "exists" in again.output
    run = runner.invoke(app, ["run", "--task", str(out), "--out", str(tmp_path / "run"), "--quiet"])
    assert run.exit_code == 0, run.output


def test_pose_errors_of_a_csv_task_name_the_file_and_line(tmp_path):
    """A condyle outside its socket at the 4th data row (after a comment line): the message names the file and
    the line as an editor shows it, and still the sample and its time."""
    from chewbot.run.pipeline import compute
    from chewbot.run.options import RunOptions

    rows = ["# comment", "t,X[mm],Y,alpha,beta"] + [f"{k * 0.001},{8.0 if k >= 3 else 0.0},0,0,0" for k in range(8)]
    path = tmp_path / "far.csv"
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(KinematicsError, match=rf"^{re.escape(str(path))}: line 6: sample 3, t = 0.003 s: the left condyle leaves its socket") as err:
        compute(RunOptions(task=str(path), method=None))
    assert err.value.sample == 3


def test_track_incisor_command_follows_a_pinned_column(tmp_path):
    """The default task's own incisor path needs its roll: with the task's alpha as a column of the path file
    (in degrees; its rates estimated from it) the command tracks it, and the recovered positions are the task's
    (the position problem uses the given alpha exactly; the rates depend on the estimate and are not compared)."""
    from typer.testing import CliRunner

    from chewbot.cli import app
    from chewbot.task.default import ChewingParameters

    m = model("target")
    known = default_task(m, "left", ChewingParameters(cycles=1, rest_s=0.1, rate_hz=200.0))
    p, v, a = incisor_path(m, known.q, known.dq, known.ddq)
    rows = ["t,Ix,Iy,Iz,dIx,dIy,dIz,ddIx,ddIy,ddIz,alpha[deg]"]
    rows += [",".join(repr(float(x)) for x in (t, *p[k], *v[k], *a[k], np.degrees(known.q[k, 2]))) for k, t in enumerate(known.t)]
    src = tmp_path / "incisor.csv"
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "tracked.csv"
    result = CliRunner().invoke(app, ["track-incisor", str(src), "--out", str(out)])
    assert result.exit_code == 0, result.output
    task = read_task_csv(out)
    assert np.abs(task.q - known.q).max() <= 1e-9  # positions: the pinned alpha is given exactly
    # without the column, alpha is held at zero and the path cannot be followed within the sockets
    src.write_text("\n".join(r.rsplit(",", 1)[0] for r in rows) + "\n")
    failed = CliRunner().invoke(app, ["track-incisor", str(src), "--out", str(tmp_path / "no.csv")])
    assert failed.exit_code == 3 and "pinned coordinate" in failed.output
    assert not (tmp_path / "no.csv").exists()
