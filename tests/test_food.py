"""Food files, the food law in its two engines, the bite point's geometry and Bourne's measures, each against a route
of its own: the laws written out by hand from the issue's formulas, an ODE solver for the Maxwell branch, finite
differences for the path's rates, the kinematics' own workspace checks, curves whose measures are known in closed form."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from chewbot.errors import KinematicsError
from chewbot.food.geometry import gap, largest_gap, molar_path_task
from chewbot.food.law import (CASADI, NUMPY, FoodError, builtin_foods, food_from_dict, load_food, maxwell_force,
                              normal_force, tangential_force)
from chewbot.food.tpa import BLEND, protocol, tpa_measures
from chewbot.kinematics.motion import solve_kinematics

from support import model

CYLINDER = {"name": "test cylinder", "shape": "cylinder", "height_mm": 8.0, "diameter_mm": 10.0, "young_modulus_kPa": 20.0,
            "tooth_friction": 0.3}
SPHERE = {"name": "test sphere", "shape": "sphere", "height_mm": 5.0, "poisson_ratio": 0.3, "young_modulus_kPa": 3750.0,
          "tooth_friction": 0.3}


def write_food(tmp_path, **keys):
    path = tmp_path / "food.toml"
    lines = ["[food]"] + [f"{k} = {v!r}" if isinstance(v, str) else f"{k} = {v}" for k, v in keys.items()]
    path.write_text("\n".join(lines).replace("'", '"') + "\n")
    return path


# ---------------------------------------------------------------------------------------- files


def test_builtin_foods_load_and_fit_the_workspace():
    """Every built-in food reads, and a 50 % texture test fits at both sides (the start gap h0 + 1 mm reachable)."""
    foods = builtin_foods()
    assert set(foods) == {"peanut", "cheddar", "gummy", "bread", "artisynth-bolus"}
    reach = largest_gap(model("target"), "left")
    for name in foods:
        f = load_food(name)
        assert f.height + 1e-3 <= reach, name


def test_artisynth_bolus_is_its_spring():
    """ArtiSynth's FoodBolus: 10 mm, 35 N at full compression: stiffness resistance / diameter = 3.5 N/mm."""
    f = load_food("artisynth-bolus")
    assert f.height == pytest.approx(0.010)
    assert f.stiffness == pytest.approx(35.0 / 0.010, rel=1e-6)
    assert float(f.elastic(f.height)) == pytest.approx(35.0, rel=1e-6)


@pytest.mark.parametrize("change, key", [
    ({"height_m": 0.008}, "food.height_m"),                       # unit not in the file's vocabulary
    ({"poisson_ratio": 0.3}, "food.poisson_ratio"),               # inapplicable to a cylinder
    ({"young_modulus_kPa": "soft"}, "food.young_modulus_kPa"),     # not a number
    ({"young_modulus_kPa": -1.0}, "food.young_modulus_kPa"),       # out of range
    ({"fracture_strain": 1.5, "stiffness_after_fracture": 0.1}, "food.fracture_strain"),
    ({"fracture_strain": 0.3}, "food.fracture_strain"),            # without its factor
    ({"relaxation_time_s": 2.0}, "food.relaxation_time_s"),        # Maxwell branch without its modulus
    ({"shape": "cube"}, "food.shape"),
])
def test_bad_food_files_name_the_file_and_the_key(tmp_path, change, key):
    path = write_food(tmp_path, **{**CYLINDER, **change})
    with pytest.raises(FoodError) as err:
        load_food(path)
    assert str(path) in str(err.value) and key in str(err.value)


def test_sphere_refuses_a_diameter_and_needs_poisson(tmp_path):
    with pytest.raises(FoodError, match="key 'food.diameter_mm': does not apply to a sphere"):
        load_food(write_food(tmp_path, **{**SPHERE, "diameter_mm": 5.0}))
    with pytest.raises(FoodError, match="key 'food.poisson_ratio': missing key"):
        load_food(write_food(tmp_path, **{k: v for k, v in SPHERE.items() if k != "poisson_ratio"}))
    with pytest.raises(FoodError, match="key 'food.tooth_friction': missing key"):
        load_food(write_food(tmp_path, **{k: v for k, v in CYLINDER.items() if k != "tooth_friction"}))
    with pytest.raises(FoodError, match="unit is part of the key"):
        load_food(write_food(tmp_path, **{**{k: v for k, v in CYLINDER.items() if k != "height_mm"}, "height_m": 0.008}))


# ---------------------------------------------------------------------------------------- the law


