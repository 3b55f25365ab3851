"""The command line end to end: models, check-model, run, exit codes, and bad input of every kind (help: test_help.py)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.commands.common import EXIT_BAD_INPUT, EXIT_OUTPUT, EXIT_UNREACHABLE
from chewbot.model.params import BUILTIN_MODELS, builtin_model_path

runner = CliRunner()


def invoke(*args: str):
    return runner.invoke(app, list(args))


def _assert_nothing_written(folder, out_name: str) -> None:
    """No results folder and no temporary sibling left behind."""
    assert not (folder / out_name).exists()
    assert [p.name for p in folder.iterdir() if out_name in p.name] == []


def _edited(task_csv, tmp_path, name: str, edit) -> str:
    lines = task_csv.read_text().splitlines()
    path = tmp_path / name
    path.write_text("\n".join(edit(lines)) + "\n")
    return str(path)


def test_models_lists_the_builtin_files():
    result = runner.invoke(app, ["models"], env={"COLUMNS": "250"})
    assert result.exit_code == 0
    for name in BUILTIN_MODELS:
        assert name in result.output and builtin_model_path(name).name in result.output


def test_check_model_prints_derived_quantities():
    result = runner.invoke(app, ["check-model", "target"], env={"COLUMNS": "250"})
    assert result.exit_code == 0, result.output
    # rho A L = 7.8e-3 g/mm^3 x 17.3494 mm^2 x 33 mm = 4.466 g; 4 x 4.466 + 2 x 7.037 = 31.94 g (MODEL.md)
    assert "4.466" in result.output and "7.037" in result.output and "couplers 31.94 g" in result.output
    assert "inside its socket" in result.output and "hkp.T_L_mm = [-2.5, 72.0, 15.965]" in result.output
    assert "valid:" in result.output


def test_check_model_names_the_file_and_key_of_a_bad_parameter(tmp_path):
    text = builtin_model_path("target").read_text().replace("mass_g = 340.22", "mass_g = -340.22")
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    result = invoke("check-model", str(bad))
    assert result.exit_code == EXIT_BAD_INPUT
    assert str(bad) in result.output and "mandible.mass_g" in result.output
    missing = invoke("check-model", str(tmp_path / "nothing.toml"))
    assert missing.exit_code == EXIT_BAD_INPUT and "no such parameter file" in missing.output


def test_run_writes_the_folder_and_never_overwrites_silently(task_csv, tmp_path):
    out = tmp_path / "run"
    first = invoke("run", "--task", str(task_csv), "--out", str(out))
    assert first.exit_code == 0, first.output
    assert {"results.csv", "run.json", "report.html", "task_space.png"} <= {p.name for p in out.iterdir()}
    assert "report.html" in first.output
    before = (out / "results.csv").read_bytes()
    (out / "mine.txt").write_text("a note of the user")
    again = invoke("run", "--task", str(task_csv), "--out", str(out))
    assert again.exit_code == EXIT_OUTPUT and "--force" in again.output
    assert (out / "mine.txt").exists() and (out / "results.csv").read_bytes() == before
    forced = invoke("run", "--task", str(task_csv), "--out", str(out), "--force", "--quiet")
    assert forced.exit_code == 0 and forced.output == ""
    assert not (out / "mine.txt").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["run"]  # no temporary or replaced folder left


def test_an_unwritable_destination_is_an_output_error(task_csv, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    result = invoke("run", "--task", str(task_csv), "--out", str(blocker / "run"), "--quiet")
    assert result.exit_code == EXIT_OUTPUT and str(blocker) in result.output


@pytest.mark.parametrize(
    "name, edit, expected",
    [
        ("missing.csv", None, "no such file (expected a target task)"),
        ("backwards.csv", lambda ls: ls[:5] + [ls[6], ls[5]] + ls[7:], "does not increase"),
        ("nan.csv", lambda ls: ls[:9] + [ls[9].replace(ls[9].split(",")[2], "nan", 1)] + ls[10:], "line 10"),
        ("no_beta.csv", lambda ls: [",".join(c for j, c in enumerate(line.split(",")) if j != 4) for line in ls], "beta"),
        ("furlong.csv", lambda ls: [ls[0].replace("X[mm]", "X[furlong]")] + ls[1:], "unknown unit 'furlong'"),
    ],
)
def test_bad_task_files_name_the_problem_and_write_nothing(task_csv, tmp_path, name, edit, expected):
    path = _edited(task_csv, tmp_path, name, edit) if edit else str(tmp_path / name)
    result = invoke("run", "--task", path, "--out", str(tmp_path / "out"), "--quiet")
    assert result.exit_code == EXIT_BAD_INPUT, result.output
    assert name in result.output and expected in result.output
    _assert_nothing_written(tmp_path, "out")


def test_an_unreachable_pose_names_the_sample_and_writes_nothing(task_csv, tmp_path):
    """X = 40 mm at one row drives the condyles out of their sockets (x at most 5 mm)."""
    def push(lines):
        cells = lines[20].split(",")
        cells[1] = "40"
        return lines[:20] + [",".join(cells)] + lines[21:]

    path = _edited(task_csv, tmp_path, "far.csv", push)
    result = invoke("run", "--task", path, "--out", str(tmp_path / "out"), "--quiet")
    assert result.exit_code == EXIT_UNREACHABLE, result.output
    assert "sample 19" in result.output and "socket" in result.output
    _assert_nothing_written(tmp_path, "out")


def test_a_bad_parameter_file_in_a_run_names_the_key(tmp_path):
    bad = tmp_path / "robot.toml"
    bad.write_text(builtin_model_path("target").read_text().replace("p1 = 1.1\n", ""))
    result = invoke("run", "--model", str(bad), "--out", str(tmp_path / "out"), "--quiet")
    assert result.exit_code == EXIT_BAD_INPUT and "robot.toml" in result.output and "hkp.p1" in result.output
    _assert_nothing_written(tmp_path, "out")


def test_progress_prints_a_line_per_stage_where_standard_error_is_not_a_terminal(capsys, monkeypatch):
    """Under a pipe or in a log (pytest's captured standard error is not a terminal) the progress display prints one
    line per stage with the seconds since the start, none for a step that goes on (same words before the colon: within
    PROGRESS_LINE_S of its line) or for a count of samples; nothing with --quiet, nor before ``delay``."""
    import re

    from chewbot.commands import common
    from chewbot.commands.common import progress

    steps = [("compiling kernels: 0 of 2 done, building a", {}), ("compiling kernels: 1 of 2 done", {}),
             ("kinematics", {"done": 0, "total": 10}), ("inverse dynamics (hessian)", {"done": 0}),
             ("inverse dynamics (hessian)", {"done": 5}), ("writing results.csv", {"stage": None})]
    for quiet, delay in ((False, 0.0), (True, 0.0), (False, 3600.0)):
        with progress(quiet, "demo", delay=delay) as step:
            for message, extra in steps:
                step(message, **extra)
        lines = capsys.readouterr().err.splitlines()
        if quiet or delay:
            assert lines == []
            continue
        assert all(re.search(r" \(\d+\.\d s\)$", line) for line in lines), lines
        assert [re.sub(r" \(\d+\.\d s\)$", "", line) for line in lines] == [
            "demo: compiling kernels: 0 of 2 done, building a", "demo: kinematics", "demo: inverse dynamics (hessian)",
            "demo: writing results.csv"]
    monkeypatch.setattr(common, "PROGRESS_LINE_S", 0.0)  # a stage that goes on: its new detail gets a line
    with progress(False, "demo") as step:
        for message, extra in steps:
            step(message, **extra)
    lines = [re.sub(r" \(\d+\.\d s\)$", "", line) for line in capsys.readouterr().err.splitlines()]
    assert lines[:2] == ["demo: compiling kernels: 0 of 2 done, building a", "demo: compiling kernels: 1 of 2 done"]
    assert lines[2:] == ["demo: kinematics", "demo: inverse dynamics (hessian)", "demo: writing results.csv"]
