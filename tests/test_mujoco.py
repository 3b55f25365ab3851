"""MuJoCo as an independent plant: the MJCF model against the model's numbers, MuJoCo's forward dynamics against
chewbot's, the home pose held by chewbot's torques, and computed torque tracking in MuJoCo (slow)."""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from chewbot.export.mjcf import mjcf  # noqa: E402
from chewbot.kinematics.motion import solve_kinematics  # noqa: E402
from chewbot.kinematics.task import TARGET_COORDS, Task  # noqa: E402
from chewbot.model.params import load_model  # noqa: E402
from chewbot.simulation.forward import forward_dynamics  # noqa: E402
from chewbot.simulation.mujoco_plant import MujocoPlant  # noqa: E402


@pytest.fixture(scope="module")
def target():
    return load_model("target")


@pytest.fixture(scope="module")
def compiled(target):
    return mujoco.MjModel.from_xml_string(mjcf(target, friction=False))


def _world_inertia(mj, body: str) -> np.ndarray:
    """The body's inertia about its mass centre, in the body's frame, from MuJoCo's principal inertia and its frame."""
    b = mj.body(body)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, b.iquat)
    R = R.reshape(3, 3)
    return R @ np.diag(b.inertia) @ R.T


def test_mjcf_masses_and_inertias_are_the_models(target, compiled):
    # independent of the writer: the model's own fields, the coupler's mass rebuilt from rho A L
    rods = target.coupler_density * target.coupler_area * target.coupler_length
    total = target.mandible_mass + target.crank_mass.sum() + rods.sum()
    assert mujoco.mj_getTotalmass(compiled) == pytest.approx(total, rel=1e-12)
    # the mandible: mass centre at O_M and the full inertia about it, in {M}
    assert compiled.body("mandible").mass[0] == pytest.approx(target.mandible_mass, rel=1e-12)
    np.testing.assert_allclose(compiled.body("mandible").ipos, 0, atol=1e-15)
    np.testing.assert_allclose(_world_inertia(compiled, "mandible"), target.mandible_inertia, rtol=0, atol=1e-12 * np.abs(target.mandible_inertia).max())
    for i in range(6):
        crank, rod = compiled.body(f"crank{i + 1}"), compiled.body(f"coupler{i + 1}")
        assert crank.mass[0] == pytest.approx(target.crank_mass[i], rel=1e-12)
        np.testing.assert_allclose(crank.ipos, 0, atol=1e-15)  # on the shaft, at G_i
        axis = compiled.joint(f"crank{i + 1}").axis
        assert axis @ _world_inertia(compiled, f"crank{i + 1}") @ axis == pytest.approx(target.crank_inertia[i], rel=1e-12)
        # the rod: mass at its middle, m L^2 / 12 across, (next to) nothing along
        L = target.coupler_length[i]
        assert rod.mass[0] == pytest.approx(rods[i], rel=1e-12)
        np.testing.assert_allclose(rod.ipos, [L / 2, 0, 0], atol=1e-15)
        inertia = _world_inertia(compiled, f"coupler{i + 1}")
        np.testing.assert_allclose(np.diag(inertia)[1:], rods[i] * L**2 / 12, rtol=1e-12)
        assert inertia[0, 0] < 1e-6 * rods[i] * L**2  # SPIN_INERTIA, never excited (the universal joint)
    assert compiled.opt.gravity.tolist() == [0, 0, -target.g]


def test_mjcf_names_motors_loops_and_the_origin_site(target, compiled):
    assert [compiled.actuator(i).name for i in range(compiled.nu)] == [f"crank{i}" for i in range(1, 7)]
    np.testing.assert_array_equal(compiled.actuator_gear[:, 0], 1.0)
    data = mujoco.MjData(compiled)
    mujoco.mj_kinematics(compiled, data)
    for i in range(6):  # each motor drives its crank's hinge, at G_i about the shaft R_C0[:, 2] (theta increasing)
        joint = compiled.joint(f"crank{i + 1}").id
        assert compiled.actuator_trnid[i, 0] == joint
        np.testing.assert_allclose(data.xaxis[joint], target.R_C0[i][:, 2], atol=1e-12)
        np.testing.assert_allclose(data.xanchor[joint], target.G[i], atol=1e-15)
    assert compiled.neq == 6 and {int(t) for t in compiled.eq_type} == {int(mujoco.mjtEq.mjEQ_CONNECT)}
    site = compiled.site("O_M")
    assert site.bodyid[0] == compiled.body("mandible").id
    np.testing.assert_array_equal(site.pos, 0)
    assert compiled.npair == 2  # one sphere-on-plane contact per condyle


