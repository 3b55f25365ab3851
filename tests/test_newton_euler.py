"""Newton–Euler inverse dynamics with friction (seed 001): each result held against another route.

Routes: the Hessian method (seed 000, frictionless minimum-norm torques), the other parametrisation of the
same motion, every free body's own Newton–Euler equations written here from the kinematics module's rates
(not from the formulation's internal elimination), and the power balance of the whole mechanism.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from chewbot.dynamics.registry import inverse_dynamics
from chewbot.dynamics.formulations.newton_euler import DELTA_N, EPS_V_T
from chewbot.dynamics.options import GOALS
from chewbot.errors import InfeasibleError
from chewbot.rotation import matrix_from_euler_angles

from support import default_kinematics, model, without_drive


@functools.cache
def ne(name="target", orientation="euler-angles", goal="min-torque", friction=True, side="left"):
    m = model(name)
    return inverse_dynamics(m, default_kinematics(name, side, orientation), "newton-euler", goal=goal, friction=friction)


def rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


# The Hessian method and Newton–Euler share no code below the kinematics; both are exact (AD and closed
# forms), so they agree to rounding amplified by the 6x6 solves (cond ~1e3): 1e-8 relative is the bound.
@pytest.mark.parametrize("name", ["target", "6rss"])
@pytest.mark.parametrize("side", ["left", "right"])
def test_frictionless_torques_equal_hessian_minimum_norm(name, side):
    m = model(name)
    kin = default_kinematics(name, side, "euler-angles")
    hessian = inverse_dynamics(m, kin, "hessian")
    assert rel(ne(name, friction=False, side=side).tau, hessian.tau) <= 1e-8


# One motion, two parametrisations: the same torques, to the Newton tolerance (1e-10 N on N_L, N_R) and
# rounding; 1e-9 relative is the bound.
@pytest.mark.parametrize("name,goal", [("target", g) for g in GOALS] + [("6rss", "min-torque")])
def test_euler_parameters_and_angles_give_the_same_torques(name, goal):
    a, p = ne(name, "euler-angles", goal), ne(name, "euler-parameters", goal)
    assert rel(p.tau, a.tau) <= 1e-9
    assert rel(p.table["tau_f1"], a.table["tau_f1"]) <= 1e-9


def test_each_goal_minimises_its_own_index():
    """Seed 001 Table 3: G1 gives the smallest F1, G2 the smallest F2, G3 the smallest F3 (and F3 ~ 0)."""
    idx = {g: ne(goal=g).info["indices"] for g in GOALS}
    for goal, key in zip(GOALS, ("F1", "F2", "F3")):
        others = [idx[g][key] for g in GOALS if g != goal]
        assert idx[goal][key] < min(others), (key, idx)
    # no limit is active on the default task, so G3 reaches N = 0 exactly
    assert idx["min-hkp-force"]["F3"] == 0.0


def _kinematic_state(name, orientation="euler-angles", side="left"):
    """Positions, velocities, accelerations of every body point, in NumPy from the kinematics module's rates."""
    m, kin = model(name), default_kinematics(name, side, orientation)
    R = matrix_from_euler_angles(kin.X[:, 3:6])
    p = kin.X[:, :3]
    v_O, w, a_O, dw = kin.twist[:, :3], kin.twist[:, 3:], kin.twist_rate[:, :3], kin.twist_rate[:, 3:]

    def body(point):
        r = R @ point
        return (p + r, r, v_O + np.cross(w, r), a_O + np.cross(dw, r) + np.cross(w, np.cross(w, r)))

    z = m.R_C0[:, :, 2]
    c, s = np.cos(kin.theta), np.sin(kin.theta)
    r_GS = m.crank_length[None, :, None] * (c[..., None] * m.R_C0[None, :, :, 0] + s[..., None] * m.R_C0[None, :, :, 1])
    v_S = kin.dtheta[..., None] * np.cross(z[None], r_GS)
    a_S = kin.ddtheta[..., None] * np.cross(z[None], r_GS) - kin.dtheta[..., None] ** 2 * r_GS
    return m, kin, R, body, r_GS, v_S, a_S


