"""Maps over poses of the mandible: workspace, singularity and force capability (a ``grid`` SPEC with ``[grid]``).

Each pose of the grid is a static pose (zero velocity and acceleration) of the SPEC's model, given by X, Y,
alpha, beta (the target's independent coordinates; on the 6RSS Z and gamma follow from the sockets as for a
task, unless the SPEC gives them). Per pose:

* **workspace**: ``reachable`` is 1 where the kinematics accept the pose, else 0 with the kinematics' own error in
  ``error`` (a condyle outside its socket, a chain out of reach, a chain at its dead point, a parallel
  singularity: docs/conventions.md). The verdicts are those of
  :func:`chewbot.kinematics.motion.solve_kinematics`, which reports the first bad sample of a task: a chunk of
  poses is solved as a task, and after an error at pose k the poses before and after it are solved again, until
  every pose has its verdict.
* **singularity**: ``min_mu_deg``, the smallest transmission angle of the six chains, with ``mu_chain`` (which
  chain), and ``kappa_J``, the reciprocal condition number of the chains' Jacobian (docs/conventions.md). They are
  given wherever every chain closes (also outside the sockets, so the map shows where the singularities lie),
  NaN where one cannot.
* **force**: ``Fmax_NAME_N``, the largest bite force at the molar of the SPEC's side, in each direction NAME of
  ``[force] directions``, that the actuators can resist within their torque limit ``limits.torque_Nm``, with the
  redundancy of the target used in full: the linear program

      maximise s  over (tau, s)   subject to   J_theta1' tau + s Q_B(d) = G_f,   abs(tau_i) <= tau_max,   s >= 0

  (Eq. 53 at rest: the torques hold gravity G_f and the bite force s d, whose generalised force is Q_B(s d) =
  s J_B' d), solved by SciPy's HiGHS. Static and frictionless: at rest the power limit does not bind and friction
  has no velocity to act along; the bearing loads are not part of it. ``inf`` where the force does no work on the
  mechanism's coordinates (the structure holds it); NaN where the limits cannot even hold the pose against
  gravity (said in ``error``).
"""

from __future__ import annotations

import re

import numpy as np

from chewbot.errors import KinematicsError
from chewbot.sweep.runner import Design
from chewbot.sweep.spec import POSE_KEYS, Spec

HOLD_FAILURE = "the torque limits cannot hold this pose against gravity"


def map_columns(spec: Spec) -> dict[str, tuple[str, str]]:
    """The output columns of a grid over poses, with (unit, description)."""
    cols = {"reachable": ("1", "1 where the kinematics accept the pose, else 0 (the reason in error)")}
    if "singularity" in spec.maps:
        cols["min_mu_deg"] = ("deg", "smallest transmission angle of the six chains (NaN where a chain cannot close)")
        cols["mu_chain"] = ("1", "the chain (1..6) with the smallest transmission angle")
        cols["kappa_J"] = ("1", "reciprocal condition number of the chains' Jacobian, columns scaled (0: singular)")
    if "force" in spec.maps:
        for name, d in spec.directions.items():
            cols[f"Fmax_{name}_N"] = ("N", f"largest bite force along ({', '.join(f'{v:.3g}' for v in d)}) in {{S}} that the "
                                           "torque limits resist at rest (linear program, redundancy used)")
    return cols


def map_kernels(mechanism: str) -> list:
    """The compiled kernels of the maps: the kinematics and the terms of Eq. 53."""
    from chewbot.dynamics.formulations.dalembert import reduced_kernel
    from chewbot.dynamics.formulations.hessian import hessian_rates
    from chewbot.kinematics.functions import kinematics_kernel

    return [kinematics_kernel(mechanism, "euler-angles"), reduced_kernel(mechanism, "hessian", hessian_rates)]


def pose_design(spec: Spec) -> Design:
    """Every pose of the grid (the SPEC's units), the last coordinate varying fastest."""
    from chewbot.sweep.samplers import grid_design

    return grid_design(spec.keys, spec.poses)


class PoseEvaluator:
    """The maps of a SPEC at chunks of poses (a worker keeps one per SPEC)."""

    def __init__(self, spec: Spec):
        from chewbot.model.params import load_model, split_overrides

        self.spec = spec
        self.model = load_model(spec.model, split_overrides(spec.fixed)[0])
        self.columns = map_columns(spec)

    def coordinates(self, values: np.ndarray) -> tuple[tuple[str, ...], np.ndarray]:
        """The poses as a task's coordinates (SI): X, Y, alpha, beta, or all six where Z or gamma is given."""
        given = {**self.spec.pose_fixed, **{k: values[:, j] for j, k in enumerate(self.spec.keys)}}
        names = ("X", "Y", "Z", "alpha", "beta", "gamma") if {"Z_mm", "gamma_deg"} & set(given) else ("X", "Y", "alpha", "beta")
        unit = {"X": "X_mm", "Y": "Y_mm", "Z": "Z_mm", "alpha": "alpha_deg", "beta": "beta_deg", "gamma": "gamma_deg"}
        q = np.column_stack([np.broadcast_to(np.asarray(given.get(unit[c], 0.0), dtype=float) * POSE_KEYS[unit[c]], len(values))
                             for c in names])
        return names, q

    def evaluate(self, values: np.ndarray) -> dict:
        n = len(values)
        names, q = self.coordinates(values)
        out = {name: np.full(n, np.nan) for name in self.columns}
        errors: list[str | None] = [None] * n
        reasons = workspace_verdicts(self.model, names, q, self.spec.side or "left")
        reachable = np.array([i not in reasons for i in range(n)])
        out["reachable"] = reachable.astype(float)
        for i, reason in reasons.items():
            errors[i] = reason
        if "singularity" in self.spec.maps:
            out["min_mu_deg"], out["mu_chain"], out["kappa_J"] = singularity_measures(self.model, names, q)
        if "force" in self.spec.maps and reachable.any():
            ok = np.flatnonzero(reachable)
            capacity = force_capability(self.model, names, q[ok], self.spec.side or "left", self.spec.directions)
            for name, values_ in capacity.items():
                out[f"Fmax_{name}_N"][ok] = values_
            held = np.isnan(np.column_stack(list(capacity.values()))).any(axis=1)
            for i in ok[held]:
                errors[i] = HOLD_FAILURE
        out["error"] = errors
        return out


