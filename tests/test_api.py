"""The Python API's verbs (chewbot.api, given as chewbot.NAME): the numbers of ``chewbot run`` on the same samples,
forward dynamics as the inverse of inverse dynamics, inverse kinematics against the NumPy closed form on poses built
from the conventions, forward kinematics as its inverse, one sample as in a batch, run's refusals, and the shapes."""

from __future__ import annotations

import inspect
import subprocess
import sys
from functools import cache

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import chewbot
from chewbot import api
from chewbot.dynamics.registry import DEFAULT_METHOD
from chewbot.errors import KinematicsError
from chewbot.kinematics import ik
from chewbot.model.params import load_model
from chewbot.run.options import OptionError, resolve
from chewbot.run.pipeline import compute
from support import model, target_pose

# One chewing cycle at 200 Hz after 50 ms of rest: 171 samples through the bite-force burst.
SHORT = {"task.cycles": 1, "task.rest_s": 0.05, "task.rate_hz": 200}
COORDS = {"target": ("X", "Y", "alpha", "beta"), "6rss": ("X", "Y", "Z", "alpha", "beta", "gamma")}
# (mechanism, method, side, options): every formulation on both robots, both sides, both contact models, newton-euler
# with and without friction and with a goal; the default task carries its bite force.
CASES = [
    ("target", "hessian", "left", {}),
    ("target", "lagrange", "right", {}),
    ("target", "liang", "left", {"contact": "unilateral"}),
    ("target", "6rss-core", "right", {"contact": "unilateral"}),
    ("target", "newton-euler", "left", {"friction": True, "goal": "min-hkp-force"}),
    ("target", "newton-euler", "right", {"friction": False, "goal": "min-coupler-force", "contact": "unilateral"}),
    ("6rss", "hessian", "right", {}),
    ("6rss", "lagrange", "left", {}),
    ("6rss", "liang", "right", {}),
    ("6rss", "6rss-core", "left", {}),
    ("6rss", "newton-euler", "right", {"friction": True}),
]


@cache
def run(mechanism: str, method: str, side: str, options: tuple = (), orientation: str = "euler-angles"):
    """What ``chewbot run`` computes for these options on the short task (its results table)."""
    return compute(resolve(model=mechanism, side=side, method=method, orientation=orientation, overrides=SHORT,
                           **dict(options)))


def samples(result, names=None):
    """q, dq, ddq and the bite force of a run's results table, as a user reads them from its results.csv."""
    names = names or COORDS[result.model.mechanism]
    q, dq, ddq = (np.column_stack([result.table[level + n] for n in names]) for level in ("", "d", "dd"))
    return q, dq, ddq, np.column_stack([result.table[c] for c in ("Fx", "Fy", "Fz")])


def columns(result, names) -> np.ndarray:
    return np.column_stack([result.table[n] for n in names])


# ------------------------------------------------------------------------------------------- inverse dynamics


@pytest.mark.parametrize("mechanism, method, side, options", CASES, ids=[f"{c[0]}-{c[1]}-{c[2]}" for c in CASES])
def test_inverse_dynamics_gives_run_s_columns_on_the_same_samples(mechanism, method, side, options):
    """tau1..tau6, N_L, N_R and every other column of the formulation equal ``chewbot run``'s to 1e-12 relative (the
    same kernels on the same inputs: the API's task is run's samples read back from its table, so only the
    representation of the inputs could differ, and it does not)."""
    r = run(mechanism, method, side, tuple(options.items()))
    q, dq, ddq, force = samples(r)
    result = chewbot.inverse_dynamics(model(mechanism), q, dq, ddq, method=method, side=side, bite_force=force, **options)
    assert result.method == method and result.options["side"] == side
    np.testing.assert_allclose(result.tau, columns(r, [f"tau{i}" for i in range(1, 7)]), rtol=1e-12, atol=0)
    if mechanism == "target":
        np.testing.assert_allclose(result.N, columns(r, ["N_L", "N_R"]), rtol=1e-12, atol=0)
    else:
        assert result.N is None
    assert list(result.columns) == list(r.dynamics.table.columns)
    for name, values in result.columns.items():
        np.testing.assert_allclose(values, r.table[name], rtol=1e-12, atol=0, err_msg=name)
        assert result.units[name] == r.table.units[name]
    assert np.abs(force).max() > 50  # the samples carry the default task's bite force (-80 N at the peak)


