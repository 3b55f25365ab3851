"""The drive train: the model's [drive] section, the gearbox's loss law, the rotor in the inverse dynamics, the plant,
the controllers' currents, the encoders and the robot logs with currents.

Each check takes another route to the quantity than the code under test: the law's inverse against its forward
form, the rotor's torque against the same model without a drive, the power balance against the energy of the robot
(its own kernel), the plant's accelerations against the inverse dynamics, the estimate against the plant's force."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

import chewbot
import support
from chewbot.dynamics.energy import energies
from chewbot.errors import ParameterError, TaskError
from chewbot.identification.force import estimate_log
from chewbot.identification.log import RobotLog, read_log
from chewbot.kinematics.motion import solve_kinematics
from chewbot.model import drive as law
from chewbot.model.params import load_model
from chewbot.model.symbolic import SymbolicModel
from chewbot.model.vector import block_slice
from chewbot.run.pipeline import load_task
from chewbot.simulation.sensor import CrankSensor
from chewbot.simulation.forward import forward_dynamics


@pytest.fixture(scope="module")
def target():
    return load_model("target")


def without_drive(model):
    return support.without_drive(model.name)


def test_the_built_in_drive_and_its_units(target):
    d = target.drive
    assert d.rotor_inertia == pytest.approx(3350e-9, rel=1e-15)  # 3350 g mm^2 = 33.5 g cm^2
    assert (d.gear_ratio, d.torque_constant, d.encoder_counts) == (51.0, pytest.approx(0.0259, rel=1e-15), 2000.0)
    assert d.reflected_inertia == pytest.approx(8.713e-3, rel=1e-3)  # docs/models.md: 8.7e-3 kg m^2 at the crank
    np.testing.assert_array_equal(target.crank_total_inertia, target.crank_inertia + d.reflected_inertia)
    assert all(k in target.assumed for k in ("drive.gear_ratio", "drive.gear_efficiency"))
    p = target.vector()
    assert p[block_slice("drive.torque_constant")][0] == d.torque_constant
    plain = load_model("target-as-printed")  # the paper's robot, no drive: the neutral entries and its own cranks
    assert plain.drive is None and plain.crank_total_inertia is plain.crank_inertia
    assert [plain.vector()[block_slice(f"drive.{k}")][0] for k in ("rotor_inertia", "gear_ratio", "efficiency",
                                                                     "torque_constant", "encoder_counts")] == [0, 1, 1, 1, 0]


@pytest.mark.parametrize("key, value, reason", [("drive.gear_efficiency", 0.1, "at least 0.2"),
                                                ("drive.encoder_counts_per_rev", 2000.5, "not a whole number"),
                                                ("drive.torque_constant_mNm_per_A", 0.0259, "implausible")])
def test_a_wrong_drive_names_its_key(key, value, reason):
    with pytest.raises(ParameterError, match=rf"{key}.*{reason}|{reason}.*{key}"):
        load_model("target", overrides={key: value})


def test_a_partial_drive_section_is_refused():
    with pytest.raises(ParameterError, match="'drive.gear_ratio' is missing from the file"):
        load_model("target-as-printed", overrides={"drive.gear_ratio": 51.0})


def _samples(n=20000, seed=0):
    rng = np.random.default_rng(seed)
    tau_m = rng.normal(0, 0.05, n)
    dtheta = rng.normal(0, 1, n) * 10 ** rng.uniform(-7, 1, n)  # through the blend (P_0 = 0.01 W) and far beyond it
    return tau_m, dtheta


@pytest.mark.parametrize("efficiency", [1.0, 0.75, 0.2])
def test_the_motor_torque_inverts_the_loss_law(target, efficiency):
    """motor_torque(crank_torque(x)) = x to rounding (1e-12 relative: Newton's iteration converged), in both
    directions of power flow and through the blend."""
    d = dataclasses.replace(target.drive, efficiency=efficiency)
    tau_m, dtheta = _samples()
    back = law.motor_torque(d, law.crank_torque(d, tau_m, dtheta), dtheta)
    np.testing.assert_allclose(back, tau_m, rtol=1e-12, atol=1e-18)


def test_the_loss_law_in_both_directions_of_power(target):
    """Far from the blend: eta N tau_m where the motor drives, N tau_m / eta where it is back-driven (tanh(100) is 1 to
    rounding); the gearbox never gives power (loss >= 0) and loses none at rest."""
    d = target.drive
    N, eta = d.gear_ratio, d.efficiency
    tau_m = np.array([0.02, -0.02, 0.02, -0.02])
    w = 100 * law.EFFICIENCY_BLEND_W / (N * 0.02) * np.array([1, -1, -1, 1])  # P_m = +-100 P_0
    np.testing.assert_allclose(law.crank_torque(d, tau_m, w), N * tau_m * np.array([eta, eta, 1 / eta, 1 / eta]), rtol=1e-14)
    tau_m, dtheta = _samples()
    loss = law.gearbox_loss(d, tau_m, dtheta)
    assert loss.min() >= 0
    assert law.gearbox_loss(d, 0.03, 0.0) == 0


def test_the_neutral_drive_is_the_identity_bit_for_bit():
    tau, dtheta = _samples(1000, seed=3)
    assert np.array_equal(law.crank_torque(law.NEUTRAL, tau, dtheta), tau)
    assert np.array_equal(law.motor_torque(law.NEUTRAL, tau, dtheta), tau)
    assert np.array_equal(law.quantise(law.NEUTRAL, dtheta), dtheta)


def test_the_casadi_law_is_the_numpy_law_and_its_derivative_exact(target):
    """The law written once: CasADi's graph gives NumPy's numbers, and its AD derivative matches a central finite
    difference (tests only) to 1e-7 relative (the difference's truncation at h = 1e-6 of the torque)."""
    m = SymbolicModel.of(target)
    x, w = ca.SX.sym("tau_m"), ca.SX.sym("w")
    f = ca.Function("f", [x, w], [law.crank_torque(m.drive, x, w), law.motor_torque(m.drive, x, w)])
    df = ca.Function("df", [x, w], [ca.jacobian(law.crank_torque(m.drive, x, w), x)])
    for tau_m, dtheta in zip(*_samples(50, seed=4)):
        out = [float(v) for v in f(tau_m, dtheta)]
        assert out[0] == pytest.approx(law.crank_torque(target.drive, tau_m, dtheta), rel=1e-14)
        assert out[1] == pytest.approx(law.motor_torque(target.drive, tau_m, dtheta), rel=1e-12)
        h = 1e-6 * max(abs(tau_m), 1e-3)
        fd = (law.crank_torque(target.drive, tau_m + h, dtheta) - law.crank_torque(target.drive, tau_m - h, dtheta)) / (2 * h)
        assert float(df(tau_m, dtheta)) == pytest.approx(fd, rel=1e-7)


@pytest.fixture(scope="module")
def motion(target):
    """One chewing cycle of the default task, its kinematics and the inverse dynamics with and without the drive."""
    task = load_task("default", target, "left", {"cycles": 1})
    kin = solve_kinematics(target, task)
    q, dq, ddq = kin.euler_angle_state()
    with_drive = chewbot.inverse_dynamics(target, q, dq, ddq, bite_force=kin.force)
    plain = chewbot.inverse_dynamics(without_drive(target), q, dq, ddq, bite_force=kin.force)
    return task, kin, with_drive, plain


@pytest.mark.parametrize("name", ["6rss", "target"])
@pytest.mark.parametrize("method", ["hessian", "newton-euler"])
def test_the_rotor_adds_its_inertia_torque_at_each_crank(name, method):
    """The 6RSS (no redundancy): tau with the drive minus tau without = J_r N^2 theta_ddot, crank by crank, to 1e-9 of
    the torques' magnitude (the formulations' rounding). The target's six torques for four freedoms are distributed
    (the minimum norm of the cranks' whole torques, rotors included): there, less the rotors' torques, they move the
    robot without a drive along the same motion (its forward dynamics, 1e-8 of the accelerations)."""
    model = load_model(name)
    kin = solve_kinematics(model, load_task("default", model, "left", {"cycles": 1}))
    q, dq, ddq = kin.euler_angle_state()
    options = {"friction": False} if method == "newton-euler" else {}
    ours = chewbot.inverse_dynamics(model, q, dq, ddq, method=method, bite_force=kin.force, **options)
    plain = without_drive(model)
    rotor = model.drive.reflected_inertia * kin.ddtheta
    assert np.abs(rotor).max() > 0.1  # a torque that matters: a fifth of the crank torques' peak or more
    if not model.has_hkp:
        mechanism = chewbot.inverse_dynamics(plain, q, dq, ddq, method=method, bite_force=kin.force, **options).tau
        np.testing.assert_allclose(ours.tau - mechanism, rotor, rtol=0, atol=1e-9 * np.abs(ours.tau).max())
    fwd = forward_dynamics(plain, q, dq, ours.tau - rotor, kin.force)
    np.testing.assert_allclose(fwd.ddq, ddq, rtol=0, atol=1e-8 * np.abs(ddq).max())
    tau_m = np.column_stack([ours[f"tau_motor{i}"] for i in range(1, 7)])
    current = np.column_stack([ours[f"i{i}"] for i in range(1, 7)])
    np.testing.assert_allclose(law.crank_torque(model.drive, tau_m, kin.dtheta), ours.tau, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(current * model.drive.torque_constant, tau_m, rtol=1e-15)
    assert ours.units["i1"] == "A" and ours.units["tau_motor1"] == "N*m"
    assert "i1" not in chewbot.inverse_dynamics(plain, q[:3], dq[:3], ddq[:3], method=method, **options).columns


def test_power_balance_with_the_loss_law(target, motion):
    """Over a chewing cycle without a bite force: the motors' mechanical power N tau_m theta_dot is the cranks' power
    tau theta_dot plus the gearbox's loss (>= 0, with the law's sign in both directions); and the cranks' power,
    integrated, is the robot's energy change (rotors included), from the energy kernel, to 1e-4 of the energy moved
    (the trapezoidal rule at 1 kHz)."""
    task, kin, _, _ = motion
    q, dq, ddq = kin.euler_angle_state()
    r = chewbot.inverse_dynamics(target, q, dq, ddq)  # no bite force
    tau_m = np.column_stack([r[f"tau_motor{i}"] for i in range(1, 7)])
    P_motor = target.drive.gear_ratio * tau_m * kin.dtheta
    P_crank = r.tau * kin.dtheta
    loss = law.gearbox_loss(target.drive, tau_m, kin.dtheta)
    np.testing.assert_allclose(P_motor, P_crank + loss, rtol=0, atol=1e-12 * np.abs(P_motor).max())
    assert loss.min() >= 0 and loss.sum() > 0
    back = P_motor < -10 * law.EFFICIENCY_BLEND_W  # back-driven samples: the motor takes back less than the crank gives
    assert back.any() and np.all(np.abs(P_motor[back]) < np.abs(P_crank[back]))
    T, V, _ = energies(target, kin)
    E = T + V
    work = np.concatenate([[0], np.cumsum(0.5 * (P_crank.sum(1)[1:] + P_crank.sum(1)[:-1]) * np.diff(kin.t))])
    moved = np.abs(np.diff(E)).sum()
    assert np.abs(work - (E - E[0])).max() < 1e-4 * moved
    T_rotors = 0.5 * target.drive.reflected_inertia * (kin.dtheta**2).sum(1)
    assert T_rotors.max() > 0.5 * T.max()  # the rotors hold most of the kinetic energy: the check sees them


def test_the_plant_accelerates_as_the_controllers_currents_say(target, motion):
    """Inverse of forward with the drive: the controller's currents (the inverse dynamics' i1..i6) through the plant's
    drive give torques under which the plant's forward dynamics returns the motion's accelerations (1e-8 of their
    magnitude: the forward solver's Newton tolerance)."""
    task, kin, r, _ = motion
    q, dq, ddq = kin.euler_angle_state()
    current = np.column_stack([r[f"i{i}"] for i in range(1, 7)])
    tau = law.crank_torque(target.drive, law.torque_of_current(target.drive, current), kin.dtheta)
    fwd = forward_dynamics(target, q, dq, tau, kin.force)
    np.testing.assert_allclose(fwd.ddq, ddq, rtol=0, atol=1e-8 * np.abs(ddq).max(axis=0).max())
    plain = forward_dynamics(without_drive(target), q, dq, tau, kin.force)  # the rotor left out: visibly wrong
    assert np.abs(plain.ddq - ddq).max() > 10 * np.abs(ddq).max()


def test_the_encoders_read_the_angles_on_their_grid(target):
    d = target.drive
    step = 2 * np.pi / (d.encoder_counts * d.gear_ratio)
    theta = np.random.default_rng(5).uniform(-1, 1, (200, 6))
    read = law.quantise(d, theta)
    counts = read / step
    np.testing.assert_allclose(counts, np.round(counts), rtol=0, atol=1e-6)
    assert np.abs(read - theta).max() <= step / 2 * (1 + 1e-9)
    sensor = CrankSensor(target, noise=0.0, cutoff=50.0, encoder=d)
    task = load_task("default", target, "left", {"cycles": 1})
    kin = solve_kinematics(target, task)
    q, dq, _ = kin.euler_angle_state()
    sensor.start(0.0, q[0], dq[0])
    for k in range(1, 30):
        seen = sensor(kin.t[k], kin.theta[k])
        np.testing.assert_allclose(seen.theta / step, np.round(seen.theta / step), rtol=0, atol=1e-6)
        assert seen.dtheta is not None


@pytest.fixture(scope="module")
def simulated(target):
    """Computed torque with the drive along one chewing cycle of the default task (its bite force on the plant)."""
    return chewbot.simulate("target", controller="computed-torque", overrides={"task.cycles": 1})


def test_the_simulation_logs_currents_and_the_plant_follows_them(target, simulated):
    """The controller's currents are its commanded torques through its model's drive at the rates it saw (here the
    plant's: no sensor); the plant's torques are the currents through the plant's drive."""
    sim = simulated.simulation
    d = target.drive
    kin = simulated.kinematics
    np.testing.assert_allclose(law.motor_torque(d, np.clip(sim.tau_cmd, -5, 5), kin.dtheta) / d.torque_constant,
                               sim.current, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(law.crank_torque(d, sim.tau_motor, kin.dtheta), sim.tau, rtol=1e-9, atol=1e-12)
    assert simulated.table.units["i1"] == "A"
    assert simulated.metrics["rms_position_mm"] < 1e-3


def test_the_estimate_from_currents_is_the_plants_force(target, simulated):
    """Given exact rates and the currents, the estimator's force is the plant's to 1e-6 N (the issue's bound; measured
    ~1e-11 N)."""
    sim = simulated.simulation
    kin = simulated.kinematics
    log = RobotLog("simulated", sim.t, kin.theta, kin.dtheta, kin.ddtheta, None, np.zeros((sim.n, 3)),
                   np.arange(sim.n) + 2, current=sim.current)
    est = estimate_log(target, log, friction=False)
    assert est.info["reads"] == "currents"
    assert np.abs(sim.force).max() > 50
    np.testing.assert_allclose(est.F_B, sim.force, rtol=0, atol=1e-6)


def _current_log(path, simulated, units="A"):
    sim, kin = simulated.simulation, simulated.kinematics
    scale = {"A": 1.0, "mA": 1e3}[units]
    header = ["t [s]", *(f"theta{i} [rad]" for i in range(1, 7)), *(f"i{i} [{units}]" for i in range(1, 7))]
    rows = np.column_stack([sim.t, kin.theta, sim.current * scale])
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.17g}" for v in row) for row in rows) + "\n")
    return path


def test_a_current_only_log_is_read(target, simulated, tmp_path):
    log = read_log(_current_log(tmp_path / "log.csv", simulated, "mA"))
    assert log.tau is None
    np.testing.assert_allclose(log.current, simulated.simulation.current, rtol=1e-15)
    assert log.reads(target) == "currents"
    with pytest.raises(TaskError, match="no drive"):
        log.crank_torques(load_model("target-as-printed"), np.zeros_like(log.current))


def test_a_log_without_torques_or_currents_is_refused(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("t," + ",".join(f"theta{i}" for i in range(1, 7)) + "\n" + "\n".join(
        ",".join(str(v) for v in [k * 1e-3] + [0.0] * 6) for k in range(20)) + "\n")
    with pytest.raises(TaskError, match="tau1..tau6 or i1..i6"):
        read_log(path)


def run_cli(*args):
    from typer.testing import CliRunner

    from chewbot.cli import app

    return CliRunner().invoke(app, list(args))


def test_estimate_force_reads_a_current_only_log(simulated, tmp_path):
    path = _current_log(tmp_path / "log.csv", simulated)
    out = run_cli("estimate-force", str(path), "--model", "target", "--friction", "off", "--out", str(tmp_path / "force.csv"))
    assert out.exit_code == 0, out.output
    assert "from the log's currents" in out.output
    out = run_cli("estimate-force", str(path), "--model", "target-as-printed", "--out", str(tmp_path / "f2.csv"))
    assert out.exit_code == 2 and "no drive" in out.output


@pytest.mark.slow  # minutes: identify over the whole cycle's log (a current log identified: test_calibration -k torque_constant)
def test_identify_reads_a_current_only_log(simulated, tmp_path):
    path = _current_log(tmp_path / "log.csv", simulated)
    out = run_cli("identify", str(path), "--model", "target", "--out", str(tmp_path / "id.toml"))
    assert out.exit_code in (0, 4), out.output
    assert (tmp_path / "id.toml").exists()


def test_a_plant_with_another_gearbox_than_the_controllers(target):
    """--plant-set drive.gear_efficiency: the controller's currents, through the plant's own loss law, give other
    torques than it meant (the loss law of 0.6 instead of 0.75 where power flows); --rate continuous, which applies the
    law's torques as they are, refuses such a plant."""
    with pytest.raises(chewbot.ChewbotError, match="--rate continuous.*drive"):
        chewbot.simulate("target", controller="computed-torque", rate="continuous",
                         overrides={"task.cycles": 1}, plant_overrides={"drive.gear_efficiency": 0.6})
    r = chewbot.simulate("target", controller="computed-torque", overrides={"task.cycles": 1},
                         plant_overrides={"drive.gear_efficiency": 0.6})
    sim, plant = r.simulation, r.plant_model.drive
    assert plant.efficiency == 0.6 and r.model.drive.efficiency == 0.75
    np.testing.assert_allclose(law.crank_torque(plant, sim.tau_motor, r.kinematics.dtheta), sim.tau, rtol=1e-9, atol=1e-12)
    meant = np.clip(sim.tau_cmd, -5, 5)
    assert np.abs(sim.tau - meant).max() > 0.05 * np.abs(meant).max()  # the gearbox the controller does not know
    assert r.metrics["stopped"] is None