def _task(names, q: np.ndarray, side: str):
    from chewbot.kinematics.task import Task

    n = len(q)
    return Task(name="pose grid", t=np.arange(n, dtype=float), coords=tuple(names), q=q, dq=np.zeros_like(q),
                ddq=np.zeros_like(q), force=np.zeros((n, 3)), side=side)


def workspace_verdicts(model, names, q: np.ndarray, side: str) -> dict[int, str]:
    """{pose index: the kinematics' error} for the poses the kinematics refuse (the others are reachable).

    Each call of the kinematics stops at its first bad pose; the poses before and after it are solved again
    (before it, only the checks that ran before the failing one were passed)."""
    from chewbot.kinematics.motion import solve_kinematics

    reasons: dict[int, str] = {}
    segments = [np.arange(len(q))]
    while segments:
        idx = segments.pop()
        if not idx.size:
            continue
        try:
            solve_kinematics(model, _task(names, q[idx], side), "euler-angles")
        except KinematicsError as exc:
            if exc.sample is None:
                raise
            k = exc.sample
            reasons[int(idx[k])] = pose_reason(exc)
            segments += [idx[:k], idx[k + 1:]]
    return reasons


# The count of bad samples that some kinematics errors end with: of the chunk's poses, meaningless for one pose.
_COUNT = re.compile(r"[ ;(]+\d+ sample\(s\) (?:outside|affected)\)?$")


def pose_reason(exc: KinematicsError) -> str:
    """A kinematics error of one pose: without the task's sample, time and count (they are the chunk's)."""
    reason = _COUNT.sub("", exc.reason)
    return f"chain {exc.chain}: {reason}" if exc.chain else reason


def _kernel_outputs(model, names, q: np.ndarray) -> dict[str, np.ndarray]:
    from chewbot.compiled.kernels import evaluate, native
    from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
    from chewbot.kinematics.motion import task_coordinates

    qe, dqe, ddqe = task_coordinates(model, _task(names, q, "left"))
    out = evaluate(native(kinematics_kernel(model.mechanism, "euler-angles")), qe, dqe, ddqe, model.vector())
    return dict(zip(KINEMATICS_OUTPUTS, out))


def singularity_measures(model, names, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(smallest transmission angle in deg, its chain 1..6, kappa of the chains' Jacobian) per pose; NaN where a
    chain cannot close."""
    from chewbot.kinematics.conditioning import reciprocal_condition

    out = _kernel_outputs(model, names, q)
    closes = (out["reach"] <= 1).all(axis=1)
    mu = np.degrees(np.arcsin(np.clip(out["transmission"], 0.0, 1.0)))
    chain = np.argmin(mu, axis=1) + 1.0
    kappa = np.full(len(q), np.nan)
    if closes.any():
        kappa[closes] = reciprocal_condition(out["J_theta1_angles"][closes])
    nan = np.where(closes, 1.0, np.nan)
    return mu.min(axis=1) * nan, chain * nan, kappa


def force_capability(model, names, q: np.ndarray, side: str, directions: dict) -> dict[str, np.ndarray]:
    """{direction name: the largest bite force (N) the torque limits resist at each (reachable) pose at rest}."""
    from scipy.optimize import linprog

    from chewbot.compiled.kernels import evaluate, native
    from chewbot.dynamics.formulations.dalembert import REDUCED_OUTPUTS, reduced_kernel
    from chewbot.dynamics.formulations.hessian import hessian_rates
    from chewbot.kinematics.motion import solve_kinematics

    kin = solve_kinematics(model, _task(names, q, side), "euler-angles")
    qe, _, _ = kin.euler_angle_state()
    fn = native(reduced_kernel(model.mechanism, "hessian", hessian_rates))
    limit = model.limits.torque
    n_ee = qe.shape[1]
    out = {}
    for name, d in directions.items():
        terms = dict(zip(REDUCED_OUTPUTS, evaluate(fn, kin.theta, qe, np.zeros_like(qe), model.molar(side),
                                                   np.asarray(d, dtype=float), model.vector())))
        best = np.empty(len(q))
        for k in range(len(q)):  # one small LP per pose: HiGHS takes about a millisecond each
            A = np.hstack([terms["J_theta1"][k].T, terms["Q_B"][k].reshape(n_ee, 1)])
            res = linprog(np.r_[np.zeros(6), -1.0], A_eq=A, b_eq=terms["G_f"][k], bounds=[(-limit, limit)] * 6 + [(0, None)],
                          method="highs")
            best[k] = res.x[6] if res.status == 0 else np.inf if res.status == 3 else np.nan
        out[name] = best
    return out