def test_the_result_offers_the_formulation_s_columns_by_name():
    r = run("target", "newton-euler", "left", (("friction", True),))
    q, dq, ddq, force = samples(r)
    result = chewbot.inverse_dynamics(model("target"), q, dq, ddq, method="newton-euler", bite_force=force)
    assert result.N_L is result.columns["N_L"] and result["tau_f3"] is result.columns["tau_f3"]
    assert "FS1_x" in dir(result) and result.units["FS1_x"] == "N"
    assert result.options == {"method": "newton-euler", "orientation": "euler-angles", "goal": "min-torque",
                              "contact": "bilateral", "side": "left", "friction": True}
    assert result.info["indices"] == pytest.approx(r.info["dynamics"]["indices"], rel=1e-12)
    with pytest.raises(AttributeError, match="no field or column 'N_X'"):
        result.N_X
    with pytest.raises(KeyError, match="no column 'tau7'"):
        result["tau7"]
    with pytest.raises(AttributeError):  # frozen
        result.tau = None


def test_samples_without_admissible_torques_are_named():
    """A preload no torques within the actuators' limits give (200 N on each condyle): newton-euler's distribution
    names both samples infeasible, as run's check distribution-infeasible does; the default preload leaves none."""
    q = np.array([[0.002, 0.001, 0.02, 0.1], [0.001, 0.0005, 0.01, 0.05]])
    heavy = load_model("target", {"contact.preload_N": 200})
    result = chewbot.inverse_dynamics(heavy, q, 0 * q, 0 * q, method="newton-euler", contact="unilateral")
    assert result.infeasible == (0, 1) and "torque (actuator 1)" in result.info["infeasible"][0]["limits"]
    assert chewbot.inverse_dynamics(model("target"), q, 0 * q, 0 * q, method="newton-euler", contact="unilateral").infeasible == ()


def test_the_default_method_is_the_registry_s_for_the_orientation():
    """No method given: the formulation table's default of the orientation (not a name written in the API)."""
    assert inspect.signature(chewbot.inverse_dynamics).parameters["method"].default is None
    m = model("target")
    q, dq, ddq, force = samples(run("target", "newton-euler", "left", (("friction", True),)))
    assert chewbot.inverse_dynamics(m, q[40], dq[40], ddq[40]).method == DEFAULT_METHOD["euler-angles"]
    r = run("target", "newton-euler", "left", (), "euler-parameters")
    qe, dqe, ddqe, _ = samples(r, ["X", "Y", "e0", "e1", "e2"])
    assert chewbot.inverse_dynamics(m, qe[40], dqe[40], ddqe[40], orientation="euler-parameters").method == \
        DEFAULT_METHOD["euler-parameters"]


