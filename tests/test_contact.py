"""The HKP normal forces of every formulation and the unilateral contact model, each held against another route.

Routes: Newton-Euler's own normal forces (unknowns of its free-body equations) against the ones the contact kernel
derives from its torques; the four frictionless formulations against each other; the mandible's Newton-Euler
equations written in NumPy (chewbot.bench.reference) with the coupler forces the torques imply; the unilateral
distributions against SciPy's SLSQP on the same problem.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from scipy.optimize import minimize

from chewbot.analysis.checks import run_checks
from chewbot.compiled.kernels import evaluate
from chewbot.dynamics.registry import inverse_dynamics
from chewbot.dynamics.g1 import CONTROLLER_MARGIN_N
from chewbot.dynamics.contact import normal_force_map, normal_forces, unilateral_minimum_norm
from chewbot.dynamics.options import GOALS
from chewbot.errors import InfeasibleError
from chewbot.model import Contact
from chewbot.model.params import load_model
from chewbot.simulation.controllers.law import inverse_dynamics_function
from chewbot.bench.reference import _equations, slsqp_distribution

from support import default_kinematics, model, without_drive

FRICTIONLESS = ("hessian", "lagrange", "liang", "6rss-core")
# One chewing cycle of the default task (t = 1.5 .. 2.3 s): the bite burst and, under G2, the right condyle pulled.
CYCLE = slice(1500, 2300)


@functools.cache
def preloaded(preload: float):
    """The target with the contact key contact.preload_N set (the kinematics do not depend on it)."""
    return model("target") if preload == 0 else load_model("target", {"contact.preload_N": preload})


def window(kin, rows):
    """The kinematics of the samples ``rows`` alone (every per-sample array cut)."""
    def cut(v):
        if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == kin.n:
            return v[rows]
        return {k: cut(x) for k, x in v.items()} if isinstance(v, dict) else v

    return dataclasses.replace(kin, **{f.name: cut(getattr(kin, f.name)) for f in dataclasses.fields(kin)})


@functools.cache
def cycle():
    return window(default_kinematics("target"), CYCLE)


@functools.cache
def run(method, contact="bilateral", preload=0.0, part="task", **options):
    """A formulation on the default task (``part="task"``) or on its chewing cycle :func:`cycle`."""
    kin = default_kinematics("target") if part == "task" else cycle()
    return inverse_dynamics(preloaded(preload), kin, method, contact=contact, **options)


def N_of(dyn):
    return np.column_stack([dyn.table["N_L"], dyn.table["N_R"]])


def test_normal_forces_from_newton_euler_torques_equal_its_own():
    """Friction off: the N that Newton-Euler distributes (its unknowns, from the free-body equations) and the N the
    contact kernel derives from its torques (the 6RSS core's two projected-out equations). Three goals give three
    different torques in the null space, so the map N = N0 + K tau is held at three points per sample."""
    m, kin = model("target"), cycle()
    own = {g: run("newton-euler", goal=g, friction=False, part="cycle") for g in GOALS}
    scale = max(np.abs(N_of(d)).max() for d in own.values())  # about 10 N
    for goal, dyn in own.items():
        # Both routes are exact; they differ by the rounding of their 6x6 and 2x2 solves (measured 2e-12 N):
        # 1e-9 relative is the bound.
        assert np.abs(normal_forces(m, kin, dyn.tau) - N_of(dyn)).max() <= 1e-9 * scale, goal
    # the goals really move N (G3 drives it to 0), so the map is not checked at one point only
    assert np.abs(N_of(own["min-torque"]) - N_of(own["min-coupler-force"])).max() > 1.0


def test_every_frictionless_formulation_gives_the_same_normal_forces():
    """Hessian, Lagrange, Liang and the 6RSS core (their minimum-norm torques by four routes) give the same N, and it
    is Newton-Euler's under G1 without friction (the same minimum-norm torques) over the chewing cycle."""
    reference = N_of(run("hessian"))
    ne = N_of(run("newton-euler", goal="min-torque", friction=False, part="cycle"))
    # the torques agree to ~1e-14 relative (test_dynamics), N follows through the kernel: 1e-9 relative; against
    # Newton-Euler's own N, as in the test above
    assert np.abs(reference[CYCLE] - ne).max() <= 1e-9 * np.abs(ne).max()
    for method in FRICTIONLESS:
        dyn = run(method)
        assert np.abs(N_of(dyn) - reference).max() <= 1e-9 * np.abs(reference).max(), method
        assert dyn.table.units["N_L"] == "N" and dyn.info["contact"]["model"] == "bilateral"
    assert "N_L" not in inverse_dynamics(model("6rss"), default_kinematics("6rss"), "hessian").table


def _mandible_residual(m, kin, tau, N):
    """The mandible's six Newton-Euler equations (chewbot.bench.reference, NumPy) with the coupler axial forces that tau
    implies through each crank's moment equation (tau_i = I_i theta_ddot_i + lever_i . F_S,i, F_S,i = F_rest,i +
    k_i u_i) and the normal forces N n at T_L, T_R: A k - (w - P N), (n, 6)."""
    e = _equations(m, kin, None)
    lu = np.sum(e.lever * e.u, axis=2)
    k = (tau - e.inertial - np.sum(e.lever * e.F_rest, axis=2)) / lu
    return np.einsum("nij,nj->ni", e.A, k) - e.w + np.einsum("nij,nj->ni", e.P, N)


@pytest.mark.parametrize("contact,preload", [("bilateral", 0.0), ("unilateral", 2.0)])
def test_mandible_newton_euler_equations_hold_with_these_normal_forces(contact, preload):
    """The defining equations: force and moment balance of the mandible (coupler forces, gravity, bite force and
    N n at each condyle) with the Hessian method's torques and its N (bilateral), and with the unilateral
    fallback's torques and N (both changed at most samples)."""
    m, kin = preloaded(preload), default_kinematics("target")
    dyn = run("hessian", contact, preload)
    residual = _mandible_residual(m, kin, dyn.tau, N_of(dyn))
    scale = np.abs(_equations(m, kin, None).w).max()  # tens of newtons
    # Every term is exact; rounding of the solves only: 1e-9 relative.
    assert np.abs(residual).max() <= 1e-9 * scale
    # the check has teeth: 10 mN more on each condyle breaks it by far more than the tolerance
    assert np.abs(_mandible_residual(m, kin, dyn.tau, N_of(dyn) + 0.01)).max() > 1e-4 * scale


def test_unilateral_fallback_is_the_least_norm_solution_with_both_condyles_pressed():
    """Preload 2 N on the default task: the bound is active at most samples, on one condyle or both. Where the
    minimum-norm torques already press both with 2 N they are returned unchanged (equal arrays); elsewhere the
    fallback gives the same motion, N >= 2 N, and what SciPy's SLSQP finds for min abs(tau)^2 subject to the
    same equations and bounds."""
    m, kin, preload = preloaded(2.0), default_kinematics("target"), 2.0
    free, uni = run("hessian"), run("hessian", "unilateral", preload)
    N_free, N = N_of(free), N_of(uni)
    terms = normal_force_map(m, kin)
    J1 = terms["J_theta1"]
    # the fallback's N sits on the bound up to the rounding of N0 + K tau (1e-13 N measured)
    assert N.min() >= preload - 1e-9
    pushes = np.all(N_free >= preload, axis=1)
    assert pushes.any() and np.array_equal(uni.tau[pushes], free.tau[pushes])
    assert uni.info["contact"]["raised_samples"] == int((~pushes).sum()) > 0 and uni.info["infeasible"] == []
    motion = np.einsum("nji,nj->ni", J1, uni.tau) - np.einsum("nji,nj->ni", J1, free.tau)
    assert np.abs(motion).max() <= 1e-12 * np.abs(np.einsum("nji,nj->ni", J1, free.tau)).max()  # Eq. (53) unchanged

    on_bound = np.abs(N - preload) < 1e-9
    one, both = np.flatnonzero(on_bound.sum(axis=1) == 1), np.flatnonzero(on_bound.all(axis=1))
    assert one.size and both.size
    for k in np.concatenate([one[:: max(1, one.size // 5)], both[:: max(1, both.size // 5)]]):
        K, b = terms["K"][k], J1[k].T @ free.tau[k]
        res = minimize(lambda x: x @ x, free.tau[k], jac=lambda x: 2 * x, method="SLSQP",
                       constraints=[{"type": "eq", "fun": lambda x: J1[k].T @ x - b, "jac": lambda x: J1[k].T},
                                    {"type": "ineq", "fun": lambda x: terms["N0"][k] + K @ x - preload, "jac": lambda x: K}],
                       options={"ftol": 1e-12, "maxiter": 500})
        assert res.success
        # a strictly convex QP with exact derivatives: SLSQP converges to its optimum (1e-16 N m measured)
        assert np.abs(uni.tau[k] - res.x).max() <= 1e-10, k


def test_unilateral_fallback_names_the_samples_where_the_redundancy_cannot_change_N():
    """Synthetic terms: at sample 1 the null-space torques do not reach N (K Z = 0), so no torques of this motion
    press the condyles: named, torques left as given; sample 0 is raised to the bound."""
    rng = np.random.default_rng(3)
    J1 = rng.normal(size=(2, 6, 4))
    K = rng.normal(size=(2, 2, 6))
    K[1] = rng.normal(size=(2, 4)) @ np.swapaxes(J1[1], 0, 1)  # rows in the range of J_theta1': K Z = 0
    tau = rng.normal(size=(2, 6))
    terms = {"N0": np.full((2, 2), -5.0), "K": K, "J_theta1": J1}
    sol = unilateral_minimum_norm(tau, terms, 1.0)
    assert sol.infeasible.tolist() == [1] and sol.raised.tolist() == [0]
    assert np.array_equal(sol.tau[1], tau[1])
    assert sol.N[0].min() >= 1.0 - 1e-9


def test_newton_euler_unilateral_keeps_the_right_condyle_pressed_under_g2():
    """G2 with friction over one chewing cycle: the bilateral optimum pulls the right condyle; the unilateral one
    does not, is unchanged where the plane already pushes, and matches SciPy's SLSQP (same goal, limits and
    friction, the bound N >= 0) where it pulled."""
    m, kin = model("target"), cycle()
    free = run("newton-euler", goal="min-coupler-force", part="cycle")
    uni = run("newton-euler", "unilateral", goal="min-coupler-force", part="cycle")
    N_free, N = N_of(free), N_of(uni)
    pulled = np.flatnonzero(N_free.min(axis=1) < 0)
    assert pulled.size > 50
    assert N.min() >= -1e-9  # LOWER_TOL at a zero bound
    pushes = np.setdiff1d(np.arange(kin.n), pulled)
    assert np.array_equal(uni.tau[pushes], free.tau[pushes]) and np.array_equal(N[pushes], N_free[pushes])
    assert uni.info["infeasible"] == [] and uni.info["contact"] == {
        "model": "unilateral", "preload_N": 0.0, "distribution": "goal min-coupler-force with N_L, N_R >= contact.preload_N as constraints"}
    samples = pulled[:: pulled.size // 6]
    tau_ref, N_ref = slsqp_distribution(m, kin, "min-coupler-force", samples, lower=0.0)
    # SLSQP with finite-difference gradients of the smoothed friction terms stops within ~1e-7 N of the optimum
    # (the cost is flat to second order there): 1e-5 N and N m leave a margin for that, not for a wrong optimum,
    # which differs by the bilateral forces' pull (newtons).
    assert np.abs(N[samples] - N_ref).max() <= 1e-5
    assert np.abs(uni.tau[samples] - tau_ref).max() <= 1e-5


def test_newton_euler_unilateral_with_both_bounds_active_matches_slsqp():
    """G1 with a preload of 2 N: at most samples of the cycle both bounds bind (then the torques follow from the
    motion and the preload), elsewhere the right one alone; SLSQP agrees at samples of each kind. On the robot without
    its drive, for which the samples were chosen (with the drive, at one of them the SQP holds the left bound active
    where SLSQP finds a cost 5e-6 lower with N_L = 2.1 N)."""
    m, kin = dataclasses.replace(without_drive("target"), contact=Contact(2.0)), cycle()
    uni = inverse_dynamics(m, kin, "newton-euler", contact="unilateral", goal="min-torque")
    N = N_of(uni)
    assert N.min() >= 2.0 - 1e-9 * 3  # LOWER_TOL (1 + |l|)
    on = np.abs(N - 2.0) < 1e-7
    samples = np.concatenate([np.flatnonzero(on.all(axis=1))[::200], np.flatnonzero(on.sum(axis=1) == 1)[::40]])
    assert samples.size >= 4
    tau_ref, N_ref = slsqp_distribution(m, kin, "min-torque", samples, lower=2.0)
    assert np.abs(N[samples] - N_ref).max() <= 1e-5  # as in the G2 test
    assert np.abs(uni.tau[samples] - tau_ref).max() <= 1e-5


def test_newton_euler_infeasible_samples_are_named_never_clipped():
    """A preload of 100 N cannot be held within the actuator limits: every sample is named with what it breaks and
    the SQP's status, the run's checks fail (distribution-infeasible, torque-limit), strict raises. The torques
    kept are the goal's optimum under the contact bounds alone (N = 100 N), not clipped to the limits."""
    m, kin = preloaded(100.0), window(cycle(), slice(100, 120))
    dyn = inverse_dynamics(m, kin, "newton-euler", contact="unilateral")
    assert len(dyn.info["infeasible"]) == kin.n
    first = dyn.info["infeasible"][0]
    assert first["sample"] == 0 and first["t"] == kin.t[0] and first["limits"] and first["solver"] not in ("", "unknown")
    assert np.abs(dyn.tau).max() > m.limits.torque and np.allclose(N_of(dyn), 100.0, rtol=0, atol=1e-7)
    cols = {"t": kin.t, **dyn.table.columns, **{f"tau{i + 1}": dyn.tau[:, i] for i in range(6)}}
    checks = {c.name: c for c in run_checks(m, cols, dyn.info, "unilateral")}
    assert checks["distribution-infeasible"].fails_run and checks["distribution-infeasible"].samples == kin.n
    assert checks["torque-limit"].fails_run and checks["contact-pull"].passed
    with pytest.raises(InfeasibleError, match=r"sample 0 .*SQP"):
        inverse_dynamics(m, kin, "newton-euler", contact="unilateral", strict=True)


def _cli(*args):
    from typer.testing import CliRunner

    from chewbot.cli import app

    return CliRunner().invoke(app, list(args))


def test_run_with_the_unilateral_contact_records_it_and_names_the_fallback(task_csv, tmp_path):
    from chewbot.outputs.record import read_results

    out = tmp_path / "pressed"
    result = _cli("run", "--task", str(task_csv), "--contact", "unilateral", "--set", "contact.preload_N=1", "--out", str(out), "-q")
    assert result.exit_code == 0, result.output
    run_json, table = read_results(out)
    assert run_json["options"]["contact"] == "unilateral"
    assert run_json["dynamics"]["contact"]["distribution"].startswith("unilateral fallback")
    assert min(table["N_L"].min(), table["N_R"].min()) >= 1.0 - 1e-9
    pull = next(c for c in run_json["checks"] if c["name"] == "contact-pull")
    assert pull["passed"] and pull["severity"] == "failure"
    report = (out / "report.html").read_text()
    assert "HKP normal forces" in report and "unilateral fallback" in report


def test_unilateral_contact_that_the_actuators_cannot_hold_fails_the_run(task_csv):
    """A preload of 300 N with newton-euler: no sample has torques within the limits that hold it; the run's checks
    fail (chewbot run then exits 4, after writing the folder: exit_after_checks, tests/test_outputs.py)."""
    from chewbot.analysis.checks import run_fails
    from chewbot.run.pipeline import compute
    from chewbot.run.options import RunOptions

    result = compute(RunOptions(task=str(task_csv), method="newton-euler", contact="unilateral",
                                overrides={"contact.preload_N": 300.0}))
    checks = {c.name: c for c in result.checks}
    infeasible = checks["distribution-infeasible"]
    assert infeasible.fails_run and infeasible.samples == 51 and "300 N" in infeasible.message
    assert run_fails(result.checks)


def test_unilateral_contact_is_refused_for_the_6rss(tmp_path):
    result = _cli("run", "--model", "6rss", "--contact", "unilateral", "--out", str(tmp_path / "x"))
    assert result.exit_code == 2 and "6RSS has no HKP contacts" in result.output
    assert not (tmp_path / "x").exists()


def test_controller_newton_euler_unilateral_equals_the_distribution_solver():
    """The controller's compiled per-sample Newton-Euler graph with the unilateral contact (fixed cost: the free
    optimum, the two faces, the corner) against the whole-task solver's active sets, G1 with friction over the chewing
    cycle: the controller keeps its margin CONTROLLER_MARGIN_N above the preload, so the graph on a model with a 2 N
    preload is the solver on the same model with a 2 N + margin preload, where the bilateral optimum leaves N_R below
    that bound at most of the 800 samples and N_L at many: the same torques to rounding (the two run the same Newton
    iteration on the same expressions; 1e-12 N m is rounding on torques of ~1 N m), and different from the bilateral
    ones by more than the test's resolution."""
    m = dataclasses.replace(without_drive("target"), contact=Contact(2.0))
    bound = 2.0 + CONTROLLER_MARGIN_N
    kin = cycle()
    uni = inverse_dynamics(dataclasses.replace(m, contact=Contact(bound)), kin, "newton-euler", contact="unilateral",
                           goal="min-torque")
    free = inverse_dynamics(m, kin, "newton-euler", goal="min-torque")
    below = (N_of(free) < bound).sum(axis=0)
    assert below[0] > 300 and below[1] > 700 and uni.info["constrained_samples"] == 0
    args = (kin.q, kin.dq, kin.ddq, m.molar(kin.side), kin.force, m.vector())
    tau = evaluate(inverse_dynamics_function("target", "newton-euler", "min-torque", True, "unilateral"), *args)[0]
    tau_free = evaluate(inverse_dynamics_function("target", "newton-euler", "min-torque", True), *args)[0]
    assert np.abs(tau - uni.tau).max() <= 1e-12
    assert np.abs(tau_free - free.tau).max() <= 1e-12
    assert np.abs(uni.tau - free.tau).max() > 1e-2
