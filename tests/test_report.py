"""The run summary, the HTML report and the atomic results folder; the report opened in headless Chromium."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from plotly.offline import get_plotlyjs

from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.files import OutputExistsError
from chewbot.outputs.writer import write
from chewbot.run.pipeline import compute
from chewbot.run.options import RunOptions
from chewbot.report import html as report_html
from chewbot.report import view as report_view
from chewbot.report.summary import column_stats, infeasible_samples, near_singular, performance_indices
from chewbot.table import Table
from chewbot.run.columns import kinematics_table
from support import default_kinematics, model

ARTIFACTS = Path(__file__).resolve().parent.parent / "test-artifacts"
# Debian's Chromium, or another build named by $CHEWBOT_CHROMIUM
CHROMIUM = Path(os.environ.get("CHEWBOT_CHROMIUM", "/usr/bin/chromium"))
runner = CliRunner()


@pytest.fixture(scope="session")
def run_with_dynamics():
    """The default task on the target with the Hessian formulation, computed once."""
    return compute(RunOptions(method="hessian"))


@pytest.fixture(scope="session")
def run_folder(run_with_dynamics, tmp_path_factory):
    """The folder that `chewbot run` writes for that run."""
    return write(run_with_dynamics, tmp_path_factory.mktemp("runs") / "default")


# --- positions of the drawn robot ------------------------------------------------------------------------


def test_crank_tips_and_mandible_points_close_every_chain():
    """S_i from theta and M_i from the pose are two routes to the same loop: |G S| = L_c and |S M| = L_r.

    The inverse kinematics is closed form, so the loops close to rounding: 1e-9 m (a nanometre) is far above
    float error on 0.1 m and far below any drawing error.
    """
    m, kin = model("target"), default_kinematics()
    idx = np.arange(0, kin.n, 7)
    pos = report_html.robot_positions(m, _rows(kinematics_table(kin), idx))
    assert np.abs(np.linalg.norm(pos["S"] - m.G, axis=2) - m.crank_length).max() < 1e-9
    assert np.abs(np.linalg.norm(pos["S"] - pos["body"][:, :6], axis=2) - m.coupler_length).max() < 1e-9


def test_mandible_points_agree_with_the_kinematics():
    """T_L, T_R, I, B_L, B_R from the pose (NumPy) equal Kinematics.points (CasADi graph) to 1e-12 m."""
    m, kin = model("target"), default_kinematics()
    body = report_html.robot_positions(m, kinematics_table(kin))["body"]
    for j, name in enumerate(report_html.MANDIBLE_POINTS):
        assert np.abs(body[:, 6 + j] - kin.points[name]).max() < 1e-12, name


def _rows(table: Table, idx: np.ndarray) -> Table:
    out = Table(units=dict(table.units))
    out.columns = {name: values[idx] for name, values in table.columns.items()}
    return out


def test_frames_cover_the_task_within_the_budget():
    t = np.arange(0, 60.0, 1e-3)  # a minute: longer than MAX_FRAMES frames at FRAME_STEP_S
    idx = report_view.frame_samples(t)
    assert idx[0] == 0 and idx[-1] == len(t) - 1
    assert len(idx) <= report_view.MAX_FRAMES + 1  # + the last sample
    short = report_view.frame_samples(np.arange(0, 5.0005, 1e-3))
    assert np.diff(short).min() == 40  # 40 ms at 1 kHz


# --- the summary's numbers ---------------------------------------------------------------------------------


def test_column_stats_of_a_known_signal():
    """sin(2 pi t) over whole periods: peak 2 at t = 0.25 s, RMS sqrt(2), mean 0 (exact on this grid)."""
    t = np.arange(0, 2.0, 1e-3)
    table = Table()
    table.add("t", t, "s")
    table.add("tau1", 2 * np.sin(2 * np.pi * t), "N*m")
    table.add("tau2", -3 + 0 * t, "N*m")
    s1, s2 = column_stats(table, ["tau1", "tau2"])
    assert s1.peak == pytest.approx(2.0, abs=1e-12) and s1.t_peak == pytest.approx(0.25, abs=1e-12)
    assert s1.rms == pytest.approx(math.sqrt(2), rel=1e-12) and abs(s1.mean) < 1e-12
    assert s2.peak == -3 and s2.rms == pytest.approx(3)


def test_near_singular_runs_are_found_chain_by_chain():
    t = np.arange(10) * 0.1
    sin_tr = np.ones((10, 6))
    sin_tr[2:5, 3] = np.sin(np.radians([14.0, 5.0, 10.0]))
    sin_tr[8, 3] = np.sin(np.radians(14.9))
    sin_tr[:, 0] = np.sin(np.radians(15.01))  # just above the threshold
    runs = near_singular(t, sin_tr, threshold_deg=15.0)
    assert [(r.chain, r.first, r.last) for r in runs] == [(4, 2, 4), (4, 8, 8)]
    assert runs[0].min_deg == pytest.approx(5.0) and runs[0].t_min == pytest.approx(0.3)


def test_indices_and_infeasible_samples_are_read_where_the_formulations_put_them():
    info = {"indices": {"F1": 0.5, "F3": float("nan")}, "F2": 2.0, "goal": "min-torque",
            "infeasible": [{"sample": 3, "t": 0.003, "limits": ["torque 2"]}, 7]}
    assert list(performance_indices(info)) == ["F1", "F2", "F3"]
    bad = infeasible_samples(info, np.arange(10) * 1e-3)
    assert bad == [{"sample": 3, "t": 0.003, "limits": ["torque 2"]}, {"sample": 7, "t": 0.007, "limits": []}]


# --- the page -------------------------------------------------------------------------------------------


def _page(folder: Path) -> str:
    return (folder / "report.html").read_text("utf-8")


def test_report_is_self_contained_and_shows_what_ran(run_folder, run_with_dynamics):
    page = _page(run_folder)
    # Nothing is fetched: no external script, style, image or frame outside plotly.js (whose code names URLs it
    # never loads here; the browser test below watches the requests), links to the folder's files are relative.
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", page.replace(get_plotlyjs(), ""))
    assert "Plotly" in page and "</html>" in page
    # plotly.js alone is ~4.8 MB; the data must stay small beside it.
    assert (run_folder / "report.html").stat().st_size < 8e6
    for text in ("Actuator torques", "Inertia coupling (MCI)", "Transmission angles", "No near-singular sample"):
        assert text in page, text
    for name in ("results.csv", "run.json", "task_space.png"):
        assert f'href="{name}"' in page
    # every column group of the table has a plot: tau1..6 and MCI1..6 are groups of their own
    assert "Actuator torques (hessian) (tau1, tau2, tau3, tau4, tau5, tau6)" in page


def test_report_degrades_without_dynamics_and_plots_unknown_columns(tmp_path):
    result = compute(RunOptions(method=None))
    n = result.table.n
    result.table.add_block(["widget_a", "widget_b"], np.ones((n, 2)), "N", "a quantity from a later stage")
    out = write(result, tmp_path / "kin-only")
    page = _page(out)
    assert "Inverse dynamics did not run" in page
    assert "Actuator torques" not in page and "Performance indices" not in page
    assert "A quantity from a later stage (widget_a, widget_b)" in page


def test_a_failure_while_writing_the_report_leaves_nothing_and_keeps_the_old_folder(run_with_dynamics, tmp_path, monkeypatch):
    out = tmp_path / "run"

    def broken(*args, **kwargs):
        raise RuntimeError("report failed")

    monkeypatch.setattr(report_html, "write_report", broken)
    with pytest.raises(RuntimeError):
        write(run_with_dynamics, out)
    assert list(tmp_path.iterdir()) == []
    out.mkdir()
    (out / "run.json").write_text('{"chewbot_run": 2}')  # an earlier result of chewbot's: --force may replace it
    (out / "keep.txt").write_text("old result")
    with pytest.raises(OutputExistsError):
        write(run_with_dynamics, out)
    with pytest.raises(RuntimeError):
        write(run_with_dynamics, out, force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    assert (out / "keep.txt").read_text() == "old result"


# --- chewbot report DIR -----------------------------------------------------------------------------------


def _contents(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_report_command_rebuilds_the_same_report_and_figures(tmp_path):
    """`chewbot run` writes its folder chunk by chunk; `chewbot report DIR --force` draws the figures and the report
    again from results.csv and run.json alone: the same bytes. results.csv and run.json are never written."""
    out = tmp_path / "run"
    assert runner.invoke(app, ["run", "--out", str(out), "-q"]).exit_code == 0
    before = _contents(out)
    stamps = {name: (out / name).stat().st_mtime_ns for name in ("results.csv", "run.json")}
    refused = runner.invoke(app, ["report", str(out)])
    assert refused.exit_code == 5 and "--force" in refused.output
    assert _contents(out) == before
    again = runner.invoke(app, ["report", str(out), "--force"])
    assert again.exit_code == 0, again.output
    assert _contents(out) == before
    assert {name: (out / name).stat().st_mtime_ns for name in stamps} == stamps


def test_a_batch_run_gets_its_figures_and_report_later(tmp_path):
    out = tmp_path / "batch"
    assert runner.invoke(app, ["run", "--out", str(out), "--no-figures", "--no-report", "-q"]).exit_code == 0
    assert sorted(p.name for p in out.iterdir()) == ["model.toml", "results.csv", "run.json"]  # the data and the copy of the model, no drawing
    result = runner.invoke(app, ["report", str(out), "--no-figures"])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == ["model.toml", "report.html", "results.csv", "run.json"]
    assert 'href="task_space.png"' not in _page(out)
    assert runner.invoke(app, ["report", str(out), "--no-report"]).exit_code == 0  # the figures: none existed
    assert runner.invoke(app, ["report", str(out), "--no-figures", "--force"]).exit_code == 0
    assert 'href="task_space.png"' in _page(out)  # now the folder has them: the report links to them


def test_report_command_writes_only_into_chewbot_s_results_folders(tmp_path, run_folder):
    assert runner.invoke(app, ["report", str(tmp_path / "missing")]).exit_code == 2
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "results.csv").write_text("t\n0\n")
    result = runner.invoke(app, ["report", str(mine)])
    assert result.exit_code == 5 and "not a results folder written by chewbot" in result.output
    assert sorted(p.name for p in mine.iterdir()) == ["results.csv"]
    # a run whose model has changed since: its parameters' SHA-256 no longer match
    copy = tmp_path / "copy"
    shutil.copytree(run_folder, copy)
    record = json.loads((copy / "run.json").read_text())
    record["model"]["parameters_sha256"] = "0" * 64
    (copy / "run.json").write_text(json.dumps(record))
    result = runner.invoke(app, ["report", str(copy), "--force"])
    assert result.exit_code == 2 and "no longer has the run's parameters" in result.output


# --- in a real browser ----------------------------------------------------------------------------------


def _chromium():
    """The playwright module, or a skip where the browser cannot run. With $CHEWBOT_REQUIRE_BROWSER set (the
    README's test command and .ci/run set it, after installing Chromium from the system's packages) a missing
    browser fails the test instead: on a fresh machine the report's JavaScript is always run."""
    required = bool(os.environ.get("CHEWBOT_REQUIRE_BROWSER"))
    try:
        from playwright import sync_api
    except ImportError:
        if required:
            pytest.fail("playwright is not installed (pip install -e '.[test]') and $CHEWBOT_REQUIRE_BROWSER is set")
        pytest.skip("playwright is not installed (pip install -e '.[test]')")
    if not CHROMIUM.exists():
        if required:
            pytest.fail(f"no browser: {CHROMIUM} is missing and $CHEWBOT_REQUIRE_BROWSER is set (Debian: apt-get install chromium)")
        pytest.skip(f"no browser: {CHROMIUM} is missing (Debian: apt-get install chromium)")
    return sync_api


