"""The bite force from the torques (docs/bite_force.md): chewbot.dynamics.bite_force and chewbot estimate-force.

The logs are made by the inverse dynamics with a known bite force (tau = ID(motion, F_B): Newton-Euler with friction
and its optimal distribution of the redundant torques, or the Hessian method without friction), the other way round
from the estimator, which must give the force back.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from scipy.optimize import lsq_linear
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.dynamics.bite_force import MAX_CONDITION, estimate, summarise
from chewbot.dynamics.registry import inverse_dynamics
from chewbot.identification.force import estimate_angles
from chewbot.kinematics.motion import solve_kinematics
from chewbot.model.params import load_model
from chewbot.table import Table
from chewbot.task.default import ChewingParameters, default_task

runner = CliRunner()


@functools.cache
def chewing(friction: bool = True, method: str = "newton-euler", rate_hz: float = 1000.0):
    """One chewing cycle (a bite-force burst to -80 N) after 0.2 s of rest: the model, kinematics with exact rates,
    the torques of the inverse dynamics with the task's bite force, and its normal forces."""
    m = load_model("target")
    kin = solve_kinematics(m, default_task(m, "left", ChewingParameters(cycles=1, rest_s=0.2, rate_hz=rate_hz)), "euler-angles")
    d = inverse_dynamics(m, kin, method, **({"friction": friction} if method == "newton-euler" else {}))
    return m, kin, d.tau, np.column_stack([d.table["N_L"], d.table["N_R"]])


def take(kin, rows):
    """The kinematics of the samples ``rows`` (repeated rows allowed)."""
    arrays = {f.name: getattr(kin, f.name)[rows] for f in dataclasses.fields(kin)
              if isinstance(getattr(kin, f.name), np.ndarray) and getattr(kin, f.name).shape[:1] == (kin.n,)}
    points = {k: v[rows] for k, v in kin.points.items()}
    return dataclasses.replace(kin, points=points, **arrays)


@pytest.mark.parametrize("friction", [True, False])
def test_exact_rates_give_the_bite_force_and_the_normal_forces_back(friction):
    # friction on: the plant's model (Newton-Euler with friction), friction off: torques of the Hessian method, an
    # independent formulation. Tolerance 1e-6 of the peak force (80 N): the equations hold to rounding (~1e-15 N m
    # on torques of ~1 N m) and G's condition number is below 40, so ~1e-12 N remain; 1e-6 is what the issue asks.
    m, kin, tau, N = chewing(friction, "newton-euler" if friction else "hessian")
    e = estimate(m, kin, tau, friction=friction)
    peak = np.abs(kin.force).max()
    assert np.abs(e.F_B - kin.force).max() <= 1e-6 * peak
    assert np.abs(e.N - N).max() <= 1e-6 * peak
    assert e.residual.max() < 1e-9 and not e.warnings
    assert e.condition.max() < MAX_CONDITION


def test_from_angles_alone_at_1_kHz_the_force_is_within_2_percent_of_its_peak():
    # The motion from the crank angles only (poses by least squares, rates by identify's Savitzky-Golay filter):
    # the filter's error on the accelerations and the regularised friction near zero crank speed are what remain.
    m, kin, tau, _ = chewing()
    e = estimate_angles(m, kin.t, kin.theta, tau)
    assert e.info["rates"] == {"first": "smoothed", "second": "smoothed"}
    err = np.linalg.norm(e.F_B - kin.force, axis=1)
    assert np.sqrt(np.mean(err**2)) <= 0.02 * np.abs(kin.force).max()


def test_with_torque_noise_the_spread_of_the_estimate_matches_its_standard_errors():
    # Monte Carlo: five samples of the chewing cycle (rest, opening, the burst's rise and peak, closing), each
    # repeated 600 times with independent Gaussian torque noise (seeded), estimated with exact rates. The standard
    # deviation of 600 draws is known to ~3 % (1/sqrt(2 * 600)), and the linearisation's error is ~sigma/|F| ~1e-3:
    # 20 % (the bound) is six standard errors of the check.
    m, kin, tau, _ = chewing()
    rows = np.repeat([100, 450, 700, 840, 950], 600)
    sub = take(kin, rows)
    sigma = 0.01  # N m, against torques of ~1 N m
    rng = np.random.default_rng(20)
    noisy = tau[rows] + rng.normal(0.0, sigma, (rows.size, 6))
    e = estimate(m, sub, noisy)
    # the pooled sigma: 3000 residuals with one degree of freedom each, known to ~1.3 %
    assert abs(e.sigma / sigma - 1) < 0.05
    for k in range(5):
        block = slice(600 * k, 600 * (k + 1))
        spread = np.std(e.u[block], axis=0)
        predicted = np.sqrt(np.mean(e.se[block] ** 2, axis=0))
        assert np.all(np.abs(spread / predicted - 1) < 0.2), (k, spread, predicted)


