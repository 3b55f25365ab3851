"""chewbot identify: friction and inertia from robot logs (docs/identification.md).

The logs are made here by chewbot's own inverse dynamics (Newton-Euler with friction, the G1 distribution) on a
model whose friction and inertia differ from the start model's; the identification starts from the unchanged
model and must find the changed values.
"""

from __future__ import annotations

import functools
import json
import re

import numpy as np
import pytest
import tomllib
from typer.testing import CliRunner

from chewbot import load_model
from chewbot.cli import app
from chewbot.dynamics.registry import inverse_dynamics
from chewbot.errors import ChewbotError, TaskError
from chewbot.identification.identifier import identify
from chewbot.identification.log import read_log
from chewbot.identification.parameters import DRIVE, INERTIA, N_X, NAMES, phi_of, x_of, x_of_phi
from chewbot.kinematics.motion import solve_kinematics
from chewbot.run.pipeline import compute
from chewbot.run.options import RunOptions
from chewbot.task.default import ChewingParameters, default_task

runner = CliRunner()

# The robot the logs come from: every identified group changed from the built-in target's values (friction by
# 30-60 %, the mass by 12 %, two principal moments by 6-10 %).
TRUE = {"friction.hkp_coulomb": 0.15, "friction.hkp_viscous_Ns_per_m": 0.8, "friction.actuator_coulomb": 0.07,
        "friction.actuator_viscous_Nms_per_rad": 0.015, "mandible.mass_g": 380.0,
        "mandible.inertia_g_mm2[1][1]": 900000.0, "mandible.inertia_g_mm2[2][2]": 450000.0}
# The true mass differs from the file's: these logs identify it (the file's is otherwise the given, weighed one).
FREE = ("mandible.mass_g",)
ANGLES = [f"theta{i}" for i in range(1, 7)]
TORQUES = [f"tau{i}" for i in range(1, 7)]


@functools.cache
def robot(name: str = "target", rate_hz: float = 250.0, cycles: int = 1, **motion):
    """The true model and its kinematics and torques along the default chewing motion (no rest: every crank
    turns nearly all the time; ``motion``: other ChewingParameters)."""
    m = load_model(name, TRUE if name == "target" else {k: v for k, v in TRUE.items() if "hkp" not in k})
    task = default_task(m, "left", ChewingParameters(cycles=cycles, rest_s=0.0, rate_hz=rate_hz, **motion))
    kin = solve_kinematics(m, task, "euler-angles")
    return m, kin, inverse_dynamics(m, kin, "newton-euler", friction=True).tau


def write_log(path, kin, tau, theta=None, rates=True, degrees=False):
    """A log CSV: t, the angles (rad or deg), optionally the exact rates, the torques, the bite force."""
    theta = kin.theta if theta is None else theta
    unit = "[deg]" if degrees else ""
    f = np.degrees if degrees else (lambda a: a)
    cols, data = ["t"] + [a + unit for a in ANGLES], [kin.t, f(theta)]
    if rates:
        cols += [f"d{a}{unit and '[deg/s]'}" for a in ANGLES] + [f"dd{a}{unit and '[deg/s^2]'}" for a in ANGLES]
        data += [f(kin.dtheta), f(kin.ddtheta)]
    cols += TORQUES + ["Fx", "Fy", "Fz"]
    data += [tau, kin.force]
    np.savetxt(path, np.column_stack(data), delimiter=",", header=",".join(cols), comments="", fmt="%.17g")
    return path


PROGRESS: list[str] = []  # the messages of exact_identification's progress


@functools.cache
def exact_identification(tmp):
    m, kin, tau = robot()
    return identify(load_model("target"), read_log(write_log(tmp / "exact.csv", kin, tau, degrees=True)),
                    progress=lambda msg, done=None, total=None, stage=None: PROGRESS.append(msg), free=FREE)