def _cols(table, fmt, n, comps="xyz"):
    return np.stack([np.stack([table[fmt.format(i + 1, c)] for c in comps], axis=1) for i in range(n)], axis=1)


@pytest.mark.parametrize("name,goal", [("target", "min-torque"), ("target", "min-coupler-force"), ("6rss", "min-torque")])
def test_every_body_satisfies_its_newton_euler_equations(name, goal):
    """Mandible, each coupler, each crank: force and moment residuals with the computed constraint forces."""
    dyn = ne(name, goal=goal)
    m, kin, R, body, r_GS, v_S, a_S = _kinematic_state(name)
    t = dyn.table
    grav = np.array([0.0, 0.0, -m.g])
    FS, FM, FG = _cols(t, "FS{}_{}", 6), _cols(t, "FM{}_{}", 6), _cols(t, "FG{}_{}", 6)
    MG = _cols(t, "MG{}_{}", 6, "xy")
    scale_F = np.abs(FS).max()  # tens of newtons
    scale_M = scale_F * 0.05  # a force times the mandible's size
    # Rounding of the 6x6 solves only (every term here is exact): 1e-10 relative to the largest force.
    tol_F, tol_M = 1e-10 * scale_F, 1e-10 * scale_M

    # couplers: Newton at the mass centre E, Euler about E with the rod's inertia tensor (no spin inertia)
    pos_M = []
    for i in range(6):
        P, r, v, a = body(m.M[i])
        S = m.G[i] + r_GS[:, i]
        L, mc = m.coupler_length[i], m.coupler_mass[i]
        u = (P - S) / L
        du, ddu = (v - v_S[:, i]) / L, (a - a_S[:, i]) / L
        a_E = (a + a_S[:, i]) / 2
        newton = FS[:, i] - FM[:, i] + mc * grav - mc * a_E
        assert np.abs(newton).max() <= tol_F
        I_E = mc * L**2 / 12 * (np.eye(3) - u[:, :, None] * u[:, None, :])
        w_c, dw_c = np.cross(u, du), np.cross(u, ddu)
        rate = np.einsum("nij,nj->ni", I_E, dw_c) + np.cross(w_c, np.einsum("nij,nj->ni", I_E, w_c))
        euler = np.cross(-L / 2 * u, FS[:, i]) + np.cross(L / 2 * u, -FM[:, i]) - rate
        assert np.abs(euler).max() <= tol_M
        pos_M.append(r)

    # cranks: mass centre fixed at G_i; moment about G_i = (I_i + J_r N^2) theta_ddot z_i, the rotor reflected to it
    rotor = 0.0 if m.drive is None else m.drive.rotor_inertia * m.drive.gear_ratio**2
    for i in range(6):
        x, y, z = m.R_C0[i].T
        assert np.abs(FG[:, i] - FS[:, i] + m.crank_mass[i] * grav).max() <= tol_F
        drive = (dyn.tau[:, i] - t[f"tau_f{i + 1}"])[:, None] * z
        moment = drive + MG[:, i, :1] * x + MG[:, i, 1:] * y + np.cross(r_GS[:, i], -FS[:, i])
        assert np.abs(moment - (m.crank_inertia[i] + rotor) * kin.ddtheta[:, i, None] * z).max() <= tol_M

    # mandible: Newton at O_M and Euler about O_M with I = R I_M R'
    _, r_B, _, _ = body(m.molar(kin.side))
    F = FM.sum(axis=1) + kin.force + m.mandible_mass * grav
    Mo = np.cross(np.stack(pos_M, axis=1), FM).sum(axis=1) + np.cross(r_B, kin.force)
    if m.has_hkp:
        n = m.hkp.normal
        for j, T in zip("LR", (m.hkp.T_L, m.hkp.T_R)):
            _, r_T, _, _ = body(T)
            f = t[f"N_{j}"][:, None] * n + np.stack([t[f"fT_{j}_{c}"] for c in "xyz"], axis=1)
            F, Mo = F + f, Mo + np.cross(r_T, f)
    I_S = R @ m.mandible_inertia @ R.transpose(0, 2, 1)
    w, dw = kin.twist[:, 3:], kin.twist_rate[:, 3:]
    assert np.abs(F - m.mandible_mass * kin.twist_rate[:, :3]).max() <= tol_F
    euler = Mo - np.einsum("nij,nj->ni", I_S, dw) - np.cross(w, np.einsum("nij,nj->ni", I_S, w))
    assert np.abs(euler).max() <= tol_M