def test_unilateral_contact_is_the_bounded_least_squares():
    # Without friction r is affine in u: the unilateral estimate must be SciPy's bounded linear least squares
    # (lsq_linear, N_L, N_R >= 0) at every sample. The torques get internal torques (null space of J_theta1') that
    # pull one condyle or the other, so that the bounds hold somewhere.
    m, kin, tau, _ = chewing(False, "hessian")
    rows = np.arange(300, 1000, 7)
    sub = take(kin, rows)
    J = sub.jacobians()["J_theta1"]
    Z = np.linalg.qr(J, mode="complete")[0][:, :, 4:]
    rng = np.random.default_rng(3)
    pushed = tau[rows] + np.einsum("nij,nj->ni", Z, rng.normal(0, 0.5, (rows.size, 2)))
    free = estimate(m, sub, pushed, friction=False)
    assert (free.N < -1).any(axis=0).all()  # both condyles pulled somewhere
    e = estimate(m, sub, pushed, friction=False, contact="unilateral")
    assert (e.N >= 0).all()
    # G and r(0) of the affine problem, from the estimator's own kernel at u = 0 and its slope
    from chewbot.compiled.kernels import evaluate, native
    from chewbot.dynamics.bite_force import residual_kernel

    q, dq, ddq = sub.euler_angle_state()
    r0, G = evaluate(native(residual_kernel("target")), sub.theta, q, dq, ddq, m.molar("left"), np.zeros((rows.size, 5)),
                     pushed, np.zeros(2), 0.0, m.vector())
    for k in range(rows.size):
        ref = lsq_linear(G[k], -r0[k], bounds=([-np.inf] * 3 + [0, 0], np.inf), method="bvls", tol=1e-14).x
        assert np.abs(e.u[k] - ref).max() < 1e-8 * (1 + np.abs(ref).max()), k


def test_an_ill_conditioned_sample_is_named():
    G = np.tile(np.eye(6, 5), (3, 1, 1))
    G[1, :, 4] = G[1, :, 3] + 1e-6 * np.eye(6)[5]  # N_R's column nearly N_L's
    torque = 1e-6 * np.linalg.inv(np.einsum("nki,nkj->nij", G, G))  # sigma = 1e-3 N*m on each torque
    zero = np.zeros((3, 5, 5))
    parts = {"torque": torque, "rates": zero, "parameters": zero, "sigma": 1e-3, "dof": 3, "sigma_source": "given"}
    e = summarise(np.array([0.0, 0.001, 0.002]), np.zeros((3, 5)), np.full((3, 6), 1e-3), G, np.ones((3, 5), bool), parts)
    assert e.ill_conditioned.tolist() == [1]
    assert "1 (t = 0.001 s)" in e.warnings[0]
    assert e.se[1, 3] > 100 * e.se[0, 3]


def write_log(path, kin, tau):
    cols = ["t [ms]"] + [f"theta{i} [deg]" for i in range(1, 7)] + [f"tau{i} [N*m]" for i in range(1, 7)]
    np.savetxt(path, np.column_stack([kin.t * 1e3, np.degrees(kin.theta), tau]), delimiter=",", header=",".join(cols),
               comments="", fmt="%.17g")
    return path


def test_estimate_force_writes_one_row_per_log_sample_with_units(tmp_path):
    m, kin, tau, _ = chewing()
    log = write_log(tmp_path / "log.csv", kin, tau)
    out = tmp_path / "force.csv"
    r = runner.invoke(app, ["estimate-force", str(log), "--model", "target", "--out", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    table = Table.read_csv(out)
    unknowns = ["Fx", "Fy", "Fz", "N_L", "N_R"]
    assert list(table.columns) == ["t", *unknowns, *[f"s{u}" for u in unknowns],
                                   *[f"{u}_{end}95" for u in unknowns for end in ("low", "high")], "residual"]
    assert table.units["Fz"] == "N" and table.units["residual"] == "N*m" and table.units["t"] == "s"
    assert table.units["Fz_low95"] == "N" and table.units["Fz_high95"] == "N"
    np.testing.assert_allclose(table["Fz_high95"] - table["Fz"], 1.959963984540054 * table["sFz"], rtol=1e-9, atol=1e-12)
    assert np.allclose(table["t"], kin.t, rtol=0, atol=1e-12)
    assert np.sqrt(np.mean((table["Fz"] - kin.force[:, 2]) ** 2)) < 0.02 * 80
    # never over a file without --force; with it, over its own output
    text = out.read_text()
    r = runner.invoke(app, ["estimate-force", str(log), "--out", str(out)])
    assert r.exit_code == 5 and out.read_text() == text
    assert runner.invoke(app, ["estimate-force", str(log), "--out", str(out), "--force", "-q"]).exit_code == 0


def test_estimate_force_names_the_file_of_a_bad_log(tmp_path):
    bad = tmp_path / "bad.csv"
    rows = "".join(f"{k * 1e-3},0,0,0,0,0,0,0,0,0,0,0\n" for k in range(10))
    bad.write_text("t,theta1,theta2,theta3,theta4,theta5,theta6,tau1,tau2,tau3,tau4,tau5\n" + rows)
    r = runner.invoke(app, ["estimate-force", str(bad), "--out", str(tmp_path / "f.csv")])
    assert r.exit_code == 2 and "bad.csv" in r.output and "tau6" in r.output
    r = runner.invoke(app, ["estimate-force", str(bad), "--model", "6rss", "--out", str(tmp_path / "f.csv")])
    assert r.exit_code == 2


def test_a_results_csv_of_chewbot_is_read_as_a_log_with_its_other_columns_skipped(tmp_path):
    import json

    from chewbot.errors import TaskError
    from chewbot.identification.log import read_log

    m, kin, tau, _ = chewing()
    folder = tmp_path / "sim"
    folder.mkdir()
    cols = ["t [s]", "X [m]"] + [f"theta{i} [rad]" for i in range(1, 7)] + [f"tau{i} [N*m]" for i in range(1, 7)]
    np.savetxt(folder / "results.csv", np.column_stack([kin.t, kin.X[:, 0], kin.theta, tau]), delimiter=",",
               header=",".join(cols), comments="", fmt="%.17g")
    with pytest.raises(TaskError, match="unknown column 'X'"):
        read_log(folder / "results.csv")
    (folder / "run.json").write_text(json.dumps({"chewbot_simulation": 1, "columns": {"t": "s", "X": "m"}}))
    log = read_log(folder / "results.csv")
    assert np.array_equal(log.theta, kin.theta) and np.array_equal(log.tau, tau)
