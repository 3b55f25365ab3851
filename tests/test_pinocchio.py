"""The 6RSS forward dynamics against an independent engine: Pinocchio's rigid-body algorithms on the open tree, the
six loops closed exactly by Lagrange multipliers (a test-only dependency, the package ``pin``; skipped without it).

The tree: the mandible on a free-flyer (mass centre at O_M, its inertia about O_M in {M}); per chain a crank on a
revolute joint at G_i about the z axis of R_C0,i (mass on the shaft, its axial inertia), and the coupler, a uniform
thin rod, on a universal joint at S_i (two revolutes about the crank frame's x and then y axes: a spherical joint
would leave the rod's spin about its own axis without inertia and the mass matrix singular). The loops close
where the coupler's far end meets M_i on the mandible: three equations each, J_c a + gamma = 0 with J_c the
difference of the two points' Jacobians and gamma their relative acceleration at a = 0. With M a + b = tau +
J_c' lambda this is the KKT system of the constrained dynamics, solved densely.
"""

from __future__ import annotations

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio", reason="Pinocchio (the package pin, a test extra) is not installed")

from chewbot.kinematics.motion import solve_kinematics  # noqa: E402
from chewbot.model.chains import crank_tips  # noqa: E402
from chewbot.rotation import matrix_from_euler_angles  # noqa: E402
from chewbot.simulation.forward import forward_dynamics  # noqa: E402
from chewbot.simulation.run import motion_task  # noqa: E402
from chewbot.task.default import default_task  # noqa: E402

from support import model, random_states  # noqa: E402