def test_the_least_squares_report_each_evaluation_with_its_cost(tmp_path_factory):
    """The progress callable is told every evaluation of the residual with the cost 1/2 sum r^2, which the solver
    drives down: the last reported cost is the fit's own (SciPy's ``cost``) and far below the first."""
    result = exact_identification(tmp_path_factory.mktemp("exact"))
    costs = [float(re.search(r"evaluation \d+, cost (\S+) \(N\*m\)\^2", m).group(1)) for m in PROGRESS if "evaluation" in m]
    assert len(costs) >= 3 and costs[-1] < 1e-3 * costs[0]
    assert costs[-1] == pytest.approx(result.fit.solver.cost, rel=1e-5, abs=1e-20)  # printed to 6 digits


def test_a_noise_free_log_with_exact_rates_gives_back_the_true_parameters(tmp_path_factory):
    result = exact_identification(tmp_path_factory.mktemp("exact"))
    truth = x_of(robot()[0])
    # everything but the drive's numbers, which a log of torques does not show
    assert {NAMES[j]: s for j, s in enumerate(result.status) if s != "estimated"} == {"k_t": "not in the log", "eta": "not in the log"}
    # Tolerance: the log's values are the true model's to 17 digits and its rates exact, so the residual vanishes
    # at the truth up to rounding (torques ~0.3 N*m, rounding ~1e-16 relative); the least-squares stops at
    # relative steps of 1e-10 and the condition number is ~1e2: 1e-7 relative to each parameter's reference
    # magnitude is far above what remains and far below any error a wrong model would leave (percent).
    ref = np.abs(truth)
    ref[INERTIA] = np.trace(robot()[0].mandible_inertia) / 3
    np.testing.assert_array_less(np.abs(result.x - truth) / ref, 1e-7)
    assert np.sqrt(np.mean(result.fit.evaluation.r ** 2)) < 1e-12  # N*m: rounding, not model error
    assert 1 < result.fit.condition < 1e4
    # the start model was off: its residual is ~1e-2 N*m, ten orders of magnitude more
    assert result.rms("start").min() > 1e-3


@pytest.mark.parametrize("seed", [0])
def test_with_noise_the_estimates_are_within_their_standard_errors(tmp_path, seed):
    m, kin, tau = robot(rate_hz=250.0, cycles=2)
    rng = np.random.default_rng(seed)
    # Noise of a real robot: torque sensing 2 mN*m (1 % of the torques' RMS), encoders 2e-5 rad (~18 bit).
    sigma_tau, sigma_theta = 2e-3, 2e-5
    theta = kin.theta + sigma_theta * rng.standard_normal(kin.theta.shape)
    noisy = tau + sigma_tau * rng.standard_normal(tau.shape)
    result = identify(load_model("target"), read_log(write_log(tmp_path / "noisy.csv", kin, noisy, theta, rates=False)), free=FREE)
    truth = x_of(m)
    est = np.array([s.startswith("estimated") for s in result.status])
    # At this noise the friction and the mass are identified; the mandible's inertia's torques (~1e-2 N*m along this
    # motion) and the HKP viscous force's (tangential speeds of mm/s) are too small: both are held with their reason.
    # The cranks' inertia torques are at most a few mN*m on this motion: the heaviest cranks' may pass the test of
    # --max-relative-se, the others are held.
    named = [NAMES[j] for j in np.flatnonzero(est)]
    assert [n for n in named if not n.startswith("J_")] == ["m", "mu_H", "R*mu_c", "c_A"], result.status
    assert set(n for n in named if n.startswith("J_")) <= {"J_3", "J_4", "J_5", "J_6"}, named
    drive = np.isin(np.arange(N_X), DRIVE)
    assert all(result.status[j] == "held" and j in result.fit.reasons for j in np.flatnonzero(~est & ~drive))
    assert all(result.status[j] == "not in the log" for j in DRIVE)
    np.testing.assert_array_equal(result.x[~est], x_of(load_model("target"))[~est])  # held at the start
    z = np.abs(result.x - truth)[est] / result.se[est]
    # Tolerance: 4 standard errors. For one parameter a normal error exceeds that with probability 6e-5, so with
    # at most 11 parameters a correct estimator and correct standard errors pass with probability > 0.999 (the
    # seed is fixed: the test is deterministic); too small standard errors (a factor 4) or a bias of that size fail.
    assert z.max() < 4.0, dict(zip(np.array(NAMES)[est], z))
    # the residual is the noise: RMS within 10 % of sigma_tau (the rates' smoothing error is ~1e-6 N*m, the
    # angle noise's share of the torques below 1e-4 N*m; 10 % is 3 times the sampling spread of an RMS over
    # ~2400 residual rows, sqrt(1/(2*2400)) = 1.4 %, plus the share the fitted normal forces absorb)
    rms = np.sqrt(np.mean(result.fit.evaluation.r[result.fit.used] ** 2))
    assert 0.8 * sigma_tau < rms < 1.1 * sigma_tau
    # the standard errors follow from the noise: the friction coefficients are known to a few percent at most
    for name in ("mu_H", "R*mu_c", "c_A"):
        j = NAMES.index(name)
        assert result.se[j] < 0.05 * truth[j]


