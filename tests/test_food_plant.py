"""The food in the plant and the robot as a texture analyser, each held against a route of its own: the food laws in
closed form (hardness, fracture force, cohesiveness, resilience), the energy balance of the whole robot (the
actuators' work = the change of its energy + the work the food absorbs), the events against their guards, and the
command line's refusals."""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.commands.common import EXIT_BAD_INPUT
from chewbot.dynamics.energy import energies
from chewbot.food.geometry import gap, molar_path_task
from chewbot.food.law import load_food
from chewbot.food.tpa import protocol
from chewbot.simulation.options import resolve
from chewbot.simulation.run import compute
from chewbot.simulation.texture import resolve_tpa, run_tpa

from support import model

runner = CliRunner()
SPEED = 4.0  # mm/s: shorter tests than the default 2 mm/s, the same protocol
H0_MM, D_MM, E_KPA = 6.0, 10.0, 20.0
AREA = math.pi * (D_MM * 1e-3) ** 2 / 4


def food_file(folder, **extra) -> str:
    keys = {"name": "test cylinder", "shape": "cylinder", "height_mm": H0_MM, "diameter_mm": D_MM,
            "young_modulus_kPa": E_KPA, "tooth_friction": 0.3, **extra}
    path = folder / f"food_{abs(hash(tuple(sorted(extra.items()))))}.toml"
    path.write_text("[food]\n" + "".join(f'{k} = "{v}"\n' if isinstance(v, str) else f"{k} = {v}\n" for k, v in keys.items()))
    return str(path)


@functools.cache
def _tpa(tmp: str, extra: tuple):
    from pathlib import Path

    # the robot without friction: these tests hold the food's law in closed form (test_texture.py holds the test with it)
    return run_tpa(resolve_tpa(food_file(Path(tmp), **dict(extra)), speed=SPEED, pause=0.5, friction=False))


@pytest.fixture(scope="module")
def tpa(tmp_path_factory):
    tmp = str(tmp_path_factory.mktemp("foods"))
    return lambda **extra: _tpa(tmp, tuple(sorted(extra.items())))


def test_linear_elastic_cylinder(tpa):
    """Hardness = k x the deepest compression, 50 % of the height at the trigger h_t = h0 - F_t / k past the trigger's
    own F_t / k: E A / 2 + F_t / 2 (the crosshead leaves a few um of error), to 0.5 % from the plant and 5 % from the
    torques; cohesiveness, springiness and resilience 1 within 1 % from both."""
    r = tpa()
    expected = E_KPA * 1e3 * AREA * 0.5 + r.options.protocol.trigger_force / 2
    plant, estimated = r.plant.measures, r.estimated.measures
    assert plant["hardness_N"] == pytest.approx(expected, rel=5e-3)
    assert estimated["hardness_N"] == pytest.approx(expected, rel=5e-2)
    for source in (plant, estimated):
        for key in ("cohesiveness", "springiness", "resilience"):
            assert source[key] == pytest.approx(1.0, abs=1e-2), key
        assert source["fracturability_N"] is None
    assert r.record()["tilt_at_deepest_deg"] < 5  # the laws' parallel teeth: a few degrees at 3 mm of gap