def test_mjcf_file_from_the_command_line(tmp_path):
    from typer.testing import CliRunner

    from chewbot.cli import app

    out = tmp_path / "robot.xml"
    result = CliRunner().invoke(app, ["export-model", "--format", "mjcf", "--model", "target", "--out", str(out)])
    assert result.exit_code == 0, result.output
    mj = mujoco.MjModel.from_xml_path(str(out))
    assert mj.nu == 6 and mj.nv == 24  # free mandible 6 + 6 cranks + 6 universal joints x 2
    again = CliRunner().invoke(app, ["export-model", "--out", str(out)])
    assert again.exit_code == 5  # exists: never replaced without --force


def test_sixrss_rigid_accelerations_agree_with_chewbot():
    """The 6RSS (no HKPs, no contacts): its MJCF has the model's total mass, and MuJoCo's rigid accelerations equal
    chewbot's forward dynamics to 1e-6 of their largest magnitude at states of its default task."""
    sixrss = load_model("6rss")
    rods = sixrss.coupler_density * sixrss.coupler_area * sixrss.coupler_length
    plant = MujocoPlant(sixrss, mjcf(sixrss, friction=False))
    assert mujoco.mj_getTotalmass(plant.mj) == pytest.approx(sixrss.mandible_mass + sixrss.crank_mass.sum() + rods.sum(), rel=1e-12)
    assert plant.mj.npair == 0
    q, dq, tau, force = _task_states(sixrss, 8, seed=3)
    ours = forward_dynamics(sixrss, q, dq, tau, force)
    scale = np.abs(ours.ddq).max(axis=0)
    for k in range(8):
        ddq, N = _rigid_accelerations(plant, q[k], dq[k], tau[k], force[k])
        assert N.size == 0
        np.testing.assert_allclose(ddq, ours.ddq[k], rtol=0, atol=1e-6 * scale.max())


def _task_states(model, n: int, seed: int = 0):
    """States, torques and bite forces along the default task: the torques of chewbot's inverse dynamics there, so that
    both condyles stay pressed (N > 0: MuJoCo's contacts are unilateral)."""
    from chewbot.dynamics.registry import inverse_dynamics
    from chewbot.task.default import default_task

    task = default_task(model)
    rows = np.sort(np.random.default_rng(seed).choice(task.t.shape[0], n, replace=False))
    kin = solve_kinematics(model, task)
    dyn = inverse_dynamics(model, kin, "hessian")
    return task.q[rows], task.dq[rows], dyn.tau[rows], task.force[rows]


def test_state_round_trip_closes_every_constraint(target):
    plant = MujocoPlant(target, mjcf(target, friction=False))
    q, dq, _, _ = _task_states(target, 5)
    for k in range(5):
        plant.set_state(q[k], dq[k])
        back_q, back_dq, theta, _ = plant.read_state()
        np.testing.assert_allclose(back_q, q[k], atol=1e-14)
        np.testing.assert_allclose(back_dq, dq[k], atol=1e-12)
        loops, hkp = plant.violations()
        assert loops < 1e-15 and hkp < 1e-11  # the planes sit CONTACT_OVERLAP = 1e-12 m higher
        d = plant.data
        J = d.efc_J[:d.nefc * plant.mj.nv].reshape(d.nefc, plant.mj.nv)
        assert np.abs(J @ d.qvel).max() < 1e-12  # velocities along every loop and contact
        assert d.ncon == 2