def test_euler_parameters_give_run_s_columns_and_the_euler_angles_torques():
    """A motion given in Euler parameters (X, Y, e0, e1, e2 on the target, as run's results.csv gives them) to a
    formulation written for them: run's numbers with --orientation euler-parameters, to 1e-10 relative (the API
    converts the given parameters to Euler angles and the kinematics back: two exact conversions, each rounding at
    1e-16 times the condition of the angle rates' map, about 10 here), and the torques of the same motion in Euler
    angles to the same tolerance (the parametrisation does not change the torques). abs(e) = 1 is refused off."""
    m = model("target")
    r = run("target", "newton-euler", "left", (), "euler-parameters")
    qe, dqe, ddqe, force = samples(r, ["X", "Y", "e0", "e1", "e2"])
    result = chewbot.inverse_dynamics(m, qe, dqe, ddqe, method="newton-euler", orientation="euler-parameters",
                                      bite_force=force)
    tau = columns(r, [f"tau{i}" for i in range(1, 7)])
    scale = np.abs(tau).max()
    assert np.abs(result.tau - tau).max() < 1e-10 * scale
    assert np.abs(result.N - columns(r, ["N_L", "N_R"])).max() < 1e-10 * np.abs(result.N).max()
    q, dq, ddq, _ = samples(r)
    angles = chewbot.inverse_dynamics(m, q, dq, ddq, method="newton-euler", bite_force=force)
    assert np.abs(angles.tau - result.tau).max() < 1e-10 * scale
    off = qe.copy()
    off[7, 2] *= 1.001
    with pytest.raises(KinematicsError, match=r"sample 7: the Euler parameters leave abs\(e\) = 1"):
        chewbot.inverse_dynamics(m, off, dqe, ddqe, method="newton-euler", orientation="euler-parameters")
    with pytest.raises(OptionError) as refused:
        chewbot.inverse_dynamics(m, qe, dqe, ddqe, method="hessian", orientation="euler-parameters")
    assert "hessian is written for euler-angles" in str(refused.value)


@pytest.mark.parametrize("mechanism, method, options", [
    ("target", "hessian", {}), ("target", "lagrange", {"contact": "unilateral"}),
    ("target", "newton-euler", {"friction": True, "contact": "unilateral"}), ("6rss", "liang", {}),
    ("6rss", "newton-euler", {})])
def test_one_sample_equals_the_same_sample_inside_a_batch(mechanism, method, options):
    """Every sample's numbers are its own (compiled per-sample kernels; newton-euler's unconstrained Newton stage
    runs per sample): alone, a sample gives what it gives inside a batch, to 1e-12 relative, without the leading
    axis. A bite force given once is the bite force of every sample."""
    r = run(mechanism, method, "left", tuple(options.items()))
    q, dq, ddq, force = samples(r)
    m = model(mechanism)
    whole = chewbot.inverse_dynamics(m, q, dq, ddq, method=method, bite_force=force, **options)
    for k in (0, 95, 138):
        one = chewbot.inverse_dynamics(m, q[k], dq[k], ddq[k], method=method, bite_force=force[k], **options)
        assert one.tau.shape == (6,) and one.bite_force.shape == (3,)
        np.testing.assert_allclose(one.tau, whole.tau[k], rtol=1e-12, atol=0)
        for name, values in one.columns.items():
            assert np.shape(values) == ()
            np.testing.assert_allclose(values, whole.columns[name][k], rtol=1e-12, atol=0, err_msg=name)
        if m.has_hkp:
            assert one.N.shape == (2,)
    k = int(np.argmax(np.abs(force[:, 2])))  # inside the bite-force burst
    shared = chewbot.inverse_dynamics(m, q[k - 3:k + 3], dq[k - 3:k + 3], ddq[k - 3:k + 3], method=method,
                                      bite_force=force[k], **options)
    each = chewbot.inverse_dynamics(m, q[k - 3:k + 3], dq[k - 3:k + 3], ddq[k - 3:k + 3], method=method,
                                    bite_force=np.tile(force[k], (6, 1)), **options)
    np.testing.assert_array_equal(shared.tau, each.tau)
    np.testing.assert_array_equal(shared.bite_force, np.tile(force[k], (6, 1)))
    zero = chewbot.inverse_dynamics(m, q[k], dq[k], ddq[k], method=method, **options)
    np.testing.assert_array_equal(zero.bite_force, np.zeros(3))
    assert not np.allclose(zero.tau, shared.tau[3])  # the bite force changes the torques: it was applied


# ------------------------------------------------------------------------------------------- forward dynamics


