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
from chewbot.food.law import (CASADI, NUMPY, FoodError, builtin_foods, face_integrals, food_from_dict, fracture_state,
                              guards, load_food, loaded_force, maxwell_force, normal_force, permanent_set,
                              pressure_centre, tangential_force)
from chewbot.food.tpa import protocol
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
    assert set(foods) == {"peanut", "cheddar", "gummy", "bread", "artisynth-bolus", "carrot", "gelatin-gel"}
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
    ({"recovery_after_fracture": 0.2}, "food.recovery_after_fracture"),  # a crushed height without a fracture
    ({"fracture_strain": 0.3, "stiffness_after_fracture": 0.1, "recovery_after_fracture": 1.2},
     "food.recovery_after_fracture"),                             # out of [0, 1]
    ({"yield_strain": 0.1}, "food.yield_strain"),                  # permanent set without its share
    ({"plastic_fraction": 0.5}, "food.plastic_fraction"),
    ({"yield_strain": 0.0, "plastic_fraction": 0.5}, "food.yield_strain"),   # must be > 0
    ({"yield_strain": 0.1, "plastic_fraction": 1.5}, "food.plastic_fraction"),
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


@pytest.mark.parametrize("base", [CYLINDER, SPHERE], ids=["cylinder", "sphere"])
def test_casadi_law_equals_numpy_law_and_its_jacobian_is_exact(base):
    """The plant's CasADi force equals the NumPy force at random states, crushed, plastic and tilted included (the same
    source, two engines), and its derivatives by automatic differentiation in the compression, the deepest compression
    so far and the tilt match central differences (1e-6 relative) away from the law's kinks."""
    f = food_from_dict({"food": {**base, "damping_s_per_m": 20.0, "adhesion_N": 0.3, "relaxation_time_s": 3.0,
                                 "relaxation_modulus_kPa": 10.0, "fracture_strain": 0.4, "stiffness_after_fracture": 0.2,
                                 "recovery_after_fracture": 0.3, "yield_strain": 0.1, "plastic_fraction": 0.4}})
    v = f.vector()
    d, dd, b, Fm, dm, st, vx, vy = (ca.SX.sym(n) for n in ("d", "dd", "b", "Fm", "dm", "st", "vx", "vy"))
    Fn, Fv = normal_force(CASADI, v, d, dd, b, Fm, dm, st)
    Ft = tangential_force(CASADI, v, Fn, vx, vy)
    fn = ca.Function("f", [d, dd, b, Fm, dm, st, vx, vy], [Fn, Ft[0], ca.jacobian(Fn, ca.vertcat(d, dm, st))])
    rng = np.random.default_rng(3)
    h0 = f.height
    checked = 0
    for _ in range(200):
        x = [rng.uniform(-1e-3, 1.1 * h0), rng.uniform(-5e-3, 5e-3), float(rng.integers(0, 2)), rng.uniform(-0.2, 0.2),
             0.0, rng.choice([0.0, rng.uniform(0, 0.1)]), rng.uniform(-1e-2, 1e-2), rng.uniform(-1e-2, 1e-2)]
        x[4] = max(x[0], 0.0) + rng.uniform(0, 0.3 * h0)  # the deepest so far is at least the compression
        n_np, _ = normal_force(NUMPY, v, *x[:6])
        ft_np = tangential_force(NUMPY, v, n_np, x[6], x[7])
        n_ca, ft_ca, jac = fn(*x)
        assert float(n_ca) == pytest.approx(float(n_np), rel=1e-13, abs=1e-15)
        assert float(ft_ca) == pytest.approx(float(ft_np[0]), rel=1e-13, abs=1e-15)
        assert abs(float(ft_np[0])) <= f.tooth_friction * max(float(n_np), 0.0) + 1e-15  # |F_t| <= mu F_n
        s = float(permanent_set(NUMPY, v, x[2], x[4]))
        u, c = x[0] - s, (f.diameter or 0) / 2 * x[5]
        kinks = [u + c, u - c, x[0] - h0, x[4] - 0.1 * h0, float(fn(*x)[0]) + f.adhesion, u]
        if min(abs(k) for k in kinks[:-2]) < 1e-4 or abs(kinks[-2]) < 1e-3 or abs(kinks[-1]) < 1e-4:
            continue  # the differences' truncation near a kink (Hertz's u^1.5 curves within 0.1 mm of it)
        checked += 1
        for i, j in enumerate((0, 4, 5)):
            h = 1e-7  # central differences: truncation (h^2 / 6) F''' and rounding 1e-16 F / h below 1e-6 of the slope
            up, down = list(x), list(x)
            up[j] += h
            down[j] -= h
            fd = (float(fn(*up)[0]) - float(fn(*down)[0])) / (2 * h)
            assert float(jac[i]) == pytest.approx(fd, rel=1e-6, abs=1e-6), (j, x)
    assert checked > 30  # the derivatives were checked on enough states