def _rigid_accelerations(plant: MujocoPlant, q, dq, tau, force):
    """The accelerations and contact normal forces of MuJoCo's model with its constraints rigid: MuJoCo's own mass
    matrix, bias forces, constraint Jacobian J (loops and contacts) and, by central differences along the motion (tests
    only), J_dot v, in the KKT system [M J^T; J 0] [a; -f] = [tau - c; -J_dot v]."""
    mj, d = plant.mj, plant.data
    plant.set_state(q, dq)
    plant._load(tau, force)
    mujoco.mj_forward(mj, d)
    nv, n = mj.nv, d.nefc
    J = d.efc_J[:n * nv].reshape(n, nv).copy()
    M = np.zeros((nv, nv))
    mujoco.mj_fullM(mj, M, d.qM) if hasattr(d, "qM") else mujoco.mj_fullM(mj, d, M)
    applied = np.zeros(nv)
    b = plant._mandible
    mujoco.mj_applyFT(mj, d, d.xfrc_applied[b, :3].copy(), d.xfrc_applied[b, 3:].copy(), d.xipos[b].copy(), b, applied)
    rhs = d.qfrc_actuator + d.qfrc_passive - d.qfrc_bias + applied
    qpos, v = d.qpos.copy(), d.qvel.copy()
    eps = 1e-7
    moved = []
    for sign in (1, -1):
        x = qpos.copy()
        mujoco.mj_integratePos(mj, x, v, sign * eps)
        d.qpos[:] = x
        mujoco.mj_forward(mj, d)
        moved.append(d.efc_J[:n * nv].reshape(n, nv) @ v)
    K = np.block([[M, J.T], [J, np.zeros((n, n))]])
    solution = np.linalg.solve(K, np.concatenate([rhs, -(moved[0] - moved[1]) / (2 * eps)]))
    d.qpos[:] = qpos
    mujoco.mj_forward(mj, d)
    d.qacc[:] = solution[:nv]
    contacts = -solution[nv + 18:]  # the contact rows come after the 18 of the loops
    return plant.accelerations(), contacts


def test_forward_accelerations_agree_with_chewbot(target):
    """At states of the default task under chewbot's torques (perturbed, both N > 0: MuJoCo's contacts are unilateral):

    - MuJoCo's model with rigid constraints (its mass matrix, bias forces and Jacobians, :func:`_rigid_accelerations`)
      gives chewbot's accelerations and normal forces to 1e-6 of their largest magnitude (measured ~1e-9: the central
      difference of J_dot v);
    - MuJoCo's own (soft) forward dynamics, within 15 % of the largest magnitude of each coordinate's acceleration
      (measured 11 %): at the stiffest impedance MuJoCo admits (0.9999) each constraint keeps 1e-4 of the acceleration
      it removes, and the cranks' small inertia makes that large; its normal forces within 2 %, and chewbot's
      equations at its answer leave a residual below 1 % of the torques.
    """
    plant = MujocoPlant(target, mjcf(target, friction=False))
    q, dq, tau, force = _task_states(target, 40, seed=1)
    tau = tau + np.random.default_rng(2).normal(0, 0.002, tau.shape)
    ours = forward_dynamics(target, q, dq, tau, force)
    scale, N_scale = np.abs(ours.ddq).max(axis=0), np.abs(ours.N).max()
    for k in range(0, 40, 4):
        ddq, N = _rigid_accelerations(plant, q[k], dq[k], tau[k], force[k])
        np.testing.assert_allclose(ddq, ours.ddq[k], rtol=0, atol=1e-6 * scale.max())
        np.testing.assert_allclose(N, ours.N[k], rtol=0, atol=1e-6 * N_scale)
    theirs = plant.forward(q, dq, tau, force)
    assert ours.N.min() > 0.2 and theirs.N.min() > 0.2
    assert np.max(np.abs(theirs.ddq - ours.ddq) / scale) < 0.15
    np.testing.assert_allclose(theirs.N, ours.N, rtol=0, atol=0.02 * N_scale)
    assert theirs.residual.max() < 0.01 * np.abs(tau).max()
    # a wrong mass, frame or gravity would show: with the mandible 10 % heavier the rigid answer is far off
    heavier = MujocoPlant(target, mjcf(target, friction=False).replace(f'mass="{target.mandible_mass:.17g}"',
                                                                       f'mass="{1.1 * target.mandible_mass:.17g}"'))
    ddq, _ = _rigid_accelerations(heavier, q[0], dq[0], tau[0], force[0])
    assert np.max(np.abs(ddq - ours.ddq[0]) / scale) > 0.1  # measured 0.9 (X), against 1e-6 above