def test_brittle_cylinder(tpa):
    """Fracturability = the law's fracture force over the face the robot tilts by theta (0.43 deg here): the edge's
    fibre breaks at the fracture strain when the centre is compressed dc = df - R tan(theta), the force k dc (0.461 N;
    0.471 N with parallel faces), to 1 %; the cohesiveness is below 1 by the areas of the law: A1 = k (dc^2 / 2 +
    b (dm^2 - dc^2) / 2 + b dm^2 / 2), A2 = b k dm^2, dm the deepest compression reached (from tpa.json), to 1 %."""
    strain, b = 0.3, 0.2
    r = tpa(fracture_strain=strain, stiffness_after_fracture=b, recovery_after_fracture=1.0)
    k = E_KPA * 1e3 * AREA / (H0_MM * 1e-3)
    df = strain * H0_MM * 1e-3
    # the face tilts by theta: the fibre at the edge breaks first, at the centre's compression df - R tan(theta), and the
    # fibres' compressions, linear across the disc, sum to the centre's: the force there is k (df - R tan(theta))
    fracture = [e for e in r.record()["events"] if e["event"] == "fracture"]
    sim = r.simulation.simulation
    tilt = np.interp(fracture[0]["t"], sim.t, gap(r.simulation.plant_model, "left", sim.q, sim.dq)["tilt"])
    dc = df - 0.5 * D_MM * 1e-3 * np.tan(abs(tilt))  # the centre's compression when the edge breaks
    at_fracture = k * dc
    assert r.plant.measures["fracturability_N"] == pytest.approx(at_fracture, rel=1e-2)
    assert r.estimated.measures["fracturability_N"] == pytest.approx(at_fracture, rel=5e-2)
    dm = r.record()["deepest_compression_mm"] * 1e-3
    A1 = 0.5 * dc**2 + 0.5 * b * (dm**2 - dc**2) + 0.5 * b * dm**2
    assert r.plant.measures["cohesiveness"] == pytest.approx(b * dm**2 / A1, rel=1e-2)
    assert r.plant.measures["cohesiveness"] < 0.65  # b dm^2 / A1 = 0.60 here (0.58 with parallel faces)
    # the event at the edge fibre's strain: the centre's compression then is dc (the tilt read at the samples and
    # interpolated: 1e-4 relative)
    assert len(fracture) == 1 and fracture[0]["delta_m"] == pytest.approx(dc, rel=1e-4)
    assert r.simulation.table["food_broken"][-1] == 1


def test_kelvin_voigt_resilience(tpa):
    """Hunt-Crossley damping on the linear cylinder, F = k delta (1 + 3/2 alpha d(delta)/dt): at the constant speed v
    the withdrawal's work over the compression's is (1 - c) / (1 + c), c = 3/2 alpha v; to 1 % (the turns' blends move
    it by about 2e-3, the tracking error less)."""
    c = 0.2
    alpha = c / (1.5 * SPEED * 1e-3)
    r = tpa(damping_s_per_m=alpha)
    assert r.plant.measures["resilience"] == pytest.approx((1 - c) / (1 + c), rel=1e-2)


def test_energy_the_food_absorbs_is_the_area_under_its_curve(tmp_path):
    """Over a two-bite test of a damped, relaxing, sticky sample, the actuators' work (torques held between ticks:
    sum tau_k (theta_k+1 - theta_k), exact) equals the robot's change of energy T + V (dynamics.energy, another
    formulation) plus the area under the food's force-compression curve (trapezoids on the rows), to 1e-3 of that
    area (the trapezoids across the contact's kinks, 1 ms apart). The bite point goes straight down here: the face
    tilts 3-4 degrees and the law integrates the compression over it."""
    m = model("target")
    f = food_file(tmp_path, damping_s_per_m=20.0, relaxation_time_s=1.0, relaxation_modulus_kPa=15.0, adhesion_N=0.05)
    p = protocol(H0_MM * 1e-3, 50, SPEED, 0.3)
    t = p.times()
    task = molar_path_task(m, "left", t, *p.path(t))
    result = compute(resolve(food=f, gain_overrides={"computed_torque.frequency_Hz": 100.0}), task=task)
    table, kin, sim = result.table, result.kinematics, result.simulation
    work = float(np.sum(sim.tau[:-1] * np.diff(kin.theta, axis=0)))
    T, V, _ = energies(m, kin)
    change = (T[-1] + V[-1]) - (T[0] + V[0])
    # the compression at the bite point, h0 - g, unclamped: over the tilted face the sample's edge touches first, at
    # h0 - g = -a sin(tilt) (the column food_compression is clamped at 0)
    F, delta = table["food_force"], H0_MM * 1e-3 - gap(m, "left", sim.q)["gap"]
    area = float(np.sum(0.5 * (F[1:] + F[:-1]) * np.diff(delta)))
    loading = float(np.sum((0.5 * (F[1:] + F[:-1]) * np.diff(delta))[np.diff(delta) > 0]))
    assert area > 0.05 * loading  # the sample does absorb (dissipates) work
    assert work == pytest.approx(change + area, abs=1e-3 * loading)
    assert np.allclose(table["Fz"], -F, atol=1e-9) and np.min(F) < 0  # Fz is the food's force; it pulled (adhesion)