def _mechanical_energy(name):
    """Kinetic + potential energy of mandible, couplers and cranks (J), written from first principles."""
    m, kin, R, body, r_GS, v_S, a_S = _kinematic_state(name)
    v_O, w = kin.twist[:, :3], kin.twist[:, 3:]
    I_S = R @ m.mandible_inertia @ R.transpose(0, 2, 1)
    E = 0.5 * m.mandible_mass * (v_O**2).sum(1) + 0.5 * np.einsum("ni,nij,nj->n", w, I_S, w) + m.mandible_mass * m.g * kin.X[:, 2]
    E += 0.5 * (m.crank_inertia * kin.dtheta**2).sum(1)
    if m.drive is not None:  # the rotors turn N times faster than their cranks
        E += 0.5 * m.drive.rotor_inertia * ((m.drive.gear_ratio * kin.dtheta) ** 2).sum(1)
    for i in range(6):
        P, _, v, _ = body(m.M[i])
        S = m.G[i] + r_GS[:, i]
        L, mc = m.coupler_length[i], m.coupler_mass[i]
        v_E, du = (v + v_S[:, i]) / 2, (v - v_S[:, i]) / L
        E += 0.5 * mc * (v_E**2).sum(1) + 0.5 * mc * L**2 / 12 * (du**2).sum(1) + mc * m.g * (P + S)[:, 2] / 2
    return m, kin, body, E


@pytest.mark.parametrize("friction", [False, True])
def test_power_balance(friction):
    """tau . theta_dot + F_B . v_B = dE/dt + dissipation (actuator and HKP friction; 0 without friction).

    dE/dt by central differences (tests only). Their error is dt^2/6 E''' (dt = 1 ms): bounded here by the
    difference between steps dt and 2 dt, (4 - 1) dt^2/6 E''', so the tolerance is that difference (a
    measured bound on the truncation error, the largest over five samples) plus rounding.
    """
    dyn = ne("target", friction=friction)
    m, kin, body, E = _mechanical_energy("target")
    dt = kin.t[1] - kin.t[0]
    dE = (E[2:] - E[:-2]) / (2 * dt)
    dE2 = (E[4:] - E[:-4]) / (4 * dt)
    _, _, v_B, _ = body(m.molar(kin.side))
    P_in = (dyn.tau * kin.dtheta).sum(1) + (kin.force * v_B).sum(1)
    lost = (np.stack([dyn.table[f"tau_f{i + 1}"] for i in range(6)], 1) * kin.dtheta).sum(1)
    for j, T in zip("LR", (m.hkp.T_L, m.hkp.T_R)):
        _, _, v_T, _ = body(T)
        lost -= (np.stack([dyn.table[f"fT_{j}_{c}"] for c in "xyz"], 1) * v_T).sum(1)
    assert lost.min() >= -1e-12  # friction only dissipates
    if not friction:
        assert np.abs(lost).max() == 0.0
    residual = (P_in - lost)[1:-1] - dE
    # the truncation estimate, the largest over the five samples the wider difference spans: where the task's cycles
    # meet its jerk jumps (it is C2 there) and the estimate of one sample changes sign
    truncation = np.abs(dE[1:-1] - dE2)
    truncation = np.max([np.pad(truncation, 2, mode="edge")[j:j + truncation.size] for j in range(5)], axis=0)
    bound = truncation + 1e-9 * np.abs(P_in).max()
    assert np.all(np.abs(residual[1:-1]) <= bound)


