"""Real-time kernels: the 6RSS-core formulation, the compiled kernels, their C export, the plain references.

Each kernel is held against another route to the same quantity: the Hessian/Lagrange/Liang formulations, the
Newton-Euler solver, a NumPy Newton-Euler written independently, finite differences along the task.
"""

from __future__ import annotations

import functools
import re
import subprocess

import numpy as np
import pytest
from support import default_kinematics, model, without_drive
from typer.testing import CliRunner

from chewbot.compiled.kernels import NativeFunction, c_compiler, evaluate
from chewbot.cli import app
from chewbot.dynamics.registry import inverse_dynamics
from chewbot.dynamics.formulations.core6rss import core_terms, dynamics_kernel, torque_kernel
from chewbot.dynamics.formulations.dalembert import reduced_terms
from chewbot.dynamics.energy import energies, generalised_state
from chewbot.dynamics.formulations.hessian import hessian_rates
from chewbot.export.c import export_c
from chewbot.kinematics.functions import jacobians_function
from chewbot.dynamics.g1 import g1_distribution
from chewbot.export.realtime import EXAMPLE_T, example_inputs, kernels
from chewbot.kinematics.motion import solve_kinematics
from chewbot.bench.reference import frictionless_torques, slsqp_min_torque
from chewbot.task.default import default_task

SIDES = ("left", "right")
# Agreement of two exact routes to the same torques: the bound. Measured: ~1e-13 (target), ~1e-12 (6RSS).
AGREE = 1e-9


def _rel(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(b)).max()


@functools.cache
def torques(name: str, side: str, method: str) -> np.ndarray:
    return inverse_dynamics(model(name), default_kinematics(name, side), method).tau


@pytest.mark.parametrize("side", SIDES)
@pytest.mark.parametrize("other", ["hessian", "lagrange", "liang"])
def test_core_formulation_agrees_with_the_others(mechanism, side, other):
    assert _rel(torques(mechanism, side, "6rss-core"), torques(mechanism, side, other)) <= AGREE


@pytest.mark.parametrize("side", SIDES)
def test_numpy_newton_euler_reference_agrees(mechanism, side):
    """The plain NumPy Newton-Euler torques (an independent implementation) against the Hessian method."""
    tau = frictionless_torques(model(mechanism), default_kinematics(mechanism, side))
    assert _rel(tau, torques(mechanism, side, "hessian")) <= AGREE


@functools.cache
def full_terms(name: str):
    return core_terms(model(name), default_kinematics(name))


def test_core_matrices_satisfy_eq53(mechanism):
    """J_theta1' tau = M_f q_ddot + C_f q_dot + G_f - Q_B with the kernel's own matrices and its torques, which
    it computes without them (the right-hand side through the bodies' accelerations)."""
    kin = default_kinematics(mechanism)
    out = full_terms(mechanism)
    _, dq, ddq = generalised_state(kin)
    rhs = (np.einsum("nij,nj->ni", out["M_f"], ddq[:, 6:]) + np.einsum("nij,nj->ni", out["C_f"], dq[:, 6:])
           + out["G_f"] - out["Q_B"])
    lhs = np.einsum("nji,nj->ni", out["J_theta1"], out["tau"])
    assert _rel(lhs, rhs) <= 1e-12  # two exact routes, rounding only


def test_core_matrices_equal_the_hessian_methods(mechanism):
    """M_f, G_f, Q_B, J_theta1 are unique and agree with the Hessian method's; C_f is not unique as a matrix, but
    C_f q_dot is."""
    m, kin = model(mechanism), default_kinematics(mechanism)
    out = full_terms(mechanism)
    ref = reduced_terms(m, kin, "hessian", hessian_rates)
    _, dq, _ = generalised_state(kin)
    for key in ("J_theta1", "M_f", "G_f", "Q_B"):
        assert _rel(out[key], ref[key]) <= 1e-11, key
    assert _rel(np.einsum("nij,nj->ni", out["C_f"], dq[:, 6:]), np.einsum("nij,nj->ni", ref["C_f"], dq[:, 6:])) <= 1e-9


