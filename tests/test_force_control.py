"""Force control and the force observer in chewbot simulate (docs/bite_force.md): --controller hybrid and impedance
on the food plant (chewbot.simulation.food), each judged by the plant's own food force, not the controller's.

The foods are linear elastic cylinders (no damping, no fracture, no tooth friction unless stated) whose stiffness
E A / h0 is set; the tasks are built for the food: the molar point starts h0 + 2 mm apart, closes to h0 - 2 mm in
0.3 s (into the food), holds, and opens again; the task's Fz is the hybrid controller's force reference: 0 until
0.35 s, a ramp to the peak in 0.1 s, held 0.3 s, released in 0.1 s.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.compiled.kernels import evaluate, native
from chewbot.food.geometry import molar_path_task
from chewbot.model.params import load_model
from chewbot.simulation.controllers.gains import Gains
from chewbot.simulation.controllers.hybrid import task_state_kernel
from chewbot.simulation.options import resolve
from chewbot.simulation.run import compute

runner = CliRunner()
RAMP = (0.35, 0.45, 0.75, 0.85)  # s: the force reference's ramp, hold and release


def smooth(s):
    s = np.clip(s, 0, 1)
    return 10 * s**3 - 15 * s**4 + 6 * s**5, 30 * s**2 - 60 * s**3 + 30 * s**4, 60 * s - 180 * s**2 + 120 * s**3


def bite_task(h0: float, peak: float, press: float = 2e-3, end: float = 1.2, opens: float = 0.9):
    """The task of the module docstring on the target's left molar (1 kHz)."""
    m = load_model("target")
    t = np.arange(0, end + 1e-9, 1e-3)
    g, dg, ddg = np.full_like(t, h0 + 2e-3), np.zeros_like(t), np.zeros_like(t)
    for t0, t1, a, b in ((0.05, 0.35, h0 + 2e-3, h0 - press), (opens, opens + 0.25, h0 - press, h0 + 2e-3)):
        f, df, ddf = smooth((t - t0) / (t1 - t0))
        on, inside = t >= t0, (t >= t0) & (t <= t1)
        g = np.where(on, a + (b - a) * f, g)
        dg = np.where(inside, (b - a) * df / (t1 - t0), np.where(on, 0.0, dg))
        ddg = np.where(inside, (b - a) * ddf / (t1 - t0) ** 2, np.where(on, 0.0, ddg))
    task = molar_path_task(m, "left", t, g, dg, ddg, name="bite")
    F = np.interp(t, [0, *RAMP, 10], [0, 0, peak, peak, 0, 0])
    return dataclasses.replace(task, force=np.column_stack([np.zeros((t.size, 2)), -F]))


def cylinder(path, k: float, h0: float, mu: float = 0.0, d: float = 10e-3):
    """A linear elastic cylinder of stiffness k = E A / h0 (N/m), height h0, diameter d, tooth friction mu."""
    E = k * h0 / (np.pi * d**2 / 4)
    path.write_text(f'[food]\nname = "elastic cylinder"\nshape = "cylinder"\nheight_mm = {h0 * 1e3!r}\ndiameter_mm = {d * 1e3!r}\n'
                    f'young_modulus_kPa = {E / 1e3!r}\ndamping_s_per_m = 0.0\nadhesion_N = 0.0\ntooth_friction = {mu!r}\n')
    return str(path)


@functools.cache
def hybrid(k: float, peak: float, h0: float, folder, friction: str = "off", mu: float = 0.0, d: float = 10e-3):
    food = cylinder(folder / f"food_{k:g}_{mu:g}_{d:g}.toml", k, h0, mu, d)
    method = "newton-euler" if friction == "on" else "hessian"
    return compute(resolve("hybrid", food=food, friction=friction, method=method), task=bite_task(h0, peak))


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("foods")


def check_stable_and_back(result):
    """Not stopped, the force reference's end released the food, z position-controlled again at the end, the molar
    point back on the reference."""
    sim, table = result.simulation, result.table
    assert sim.stopped is None
    assert table["force_mode"][-1] == 0 and table["food_force"][-1] == 0
    assert np.abs(sim.q_ref[-1] - sim.q[-1]).max() < 1e-4


