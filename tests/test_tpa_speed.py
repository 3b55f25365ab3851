"""The texture test's machinery made fast without changing its results: the food's state and guards computed inside the
compiled step, the drives' law at a tick compiled, the gap compiled, the estimator's line search on the samples it has
not settled. Each against another route: the guards of the compiled step against the law's NumPy guards, the compiled
drive tick against the NumPy drive law, and a whole texture test against the values main's code gave before (the NumPy
law in the loop)."""

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
from chewbot.simulation.texture import resolve_tpa, run_tpa


def test_compiled_guards_are_the_laws():
    """The guards the compiled food function gives (CasADi's law) equal the law's NumPy guards at the same states, NaN
    (not armed) at the same places: intact and broken, before and past the yield, loading and unloading. To 1e-12 of
    the guard's scale (m for the strains and compressions, N for the adhesion's), rounding of the same expressions."""
    model = load_model("target")
    food = load_food("cheddar")
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
    delta, ddelta, deepest, _, _, _, _, _, compiled = evaluate(fn, q, dq, model.molar("left"), model.vector(), f, broken, F_m,
                                                               delta_max0, np.full(n, z))
    for k in range(n):
        expected = np.array([float(np.asarray(x)) for x in guards(NUMPY, f, delta[k, 0], ddelta[k, 0], broken[k], F_m[k],
                                                                   deepest[k, 0])])
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
    point, velocity, _ = evaluate(bite_point_function(model.mechanism), q, dq, np.asarray(model.molar("left"), float),
                                  model.vector())
    np.testing.assert_allclose(g["gap"], home_height(model, "left") - point[:, 2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(g["rate"], -velocity[:, 2], rtol=0, atol=1e-15)


# A texture test of the cheddar (20 %, 5 mm/s, 0.5 s pause: 3.5 s simulated) as main's code ran it at commit f6fb830,
# the food's law and guards in NumPy between the compiled steps, the drives in NumPy, the polish on every sample:
#   git archive f6fb830 src | tar -x -C /tmp/main && PYTHONPATH=/tmp/main/src python -c "from chewbot.simulation.texture
#   import resolve_tpa, run_tpa; r = run_tpa(resolve_tpa('cheddar', compression=20, speed=5, pause=0.5));
#   print(r.record()['plant'], r.record()['estimated'], r.record()['events'])"
MAIN_PLANT = {"hardness_N": 2.8088725626870374, "cohesiveness": 0.7898382512355615, "springiness": 0.7577008004341148,
              "resilience": 0.674771993187649, "gumminess_N": 2.2185549928562796, "chewiness_N": 1.6810008938943048,
              "springiness_at_peak": 0.7577421728165527, "resilience_at_peak": 0.6753383404726455}
MAIN_ESTIMATED = {"hardness_N": 3.5150799898430396, "fracturability_N": 0.5856724881890062, "cohesiveness": 0.7941668687914529,
                  "springiness": 0.8155696193657963, "resilience": 0.714927890110038, "adhesiveness_mJ": 0.024781732101228957,
                  "gumminess_N": 2.791560069085139, "chewiness_N": 2.2767115829805227,
                  "springiness_at_peak": 0.8153524225138538, "resilience_at_peak": 0.7165408148187079}
MAIN_EVENTS = [("contact", 1.225), ("yield", 1.4676678154501606), ("turn", 1.6989580240426334), ("adhesion", 2.028633417805459),
               ("contact", 2.0374080017318144), ("contact", 2.7547273521654922), ("adhesion", 2.762308881610094),
               ("adhesion", 3.421030886331837), ("contact", 3.4351411644264847)]
MAIN_TRIGGER_S = 1.2533343619277268


def test_texture_test_unchanged_from_mains():
    """The same test gives main's measures, events and trigger. Tolerances: the plant's measures 1e-9 relative (the
    law's arithmetic in C instead of NumPy changes the state by rounding, 1e-15 relative seen; a change of the physics
    moves them by 1e-6 or more); the estimated ones 1e-8 (the estimator's Gauss-Newton stops at its step count, so the
    torques' rounding moves it by up to 3e-11 seen); the events' times 1e-9 s (located to 1e-10 s); the trigger 1e-12
    s (interpolated between two ticks of the same states); the adhesiveness of the plant exactly zero (cheddar has
    none)."""
    result = run_tpa(resolve_tpa("cheddar", compression=20, speed=5, pause=0.5))
    record = result.record()
    for key, value in MAIN_PLANT.items():
        assert record["plant"][key] == pytest.approx(value, rel=1e-9), key
    assert record["plant"]["fracturability_N"] is None and record["plant"]["adhesiveness_mJ"] == 0.0
    for key, value in MAIN_ESTIMATED.items():
        assert record["estimated"][key] == pytest.approx(value, rel=1e-8), key
    assert [e["event"] for e in record["events"]] == [name for name, _ in MAIN_EVENTS]
    np.testing.assert_allclose([e["t"] for e in record["events"]], [t for _, t in MAIN_EVENTS], rtol=0, atol=1e-9)
    assert record["protocol"]["trigger_time_s"] == pytest.approx(MAIN_TRIGGER_S, abs=1e-12)
    assert all(c["passed"] is not False for c in record["checks"])
