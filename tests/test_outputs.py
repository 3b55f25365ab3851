"""Outputs a user can trust: exit code 4 with the folder complete, --force only over chewbot's own outputs,
no temporary files left, the umask, units in results.csv and its round trip as a task, and the command line's
help and messages."""

from __future__ import annotations

import errno
import json
import os
import re
import signal
import subprocess

import numpy as np
import pandas as pd
import pytest
import typer
from typer.testing import CliRunner

from chewbot.analysis.checks import results_from_json
from chewbot.cli import app
from chewbot.commands.common import EXIT_CHECK_FAILED, EXIT_OUTPUT, exit_after_checks
from chewbot.files import (
    RESULTS_FOLDER,
    WRITTEN_FILE,
    OutputError,
    OutputExistsError,
    atomic_files,
    atomic_folder,
    cannot_write,
    check_output,
    marker_line,
    sidecar,
    remove_stale,
)
from chewbot.model.params import builtin_model_path
from chewbot.table import Table
from chewbot.outputs.record import read_results
from chewbot.task.csvio import read_task_csv

runner = CliRunner()
FILES = {"results.csv", "run.json", "report.html", "task_space.png", "joint_space.png", "bite_force.png", "torques.png", "coupling.png"}


def invoke(*args: str):
    return runner.invoke(app, list(args), env={"COLUMNS": "250"})


@pytest.fixture(scope="module")
def finished_run(task_csv, tmp_path_factory):
    """One finished run (right side, so that the side is not the default), reused by the tests below."""
    out = tmp_path_factory.mktemp("runs") / "right"
    result = invoke("run", "--task", str(task_csv), "--side", "right", "--out", str(out), "--quiet")
    assert result.exit_code == 0, result.output
    return out


# --- exit code 4 ---------------------------------------------------------------------------------------------


def test_a_task_over_the_torque_limit_exits_4_with_the_folder_complete(task_csv, tmp_path):
    """The task needs about 0.1 N m; a model whose limit is 0.02 N m fails torque-limit: the folder is written in
    full, run.json records the check, the table of failed checks is printed; --allow-violations exits 0."""
    weak = tmp_path / "weak.toml"
    weak.write_text(re.sub(r"^torque_Nm = .*$", "torque_Nm = 0.02", builtin_model_path("target").read_text(), flags=re.M))
    out = tmp_path / "run"
    result = invoke("run", "--model", str(weak), "--task", str(task_csv), "--out", str(out))
    assert result.exit_code == EXIT_CHECK_FAILED, result.output
    assert FILES <= {p.name for p in out.iterdir()}
    checks = {c["name"]: c for c in json.loads((out / "run.json").read_text())["checks"]}
    torque = checks["torque-limit"]
    assert not torque["passed"] and torque["samples"] > 0 and torque["severity"] == "failure"
    assert torque["worst"]["unit"] == "N*m" and torque["worst"]["value"] > 0.02
    assert set(torque["first_sample"]) == {"index", "t"}
    assert "failed validity checks" in result.output and "torque-limit" in result.output
    # what --allow-violations changes: the same checks, printed, and no exit
    results = results_from_json(json.loads((out / "run.json").read_text())["checks"])
    with pytest.raises(typer.Exit) as stop:
        exit_after_checks(results, allow_violations=False, quiet=True)
    assert stop.value.exit_code == EXIT_CHECK_FAILED
    exit_after_checks(results, allow_violations=True, quiet=True)


# --- --force and markers -------------------------------------------------------------------------------------


def test_force_never_replaces_a_folder_chewbot_did_not_write(task_csv, tmp_path):
    thesis = tmp_path / "thesis"
    thesis.mkdir()
    (thesis / "chapter1.tex").write_text("months of work")
    (thesis / "run.json").write_text('{"mine": 1}')  # a run.json, but not chewbot's
    result = invoke("run", "--task", str(task_csv), "--out", str(thesis), "--force", "--quiet")
    assert result.exit_code == EXIT_OUTPUT and "not written by chewbot" in result.output
    assert sorted(p.name for p in thesis.iterdir()) == ["chapter1.tex", "run.json"]
    assert (thesis / "chapter1.tex").read_text() == "months of work"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["thesis"]


