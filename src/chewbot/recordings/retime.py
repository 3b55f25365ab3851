"""Re-timing an imported motion within the motors' limits (``chewbot import-motion --timing limits``).

The path is the task's motion q(s) with s its own time, and the bite force F(s) travels with it (indexed by the
path, so that it is re-timed with the motion). A new timing s(t) changes only the rates: q_dot = q' s_dot,
q_ddot = q' s_ddot + q'' s_dot^2. Along the path, for the frictionless inverse dynamics (the Hessian method, the
run's default, with the target's minimum-norm distribution of the torques, Eq. 54), the torques are
tau = M_t(s) q_ddot + C-terms(q, q_dot) + gravity + bite force, and the minimum-norm distribution is a fixed
linear map of the generalised forces at each s: so tau is affine in the path acceleration u = s_ddot and in
x = s_dot^2, tau = a(s) u + b(s) x + c(s); the crank accelerations likewise, theta_ddot = theta' u + theta'' x; the
crank speeds are theta' s_dot. Coulomb friction (a sign and an abs of forces) is not of this form: the re-timing
is frictionless, as the run's default.

The coefficients are computed at the grid points (every :data:`GRID_S` of the task's time) by the run's own
kinematics and inverse dynamics, evaluated at (q, 0, q') (a + c), (q, q', q'') (b + c) and (q, 0, 0) (c), all
grid points at once. The time-optimal parametrisation is TOPP-RA (the ``toppra`` package, Pham and Pham 2018:
reachability analysis on the grid, one small LP per grid point), with the limits
abs(tau_i) <= ``limits.torque_Nm``, abs(theta_ddot_i) <= ``limits.acceleration_rad_per_s2`` as linear constraints
in (u, x), and x <= min(1, (``limits.speed_rad_per_s`` / max_i abs(theta'_i))^2): never faster than recorded
(s_dot <= 1) and within the crank speed limit. Each limit is used at :data:`MARGIN` of its value (a margin for the rounding of the run's own
kinematics). The re-timed task's samples are the grid points at their new times (not uniform: at least
:data:`GRID_S` apart, since s_dot <= 1), so the limits hold at every sample a run checks; the path acceleration is
constant between two samples. The motion starts and ends at rest (s_dot = 0).

The power limit and the bearing loads are not constraints here: the run checks them on the result.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from chewbot.dynamics.registry import inverse_dynamics
from chewbot.errors import RecordingError
from chewbot.kinematics.motion import solve_kinematics
from chewbot.kinematics.task import Task
from chewbot.model import Model

GRID_S = 0.001
MARGIN = 0.999
SEGMENT_S = 0.5


@dataclass(frozen=True)
class Retiming:
    """The re-timed task and, per segment of :data:`SEGMENT_S` of the original time, its time stretch (new
    duration over old; 1: as recorded); the original and the new duration (s)."""

    task: Task
    segments: np.ndarray  # (K, 2) start and end of each segment in the original time, s
    stretch: np.ndarray  # (K,)
    original_s: float
    duration_s: float


def _coefficients(model: Model, task: Task, rows: np.ndarray, side: str):
    """a, b, c (G, 12) of [tau (6); theta_ddot (6)] = a u + b x + c, and theta' (G, 6), at the grid rows."""
    q, d1, d2 = task.q[rows], task.dq[rows], task.ddq[rows]
    force = task.force[rows]
    zero = np.zeros_like(q)

    def evaluate(dq, ddq):
        sub = replace(task, t=task.t[rows], q=q, dq=dq, ddq=ddq, force=force)
        kin = solve_kinematics(model, sub)
        return np.hstack([inverse_dynamics(model, kin, side=side).tau, kin.ddtheta]), kin.dtheta

    A, _ = evaluate(zero, d1)
    B, theta_prime = evaluate(d1, d2)
    C, _ = evaluate(zero, zero)
    return A - C, B - C, C, theta_prime


