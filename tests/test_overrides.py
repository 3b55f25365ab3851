"""--set KEY=VALUE: a model with overrides equals the file edited by hand, each consistency rule holds, and each
bad override is an error naming its argument."""

from __future__ import annotations

import json
import math
import re

import casadi as ca
import numpy as np
import pytest
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.commands.common import EXIT_BAD_INPUT
from chewbot.dynamics.registry import inverse_dynamics
from chewbot.errors import ParameterError, TaskError
from chewbot.kinematics.motion import solve_kinematics
from chewbot.model.vector import vector_digest
from chewbot.model.params import apply_overrides, builtin_model_path, load_model, parse_override, read_parameter_file
from chewbot.report.summary import home_pose
from chewbot.task.default import ChewingParameters, default_task, parameters_with

runner = CliRunner()

SHORT = ChewingParameters(cycles=1, rest_s=0.1)  # one chewing cycle: 901 samples


def _torques(m):
    return inverse_dynamics(m, solve_kinematics(m, default_task(m, "left", SHORT)), "hessian").tau


def test_overrides_equal_the_file_edited_by_hand(tmp_path):
    """The same numbers written into a copy of the file (with the values that follow from them computed here:
    S0_3 moved along its crank (the first column of the loaded R_C0,3) to 12 mm, the coupler length |M_3 - S0_3|,
    the condyles' z on the plane) give the same parameter vector and the same torques: the same inputs through the
    same code, so exactly equal."""
    overrides = {"friction.hkp_coulomb": 0.2, "couplers.density_g_per_mm3": 2.7e-3, "chains.crank_length_mm[3]": 12.0,
                 "hkp.T_L_mm[1]": -3.0, "limits.theta_range_deg[1]": -80.0, "contact.preload_N": 1.5}
    base = load_model("target")
    G, M = (np.array(read_parameter_file(builtin_model_path("target"))["chains"][k][2]) for k in ("G_mm", "M_mm"))
    S0_new = G + 12.0 * base.R_C0[2][:, 0]
    z = -(1.1 * -3.0 + -13.215)
    text = builtin_model_path("target").read_text()
    for old, new in (
        ("hkp_coulomb = 0.1 ", "hkp_coulomb = 0.2 "),
        ("density_g_per_mm3 = 7.8e-3", "density_g_per_mm3 = 2.7e-3"),
        ("crank_length_mm = [10.0, 10.0, 15.0,", "crank_length_mm = [10.0, 10.0, 12.0,"),
        ("coupler_length_mm = [33.0, 33.0, 33.0,", f"coupler_length_mm = [33.0, 33.0, {float(np.linalg.norm(M - S0_new))!r},"),
        ("  [54.11, -59.47, -30.91],", f"  [{float(S0_new[0])!r}, {float(S0_new[1])!r}, {float(S0_new[2])!r}],"),
        ("T_L_mm = [-2.5, 72.0, 15.965]", f"T_L_mm = [-3.0, 72.0, {z!r}]"),
        ("T_R_mm = [-2.5, -72.0, 15.965]", f"T_R_mm = [-3.0, -72.0, {z!r}]"),
        ("radial_load_N = 250.0    # assumed\n", "radial_load_N = 250.0    # assumed\ntheta_range_deg = [-80.0, inf]\n"),
        ("unilateral (docs/contact.md).\n", "unilateral (docs/contact.md).\n\n[contact]\npreload_N = 1.5\n"),
    ):
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / "edited.toml"
    path.write_text(text)
    by_hand, by_set = load_model(path), load_model("target", overrides)
    assert np.array_equal(by_hand.vector(), by_set.vector())
    assert not np.array_equal(base.vector(), by_set.vector())
    assert by_set.overrides == overrides and by_hand.overrides == {}
    assert np.array_equal(_torques(by_hand), _torques(by_set))


def _home_theta(m) -> np.ndarray:
    return home_pose(m)["theta"]