def test_force_replaces_chewbot_outputs_only_of_their_own_kind(finished_run, tmp_path):
    assert RESULTS_FOLDER.present(finished_run)
    other = tmp_path / "kernels"
    other.mkdir()
    (other / "chewbot-export.json").write_text('{"chewbot_export": 1}')
    with pytest.raises(OutputExistsError, match="not written by chewbot"):
        check_output(other, True, RESULTS_FOLDER)
    with pytest.raises(OutputExistsError, match="pass --force"):
        check_output(finished_run, False, RESULTS_FOLDER)
    check_output(finished_run, True, RESULTS_FOLDER)
    link = tmp_path / "link"
    link.symlink_to(finished_run)
    with pytest.raises(OutputExistsError, match="symbolic link"):
        check_output(link, True, RESULTS_FOLDER)


def test_outputs_that_hold_the_current_folder_or_an_input_are_refused(finished_run, task_csv, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for out in (".", str(tmp_path.parent)):
        result = invoke("run", "--task", str(task_csv), "--out", out, "--force", "--quiet")
        assert result.exit_code == EXIT_OUTPUT and "current folder" in result.output, out
    # the results folder's own results.csv as the task, with that folder as --out: refused, the folder intact
    before = (finished_run / "results.csv").read_bytes()
    result = invoke("run", "--task", str(finished_run / "results.csv"), "--out", str(finished_run), "--force", "--quiet")
    assert result.exit_code == EXIT_OUTPUT and "inside it" in result.output
    assert (finished_run / "results.csv").read_bytes() == before
    with pytest.raises(OutputError, match="this file"):
        check_output(task_csv, True, WRITTEN_FILE, inputs=[task_csv])


def test_single_files_carry_the_marker_and_are_written_all_or_none(tmp_path):
    a, b = tmp_path / "task.csv", tmp_path / "task.residuals.csv"
    with atomic_files([a, b], about={a: "a task"}) as (ta, tb):
        ta.write_text("t [s]\n0.5\n")
        tb.write_text("t [s]\n0.25\n")
    # plain CSV, read with no options; the marker is the sidecar beside each, with the file's SHA-256
    assert list(pd.read_csv(a).columns) == ["t [s]"] and pd.read_csv(a)["t [s]"].tolist() == [0.5]
    assert WRITTEN_FILE.present(a) and WRITTEN_FILE.present(b)
    assert json.loads(sidecar(a).read_text())["about"] == "a task"
    with pytest.raises(RuntimeError, match="report"):  # the second file fails: neither is replaced
        with atomic_files([a, b], force=True) as (ta, tb):
            ta.write_text("t [s]\n1\n")
            raise RuntimeError("report failed")
    assert a.read_text() == "t [s]\n0.5\n" and sorted(p.name for p in tmp_path.iterdir()) == [
        "task.csv", "task.csv.chewbot.json", "task.residuals.csv", "task.residuals.csv.chewbot.json"]
    with atomic_files([a], force=True) as (ta,):  # replaced with --force: new content, new SHA-256
        ta.write_text("t [s]\n2\n")
    assert a.read_text() == "t [s]\n2\n" and WRITTEN_FILE.present(a)
    a.write_text("t [s]\n3\n")  # edited by the user since: no longer chewbot's, never replaced
    with pytest.raises(OutputExistsError, match="changed since chewbot wrote it"):
        check_output(a, True, WRITTEN_FILE)
    with pytest.raises(RuntimeError, match="did not mark"):  # a TOML file without chewbot's line could never be replaced
        with atomic_files([tmp_path / "c.toml"]) as (tc,):
            tc.write_text("x = 1\n")


def test_csv_files_written_before_the_sidecars_are_still_chewbot_s(tmp_path):
    """A CSV of an earlier version begins with the marker line and has no sidecar: --force still replaces it (and
    the new one is plain, with its sidecar); without the line and the sidecar it is the user's."""
    old = tmp_path / "task.csv"
    old.write_text("# written by chewbot 0.1.0: a task, read it with chewbot run --task\nt [s]\n0\n")
    assert WRITTEN_FILE.present(old)
    with pytest.raises(OutputExistsError, match="pass --force"):
        check_output(old, False, WRITTEN_FILE)
    with atomic_files([old], force=True) as (tmp,):
        tmp.write_text("t [s]\n1\n")
    assert old.read_text() == "t [s]\n1\n" and sidecar(old).is_file() and WRITTEN_FILE.present(old)
    mine = tmp_path / "mine.csv"
    mine.write_text("t [s]\n0\n")
    with pytest.raises(OutputExistsError, match="not written by chewbot"):
        check_output(mine, True, WRITTEN_FILE)
    mine = tmp_path / "notes.md"
    mine.write_text("# my notes\n")
    with pytest.raises(OutputExistsError, match="not written by chewbot"):
        check_output(mine, True, WRITTEN_FILE)
    with pytest.raises(RuntimeError, match="did not mark"):  # a folder without its marker, likewise
        with atomic_folder(tmp_path / "run") as tmp:
            (tmp / "results.csv").write_text("t\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.csv", "notes.md", "task.csv", "task.csv.chewbot.json"]


def test_bench_out_follows_the_force_rule(tmp_path, monkeypatch):
    from chewbot.bench import benchmark as bench

    # the timings themselves are not this test's subject
    monkeypatch.setattr(bench, "benchmark", lambda **options: "| case | median (ms) |\n")
    out = tmp_path / "bench.md"
    assert invoke("bench", "--out", str(out)).exit_code == 0
    assert out.read_text().startswith("<!-- written by chewbot ") and "| case | median (ms) |" in out.read_text()
    assert invoke("bench", "--out", str(out)).exit_code == EXIT_OUTPUT
    assert invoke("bench", "--out", str(out), "--force").exit_code == 0
    mine = tmp_path / "notes.md"
    mine.write_text("my notes\n")
    result = invoke("bench", "--out", str(mine), "--force")
    assert result.exit_code == EXIT_OUTPUT and "not written by chewbot" in result.output and mine.read_text() == "my notes\n"


def test_export_writes_its_marker_and_force_replaces_only_an_export(tmp_path):
    import casadi as ca

    from chewbot.export.c import Kernel, export_c

    x = ca.SX.sym("x")
    k = Kernel(ca.Function("twice", [x], [2 * x], ["x"], ["y"]), "2 x", {"x": "m"}, {"y": "m"}, {"x": np.array([1.5])})
    out = export_c([k], tmp_path / "c")
    assert json.loads((out / "chewbot-export.json").read_text())["kernels"] == ["twice"]
    export_c([k], out, force=True)
    mine = tmp_path / "controller"
    mine.mkdir()
    (mine / "main.c").write_text("int main(void) { return 0; }\n")
    with pytest.raises(OutputExistsError, match="not written by chewbot"):
        export_c([k], mine, force=True)
    assert [p.name for p in mine.iterdir()] == ["main.c"]


# --- temporary files -----------------------------------------------------------------------------------------


def _dead_pid() -> int:
    p = subprocess.Popen(["true"])
    p.wait()
    return p.pid


def _write_results_folder(out, force=False):
    """What a command does: the folder through atomic_folder, its marker inside."""
    with atomic_folder(out, force) as tmp:
        (tmp / "results.csv").write_text("t [s]\n0.0\n")
        (tmp / "run.json").write_text('{"chewbot_run": 2}')


def test_stale_temporaries_of_dead_processes_are_removed_and_those_of_live_ones_kept(tmp_path):
    live = subprocess.Popen(["sleep", "60"])
    try:
        dead = _dead_pid()
        (tmp_path / f".run.partial-{dead}-0123abcd").mkdir()
        (tmp_path / f".task.csv.partial-{dead}-0123abcd").write_text("half")
        (tmp_path / f".run.partial-{live.pid}-89abcdef").mkdir()  # a concurrent run, still writing
        (tmp_path / f".old.replaced-{dead}-0123abcd").mkdir()  # moved aside by a killed run, never replaced
        (tmp_path / f".old.replaced-{dead}-0123abcd" / "run.json").write_text('{"chewbot_run": 2}')
        _write_results_folder(tmp_path / "run")
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["run", "old", f".run.partial-{live.pid}-89abcdef"])
        assert (tmp_path / "old" / "run.json").exists()  # put back
    finally:
        live.send_signal(signal.SIGTERM)
        live.wait()
    assert [p.name for p in remove_stale(tmp_path)] == [f".run.partial-{live.pid}-89abcdef"]