def test_hkp_friction_matches_the_unsmoothed_law_away_from_zero_velocity():
    """f_T = -(mu_c |N| + mu_v |v|) v/|v|: the smoothing of |N| and v/|v| changes it by at most mu_c delta
    plus the velocity regularisation, (1 - |v|/sqrt(v^2+eps^2)) mu_c |N| <= mu_c |N| eps^2 / (2 v^2)."""
    dyn = ne("target")
    m, kin, _, body, *_ = _kinematic_state("target")
    fr = m.friction
    for j, T in zip("LR", (m.hkp.T_L, m.hkp.T_R)):
        _, _, v, _ = body(T)
        moving = np.linalg.norm(v, axis=1) > 1e-3  # 1 mm/s, 100 eps: most of the chewing cycles
        v = v[moving]
        speed = np.linalg.norm(v, axis=1)
        N = dyn.table[f"N_{j}"][moving]
        exact = -(fr.hkp_coulomb * np.abs(N) + fr.hkp_viscous * speed)[:, None] * v / speed[:, None]
        got = np.stack([dyn.table[f"fT_{j}_{c}"] for c in "xyz"], 1)[moving]
        bound = fr.hkp_coulomb * (DELTA_N + np.abs(N) * 0.5 * (EPS_V_T / speed) ** 2) + 1e-12
        assert moving.sum() > 1000
        assert np.all(np.linalg.norm(got - exact, axis=1) <= bound)


@pytest.mark.parametrize("name", ["target", "6rss"])
def test_actuator_friction_matches_its_law(name):
    """tau_f = R mu_c |F_G| sgn(theta_dot) + mu_v theta_dot (MODEL.md), rebuilt from the bearing-force columns
    FG1_x.. and theta_dot: the smoothing changes it by at most R mu_c (delta + |F_G| eps^2 / (2 theta_dot^2))
    where the crank turns faster than 100 eps; elsewhere (at rest) the Coulomb part is regularised to zero."""
    from chewbot.dynamics.formulations.newton_euler import DELTA_F_G, EPS_THETA_DOT

    dyn = ne(name)
    m, kin = model(name), default_kinematics(name)
    fr = m.friction
    FG = np.linalg.norm(_cols(dyn.table, "FG{}_{}", 6), axis=2)
    dth = kin.dtheta
    exact = fr.actuator_arm * fr.actuator_coulomb * FG * np.sign(dth) + fr.actuator_viscous * dth
    got = np.column_stack([dyn.table[f"tau_f{i + 1}"] for i in range(6)])
    turning = np.abs(dth) > 100 * EPS_THETA_DOT
    bound = fr.actuator_arm * fr.actuator_coulomb * (DELTA_F_G + FG * 0.5 * (EPS_THETA_DOT / np.where(turning, dth, 1.0)) ** 2) + 1e-15
    assert turning.sum() > 10000
    assert np.all(np.abs(got - exact)[turning] <= bound[turning])
    # and the law is not trivially met: without the crank's weight in F_G it is off by far more than the bound
    no_weight = np.linalg.norm(_cols(dyn.table, "FS{}_{}", 6), axis=2)
    wrong = fr.actuator_arm * fr.actuator_coulomb * no_weight * np.sign(dth) + fr.actuator_viscous * dth
    assert np.abs(got - wrong)[turning].max() > 100 * bound[turning].max()


def test_friction_share_and_indices_follow_their_definitions():
    """Eq. 75 and F4..F7 recomputed from the table's columns by their definitions (MODEL.md), sample by sample."""
    dyn = ne("target")
    t = dyn.table
    for i in range(1, 7):
        share = 100 * np.abs(t[f"tau_f{i}"] + t[f"tau_fT{i}"]) / np.abs(dyn.tau[:, i - 1])
        assert np.allclose(t[f"friction_share{i}"], share, rtol=1e-12, atol=0)
    stack = {
        "F4": np.column_stack([t[f"tau_f{i}"] for i in range(1, 7)]),
        "F5": np.column_stack([t[f"MG{i}_{c}"] for i in range(1, 7) for c in "xy"]),
        "F6": np.column_stack([t[f"FG{i}_{c}"] for i in range(1, 7) for c in "xyz"]),
        "F7": np.column_stack([t[f"fT_{j}_{c}"] for j in "LR" for c in "xyz"]),
    }
    for key, values in stack.items():
        assert dyn.info["indices"][key] == pytest.approx(np.mean([np.linalg.norm(row) for row in values]), rel=1e-12)