def test_the_physical_parametrisation_and_its_jacobian():
    x = x_of(load_model("target"))
    phi = phi_of(x)
    back, J = x_of_phi(phi)
    np.testing.assert_allclose(back, x, rtol=1e-12, atol=1e-12 * np.abs(x).max())  # rounding of a Cholesky
    # Jacobian against central differences; step 1e-6 relative, truncation O(h^2) is zero (x is quadratic in
    # phi) so only rounding remains: ~1e-16 / 1e-6 = 1e-10 relative
    h = 1e-6 * np.maximum(np.abs(phi), 1e-3)
    fd = np.column_stack([(x_of_phi(phi + h[k] * e)[0] - x_of_phi(phi - h[k] * e)[0]) / (2 * h[k])
                          for k, e in enumerate(np.eye(N_X))])
    np.testing.assert_allclose(J, fd, rtol=1e-7, atol=1e-9 * np.abs(J).max())
    # every phi within the bounds is a physical body: random L factors give positive-definite inertias that
    # satisfy the triangle inequality
    rng = np.random.default_rng(1)
    for _ in range(20):
        p = phi.copy()
        p[1:7] = rng.standard_normal(6) * np.abs(phi[1:7]).max()
        p[[1, 3, 6]] = np.abs(p[[1, 3, 6]]) + 1e-6
        xx = x_of_phi(p)[0]
        I = np.array([[xx[1], xx[4], xx[5]], [xx[4], xx[2], xx[6]], [xx[5], xx[6], xx[3]]])
        w = np.linalg.eigvalsh(I)
        assert w.min() > 0 and w[0] + w[1] > w[2]


def test_a_log_that_does_not_excite_the_inertia_reports_it_and_keeps_the_files_values(tmp_path):
    # A motion without rotation (alpha = beta = 0 and so gamma = 0: pure translation) puts no torque on the
    # inertia: its six entries cannot be identified. They are reported one by one and kept; the rest is found.
    m, _, _ = robot()
    task = default_task(m, "left", ChewingParameters(cycles=1, rest_s=0.0, rate_hz=250.0, alpha_deg=0.0, beta_deg=0.0))
    kin = solve_kinematics(m, task, "euler-angles")
    assert np.abs(kin.X[:, 3:]).max() < 1e-12
    tau = inverse_dynamics(m, kin, "newton-euler", friction=True).tau
    start = load_model("target")
    result = identify(start, read_log(write_log(tmp_path / "translation.csv", kin, tau)), free=FREE)
    inertia = [NAMES[j] for j in range(N_X)][INERTIA]
    assert [result.status[j] for j in range(N_X)][INERTIA] == ["held"] * 6
    assert sorted(name for d in result.held_directions for name in d) == sorted(inertia)
    assert all(len(d) == 1 for d in result.held_directions)
    assert result.fit.condition == np.inf
    np.testing.assert_array_equal(result.x[INERTIA], x_of(start)[INERTIA])
    assert "mandible.inertia_g_mm2" not in result.identified
    est = [j for j in range(N_X) if result.status[j] == "estimated"]
    assert [NAMES[j] for j in est] == ["m", "J_1", "J_2", "J_3", "J_4", "J_5", "J_6", "mu_H", "c_H", "R*mu_c", "c_A"]
    np.testing.assert_allclose(result.x[est], x_of(m)[est], rtol=1e-7)  # as in the noise-free test
    assert any("not identifiable" in line and "I_xx" in line for line in result.summary())


