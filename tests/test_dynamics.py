"""The Hessian, Lagrange and Liang formulations against each other and against independent routes.

Independent routes: the three formulations (different derivative machinery, different linear algebra: QR
pseudo-inverse vs a KKT system); the power balance of the whole robot along the task; Eq. (30)'s integral by
quadrature; C q_dot against finite differences of the kinetic energy. Finite differences are used here only.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np
import pytest
from support import default_kinematics, model

from chewbot.compiled.cache import folded
from chewbot.compiled.kernels import evaluate
from chewbot.dynamics.registry import inverse_dynamics
from chewbot.dynamics.formulations.dalembert import reduced_rhs, reduced_terms
from chewbot.dynamics.energy import energies, energy, generalised_state
from chewbot.dynamics.formulations.hessian import hessian_rates
from chewbot.dynamics.formulations.liang import liang_rates
from chewbot.errors import ChewbotError

METHODS = ("hessian", "lagrange", "liang")
SIDES = ("left", "right")
DERIVATIONS = {"hessian": hessian_rates, "liang": liang_rates}


@functools.cache
def torques(name: str, side: str, method: str) -> np.ndarray:
    return inverse_dynamics(model(name), default_kinematics(name, side), method).tau


@pytest.mark.parametrize("side", SIDES)
@pytest.mark.parametrize("method", ("lagrange", "liang"))
def test_methods_agree(mechanism, side, method):
    # All three are exact (AD, no finite differences); what separates them is rounding in different operation
    # orders and linear solves, ~1e-15 relative. 1e-9 is the bound and leaves room for harder tasks.
    ref = torques(mechanism, side, "hessian")
    other = torques(mechanism, side, method)
    assert np.abs(other - ref).max() <= 1e-9 * np.abs(ref).max()


@pytest.mark.parametrize("side", SIDES)
def test_power_balance(mechanism, side):
    """tau . theta_dot + F_B . v_B = dE/dt, E = T + V: the only forces that work are the actuators and the bite."""
    m, kin = model(mechanism), default_kinematics(mechanism, side)
    tau = torques(mechanism, side, "hessian")
    T, V, _ = energies(m, kin)
    E = T + V
    B = kin.points["B_L" if side == "left" else "B_R"]
    v_B = kin.twist[:, :3] + np.cross(kin.twist[:, 3:], B - kin.X[:, :3])
    power = np.sum(tau * kin.dtheta, axis=1) + np.sum(kin.force * v_B, axis=1)
    h = kin.t[1] - kin.t[0]
    # dE/dt by 4th-order central differences of E along the trajectory: truncation h^4/30 E^(5), ~3e-7 of the peak
    # power at h = 1 ms on this smooth task (the 2nd-order difference misses by ~3e-5). A single coupler's inertia
    # or weight left out changes dE/dt by more than 1e-5 of the peak power, well above the 1e-6 bound.
    dE = (E[:-4] - 8 * E[1:-3] + 8 * E[3:-1] - E[4:]) / (12 * h)
    residual = np.abs(dE - power[2:-2]).max()
    assert residual <= 1e-6 * np.abs(power).max(), residual


def test_inertia_matrix_symmetric_positive_definite(mechanism):
    _, _, M = energies(model(mechanism), default_kinematics(mechanism))
    # Built as sums of J' A J with symmetric A: symmetric up to rounding of the products (~1e-16 of the largest entry).
    scale = np.abs(M).max()
    assert np.abs(M - np.swapaxes(M, 1, 2)).max() <= 1e-13 * scale
    eig = np.linalg.eigvalsh(M)
    # Cranks make the theta block, the mandible the q_EE block definite: the smallest eigenvalue is far from zero.
    assert eig.min() > 1e-8 * eig.max()


@pytest.mark.parametrize("method", ("hessian", "liang", "lagrange"))
def test_torques_solve_reduced_equation(mechanism, method):
    """J_theta1' tau = M_f q_ddot + C_f q_dot + G_f - J_B' F_B (Eq. 53) with the Hessian method's terms.

    For the Hessian method itself this is a consistency check of the solve (its torques come from these very
    terms); for Liang's and Lagrange's torques, computed from their own terms, it is a cross-check."""
    kin = default_kinematics(mechanism, "left")
    terms = reduced_terms(model(mechanism), kin, "hessian", hessian_rates)
    rhs = reduced_rhs(terms, kin)
    lhs = np.einsum("nji,nj->ni", terms["J_theta1"], torques(mechanism, "left", method))
    # Rounding of a 4x6 (6x6) solve with condition numbers < 1e3: far below 1e-10 of the largest generalised force.
    assert np.abs(lhs - rhs).max() <= 1e-10 * np.abs(rhs).max()


def test_minimum_norm_on_target():
    """The target's torques have no component in the null space of J_theta1' (they are the least-norm solution)."""
    kin = default_kinematics("target")
    J1 = reduced_terms(model("target"), kin, "hessian", hessian_rates)["J_theta1"]
    tau = torques("target", "left", "hessian")
    _, _, vt = np.linalg.svd(np.swapaxes(J1, 1, 2))
    null = vt[:, 4:, :]  # the 2 directions that J_theta1' maps to zero
    assert np.abs(np.einsum("nkj,nj->nk", null, tau)).max() <= 1e-12 * np.abs(tau).max()


def _sample_states(mechanism, count=3, seed=0):
    """Task samples with an arbitrary q_dot (not tied to the closure): tests of the unconstrained M and C."""
    kin = default_kinematics(mechanism)
    q, _, _ = generalised_state(kin)
    rng = np.random.default_rng(seed)
    rows = np.linspace(1200, 4000, count).astype(int)
    return q[rows], rng.normal(size=(count, q.shape[1]))


def test_coupler_inertia_against_quadrature(mechanism):
    """M_SM of Eq. (30) by Gauss-Legendre quadrature of J_P' rho A J_P along the rod, P(s) = (1 - s) S + s M."""
    m = model(mechanism)
    e = energy(folded(m))
    s_sym = ca.SX.sym("s")
    nodes, weights = np.polynomial.legendre.leggauss(6)  # exact for the integrand, a polynomial of degree 2 in s
    q, _ = _sample_states(mechanism)
    for i in range(6):
        P = (1 - s_sym) * e.kin.crank_tip(i) + s_sym * e.kin.coupler_end(i)
        J = ca.jacobian(P, e.q)
        integrand = ca.Function("integrand", [e.q, s_sym], [m.coupler_mass[i] * ca.mtimes(J.T, J)])
        closed = ca.Function("closed", [e.q], [e.M_couplers[i]])
        for qk in q:
            quad = sum(w / 2 * np.array(integrand(qk, (x + 1) / 2)) for x, w in zip(nodes, weights))
            # Same sums in a different order: rounding only.
            assert np.allclose(np.array(closed(qk)), quad, rtol=0, atol=1e-13 * np.abs(quad).max())