@pytest.mark.parametrize("k, peak, h0", [(50e3, 20.0, 5e-3), (200.0, 0.5, 5e-3)])
def test_hybrid_follows_the_force_reference_on_the_stiffest_and_the_softest_food(k, peak, h0, folder):
    # 20 N on the 50 kN/m food (0.4 mm of 5 mm); the 200 N/m food cannot give 20 N before the teeth meet (1 N at
    # 5 mm), so its reference peaks at 0.5 N (half its height). The figure: the plant's food force (not the
    # observer's) against the reference over the ramp, hold and release, RMS <= 5 % of the peak (the bound;
    # measured 1.4 % and 1.5 %: the force loop's and the observer's lag on the ramps).
    # a slender sample (1 mm across): the face the bite point's path tilts by 3 degrees meets the whole of it within
    # 0.05 mm of compression (an eighth of the 0.4 mm), so the food is the linear spring the estimate is checked
    # against (a 10 mm face's contact grows over the ramp, 37 to 50 kN/m, and the estimate reads 43 kN/m; 3 mm: 47.8)
    r = hybrid(k, peak, h0, folder, d=1e-3)
    f = r.metrics["force"]
    assert f["samples"] == 500 and f["reference_peak_N"] == peak
    assert f["rms_percent"] <= 5.0, f
    check_stable_and_back(r)
    # the on-line stiffness estimate during the hold is the food's, to 2 %
    hold = (r.simulation.t > 0.5) & (r.simulation.t < 0.75)
    assert np.allclose(r.table["stiffness_estimate"][hold], k, rtol=0.02)


def test_the_observer_gives_the_plant_s_food_force_while_it_is_held(folder):
    # Exact model, no noise: the observer's equations are the plant's, its only errors the mid-interval acceleration
    # and the low-pass's lag, both vanishing while the force is constant (the hold, after 5 of the low-pass's time
    # constants and the force loop's settling). 1e-3 N against 20 N.
    r = hybrid(50e3, 20.0, 5e-3, folder)
    hold = (r.simulation.t > 0.55) & (r.simulation.t < 0.75)
    for c in ("Fx", "Fy", "Fz"):
        assert np.abs(r.table[f"{c}_obs"][hold] - r.simulation.force[hold, "xyz".index(c[1])]).max() < 1e-3
    assert np.abs(r.table["N_L_obs"][hold] - r.table["N_L"][hold]).max() < 1e-3


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "with the drive's rotors (about 631 kg at the molar point along z) the 200 N/m food's teeth meet at 25 mm/s, as fast "
    "as the drive's authority lets the force loop close, and the tooth contact peaks at 250 N (270 N before the hybrid "
    "law's changes for the chew); the 200 N bound was measured without the drive"))
def test_hybrid_on_a_middle_food_and_one_that_cannot_give_the_force(folder):
    # 5 kN/m (4 mm of 8 mm for 20 N): within 5 %. The 200 N/m food and 20 N: the teeth meet (the food's stiff tooth
    # contact, 1e6 N/m); the loop stays stable (bounded force, released, back on the reference), the speed limit
    # keeping the impact small.
    r = hybrid(5e3, 20.0, 8e-3, folder)
    assert r.metrics["force"]["rms_percent"] <= 5.0
    check_stable_and_back(r)
    r = hybrid(200.0, 20.0, 5e-3, folder)
    check_stable_and_back(r)
    assert np.abs(r.simulation.force[:, 2]).max() < 200.0  # measured 96 N: the teeth meet at up to 50 mm/s (docs)


@pytest.mark.slow
def test_hybrid_with_friction_in_plant_and_controller_and_a_rough_tooth(folder):
    # The plant's HKP and actuator friction, the controller's Newton-Euler model with the same friction, tooth
    # friction 0.3 (the food drags the molar sideways, position-controlled in x and y).
    r = hybrid(50e3, 20.0, 5e-3, folder, "on", 0.3)
    assert r.metrics["force"]["rms_percent"] <= 5.0
    check_stable_and_back(r)


@pytest.mark.xfail(strict=True, reason=(
    "the default impedance gains are the robot's without a drive: with the rotors reflected to the molar point the "
    "spring is nearly undamped and the molar bounces off the food (F_z = 0 at 0.8 s; 5.7 N at 0.4 s)"))
def test_impedance_holds_the_food_with_its_springs(folder):
    # At rest on the food the impedance's wrench balances the food's force at the molar: K (y_ref - y) = -F for x, y,
    # z (the inverse dynamics cancels gravity exactly with the exact model; the pinned angle carries no load). The
    # food's force is the plant's, the deflection the simulated motion's: 0.5 % after 0.45 s of hold (the damped
    # spring settles within ~0.1 s; what remains is its decay).
    food = cylinder(folder / "imp.toml", 5e3, 8e-3)
    task = bite_task(8e-3, 0.0, opens=0.8)
    r = compute(resolve("impedance", food=food), task=task)
    sim, g = r.simulation, Gains.load()
    m = load_model("target")
    y, _, y_ref, _ = evaluate(native(task_state_kernel("target")), sim.q, sim.dq, sim.q_ref, sim.dq_ref, m.molar("left"), m.vector())
    k = np.searchsorted(sim.t, 0.8)
    F = sim.force[k]
    assert F[2] < -1.0  # pressed: about K_z k / (K_z + k) 2 mm
    assert np.allclose(np.array(g["impedance"].stiffness_N_per_m) * (y_ref[k, :3] - y[k, :3]), -F, rtol=5e-3, atol=1e-3)
    assert sim.stopped is None


