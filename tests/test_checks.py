"""Validity checks (chewbot.analysis.checks), the transmission angle and the conditioning they use.

Routes: the transmission angle against a finite difference of the chain's own geometry (how fast the coupler
end moves along the coupler when the crank turns), kappa against its defining property (no dependence on the
units of the coordinates), each check's counts against a direct count written here, and chunks against one
whole-task update.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from chewbot.analysis.checks import (
    BITE_FORCE_BOUND_N,
    CHECKS,
    KAPPA_MIN,
    NEAR_SINGULAR_DEG,
    RunChecks,
    run_checks,
    run_fails,
)
from chewbot.dynamics.registry import inverse_dynamics
from chewbot.kinematics.conditioning import jacobian_conditioning, reciprocal_condition
from chewbot.kinematics.ik import transmission
from chewbot.model import Limits
from chewbot.run.pipeline import compute
from chewbot.run.options import RunOptions
from chewbot.model.chains import crank_tips
from chewbot.rotation import matrix_from_euler_angles

from support import default_kinematics, model


def _coupler_ends(m, kin):
    R = matrix_from_euler_angles(kin.X[:, 3:6])
    return kin.X[:, None, :3] + np.einsum("nij,kj->nki", R, m.M)


@pytest.mark.parametrize("name", ["target", "6rss"])
def test_transmission_angle_is_the_share_of_the_crank_motion_along_the_coupler(name):
    """sin mu_i = |d|S_i - M_i|/d theta_i| / L_c: turn the crank by +-h with the mandible held, measure how fast the
    coupler's length changes (central difference, h = 1e-6 rad: error O(h^2) ~ 1e-12 plus rounding 1e-16/h ~ 1e-10
    relative), compare with the closed form of chewbot.kinematics.ik.transmission to 1e-8."""
    m = model(name)
    kin = default_kinematics(name)
    M = _coupler_ends(m, kin)
    h = 1e-6
    length = [np.linalg.norm(crank_tips(m, kin.theta + s * h) - M, axis=2) for s in (1, -1)]
    rate = np.abs(length[0] - length[1]) / (2 * h)
    R = matrix_from_euler_angles(kin.X[:, 3:6])
    assert np.abs(rate / m.crank_length - transmission(m, kin.X[:, :3], R)).max() <= 1e-8
    # the run's values come from the compiled kinematics kernel: the same formula, another evaluation (rounding)
    assert np.abs(kin.transmission - transmission(m, kin.X[:, :3], R)).max() <= 1e-12


def test_transmission_angles_of_the_default_task_are_those_the_docs_state():
    """docs/conventions.md: chains 3 and 4 at 17.96 deg at home, chain 4 down to 13.98 deg (left side), the others
    above 32 deg (to the 0.01 deg the docs print)."""
    mu = np.degrees(np.arcsin(default_kinematics("target").transmission))
    # the docs print 0.01 deg: the values within half of it (rounding a value that lies on a rounding boundary
    # could differ from machine to machine; a tolerance cannot)
    assert mu[0, 2:4] == pytest.approx([17.96, 17.96], abs=0.005)
    assert mu[:, 3].min() == pytest.approx(13.98, abs=0.005) and mu[:, [0, 1, 4, 5]].min() > 32
    assert mu.min() > NEAR_SINGULAR_DEG


def test_kappa_does_not_depend_on_the_units_and_vanishes_at_rank_loss():
    rng = np.random.default_rng(3)
    J = rng.normal(size=(50, 6, 4))
    scaled = J * rng.uniform(1e-3, 1e3, size=(50, 1, 4))  # each coordinate in another unit
    assert np.abs(reciprocal_condition(scaled) - reciprocal_condition(J)).max() <= 1e-12
    J[:, :, 3] = J[:, :, 0] + 2 * J[:, :, 1]  # a motion the cranks do not see
    assert reciprocal_condition(J).max() <= 1e-14
    # the same motion in Euler parameters gets the same kappa (it is always evaluated in Euler angles); the two
    # kinematics agree to rounding (theta from another parametrisation of the pose), hence 1e-12
    m = model("target")
    kin_a, kin_p = default_kinematics("target"), default_kinematics("target", "left", "euler-parameters")
    kappa = kin_a.kappa
    assert np.abs(kin_p.kappa - kappa).max() <= 1e-12
    # J_theta1 as d theta / d q of the closed-form inverse kinematics (the kernel) against -J_theta^-1 J_qEE of the
    # closure equations (Eq. 14, jacobians_function)
    assert np.abs(reciprocal_condition(kin_a.jacobians()["J_theta1"]) - kappa).max() <= 1e-12
    assert np.abs(jacobian_conditioning(m, kin_a.euler_angle_state()[0]) - kappa).max() <= 1e-12
    assert 0.3 < kappa.min() and kappa.max() < 0.42  # docs/conventions.md: 0.34-0.41 on the default task


@functools.cache
def _newton_euler_run(name="target"):
    """Columns and info of a Newton-Euler run (G1 with friction) of the default task: every column the checks use."""
    result = compute(RunOptions(model=name, method="newton-euler", goal="min-torque" if name == "target" else None, friction="on"))
    return result


TIGHT = Limits(torque=0.1, power=0.05, axial_load=5.0, radial_load=8.0, theta_range=np.radians([-10.0, 12.0]), speed=1.0)


def _direct_counts(cols, lim: Limits) -> dict[str, tuple[int, int | None]]:
    """(failing samples, first failing sample) of each limit check, counted here from the defining inequalities."""
    r = 1 + 1e-6  # the distribution's LIMIT_RTOL
    tau = np.column_stack([cols[f"tau{i}"] for i in range(1, 7)])
    dth = np.column_stack([cols[f"dtheta{i}"] for i in range(1, 7)])
    th = np.column_stack([cols[f"theta{i}"] for i in range(1, 7)])
    ax = np.column_stack([cols[f"FG{i}_axial"] for i in range(1, 7)])
    rad = np.column_stack([cols[f"FG{i}_radial"] for i in range(1, 7)])
    masks = {
        "torque-limit": (np.abs(tau) > lim.torque * r).any(axis=1),
        "power-limit": (np.abs(tau * dth) > lim.power * r).any(axis=1),
        "bearing-load": ((np.abs(ax) > lim.axial_load * r) | (rad > lim.radial_load * r)).any(axis=1),
        "crank-range": ((th < lim.theta_range[0]) | (th > lim.theta_range[1])).any(axis=1),
        "speed-limit": (np.abs(dth) > lim.speed * r).any(axis=1),
    }
    return {k: (int(v.sum()), int(np.argmax(v)) if v.any() else None) for k, v in masks.items()}


def test_each_limit_check_counts_the_samples_that_break_its_inequality():
    result = _newton_euler_run()
    checks = RunChecks(TIGHT, has_hkp=True)
    checks.update(0, result.table, result.info["dynamics"])
    got = {c.name: c for c in checks.results()}
    for name, (count, first) in _direct_counts(result.table, TIGHT).items():
        assert count > 0, name  # the tight limits are broken somewhere, so the check is exercised
        assert (got[name].samples, got[name].first_sample["index"]) == (count, first), name
        assert not got[name].passed and got[name].fails_run
    peak = max(np.abs(result.table[f"tau{i}"]).max() for i in range(1, 7))
    assert got["torque-limit"].worst == {"value": peak, "unit": "N*m"}
    # with the model's own limits the default task is within every limit and feasible
    own = {c.name: c for c in result.checks}
    assert all(own[n].passed and own[n].samples == 0 for n in ("torque-limit", "power-limit", "bearing-load", "distribution-infeasible"))
    assert own["crank-range"].samples is None and "limits.theta_range_deg" in own["crank-range"].message


def test_two_chunks_give_the_verdicts_of_one():
    """The reducers (for a caller that processes a long task in chunks): the run split at sample 1700, the info's
    infeasible samples counted from each chunk's start, gives exactly the results of one update."""
    result = _newton_euler_run()
    cols = {name: result.table[name] for name in result.table.columns}
    infeasible = [{"sample": k, "t": float(cols["t"][k]), "limits": ["torque (actuator 3)"], "solver": "Infeasible_Problem_Detected"}
                  for k in (1650, 1690, 1702, 3000)]
    whole = RunChecks(TIGHT, has_hkp=True, contact="unilateral")
    whole.update(0, cols, {"infeasible": infeasible})
    split = 1700
    chunked = RunChecks(TIGHT, has_hkp=True, contact="unilateral")
    for lo, hi in ((0, split), (split, len(cols["t"]))):
        part = [{**e, "sample": e["sample"] - lo} for e in infeasible if lo <= e["sample"] < hi]
        chunked.update(lo, {k: v[lo:hi] for k, v in cols.items()}, {"infeasible": part})
    assert chunked.results() == whole.results()
    by_name = {c.name: c for c in whole.results()}
    assert by_name["distribution-infeasible"].samples == 4 and by_name["distribution-infeasible"].first_sample["index"] == 1650
    assert {c.name for c in whole.results()} == {cls.name for cls in CHECKS}


