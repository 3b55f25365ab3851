"""`chewbot run` and its results folder, kinematics only: column names, exact numbers, run.json, atomicity."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.outputs.writer import write
from chewbot.run.pipeline import compute
from chewbot.run.options import RunOptions
from chewbot.table import Table

COORDS = ("X", "Y", "Z", "alpha", "beta", "gamma")
ISSUE_COLUMNS = (
    ["t"] + list(COORDS) + ["d" + c for c in COORDS] + ["dd" + c for c in COORDS]
    + [f"{p}theta{i}" for p in ("", "d", "dd") for i in range(1, 7)] + ["Fx", "Fy", "Fz"]
)
SINGULARITY_COLUMNS = [f"mu{i}" for i in range(1, 7)] + ["kappa_J"]  # transmission angles, conditioning


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    result = compute(RunOptions(model="target", method=None))
    out = write(result, tmp_path_factory.mktemp("runs") / "left")
    return result, out


def test_results_csv_has_the_issue_columns_with_units_and_exact_numbers(run_folder):
    result, out = run_folder
    text = (out / "results.csv").read_text()
    header = text.split("\n", 1)[0].split(",")
    assert header == [f"{name} [{result.table.units[name]}]" for name in ISSUE_COLUMNS + SINGULARITY_COLUMNS]
    assert header[:2] == ["t [s]", "X [m]"] and "ddalpha [rad/s^2]" in header
    assert not re.search(r"(^|,)-0\.0(,|$)", text, re.MULTILINE)  # a signed zero reads as a sign a person looks for
    assert re.search(r"(^|,)0\.0(,|$)", text, re.MULTILINE)  # the zeros are there (the rest at t = 0), unsigned
    back = Table.read_csv(out / "results.csv")
    for name in ISSUE_COLUMNS + SINGULARITY_COLUMNS:
        assert np.array_equal(back[name], result.table[name]), name  # bit-exact round trip
        assert back.units[name] == result.table.units[name]
    assert back.n == 5001


def test_run_json_records_model_options_versions_and_units(run_folder):
    result, out = run_folder
    info = json.loads((out / "run.json").read_text())
    assert info["model"]["file"].endswith("target.toml") and len(info["model"]["sha256"]) == 64
    assert info["options"]["model"] == "target" and info["options"]["side"] == "left"
    assert {"python", "numpy", "scipy", "casadi"} <= set(info["versions"])
    units = {name: c["unit"] for name, c in info["columns"].items()}
    assert set(units) == set(ISSUE_COLUMNS + SINGULARITY_COLUMNS)
    assert units["t"] == "s" and units["X"] == "m" and units["dalpha"] == "rad/s" and units["ddZ"] == "m/s^2"
    assert units["ddtheta3"] == "rad/s^2" and units["Fz"] == "N"


def test_figures_exist(run_folder):
    _, out = run_folder
    pngs = sorted(out.glob("*.png"))
    assert pngs and all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)


def _cli(args):
    return CliRunner().invoke(app, ["run", "--quiet", *args])


@pytest.mark.parametrize(
    "args, message",
    [
        (["--task", "absent.csv"], "no such file (expected a target task)"),
        (["--model", "absent.toml"], "no such parameter file"),
    ],
)
def test_cli_bad_input_leaves_no_folder(tmp_path, args, message):
    out = tmp_path / "run"
    res = _cli([*args, "--out", str(out)])
    assert res.exit_code != 0 and message in res.output
    assert list(tmp_path.iterdir()) == []  # neither the folder nor a partial one


def test_cli_condyle_outside_socket_leaves_no_folder(tmp_path):
    csv = tmp_path / "out_of_socket.csv"
    csv.write_text("t,X[mm],Y,alpha,beta\n" + "\n".join(f"{i / 1000!r},8,0,0,0" for i in range(10)) + "\n")
    out = tmp_path / "run"
    res = _cli(["--task", str(csv), "--out", str(out)])
    assert res.exit_code != 0 and "condyle leaves its socket" in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out_of_socket.csv"]


def test_cli_refuses_an_existing_folder_without_force(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    res = _cli(["--out", str(out)])
    assert res.exit_code != 0 and "--force" in res.output
    assert [p.name for p in out.iterdir()] == ["keep.txt"]