def limit_report(model: Model, task: Task) -> list[str]:
    """Where ``task`` at its own times breaks the model's crank speed, acceleration and torque limits (the
    frictionless inverse dynamics, as :func:`retime` uses them): per limit broken, its largest value, the crank
    and the time, and the span of times over which it is broken."""
    lim = model.limits
    kin = solve_kinematics(model, task)
    tau = inverse_dynamics(model, kin, side=task.side).tau
    out = []
    for name, v, bound, unit in (("crank speed", kin.dtheta, lim.speed, "rad/s"), ("crank acceleration", kin.ddtheta, lim.acceleration, "rad/s^2"),
                                 ("torque", tau, lim.torque, "N*m")):
        over = np.abs(v) > bound
        if np.isfinite(bound) and over.any():
            i, j = np.unravel_index(int(np.argmax(np.abs(v))), v.shape)
            times = task.t[over.any(axis=1)]
            out.append(f"{name} up to {abs(v[i, j]):.4g} {unit} (crank {j + 1}, t = {task.t[i]:.4g} s) above the limit {bound:g} {unit} "
                       f"between t = {times[0]:.4g} and {times[-1]:.4g} s")
    return out


def retime(model: Model, task: Task) -> Retiming:
    """The time-optimal re-timing of ``task`` within ``model``'s limits (module docstring): its samples every
    :data:`GRID_S` of its own time are the grid, each at its new time."""
    import toppra
    from toppra.constraint import LinearConstraint

    lim = model.limits
    if not np.isfinite([lim.speed, lim.acceleration, lim.torque]).all():
        raise RecordingError(f"{model.source}: --timing limits needs limits.torque_Nm, limits.speed_rad_per_s and "
                             "limits.acceleration_rad_per_s2 (the model leaves one unbounded)")
    step = max(1, int(round(GRID_S / float(np.median(np.diff(task.t))))))
    rows = np.unique(np.r_[np.arange(0, task.n, step), task.n - 1])
    s = task.t[rows]
    a, b, c, theta_prime = _coefficients(model, task, rows, task.side)
    bound = MARGIN * np.r_[np.full(6, lim.torque), np.full(6, lim.acceleration)]
    speed = np.abs(theta_prime).max(axis=1)
    with np.errstate(divide="ignore"):
        x_max = np.minimum(1.0, (MARGIN * lim.speed / speed) ** 2)
    if (np.abs(c) > bound).any():
        i = int(np.argmax((np.abs(c) / bound).max(axis=1)))
        raise RecordingError(f"at t = {s[i]:.4g} s the task's torques at rest ({np.abs(c[i]).max():.3g} N*m: gravity and the "
                             "bite force) exceed the torque limit: no timing can hold it")

    class Limits(LinearConstraint):
        """[tau; theta_ddot] = a u + b x + c within +-bound, x within [0, x_max] (precomputed on the grid)."""

        def __init__(self):
            super().__init__()
            self.identical = True

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            F = np.vstack([np.eye(12), -np.eye(12)])
            g = np.r_[bound, bound]
            return a, b, c, F, g, None, np.column_stack([np.zeros_like(x_max), x_max])

    path = toppra.SplineInterpolator(s, task.q[rows])
    algorithm = toppra.algorithm.TOPPRA([Limits()], path, gridpoints=s, solver_wrapper="seidel")
    algorithm.compute_parameterization(0.0, 0.0)
    data = algorithm.problem_data
    if data.sd_vec is None:
        raise RecordingError(f"--timing limits: no timing of the task holds the limits (TOPP-RA: {data.return_code})")
    sd = np.maximum(np.asarray(data.sd_vec, dtype=float), 0.0)
    ds = np.diff(s)
    with np.errstate(divide="ignore"):
        dt = 2 * ds / (sd[:-1] + sd[1:])
    t_grid = np.r_[0.0, np.cumsum(dt)]
    u = (sd[1:] ** 2 - sd[:-1] ** 2) / (2 * ds)  # constant path acceleration between grid points
    # the samples are the grid points at their new times (no longer uniform): there the limits hold as TOPP-RA
    # imposed them; between grid points the path acceleration u is constant
    u = np.r_[u, 0.0]
    q1, q2 = task.dq[rows], task.ddq[rows]
    new = replace(task, t=t_grid, q=task.q[rows], dq=q1 * sd[:, None], ddq=q1 * u[:, None] + q2 * sd[:, None] ** 2,
                  force=task.force[rows], meta={**task.meta, "timing": "limits"})
    edges = np.r_[np.arange(s[0], s[-1], SEGMENT_S), s[-1]]
    t_at = np.interp(edges, s, t_grid)
    return Retiming(new, np.column_stack([edges[:-1], edges[1:]]), np.diff(t_at) / np.diff(edges), float(s[-1] - s[0]),
                    float(t_grid[-1]))