@pytest.mark.parametrize("mechanism", ["target", "6rss"])
@pytest.mark.parametrize("friction", [False, True])
def test_forward_dynamics_inverts_inverse_dynamics(mechanism, friction):
    """forward_dynamics(q, dq, inverse_dynamics(q, dq, ddq).tau) gives ddq back, and on the target the inverse's N,
    to 1e-9 relative to the largest acceleration (force): the forward kernel is one exact linear step without
    friction and Newton's to a torque residual below 1e-13 N m with it, which the inverse inertia turns into
    accelerations below 1e-10 (measured: 1e-13 relative without friction, 7e-11 with). Without friction, the
    Hessian formulation's torques (another formulation) give the same accelerations to 1e-9 (measured 4e-11)."""
    r = run(mechanism, "newton-euler", "left", (("friction", friction),))
    q, dq, ddq, force = samples(r)
    m = model(mechanism)
    methods = ["newton-euler"] + ([] if friction else ["hessian"])
    for method in methods:
        inverse = chewbot.inverse_dynamics(m, q, dq, ddq, method=method, bite_force=force,
                                           **({"friction": friction} if method == "newton-euler" else {}))
        fd = chewbot.forward_dynamics(m, q, dq, inverse.tau, friction=friction, bite_force=force)
        assert fd.ddq.shape == q.shape and fd.residual.max() < 1e-12
        assert np.abs(fd.ddq - ddq).max() < 1e-9 * np.abs(ddq).max(), method
        if m.has_hkp:
            assert np.abs(fd.N - inverse.N).max() < 1e-9 * np.abs(inverse.N).max(), method
        else:
            assert fd.N is None
        np.testing.assert_array_equal(fd.bite_force, force)
        assert fd.pulls is None
        k = 95
        one = chewbot.forward_dynamics(m, q[k], dq[k], inverse.tau[k], friction=friction, bite_force=force[k])
        assert one.ddq.shape == (len(COORDS[mechanism]),) and np.shape(one.residual) == ()
        np.testing.assert_allclose(one.ddq, fd.ddq[k], rtol=1e-12, atol=1e-15)


def test_forward_dynamics_under_the_unilateral_contact_marks_where_a_plane_pulls():
    """Torques that make a plane pull (the bilateral answer's N below 0): ``pulls`` says which samples, from N."""
    r = run("target", "hessian", "left")
    q, dq, ddq, force = samples(r)
    m = model("target")
    tau = chewbot.inverse_dynamics(m, q, dq, ddq, bite_force=force).tau
    tau = tau + np.linspace(-1, 1, len(tau))[:, None] * np.array([0.5, 0.5, 0, 0, 0, 0])  # squeeze and pull the TMJs
    fd = chewbot.forward_dynamics(m, q, dq, tau, contact="unilateral", bite_force=force)
    np.testing.assert_array_equal(fd.pulls, (fd.N < -1e-6).any(axis=1))
    assert 0 < fd.pulls.sum() < len(q)
    bilateral = chewbot.forward_dynamics(m, q, dq, tau, bite_force=force)
    np.testing.assert_array_equal(bilateral.ddq, fd.ddq)


# ------------------------------------------------------------------------------------------- kinematics


def sixrss_pose(q):
    """p, R of 6RSS poses q (N, 6) from the conventions (R = Rx Ry Rz, SciPy's intrinsic "XYZ")."""
    return q[:, :3], Rotation.from_euler("XYZ", q[:, 3:]).as_matrix()


@pytest.mark.parametrize("mechanism", ["target", "6rss"])
def test_inverse_kinematics_against_the_closed_form_and_forward_kinematics_as_its_inverse(mechanism):
    """The API's crank angles (the compiled kinematics) equal the NumPy closed form of kinematics.ik on poses built
    from the conventions with SciPy's rotations (parasitic Z and gamma by hand), to 1e-12 rad (both exact; rounding
    of atan2 and acos near 1 rad); forward kinematics of them gives the poses back to 1e-12 (Newton's method to a
    step below 1e-13), one pose alone as inside the batch. Run's theta columns are the same angles."""
    r = run(mechanism, "hessian", "left")
    q = samples(r)[0]
    m = model(mechanism)
    theta = chewbot.inverse_kinematics(m, q)
    p, R = target_pose(m, q) if mechanism == "target" else sixrss_pose(q)
    np.testing.assert_allclose(theta, ik.inverse_kinematics(m, p, R), rtol=0, atol=1e-12)
    np.testing.assert_allclose(theta, columns(r, [f"theta{i}" for i in range(1, 7)]), rtol=0, atol=1e-12)
    back = chewbot.forward_kinematics(m, theta)
    np.testing.assert_allclose(back, q, rtol=0, atol=1e-12)
    k = 120
    assert chewbot.inverse_kinematics(m, q[k]).shape == (6,)
    np.testing.assert_array_equal(chewbot.inverse_kinematics(m, q[k]), theta[k])
    np.testing.assert_allclose(chewbot.forward_kinematics(m, theta[k]), q[k], rtol=0, atol=1e-12)