def build(m):
    """The Pinocchio model of the 6RSS ``m`` and the ids it needs: joints per chain, the frames of the loops."""
    p = pin.Model()
    p.gravity = pin.Motion(np.array([0.0, 0.0, -m.g]), np.zeros(3))
    ff = p.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "mandible")
    p.appendBodyToJoint(ff, pin.Inertia(m.mandible_mass, np.zeros(3), m.mandible_inertia), pin.SE3.Identity())
    chains, loops = [], []
    for i in range(6):
        crank = p.addJoint(0, pin.JointModelRZ(), pin.SE3(m.R_C0[i], m.G[i]), f"crank{i + 1}")
        p.appendBodyToJoint(crank, pin.Inertia(m.crank_mass[i], np.zeros(3), np.eye(3) * m.crank_inertia[i]), pin.SE3.Identity())
        ux = p.addJoint(crank, pin.JointModelRX(), pin.SE3(np.eye(3), np.array([m.crank_length[i], 0.0, 0.0])), f"coupler{i + 1}_x")
        uy = p.addJoint(ux, pin.JointModelRY(), pin.SE3.Identity(), f"coupler{i + 1}_y")
        L, mc = m.coupler_length[i], m.coupler_mass[i]
        p.appendBodyToJoint(uy, pin.Inertia(mc, np.array([0.0, 0.0, L / 2]), np.diag([mc * L**2 / 12, mc * L**2 / 12, 0.0])),
                            pin.SE3.Identity())
        end = p.addFrame(pin.Frame(f"coupler{i + 1}_end", uy, pin.SE3(np.eye(3), np.array([0.0, 0.0, L])), pin.FrameType.OP_FRAME))
        onto = p.addFrame(pin.Frame(f"M{i + 1}", ff, pin.SE3(np.eye(3), m.M[i]), pin.FrameType.OP_FRAME))
        chains.append((crank, ux, uy))
        loops.append((end, onto))
    body = p.addFrame(pin.Frame("O_M", ff, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    if m.drive is not None:  # each motor's rotor, reflected through its gears: the crank joint's armature
        armature = p.armature.copy()
        for crank, _, _ in chains:
            armature[p.joints[crank].idx_v] = m.drive.rotor_inertia * m.drive.gear_ratio**2
        p.armature = armature
    return p, chains, loops, body


def state(m, p, chains, loops, kin, k):
    """Pinocchio's q, v for sample k of the kinematics ``kin``: the mandible's pose and twist, the crank angles and
    rates, and the universal joints' angles (the coupler pointing at M_i) and rates (closing the loops' velocities)."""
    R = matrix_from_euler_angles(kin.X[k:k + 1, 3:6])[0]
    q, v = pin.neutral(p), np.zeros(p.nv)
    q[:3], q[3:7] = kin.X[k, :3], pin.Quaternion(R).coeffs()
    v[:3], v[3:6] = R.T @ kin.twist[k, :3], R.T @ kin.twist[k, 3:]
    S = crank_tips(m, kin.theta[k:k + 1])[0]
    M = kin.X[k, :3] + m.M @ R.T
    for i, (crank, ux, uy) in enumerate(chains):
        q[p.joints[crank].idx_q], v[p.joints[crank].idx_v] = kin.theta[k, i], kin.dtheta[k, i]
        Rc = m.R_C0[i] @ np.array([[np.cos(kin.theta[k, i]), -np.sin(kin.theta[k, i]), 0], [np.sin(kin.theta[k, i]), np.cos(kin.theta[k, i]), 0], [0, 0, 1]])
        u = Rc.T @ (M[i] - S[i]) / m.coupler_length[i]  # Rx(a) Ry(b) z = (sin b, -sin a cos b, cos a cos b)
        q[p.joints[ux].idx_q], q[p.joints[uy].idx_q] = np.arctan2(-u[1], u[2]), np.arcsin(u[0])
    data = p.createData()
    pin.computeJointJacobians(p, data, q)
    pin.updateFramePlacements(p, data)
    # the universal joints' rates: the coupler end's velocity equals M_i's (3 equations, 2 unknowns, consistent)
    for (crank, ux, uy), (end, onto) in zip(chains, loops):
        J_end = pin.getFrameJacobian(p, data, end, pin.LOCAL_WORLD_ALIGNED)[:3]
        J_on = pin.getFrameJacobian(p, data, onto, pin.LOCAL_WORLD_ALIGNED)[:3]
        cols = [p.joints[ux].idx_v, p.joints[uy].idx_v]
        rest = J_on @ v - J_end @ v  # with the universal rates still zero
        v[cols] = np.linalg.lstsq(J_end[:, cols], rest, rcond=None)[0]
    return q, v


def constrained_accelerations(p, loops, q, v, tau_full):
    """a of M a + b = tau + J_c' lambda, J_c a = -gamma (the loops closed exactly)."""
    data = p.createData()
    M = pin.crba(p, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    b = pin.nonLinearEffects(p, data, q, v)
    pin.computeJointJacobians(p, data, q)
    pin.forwardKinematics(p, data, q, v, np.zeros(p.nv))
    pin.updateFramePlacements(p, data)
    J, gamma = [], []
    for end, onto in loops:
        J.append(pin.getFrameJacobian(p, data, end, pin.LOCAL_WORLD_ALIGNED)[:3] - pin.getFrameJacobian(p, data, onto, pin.LOCAL_WORLD_ALIGNED)[:3])
        gamma.append(pin.getFrameClassicalAcceleration(p, data, end, pin.LOCAL_WORLD_ALIGNED).linear
                     - pin.getFrameClassicalAcceleration(p, data, onto, pin.LOCAL_WORLD_ALIGNED).linear)
    J, gamma = np.vstack(J), np.concatenate(gamma)
    K = np.block([[M, -J.T], [J, np.zeros((len(gamma), len(gamma)))]])
    return np.linalg.solve(K, np.concatenate([tau_full - b, -gamma]))[:p.nv], J


def test_6rss_forward_dynamics_agrees_with_pinocchio():
    """At 20 random states and torques (no friction, no bite force) the 6RSS forward dynamics gives the mandible's
    linear and angular accelerations and the crank accelerations that Pinocchio's constrained dynamics gives, to 1e-6
    relative to their largest value (the issue's tolerance; two exact formulations agree to rounding amplified by the
    KKT system's condition: measured 1e-13, while a coupler 1 % heavier in Pinocchio's model gives 1.3e-4)."""
    m = model("6rss")
    _, q_all, dq_all, tau, _ = random_states("6rss", 20, 5)
    zero = np.zeros((len(q_all), 3))
    fwd = forward_dynamics(m, q_all, dq_all, tau, zero, "left", friction=False)
    kin = solve_kinematics(m, motion_task(m, default_task(m), np.arange(len(q_all)) * 1e-3, q_all, dq_all, fwd.ddq, zero))
    p, chains, loops, body = build(m)
    for k in range(len(q_all)):
        q, v = state(m, p, chains, loops, kin, k)
        tau_full = np.zeros(p.nv)
        for i, (crank, _, _) in enumerate(chains):
            tau_full[p.joints[crank].idx_v] = tau[k, i]
        a, J = constrained_accelerations(p, loops, q, v, tau_full)
        assert np.max(np.abs(J @ v)) < 1e-12  # m/s: the state closes the loops' velocities
        data = p.createData()
        pin.forwardKinematics(p, data, q, v, a)
        pin.updateFramePlacements(p, data)
        acc = pin.getFrameClassicalAcceleration(p, data, body, pin.LOCAL_WORLD_ALIGNED)
        theirs = np.concatenate([acc.linear, acc.angular, [a[p.joints[c].idx_v] for c, _, _ in chains]])
        ours = np.concatenate([kin.twist_rate[k], kin.ddtheta[k]])
        assert np.max(np.abs(ours - theirs)) <= 1e-6 * np.max(np.abs(theirs)), k