def _home_torques(model) -> np.ndarray:
    from chewbot.dynamics.registry import inverse_dynamics

    t, zeros = np.array([0.0, 1.0]), np.zeros((2, 4))
    kin = solve_kinematics(model, Task("home", t, TARGET_COORDS, zeros, zeros, zeros, np.zeros((2, 3)), "left"))
    return inverse_dynamics(model, kin, "hessian").tau[0]


def _hold(plant, tau: np.ndarray, q0: np.ndarray) -> np.ndarray:
    """X, Y, alpha, beta at 0.25, 0.5, 0.75 and 1 s under the torques tau held, from rest at q0."""
    held = np.vstack([np.repeat(tau[:, None], 3, axis=1), np.zeros((3, 3))])
    state = plant.initial(0.0, q0, np.zeros(4))
    out = []
    for k in range(100):  # ticks of 10 ms
        state = plant.advance(state, 0.01, lambda t0, h: held)
        if k % 25 == 24:
            out.append(state.q)
    return np.array(out)


def test_chewbots_home_torques_hold_the_home_pose_in_mujoco(target):
    """The torques of chewbot's inverse dynamics at the home pose at rest, held on MuJoCo's robot from rest at home.

    The equilibrium is unstable (the mandible on its planes under constant torques): a disturbance grows as e^(lambda t)
    with lambda = 14.4 /s, in MuJoCo and in chewbot's plant alike (checked here: the growth of the last quarter second
    agrees within 5 %). chewbot's plant, started on the equilibrium, stays there; MuJoCo's first 10 ms move O_M by
    1.8e-10 m (the same with RK4 or implicitfast, steps of 0.1 or 0.05 ms, any solref; 10 times more at an impedance
    of 0.999 than at MuJoCo's largest, 0.9999: the constraints' softness), which has grown to 0.105 mm after 1 s: O_M
    stays within 0.03 mm for 0.9 s and within 0.11 mm for 1 s."""
    from chewbot.simulation.plant import Plant

    tau = _home_torques(target)
    plant = MujocoPlant(target, mjcf(target, friction=False))
    theirs = _hold(plant, tau, np.zeros(4))
    site = plant.mj.site("O_M").id
    assert np.linalg.norm(plant.data.site_xpos[site]) < 1.1e-4
    assert np.linalg.norm(theirs[1, :2]) < 1e-6  # at 0.5 s
    ours = _hold(Plant(target), tau, np.array([1e-9, 0, 0, 0]))  # chewbot's plant from a disturbance of 1 nm
    growth = [np.linalg.norm(x[3, :2]) / np.linalg.norm(x[2, :2]) for x in (theirs, ours)]
    assert growth[0] == pytest.approx(growth[1], rel=0.05)
    assert growth[1] > 20  # the test can fail: a stable equilibrium would not grow
    # the torques matter: 1 % less lets the mandible sag by far more within the same second
    plant.initial(0.0, np.zeros(4), np.zeros(4))
    _hold(plant, 0.99 * tau, np.zeros(4))
    assert np.linalg.norm(plant.data.site_xpos[site]) > 1e-3