# ---------------------------------------------------------------------------------------- the command line


def test_simulate_food_refuses_a_task_with_a_bite_force_and_a_sample_that_does_not_fit(tmp_path):
    r = runner.invoke(app, ["simulate", "--food", "cheddar", "--out", str(tmp_path / "a")])
    assert r.exit_code == EXIT_BAD_INPUT and "carries a bite force" in r.output and "hybrid" in r.output
    r = runner.invoke(app, ["simulate", "--food", "cheddar", "--set", "task.force_z_N=0", "--set", "task.force_x_N=0",
                            "--set", "task.force_y_N=0", "--out", str(tmp_path / "b")])
    assert r.exit_code == EXIT_BAD_INPUT and "mild cheddar cube" in r.output and "does not fit" in r.output
    r = runner.invoke(app, ["simulate", "--food", str(tmp_path / "none.toml"), "--out", str(tmp_path / "c")])
    assert r.exit_code == EXIT_BAD_INPUT and "none.toml" in r.output
    assert not any(p.name.startswith(("a", "b", "c")) for p in tmp_path.iterdir())


def test_tpa_refuses_a_sample_taller_than_the_workspace(tmp_path):
    big = tmp_path / "big.toml"
    big.write_text('[food]\nname = "tall"\nshape = "cylinder"\nheight_mm = 18.0\ndiameter_mm = 10.0\n'
                   'young_modulus_kPa = 10.0\ntooth_friction = 0.1\n')
    r = runner.invoke(app, ["tpa", "--food", str(big), "--out", str(tmp_path / "t")])
    assert r.exit_code == EXIT_BAD_INPUT and "largest sample is 15.08 mm" in " ".join(r.output.split())