def _shaft(m, i):
    return m.R_C0[i][:, 2]


@pytest.mark.parametrize("key, delta, chain", [("G_mm", [0.0, 0.0, 1.0], 0),  # along chain 1's vertical shaft
                                               ("G_mm", [1.0, 0.5, 0.0], 2),  # partly along chain 3's inclined shaft
                                               ("S0_mm", [0.5, 0.0, -0.5], 4)])
def test_moving_a_crank_point_keeps_the_crank_across_its_shaft(key, delta, chain):
    """G_i or S0_i moved: the shaft's direction is kept, the other point follows along the shaft so that the crank
    stays perpendicular to it, the lengths and R_C0,i follow, and the chain closes exactly at home (theta_i = 0)."""
    raw = read_parameter_file(builtin_model_path("target"))
    old = np.array(raw["chains"][key][chain])
    overrides = {f"chains.{key}[{chain + 1}][{k + 1}]": float(old[k] + d) for k, d in enumerate(delta)}
    base, m = load_model("target"), load_model("target", overrides)
    z = _shaft(base, chain)
    assert np.abs(_shaft(m, chain) - z).max() < 1e-15
    arm = m.S0[chain] - m.G[chain]
    assert abs(arm @ z) < 1e-15 and np.abs(m.R_C0[chain][:, 0] - arm / np.linalg.norm(arm)).max() < 1e-15
    assert m.crank_length[chain] == pytest.approx(np.linalg.norm(arm), rel=1e-15)
    assert m.coupler_length[chain] == pytest.approx(np.linalg.norm(m.M[chain] - m.S0[chain]), rel=1e-15)
    moved = (m.S0 - base.S0) if key == "G_mm" else (m.G - base.G)  # the point that follows
    # it follows along the shaft by the shift's component there (and the printed coordinates' ~1 um off the crank's
    # plane is dropped from S0)
    assert np.abs(moved[chain] - (np.asarray(delta) * 1e-3 @ z) * z).max() < 3e-6
    assert abs(_home_theta(m)[chain]) < 1e-12
    others = [i for i in range(6) if i != chain]
    for attr in ("G", "S0", "M", "R_C0", "crank_length", "coupler_length"):  # the other chains are untouched
        assert np.array_equal(getattr(m, attr)[others], getattr(base, attr)[others]), attr


def test_moving_a_coupler_end_recomputes_its_length():
    m = load_model("target", {"chains.M_mm[5][3]": 1.0})
    assert m.M[4, 2] == pytest.approx(1e-3) and m.coupler_length[4] == pytest.approx(np.linalg.norm(m.M[4] - m.S0[4]), rel=1e-15)
    assert abs(_home_theta(m)[4]) < 1e-12


def test_crank_length_moves_the_crank_tip_along_the_crank():
    base, m = load_model("target"), load_model("target", {"chains.crank_length_mm[3]": 12.0})
    assert np.linalg.norm(m.S0[2] - m.G[2]) == pytest.approx(0.012, rel=1e-15)
    assert np.abs((m.S0[2] - m.G[2]) / 0.012 - base.R_C0[2][:, 0]).max() < 1e-15 and np.array_equal(m.R_C0, base.R_C0)
    assert m.coupler_length[2] == pytest.approx(np.linalg.norm(m.M[2] - m.S0[2]), rel=1e-15)
    assert abs(_home_theta(m)[2]) < 1e-12


def test_coupler_length_moves_the_coupler_end_along_the_coupler():
    base, m = load_model("target"), load_model("target", {"chains.coupler_length_mm[6]": 50.0})
    assert np.linalg.norm(m.M[5] - m.S0[5]) == pytest.approx(0.05, rel=1e-15)
    u = lambda x: (x.M[5] - x.S0[5]) / np.linalg.norm(x.M[5] - x.S0[5])  # noqa: E731
    assert np.abs(u(m) - u(base)).max() < 1e-4  # along the coupler from the crank tip of R_C0 (printed S0: 4 digits)
    assert abs(_home_theta(m)[5]) < 1e-12
    assert m.coupler_mass[5] == pytest.approx(base.coupler_mass[5] * 50 / 52, rel=1e-12)  # rho A L follows