def _with_limits(name, **limits):
    m = model(name)
    return dataclasses.replace(m, limits=dataclasses.replace(m.limits, **limits))


def test_active_torque_limit_is_respected_by_the_constrained_solution():
    """A torque limit below the G1 optimum's peak: the SQP samples meet it, cost no less than the
    unconstrained optimum, and nothing is reported infeasible. On the robot without its drive: the rotors' inertia
    torques, which no distribution moves off their cranks, make 90 % of the peak unreachable where cranks 3 and 4
    accelerate hardest."""
    plain = without_drive("target")
    kin = default_kinematics("target", "left", "euler-angles")  # the same geometry
    free = inverse_dynamics(plain, kin, "newton-euler")
    peak = np.abs(free.tau).max()
    m = dataclasses.replace(plain, limits=dataclasses.replace(plain.limits, torque=0.9 * peak))
    dyn = inverse_dynamics(m, kin, "newton-euler")
    assert dyn.info["constrained_samples"] > 0
    assert dyn.info["infeasible"] == []
    assert np.abs(dyn.tau).max() <= 0.9 * peak * (1 + 1e-6)
    assert np.all((dyn.tau**2).sum(1) >= (free.tau**2).sum(1) * (1 - 1e-9))


def test_infeasible_samples_are_reported_not_clipped():
    m = _with_limits("target", axial_load=1e-3)
    kin = default_kinematics("target", "left", "euler-angles")
    dyn = inverse_dynamics(m, kin, "newton-euler")
    bad = dyn.info["infeasible"]
    assert bad and {"sample", "t", "limits"} <= set(bad[0])
    assert any(name.startswith("axial_load") for name in bad[0]["limits"])
    with pytest.raises(InfeasibleError, match=r"sample \d+ .*axial_load"):
        inverse_dynamics(m, kin, "newton-euler", strict=True)


def test_outputs_are_named_with_units():
    t = ne().table
    for name, unit in (("tau_f1", "N*m"), ("N_L", "N"), ("fT_R_z", "N"), ("FS6_z", "N"), ("FG3_x", "N"),
                       ("MG2_y", "N*m"), ("friction_share4", "%"), ("FG1_axial", "N")):
        assert t.units[name] == unit
    assert set(ne().info["indices"]) == {f"F{k}" for k in range(1, 8)}
    assert "N_L" not in ne("6rss").table and np.isnan(ne("6rss").info["indices"]["F3"])


def test_bad_goal_is_rejected():
    with pytest.raises(ValueError, match="goal must be one of"):
        inverse_dynamics(model("target"), default_kinematics(), "newton-euler", goal="fast")


def test_cli_runs_newton_euler_with_goal_and_friction(tmp_path):
    import json

    from typer.testing import CliRunner

    from chewbot.cli import app

    out = tmp_path / "ne"
    result = CliRunner().invoke(app, ["run", "--method", "newton-euler", "--goal", "min-hkp-force",
                                      "--friction", "off", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    run = json.loads((out / "run.json").read_text())
    assert run["options"]["goal"] == "min-hkp-force" and run["options"]["friction"] == "off"
    assert run["columns"]["FS1_x"]["unit"] == "N" and run["dynamics"]["friction"] is False
    assert (out / "ne_friction_share.png").exists()
    # options that do not apply are refused, not recorded as if they had been used
    for args, reason in ((["--model", "6rss", "--method", "newton-euler", "--goal", "min-hkp-force"], "no redundant actuation"),
                         (["--method", "liang", "--friction", "off"], "--friction applies to the newton-euler method")):
        refused = CliRunner().invoke(app, ["run", *args, "--out", str(tmp_path / "no"), "--quiet"])
        assert refused.exit_code == 2 and reason in refused.output, refused.output
        assert not (tmp_path / "no").exists()