def test_gains_files_may_leave_out_the_new_sections_and_name_bad_keys(tmp_path):
    from chewbot.errors import ChewbotError

    old = tmp_path / "old.toml"
    old.write_text("[pd]\nkp_Nm_per_rad = 10\nkd_Nms_per_rad = 0.01\n[computed_torque]\nfrequency_Hz = 30\ndamping = 1\n"
                   "[estimator]\ncutoff_Hz = 50\n")
    g = Gains.load(old)
    assert g["observer"].cutoff_Hz == Gains.load()["observer"].cutoff_Hz and "hybrid.threshold_N" in g.defaulted
    bad = tmp_path / "bad.toml"
    bad.write_text(old.read_text() + "[hybrid]\nthreshold_N = -1\n")
    with pytest.raises(ChewbotError, match=r"bad\.toml: key 'hybrid\.threshold_N': expected one positive number"):
        Gains.load(bad)
    with pytest.raises(ChewbotError, match="stiffness_min_N_per_m"):
        Gains.load(overrides={"hybrid.stiffness_min_N_per_m": 1e8})  # above the maximum, 1e7


def test_hybrid_needs_a_food_and_a_control_rate(tmp_path):
    r = runner.invoke(app, ["simulate", "--controller", "hybrid", "--out", str(tmp_path / "a")])
    assert r.exit_code == 2 and "--food" in r.output
    r = runner.invoke(app, ["simulate", "--controller", "hybrid", "--food", "cheddar", "--rate", "continuous", "--out", str(tmp_path / "b")])
    assert r.exit_code == 2 and "continuous" in r.output


def test_the_estimator_gives_back_the_food_plant_s_force_from_the_simulated_log(folder):
    # The simulated robot as a logged one: its crank angles, rates and accelerations and the torques it applied (held
    # over each tick) are what results.csv holds; the plant integrated the food's force from its state (Radau IIA,
    # the food's events located). The estimator, the plant's equations the other way round, gives that force back to
    # rounding (the forward dynamics' residual is ~1e-13 N m): 1e-6 of the peak, the issue's bound for exact rates.
    from chewbot.identification.force import estimate_angles

    r = hybrid(50e3, 20.0, 5e-3, folder)
    tab = r.table
    cols = lambda name: np.column_stack([tab[f"{name}{i}"] for i in range(1, 7)])  # noqa: E731
    e = estimate_angles(load_model("target"), tab["t"], cols("theta"), cols("tau"), rates=(cols("dtheta"), cols("ddtheta")),
                        friction=False)
    assert np.abs(e.F_B - r.simulation.force).max() <= 1e-6 * 20.0
    assert np.abs(e.N - r.simulation.N).max() <= 1e-6 * 20.0


def test_the_observer_s_compiled_tick_is_the_estimator_s_answer():
    """The observer's tick (one compiled kernel: the friction-free least squares, then Gauss-Newton steps on the
    smoothed model) against the whole-log estimator (its sign patterns and damped polish: another route to the same
    minimiser), on the default task with the model's friction and a 30 N bite at the left molar, the torques Newton-
    Euler's with the same friction: both give the force the torques were made with. The interval's ends are built so
    that its midpoint is the sample's state and its mean acceleration the sample's. 1e-9 N: rounding of the solves on
    forces of ~30 N (measured 3e-12 N)."""
    from chewbot.dynamics.bite_force import solve_states
    from chewbot.dynamics.registry import inverse_dynamics
    from chewbot.simulation.observer import tick_kernel
    from support import default_kinematics, model

    m, kin = model("target"), default_kinematics()
    force = np.zeros_like(kin.force)
    force[:, 0], force[:, 2] = 3.0, -30.0 * np.sin(np.linspace(0, 3, len(force)))**2
    kin = dataclasses.replace(kin, force=force)
    tau = inverse_dynamics(m, kin, "newton-euler", friction=True).tau
    rows = slice(None, None, 10)
    h = 1e-3
    q, dq, ddq = kin.q[rows], kin.dq[rows], kin.ddq[rows]
    u = evaluate(native(tick_kernel("target")), q, dq - ddq * h / 2, q, dq + ddq * h / 2, np.full(len(q), h), tau[rows],
                 m.molar("left"), 1.0, m.vector())[0]
    whole, _, _ = solve_states(m, kin.theta[rows], q, dq, ddq, tau[rows], side="left", friction=True, residuals=False)
    assert np.abs(u - whole).max() < 1e-9
    assert np.abs(u[:, :3] - force[rows]).max() < 1e-9