def test_core_coriolis_matrix_is_passive(mechanism):
    """M_f_dot - 2 C_f is skew-symmetric (the property passivity-based control uses). M_f_dot by central
    differences of the kernel's M_f along q_dot, M_f(q + h q_dot) - M_f(q - h q_dot) over 2h with h = 1e-6 s:
    truncation O(h^2) and rounding ~eps/h, both far below the 1e-8 relative bound."""
    m, kin = model(mechanism), default_kinematics(mechanism)
    fn = dynamics_kernel(mechanism).folded(m).graph()
    k = np.arange(1200, 4800, 97)  # inside the chewing cycles
    q, dq, ddq = generalised_state(kin)
    q, dq, ddq = q[k, 6:], dq[k, 6:], ddq[k, 6:]

    def terms(x):
        return dict(zip(fn.name_out(), evaluate(fn, x, dq, ddq, m.molar_left, kin.force[k])))

    h = 1e-6
    M_dot = (terms(q + h * dq)["M_f"] - terms(q - h * dq)["M_f"]) / (2 * h)
    C = terms(q)["C_f"]
    scale = np.abs(M_dot).max() + np.abs(2 * C).max()
    S = M_dot - 2 * C
    assert np.abs(S + np.swapaxes(S, 1, 2)).max() <= 1e-8 * scale
    S1 = M_dot - C  # and the test can fail: C_f alone does not make it skew
    assert np.abs(S1 + np.swapaxes(S1, 1, 2)).max() > 1e-2 * scale


def test_coupling_kernel_against_pseudo_inverse():
    """M_A from the compiled kernel (pseudo-inverse solved in the graph) against NumPy's pinv of J_theta1."""
    from chewbot.analysis.coupling import joint_space_inertia

    for name in ("target", "6rss"):
        m, kin = model(name), default_kinematics(name)
        q, _, _ = generalised_state(kin)
        J1 = evaluate(jacobians_function(name, "euler-angles"), q[:, :6], q[:, 6:], m.vector())[2]
        _, _, M = energies(m, kin)
        J5 = np.concatenate([np.broadcast_to(np.eye(6), (kin.n, 6, 6)), np.linalg.pinv(J1)], axis=1)
        assert _rel(joint_space_inertia(m, kin), np.swapaxes(J5, 1, 2) @ M @ J5) <= 1e-10


@functools.cache
def g1(orientation: str, drive: bool = False):
    m = model("target") if drive else without_drive("target")
    kin = default_kinematics("target", "left", orientation)  # the same geometry
    return g1_distribution(m, kin), inverse_dynamics(m, kin, "newton-euler", goal="min-torque", friction=True)


@pytest.mark.parametrize("drive", [False, True])
@pytest.mark.parametrize("orientation", ["euler-parameters", "euler-angles"])
def test_g1_kernel_equals_the_newton_euler_solver(orientation, drive):
    """The fixed-iteration G1 kernel against the distribution solver (damped Newton to convergence)."""
    out, ne = g1(orientation, drive)
    N = np.column_stack([ne.table["N_L"], ne.table["N_R"]])
    assert _rel(out["tau"], ne.tau) <= 1e-10
    assert np.abs(out["N"] - N).max() <= 1e-8  # N in newtons, solver's step tolerance 1e-10 (1 + |N|)
    # at its answer the gradient of |tau|^2 vanishes to rounding (|tau|^2 ~ 0.1 N^2 m^2, grad in N m^2 / N)
    assert np.abs(out["grad"]).max() <= 1e-12
    assert out["step"].max() <= 1e-9  # N: converged, the last step is at rounding level
    assert np.abs(out["limits"][:, :6] - ne.tau).max() <= 1e-10 * np.abs(ne.tau).max()