def test_tpa_command_writes_its_folder(tmp_path):
    """chewbot tpa writes tpa.json with both sets of measures, results.csv with the food's columns, the figures and
    the reports; its hardness lies between the equilibrium and the instantaneous modulus' force; and chewbot tpa --log
    on the same angles and torques gives the same estimated measures."""
    food = food_file(tmp_path, height_mm=4.0, relaxation_time_s=1.0, relaxation_modulus_kPa=10.0, damping_s_per_m=10.0)
    r = runner.invoke(app, ["tpa", "--food", food, "--speed", "8", "--pause", "0.3", "--out", str(tmp_path / "tpa"), "-q"])
    assert r.exit_code == 0, r.output
    record = json.loads((tmp_path / "tpa" / "tpa.json").read_text())
    for source in ("plant", "estimated"):
        assert set(record[source]) >= {"hardness_N", "fracturability_N", "cohesiveness", "springiness", "resilience",
                                       "adhesiveness_mJ", "gumminess_N", "chewiness_N"}
    header = (tmp_path / "tpa" / "results.csv").read_text().splitlines()[0]
    assert "food_compression [m]" in header and "food_force [N]" in header and "food_broken [1]" in header
    for name in ("force_time.png", "force_displacement.png", "tpa.html", "report.html", "task.csv"):
        assert (tmp_path / "tpa" / name).exists()
    # the hardness lies between the equilibrium and the instantaneous modulus' force (damping on top)
    sample = load_food(food)
    elastic = float(sample.elastic(0.5 * sample.height))
    instantaneous = elastic * (1 + sample.relaxation_modulus / sample.young_modulus) * (1 + 1.5 * sample.damping * 8e-3)
    assert elastic * 0.99 < record["plant"]["hardness_N"] < instantaneous
    # the same test from the robot's log (its angles, torques and currents): the same "estimated" measures
    import csv

    with open(tmp_path / "tpa" / "results.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    columns = ["t [s]"] + [f"theta{i} [rad]" for i in range(1, 7)] + [f"tau{i} [N*m]" for i in range(1, 7)]
    columns += [c for c in (f"i{i} [A]" for i in range(1, 7)) if c in rows[0]]  # the drive's currents, as tpa read them
    keep = [rows[0].index(c) for c in columns]
    with open(tmp_path / "log.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([[row[j] for j in keep] for row in rows])
    r = runner.invoke(app, ["tpa", "--log", str(tmp_path / "log.csv"), "--food", food, "--out", str(tmp_path / "logged"), "-q"])
    assert r.exit_code == 0, r.output
    logged = json.loads((tmp_path / "logged" / "tpa.json").read_text())
    assert logged["plant"] is None
    for key, value in record["estimated"].items():
        if isinstance(value, float):
            assert logged["estimated"][key] == pytest.approx(value, rel=1e-6, abs=1e-9), key


def _smooth_step(t, t0, duration, size):
    """A C^2 step of ``size`` from t0 over ``duration`` (quintic), with its rate and acceleration."""
    u = np.clip((t - t0) / duration, 0, 1)
    inside = (t > t0) & (t < t0 + duration)
    return (size * (10 * u**3 - 15 * u**4 + 6 * u**5), np.where(inside, size * (30 * u**2 - 60 * u**3 + 30 * u**4) / duration, 0),
            np.where(inside, size * (60 * u - 180 * u**2 + 120 * u**3) / duration**2, 0))


def test_sliding_on_the_tooth(tmp_path):
    """The sample compressed by 30 %, then slid 1 mm along x and back: the friction never exceeds mu F_n, opposes the
    sliding, and reaches at least 0.89 mu F_n where the bite point slides faster than 2 mm/s (the regularised law at
    twice its speed scale: 2 / sqrt(5)); the sliding velocity is taken from the kinematics' bite point (central
    differences). Energy: the actuators' work equals the robot's change of energy plus the work done on the food,
    -sum F . v_B dt, normal and tangential, to 1e-4 of the latter."""
    m = model("target")
    t = np.arange(0, 2.2001, 1e-3)
    h0, mu = H0_MM * 1e-3, 0.4
    close = _smooth_step(t, 0.1, 0.8, -(1e-3 + 0.3 * h0))
    g = (close[0] + h0 + 1e-3, close[1], close[2])
    there, back = _smooth_step(t, 1.0, 0.5, 1e-3), _smooth_step(t, 1.6, 0.5, -1e-3)
    shift = tuple(np.column_stack([a + b, np.zeros(t.size)]) for a, b in zip(there, back))
    task = molar_path_task(m, "left", t, *g, shift=shift)
    result = compute(resolve(food=food_file(tmp_path, tooth_friction=mu),
                                     gain_overrides={"computed_torque.frequency_Hz": 100.0}), task=task)
    table, kin, sim = result.table, result.kinematics, result.simulation
    F = np.column_stack([table["Fx"], table["Fy"], table["Fz"]])
    Fn = table["food_force"]
    v = np.gradient(kin.points["B_L"], sim.t, axis=0)
    assert np.all(np.hypot(F[:, 0], F[:, 1]) <= mu * Fn + 1e-12)
    sliding = np.abs(v[:, 0]) > 2e-3
    assert sliding.sum() > 300
    assert np.all(np.sign(F[sliding, 0]) == -np.sign(v[sliding, 0]))
    assert np.all(np.abs(F[sliding, 0]) >= 0.89 * mu * Fn[sliding])
    work = float(np.sum(sim.tau[:-1] * np.diff(kin.theta, axis=0)))
    T, V, _ = energies(m, kin)
    power = -np.sum(F * v, axis=1)
    on_food = float(np.sum(0.5 * (power[1:] + power[:-1]) * np.diff(sim.t)))
    normal = float(np.sum(0.5 * (Fn[1:] + Fn[:-1]) * np.diff(table["food_compression"])))
    assert on_food > 1.5 * normal > 0  # the friction did work too
    assert work == pytest.approx((T[-1] + V[-1]) - (T[0] + V[0]) + on_food, abs=1e-4 * on_food)