def test_contact_pull_is_a_failure_only_under_the_unilateral_contact_model():
    """Goal G2 on the default task: the plane pulls the right condyle in part of the samples (issue 10: 16 %,
    down to -4 N); reported either way, a failure only when the contact is unilateral."""
    m = model("target")
    kin = default_kinematics("target")
    dyn = inverse_dynamics(m, kin, "newton-euler", goal="min-coupler-force", friction=True)
    cols = {"t": kin.t, "N_L": dyn.table["N_L"], "N_R": dyn.table["N_R"]}
    pulls = int(((cols["N_L"] < -1e-6) | (cols["N_R"] < -1e-6)).sum())
    assert pulls > 0
    for contact, fails in (("bilateral", False), ("unilateral", True)):
        (pull,) = [c for c in RunChecks(m.limits, True, contact).checks if c.name == "contact-pull"]
        pull.update(0, cols)
        r = pull.result()
        assert r.samples == pulls and not r.passed and r.fails_run is fails
        assert r.worst["value"] == min(cols["N_L"].min(), cols["N_R"].min()) < 0
    # the 6RSS has no contacts: not evaluated
    (pull,) = [c for c in RunChecks(m.limits, False).checks if c.name == "contact-pull"]
    pull.update(0, cols)
    assert pull.result().samples is None and pull.result().passed is None  # not evaluated: null in run.json, not true