@pytest.mark.parametrize("method", ("hessian", "liang"))
def test_coriolis_against_finite_differences(mechanism, method):
    """C q_dot = d/dt(dT/dq_dot) - M q_ddot - dT/dq = (dM/dq . q_dot) q_dot - dT/dq, by central differences of T."""
    e = energy(folded(model(mechanism)))
    rates = DERIVATIONS[method](e)
    fn = ca.Function("f", [e.q, e.dq], [e.T, ca.mtimes(rates.C, e.dq), e.M])
    q, dq = _sample_states(mechanism)
    eps = 1e-4
    for qk, dqk in zip(q, dq):
        def T(x):
            return float(fn(x, dqk)[0])

        def M(x):
            return np.array(fn(x, dqk)[2])

        def diff(f, u):  # 4th-order central difference of f along u
            return (f(qk - 2 * eps * u) - 8 * f(qk - eps * u) + 8 * f(qk + eps * u) - f(qk + 2 * eps * u)) / (12 * eps)

        grad_T = np.array([diff(T, u) for u in np.eye(len(qk))])
        fd = diff(M, dqk) @ dqk - grad_T
        exact = np.array(fn(qk, dqk)[1]).ravel()
        # The natural size of C q_dot is abs(M) abs(q_dot)^2. Truncation eps^4 / 30 times fifth derivatives (~1e-17 of
        # it) and rounding eps_mach / eps (~1e-12 of it) are far below 1e-9 of it; a missing factor 1/2, a
        # transposed H12 or a dropped coupler term changes C q_dot by far more.
        scale = np.abs(M(qk)).max() * np.abs(dqk).max() ** 2
        assert np.abs(exact - fd).max() <= 1e-9 * scale


def test_coriolis_matrices_differ_but_agree_on_q_dot(mechanism):
    """Eq. (52) with H12 and Eq. (61) give different C matrices with the same C q_dot (documented in both modules)."""
    e = energy(folded(model(mechanism)))
    Ch, Cl = hessian_rates(e).C, liang_rates(e).C
    fn = ca.Function("f", [e.q, e.dq], [Ch, Cl, ca.mtimes(Ch - Cl, e.dq)])
    q, dq = _sample_states(mechanism)
    Ch_v, Cl_v, diff = evaluate(fn, q, dq)
    scale = np.abs(Ch_v).max()
    assert np.abs(Ch_v - Cl_v).max() > 1e-3 * scale
    assert np.abs(diff).max() <= 1e-12 * scale * np.abs(dq).max()


@pytest.mark.parametrize("method", METHODS)
def test_euler_parameters_are_refused(method):
    kin = default_kinematics("target", "left", "euler-parameters")
    with pytest.raises(ChewbotError, match="takes Euler angles"):
        inverse_dynamics(model("target"), kin, method)


def test_side_option_overrides_kinematics():
    """side= moves the bite force to the other molar: the torques change and solve Eq. (53) with Q_B at B_R."""
    kin = default_kinematics("target", "left")
    left = inverse_dynamics(model("target"), kin, "hessian").tau
    right = inverse_dynamics(model("target"), kin, "hessian", side="right").tau
    assert np.abs(left - right).max() > 1e-3 * np.abs(left).max()
    terms = reduced_terms(model("target"), kin, "liang", liang_rates, side="right")
    lhs = np.einsum("nji,nj->ni", terms["J_theta1"], right)
    assert np.abs(lhs - reduced_rhs(terms, kin)).max() <= 1e-10 * np.abs(lhs).max()