def test_condyles_mirror_and_stay_on_their_plane():
    m = load_model("target", {"hkp.T_L_mm[1]": -3.0})
    assert m.hkp.T_R.tolist() == [m.hkp.T_L[0], -m.hkp.T_L[1], m.hkp.T_L[2]]
    for T in (m.hkp.T_L, m.hkp.T_R):
        assert m.hkp.p1 * T[0] + T[2] + m.hkp.p2 == pytest.approx(0, abs=1e-15)
    tilted = load_model("target", {"hkp.p1": 1.0})  # the plane turns: the condyles' z follows
    assert tilted.hkp.p1 * tilted.hkp.T_L[0] + tilted.hkp.T_L[2] + tilted.hkp.p2 == pytest.approx(0, abs=1e-15)
    raised = load_model("target", {"hkp.T_L_mm[3]": 17.0})  # the condyle's z given: the plane (p2) follows
    assert raised.hkp.T_R[2] == pytest.approx(0.017) and raised.hkp.p2 == pytest.approx(-(1.1 * -2.5e-3 + 0.017), rel=1e-12)


def test_other_derived_values():
    base = load_model("target")
    light = load_model("target", {"couplers.density_g_per_mm3": 2.7e-3})
    assert np.allclose(light.coupler_mass, base.coupler_mass * 2.7 / 7.8, rtol=1e-14)
    sym = load_model("target", {"mandible.inertia_g_mm2[1][3]": -1.0e5})
    assert sym.mandible_inertia[0, 2] == sym.mandible_inertia[2, 0] == pytest.approx(-1e-4)
    assert np.array_equal(load_model("target", {"cranks.inertia_g_mm2[1]": 4000.0}).crank_mass, base.crank_mass)  # a key of its own
    bounded = load_model("target", {"limits.theta_range_deg[2]": 80.0, "limits.speed_rad_per_s": 12.0})
    assert bounded.limits.theta_range[0] == -math.inf and bounded.limits.theta_range[1] == pytest.approx(np.radians(80))
    assert bounded.limits.speed == 12.0 and base.limits.speed == 17.0


def test_applying_overrides_builds_no_graph(monkeypatch):
    """A sweep applies overrides to thousands of parameter sets: loading and the vector are NumPy only."""
    raw = read_parameter_file(builtin_model_path("target"))
    monkeypatch.setattr(ca.SX, "sym", lambda *a, **k: (_ for _ in ()).throw(AssertionError("a graph was built")))
    from chewbot.model.params import model_from_dict

    m = model_from_dict(apply_overrides(raw, {"chains.crank_length_mm[3]": 12.5}), source="target.toml")
    assert m.vector()[0] == 9.8


@pytest.mark.parametrize("overrides, match", [
    ({"friction.hkp_colomb": 0.2}, r"--set friction.hkp_colomb=0.2: unknown key 'friction.hkp_colomb'; did you mean 'friction.hkp_coulomb'"),
    ({"chains.crank_length_mm[9]": 12.0}, r"--set chains.crank_length_mm\[9\]=12: index 9 of chains.crank_length_mm is out of range"),
    ({"chains.G_mm[2]": 1.0}, r"--set chains.G_mm\[2\]=1: chains.G_mm is an array of shape 6x3: give 2 index"),
    ({"friction.hkp_coulomb[1]": 1.0}, r"friction.hkp_coulomb is a number: give 0 index"),
    ({"name": 1.0}, r"--set name=1: unknown key 'name'"),
    ({"hkp.T_R_mm[1]": -3.0}, r"hkp.T_R_mm mirrors hkp.T_L_mm"),
    ({"chains.crank_length_mm[3]": -2.0}, r"\(with --set chains.crank_length_mm\[3\]=-2\): key 'chains.crank_length_mm\[3\]': must be greater than 0, not -2.0"),
    ({"mandible.mass_g": float("nan")}, r"key 'mandible.mass_g'"),
    ({"limits.theta_range_deg[1]": 100.0, "limits.theta_range_deg[2]": 90.0}, r"key 'limits.theta_range_deg'.*not an interval"),
    ({"contact.preload_N": -1.0}, r"key 'contact.preload_N': must be at least 0, not -1.0"),
])
def test_bad_override_names_its_argument_and_key(overrides, match):
    with pytest.raises(ParameterError, match=match):
        load_model("target", overrides)