def test_kinematics_in_euler_parameters():
    """The same poses in Euler parameters (from SciPy's quaternions of the same rotations, scalar first, and
    the target's X, Y, e0, e1, e2) give the same crank angles, and forward kinematics answers in them."""
    m = model("target")
    q = samples(run("target", "hessian", "left"))[0]
    theta = chewbot.inverse_kinematics(m, q)
    _, R = target_pose(m, q)
    e = Rotation.from_matrix(R).as_quat(scalar_first=True)
    e *= np.sign(e[:, :1])
    qe = np.column_stack([q[:, :2], e[:, :3]])
    np.testing.assert_allclose(chewbot.inverse_kinematics(m, qe, orientation="euler-parameters"), theta, rtol=0, atol=1e-12)
    np.testing.assert_allclose(chewbot.forward_kinematics(m, theta, orientation="euler-parameters"), qe, rtol=0, atol=1e-12)


def test_kinematics_refuse_what_no_robot_reaches():
    m = model("target")
    with pytest.raises(KinematicsError, match="sample 1: the left condyle leaves its socket"):
        chewbot.inverse_kinematics(m, [[0, 0, 0, 0], [0.02, 0, 0, 0]])
    with pytest.raises(KinematicsError, match="sample 1: the left condyle leaves its socket"):
        chewbot.forward_dynamics(m, [[0, 0, 0, 0], [0.02, 0, 0, 0]], np.zeros(4), np.zeros(6))
    with pytest.raises(KinematicsError, match="sample 1: the left condyle leaves its socket"):
        chewbot.inverse_dynamics(m, [[0, 0, 0, 0], [0.02, 0, 0, 0]], np.zeros(4), np.zeros(4))
    with pytest.raises(KinematicsError, match="sample 0"):
        chewbot.forward_kinematics(m, [0.3, 0, 0, 0, 0, 0])  # the target's four coordinates cannot close six chains so


# ------------------------------------------------------------------------------------------- options and shapes


@pytest.mark.parametrize("mechanism, given", [
    ("target", {"method": "hessian", "friction": True}),
    ("target", {"method": "lagrange", "goal": "min-torque"}),
    ("target", {"method": "liang", "goal": "min-torque", "friction": False}),
    ("6rss", {"method": "newton-euler", "goal": "min-torque"}),
    ("6rss", {"contact": "unilateral"}),
    ("target", {"method": "hessian", "orientation": "euler-parameters"}),
    ("target", {"method": "featherstone"}),
    ("target", {"goal": "min-effort", "method": "newton-euler"}),
    ("target", {"contact": "sticky"}),
    ("target", {"side": "middle"}),
])
def test_options_a_method_does_not_use_are_refused_with_run_s_messages(mechanism, given):
    """The refusal is run's: the same OptionError and message as ``chewbot.run.options.resolve`` (which ``chewbot
    run`` words with its --options), before anything is computed."""
    m = model(mechanism)
    with pytest.raises(OptionError) as by_run:
        resolve(model=mechanism, **given)
    q = np.zeros(len(COORDS[mechanism]) + (1 if given.get("orientation") == "euler-parameters" else 0))
    with pytest.raises(OptionError) as by_api:
        chewbot.inverse_dynamics(m, q, q, q, **given)
    assert str(by_api.value) == str(by_run.value)