@pytest.mark.parametrize("coulomb", [(0.3, 0.3), (1.0, 0.5)])
def test_g1_kernel_with_more_friction(coulomb):
    """The friction coefficients are assumed values that users replace. With larger Coulomb coefficients the
    optimum often sits on a kink (one condyle nearly unloaded), where plain Newton from the friction-free optimum
    goes astray (14 % off at 0.3/0.3); the kernel must still reach the solver's optimum."""
    import dataclasses

    from chewbot.model import Friction

    base = without_drive("target")
    fr = base.friction
    m = dataclasses.replace(base, friction=Friction(coulomb[0], fr.hkp_viscous, fr.actuator_arm, coulomb[1], fr.actuator_viscous))
    kin = solve_kinematics(m, default_task(m), "euler-parameters")
    ne = inverse_dynamics(m, kin, "newton-euler", goal="min-torque", friction=True)
    out = g1_distribution(m, kin)
    assert _rel(out["tau"], ne.tau) <= 1e-10
    assert out["step"].max() <= 1e-9


def test_slsqp_reference_agrees_with_the_solver():
    """SciPy's SLSQP (finite-difference gradients, so ~1e-6 relative at best) reaches the same G1 optimum."""
    m, kin = model("target"), default_kinematics("target")
    _, ne = g1("euler-angles", drive=True)
    idx = np.arange(2100, 2110)
    tau, N = slsqp_min_torque(m, kin, idx)
    assert _rel(tau, ne.tau[idx]) <= 1e-4


def test_native_calls_equal_casadi():
    """One-sample and batched ctypes calls of a compiled kernel against CasADi's own evaluation of the graph."""
    if c_compiler() is None:
        pytest.skip("no C compiler: kernels run in CasADi's virtual machine")
    m, kin = model("target"), default_kinematics("target")
    p = m.vector()  # the kernels the formulations use: the model's parameters as the last input
    fn = torque_kernel("target").graph()
    nf = NativeFunction(torque_kernel("target"))
    q, dq, ddq = kin.X[:, [0, 1, 3, 4]], kin.dX[:, [0, 1, 3, 4]], kin.ddX[:, [0, 1, 3, 4]]
    ref = evaluate(fn, q, dq, ddq, m.molar_left, kin.force, p)
    got = nf.batch(q, dq, ddq, m.molar_left, kin.force, p)
    for a, b in zip(got, ref):
        assert _rel(a, b) <= 1e-13
    one = nf(q[2100], dq[2100], ddq[2100], m.molar_left, kin.force[2100], p)
    for a, b in zip(one, ref):
        assert _rel(a, b[2100]) <= 1e-13
    # matrix outputs, and results that stay valid after the next call reuses the buffers
    full = NativeFunction(dynamics_kernel("target"))
    k = 2440  # inside a bite: every output is non-zero
    first = full(q[k], dq[k], ddq[k], m.molar_left, kin.force[k], p)
    full(q[900], dq[900], ddq[900], m.molar_left, kin.force[900], p)
    for a, b in zip(first, evaluate(dynamics_kernel("target").graph(), q[k:k + 1], dq[k:k + 1], ddq[k:k + 1], m.molar_left, kin.force[k:k + 1], p)):
        assert _rel(np.asarray(a).reshape(b[0].shape), b[0]) <= 1e-13
    with pytest.raises(ValueError, match="6 inputs|takes 6"):
        full(q[2100], dq[2100])
    with pytest.raises(ValueError, match="entries, expected"):
        full(q[2100], dq[2100], ddq[2100], m.molar_left, 3.0, p)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    if c_compiler() is None:
        pytest.skip("no C compiler found: the exported C cannot be compiled here")
    target, sixrss = model("target"), model("6rss")
    ks = kernels(target, sixrss)
    folder = export_c(ks, tmp_path_factory.mktemp("c") / "kernels")
    exe = folder / "example"
    subprocess.run([c_compiler(), "-O2", "-std=c99", "-Wall", "-Werror=implicit-function-declaration", "-o", str(exe),
                    str(folder / "example.c"), str(folder / "chewbot_kernels.c"), "-lm"], check=True, capture_output=True)
    stdout = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout  # exit 0: its own check passed
    printed, confirmed = {}, set()
    for line in stdout.splitlines():
        if ": as chewbot computes it" in line:  # the program's own check against the values written into it
            confirmed.add(tuple(line.split(":")[0].split()))
            continue
        name, output, *values = line.split()
        printed[name, output] = np.array([float(v) for v in values])
    assert confirmed == set(printed)  # every output checked by the example program itself
    return ks, printed, folder