def test_neutral_keys_keep_the_elastic_law():
    """With recovery_after_fracture = 1 and no yield strain the sample keeps its height: the force is b F_e(delta) +
    its damping, whatever the deepest compression so far (the law before crushing and plastic set, written out)."""
    f = food_from_dict({"food": {**CYLINDER, "damping_s_per_m": 20.0, "fracture_strain": 0.4, "stiffness_after_fracture": 0.2,
                                 "recovery_after_fracture": 1.0}})
    k = 20e3 * math.pi * 0.01**2 / 4 / 8e-3
    rng = np.random.default_rng(5)
    delta, rate, broken = rng.uniform(0, 8e-3, 100), rng.uniform(-4e-3, 4e-3, 100), rng.integers(0, 2, 100)
    deepest = delta + rng.uniform(0, 3e-3, 100)
    F, _ = normal_force(NUMPY, f.vector(), delta, rate, broken, 0.0, deepest)
    b = np.where(broken == 1, 0.2, 1.0)
    assert np.allclose(F, np.maximum(b * k * delta * (1 + 1.5 * 20.0 * rate), 0), rtol=1e-13, atol=1e-15)


def test_crushed_and_plastic_heights_are_the_issues_formulas():
    """Crushed: the unloaded height h_c = h0 - delta_max (1 - r) and stiffness_after_fracture x the law of a sample of
    that height (cylinder E A / h_c, sphere Hertz with R = h_c / 2); plastic: the set phi (delta_max - yield_strain
    h0) past the yield strain; the larger set wins. Written out here for both shapes."""
    r, b, dmax = 0.25, 0.5, 4e-3
    c = food_from_dict({"food": {**CYLINDER, "fracture_strain": 0.3, "stiffness_after_fracture": b,
                                 "recovery_after_fracture": r}})
    h_c = 8e-3 - dmax * (1 - r)
    delta = np.linspace(0, dmax, 11)
    expected = b * 20e3 * math.pi * 0.01**2 / 4 / h_c * np.maximum(delta - (8e-3 - h_c), 0)
    assert np.allclose(loaded_force(NUMPY, c.vector(), delta, 1.0, dmax), expected, rtol=1e-13, atol=1e-15)
    assert float(loaded_force(NUMPY, c.vector(), 8e-3 - h_c, 1.0, dmax)) == 0  # unloaded at its new height
    s = food_from_dict({"food": {**SPHERE, "fracture_strain": 0.3, "stiffness_after_fracture": b, "recovery_after_fracture": r}})
    h_c = 5e-3 - dmax * (1 - r)
    hertz = b * 4 / 3 * 3750e3 / (1 - 0.09) * math.sqrt(h_c / 2) * (np.maximum(delta - (5e-3 - h_c), 0) / 2) ** 1.5
    assert np.allclose(loaded_force(NUMPY, s.vector(), delta, 1.0, dmax), hertz, rtol=1e-13, atol=1e-15)
    p = food_from_dict({"food": {**CYLINDER, "yield_strain": 0.1, "plastic_fraction": 0.6}})
    for deepest, expected_set in ((0.5e-3, 0.0), (3e-3, 0.6 * (3e-3 - 0.8e-3))):
        assert float(permanent_set(NUMPY, p.vector(), 0.0, deepest)) == pytest.approx(expected_set, abs=1e-18)
        F = loaded_force(NUMPY, p.vector(), deepest, 0.0, deepest)
        assert float(F) == pytest.approx(20e3 * math.pi * 0.01**2 / 4 / (8e-3 - expected_set) * (deepest - expected_set),
                                         rel=1e-13)
    both = food_from_dict({"food": {**CYLINDER, "yield_strain": 0.1, "plastic_fraction": 0.6, "fracture_strain": 0.3,
                                    "stiffness_after_fracture": b, "recovery_after_fracture": 0.9}})
    assert float(permanent_set(NUMPY, both.vector(), 1.0, dmax)) == pytest.approx(0.6 * (dmax - 0.8e-3), rel=1e-14)


