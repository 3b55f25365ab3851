"""A design search: minimise an output over bounded parameters, the task staying reachable and feasible.

SciPy's ``differential_evolution`` drives the search; each generation's population is evaluated on the cluster
in chunks, as every other sweep (:class:`chewbot.sweep.runner.ChunkRunner`: each evaluation is a row of
samples.parquet and its chunk is written as it arrives). The constraint is evaluated with the population
(SciPy's ``vectorized`` interface; with ``workers=`` SciPy would evaluate constraints one trial at a time, outside
the map): ``c = violation_share`` of the validity checks that make ``chewbot run`` exit 4 (0 where feasible), and
2 where the evaluation fails (a pose out of reach, a value the model refuses). SciPy's rule for constraints
(Lampinen 2002) then prefers a feasible trial to an infeasible one and, among infeasible ones, the smaller
violation; the objective is compared among feasible trials only. With ``require_feasible = false`` only the
kinematics must succeed (c is 0 or 2). SciPy's final local polish is off (it would evaluate one trial at a time
by finite differences): the result is the best member of the last generation.

A generation is deterministic given the seed, so an interrupted search resumes by replaying it: the
evaluations of the chunks already written are read back instead of computed.
"""

from __future__ import annotations

import numpy as np

from chewbot.sweep.runner import ChunkRunner, Design
from chewbot.sweep.spec import Spec

FAILED = 2.0  # constraint value of an evaluation that fails (beyond any share of failing samples of a check)


def optimize(spec: Spec, runner: ChunkRunner) -> tuple[dict, list[dict]]:
    """Run the search; returns the optimum (parameters, outputs, sample, feasible) and the convergence per
    generation (best objective, SciPy's convergence measure, feasible members, the best parameters)."""
    from scipy.optimize import NonlinearConstraint, differential_evolution

    s = spec.optimizer
    keys = spec.keys
    objective = spec.minimize
    keep = (*spec.computed_outputs, "error")
    seen: dict[bytes, dict] = {}  # x -> kept outputs of its evaluation
    state = {"next": 0, "history": []}

    def evaluate(X: np.ndarray) -> None:
        new = [x for x in X if x.tobytes() not in seen]
        if not new:
            return
        unique = np.unique(np.array(new), axis=0)
        first = state["next"]
        kept = runner.run(Design.of(keys, unique, first), keep)
        for k, x in enumerate(unique):
            seen[x.tobytes()] = {name: kept[name][k] for name in keep} | {"sample": first + k}
        state["next"] += len(unique)

    def violation(x: np.ndarray) -> np.ndarray:
        X = np.atleast_2d(x.T)
        evaluate(X)
        c = np.array([_violation(seen[r.tobytes()], spec.require_feasible) for r in X])
        return c[None, :] if x.ndim == 2 else c[:1]  # (constraints, trials), SciPy's vectorized shape

    def energy(x: np.ndarray) -> np.ndarray:
        X = np.atleast_2d(x.T)
        evaluate(X)
        return np.array([seen[r.tobytes()][objective] for r in X])

    def record(intermediate_result) -> None:  # SciPy passes its OptimizeResult to a parameter of this name
        intermediate = intermediate_result
        population = getattr(intermediate, "population", None)
        feasible = None
        if population is not None:
            feasible = int(sum(_violation(seen[r.tobytes()], spec.require_feasible) <= 0 for r in population
                               if r.tobytes() in seen))
        state["history"].append({"generation": len(state["history"]) + 1, "evaluations": state["next"],
                                 "best": float(intermediate.fun), "convergence": float(getattr(intermediate, "convergence", np.nan)),
                                 "feasible": feasible, "x": [float(v) for v in intermediate.x]})

    bounds = [p.args for p in spec.parameters]
    constraint = NonlinearConstraint(violation, -np.inf, 0.0)
    result = differential_evolution(energy, bounds, constraints=(constraint,), vectorized=True, updating="deferred",
                                    maxiter=s["generations"], popsize=s["popsize"], tol=s["tol"], atol=s["atol"],
                                    mutation=tuple(s["mutation"]) if isinstance(s["mutation"], list) else s["mutation"],
                                    recombination=s["recombination"], init=s["init"], rng=spec.seed, polish=False,
                                    callback=record)
    best = seen[np.asarray(result.x, dtype=float).tobytes()]
    optimum = {"parameters": dict(zip(keys, map(float, result.x))),
               "outputs": {name: float(best[name]) for name in spec.computed_outputs},
               "sample": int(best["sample"]), "constraints_met": bool(_violation(best, spec.require_feasible) <= 0),
               "generations": int(result.nit), "evaluations": state["next"], "message": str(result.message)}
    return optimum, state["history"]


def _violation(outputs: dict, require_feasible: bool) -> float:
    if outputs["error"]:
        return FAILED
    return float(outputs["violation_share"]) if require_feasible else 0.0
