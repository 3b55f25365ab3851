"""The fused kinematics kernel (one compiled call per task) against independent routes: the NumPy closed-form
inverse kinematics, the separate CasADi functions, finite differences along a task, and R_omega."""

from __future__ import annotations

import numpy as np
import pytest
from support import default_kinematics, model

from chewbot.compiled.cache import symbols
from chewbot.compiled.kernels import evaluate
from chewbot.errors import KinematicsError
from chewbot.kinematics.functions import parasitic_function, points_function, pose_function, rates_function
from chewbot.kinematics.ik import inverse_kinematics, transmission
from chewbot.kinematics.motion import solve_kinematics
from chewbot.kinematics.options import ORIENTATIONS
from chewbot.rotation import R_omega, euler_angles_to_parameters, matrix_from_euler_angles
from chewbot.kinematics.task import TARGET_COORDS, Task
from chewbot.task.default import ChewingParameters, default_task


def _rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_theta_and_transmission_equal_the_numpy_inverse_kinematics(mechanism, orientation):
    """theta and the transmission sines against the NumPy closed form on the pose (R from the Euler angles in
    NumPy): the same formula in another code, rounding only (angles of order 1 rad: 1e-12 rad)."""
    m = model(mechanism)
    for side in ("left", "right"):
        kin = default_kinematics(mechanism, side, orientation)
        p, R = kin.X[:, :3], matrix_from_euler_angles(kin.X[:, 3:])
        assert np.abs(kin.theta - inverse_kinematics(m, p, R, kin.t)).max() <= 1e-12
        assert np.abs(kin.transmission - transmission(m, p, R)).max() <= 1e-12


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_equals_the_route_through_separate_functions(mechanism, orientation):
    """Every output against the separate functions of the graph (pose, points, rates; the parasitic lift) and
    the NumPy conversion to Euler parameters: the same expressions evaluated another way, 1e-12 relative."""
    m = model(mechanism)
    kin = default_kinematics(mechanism, "left", orientation)
    p = m.vector()
    pose, _, _ = evaluate(pose_function(mechanism, orientation), kin.q, p)
    X = kin.X if orientation == "euler-angles" else None
    if orientation == "euler-angles":
        assert _rel(kin.X, pose) <= 1e-12
    else:
        assert _rel(kin.e, pose[:, 3:]) <= 1e-12 and _rel(kin.X[:, :3], pose[:, :3]) <= 1e-12
    if mechanism == "target":
        X, dX, ddX = evaluate(parasitic_function(symbols(mechanism)), *(x[:, [0, 1, 3, 4]] for x in (kin.X, kin.dX, kin.ddX)), p)
        for a, b in ((kin.X, X), (kin.dX, dX), (kin.ddX, ddX)):
            assert _rel(a, b) <= 1e-12
    for a, b in zip((kin.e, kin.de, kin.dde), euler_angles_to_parameters(kin.X[:, 3:], kin.dX[:, 3:], kin.ddX[:, 3:])):
        assert _rel(a, b) <= 1e-12
    for name, value in zip(("T_L", "T_R", "I", "B_L", "B_R"), evaluate(points_function(mechanism, orientation), kin.q, p)):
        assert _rel(kin.points[name], value) <= 1e-12
    dth, ddth, tw, twr, _, _ = evaluate(rates_function(mechanism, orientation), kin.theta, kin.q, kin.dq, kin.ddq, p)
    for a, b in ((kin.dtheta, dth), (kin.ddtheta, ddth), (kin.twist, tw), (kin.twist_rate, twr)):
        assert _rel(a, b) <= 1e-12


def test_twist_against_the_euler_angle_rates(mechanism):
    """v_OM = (X, Y, Z)_dot and omega = R_omega [alpha, beta, gamma]_dot (NumPy), for both parametrisations: the
    Euler-parameter kernel computes omega as 2 E(e) e_dot, another formula for the same vector."""
    for orientation in ORIENTATIONS:
        kin = default_kinematics(mechanism, "left", orientation)
        omega = np.einsum("nij,nj->ni", R_omega(kin.X[:, 3:]), kin.dX[:, 3:])
        assert np.abs(kin.twist[:, :3] - kin.dX[:, :3]).max() <= 1e-15
        assert np.abs(kin.twist[:, 3:] - omega).max() <= 1e-12 * np.abs(omega).max()