def test_elastic_laws_are_the_issues_formulas():
    """Cylinder F = E A delta / h0, sphere F = 4/3 E / (1 - nu^2) sqrt(R) (delta / 2)^1.5, written out here."""
    c, s = food_from_dict({"food": CYLINDER}), food_from_dict({"food": SPHERE})
    delta = np.linspace(0, 4e-3, 9)
    assert np.allclose(c.elastic(delta), 20e3 * math.pi * 0.01**2 / 4 * delta / 8e-3, rtol=1e-14)
    hertz = 4 / 3 * 3750e3 / (1 - 0.09) * math.sqrt(2.5e-3) * (delta / 2) ** 1.5
    assert np.allclose(s.elastic(delta), hertz, rtol=1e-14)


def test_casadi_law_equals_numpy_law_and_its_jacobian_is_exact():
    """The plant's CasADi force equals the NumPy force at random states (the same source, two engines), and its
    derivative by automatic differentiation matches a central difference (1e-6 relative)."""
    f = food_from_dict({"food": {**CYLINDER, "damping_s_per_m": 20.0, "adhesion_N": 0.3, "relaxation_time_s": 3.0,
                                 "relaxation_modulus_kPa": 10.0, "fracture_strain": 0.4, "stiffness_after_fracture": 0.2}})
    v = f.vector()
    d, dd, b, Fm, vx, vy = (ca.SX.sym(n) for n in ("d", "dd", "b", "Fm", "vx", "vy"))
    Fn, Fv = normal_force(CASADI, v, d, dd, b, Fm)
    Ft = tangential_force(CASADI, v, Fn, vx, vy)
    fn = ca.Function("f", [d, dd, b, Fm, vx, vy], [Fn, Ft[0], ca.jacobian(Fn, d)])
    rng = np.random.default_rng(3)
    for _ in range(50):
        x = (rng.uniform(-1e-3, 9e-3), rng.uniform(-5e-3, 5e-3), float(rng.integers(0, 2)), rng.uniform(-0.2, 0.2),
             rng.uniform(-1e-2, 1e-2), rng.uniform(-1e-2, 1e-2))
        n_np, _ = normal_force(NUMPY, v, *x[:4])
        ft_np = tangential_force(NUMPY, v, n_np, x[4], x[5])
        n_ca, ft_ca, jac = (float(o) for o in fn(*x))
        assert n_ca == pytest.approx(float(n_np), abs=1e-15) and ft_ca == pytest.approx(float(ft_np[0]), abs=1e-15)
        h = 1e-9
        fd = (float(fn(x[0] + h, *x[1:])[0]) - float(fn(x[0] - h, *x[1:])[0])) / (2 * h)
        if abs(x[0]) > 1e-8 and abs(x[0] - f.height) > 1e-8 and abs(float(fn(*x)[0]) + f.adhesion) > 1e-6:
            assert jac == pytest.approx(fd, rel=1e-6, abs=1e-6)
    assert abs(ft_np[0]) <= f.tooth_friction * max(float(n_np), 0.0) + 1e-15  # |F_t| <= mu F_n


def test_maxwell_branch_is_its_ode():
    """The closed form over a step equals SciPy's solve_ivp of dF_m/dt = rho d(bF_e)/dt - F_m / tau for an elastic
    force growing linearly (1e-9 relative), whatever the step."""
    f = food_from_dict({"food": {**CYLINDER, "relaxation_time_s": 0.7, "relaxation_modulus_kPa": 15.0}})
    rho, tau = 15.0 / 20.0, 0.7
    rate = 3.0  # N/s of b F_e
    sol = solve_ivp(lambda t, y: [rho * rate - y[0] / tau], (0, 2.0), [0.4], rtol=1e-12, atol=1e-14, dense_output=True)
    for t in (1e-6, 0.01, 0.5, 2.0):
        closed = maxwell_force(NUMPY, f.vector(), 0.4, 1.0, 1.0 + rate * t, t)
        assert float(closed) == pytest.approx(sol.sol(t)[0], rel=1e-9)


# ---------------------------------------------------------------------------------------- geometry


def test_molar_path_follows_its_gap_with_exact_rates():
    """The point path's poses put the bite point at its gap (through the kinematics' own points), with alpha = 0 and
    rates equal to central differences of the poses (to their truncation error h^2/6 times the third derivative,
    about 50 rad/s^3 in the blends: 1e-5 rad/s at 1 kHz), the gap's rate through the bite point's velocity to
    1e-12 m/s."""
    m = model("target")
    p = protocol(0.008, 50, 2, 0.5)
    t = p.times()[:1500]
    g, dg, ddg = p.path(t)
    task = molar_path_task(m, "right", t, g, dg, ddg)
    kin = solve_kinematics(m, task)
    assert np.allclose(kin.points["B_R"][:, 2], m.molar("right")[2] - g, atol=1e-12)
    assert np.allclose(kin.points["B_R"][:, :2], m.molar("right")[:2], atol=1e-12)
    assert np.all(task.q[:, 2] == 0)
    dt = t[1] - t[0]
    fd = (task.q[2:] - task.q[:-2]) / (2 * dt)
    assert np.max(np.abs(task.dq[1:-1] - fd)) < 1e-5
    assert np.allclose(gap(m, "right", task.q, task.dq)["rate"], dg, atol=1e-12)


