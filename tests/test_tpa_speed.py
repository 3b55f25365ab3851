"""The texture test's machinery made fast without changing its results: the food's state and guards computed inside the
compiled step, the drives' law at a tick compiled, the gap compiled, the estimator's line search on the samples it has
not settled. Each against another route: the guards of the compiled step against the law's NumPy guards, the compiled
drive tick against the NumPy drive law, and a compression of a food by the robot, with the force estimated from its
torques, against the values the NumPy law in the loop gave before (tex-face's code, the law over the tilted face)."""

from __future__ import annotations

import numpy as np
import pytest

from chewbot.compiled.kernels import evaluate, native
from chewbot.food.geometry import gap, home_height
from chewbot.food.law import FOOD_EVENTS, NUMPY, guards, load_food
from chewbot.model import drive as drive_law
from chewbot.model.params import load_model
from chewbot.simulation.food import food_quantities_kernel
from chewbot.simulation.simulator import DRIVE, drive_tick_kernel


@pytest.mark.parametrize("name", ["cheddar", "carrot"])
def test_compiled_guards_are_the_laws(name):
    """The guards the compiled food function gives (CasADi's law) equal the law's NumPy guards at the same states, NaN
    (not armed) at the same places: intact and broken, before and past the yield, loading and unloading, the lower
    tooth tilted (beta up to 0.2 rad) and the deepest compression's tilt tilt_max of either sign (the set's slope over
    the face; the fracture read on the most compressed fibre). To 1e-12 of the guard's scale (m for the strains and
    compressions, N for the adhesion's), rounding of the same expressions."""
    model = load_model("target")
    food = load_food(name)
    f = food.vector()
    z = home_height(model, "left")
    fn = native(food_quantities_kernel(model.mechanism))
    n = 24
    rng = np.random.default_rng(7)
    q = np.column_stack([rng.uniform(-1e-3, 3e-3, n), np.zeros(n), np.zeros(n), rng.uniform(0.02, 0.2, n)])
    dq = np.column_stack([np.zeros(n), np.zeros(n), np.zeros(n), rng.uniform(-0.2, 0.2, n)])
    broken = np.tile([0.0, 1.0], n // 2)
    F_m = rng.uniform(-0.5, 0.5, n)
    delta_max0 = rng.uniform(0.0, 6e-3, n)
    tilt_max0 = rng.uniform(-0.1, 0.1, n)
    delta, ddelta, deepest, tilt_max, _, _, _, _, _, sin_tilt, compiled = evaluate(
        fn, q, dq, model.molar("left"), model.vector(), f, broken, F_m, delta_max0, tilt_max0, np.full(n, z))
    assert np.all(sin_tilt[:, 0] > 0.01)  # the faces tilt at every state
    for k in range(n):
        expected = np.array([float(np.asarray(x)) for x in guards(NUMPY, f, delta[k, 0], ddelta[k, 0], broken[k], F_m[k],
                                                                   deepest[k, 0], sin_tilt[k, 0], tilt_max[k, 0])])
        assert np.array_equal(np.isnan(compiled[k]), np.isnan(expected)), (k, compiled[k], expected)
        armed = ~np.isnan(expected)
        np.testing.assert_allclose(compiled[k][armed], expected[armed], rtol=0, atol=1e-12)
    assert compiled.shape == (n, len(FOOD_EVENTS))


def test_compiled_drive_tick_is_the_drive_law():
    """The drives at a tick, compiled, give the NumPy drive law's saturated torques, currents and crank torques (two
    different drives, rates of both signs and zero, torques beyond the limit), to 1e-12 relative: Newton's iteration in
    C and in NumPy, the same steps."""
    target = load_model("target")
    ours = drive_law.of(target)
    theirs = drive_law.NEUTRAL.__class__(rotor_inertia=4e-6, gear_ratio=43.0, efficiency=0.7, torque_constant=0.03,
                                         encoder_counts=0.0)
    tick = native(drive_tick_kernel())
    numbers = [DRIVE.pack(**{name: getattr(d, name) for name in DRIVE.names}) for d in (ours, theirs)]
    rng = np.random.default_rng(3)
    limit = 1.5
    for _ in range(20):
        tau_cmd, seen, rates = rng.normal(0, 1.0, 6), rng.normal(0, 2.0, 6), rng.normal(0, 2.0, 6)
        seen[0] = rates[1] = 0.0
        tau_k, current, applied = tick(tau_cmd, limit, seen, rates, *numbers)
        expected_tau = np.clip(tau_cmd, -limit, limit)
        expected_current = drive_law.current(ours, drive_law.motor_torque(ours, expected_tau, seen))
        expected_applied = drive_law.crank_torque(theirs, drive_law.torque_of_current(theirs, expected_current), rates)
        np.testing.assert_array_equal(tau_k, expected_tau)
        np.testing.assert_allclose(current, expected_current, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(applied, expected_applied, rtol=1e-12, atol=1e-15)


def test_compiled_gap_is_the_graphs():
    """The gap from the compiled bite point equals CasADi's graph evaluated in its virtual machine (to 1e-15 m)."""
    from chewbot.food.geometry import bite_point_function

    model = load_model("target")
    q = np.column_stack([np.linspace(0, 2e-3, 5), np.zeros(5), np.zeros(5), np.linspace(0, 0.15, 5)])
    dq = np.column_stack([np.zeros(5), np.zeros(5), np.zeros(5), np.full(5, 0.1)])
    g = gap(model, "left", q, dq)
    point, velocity, cos_tilt, sin_tilt = evaluate(bite_point_function(model.mechanism), q, dq,
                                                   np.asarray(model.molar("left"), float), model.vector())
    np.testing.assert_allclose(g["gap"], home_height(model, "left") - point[:, 2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(g["rate"], -velocity[:, 2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(g["tilt"], np.arctan2(sin_tilt[:, 0], cos_tilt[:, 0]), rtol=0, atol=1e-15)


# A compression of the cheddar by the robot under computed torque with its friction (30 % of the height found after
# 0.9 s at 5 mm/s, a 0.2 s pause: 4.1 s simulated), as the branch tex-face's code ran it at commit 4cbf52c (the food's
# law integrated over the tilted face, its guards in NumPy between the compiled steps, the drives in NumPy, the
# estimator's polish on every sample): alpha pinned, the face tilts with beta, so its edge touches at 0.557 s, not the
# centre at 0.985 s as with the law at the face's centre (main's values before the merge, at f6fb830 and 9b8b67d):
#   git archive 4cbf52c src | tar -x -C /tmp/ref, then _compression() below (its imports all exist there) run as a
#   script with PYTHONPATH=/tmp/ref/src, printing result.info["food"]["events"], the plant's peak food force, sim.q[-1],
#   the deepest compression, the RMS of sim.tau and the estimate's peak, RMS and mean force, sigma and noise.
LOOP_EVENTS = [("contact", 0.5571716266050337), ("yield", 1.1851381296245262), ("adhesion", 1.9938039989274585),
               ("contact", 2.070393844784807), ("contact", 2.5977022149209685), ("adhesion", 2.670270610171048),
               ("adhesion", 3.517510535416487), ("contact", 3.609391977106466)]
LOOP_PEAK_FORCE_N = 3.6667194962538465
LOOP_FINAL_Q = [0.0030211707794686885, 5.261654658481589e-16, -6.703980308677485e-15, 0.12234220669955281]
LOOP_DEEPEST_MM = 2.771439814210288
LOOP_TAU_RMS_NM = 0.020012402526979858


def _compression():
    from chewbot.food.tpa import settings
    from chewbot.food.geometry import molar_path_task
    from chewbot.simulation.controllers.table import controller_row
    from chewbot.simulation.options import resolve
    from chewbot.simulation.run import compute, load_models
    from chewbot.simulation.texture import estimate_from_log, simulated_log

    options = resolve(controller_row("computed-torque"), model="target", side="left", friction=True, rate=1000.0, food="cheddar")
    food = load_food("cheddar")
    model, _, _ = load_models(options)
    protocol = settings(30.0, 5.0, 0.2)
    profile = protocol.profile(food.height + protocol.approach, 0.9, 1000.0)
    t = profile.times()
    result = compute(options, task=molar_path_task(model, "left", t, *profile.path(t), name="compression of the cheddar"))
    curve, estimator = estimate_from_log(model, simulated_log(result), "left")
    return result, curve, estimator


def test_food_simulation_unchanged_from_the_numpy_loop_and_its_estimate_follows_the_plant():
    """The same compression gives the NumPy loop's events, peak force, final state and torques; the force estimated
    from the torques follows the plant's. Tolerances: the events' times 1e-12 s (located to 1e-10 s; 2e-16 s seen), the
    peak force and the torques 1e-12 relative (the law's arithmetic in C instead of NumPy: 5e-16 seen), the final
    coordinates 1e-12 m or rad (1e-22 seen). A change of the physics or of the events moves these by 1e-6 or more. The
    estimate (the robot's drive on, exact angles and the held currents): its RMS difference from the plant's force 1 %
    of the peak and its peak within 3 % (0.003 N RMS and +1.7 % seen: the smoothing window's share of the rotors'
    accelerations; 4.42 N for 3.67 N, +21 %, when each sample's torques met the window's accelerations)."""
    result, curve, estimator = _compression()
    sim, info = result.simulation, result.info["food"]
    assert [e["event"] for e in info["events"]] == [name for name, _ in LOOP_EVENTS]
    np.testing.assert_allclose([e["t"] for e in info["events"]], [t for _, t in LOOP_EVENTS], rtol=0, atol=1e-12)
    plant = sim.quantities["force"]
    assert float(plant.max()) == pytest.approx(LOOP_PEAK_FORCE_N, rel=1e-12)
    np.testing.assert_allclose(sim.q[-1], LOOP_FINAL_Q, rtol=0, atol=1e-12)
    assert info["deepest_compression_m"] * 1e3 == pytest.approx(LOOP_DEEPEST_MM, rel=1e-12)
    assert float(np.sqrt(np.mean(sim.tau**2))) == pytest.approx(LOOP_TAU_RMS_NM, rel=1e-12)
    force = np.asarray(curve["force"])
    at = np.interp(np.asarray(curve["t"]), sim.t, plant)
    assert float(np.sqrt(np.mean((force - at) ** 2))) <= 0.01 * plant.max()
    assert float(force.max()) == pytest.approx(float(plant.max()), rel=0.03)