def test_folders_and_files_follow_the_umask(tmp_path):
    for umask, folder, file in ((0o027, 0o750, 0o640), (0o002, 0o775, 0o664)):
        old = os.umask(umask)
        try:
            out = tmp_path / f"{umask:o}" / "run"
            _write_results_folder(out)
            with atomic_files([out.parent / "task.csv"]) as (tmp,):
                tmp.write_text(marker_line() + "\n")
        finally:
            os.umask(old)
        for path in (out.parent, out):
            assert path.stat().st_mode & 0o777 == folder, path
        for path in (out / "results.csv", out.parent / "task.csv"):
            assert path.stat().st_mode & 0o777 == file, path


def test_messages_for_unwritable_paths_name_the_path_and_the_reason(task_csv, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    result = invoke("run", "--task", str(task_csv), "--out", str(blocker / "run"), "--quiet")
    assert result.exit_code == EXIT_OUTPUT
    assert str(blocker / "run") in result.output and "a file of that name is in the way" in result.output
    for code, words in ((errno.EACCES, "permission denied"), (errno.ENOSPC, "the disk is full"), (errno.EROFS, "read-only")):
        message = str(cannot_write(tmp_path / "x", OSError(code, os.strerror(code))))
        assert str(tmp_path / "x") in message and words in message


# --- results.csv ---------------------------------------------------------------------------------------------


def test_results_csv_round_trips_as_a_task(finished_run, tmp_path):
    """The results of a run, read back as --task: the side comes from the run.json beside it, the output columns
    are skipped, every rate is used as written; the same method gives the same torques (1e-12 N m: the floats
    are written in their shortest exact form, so only a different order of operations could differ)."""
    run, table = read_results(finished_run)
    assert run["chewbot_run"] == 2 and table.units["tau1"] == "N*m" and table.units["ddalpha"] == "rad/s^2"
    task = read_task_csv(finished_run / "results.csv")
    assert task.side == "right" and task.meta["derivatives_estimated"] == []
    again = tmp_path / "again"
    result = invoke("run", "--task", str(finished_run / "results.csv"), "--out", str(again), "--quiet")
    assert result.exit_code == 0, result.output
    run2, table2 = read_results(again)
    assert run2["options"]["side"] == "right"
    for i in range(1, 7):
        assert np.abs(table2[f"tau{i}"] - table[f"tau{i}"]).max() <= 1e-12
    assert read_task_csv(finished_run / "results.csv", side="left").side == "left"  # what --side passes


def test_results_of_format_1_are_still_read(finished_run, tmp_path):
    """Version 1: names alone in the header (units in run.json), run.json's "chewbot_run" 1."""
    old = tmp_path / "old"
    old.mkdir()
    run, table = read_results(finished_run)
    run["chewbot_run"] = 1
    (old / "run.json").write_text(json.dumps(run))
    lines = (finished_run / "results.csv").read_text().splitlines()
    (old / "results.csv").write_text("\n".join([re.sub(r" \[[^\]]*\]", "", lines[0])] + lines[1:]) + "\n")
    run1, table1 = read_results(old)
    assert table1.units == table.units and all(np.array_equal(table1[n], table[n]) for n in table.columns)
    assert np.array_equal(read_task_csv(old / "results.csv").q, read_task_csv(finished_run / "results.csv").q)
    run["chewbot_run"] = 9
    (old / "run.json").write_text(json.dumps(run))
    with pytest.raises(Exception, match="results format 9"):
        read_results(old)


def test_a_results_csv_without_its_run_json_is_an_ordinary_task_file(finished_run, tmp_path):
    copy = tmp_path / "results.csv"
    copy.write_text((finished_run / "results.csv").read_text())
    with pytest.raises(Exception, match="unknown column 'theta1'.*run.json"):
        read_task_csv(copy)
    assert Table.read_csv(copy).units["X"] == "m"


# --- the command line ----------------------------------------------------------------------------------------


def test_the_top_help_states_the_exit_codes():
    top = invoke("-h")
    assert top.exit_code == 0 and "4 results written, a validity check failed" in top.output
    assert "--allow-violations" in invoke("run", "-h").output


def test_check_model_prints_units_and_warns_near_a_singular_home_pose(monkeypatch):
    import dataclasses

    from chewbot.model import params
    from chewbot.kinematics.ik import transmission
    from chewbot.report.summary import home_pose

    result = invoke("check-model", "target")
    assert result.exit_code == 0
    for header in ("crank [mm]", "coupler mass [g]", "θ home [deg]", "μ home [deg]"):
        assert header in result.output, header
    assert "17.96" in result.output and "warning" not in result.output  # chains 3, 4 at home: above 10 deg
    # turn chain 3's crank about its shaft (a new home pose of the crank, the coupler fitted to it) until its
    # coupler is less than 6 deg from the crank's plane at home
    m = params.load_model("target")
    Rz = lambda a: np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])  # noqa: E731
    for angle in np.radians(np.arange(0.0, 180.0, 0.25)):
        R_C0 = m.R_C0.copy()
        R_C0[2] = m.R_C0[2] @ Rz(angle)
        S0 = m.G + m.crank_length[:, None] * R_C0[:, :, 0]
        near = dataclasses.replace(m, R_C0=R_C0, S0=S0, coupler_length=np.linalg.norm(m.M - S0, axis=1))
        if np.degrees(np.arcsin(transmission(near, np.zeros((1, 3)), np.eye(3)[None])[0, 2])) < 6.0:
            break
    assert 3.0 < home_pose(near)["mu_deg"][2] < 6.0
    monkeypatch.setattr(params, "load_model", lambda name, overrides=None: near)
    result = invoke("check-model", "target")
    assert result.exit_code == 0 and "warning: chain 3 is near-singular at the home pose" in result.output