def test_largest_gap_is_the_workspace_edge():
    """Just below the largest gap the kinematics passes its workspace checks; just above, the path or the checks fail."""
    m = model("target")
    edge = largest_gap(m, "left")
    ok = molar_path_task(m, "left", [0, 1], [edge - 1e-4] * 2, [0, 0], [0, 0])
    solve_kinematics(m, ok)
    with pytest.raises(KinematicsError):
        solve_kinematics(m, molar_path_task(m, "left", [0, 1], [edge + 1e-4] * 2, [0, 0], [0, 0]))


# ---------------------------------------------------------------------------------------- the protocol and the measures


def test_protocol_turns_at_the_compression_at_the_speed():
    p = protocol(0.010, 50, 2, 2)
    t = np.linspace(0, p.duration, 200001)
    g, dg, ddg = p.path(t)
    turns = p.schedule()[0][[1, 4]]
    assert np.allclose(p.path(turns)[0], 0.005, atol=1e-15) and np.allclose(p.path(turns)[1], 0, atol=1e-15)
    assert g.min() >= 0.005 - 1e-15
    assert g[0] == pytest.approx(0.011) and g[-1] == pytest.approx(0.011, abs=1e-12)
    assert np.max(np.abs(dg)) == pytest.approx(0.002, rel=1e-12)
    h = t[1] - t[0]
    # central differences to their truncation error h^2/6 max abs(g''') = 8e-9 m/s at this h
    assert np.allclose(np.gradient(g, h)[1:-1], dg[1:-1], atol=2e-8)
    assert np.allclose(np.gradient(dg, h)[1:-1], ddg[1:-1], atol=2e-3 * 0.002 / BLEND)


def test_measures_of_analytic_curves():
    """Closed-form curves on the protocol's path (1e-4: trapezoids at 1 kHz): elastic (all ratios 1), Kelvin-Voigt at
    constant speed (resilience (1 - c) / (1 + c), c = 3/2 alpha v), brittle (fracturability the fracture force,
    cohesiveness from the areas of its law) and sticky (adhesiveness the pull's work)."""
    p = protocol(0.010, 50, 2, 2)
    t = p.times()
    g, dg, _ = p.path(t)
    delta = np.maximum(p.height - g, 0)
    k = 1000.0
    m = tpa_measures(t, g, k * delta)
    assert m["hardness_N"] == pytest.approx(k * 0.005, rel=1e-6)
    for key in ("cohesiveness", "springiness", "resilience"):
        assert m[key] == pytest.approx(1.0, abs=1e-3)
    assert m["fracturability_N"] is None and m["adhesiveness_mJ"] == 0
    # Kelvin-Voigt: the resilience at constant speed; the blends at the turns move it by less than 2e-3
    c = 0.2
    kv = k * delta * (1 - c * dg / 0.002)  # d(delta)/dt = -dg
    assert tpa_measures(t, g, kv)["resilience"] == pytest.approx((1 - c) / (1 + c), abs=2e-3)
    # brittle: breaks at delta_f to b times its stiffness, for good
    df, b = 0.003, 0.2
    broken = np.maximum.accumulate(delta >= df)
    F = k * delta * np.where(broken, b, 1.0)
    mb = tpa_measures(t, g, F)
    dm = 0.005
    A1 = 0.5 * k * df**2 + 0.5 * b * k * (dm**2 - df**2) + 0.5 * b * k * dm**2
    assert mb["fracturability_N"] == pytest.approx(k * df, rel=1e-3)
    assert mb["cohesiveness"] == pytest.approx(b * k * dm**2 / A1, rel=1e-3)
    # sticky: a constant pull of 0.5 N over the last millimetre of the first withdrawal
    one = np.arange(t.size) < t.size // 2
    pull = np.where(one & (dg > 0) & (delta > 0) & (delta < 1e-3), -0.5, 0.0)
    assert tpa_measures(t, g, np.where(pull < 0, pull, k * delta))["adhesiveness_mJ"] == pytest.approx(0.5, rel=2e-3)