@contextmanager
def _browser_page(errors: list[str]):
    """A page of headless Chromium (a fresh profile, removed after) whose thrown exceptions (also as
    ``window.__thrown``, caught by a listener installed before the page's own scripts run), console errors and
    network requests other than file: and data: are appended to ``errors``; the browser closed after."""
    sync_api = _chromium()
    profile = tempfile.mkdtemp(prefix="chewbot-chromium-")
    try:
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch_persistent_context(
                profile, executable_path=str(CHROMIUM), headless=True, viewport={"width": 1400, "height": 1000},
                args=["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                      "--disable-component-update", "--disable-sync"])
            try:
                page = browser.new_page()
                page.add_init_script("window.addEventListener('error', e => { window.__thrown = String(e.message); });")
                page.on("console", lambda msg: errors.append(msg.text) if msg.type == "error" else None)
                page.on("pageerror", lambda exc: errors.append(f"the page threw: {exc}"))
                page.on("request", lambda req: errors.append(f"network request {req.url}") if not req.url.startswith(("file:", "data:")) else None)
                yield page
            finally:
                browser.close()
    finally:
        shutil.rmtree(profile, ignore_errors=True)


def _check_report_in_chromium(report: Path, screenshots: bool = False) -> None:
    """Open ``report`` from disk in headless Chromium and assert: no exception thrown by the page, no console error,
    no network request, every plot drawn, the 3D robot animated. An exception thrown by the page ends the wait at
    once (it is caught by a listener installed before the page's own scripts run)."""
    errors: list[str] = []
    with _browser_page(errors) as page:
        page.goto(report.as_uri())
        page.wait_for_function("document.body && (document.body.dataset.plotsDrawn !== undefined || window.__thrown !== undefined)",
                               timeout=60_000)
        thrown = page.evaluate("window.__thrown === undefined ? null : window.__thrown")
        assert thrown is None and errors == [], (thrown, errors)
        drawn = int(page.get_attribute("body", "data-plots-drawn"))
        plots = page.eval_on_selector_all(".js-plotly-plot", "els => els.map(e => e.id)")
        assert drawn == len(plots) >= 7  # robot, task space, joint space, bite force, transmission, tau, MCI
        # each 2D plot has drawn its lines as SVG paths with data
        lines = page.eval_on_selector_all(".js-plotly-plot:not(#robot)",
                                          "els => els.map(e => e.querySelectorAll('.scatterlayer .trace path.js-line').length)")
        assert all(n > 0 for n in lines), lines
        # the 3D scene is a WebGL canvas of real size, with its animation frames
        size = page.eval_on_selector("#robot canvas", "c => [c.width, c.height]")
        assert size[0] > 300 and size[1] > 300
        frames = page.evaluate("document.getElementById('robot')._transitionData._frames.length")
        assert frames > 100
        # jump to a frame inside a bite-force burst (the arrow shows) and keep a picture
        assert page.evaluate("Plotly.animate('robot', ['1.640'], {frame: {duration: 0, redraw: true}, mode: 'immediate'}).then(() => 'shown')") == 'shown'
        page.wait_for_timeout(500)
        if screenshots:
            ARTIFACTS.mkdir(exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "report.png"))
            page.screenshot(path=str(ARTIFACTS / "report-full.png"), full_page=True)
    assert errors == []


@pytest.mark.browser
def test_report_renders_in_headless_chromium(run_folder):
    """Open report.html from disk in Chromium: no exception or console error, every plot drawn, the 3D robot animated."""
    _check_report_in_chromium(run_folder / "report.html", screenshots=True)


@pytest.mark.browser
def test_the_browser_check_fails_when_the_page_throws(run_folder, tmp_path):
    """The same check on the report with one script that throws: it must fail (naming the exception), so a
    report whose JavaScript breaks cannot pass."""
    broken = tmp_path / "report.html"
    html = (run_folder / "report.html").read_text(encoding="utf-8")
    broken.write_text(html.replace("<head>", "<head><script>throw new Error('injected by the test');</script>", 1), encoding="utf-8")
    with pytest.raises(AssertionError, match="injected by the test"):
        _check_report_in_chromium(broken)


def test_the_formulation_s_flags_read_as_words():
    """The report's "Formulation" listing shows friction on/off and other flags yes/no, never Python's True/False."""
    from chewbot.report.summary import solver_notes

    assert solver_notes({"friction": False, "strict": True, "goal": "min-torque", "iterations": 3, "table": [1]}) == {
        "friction": "off", "strict": "yes", "goal": "min-torque", "iterations": 3}


def _tpa_folder(folder: Path) -> Path:
    """A texture test's folder from a hand-built two-bite curve (an elastic cylinder of 1000 N/m along a profile of
    the protocol): tpa.json, the two figures, tpa.html, as ``chewbot tpa --log`` writes them."""
    from chewbot.food.tpa import Protocol, analyse
    from chewbot.outputs.tpa import write_tpa_log

    profile = Protocol(pause=0.5).profile(0.011, 1.25)
    t = profile.times()
    g = profile.path(t)[0]
    F = 1000.0 * np.maximum(0.010 - g, 0.0)
    analysis = analyse(t, g, F, 0.049, label="estimated")
    record = {"chewbot_tpa": 2, "options": {"log": "hand-built"}, "protocol": profile.record(), "food": None, "plant": None,
              "estimated": analysis.measures, "definitions": analysis.definitions, "anchors": {"estimated": analysis.anchors},
              "estimator": {"contact_force_N": 0.049}, "checks": [c.as_dict() for c in analysis.checks]}
    return write_tpa_log(record, {"t": t, "gap": g, "force": F}, 0.010, "hand-built cylinder", folder / "tpa")


def test_tpa_report_is_tables_and_figures_not_raw_json(tmp_path):
    page = (_tpa_folder(tmp_path) / "tpa.html").read_text(encoding="utf-8")
    assert "<pre>" not in page and "{&quot;" not in page and '{"' not in page
    for heading in ("Measures", "Force over time", "Force over compression", "Checks", "The protocol as run"):
        assert f"<h2>{heading}</h2>" in page
    assert "estimated-springiness-range" in page and "<td>hardness [N]</td>" in page and "<td>springiness at peak</td>" in page


@pytest.mark.browser
def test_tpa_report_renders_in_headless_chromium(tmp_path):
    """tpa.html opened from disk: no exception or console error, no network request, both figures loaded."""
    _chromium()
    report = _tpa_folder(tmp_path) / "tpa.html"
    errors: list[str] = []
    with _browser_page(errors) as page:
        page.goto(report.as_uri())
        page.wait_for_load_state("load")
        widths = page.eval_on_selector_all("img", "els => els.map(e => e.naturalWidth)")
        assert len(widths) == 2 and all(w > 300 for w in widths), widths
        assert page.eval_on_selector_all("table", "els => els.length") >= 4
    assert errors == []


# --- the food sample in the 3D view of simulate --food --------------------------------------------------------------

CRUSHING = {"name": "crushing cylinder", "shape": "cylinder", "height_mm": 4.0, "diameter_mm": 10.0, "young_modulus_kPa": 100.0,
            "fracture_strain": 0.3, "stiffness_after_fracture": 0.5, "recovery_after_fracture": 0.1, "tooth_friction": 0.3}


@pytest.fixture(scope="session")
def food_run_folder(tmp_path_factory):
    """``chewbot simulate --food`` on a crushing 4 mm cylinder: two bites to half its height at 6 mm/s on the texture
    test's path (about 2 s), its folder with report.html."""
    from chewbot.food.geometry import face_path_task
    from chewbot.food.tpa import Protocol
    from chewbot.task.csvio import task_table

    folder = tmp_path_factory.mktemp("food-run")
    (folder / "crushing.toml").write_text("[food]\n" + "".join(f'{k} = "{v}"\n' if isinstance(v, str) else f"{k} = {v}\n"
                                                                for k, v in CRUSHING.items()))
    profile = Protocol(pre_test_speed=4e-3, test_speed=6e-3, post_test_speed=6e-3, pause=0.1).profile(5e-3, 0.3)
    t = profile.times()
    task = face_path_task(model("target"), "left", t, *profile.path(t), 4e-3, 1e-3, name="two bites")
    task_table(task).to_csv(folder / "task.csv")
    result = runner.invoke(app, ["simulate", "--food", str(folder / "crushing.toml"), "--task", str(folder / "task.csv"),
                                 "--out", str(folder / "run"), "--allow-violations", "-q"])
    assert result.exit_code == 0, result.output
    return folder / "run"


def _food_rows(folder: Path) -> Table:
    return Table.read_csv(folder / "results.csv")


def test_the_food_sample_is_drawn_compressed_by_the_gap_and_crushed(food_run_folder):
    """The sample's cylinder (report.html.sample_vertices) from results.csv: its bottom centre at the bite point, its
    rim 5 mm around it in the lower tooth's plane; its top cut off at the upper tooth (z = B_z at home) where the
    centre's fibre is compressed, so that the drawn height at its centre is the gap; elsewhere its height is its
    unloaded height at the centre, h0 before the fracture and, crushed, h0 - (1 - r) delta_max after it, delta_max
    the deepest compression of the face's centre (over the rows: to 1 um, the travel between two rows at 1 ms near
    the turn is below 0.1 um)."""
    from chewbot.food.geometry import gap

    m = model("target")
    rows = _food_rows(food_run_folder)
    V = report_html.sample_vertices(m, "left", rows, 10e-3)
    z_home = float(m.molar("left")[2])
    q = np.column_stack([rows[c] for c in ("X", "Y", "alpha", "beta")])
    g = gap(m, "left", q)
    assert np.allclose(V[:, 0], g["point"], atol=1e-12)
    rim = V[:, 2:2 + report_html.SAMPLE_SIDES] - V[:, :1]
    assert np.allclose(np.linalg.norm(rim, axis=2), 5e-3, atol=1e-12)
    pressed = g["gap"] < rows["food_height"]  # the centre's fibre compressed
    assert pressed.any() and np.allclose(V[pressed, 1, 2], z_home, atol=1e-12)
    assert np.allclose((V[pressed, 1] - V[pressed, 0])[:, 2], g["gap"][pressed], atol=1e-12)
    assert np.allclose(np.linalg.norm(V[~pressed, 1] - V[~pressed, 0], axis=1), rows["food_height"][~pressed], atol=1e-12)
    broken = rows["food_broken"] > 0
    assert broken.any() and not broken[0] and np.all(rows["food_height"][~broken] == 4e-3)
    assert rows["food_height"][-1] == pytest.approx(4e-3 - 0.9 * (4e-3 - g["gap"]).max(), abs=1e-6)


@pytest.mark.browser
def test_the_food_sample_shows_in_the_3d_view(food_run_folder):
    """report.html of simulate --food opened in Chromium: no exception or console error, the robot's scene has the
    food sample as a mesh, green before the fracture and brown after it, lower than h0 in the first compression."""
    errors: list[str] = []
    with _browser_page(errors) as page:
        page.goto((food_run_folder / "report.html").as_uri(), timeout=120_000)
        page.wait_for_function("document.body.dataset.plotsDrawn !== undefined", timeout=120_000)
        sample = "gd => gd.data.find(d => d.name.startsWith('food sample'))"
        names = page.evaluate("document.getElementById('robot')._transitionData._frames.map(f => f.name)")
        rows = _food_rows(food_run_folder)
        t_break = float(rows["t"][np.argmax(rows["food_broken"] > 0)])
        for when, colour in ((0.0, report_html.SAMPLE_COLOURS[False]), (float(rows["t"][-1]), report_html.SAMPLE_COLOURS[True])):
            name = min(names, key=lambda n: abs(float(n) - when))
            assert (float(name) < t_break) == (colour == report_html.SAMPLE_COLOURS[False])
            page.evaluate(f"Plotly.animate('robot', ['{name}'], {{frame: {{duration: 0, redraw: true}}, mode: 'immediate'}})")
            page.wait_for_timeout(300)
            drawn = page.eval_on_selector("#robot", f"el => {{ const s = ({sample})(el); return [s.type, s.color, s.z.length]; }}")
            assert drawn == ["mesh3d", colour, 2 + 2 * report_html.SAMPLE_SIDES]
        size = page.eval_on_selector("#robot canvas", "c => [c.width, c.height]")
        assert size[0] > 300 and size[1] > 300
    assert errors == []