def test_bad_logs_get_errors_naming_file_line_and_column(tmp_path):
    m, kin, tau = robot()
    good = write_log(tmp_path / "good.csv", kin, tau, rates=False)
    lines = good.read_text().splitlines()

    def bad(name, text):
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(ChewbotError) as info:
            identify(load_model("target"), read_log(path))
        return str(info.value)

    header = lines[0].split(",")
    msg = bad("missing.csv", "\n".join(",".join(r.split(",")[:-4] + r.split(",")[-3:]) for r in lines) + "\n")
    assert "missing.csv" in msg and "tau6" in msg
    row = lines[5].split(",")
    row[header.index("tau3")] = "abc"
    msg = bad("text.csv", "\n".join(lines[:5] + [",".join(row)] + lines[6:]) + "\n")
    assert "text.csv" in msg and "line 6" in msg and "tau3" in msg
    row = lines[8].split(",")
    row[header.index("t")] = lines[7].split(",")[0]
    msg = bad("time.csv", "\n".join(lines[:8] + [",".join(row)] + lines[9:]) + "\n")
    assert "time.csv" in msg and "line 9" in msg and "t" in msg
    # a crank angle off by 0.1 rad: no pose of the model fits it
    row = lines[20].split(",")
    row[header.index("theta4")] = repr(float(row[header.index("theta4")]) + 0.1)
    msg = bad("offset.csv", "\n".join(lines[:20] + [",".join(row)] + lines[21:]) + "\n")
    assert "offset.csv" in msg and "line 21" in msg and "theta4" in msg
    # some rates but not all
    msg = bad("rates.csv", "\n".join([lines[0] + ",dtheta1"] + [r + ",0" for r in lines[1:]]) + "\n")
    assert "rates.csv" in msg and "dtheta2" in msg
    with pytest.raises(TaskError, match=r"unknown unit|unit"):
        read_log(tmp_path / "unit.csv") if (tmp_path / "unit.csv").write_text(
            lines[0].replace("tau1", "tau1[furlong]") + "\n" + "\n".join(lines[1:]) + "\n") else None