def _difference_check(x, dx, h):
    """dx against central differences of x (step h), interior samples. The truncation error of the step-h
    difference, h^2 x'''/6, is a third of its distance to the step-2h difference (4 h^2 x'''/6); where x''' crosses
    zero that distance vanishes before the error does (the h^4 terms), so the bound is the distance's largest
    value within +-25 samples (x''' varies little over 1.25 ms), plus rounding (1e3 eps |x| / h)."""
    fd1 = (x[2:] - x[:-2]) / (2 * h)
    fd2 = (x[4:] - x[:-4]) / (4 * h)
    err = np.abs(fd1[1:-1] - dx[2:-2])
    gap = np.pad(np.abs(fd1[1:-1] - fd2), ((25, 25), (0, 0)), mode="edge")
    bound = np.lib.stride_tricks.sliding_window_view(gap, 51, axis=0).max(axis=-1) + 1e3 * np.finfo(float).eps * np.abs(x).max() / h
    assert np.all(err <= bound), float((err - bound).max())
    assert err.max() > 0  # two different routes


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_rates_against_finite_differences(mechanism, orientation):
    """On one chewing cycle sampled at 20 kHz (analytic in each cycle), every rate the kernel computes is the time
    derivative of its position: X_EE, e, theta, theta_dot, the twist (to its rate)."""
    m = model(mechanism)
    params = ChewingParameters(cycles=1, rest_s=0.0, rate_hz=20000.0)
    kin = solve_kinematics(m, default_task(m, "left", params), orientation)
    h = 1 / params.rate_hz
    for x, dx in ((kin.X, kin.dX), (kin.dX, kin.ddX), (kin.e, kin.de), (kin.de, kin.dde), (kin.theta, kin.dtheta),
                  (kin.dtheta, kin.ddtheta), (kin.twist, kin.twist_rate)):
        _difference_check(x, dx, h)


def test_undefined_parasitic_e3_is_reported():
    """With alpha = 0 and beta beyond 90 deg the parasitic gamma is pi and e0 = e2 = 0: p1 e0 - e2 = 0, e3 undefined
    (checked before the sockets, which this pose leaves too)."""
    q = np.tile([0.0, 0.0, 0.0, 2.0], (3, 1))
    task = Task("flipped", np.arange(3) * 1e-3, TARGET_COORDS, q, np.zeros_like(q), np.zeros_like(q), np.zeros((3, 3)))
    with pytest.raises(KinematicsError, match=r"sample 0, t = 0 s: Euler parameters: p1 e0 - e2 = 0"):
        solve_kinematics(model("target"), task, "euler-parameters")
    with pytest.raises(KinematicsError, match="condyle leaves its socket"):
        solve_kinematics(model("target"), task, "euler-angles")


def test_parallel_singularity_screen_misses_nothing():
    """The determinant bound only skips samples whose singular-value ratio is certainly above the tolerance: on
    matrices built with ratios on both sides of it (after the column normalisation), the check names the first
    sample below, with the ratio the SVD gives."""
    from chewbot.kinematics.motion import PARALLEL_SINGULAR_TOLERANCE, check_parallel_singularity

    rng = np.random.default_rng(3)
    U, _ = np.linalg.qr(rng.normal(size=(40, 6, 4)))
    V, _ = np.linalg.qr(rng.normal(size=(40, 4, 4)))
    sv = np.tile([1.0, 0.7, 0.4, 0.2], (40, 1))
    sv[[7, 11, 23], 3] = [3e-6, 4e-7, 1e-9]  # 7 stays above the tolerance once normalised, 11 and 23 do not
    J = U @ (sv[:, :, None] * V)
    normalised = J / np.linalg.norm(J, axis=1, keepdims=True)
    ratio = (lambda s: s[:, -1] / s[:, 0])(np.linalg.svd(normalised, compute_uv=False))
    below = np.flatnonzero(ratio < PARALLEL_SINGULAR_TOLERANCE)
    assert below.tolist() == [11, 23]
    with pytest.raises(KinematicsError, match=rf"sample 11, .*ratio {ratio[11]:.2e} < 1e-06.*2 sample\(s\)"):
        check_parallel_singularity(J, None, np.arange(40) * 1e-3)
    check_parallel_singularity(np.delete(J, below, axis=0), None, np.arange(38) * 1e-3)


def test_unit_norm_tangent_is_an_orthonormal_basis():
    from chewbot.kinematics.motion import _unit_norm_tangent

    g = np.random.default_rng(4).normal(size=(50, 1, 5))
    g[:10, 0, 2] *= -30  # the largest entry negative
    B = _unit_norm_tangent(g)
    assert B.shape == (50, 5, 4)
    assert np.abs(np.swapaxes(B, 1, 2) @ B - np.eye(4)).max() < 1e-14
    assert np.abs(g @ B).max() < 1e-14 * np.abs(g).max()