def test_parse_override():
    assert parse_override("chains.G_mm[2][1] = 24") == ("chains.G_mm[2][1]", 24.0)
    for bad, match in (("friction.hkp_coulomb", "expected KEY=VALUE"), ("=3", "expected KEY=VALUE"),
                       ("friction.hkp_coulomb=high", "'high' is not a number")):
        with pytest.raises(ParameterError, match=match):
            parse_override(bad)


def test_task_overrides():
    task = default_task(None, "left", parameters_with({"force_z_N": -100.0, "cycles": 2}))
    assert task.force[:, 2].min() == pytest.approx(-100.0) and task.t[-1] == pytest.approx(2.6)
    for bad, match in (({"forcez_N": 1.0}, "did you mean 'task.force_z_N'"), ({"force_z_kN": 1.0}, "the unit is part of the key, and force_z is given in N, not kN: 'task.force_z_N'"), ({"cycles": 2.5}, "whole number"),
                       ({"period_s": -1.0}, r"--set task.period_s=-1: default task: period_s must be positive")):
        with pytest.raises(TaskError, match=match):
            parameters_with(bad)


def test_run_records_the_overrides(tmp_path):
    """chewbot run --set writes run.json with the overrides as given and the SHA-256 of the resulting p; a bad
    override exits 2 naming the argument, an override of the default task with a CSV task too."""
    runner = CliRunner()
    args = ["--set", "chains.crank_length_mm[3]=12", "--set", "task.force_z_N=-100", "--set", "task.cycles=1"]
    result = runner.invoke(app, ["run", "--out", str(tmp_path / "run"), "-q", *args])
    assert result.exit_code == 0, result.output
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["overrides"] == {"chains.crank_length_mm[3]": 12.0, "task.force_z_N": -100.0, "task.cycles": 1.0}
    assert run["model"]["parameters_sha256"] == vector_digest(load_model("target", {"chains.crank_length_mm[3]": 12.0}))
    assert run["task"]["meta"]["parameters"]["force_z_N"] == -100.0
    bad = runner.invoke(app, ["run", "--out", str(tmp_path / "bad"), "--set", "chains.crank_length_mm[7]=12"])
    assert bad.exit_code == EXIT_BAD_INPUT and "--set chains.crank_length_mm[7]=12" in bad.output
    csv = tmp_path / "run" / "results.csv"
    bad = runner.invoke(app, ["run", "--out", str(tmp_path / "bad"), "--task", str(csv), "--set", "task.force_z_N=-1"])
    assert bad.exit_code == EXIT_BAD_INPUT and "apply to --task default" in bad.output
    assert not (tmp_path / "bad").exists()
    check = runner.invoke(app, ["check-model", "target", "--set", "friction.hkp_coulomb=0.3"], env={"COLUMNS": "250"})
    assert check.exit_code == 0 and "friction.hkp_coulomb = 0.3" in check.output


# --- nothing silently ignored ------------------------------------------------------------------------------------


@pytest.mark.parametrize("argument", ["task.force_z_N=nan", "task.force_z_N=inf", "friction.hkp_coulomb=-inf",
                                      "chains.crank_length_mm[3]=NaN"])