def test_fracture_state_and_guards():
    """At the fracture the Maxwell branch's force is scaled by b F_e after / F_e before: the factor b where the sample
    keeps its height (r = 1). The guards change sign at their events: contact at the permanent set, fracture at its
    strain, the turn with the rate where the compression is the deepest so far."""
    keep = food_from_dict({"food": {**CYLINDER, "fracture_strain": 0.3, "stiffness_after_fracture": 0.2,
                                    "recovery_after_fracture": 1.0}})
    broken, F_m, _ = fracture_state(NUMPY, keep.vector(), 2.4e-3, 0.7, 2.4e-3)
    assert broken == 1 and float(F_m) == pytest.approx(0.7 * 0.2, rel=1e-14)
    crush = food_from_dict({"food": {**CYLINDER, "fracture_strain": 0.3, "stiffness_after_fracture": 0.5}})
    v, df = crush.vector(), 2.4e-3
    g = guards(NUMPY, v, df - 1e-9, 1e-3, 0, 0.0, df - 1e-9)
    g2 = guards(NUMPY, v, df + 1e-9, 1e-3, 0, 0.0, df + 1e-9)
    assert g[2] < 0 < g2[2]  # fracture
    gb = guards(NUMPY, v, df, 1e-3, 1, 0.0, df)
    assert np.isnan(gb[2]) and gb[5] > 0 and guards(NUMPY, v, df, -1e-3, 1, 0.0, df)[5] < 0  # disarmed; the turn
    h_set = df * 0.9
    assert guards(NUMPY, v, h_set - 1e-9, -1e-3, 1, 0.0, df)[0] < 0 < guards(NUMPY, v, h_set + 1e-9, -1e-3, 1, 0.0, df)[0]


def test_face_integrals_are_the_cross_sections_integral():
    """G and M of the tilted face against a midpoint sum over a 2000 x 2000 grid of the disc (to 1e-5 of u + c, the
    grid's error at the contact line), in full, partial and no contact; G is max(u, 0) at zero tilt; dG/du (CasADi)
    is continuous across the contact line's entry and exit (C^1: no kink left at contact with a tilt)."""
    a = 0.006
    n = 2000
    x = (np.arange(n) + 0.5) / n * 2 * a - a
    X, Y = np.meshgrid(x, x)
    inside = X**2 + Y**2 <= a**2
    for u, sin_t in ((1e-3, 0.05), (1e-4, 0.05), (-2e-4, 0.05), (-5e-4, 0.05), (3e-4, 0.0), (-3e-4, 0.0)):
        G, M = face_integrals(NUMPY, u, a * sin_t)
        local = np.maximum(u + X * sin_t, 0) * inside
        G_grid = local.sum() / inside.sum()
        M_grid = (X * local).sum() / inside.sum() / a
        assert float(G) == pytest.approx(G_grid, abs=1e-5 * (abs(u) + a * sin_t))
        assert float(M) == pytest.approx(M_grid, abs=1e-5 * (abs(u) + a * sin_t))
    uu, cc = ca.SX.sym("u"), ca.SX.sym("c")
    dG = ca.Function("dG", [uu, cc], [ca.jacobian(face_integrals(CASADI, uu, cc)[0], uu)])
    c = a * 0.05
    for edge, value in ((c, 1.0), (-c, 0.0)):
        assert float(dG(edge - 1e-12, c)) == pytest.approx(value, abs=1e-5)
        assert float(dG(edge + 1e-12, c)) == pytest.approx(value, abs=1e-5)
    f = food_from_dict({"food": CYLINDER})
    assert float(pressure_centre(NUMPY, f.vector(), 2e-3, 0.0, 2e-3, 0.05)) == pytest.approx(0.005**2 * 0.05 / (4 * 2e-3),
                                                                                            rel=1e-12)
    assert float(loaded_force(NUMPY, f.vector(), 2e-3, 0.0, 2e-3, 0.05)) == pytest.approx(float(f.elastic(2e-3)), rel=1e-14)


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
