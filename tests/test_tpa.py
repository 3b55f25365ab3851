"""The texture analyser's protocol, its profile, Bourne's measures in both readings and the ideal texture analyser,
each against a route of its own: force curves built here whose measures are known in closed form, the profile's
exact rates against finite differences, the Maxwell branch against SciPy's ODE solver, the crushed sample's
springiness against the issue's definition (r at a constant compression target)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from chewbot.food.calibration import FRACTIONS, calibrations, compare, fit, reference_table, table
from chewbot.food.law import food_from_dict
from chewbot.food.tpa import (BLEND, DEFINITIONS, HOLD, MEASURES, RATIO_TOLERANCE, Protocol, TpaError, analyse, ideal_test,
                              protocol_checks, settings)

CYLINDER = {"name": "test cylinder", "shape": "cylinder", "height_mm": 10.0, "diameter_mm": 10.0, "young_modulus_kPa": 100.0,
            "tooth_friction": 0.3}
K = 100e3 * math.pi * 0.01**2 / 4 / 0.01  # E A / h0 of CYLINDER (N/m)


def food(**extra):
    return food_from_dict({"food": {**CYLINDER, **extra}})


def curve(protocol=Protocol(pause=1.0), start=0.011, trigger=None):
    """A profile whose trigger is where the approach reaches h0 = 10 mm (``trigger``: or at this time), its samples and
    the compression delta = h0 - g."""
    t_tr = HOLD + protocol.blend / 2 + (start - 0.010) / protocol.pre_test_speed if trigger is None else trigger
    p = protocol.profile(start, t_tr)
    t = p.times()
    g, dg, _ = p.path(t)
    return p, t, g, dg, 0.010 - g


# ---------------------------------------------------------------------------------------- the protocol


@pytest.mark.parametrize("kwargs, message", [
    ({"compression_percent": 0.5}, "did you mean 50 %?"),
    ({"compression_percent": 100.0}, "between 0 and 100"),
    ({"compression_percent": 50.0, "distance_mm": 3.0}, "give one"),
    ({"compression_percent": None, "distance_mm": -1.0}, "--distance -1"),
    ({"test_speed_mm_s": 0.0}, "--speed 0"),
    ({"pre_test_speed_mm_s": -1.0}, "--pre-test-speed -1"),
    ({"post_test_speed_mm_s": float("nan")}, "--post-test-speed nan"),
    ({"trigger_force_N": 0.0}, "--trigger-force 0"),
    ({"pause_s": -1.0}, "--pause -1"),
    ({"compression_percent": None}, "give one"),
])
def test_settings_refuse_what_a_texture_analyser_would_not_run(kwargs, message):
    with pytest.raises(TpaError, match=message.replace("?", r"\?")):
        settings(**kwargs)


def test_settings_in_si():
    p = settings(40, 3, 1.5, pre_test_speed_mm_s=0.5, trigger_force_N=0.1)
    assert (p.compression, p.test_speed, p.post_test_speed, p.pre_test_speed, p.pause, p.trigger_force) == \
        (0.4, 3e-3, 3e-3, 0.5e-3, 1.5, 0.1)
    d = settings(None, distance_mm=4.0)
    assert d.distance == 4e-3 and d.compression is None and d.target_gap(0.010) == pytest.approx(0.006)


def test_profile_holds_its_speeds_and_stops_exactly_where_it_must():
    """From the trigger (at h_t, here 9.8 mm) the profile compresses at the test speed to h_t (1 - c) exactly, returns
    at the post-test speed to h_t exactly, pauses there, bites again to the same depth and returns to its start; each
    stroke at its speed between its changes of speed; the path is C^2, its rates the exact derivatives (central
    differences at 10 kHz to their truncation error, h^2 / 6 max |g'''| = 8e-9 m/s and 4e-4 m/s^2)."""
    pr = Protocol(pre_test_speed=1e-3, test_speed=3e-3, post_test_speed=2e-3, compression=0.4, pause=0.7)
    p, _, _, _, _ = curve(pr, trigger=HOLD + BLEND / 2 + 1.2)  # the approach covers 1.2 mm: h_t = 9.8 mm
    assert p.trigger_gap == pytest.approx(0.0098, abs=1e-15)
    stops = np.array(p.stops)
    g, dg, _ = p.path(stops)
    assert np.allclose(g, [0.0098 * 0.6, 0.0098, 0.0098 * 0.6, 0.011], atol=1e-15) and np.allclose(dg, 0, atol=1e-15)
    for a, b, speed in p.held():
        _, v, _ = p.path(np.linspace(a, b, 50))
        assert np.allclose(v, speed, rtol=1e-12)
    assert [s for _, _, s in p.held()] == [-3e-3, 2e-3, -3e-3, 2e-3]
    assert p.stops[2] - p.stops[1] >= 0.7  # the pause, at rest at h_t
    _, v_pause, _ = p.path(np.linspace(p.stops[1], p.stops[1] + 0.7, 20))
    assert np.all(v_pause == 0)
    t = np.arange(0, p.duration, 1e-4)
    g, dg, ddg = p.path(t)
    assert g.min() >= 0.0098 * 0.6 - 1e-15
    assert np.allclose(np.gradient(g, t)[1:-1], dg[1:-1], atol=2e-8)
    assert np.allclose(np.gradient(dg, t)[1:-1], ddg[1:-1], atol=1e-3)


def test_profile_refuses_strokes_shorter_than_their_changes_of_speed():
    with pytest.raises(TpaError, match="lower the speed"):
        curve(Protocol(test_speed=0.2, compression=0.01))
    with pytest.raises(TpaError, match="more than the sample's height"):
        curve(Protocol(compression=None, distance=0.02))


# ---------------------------------------------------------------------------------------- the measures


def test_measures_of_an_elastic_curve():
    """F = k delta: hardness k delta_deepest; cohesiveness, springiness, resilience and both peak readings 1 (1e-4:
    trapezoids at 1 kHz across the contact kink); no fracture, no adhesion; the definitions are MEASURES' in words."""
    p, t, g, _, delta = curve()
    a = analyse(t, g, K * np.maximum(delta, 0), contact_force=0.01)
    m = a.measures
    assert list(m) == list(MEASURES)
    assert m["hardness_N"] == pytest.approx(K * 0.005, rel=1e-8)  # the sample nearest the turn, where the probe rests
    for key in ("cohesiveness", "springiness", "resilience", "springiness_at_peak", "resilience_at_peak"):
        assert m[key] == pytest.approx(1.0, abs=1e-4), key
    assert m["fracturability_N"] is None and m["adhesiveness_mJ"] == 0
    assert m["gumminess_N"] == pytest.approx(m["hardness_N"] * m["cohesiveness"], rel=1e-15)
    assert set(a.definitions) == set(MEASURES) | {"areas"} and "0.01 N (the trigger force)" in a.definitions["springiness"]
    assert all(c.passed for c in a.checks) and [c.name for c in a.checks] == [
        "cohesiveness-range", "springiness-range", "resilience-range"]
    assert a.anchors["deepest_1"]["gap_mm"] == pytest.approx(5.0, abs=1e-8)
    assert a.anchors["areas_mJ"]["first_compression"] == pytest.approx(K * 0.005**2 / 2 * 1e3, rel=1e-4)


def test_resilience_of_a_kelvin_voigt_curve():
    """F = k delta (1 + c d(delta)/dt / v) at the held speed v: the work returned over the work taken is
    (1 - c) / (1 + c); the changes of speed at the turn (the damping fades while the probe stops) move it by less than
    2e-3. The fading force is no break: no fracturability."""
    c = 0.2
    _, t, g, dg, delta = curve()
    F = K * np.maximum(delta, 0) * (1 - c * dg / 2e-3)
    m = analyse(t, g, F, contact_force=0.01).measures
    assert m["resilience"] == pytest.approx((1 - c) / (1 + c), abs=2e-3)
    assert m["fracturability_N"] is None


def test_measures_of_a_brittle_curve():
    """Breaks at delta_f to b k for good (its height kept): fracturability k delta_f; A1 = k (df^2 / 2 + b (dm^2 -
    df^2) / 2 + b dm^2 / 2), A2 = b k dm^2; resilience = b dm^2 / (df^2 + b (dm^2 - df^2)); the macro's readings at the
    peak force (the fracture in the first bite, the deepest point in the second): springiness_at_peak = (dm - c2) /
    (df - c1) and resilience_at_peak = b (2 dm^2 - df^2) / df^2, c1, c2 the compressions at contact; to 1e-3
    (trapezoids across the fracture, 2 um apart at 1 kHz)."""
    df, dm, b, Fc = 0.004, 0.005, 0.3, 0.01
    _, t, g, _, delta = curve()
    broken = np.maximum.accumulate(delta >= df)
    F = K * np.maximum(delta, 0) * np.where(broken, b, 1.0)
    m = analyse(t, g, F, contact_force=Fc).measures
    A1 = df**2 / 2 + b * (dm**2 - df**2) / 2 + b * dm**2 / 2
    assert m["hardness_N"] == pytest.approx(K * df, rel=1e-3) and m["fracturability_N"] == pytest.approx(K * df, rel=1e-3)
    assert m["cohesiveness"] == pytest.approx(b * dm**2 / A1, rel=1e-3)
    assert m["resilience"] == pytest.approx(b * dm**2 / (df**2 + b * (dm**2 - df**2)), rel=1e-3)
    c1, c2 = Fc / K, Fc / (b * K)
    assert m["springiness"] == pytest.approx((dm - c2) / (dm - c1), rel=1e-4)
    assert m["springiness_at_peak"] == pytest.approx((dm - c2) / (df - c1), rel=1e-3)
    assert m["resilience_at_peak"] == pytest.approx(b * (2 * dm**2 - df**2) / df**2, rel=2e-3)
    assert m["springiness_at_peak"] > 1  # the macro's reading of a fracture, unchecked
    assert m["gumminess_N"] == pytest.approx(K * df * b * dm**2 / A1, rel=1e-3)
    assert m["chewiness_N"] == pytest.approx(K * df * b * dm**2 / A1 * (dm - c2) / (dm - c1), rel=1e-3)


def test_measures_of_a_crushed_curve():
    """Breaks at delta_f and is crushed: unloaded height h_c = h0 - dm (1 - r), stiffness b E A / h_c beyond it. The
    second bite meets it dm (1 - r) deeper: springiness = (r dm - c2) / (dm - c1); cohesiveness = the crushed sample's
    works over the first bite's, in closed form; to 1e-3."""
    df, dm, b, r, Fc = 0.002, 0.005, 0.8, 0.1, 0.01
    _, t, g, _, delta = curve()
    broken = np.maximum.accumulate(delta >= df)
    deepest = np.maximum.accumulate(np.maximum(delta, 0))
    h_c = 0.010 - deepest * (1 - r)
    k_c = b * K * 0.010 / h_c
    F = np.where(broken, k_c * np.maximum(delta - (0.010 - h_c), 0), K * np.maximum(delta, 0))
    m = analyse(t, g, F, contact_force=Fc).measures
    kc = b * K * 0.010 / (0.010 - dm * (1 - r))
    c1, c2 = Fc / K, Fc / kc
    assert m["springiness"] == pytest.approx((r * dm - c2) / (dm - c1), rel=1e-4)
    # loading after the fracture: F = b K h0 r delta / (h0 - (1 - r) delta); its work in closed form
    q = (1 - r) / 0.010
    loading = b * K * r * ((-math.log(1 - q * dm) - q * dm) - (-math.log(1 - q * df) - q * df)) / q**2
    A1 = K * df**2 / 2 + loading + kc * (r * dm) ** 2 / 2
    assert m["cohesiveness"] == pytest.approx(kc * (r * dm) ** 2 / A1, rel=1e-3)
    assert m["springiness"] < 0.1  # a food scientist's fractured sample: fragments


def test_adhesiveness_is_the_pull_off_work():
    """A constant pull of 0.5 N over the last millimetre of the first withdrawal: 0.5 mJ (2e-3: the trapezoids at the
    pull's ends)."""
    _, t, g, dg, delta = curve()
    one = np.arange(t.size) < t.size // 2
    pull = np.where(one & (dg > 0) & (delta > 0) & (delta < 1e-3), -0.5, 0.0)
    m = analyse(t, g, np.where(pull < 0, pull, K * np.maximum(delta, 0)), contact_force=0.01).measures
    assert m["adhesiveness_mJ"] == pytest.approx(0.5, rel=2e-3)


def test_energy_readings_outside_zero_one_fail_their_check():
    """A curve no passive sample makes under a constant target: the second bite goes 0.5 mm deeper than the first
    (springiness 5.5 / 5 = 1.1, cohesiveness 1.21): their checks fail, naming the measure, its value and the sample of
    the second bite's deepest point; resilience passes; a second bite 0.4 % harder (within the tolerance) passes."""
    p, t, g, _, delta = curve()
    second = np.arange(t.size) > np.argmax(t >= p.stops[1])
    deeper = g - 0.5e-3 * second * np.clip((p.trigger_gap - g) / (p.trigger_gap - p.deepest_gap), 0, None)
    a = analyse(t, deeper, K * np.maximum(0.010 - deeper, 0), contact_force=0.01, label="plant")
    failed = {c.name: c for c in a.checks if c.passed is False}
    assert set(failed) == {"plant-cohesiveness-range", "plant-springiness-range"}
    c = failed["plant-springiness-range"]
    assert a.measures["springiness"] == pytest.approx(1.1, rel=1e-3)
    assert c.fails_run and c.samples == 1 and c.worst["value"] == a.measures["springiness"]
    assert c.first_sample["index"] == a.anchors["deepest_2"]["index"] and "1.1" in c.message
    assert a.checks[2].passed  # resilience
    ok = analyse(t, g, K * np.maximum(delta, 0) * np.where(second, 1.0 + 0.8 * RATIO_TOLERANCE, 1.0), contact_force=0.01)
    assert all(c.passed for c in ok.checks)
    assert set(ok.as_dict()["checks"][0]) == {"name", "passed", "samples", "first_sample", "worst", "message", "severity"}


def test_protocol_checks():
    """The profile itself holds its protocol; a bite 2 % short of its compression fails ``compression-reached``, a
    stroke 3 % slow fails ``speed-held``."""
    p, t, g, dg, delta = curve(Protocol(pause=1.0))
    F = K * np.maximum(delta, 0)
    assert all(c.passed for c in protocol_checks(t, g, F, p, rate=dg))
    short = np.maximum(g, p.deepest_gap + 0.02 * (p.trigger_gap - p.deepest_gap))  # stops 2 % short of the target
    failed = [c.name for c in protocol_checks(t, short, F, p) if not c.passed]
    assert failed == ["compression-reached"]
    slow = dg * np.where((t > p.held()[0][0]) & (t < p.held()[0][1]), 0.97, 1.0)
    checks = protocol_checks(t, g, F, p, rate=slow)
    assert [c.passed for c in checks] == [True, False] and "first compression" in checks[1].message


# ---------------------------------------------------------------------------------------- the ideal texture analyser


def test_ideal_analyser_on_an_elastic_cylinder():
    """The trigger where k (h0 - g) reaches the trigger force (the exact time); the deepest gap h_t (1 - c); hardness
    k (h0 - h_t (1 - c)); the energy readings 1 within 2e-4."""
    pr = Protocol(pause=1.0)
    r = ideal_test(food(), pr)
    h_t = 0.010 - pr.trigger_force / K
    assert r.profile.trigger_gap == pytest.approx(h_t, abs=1e-13)
    assert r.measures["hardness_N"] == pytest.approx(K * (0.010 - 0.5 * h_t), rel=1e-9)
    for key in ("cohesiveness", "springiness", "resilience"):
        assert r.measures[key] == pytest.approx(1.0, abs=2e-4)
    assert r.events[0]["event"] == "trigger"


def test_ideal_analyser_kelvin_voigt_and_fracture():
    """Hunt-Crossley damping: resilience (1 - c) / (1 + c), c = 3/2 alpha v (2e-3 for the turn). A brittle sample: the
    fracture at its exact strain (an event, two samples at its time), the fracturability its fracture force to 1e-9."""
    c = 0.2
    r = ideal_test(food(damping_s_per_m=c / (1.5 * 2e-3)), Protocol(pause=1.0))
    assert r.measures["resilience"] == pytest.approx((1 - c) / (1 + c), abs=2e-3)
    b = food(fracture_strain=0.3, stiffness_after_fracture=0.5)
    r = ideal_test(b, Protocol(pause=1.0))
    fracture = [e for e in r.events if e["event"] == "fracture"]
    assert len(fracture) == 1 and fracture[0]["delta_m"] == pytest.approx(0.003, rel=1e-12)
    assert r.measures["fracturability_N"] == pytest.approx(b.fracture_force, rel=1e-9)


@pytest.mark.parametrize("r_", [0.1, 0.3])
def test_crushed_sample_springs_back_by_r(r_):
    """The issue's test: a crushing sample's springiness is r (within 0.02) at a constant compression target."""
    crushing = food(fracture_strain=0.2, stiffness_after_fracture=1.0, recovery_after_fracture=r_)
    assert ideal_test(crushing, Protocol(pause=1.0)).measures["springiness"] == pytest.approx(r_, abs=0.02)


def test_ideal_analysers_maxwell_branch_is_its_ode():
    """The Maxwell branch along the test (exact steps between samples) against SciPy's solve_ivp of dF_m/dt = rho
    d(b F_e)/dt - F_m / tau on the same path (b F_e = k max(delta, 0), intact), to 1e-6 of the peak force: the steps
    are exact for b F_e linear between samples, the path's curvature at the changes of speed leaves less."""
    tau, Em = 0.8, 40.0
    sample = food(relaxation_time_s=tau, relaxation_modulus_kPa=Em)
    r = ideal_test(sample, Protocol(pause=1.0))
    rho = Em / 100.0

    def rhs(t, y):
        g, dg, _ = r.profile.path(np.array([t]))
        rate = K * (-dg[0]) if g[0] < 0.010 else 0.0
        return [rho * rate - y[0] / tau]

    sol = solve_ivp(rhs, (0, r.t[-1]), [0.0], rtol=1e-10, atol=1e-12, dense_output=True, max_step=0.01)
    assert np.max(np.abs(sol.sol(r.t)[0] - r.state["F_m"])) < 1e-6 * r.measures["hardness_N"]


def test_small_compressions_and_tilted_faces():
    """A 10 % test (its bites shallower than the approach) is two bites; a cylinder between faces tilted by 3 degrees
    triggers earlier (its edge touches first: the trigger is found on the integrated law) and, in full contact at the
    deepest point, reads the same hardness as between parallel faces for the same deepest gap (the linear law's
    integral is the centre's compression times the area)."""
    r = ideal_test(food(), Protocol(compression=0.1, pause=0.5))
    assert r.measures["springiness"] == pytest.approx(1.0, abs=1e-3)
    flat = ideal_test(food(), Protocol(pause=0.5))
    tilted = ideal_test(food(), Protocol(pause=0.5), tilt=math.radians(3))
    assert tilted.profile.trigger_gap > flat.profile.trigger_gap
    assert tilted.measures["hardness_N"] == pytest.approx(K * (0.010 - tilted.profile.deepest_gap), rel=1e-9)


def test_a_third_bite_is_refused():
    p, t, g, _, delta = curve()
    third = np.concatenate([g, g[t.size // 2:]])
    with pytest.raises(TpaError, match="two deepest points"):
        analyse(np.arange(third.size) * 1e-3, third, K * np.maximum(0.010 - third, 0))


def test_ideal_analyser_refuses_a_sample_that_never_triggers():
    with pytest.raises(TpaError, match="trigger force"):
        ideal_test(food(young_modulus_kPa=0.001), Protocol(trigger_force=5.0))


def test_definitions_cover_the_measures():
    assert set(DEFINITIONS) == set(MEASURES)


# ---------------------------------------------------------------------------------------- the built-in foods' calibration


def test_builtin_foods_give_their_published_values():
    """The ideal analyser with each published protocol gives the published values to 1e-4 (the fitted values are
    written with five significant digits, which moves them by up to 3e-5)."""
    entries = calibrations()
    assert {e.name for e in entries} >= {"carrot", "cheddar", "gelatin-gel", "peanut"}
    for e in entries:
        for key, rel in compare(e).relative.items():
            assert abs(rel) < 1e-4, (e.name, key, rel)


@pytest.mark.parametrize("name", ["carrot", "cheddar", "gelatin-gel", "peanut"])
def test_fitted_values_are_the_fit(name):
    """Fitted from 20 % off, the fit returns to the food file's values (to 1e-3: the fit's residuals are below 1e-9,
    the file's values rounded to five digits); the file marks them, and only them, fitted."""
    from chewbot.food.law import builtin_foods

    entry = next(e for e in calibrations() if e.name == name)
    here = compare(entry).values
    fitted, _ = fit(entry, start={k: v * (0.8 if v * 1.2 > 1 or k not in FRACTIONS else 1.2) for k, v in here.items()})
    for k, v in here.items():
        assert fitted.values[k] == pytest.approx(v, rel=1e-3), k
    text = builtin_foods()[name].read_text()
    food_table = text.split("[food]", 1)[1].split("\n[", 1)[0]  # a [comminution] table has fitted keys of its own
    marked = {line.split("=")[0].strip() for line in food_table.splitlines() if "# fitted" in line}
    assert marked == set(entry.fitted)


def test_docs_show_the_calibration():
    """docs/food.md's tables, published values beside chewbot's and the built-in foods under a texture analyser's
    default protocol, are the ones chewbot.food.calibration computes."""
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "food.md").read_text(encoding="utf-8")
    for row in table() + reference_table():
        assert row in page, row