def test_the_report_names_the_dynamics_in_effect_and_every_figure_has_a_title(finished_run, tmp_path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from chewbot.report.plotting import save, subplots

    page = (finished_run / "report.html").read_text()
    assert "None" not in re.sub(r"<script.*?</script>", "", page, flags=re.S)
    assert "inverse dynamics: hessian (minimum-norm torques, no friction)" in page
    assert "Validity checks" in page
    fig, ax = subplots()
    with pytest.raises(ValueError, match="without a title"):
        save(fig, tmp_path / "untitled.png")
    assert isinstance(fig.canvas, FigureCanvasAgg)  # drawn without a display


def test_study_prints_its_table_of_claims(tmp_path, monkeypatch):
    from chewbot import study
    from chewbot.files import STUDY_FOLDER
    from chewbot.study.claims import STUDY_FORMAT, Claim, write_claims

    def fake(out, force=False, progress=None):
        with atomic_folder(out, force, STUDY_FOLDER) as tmp:
            write_claims([Claim(1, "default", "torques agree", "1e-15", True)], tmp)
            (tmp / "study.json").write_text(json.dumps({"chewbot_study": STUDY_FORMAT}))
        return out

    monkeypatch.setitem(study.STUDIES, "fake", fake)
    result = invoke("study", "fake", "--out", str(tmp_path / "s"))
    assert result.exit_code == 0, result.output
    assert "torques agree" in result.output and "1e-15" in result.output and "yes" in result.output
    assert invoke("study", "fake", "--out", str(tmp_path / "s")).exit_code == EXIT_OUTPUT
    assert invoke("study", "fake", "--out", str(tmp_path / "s"), "--force").exit_code == 0


def test_read_results_gives_a_dataframe_with_plain_names_and_units(finished_run):
    """chewbot.read_results: the same numbers as the Table reader (another parser: csv + float), plain names, the
    units of run.json in attrs; a folder that is not chewbot's is named."""
    import chewbot

    frame = chewbot.read_results(finished_run)
    run, table = read_results(finished_run)
    assert list(frame.columns) == list(table.columns)
    assert frame.attrs["units"] == {n: run["columns"][n]["unit"] for n in table.columns}
    assert frame.attrs["units"]["tau1"] == "N*m" and frame.attrs["descriptions"]["tau1"]
    for name in table.columns:  # the shortest repr that reads back exactly: both parsers give the same doubles
        assert np.array_equal(frame[name].to_numpy(), table[name], equal_nan=True), name
    assert chewbot.read_results(finished_run / "results.csv").shape == frame.shape
    with pytest.raises(chewbot.ChewbotError, match="not a results folder"):
        chewbot.read_results(finished_run.parent)


def test_a_results_folder_carries_its_model_and_task_and_is_redrawn_elsewhere(task_csv, tmp_path):
    """The folder holds copies of its parameter file and task file (run.json names them, with the SHA-256 of the
    originals); with the originals gone and the folder moved, `chewbot report` draws it from the copies, and the
    copied task reads back as the task the run read."""
    import shutil

    from chewbot.files import file_sha256

    mine = tmp_path / "my_robot.toml"
    shutil.copyfile(builtin_model_path("target"), mine)
    task = tmp_path / "chewing.csv"
    shutil.copyfile(task_csv, task)
    out = tmp_path / "runs" / "mine"
    result = invoke("run", "--model", str(mine), "--task", str(task), "--no-figures", "--no-report", "--out", str(out), "-q")
    assert result.exit_code == 0, result.output
    run = json.loads((out / "run.json").read_text())
    assert run["model"]["copy"] == "model.toml" and run["task"]["copy"] == "task.csv"
    assert file_sha256(out / "model.toml") == run["model"]["sha256"] == file_sha256(mine)
    assert file_sha256(out / "task.csv") == run["task"]["sha256"] == file_sha256(task)
    mine.unlink()
    task.unlink()
    moved = tmp_path / "elsewhere"
    out.rename(moved)
    result = invoke("report", str(moved), "--no-figures", "-q")
    assert result.exit_code == 0, result.output
    assert (moved / "report.html").is_file()
    assert np.array_equal(read_task_csv(moved / "task.csv").q, read_task_csv(task_csv).q)
    # a run of the folder's results.csv copies the task it read (not the results table): it reads back exactly
    again = tmp_path / "again"
    result = invoke("run", "--model", str(moved / "model.toml"), "--task", str(moved / "results.csv"), "--no-figures",
                    "--no-report", "--out", str(again), "-q")
    assert result.exit_code == 0, result.output
    copied, read = read_task_csv(again / "task.csv"), read_task_csv(moved / "results.csv")
    assert np.array_equal(copied.q, read.q) and np.array_equal(copied.dq, read.dq) and np.array_equal(copied.force, read.force)
def test_parquet_results_hold_the_csv_columns_and_values_with_units_in_the_schema(task_csv, tmp_path):
    """--format parquet: results.parquet instead of results.csv, the same columns (header cells as names) and the same
    float64 values (CSV writes each float in its shortest exact form: the two read back equal), units and descriptions
    in the schema's metadata; chewbot report redraws from it."""
    import pyarrow.parquet as pq

    csv_out, pq_out = tmp_path / "csv", tmp_path / "parquet"
    assert invoke("run", "--task", str(task_csv), "--quiet", "--out", str(csv_out)).exit_code == 0
    result = invoke("run", "--task", str(task_csv), "--format", "parquet", "--quiet", "--no-report", "--no-figures", "--out", str(pq_out))
    assert result.exit_code == 0, result.output
    assert not (pq_out / "results.csv").exists() and (pq_out / "results.parquet").is_file()
    run_csv, table_csv = read_results(csv_out)
    run_pq, table_pq = read_results(pq_out)
    assert run_pq["results_file"] == "results.parquet"
    assert list(table_pq.columns) == list(table_csv.columns) and table_pq.units == table_csv.units
    for name in table_csv.columns:
        np.testing.assert_array_equal(table_pq[name], table_csv[name], err_msg=name)
    header = (csv_out / "results.csv").read_text().splitlines()[0].split(",")
    schema = pq.read_schema(pq_out / "results.parquet")
    assert schema.names == header
    assert json.loads(schema.metadata[b"chewbot_units"]) == table_csv.units
    tau1 = schema.field("tau1 [N*m]")
    assert tau1.metadata[b"unit"] == b"N*m" and tau1.metadata[b"description"]
    redrawn = invoke("report", str(pq_out))
    assert redrawn.exit_code == 0, redrawn.output
    assert (pq_out / "report.html").is_file()
