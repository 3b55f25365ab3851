"""Kinematics of both mechanisms, each quantity held against an independent route to it.

Finite differences appear here only (the product differentiates exactly). Central differences with step h have
a truncation error ~h^2 f'''/6 and a rounding error ~eps f / h; the tolerances below say which dominates.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import default_kinematics, model

from chewbot.compiled.kernels import evaluate
from chewbot.errors import KinematicsError
from chewbot.kinematics.functions import pose_function
from chewbot.kinematics.ik import forward_kinematics, inverse_kinematics, transmission
from chewbot.kinematics.motion import solve_kinematics
from chewbot.rotation import (
    euler_angles_to_parameters,
    euler_parameters_to_angles,
    matrix_from_euler_angles,
    matrix_from_euler_parameters,
)
from chewbot.kinematics.task import TARGET_COORDS, Task
from chewbot.task.default import ChewingParameters, default_task, lift_to_full

ORIENTATIONS = ("euler-angles", "euler-parameters")
# amplitudes of the random smooth task (m, m, rad, rad): inside both sockets and far from singularities
AMPLITUDE = np.array([1.5e-3, 1.0e-3, np.radians(1.0), np.radians(3.0)])
OFFSET = np.array([0.5e-3, 0.0, 0.0, np.radians(4.0)])


def smooth_motion(t: np.ndarray, seed: int = 1):
    """A random sum of sines in (X, Y, alpha, beta) with its exact rates: (q, dq, ddq), (N, 4) each."""
    rng = np.random.default_rng(seed)
    freq = rng.uniform(0.3, 2.0, (3, 4))  # Hz
    phase = rng.uniform(0, 2 * np.pi, (3, 4))
    weight = rng.uniform(0.2, 1.0, (3, 4))
    weight /= weight.sum(axis=0)
    w = 2 * np.pi * freq
    arg = w[None] * np.asarray(t)[:, None, None] + phase[None]
    q = OFFSET + AMPLITUDE * (weight * np.sin(arg)).sum(axis=1)
    dq = AMPLITUDE * (weight * w * np.cos(arg)).sum(axis=1)
    ddq = -AMPLITUDE * (weight * w**2 * np.sin(arg)).sum(axis=1)
    return q, dq, ddq


def smooth_task(name: str, t: np.ndarray) -> Task:
    q, dq, ddq = smooth_motion(t)
    task = Task("random-smooth", np.asarray(t, dtype=float), TARGET_COORDS, q, dq, ddq, np.zeros((len(t), 3)))
    m = model(name)
    return task if m.has_hkp else lift_to_full(m, task)


def smooth_kinematics(name: str, orientation: str, t: np.ndarray):
    return solve_kinematics(model(name), smooth_task(name, t), orientation)


# ------------------------------------------------------------------ the HKPs and the parasitic motions


@pytest.mark.parametrize("orientation", ORIENTATIONS)
@pytest.mark.parametrize("which", ["default", "random"])
def test_hkp_residual_at_both_condyles(orientation, which):
    m = model("target")
    kin = default_kinematics("target", "left", orientation) if which == "default" else smooth_kinematics("target", orientation, np.linspace(0, 3, 601))
    for label in ("T_L", "T_R"):
        T = kin.points[label]
        # both plane equations p1 x + z + p2 = 0; the parasitic motions are closed form: 1e-12 m is rounding
        assert np.abs(m.hkp.p1 * T[:, 0] + T[:, 2] + m.hkp.p2).max() <= 1e-12


def test_parasitic_gamma_satisfies_the_difference_equation_and_the_printed_formula_does_not():
    p1 = model("target").hkp.p1
    a, b = np.meshgrid(np.linspace(-0.3, 0.3, 13), np.linspace(-0.4, 0.4, 17))
    a, b = a.ravel(), b.ravel()
    task = Task("grid", np.arange(a.size, dtype=float), TARGET_COORDS, np.column_stack([0 * a, 0 * a, a, b]),
                np.zeros((a.size, 4)), np.zeros((a.size, 4)), np.zeros((a.size, 3)))
    X = lift_to_full(model("target"), task).q
    R = matrix_from_euler_angles(X[:, 3:6])
    assert np.abs(p1 * R[:, 0, 1] + R[:, 2, 1]).max() < 1e-14  # rounding of a closed form

    alpha, beta = 0.05, 0.2
    printed = np.arctan2(np.sin(alpha), p1 * np.cos(beta) + np.cos(alpha) * np.sin(beta))  # seed 000 Eq. (5) as printed
    R = matrix_from_euler_angles(np.array([[alpha, beta, printed]]))[0]
    residual = p1 * R[0, 1] + R[2, 1]
    assert 5e-3 < abs(residual) < 5e-2  # MODEL.md: violated by ~1e-2


def test_parasitic_e3_satisfies_the_difference_equation():
    p1 = model("target").hkp.p1
    kin = smooth_kinematics("target", "euler-parameters", np.linspace(0, 3, 301))
    pose, _, R = evaluate(pose_function("target", "euler-parameters"), kin.q, model("target").vector())
    assert np.abs(p1 * R[:, 0, 1] + R[:, 2, 1]).max() < 1e-14
    assert np.abs((pose[:, 3:7] ** 2).sum(axis=1) - 1).max() < 1e-14  # |e| = 1 with e3 parasitic


# ------------------------------------------------------------------ IK and FK


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_ik_then_fk_round_trip(mechanism, orientation):
    kin = default_kinematics(mechanism, "left", orientation)
    rows = slice(1000, None, 97)
    q = forward_kinematics(model(mechanism), kin.theta[rows], orientation)  # starts from home, not from the answer
    # Newton converges quadratically; 1e-11 (m, rad, -) leaves room for the conditioning of the closure equations
    assert np.abs(q - kin.q[rows]).max() < 1e-11


def test_home_pose_solves_near_zero():
    m = model("target")
    theta = inverse_kinematics(m, np.zeros((1, 3)), np.eye(3)[None])
    # MODEL.md: the printed geometry disagrees in the 4th digit, so theta is 0 only to 0.02 deg
    assert np.degrees(np.abs(theta)).max() < 0.02


# ------------------------------------------------------------------ Jacobians against finite differences


def _closure(m, p, R, theta):
    """h_i = abs(S_i - M_i)^2 - L_r^2 written out in NumPy (seed 000, Eq. 8), for the finite differences."""
    u, v = m.R_C0[:, :, 0], m.R_C0[:, :, 1]
    S = m.G + m.crank_length[:, None] * (np.cos(theta)[:, None] * u + np.sin(theta)[:, None] * v)
    Mi = p + m.M @ R.T
    return ((S - Mi) ** 2).sum(axis=1) - m.coupler_length**2


def _vee(W):
    return np.array([W[2, 1], W[0, 2], W[1, 0]])


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_jacobians_against_finite_differences(mechanism, orientation):
    m = model(mechanism)
    kin = default_kinematics(mechanism, "left", orientation)
    jac = kin.jacobians()
    fn, p = pose_function(mechanism, orientation), m.vector()

    def pose(x):
        return fn(x, p)

    h = 1e-6  # coordinates are ~1e-3 m and ~0.1 rad: truncation ~1e-12, rounding ~1e-10 of the entries
    for k in range(1000, kin.n, 613):
        q, theta = kin.q[k], kin.theta[k]
        n = q.size
        x0, p0, R0 = (np.asarray(o) for o in pose(q))
        Jq, MJ, M0b, Jt1 = (np.empty((6, n)), np.empty((x0.size, n)), np.empty((6, n)), np.empty((6, n)))
        for j in range(n):
            dx = np.zeros(n)
            dx[j] = h
            (xp, pp, Rp), (xm, pm, Rm) = ((np.asarray(o) for o in pose(x)) for x in (q + dx, q - dx))
            Jq[:, j] = (_closure(m, pp.ravel(), Rp, theta) - _closure(m, pm.ravel(), Rm, theta)) / (2 * h)
            MJ[:, j] = (xp - xm).ravel() / (2 * h)
            M0b[:, j] = np.r_[(pp - pm).ravel() / (2 * h), _vee((Rp - Rm) / (2 * h) @ R0.T)]
            # J_theta1 by the closed-form IK: a route that never touches the closure's derivatives
            th = [inverse_kinematics(m, x.reshape(1, 3), Rx[None])[0] for x, Rx in ((pp, Rp), (pm, Rm))]
            Jt1[:, j] = (th[0] - th[1]) / (2 * h)
        Jt = np.array([(_closure(m, p0.ravel(), R0, theta + h * e) - _closure(m, p0.ravel(), R0, theta - h * e)) @ e / (2 * h) for e in np.eye(6)])
        for name, fd in (("J_theta", Jt), ("J_qEE", Jq), ("M_J", MJ), ("M_0b", M0b), ("J_theta1", Jt1)):
            exact = jac[name][k]
            assert np.abs(exact - fd).max() <= 1e-7 * np.abs(fd).max(), (name, k)
        # M_0b = M_0a M_J (seed 000, Eq. 33)
        assert np.abs(jac["M_0a"][k] @ jac["M_J"][k] - jac["M_0b"][k]).max() < 1e-13 * np.abs(jac["M_0b"][k]).max()


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_rates_against_finite_differences_in_time(mechanism, orientation):
    """twist, twist rate, theta_dot, theta_ddot along an analytic motion, against central differences in time."""
    h = 1e-4  # s; motions of ~1 Hz: truncation ~h^2 (2 pi)^3 / 6 ~ 4e-7 relative, rounding ~eps / h ~ 1e-12
    t0 = np.linspace(0.2, 2.8, 9)
    t = np.concatenate([t0 - h, t0, t0 + h])
    kin = smooth_kinematics(mechanism, orientation, t)
    n = t0.size
    lo, mid, hi = slice(0, n), slice(n, 2 * n), slice(2 * n, 3 * n)
    _, p, R = evaluate(pose_function(mechanism, orientation), kin.q, model(mechanism).vector())
    v = (p[hi] - p[lo]) / (2 * h)
    Rdot = (R[hi] - R[lo]) / (2 * h)
    omega = np.array([_vee(Rd @ Rm.T) for Rd, Rm in zip(Rdot, R[mid])])  # [omega]x = R_dot R^T
    checks = {
        "twist": (kin.twist[mid], np.column_stack([v, omega])),
        "twist_rate": (kin.twist_rate[mid], (kin.twist[hi] - kin.twist[lo]) / (2 * h)),
        "dtheta": (kin.dtheta[mid], (kin.theta[hi] - kin.theta[lo]) / (2 * h)),
        "ddtheta": (kin.ddtheta[mid], (kin.dtheta[hi] - kin.dtheta[lo]) / (2 * h)),
        "ddtheta from theta": (kin.ddtheta[mid], (kin.theta[hi] - 2 * kin.theta[mid] + kin.theta[lo]) / h**2),
    }
    for name, (exact, fd) in checks.items():
        # second differences lose eps / h^2 ~ 2e-8 of theta (~0.1 rad): 1e-5 relative covers both
        tol = (1e-5 if name == "ddtheta from theta" else 1e-6) * np.abs(fd).max()
        assert np.abs(exact - fd).max() <= tol, name


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_J_theta2_to_4_against_finite_differences_in_time(mechanism, orientation):
    """J_theta2 = -J_theta^-1 (J_theta_dot J_theta1 + J_qEE_dot) (Eq. 17) with the Jacobians' rates by central
    differences in time along an analytic motion; J_theta3, J_theta4 stack them as Eq. (19); and
    theta_ddot = J_theta2 q_dot + J_theta1 q_ddot (Eq. 16)."""
    h = 1e-4  # s, as in the test above: truncation ~4e-7 relative
    t0 = np.linspace(0.2, 2.8, 9)
    kin = smooth_kinematics(mechanism, orientation, np.concatenate([t0 - h, t0, t0 + h]))
    n = t0.size
    lo, mid, hi = slice(0, n), slice(n, 2 * n), slice(2 * n, 3 * n)
    jac = kin.jacobians()
    Jt_dot = (jac["J_theta"][hi] - jac["J_theta"][lo]) / (2 * h)
    JqEE_dot = (jac["J_qEE"][hi] - jac["J_qEE"][lo]) / (2 * h)
    fd = -(Jt_dot[:, :, None] * jac["J_theta1"][mid] + JqEE_dot) / jac["J_theta"][mid][:, :, None]
    J2 = jac["J_theta2"][mid]
    assert np.abs(J2 - fd).max() <= 1e-6 * np.abs(fd).max()
    ne = kin.q.shape[1]
    assert np.array_equal(jac["J_theta3"][mid][:, :6], jac["J_theta1"][mid])
    assert np.array_equal(jac["J_theta3"][mid][:, 6:], np.broadcast_to(np.eye(ne), (n, ne, ne)))
    assert np.array_equal(jac["J_theta4"][mid][:, :6], J2) and not jac["J_theta4"][mid][:, 6:].any()
    ddtheta = np.einsum("nij,nj->ni", J2, kin.dq[mid]) + np.einsum("nij,nj->ni", jac["J_theta1"][mid], kin.ddq[mid])
    assert np.abs(ddtheta - kin.ddtheta[mid]).max() <= 1e-10 * np.abs(kin.ddtheta[mid]).max()


# ------------------------------------------------------------------ orientation conversions


def _angle_motion(t):
    """An analytic motion of XYZ angles (beta up to ~1.2 rad, away from gimbal lock) with exact rates."""
    c = np.array([[0.3, -0.2, 0.5], [0.4, 1.1, -0.7], [0.2, -0.3, 0.6]])  # a, b sin(w t), w per angle
    w = np.array([1.3, 0.9, 2.1])
    a = c[0] + c[1] * np.sin(w * t[:, None])
    da = c[1] * w * np.cos(w * t[:, None])
    dda = -c[1] * w**2 * np.sin(w * t[:, None])
    return a, da, dda


def test_euler_angles_to_parameters_and_back_at_three_levels():
    t = np.linspace(0, 5, 41)
    a, da, dda = _angle_motion(t)
    e, de, dde = euler_angles_to_parameters(a, da, dda)
    # the same rotation, unit norm, and its derivative constraints e.e_dot = 0, e.e_ddot + abs(e_dot)^2 = 0
    assert np.abs(matrix_from_euler_parameters(e) - matrix_from_euler_angles(a)).max() < 1e-14
    assert np.abs((e * e).sum(1) - 1).max() < 1e-14
    assert np.abs((e * de).sum(1)).max() < 1e-14
    assert np.abs((e * dde).sum(1) + (de * de).sum(1)).max() < 1e-13
    back = euler_parameters_to_angles(e, de, dde)
    for x, y in zip(back, (a, da, dda)):
        assert np.abs(x - y).max() < 1e-12  # cos(beta) >= 0.3 here: the inverse maps lose at most a few digits


def _E(e):
    """E(e) written out (omega = 2 E e_dot, angular velocity in {S})."""
    return np.array([[-e[1], e[0], -e[3], e[2]], [-e[2], e[3], e[0], -e[1]], [-e[3], -e[2], e[1], e[0]]])


def test_euler_parameters_against_finite_differences_of_the_rotation():
    h = 1e-5  # s; rates ~1-4 rad/s: truncation ~h^2 w^3 ~ 1e-9, rounding ~eps / h ~ 1e-11
    t0 = np.linspace(0.1, 4.9, 7)
    t = np.concatenate([t0 - h, t0, t0 + h])
    a, da, dda = _angle_motion(t)
    e, de, dde = euler_angles_to_parameters(a, da, dda)
    n = t0.size
    R = matrix_from_euler_angles(a)
    Rdot = (R[2 * n:] - R[:n]) / (2 * h)
    omega_fd = np.array([_vee(x @ y.T) for x, y in zip(Rdot, R[n:2 * n])])
    omega = np.array([2 * _E(x) @ y for x, y in zip(e, de)])
    assert np.abs(omega[n:2 * n] - omega_fd).max() < 1e-8
    omega_dot_fd = (omega[2 * n:] - omega[:n]) / (2 * h)
    omega_dot = np.array([2 * _E(x) @ y for x, y in zip(e[n:2 * n], dde[n:2 * n])])
    assert np.abs(omega_dot - omega_dot_fd).max() < 1e-7


def test_gimbal_lock_is_reported_with_its_sample():
    a = np.array([[0.1, 0.2, 0.3], [0.1, np.pi / 2, 0.3]])
    e, de, dde = euler_angles_to_parameters(a, np.ones_like(a), np.zeros_like(a))
    with pytest.raises(KinematicsError, match=r"sample 1.*gimbal lock"):
        euler_parameters_to_angles(e, de, dde)


# ------------------------------------------------------------------ the default task and bad poses


def test_default_task_rates_are_the_derivatives_of_its_positions(mechanism):
    params = ChewingParameters()
    task = default_task(model(mechanism), "left", params)
    h = task.t[1] - task.t[0]
    # the bumps are polynomials inside a cycle and join with C^2 continuity only: keep the stencils off the joins
    joins = params.rest_s + params.period_s * np.arange(params.cycles + 1)
    inside = np.abs(task.t[1:-1, None] - joins[None]).min(axis=1) > 1.5 * h
    for lower, upper in ((task.q, task.dq), (task.dq, task.ddq)):
        fd = (lower[2:] - lower[:-2]) / (2 * h)
        # truncation of a central difference: h^2/6 max abs(third derivative of `lower`), bounded from the data
        third = np.abs(np.diff(upper, 2, axis=0)).max(axis=0) / h**2
        tol = 1.5 * h**2 / 6 * third + 1e-12
        assert (np.abs(fd - upper[1:-1])[inside].max(axis=0) <= tol).all()
    assert (np.abs(task.dq).max(axis=0) > 0).all()  # not a trivially constant task


def test_all_peaks_together_push_a_condyle_out_of_its_socket():
    m = model("target")
    params = ChewingParameters(peak_swing=0.4, peak_open=0.4)
    with pytest.raises(KinematicsError, match=r"sample \d+.*condyle leaves its socket"):
        solve_kinematics(m, default_task(m, "left", params))


def _constant_task(coords_values, mechanism):
    q = np.tile(coords_values, (5, 1))
    return Task("constant", np.arange(5) * 1e-3, TARGET_COORDS if mechanism == "target" else ("X", "Y", "Z", "alpha", "beta", "gamma"),
                q, np.zeros_like(q), np.zeros_like(q), np.zeros((5, 3)))


def test_condyle_outside_socket_is_reported():
    with pytest.raises(KinematicsError, match=r"sample 0.*left condyle leaves its socket.*x in \[-10, 5\] mm"):
        solve_kinematics(model("target"), _constant_task([8e-3, 0, 0, 0], "target"))


def test_unreachable_pose_names_sample_and_chain():
    with pytest.raises(KinematicsError, match=r"sample 0.*chain \d.*out of reach") as err:
        solve_kinematics(model("6rss"), _constant_task([0, 0, 0.03, 0, 0, 0], "6rss"))
    assert err.value.sample == 0 and err.value.chain in range(1, 7)


def test_singular_configuration_is_reported():
    m = model("6rss")
    # bisect along Z between home (reachable) and 30 mm (not) for the boundary, where a crank and its coupler align
    lo, hi = 0.0, 0.03
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        reach = transmission(m, np.array([[0, 0, mid]]), np.eye(3)[None]).min() > 0
        lo, hi = (mid, hi) if reach else (lo, mid)
    assert 0 < transmission(m, np.array([[0, 0, lo]]), np.eye(3)[None]).min() < 1e-4
    with pytest.raises(KinematicsError, match=r"sample 0.*chain \d is singular") as err:
        solve_kinematics(m, _constant_task([0, 0, lo, 0, 0, 0], "6rss"))
    assert err.value.chain in range(1, 7)


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_parallel_singularity_is_reported(orientation):
    """Six couplers meeting at one point of the mandible leave its rotations about that point to no actuator:
    J_theta1 has rank 3 (type II singularity). The default geometry at the same pose is far from it."""
    import dataclasses

    m = model("6rss")
    common = np.array([0.02, 0.0, -0.02])  # m, in {M}; at home {M} = {S}
    singular = dataclasses.replace(m, M=np.tile(common, (6, 1)), coupler_length=np.linalg.norm(m.S0 - common, axis=1))
    task = _constant_task([0, 0, 0, 0, 0, 0], "6rss")
    with pytest.raises(KinematicsError, match=r"sample 0.*parallel \(type II\) singularity"):
        solve_kinematics(singular, task, orientation)
    solve_kinematics(m, task, orientation)  # the real robot at home: no error
