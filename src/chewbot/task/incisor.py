"""A task from a path of the lower incisor: the mandible's coordinates that make point I follow it (seed 001, Sect. 5.1).

Given the position p_I, velocity v_I and acceleration a_I of the incisor point I (``model.incisor``) in {S},
three problems are solved at every sample, as in seed 001 (Eqs. 55-60), each by sequential quadratic
programming (CasADi ``sqpmethod`` with the ``qrqp`` QP solver, exact derivatives by automatic differentiation):

* displacement: min abs(f_D)^2, f_D = I(q_EE) - p_I, subject to the sockets' x/y bounds on both condyles
  (and abs(e) = 1 for Euler parameters); warm-started from the previous sample's solution;
* velocity: min abs(f_V)^2, f_V = M_I q_EE_dot - v_I, M_I = dI/dq_EE;
* acceleration: min abs(f_A)^2, f_A = M_I q_EE_ddot + M_I_dot q_EE_dot - a_I;

the velocity and acceleration constraints being the time derivatives of the position-level ones. The HKPs'
parasitic motions are built into I(q_EE) (:mod:`chewbot.kinematics.symbolic`).

Redundancy: the target has 4 DOF and the incisor gives 3 equations, so a path of I alone does not fix the
motion (seed 001 notes infinitely many solutions). Here one coordinate is pinned: ``pin`` (X, Y, alpha or beta)
follows a given trajectory (by default held at 0: alpha = 0, no roll), added as an equality constraint at all
three levels. The problems are then square and their solution unique near the previous sample's, and the
rates are the exact time derivatives of the positions (a regularisation toward the previous sample would make
the velocity problem's choice differ from the derivative of the displacement problem's). A motion generated
from known coordinates is recovered exactly when its own trajectory of the pinned coordinate is given.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from chewbot.compiled.cache import cached_graph, folded
from chewbot.compiled.kernels import evaluate
from chewbot.errors import KinematicsError, TaskError
from chewbot.kinematics.motion import euler_angle_motion
from chewbot.kinematics.options import check_orientation
from chewbot.kinematics.symbolic import COORDINATES, symbolic
from chewbot.model import Model
from chewbot.table import Table
from chewbot.kinematics.task import TARGET_COORDS, Task
from chewbot.units import factor

PINNABLE = ("X", "Y", "alpha", "beta")
LEVELS = ("displacement", "velocity", "acceleration")
# Residuals are scaled to millimetres and lengths to millimetres in the solver, so that its tolerances are
# meaningful for a mandible whose motions are millimetres and tenths of radians.
_MM = factor("mm")
# A pinned coordinate or abs(e) = 1 violated by more than this after a solve means the solver failed.
CONSTRAINT_TOLERANCE = 1e-9
_SQP = {
    "qpsol": "qrqp",
    "qpsol_options": {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False},
    "print_time": False, "print_header": False, "print_iteration": False, "print_status": False,
    "error_on_fail": False,
    "tol_pr": 1e-14, "tol_du": 1e-14, "max_iter": 50,
}


@dataclass(frozen=True, eq=False)
class IncisorTracking:
    """The result of :func:`track_incisor` (arrays samples first).

    ``task``: the motion in XYZ Euler angles (X, Y, alpha, beta), ready for the kinematics; ``q``, ``dq``, ``ddq``:
    q_EE of the target in ``orientation`` (``coords``); ``f_D`` (m), ``f_V`` (m/s), ``f_A`` (m/s^2): the
    residuals of the three problems, (N, 3) each; ``pin``: the coordinate that was pinned.
    """

    task: Task
    orientation: str
    coords: tuple[str, ...]
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    f_D: np.ndarray
    f_V: np.ndarray
    f_A: np.ndarray
    pin: str

    def tables(self) -> tuple[Table, Table]:
        """The task (t, X, Y, alpha, beta, their rates, Fx, Fy, Fz; SI, as ``chewbot run --task`` reads it) and
        the residuals (t, f_D, f_V, f_A per axis) as tables."""
        from chewbot.task.csvio import task_table

        task, res = task_table(self.task), Table()
        res.add("t", self.task.t, "s")
        for label, arr, unit in (("f_D", self.f_D, "m"), ("f_V", self.f_V, "m/s"), ("f_A", self.f_A, "m/s^2")):
            res.add_block([f"{label}_{c}" for c in "xyz"], arr, unit)
        return task, res


def _levels(expr: ca.SX, q: ca.SX, dq: ca.SX, ddq: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """An expression of q and its first and second time derivatives (exact chain rule)."""
    d1 = ca.jtimes(expr, q, dq)
    return expr, d1, ca.jtimes(expr, q, ddq) + ca.jtimes(d1, q, dq)


def _pinned_sx(s, name: str) -> ca.SX:
    """The coordinate ``name`` of the pose, as a function of q_EE in either orientation."""
    if name in ("X", "Y"):
        return s.q[PINNABLE.index(name)]
    if name == "alpha":
        return ca.atan2(-s.R[1, 2], s.R[2, 2])
    return ca.atan2(s.R[0, 2], ca.sqrt(s.R[0, 0] ** 2 + s.R[0, 1] ** 2))


def _incisor_function(model: Model, orientation: str) -> ca.Function:
    """(q, dq, ddq) -> position, velocity and acceleration of the incisor point I in {S}."""

    def build():
        s = symbolic(folded(model), orientation)
        levels = _levels(s.point(model.incisor), s.q, s.dq, s.ddq)
        return ca.Function("incisor", [s.q, s.dq, s.ddq], list(levels), ["q", "dq", "ddq"], ["I", "dI", "ddI"])

    return cached_graph(folded(model), ("incisor", orientation), build)


def _problems(model: Model, orientation: str, pin: str):
    """(constraints, solvers, scale): the equality constraints at three levels as a function of (q, dq, ddq),
    the displacement, velocity and acceleration NLP solvers, and the scale of their variables."""

    def build():
        s = symbolic(folded(model), orientation)
        incisor = _levels(s.point(model.incisor), s.q, s.dq, s.ddq)
        equal = [_levels(_pinned_sx(s, pin), s.q, s.dq, s.ddq)]
        if s.unit is not None:
            equal.append(_levels(s.unit, s.q, s.dq, s.ddq))
        constraints = ca.Function("incisor_constraints", [s.q, s.dq, s.ddq], [ca.vertcat(*e) for e in zip(*equal)],
                                  ["q", "dq", "ddq"], ["c", "dc", "ddc"])
        # solver variables are q_EE (and rates) with lengths in mm
        scale = ca.DM([_MM if c in ("X", "Y") else 1.0 for c in s.coords])
        sockets = ca.vertcat(*(s.point(T)[:2] for T in (model.hkp.T_L, model.hkp.T_R)))
        solvers = []
        for level, var in enumerate((s.q, s.dq, s.ddq)):
            z = ca.SX.sym("z", var.numel())
            target, ref = ca.SX.sym("target", 3), ca.SX.sym("ref", 1)

            def scaled(e, var=var, z=z):
                return ca.substitute(e, var, scale * z)

            g = [scaled(equal[0][level] - ref)] + [scaled(e[level]) for e in equal[1:]]
            if level == 0:
                g.append(scaled(sockets))
            nlp = {"x": z, "p": ca.vertcat(*[s.q, s.dq][:level], target, ref),
                   "f": ca.sumsqr(scaled(incisor[level] - target) / _MM), "g": ca.vertcat(*g)}
            solvers.append(ca.nlpsol(f"incisor_{LEVELS[level]}", "sqpmethod", nlp, _SQP))
        return constraints, solvers, np.asarray(scale).ravel()

    return cached_graph(folded(model), ("incisor", orientation, pin), build)


def incisor_path(model: Model, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, orientation: str = "euler-angles"):
    """Position (m), velocity (m/s) and acceleration (m/s^2) of the incisor point I in {S} along a motion of the target.

    ``q``, ``dq``, ``ddq`` (N, n): q_EE of the target in ``orientation``. Returns three (N, 3) arrays.
    """
    _check_model(model)
    check_orientation(orientation)
    return tuple(evaluate(_incisor_function(model, orientation), q, dq, ddq))


def _check_model(model: Model) -> None:
    if not model.has_hkp:
        raise TaskError(f"model {model.name!r}: incisor tracking resolves the motion through the target's sockets; track "
                        f"on a target model and lift the task with chewbot.task.default.lift_to_full for the 6RSS")


def track_incisor(
    model: Model,
    t: np.ndarray,
    p: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    orientation: str = "euler-angles",
    pin: str = "alpha",
    pinned: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    force: np.ndarray | None = None,
    side: str = "left",
    max_residual: float | None = 1e-6,
    name: str = "incisor",
) -> IncisorTracking:
    """The target's motion that makes the incisor follow ``p``, ``v``, ``a`` ((N, 3), m, m/s, m/s^2, in {S}) at times ``t``.

    ``pin``: the coordinate that resolves the redundancy (X, Y, alpha or beta); ``pinned``: its trajectory
    (values, rates, accelerations, (N,) each, SI), default zero. ``force``: bite force (N, 3), default zero.
    Raises :class:`KinematicsError` naming the sample where abs(f_D) exceeds ``max_residual`` (m; None: never)
    or where a solve violates its equality constraints.
    """
    _check_model(model)
    check_orientation(orientation)
    if pin not in PINNABLE:
        raise TaskError(f"pin must be one of {', '.join(PINNABLE)}, not {pin!r}")
    t = np.asarray(t, dtype=float)
    n = t.shape[0]
    p, v, a = (np.asarray(x, dtype=float) for x in (p, v, a))
    for label, x in (("p", p), ("v", v), ("a", a)):
        if x.shape != (n, 3):
            raise TaskError(f"incisor {label} has shape {x.shape}, expected {(n, 3)}")
    refs = [np.zeros(n) for _ in range(3)] if pinned is None else [np.asarray(x, dtype=float).reshape(n) for x in pinned]
    constraints, (displacement, velocity, acceleration), scale = _problems(model, orientation, pin)
    coords = COORDINATES[("target", orientation)]
    h = model.hkp

    lbg = np.concatenate([np.zeros(constraints.numel_out(0)), [h.x_range[0], h.y_left[0], h.x_range[0], h.y_right[0]]])
    ubg = np.concatenate([np.zeros(constraints.numel_out(0)), [h.x_range[1], h.y_left[1], h.x_range[1], h.y_right[1]]])
    z = np.zeros(len(coords))
    if orientation == "euler-parameters":
        z[coords.index("e0")] = 1.0
    Z = np.empty((n, len(coords)))
    # sequential by nature: each sample starts from the previous solution (seed 001), so the branch is kept
    for k in range(n):
        z = np.asarray(displacement(x0=z, p=np.r_[p[k], refs[0][k]], lbg=lbg, ubg=ubg)["x"]).ravel()
        Z[k] = z
    q = Z * scale
    # the velocity and acceleration problems are independent per sample: solved all at once
    zero = np.zeros((len(coords), n))
    dq = _solve_mapped(velocity, n, zero, np.vstack([q.T, v.T, refs[1]])) * scale
    ddq = _solve_mapped(acceleration, n, zero, np.vstack([q.T, dq.T, a.T, refs[2]])) * scale

    I, dI, ddI = incisor_path(model, q, dq, ddq, orientation)
    f_D, f_V, f_A = I - p, dI - v, ddI - a
    _check_solution(t, f_D, max_residual, evaluate(constraints, q, dq, ddq), refs)
    X = euler_angle_motion(model, orientation, q, dq, ddq, t)
    task = Task(name=name, t=t, coords=TARGET_COORDS, q=X[0], dq=X[1], ddq=X[2],
                force=np.zeros((n, 3)) if force is None else force, side=side, source="incisor tracking",
                meta={"generator": "incisor", "orientation": orientation, "pin": pin,
                      "max_abs_f_D_m": float(np.abs(f_D).max()), "max_abs_f_V_m_per_s": float(np.abs(f_V).max()),
                      "max_abs_f_A_m_per_s2": float(np.abs(f_A).max())})
    return IncisorTracking(task, orientation, coords, q, dq, ddq, f_D, f_V, f_A, pin)


def _solve_mapped(solver: ca.Function, n: int, x0: np.ndarray, params: np.ndarray) -> np.ndarray:
    m = solver.nnz_out("g")
    mapped = solver.map(n) if n > 1 else solver
    return np.asarray(mapped(x0=x0, p=params, lbg=np.zeros((m, n)), ubg=np.zeros((m, n)))["x"]).T


def _check_solution(t, f_D, max_residual, constraints, refs) -> None:
    for level, (c, ref) in enumerate(zip(constraints, refs)):
        c = c.copy()
        c[:, 0] -= ref
        bad = np.flatnonzero(np.abs(c).max(axis=1) > CONSTRAINT_TOLERANCE)
        if bad.size:
            i = int(bad[0])
            raise KinematicsError(f"incisor tracking: the {LEVELS[level]} problem did not "
                                  f"satisfy its constraints (violation {np.abs(c[i]).max():.3g})", sample=i, time=float(t[i]))
    if max_residual is not None:
        err = np.linalg.norm(f_D, axis=1)
        bad = np.flatnonzero(err > max_residual)
        if bad.size:
            i = int(bad[0])
            raise KinematicsError(f"incisor tracking: the incisor point cannot be reached within the sockets (abs(f_D) = "
                                  f"{err[i]:.3g} m > {max_residual:g} m; {bad.size} sample(s)) with the pinned coordinate's "
                                  "trajectory; give the one the motion has (a column of the path file, such as "
                                  "alpha[deg], or pinned= from Python) or pin another coordinate", sample=i, time=float(t[i]))