def test_exported_c_equals_the_python_model(exported):
    """Every output of every kernel, compiled by the system C compiler from the exported source, against the
    same kernel evaluated in Python (<= 1e-10 relative, the issue's bound)."""
    ks, printed, _ = exported
    for k in ks:
        f = k.function
        values = f.call({name: np.asarray(v, dtype=float).reshape(-1, 1) if f.size2_in(name) == 1 else v for name, v in k.example.items()})
        for j in range(f.n_out()):
            want = np.ravel(np.asarray(values[f.name_out(j)]), order="F")
            got = printed[k.name, f.name_out(j)]
            assert got.shape == want.shape
            assert np.abs(got - want).max() <= 1e-10 * max(np.abs(want).max(), 1e-300), (k.name, f.name_out(j))


def test_exported_torques_equal_the_hessian_method(exported):
    """The C torques at the example sample against the Hessian method in Python: an independent route."""
    _, printed, _ = exported
    t = default_kinematics("target").t
    k = int(np.argmin(np.abs(t - EXAMPLE_T)))  # the sample example_inputs takes
    for name, tag in (("target", "target"), ("6rss", "sixrss")):
        ref = torques(name, "left", "hessian")[k]
        assert _rel(printed[f"tau_{tag}", "tau"], ref) <= AGREE
        assert _rel(printed[f"dynamics_{tag}", "tau"], ref) <= AGREE


def test_export_folder_is_self_contained(exported):
    _, _, folder = exported
    names = {p.name for p in folder.iterdir()}
    assert {"chewbot_kernels.c", "chewbot_kernels.h", "example.c", "README.md", "Makefile"} <= names
    source = (folder / "chewbot_kernels.c").read_text()
    includes = set(re.findall(r"#include\s*<([^>]+)>", source))
    assert includes <= {"math.h", "string.h", "stdio.h", "stdlib.h"}, includes
    readme = (folder / "README.md").read_text()
    for k in ("tau_target", "dynamics_target", "coupling_target", "tau_sixrss", "g1_target"):
        assert f"`{k}`" in readme


def test_export_command_refuses_an_existing_folder(tmp_path):
    out = tmp_path / "c"
    out.mkdir()
    result = CliRunner().invoke(app, ["export-c", "--out", str(out)])
    assert result.exit_code == 5
    assert "exists" in result.output
    assert list(out.iterdir()) == []


def test_example_inputs_sample_is_inside_a_bite():
    """The README's example sample carries a bite force, so the kernels' force path is exercised."""
    ex = example_inputs(model("target"), model("6rss"))
    assert np.linalg.norm(ex["tau_target"]["F_B"]) > 10


def test_numpy_reference_with_friction_reproduces_the_newton_euler_torques():
    """At the solver's normal forces, the plain NumPy Newton-Euler with friction (written independently of the
    CasADi model) gives the same torques: an independent check of the friction model and the force chain."""
    from chewbot.dynamics.formulations.newton_euler import DELTA_F_G, DELTA_N, EPS_THETA_DOT, EPS_V_T
    from chewbot.bench.reference import _equations, _sample_torques

    assert DELTA_N == DELTA_F_G  # the reference smooths both magnitudes with one delta

    m, kin = model("target"), default_kinematics("target")
    _, ne = g1("euler-angles", drive=True)
    N = np.column_stack([ne.table["N_L"], ne.table["N_R"]])
    e = _equations(m, kin, None)
    rows = np.arange(0, kin.n, 7)
    tau = np.array([_sample_torques(m, e, k, N[k], kin.dtheta[k], EPS_THETA_DOT, EPS_V_T, DELTA_N)[0] for k in rows])
    # both exact given N (6x6 solves, cond ~1e3): rounding only
    assert _rel(tau, ne.tau[rows]) <= 1e-10
