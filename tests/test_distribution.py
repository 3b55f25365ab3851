"""The distribution solver on small problems whose optimum is known in closed form or by SciPy."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import minimize

from chewbot.dynamics.distribution import ProblemGraph, SampleData, build_problem, solve
from chewbot.errors import InfeasibleError

RNG = np.random.default_rng(7)
N_SAMPLES = 64


def _problem(nonlinear: float):
    """r = A x + b + nonlinear * friction * [sqrt(x0^2 + 1e-6); 0; x1^2] (A, b from D), limit c = x0."""
    D, x, fl = ca.SX.sym("D", 9), ca.SX.sym("x", 2), ca.SX.sym("friction")
    A, b = ca.reshape(D[:6], 3, 2), D[6:9]
    r = ca.mtimes(A, x) + b + nonlinear * fl * ca.vertcat(ca.sqrt(x[0] ** 2 + 1e-6), 0, x[1] ** 2)
    return build_problem(f"test_{int(nonlinear * 10)}", lambda: ProblemGraph(D, x, fl, [], r, x[0]), 2, ["x0"], has_start=False)


def _data():
    D = RNG.normal(size=(N_SAMPLES, 9))
    return D, SampleData(ca.DM(D.T))


def test_without_friction_the_solution_is_the_least_squares_solution():
    D, data = _data()
    sol = solve(_problem(0.3), data, 0.0, np.arange(N_SAMPLES), [1e9])
    for k in range(N_SAMPLES):
        A, b = D[k, :6].reshape(2, 3).T, D[k, 6:]
        expected = np.linalg.lstsq(A, -b, rcond=None)[0]
        # closed form against one Newton step of a 2x2 system: rounding only (cond(A'A) < 1e4 here)
        assert np.allclose(sol.x[k], expected, rtol=1e-10, atol=1e-12)


def test_nonlinear_optimum_matches_scipy():
    D, data = _data()
    prob = _problem(0.3)
    sol = solve(prob, data, 1.0, np.arange(N_SAMPLES), [1e9])
    assert not sol.unconverged
    for k in range(N_SAMPLES):
        A, b = D[k, :6].reshape(2, 3).T, D[k, 6:]

        def J(x):
            r = A @ x + b + 0.3 * np.array([np.sqrt(x[0] ** 2 + 1e-6), 0, x[1] ** 2])
            return r @ r

        ref = minimize(J, sol.x[k], method="Nelder-Mead", options={"xatol": 1e-12, "fatol": 1e-16, "maxiter": 10000})
        # the solver's point is at least as good as any SciPy finds starting from it (a local optimum)
        assert J(sol.x[k]) <= ref.fun + 1e-12 * (1 + abs(ref.fun))


def test_active_limit_is_met_by_sqp():
    D, data = _data()
    free = solve(_problem(0.0), data, 0.0, np.arange(N_SAMPLES), [1e9]).x
    bound = 0.5 * np.abs(free[:, 0]).max()
    sol = solve(_problem(0.0), data, 0.0, np.arange(N_SAMPLES), [bound])
    assert sol.constrained and not sol.infeasible
    assert np.abs(sol.x[:, 0]).max() <= bound * (1 + 1e-6)
    for k in sol.constrained:
        # a convex quadratic with x0 fixed at the bound: x1 is the 1-D least squares solution
        A, b = D[k, :6].reshape(2, 3).T, D[k, 6:]
        x0 = np.sign(free[k, 0]) * bound
        x1 = -(A[:, 1] @ (A[:, 0] * x0 + b)) / (A[:, 1] @ A[:, 1])
        assert sol.x[k, 0] == pytest.approx(x0, rel=1e-6)
        assert sol.x[k, 1] == pytest.approx(x1, rel=1e-6, abs=1e-8)


def test_infeasible_limit_is_recorded_or_raised():
    D, x, fl = ca.SX.sym("D", 9), ca.SX.sym("x", 2), ca.SX.sym("friction")
    prob = build_problem("test_infeasible", lambda: ProblemGraph(D, x, fl, [], x - D[:2], ca.vertcat(D[2] + 0 * x[0])), 2,
                         ["fixed load"], has_start=False)
    Dv = np.zeros((4, 9))
    Dv[2, 2] = 1.0  # sample 2 carries a load of 1 > 0.5 whatever x is
    sol = solve(prob, SampleData(ca.DM(Dv.T)), 0.0, np.arange(4) * 0.1, [0.5])
    assert len(sol.infeasible) == 1
    entry = sol.infeasible[0]
    assert entry["sample"] == 2 and entry["t"] == pytest.approx(0.2) and entry["limits"] == ["fixed load"]
    assert entry["solver"]  # the SQP's return status, which the report shows beside the sample
    with pytest.raises(InfeasibleError, match=r"sample 2 \(t = 0.2 s\).*fixed load"):
        solve(prob, SampleData(ca.DM(Dv.T)), 0.0, np.arange(4) * 0.1, [0.5], strict=True)