def test_a_value_that_is_not_finite_is_refused_naming_it(argument):
    with pytest.raises(ParameterError, match=rf"--set {re.escape(argument)}: .* is not a finite number"):
        parse_override(argument)
    result = runner.invoke(app, ["run", "--set", argument, "--out", "unused"])
    assert result.exit_code == EXIT_BAD_INPUT and "not a finite number" in result.output and "Traceback" not in result.output


def test_nan_in_a_parameter_file_is_refused_naming_the_key(tmp_path):
    path = tmp_path / "nan.toml"
    path.write_text(builtin_model_path("target").read_text().replace("[limits]", "[limits]\ntheta_range_deg = [nan, 90.0]", 1))
    with pytest.raises(ParameterError, match=r"nan.toml: key 'limits.theta_range_deg\[1\]': must be a number or \+/-inf, not nan"):
        load_model(path)


@pytest.mark.parametrize("args, words", [
    (["--set", "friction.hkp_coulomb=0.2"], "--set friction.hkp_coulomb=0.2 changes nothing: the friction coefficients are used by the newton-euler method"),
    (["--method", "newton-euler", "--friction", "off", "--set", "friction.actuator_coulomb=0.1"], "this run has --friction off"),
    (["--set", "contact.preload_N=2"], "--set contact.preload_N=2 changes nothing: the preload is the smallest normal force of the unilateral contact"),
])
def test_an_override_the_run_does_not_use_is_refused_naming_what_uses_it(args, words, tmp_path):
    """The README's old example (friction with the default, frictionless method) changed nothing; now it is exit 2."""
    result = runner.invoke(app, ["run", *args, "--out", str(tmp_path / "x")], env={"COLUMNS": "300"})
    assert result.exit_code == EXIT_BAD_INPUT and words in result.output, result.output
    assert not (tmp_path / "x").exists()


def test_where_friction_is_used_the_override_changes_the_torques():
    """The other side of the rule: with newton-euler and friction on, friction.hkp_coulomb changes tau."""
    from chewbot.run.options import resolve
    from chewbot.run.pipeline import compute

    base = compute(resolve(method="newton-euler", overrides={"task.cycles": 1, "task.rest_s": 0.1}))
    more = compute(resolve(method="newton-euler", overrides={"task.cycles": 1, "task.rest_s": 0.1, "friction.hkp_coulomb": 0.3}))
    assert np.abs(more.table["tau1"] - base.table["tau1"]).max() > 1e-4


@pytest.mark.parametrize("args, words", [
    (["--controller", "pd", "--method", "liang"], "--method applies to the model-based controllers"),
    (["--controller", "pd", "--bite-unknown"], "--bite-unknown applies to the model-based controllers"),
    (["--controller", "pd", "--gain", "computed_torque.damping=0.7"], "it is a gain of --controller computed-torque"),
    (["--gain", "estimator.cutoff_Hz=100"], "the estimator runs only with sensor noise"),
    (["--set", "friction.hkp_coulomb=0.2"], "used by the plant with --friction on"),
    (["--gain", "pd.kp_Nm_per_rad=nan"], "--gain pd.kp_Nm_per_rad=nan: 'nan' is not a finite number"),
])
def test_simulate_refuses_what_its_controllers_do_not_use(args, words, tmp_path):
    result = runner.invoke(app, ["simulate", *args, "--out", str(tmp_path / "x")], env={"COLUMNS": "300"})
    assert result.exit_code == EXIT_BAD_INPUT and words in result.output, result.output


def test_the_run_summary_names_the_method_it_used(tmp_path):
    """--orientation euler-parameters switches the default method to newton-euler (with friction and its goal): the
    summary says so."""
    result = runner.invoke(app, ["run", "--orientation", "euler-parameters", "--set", "task.cycles=1", "--set", "task.rest_s=0.1",
                                 "--no-figures", "--no-report", "--out", str(tmp_path / "ep")], env={"COLUMNS": "300"})
    assert result.exit_code == 0, result.output
    assert "used: method newton-euler (euler-parameters), goal min-torque, friction on, contact bilateral" in result.output