def test_forward_dynamics_refuses_as_run_does():
    with pytest.raises(OptionError, match="unilateral applies to the target robot"):
        chewbot.forward_dynamics(model("6rss"), np.zeros(6), np.zeros(6), np.zeros(6), contact="unilateral")
    with pytest.raises(OptionError, match="side must be one of left, right"):
        chewbot.forward_dynamics(model("target"), np.zeros(4), np.zeros(4), np.zeros(6), side="both")
    with pytest.raises(ValueError, match="friction must be True, False or None"):
        chewbot.forward_dynamics(model("target"), np.zeros(4), np.zeros(4), np.zeros(6), friction="on")


@pytest.mark.parametrize("call, message", [
    (lambda m: chewbot.inverse_dynamics(m, np.zeros(5), np.zeros(4), np.zeros(4)),
     r"q: expected shape \(4,\) for one sample or \(N, 4\) for N samples \(X, Y, alpha, beta of the target, in m, rad\), got \(5,\)"),
    (lambda m: chewbot.inverse_dynamics(m, np.zeros((3, 4)), np.zeros((2, 4)), np.zeros(4)),
     r"dq: 2 samples, but q has 3"),
    (lambda m: chewbot.inverse_dynamics(m, np.zeros(4), np.zeros(4), np.zeros((2, 2, 4))),
     r"ddq: expected shape \(4,\) .* \(the accelerations of X, Y, alpha, beta of the target, in m/s\^2, rad/s\^2\), got \(2, 2, 4\)"),
    (lambda m: chewbot.inverse_dynamics(m, np.zeros(4), np.zeros(4), np.zeros(4), bite_force=[0, -80]),
     r"bite_force: expected shape \(3,\) .* got \(2,\)"),
    (lambda m: chewbot.inverse_dynamics(m, np.zeros((0, 4)), np.zeros(4), np.zeros(4)), r"q: no sample"),
    (lambda m: chewbot.inverse_dynamics(m, [[0, 0, 0, 0], [0, np.nan, 0, 0]], np.zeros(4), np.zeros(4)),
     r"q: sample 1 is not finite"),
    (lambda m: chewbot.forward_dynamics(m, np.zeros(4), np.zeros(4), np.zeros(4)), r"tau: expected shape \(6,\) .* got \(4,\)"),
    (lambda m: chewbot.inverse_kinematics(m, np.zeros(6)), r"q: expected shape \(4,\) .* got \(6,\)"),
    (lambda m: chewbot.forward_kinematics(m, "home"), r"theta: expected numbers"),
])
def test_a_wrong_shape_names_the_argument_the_shape_expected_and_the_shape_given(call, message):
    with pytest.raises(ValueError, match=message):
        call(model("target"))


def test_the_6rss_expects_its_six_coordinates():
    with pytest.raises(ValueError, match=r"q: expected shape \(6,\) .* \(X, Y, Z, alpha, beta, gamma of the 6RSS, in m, rad\), got \(4,\)"):
        chewbot.inverse_dynamics(model("6rss"), np.zeros(4), np.zeros(4), np.zeros(4))


# ------------------------------------------------------------------------------------------- the package


def test_import_chewbot_stays_cheap_and_lists_the_verbs():
    """``import chewbot`` loads neither NumPy nor CasADi; ``chewbot.__all__`` and ``dir(chewbot)`` list the API's
    verbs (chewbot.API is chewbot.api.__all__), and each is the function of its module."""
    code = "import sys, chewbot; print(sorted(m for m in ('numpy', 'casadi', 'chewbot.api') if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"
    assert sorted(chewbot.API) == sorted(api.__all__)
    assert set(api.__all__) <= set(chewbot.__all__) and set(api.__all__) <= set(dir(chewbot))
    for name in api.__all__:
        assert getattr(chewbot, name) is getattr(api, name)
    from chewbot.outputs.record import read_frame

    assert chewbot.load_model is load_model and chewbot.read_results is read_frame
