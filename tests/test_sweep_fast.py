"""The sweep's fused path (torques and MCI in one kernel per evaluation) against the run pipeline.

Where a SPEC's outputs need only the torques and MCI and the formulation is a Lagrange-d'Alembert reduction under
the bilateral contact model, an evaluation computes tau and MCI by :func:`chewbot.analysis.coupling.torques_coupling_kernel`
instead of the run's stages. The two routes solve Eq. (54) differently (the run by the QR factors of J_theta1, the
fused kernel by J_theta1 (J_theta1' J_theta1)^-1 inside the graph), so they agree to rounding: the tolerance is
1e-12 of max abs(tau) (J_theta1's columns, scaled, have kappa 0.34-0.41 on the default task: its Gram matrix's
condition number is below 10, and the rounding of a 4 x 4 solve is about 1e-15 of that).
"""

from __future__ import annotations

import numpy as np
import pytest

from chewbot.sweep.spec import parse_spec, read_spec

# 1e-12 relative: the tolerance for the fused path; the routes differ by rounding only (module docstring)
RTOL = 1e-12


def _kinematics(model_name, overrides=None):
    from chewbot.kinematics.motion import solve_kinematics
    from chewbot.model.params import load_model
    from chewbot.model.params import split_overrides
    from chewbot.task.default import default_task, parameters_with

    model_o, task_o = split_overrides(overrides or {})
    model = load_model(model_name, model_o) if model_o else load_model(model_name)
    task = default_task(None, "left", parameters_with(task_o) if task_o else None)
    return model, solve_kinematics(model, task)


@pytest.mark.parametrize("model_name,method", [("target", "hessian"), ("target", "liang"), ("6rss", "hessian")])
def test_fused_kernel_equals_the_formulation_and_the_coupling_per_sample(model_name, method):
    """tau and MCI of every sample of the default task equal the formulation's (Dynamics.tau) and the coupling's."""
    from chewbot.analysis.coupling import coupling, torques_coupling
    from chewbot.dynamics.registry import FORMULATIONS, inverse_dynamics

    model, kin = _kinematics(model_name)
    tau, mci = torques_coupling(model, kin, method, FORMULATIONS[method].rates)
    expected = inverse_dynamics(model, kin, method).tau
    scale = np.abs(expected).max()
    assert np.abs(tau - expected).max() <= RTOL * scale
    assert np.abs(mci - coupling(model, kin).MCI).max() <= RTOL * np.abs(mci).max()


def test_sobol_scale_samples_equal_chewbot_run():
    """Rows of the built-in sobol-scale study (its own parameters) by the fused path equal chewbot run's numbers
    with the same --set values (the pipeline in memory); the evaluator did take the fused path."""
    from chewbot.run.options import RunOptions
    from chewbot.run.pipeline import compute
    from chewbot.sweep.evaluate import Evaluator

    spec = read_spec("sobol-scale")
    evaluator = Evaluator(spec)
    assert evaluator.rates is not None  # peak_tau_Nm and mean_MCI: the fused path
    lo = np.array([p.args[0] for p in spec.parameters])
    hi = np.array([p.args[1] for p in spec.parameters])
    values = lo + (hi - lo) * np.array([[0.5] * 8, [0.1, 0.9, 0.2, 0.8, 0.3, 0.7, 0.4, 0.6], [0.95, 0.05, 0.9, 0.1, 0.85, 0.15, 0.8, 0.2]])
    out = evaluator.evaluate(values)
    assert out["error"] == [None] * 3
    for k, row in enumerate(values):
        run = compute(RunOptions(method="hessian", overrides=dict(zip(spec.keys, map(float, row)))))
        tau = np.column_stack([run.table[f"tau{i}"] for i in range(1, 7)])
        mci = np.column_stack([run.table[f"MCI{i}"] for i in range(1, 7)])
        assert out["peak_tau_Nm"][k] == pytest.approx(np.abs(tau).max(), rel=RTOL)
        assert out["mean_MCI"][k] == pytest.approx(mci.mean(), rel=RTOL)


@pytest.mark.parametrize("outputs,contact,method,fused", [
    (["peak_tau_Nm", "mean_MCI"], "bilateral", "hessian", True),
    (["peak_tau_Nm", "peak_N_L"], "bilateral", "hessian", False),  # reads the formulation's N_L
    (["peak_tau_Nm", "feasible"], "bilateral", "hessian", False),  # reads the run's checks
    (["peak_tau_Nm"], "unilateral", "hessian", False),  # the unilateral fallback changes the torques
    (["peak_tau_Nm"], "bilateral", "newton-euler", False),  # friction and G1: not a reduction of Eq. (53)
])
def test_the_fused_path_is_taken_only_where_it_gives_the_runs_numbers(outputs, contact, method, fused):
    from chewbot.sweep.evaluate import Evaluator

    spec = parse_spec({"kind": "monte-carlo", "samples": 1, "method": method, "contact": contact, "outputs": outputs,
                       "parameters": {"task.force_z_N": {"uniform": [-120.0, -40.0]}}}, "fused.toml")
    assert (Evaluator(spec).rates is not None) == fused