def _settle(plant, tau: np.ndarray) -> tuple[np.ndarray, float]:
    """MuJoCo's own static equilibrium under the torques tau held (zero velocity, qacc = 0), found by Newton's
    method from the plant's current state: MuJoCo's qpos and the largest abs(qacc) left there.

    The Jacobian d qacc / d qpos is by central differences (steps of 1e-11 in MuJoCo's tangent coordinates: the
    soft constraints' stiffness, 1/(2e-4 s)^2, makes qacc change by about 1e-3 per step, far above rounding, and a
    step that small never moves a condyle off its plane); each Newton step halved until abs(qacc) decreases."""
    import mujoco

    m, d = plant.mj, plant.data

    def qacc(qpos):
        d.qpos[:], d.qvel[:] = qpos, 0
        plant._load(tau, np.zeros(3))
        mujoco.mj_forward(m, d)
        return d.qacc.copy()

    q = d.qpos.copy()
    a = qacc(q)
    for _ in range(8):
        J = np.zeros((m.nv, m.nv))
        for j in range(m.nv):
            e = np.zeros(m.nv)
            e[j] = 1e-11
            qp, qm = q.copy(), q.copy()
            mujoco.mj_integratePos(m, qp, e, 1.0)
            mujoco.mj_integratePos(m, qm, e, -1.0)
            J[:, j] = (qacc(qp) - qacc(qm)) / 2e-11
        step = -np.linalg.lstsq(J, a, rcond=None)[0]
        for frac in 0.5 ** np.arange(20):
            qn = q.copy()
            mujoco.mj_integratePos(m, qn, step, frac)
            an = qacc(qn)
            if np.abs(an).max() < np.abs(a).max():
                q, a = qn, an
                break
        else:
            break
    qacc(q)
    return q, float(np.abs(a).max())


def test_home_torques_hold_mujocos_own_equilibrium_at_home(target):
    """Started consistently, MuJoCo holds the home pose under chewbot's home torques: its own static equilibrium
    under those torques (the soft constraints deflected to carry the load, qacc = 0) lies 0.42 nm from home, and
    from there O_M moves 1.2e-11 m in 1 s (the issue asks at most 0.1 mm). Started instead on the rigid home pose
    (the previous test), the constraints' missing deflection is the 1.8e-10 m seed that the unstable equilibrium
    grows to 0.105 mm. With 1 % less torque there is no equilibrium near home: the search ends far from it or
    with qacc left."""
    import mujoco

    tau = _home_torques(target)
    plant = MujocoPlant(target, mjcf(target, friction=False))
    site = plant.mj.site("O_M").id
    plant.set_state(np.zeros(4), np.zeros(4))
    q, residual = _settle(plant, tau)
    start = plant.data.site_xpos[site].copy()
    assert residual < 1e-6  # rad/s^2 or m/s^2: from 0.67 on the rigid home pose
    assert np.linalg.norm(start) < 1e-9  # m: the soft constraints' deflection, not another pose
    plant.data.qpos[:], plant.data.qvel[:] = q, 0
    mujoco.mj_forward(plant.mj, plant.data)
    state = plant._state(0.0)
    held = np.vstack([np.repeat(tau[:, None], 3, axis=1), np.zeros((3, 3))])
    for _ in range(100):  # 1 s in ticks of 10 ms
        state = plant.advance(state, 0.01, lambda t0, h: held)
    assert np.linalg.norm(plant.data.site_xpos[site] - start) <= 1e-4  # the 0.1 mm over 1 s (measured 1.2e-11 m)
    assert np.linalg.norm(plant.data.site_xpos[site]) <= 1e-4
    plant.set_state(np.zeros(4), np.zeros(4))
    q, residual = _settle(plant, 0.99 * tau)
    assert residual > 1e-3 or np.linalg.norm(plant.data.site_xpos[site]) > 1e-6


@pytest.mark.slow
def test_computed_torque_tracks_the_default_task_in_mujoco():
    """Computed torque (Hessian method, 1 kHz, the exact model) on MuJoCo's plant: RMS tracking error at most 0.1 mm
    and 0.1 deg over the default task (measured 0.0018 mm and 0.0041 deg, as on chewbot's plant), both condyles pressed
    throughout, the loops closed to 1 um (measured 0.15 um)."""
    from chewbot.simulation.options import resolve
    from chewbot.simulation.run import compute

    r = compute(resolve(engine="mujoco", contact="unilateral"), write_mjcf=mjcf)
    assert r.metrics["stopped"] is None
    assert r.metrics["rms_position_mm"] <= 0.1 and r.metrics["rms_orientation_deg"] <= 0.1
    assert r.simulation.N.min() > 0
    assert r.table["drift_chains"].max() < 1e-6
    assert all(c.passed for c in r.checks), [c.name for c in r.checks if not c.passed]