def test_the_command_writes_a_model_that_check_model_and_run_accept(tmp_path):
    m, kin, tau = robot()
    log = write_log(tmp_path / "log.csv", kin, tau)
    out = tmp_path / "identified.toml"
    r = runner.invoke(app, ["identify", str(log), "--model", "target", "--out", str(out), "--free", "mandible.mass_g"])
    assert r.exit_code == 0, r.output
    text = out.read_text()
    assert text.startswith("# written by chewbot")
    data = tomllib.loads(text)
    assert set(data["identified"]) >= {"friction.hkp_coulomb", "friction.actuator_coulomb", "mandible.mass_g"}
    assert not set(data["identified"]) & set(data["assumed"])
    assert data["friction"]["actuator_arm_mm"] == 5.0  # R as in the file; mu_c carries the product
    # the identified values are the true ones (noise-free log, exact rates; tolerance as in the API test)
    assert data["friction"]["actuator_coulomb"] == pytest.approx(0.07, rel=1e-7)
    assert data["mandible"]["mass_g"] == pytest.approx(380.0, rel=1e-7)
    table = (tmp_path / "identified.identification.csv").read_text()
    assert table.startswith("parameter,key,") and "standard_error" in table  # plain CSV: the marker and summary in its sidecar
    side = json.loads((tmp_path / "identified.identification.csv.chewbot.json").read_text())
    assert side["chewbot_file"] == 1 and side["about"].startswith("estimates of chewbot identify") and side["summary"]
    assert "condition number" in r.output
    r = runner.invoke(app, ["check-model", str(out)])
    assert r.exit_code == 0, r.output
    # the model runs (chewbot run's own computation, in memory), and its torques are the true model's: the same
    # tolerance as the parameters (the torques are linear in most of them, and the least squares fitted them)
    identified = load_model(str(out))
    np.testing.assert_allclose(x_of(identified), x_of(robot()[0]), rtol=1e-7, atol=1e-7 * np.abs(x_of(robot()[0])).max())
    task = {"task.cycles": 1, "task.rest_s": 0.2}
    ran = compute(RunOptions(model=str(out), method="newton-euler", overrides=task))
    true = compute(RunOptions(model="target", method="newton-euler", overrides={**TRUE, **task}))
    assert ran.model.identified == tuple(data["identified"])
    tau = [f"tau{i}" for i in range(1, 7)]
    np.testing.assert_allclose(np.column_stack([ran.table[c] for c in tau]), np.column_stack([true.table[c] for c in tau]),
                               rtol=1e-6, atol=1e-6 * np.abs(true.table["tau1"]).max())
    # an existing output: refused without --force (exit 5), replaced with it; a user's file never
    r = runner.invoke(app, ["identify", str(log), "--out", str(out)])
    assert r.exit_code == 5 and out.read_text() == text
    user = tmp_path / "mine.toml"
    user.write_text("# my model\n")
    r = runner.invoke(app, ["identify", str(log), "--out", str(user), "--force"])
    assert r.exit_code == 5 and user.read_text() == "# my model\n"
    assert not list(tmp_path.glob(".*partial*"))
    # an identified model identified again: one marker line, the keys listed once
    r = runner.invoke(app, ["identify", str(log), "--model", str(out), "--out", str(tmp_path / "again.toml"), "--free",
                            "mandible.mass_g"])
    assert r.exit_code == 0, r.output
    again = (tmp_path / "again.toml").read_text()
    assert len(re.findall(r"^# written by chewbot", again, re.M)) == 1
    assert runner.invoke(app, ["check-model", str(tmp_path / "again.toml")]).exit_code == 0


def test_a_coefficient_at_its_bound_is_written_as_the_bound(tmp_path):
    """A robot without HKP viscous friction: the estimate of c_H sits on its bound 0 and is written as 0, not as the
    solver's last iterate a hair inside it (5.2e-43 was written before)."""
    truth = {**TRUE, "friction.hkp_viscous_Ns_per_m": 0.0}
    m = load_model("target", truth)
    task = default_task(m, "left", ChewingParameters(cycles=2, rest_s=0.0, rate_hz=150.0))
    kin = solve_kinematics(m, task, "euler-angles")
    tau = inverse_dynamics(m, kin, "newton-euler", friction=True).tau
    out = tmp_path / "identified.toml"
    r = runner.invoke(app, ["identify", str(write_log(tmp_path / "log.csv", kin, tau)), "--model", "target", "--out", str(out),
                            "--free", "mandible.mass_g"])
    assert r.exit_code == 0, r.output
    value = tomllib.loads(out.read_text())["friction"]["hkp_viscous_Ns_per_m"]
    assert value == 0.0  # on the bound exactly (measured: the solver stops at its bound), never a denormal


def test_an_empty_or_missing_log_is_named_as_a_robot_log(tmp_path):
    """The messages name what was expected (a robot log), not a task file."""
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    with pytest.raises(TaskError, match=r"empty.csv: empty file \(expected a robot log \(t, theta1..6, and tau1..6 or i1..6\)"):
        read_log(empty)
    with pytest.raises(TaskError, match=r"absent.csv: no such file \(expected a robot log"):
        read_log(tmp_path / "absent.csv")