def test_contact_pull_under_a_unilateral_contact_fails_below_the_preload():
    """Unilateral with a preload of 2 N: a normal force of 1.5 N presses the condyle but less than the preload, so
    the sample fails (a run exits 4); bilateral, only a negative N counts (a warning)."""
    m = model("target")
    t = np.arange(5) * 1e-3
    cols = {"t": t, "N_L": np.array([3.0, 1.5, 2.0, 2.0 - 1e-7, 4.0]), "N_R": np.full(5, 2.5)}
    uni = RunChecks(m.limits, True, "unilateral", preload=2.0)
    uni.update(0, cols)
    pull = {c.name: c for c in uni.results()}["contact-pull"]
    # 1e-7 N below the bound is within PULL_TOLERANCE_N (1e-6 N): rounding, not a pull
    assert pull.samples == 1 and pull.first_sample == {"index": 1, "t": 1e-3} and pull.fails_run
    assert "preload 2 N" in pull.message and run_fails(uni.results())
    bil = RunChecks(m.limits, True, "bilateral", preload=2.0)
    bil.update(0, cols)
    assert {c.name: c for c in bil.results()}["contact-pull"].samples == 0
    # for_model takes the preload from the model's contact.preload_N
    from chewbot.model.params import load_model

    ctx = RunChecks.for_model(load_model("target", {"contact.preload_N": 2.0}), "unilateral").checks[0].ctx
    assert ctx.preload == 2.0 and ctx.contact == "unilateral"


def test_warnings_do_not_fail_a_run_and_methods_without_bearing_forces_are_not_evaluated():
    result = compute(RunOptions(method="hessian"))
    cols = {name: result.table[name] for name in result.table.columns}
    cols["Fz"] = cols["Fz"] * 20  # 1.6 kN bursts: a unit mistake
    cols["mu4"] = np.where(cols["t"] > 2.0, np.radians(5.0), cols["mu4"])
    results = {c.name: c for c in run_checks(model("target"), cols)}
    assert not results["bite-force"].passed and results["bite-force"].worst["value"] > BITE_FORCE_BOUND_N
    assert not results["near-singular"].passed and results["near-singular"].worst == {"value": pytest.approx(5.0), "unit": "deg"}
    assert results["near-singular"].first_sample["t"] > 2.0
    assert not run_fails(list(results.values()))  # warnings only
    assert results["bearing-load"].samples is None and results["bearing-load"].passed is None
    assert results["distribution-infeasible"].samples is None
    kappa = dict(cols, kappa_J=np.where(cols["t"] > 4.0, KAPPA_MIN / 2, cols["kappa_J"]), mu4=result.table["mu4"])
    near = {c.name: c for c in run_checks(model("target"), kappa)}["near-singular"]
    assert not near.passed and near.first_sample["t"] > 4.0 and "kappa" in near.message


def test_limits_of_a_model_without_crank_range_or_speed_are_not_evaluated():
    m = model("target")
    assert np.isinf(m.limits.theta_range).all()  # key left out: unbounded
    result = compute(RunOptions(method="hessian"))
    open_ended = dataclasses.replace(m.limits, speed=np.inf, acceleration=np.inf)
    got = {c.name: c for c in RunChecks(open_ended, True).checks}
    for name in ("crank-range", "speed-limit", "acceleration-limit"):
        got[name].update(0, result.table)
        assert got[name].result().samples is None and "sets no" in got[name].result().message
    strict = dataclasses.replace(m.limits, theta_range=np.radians([-1.0, 1.0]), speed=0.5, acceleration=20.0)
    got = {c.name: c for c in RunChecks(strict, True).checks}
    for name in ("crank-range", "speed-limit", "acceleration-limit"):
        got[name].update(0, result.table)
        assert got[name].result().samples > 0 and got[name].result().fails_run


def test_speed_and_acceleration_limits_count_the_samples_beyond_them_and_warn_on_a_simulated_motion():
    """The built-in limits (17 rad/s, 200 rad/s^2, assumed) hold on the default task; lowered below its peaks they
    fail exactly the samples whose largest abs(theta_dot_i), abs(theta_ddot_i) exceed them (counted here from the
    columns), and on a simulated plant's motion (planned=False) the same samples are a warning."""
    m = model("target")
    assert (m.limits.speed, m.limits.acceleration) == (17.0, 200.0)
    table = compute(RunOptions(method="hessian")).table
    results = {c.name: c for c in run_checks(m, {n: table[n] for n in table.columns})}
    assert results["speed-limit"].passed and results["acceleration-limit"].passed
    dd = np.abs(np.column_stack([table[f"ddtheta{i}"] for i in range(1, 7)])).max(axis=1)
    d = np.abs(np.column_stack([table[f"dtheta{i}"] for i in range(1, 7)])).max(axis=1)
    assert results["acceleration-limit"].worst["value"] == pytest.approx(dd.max())
    low = dataclasses.replace(m.limits, speed=0.5 * d.max(), acceleration=0.5 * dd.max())
    for planned in (True, False):
        got = {c.name: c for c in RunChecks(low, True, planned=planned).checks}
        for name, peak in (("speed-limit", d), ("acceleration-limit", dd)):
            got[name].update(0, table)
            r = got[name].result()
            assert r.samples == int(np.sum(peak > 0.5 * peak.max() * (1 + 1e-6)))  # the limits' relative tolerance
            assert r.fails_run == planned and r.severity == ("failure" if planned else "warning")
