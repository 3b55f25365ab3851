"""Excitation tasks: a motion designed for identification, a periodic Fourier series in the task coordinates.

Swevers, Ganseman, Tukel, De Schutter and Van Brussel (1997), "Optimal robot excitation and identification", IEEE
Trans. Robot. Autom. 13(5) 730-740: each independent coordinate (X, Y, alpha, beta of the target; the six of the
6RSS) is a finite Fourier series of one fundamental period T,

    q_j(t) = sum_l a_jl sin(l w t) + b_jl (cos(l w t) - 1),   w = 2 pi / T,  l = 1 .. L,

so that q_j(0) = 0 (home); sum_l l a_jl = 0 and sum_l l^2 b_jl = 0 make the rates and accelerations zero at t = 0
as well. The series is periodic: every whole period starts and ends at rest at home, and a task of several periods
repeats it (the repetitions average the noise; the identification sees the same information each period).

Its coefficients maximise the information of the identification's regressor (:mod:`chewbot.identification.
regressor`): the log-determinant of sum_k W_k' W_k over a period (D-optimality), W_k the torques' derivatives
with respect to the identified parameters x at sample k, each column scaled by its parameter's reference magnitude
(:func:`chewbot.identification.identifier.references`) and the normal forces projected out as the identification
eliminates them (W_k = (1 - P_k) d tau / d x, P_k the projector onto the columns d tau / d N of the two HKP normal
forces). The regressor is evaluated where the log's torques are the model's own: the normal forces of the
friction-free minimum-norm torques, the torques of the model with its friction at them. Subject to, at every
sample of the period: each crank's speed, acceleration and torque within :data:`MARGIN` of the model's limits,
the condyles inside their sockets (:data:`SOCKET_MARGIN_M` from the walls), every chain within reach
(:data:`MAX_REACH`) and its transmission angle above :data:`MIN_TRANSMISSION_DEG`. SciPy's SLSQP solves it with
the exact gradients of the objective and the constraints: CasADi's derivatives of the regressor, the torques and
the kinematics with respect to the motion of a sample, chained with the series' linear map
(:func:`excitation_kernel`).

The condition number reported is the identification's own: that of ``chewbot identify``'s Jacobian (unit-norm
columns) on the noise-free log of the task, the model's torques (:func:`identification_condition`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from chewbot.analysis.checks import NEAR_SINGULAR_DEG
from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.formulations.newton_euler import coefficients_kernel, forces_sx, n_unknowns
from chewbot.errors import ChewbotError
from chewbot.identification.parameters import N_X
from chewbot.identification.regressor import ORIENTATION, with_x
from chewbot.kinematics.functions import kinematics_kernel
from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task
from chewbot.model import Model
from chewbot.model.symbolic import SymbolicModel, c_name
from chewbot.model.vector import N_P
from chewbot.progress import SILENT, Progress
from chewbot.units import factor

HARMONICS = 5  # L: the highest frequency is L / T
PERIOD_S = 2.0  # T: harmonics at 0.5, 1, ... 2.5 Hz, the chewing band's
DESIGN_RATE_HZ = 100.0  # samples of the period the design constrains and evaluates (the task is written at --rate)
MARGIN = 0.8  # the design keeps each crank's speed, acceleration and torque within this fraction of its limit
SOCKET_MARGIN_M = 0.5e-3  # ... and each condyle this far from its socket's walls
MAX_REACH = 0.95  # ... and each chain's |C| / sqrt(A^2 + B^2) below this (1: the coupler stretched to the crank tip)
MIN_TRANSMISSION_DEG = NEAR_SINGULAR_DEG + 2.0  # ... and each transmission angle above this
START_USE = 0.5  # the start: the seed's random coefficients scaled until the constraints use half of what they allow
MAX_ITERATIONS = 200
# The motion's unit of each coordinate for the optimiser (m for lengths, rad for angles): 1 mm and 1 deg.
COORDINATE_SCALE = {**dict.fromkeys(("X", "Y", "Z"), factor("mm")),
                    **dict.fromkeys(("alpha", "beta", "gamma"), factor("deg"))}
# The kernel's outputs that the constraints read (per sample) and the regressor: named, each with its Jacobian
# with respect to the sample's motion m = (q, q_dot, q_ddot), "d_" + name.
QUANTITIES = ("dtheta", "ddtheta", "tau", "T", "reach", "transmission")


def coordinates(model: Model) -> tuple[str, ...]:
    """The independent coordinates the series moves, named as in task files."""
    return TARGET_COORDS if model.has_hkp else FULL_COORDS


def excitation_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (q, q_dot, q_ddot, x, p) -> the constraints' quantities of :data:`QUANTITIES` (crank rates
    and accelerations, the torques, the condyles' x and y in {S} (T_L then T_R), each chain's reach ratio and
    sine of its transmission angle), ``W`` (6 x N_X) the regressor with the normal forces projected out, and the
    Jacobian of each with respect to the motion (q, q_dot, q_ddot) of the sample (``d_`` + name; ``d_W`` of
    vec(W)). q in Euler angles; x the identified parameters in place in p (:func:`chewbot.identification.regressor.
    with_x`): the model's at the design."""
    name = f"excitation_{c_name(mechanism)}"

    def build(params):
        n = 4 if mechanism == "target" else 6
        nN = n_unknowns(mechanism)
        q, dq, ddq = ca.SX.sym("q", n), ca.SX.sym("dq", n), ca.SX.sym("ddq", n)
        p, x = ca.SX.sym("p", N_P), ca.SX.sym("x", N_X)
        m = SymbolicModel(mechanism, with_x(p, x))
        kin = kinematics_kernel(mechanism, ORIENTATION).graph()(q=q, dq=dq, ddq=ddq, p=m.p)
        D = coefficients_kernel(mechanism, ORIENTATION).graph()(kin["theta"], q, dq, ddq, ca.SX.zeros(3), ca.SX.zeros(3), m.p)[0]
        N = ca.SX.sym("N", nN)
        free_tau = forces_sx(m, D, N, 0.0)["tau"]  # affine in N
        if nN:
            B = ca.jacobian(free_tau, N)
            a = ca.substitute(free_tau, N, ca.DM.zeros(nN))
            N_star = -ca.solve(ca.mtimes(B.T, B), ca.mtimes(B.T, a))
        else:
            N_star = ca.SX(0, 1)
        r = forces_sx(m, D, N, 1.0)["tau"]
        W = ca.jacobian(r, x)
        if nN:
            dr_dN = ca.jacobian(r, N)
            W = W - ca.mtimes(dr_dN, ca.solve(ca.mtimes(dr_dN.T, dr_dN), ca.mtimes(dr_dN.T, W)))
        outs = {"dtheta": kin["dtheta"], "ddtheta": kin["ddtheta"], "tau": r,
                "T": ca.vertcat(kin["T_L"][0:2], kin["T_R"][0:2]) if nN else ca.SX(0, 1),
                "reach": kin["reach"], "transmission": kin["transmission"], "W": ca.vec(W)}
        outs = {k: ca.substitute(v, N, N_star) for k, v in outs.items()}
        motion = ca.vertcat(q, dq, ddq)
        names, values = [], []
        for key, value in outs.items():
            names += [key, "d_" + key]
            values += [value, ca.jacobian(value, motion)]
        return ca.Function(name, [q, dq, ddq, x, p], [ca.densify(v) for v in values], ["q", "dq", "ddq", "x", "p"], names,
                           {"cse": True})

    return KernelSpec(name, build, (mechanism, "excitation"), mechanism)


@dataclass(frozen=True)
class Series:
    """A Fourier series of period ``period`` (s) with ``harmonics`` harmonics per coordinate: ``a``, ``b`` (dof, L)
    in SI (m, rad) as in the module docstring."""

    period: float
    a: np.ndarray
    b: np.ndarray

    @property
    def harmonics(self) -> int:
        return self.a.shape[1]

    def at(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, q_dot, q_ddot (n, dof) at times ``t`` (n,): exact derivatives of the series."""
        B = basis(np.asarray(t, float), self.period, self.harmonics)
        c = np.hstack([self.a, self.b]).T  # (2L, dof)
        return tuple(Bk @ c for Bk in B)


def basis(t: np.ndarray, period: float, harmonics: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The series' basis at times t and its first two derivatives, each (n, 2L): the columns multiply a_1..a_L then
    b_1..b_L."""
    w = 2 * np.pi / period
    lw = w * np.arange(1, harmonics + 1)
    s, c = np.sin(np.outer(t, lw)), np.cos(np.outer(t, lw))
    return (np.hstack([s, c - 1]), np.hstack([lw * c, -lw * s]), np.hstack([-lw**2 * s, -lw**2 * c]))


def rest_constraints(harmonics: int) -> np.ndarray:
    """(2L, 2L - 2): an orthonormal basis of the coefficients (a, b) whose series starts at rest (q_dot(0) =
    q_ddot(0) = 0; q(0) = 0 by construction)."""
    from scipy.linalg import null_space

    l = np.arange(1, harmonics + 1, dtype=float)
    A = np.vstack([np.concatenate([l, 0 * l]), np.concatenate([0 * l, l**2])])
    return null_space(A)


@dataclass
class Design:
    """The result of :func:`design`: the ``series``, the information criterion at the start and at the design
    (``log_det``: log-determinant of the scaled information matrix per sample of the period), the identification's
    condition number (:func:`identification_condition`, filled in by :func:`design`), which constraints bind, and
    the solver's report."""

    series: Series
    log_det_start: float
    log_det: float
    condition: float
    binding: dict
    solver: dict
    parameters: list[str] = field(default_factory=list)
    seed: int = 0
    side: str = "left"

    def task(self, model: Model, duration: float, rate: float, name: str = "excitation") -> Task:
        """The task of ``duration`` (whole periods; at least one) sampled at ``rate`` Hz, no bite force."""
        periods = periods_of(duration, self.series.period)
        n = int(round(periods * self.series.period * rate)) + 1
        t = np.arange(n) / rate
        q, dq, ddq = self.series.at(t)
        return Task(name=name, t=t, coords=coordinates(model), q=q, dq=dq, ddq=ddq, force=np.zeros((n, 3)), side=self.side,
                    source=name, meta={"excitation": self.record()})

    def record(self) -> dict:
        """What the sidecar of the task says about the design (SI)."""
        return {"method": "Fourier series in the task coordinates (Swevers et al. 1997), D-optimal for chewbot "
                          "identify's regressor under the limits", "period_s": self.series.period,
                "harmonics": self.series.harmonics, "seed": self.seed, "side": self.side,
                "identification_condition_number": self.condition, "log_det_start": self.log_det_start,
                "log_det": self.log_det, "parameters": self.parameters, "binding_constraints": self.binding,
                "margin": MARGIN, "solver": self.solver,
                "coefficients": {"a": self.series.a.tolist(), "b": self.series.b.tolist(),
                                 "units": "m for X, Y, Z; rad for alpha, beta, gamma"}}


def periods_of(duration: float, period: float) -> int:
    """Whole periods in ``duration`` (the nearest number, at least one)."""
    return max(1, int(round(duration / period)))


class DesignProblem:
    """The design's objective and constraints as functions of the scaled coefficients y (with their gradients), on
    the grid of one period."""

    def __init__(self, model: Model, estimated: np.ndarray, ref: np.ndarray):
        from chewbot.identification.parameters import x_of

        self.model = model
        self.dof = model.dof
        self.L = HARMONICS
        self.Nz = rest_constraints(self.L)  # (2L, k)
        k = self.Nz.shape[1]
        self.t = np.arange(int(round(PERIOD_S * DESIGN_RATE_HZ))) / DESIGN_RATE_HZ
        B = basis(self.t, PERIOD_S, self.L)
        self.Phi = [Bk @ self.Nz for Bk in B]  # (n, k) each: q, dq, ddq of one coordinate per unit z
        self.scale = np.array([COORDINATE_SCALE[c] for c in coordinates(model)])
        self.size = self.dof * k
        self.k = k
        self.fn = native(excitation_kernel(model.mechanism))
        self.x0, self.p = x_of(model), model.vector()
        self.estimated, self.ref = estimated, ref
        self.limits = model.limits
        self._cache: tuple[bytes, dict] | None = None

    def series(self, y: np.ndarray) -> Series:
        z = y.reshape(self.dof, self.k) * self.scale[:, None]
        c = z @ self.Nz.T  # (dof, 2L)
        return Series(PERIOD_S, c[:, : self.L], c[:, self.L:])

    def evaluate(self, y: np.ndarray) -> dict:
        key = y.tobytes()
        if self._cache is None or self._cache[0] != key:
            z = y.reshape(self.dof, self.k) * self.scale[:, None]
            q, dq, ddq = (P @ z.T for P in self.Phi)
            out = dict(zip(self.fn.name_out(), evaluate(self.fn, q, dq, ddq, self.x0, self.p)))
            self._cache = (key, out)
        return self._cache[1]

    def chain(self, d: np.ndarray) -> np.ndarray:
        """d (n, m, 3 dof): derivatives of m quantities per sample with respect to the sample's motion -> (n, m,
        size): with respect to y."""
        n = d.shape[0]
        d = d.reshape(n, d.shape[1], 3, self.dof)
        out = np.einsum("nmoj,onk->nmjk", d, np.stack(self.Phi))  # (n, m, dof, k)
        return (out * self.scale[None, None, :, None]).reshape(n, d.shape[1], self.size)

    def information(self, y: np.ndarray, gradient: bool = False):
        """log det of the scaled information matrix per sample, and its gradient in y."""
        out = self.evaluate(y)
        n = self.t.size
        W = out["W"].reshape(n, N_X, 6).transpose(0, 2, 1)[:, :, self.estimated] * self.ref[self.estimated]  # (n, 6, e)
        A = np.einsum("nij,nik->jk", W, W) / n
        if not np.isfinite(A).all():  # a trial point out of reach (the solver's step): no information there
            return (-np.inf, np.zeros(self.size)) if gradient else (-np.inf, A)
        sign, logdet = np.linalg.slogdet(A)
        if sign <= 0:
            logdet = -np.inf
        if not gradient:
            return logdet, A
        Ainv = np.linalg.inv(A)
        dW = out["d_W"].reshape(n, N_X, 6, -1).transpose(0, 2, 1, 3)[:, :, self.estimated, :] \
            * self.ref[self.estimated][None, None, :, None]  # (n, 6, e, 3 dof)
        G = 2 * np.einsum("jk,nik,nijm->nm", Ainv, W, dW) / n  # d logdet / d motion of sample n
        grad = self.chain(G[:, None, :])[:, 0, :].sum(axis=0)
        return logdet, grad

    def constraints(self, y: np.ndarray, jacobian: bool = False):
        """The constraints g(y) >= 0 (scaled to about 1 at their bound's distance) and their Jacobian."""
        out = self.evaluate(y)
        values, grads = [], []
        for name, kind, bound in self.specs():
            v, d = out[name], out["d_" + name]
            n, m = v.shape
            d = d.reshape(n, m, -1)
            if kind == "abs":  # (bound^2 - v^2) / bound^2 >= 0
                values.append((1 - (v / bound) ** 2).ravel())
                if jacobian:
                    grads.append((self.chain(-2 * v[:, :, None] / bound**2 * d)).reshape(n * m, -1))
            elif kind == "below":
                values.append((bound - v).ravel())
                if jacobian:
                    grads.append(-self.chain(d).reshape(n * m, -1))
            elif kind == "above":
                values.append((v - bound).ravel())
                if jacobian:
                    grads.append(self.chain(d).reshape(n * m, -1))
            else:  # "within": bound (m, 2) low and high per quantity, in m: (v - lo)(hi - v) / half-width^2 >= 0
                lo, hi = bound[:, 0], bound[:, 1]
                half = (hi - lo) / 2
                values.append((((v - lo) * (hi - v)) / half**2).ravel())
                if jacobian:
                    grads.append(self.chain(((hi + lo - 2 * v) / half**2)[:, :, None] * d).reshape(n * m, -1))
        g = np.concatenate(values)
        return (g, np.vstack(grads)) if jacobian else g

    def specs(self):
        """(kernel output, kind, bound) of each constraint: limits the model does not give are not constraints."""
        lim = self.limits
        out = []
        for name, limit in (("dtheta", lim.speed), ("ddtheta", lim.acceleration), ("tau", lim.torque)):
            if np.isfinite(limit):
                out.append((name, "abs", MARGIN * limit))
        if self.model.has_hkp:
            h = self.model.hkp
            walls = [h.x_range, h.y_left, h.x_range, h.y_right]
            out.append(("T", "within", np.array([[w[0] + SOCKET_MARGIN_M, w[1] - SOCKET_MARGIN_M] for w in walls])))
        out.append(("reach", "below", MAX_REACH))
        out.append(("transmission", "above", np.sin(np.radians(MIN_TRANSMISSION_DEG))))
        return out

    def usage(self, y: np.ndarray) -> float:
        """The largest fraction of its design bound that a speed, acceleration or torque reaches."""
        out = self.evaluate(y)
        return max((float(np.abs(out[name]).max() / bound) for name, kind, bound in self.specs() if kind == "abs"),
                   default=0.0)

    def binding(self, y: np.ndarray) -> dict:
        """Per constraint kind, the smallest slack (1 - used fraction for the limits)."""
        out = self.evaluate(y)
        report = {}
        for name, kind, bound in self.specs():
            v = out[name]
            if kind == "abs":
                report[name] = {"largest_abs": float(np.abs(v).max()), "limit_used": float(np.abs(v).max() / (bound / MARGIN))}
            elif kind == "within":
                report[name] = {"closest_to_wall_m": float(np.min(np.minimum(v - bound[:, 0], bound[:, 1] - v)) + SOCKET_MARGIN_M)}
            else:
                report[name] = {"worst": float(v.max() if kind == "below" else v.min()), "bound": float(bound)}
        return report


def design(model: Model, seed: int = 0, side: str = "left", progress: Progress = SILENT, check=None) -> Design:
    """The excitation's Fourier series for ``model`` (module docstring), from the start the ``seed`` draws (``side``
    right: its mirror image in Y and alpha, the robot being symmetric). ``progress(message, stage=None)`` is told
    the solver's iterations; ``check()`` is called at each evaluation and raises to stop."""
    from scipy.optimize import minimize

    from chewbot.identification.identifier import estimated_by_default, references
    from chewbot.identification.parameters import NAMES, x_of

    estimated = estimated_by_default(model)
    problem = DesignProblem(model, estimated, references(model, x_of(model)))
    rng = np.random.default_rng(seed)
    y0 = rng.standard_normal(problem.size)
    if side == "right":  # the mirror image: Y and alpha change sign
        names = coordinates(model)
        y0 = y0.reshape(problem.dof, problem.k)
        for j, c in enumerate(names):
            if c in ("Y", "alpha", "gamma"):
                y0[j] *= -1
        y0 = y0.ravel()
    y0 = _feasible_start(problem, y0)
    start_logdet = problem.information(y0)[0]
    state = {"it": 0}

    def objective(y):
        if check is not None:
            check()
        value, grad = problem.information(y, gradient=True)
        return -value, -grad

    def callback(y):
        state["it"] += 1
        progress(f"design: iteration {state['it']}, log det {problem.information(y)[0]:.5g}")

    progress("design of the excitation", stage="fit")
    result = minimize(objective, y0, jac=True, method="SLSQP", callback=callback,
                      constraints=[{"type": "ineq", "fun": problem.constraints,
                                    "jac": lambda y: problem.constraints(y, jacobian=True)[1]}],
                      options={"maxiter": MAX_ITERATIONS, "ftol": 1e-8})
    y = result.x
    if not (problem.constraints(y) >= -1e-6).all():  # the solver's last point outside: the start is
        y = y0
    logdet = problem.information(y)[0]
    return Design(problem.series(y), float(start_logdet), float(logdet), float("nan"), problem.binding(y),
                  {"method": "SLSQP", "iterations": int(result.nit), "message": str(result.message),
                   "success": bool(result.success)},
                  [NAMES[j] for j in np.flatnonzero(estimated)], seed, side)


def _feasible_start(problem: DesignProblem, y: np.ndarray) -> np.ndarray:
    """``y`` scaled so that the speeds, accelerations and torques use at most :data:`START_USE` of what the design
    allows them, every other constraint holding (bisection on the scale, the motion growing from rest at home)."""
    def fits(s):
        return (problem.constraints(s * y) >= 0).all() and problem.usage(s * y) <= START_USE

    lo, hi = 0.0, 1.0
    while fits(hi) and hi < 1e6:
        lo, hi = hi, 2 * hi
    for _ in range(40):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    if lo == 0.0:
        raise ChewbotError(f"{problem.model.name}: no motion around the home pose satisfies the excitation's "
                           "constraints (is the home pose inside the limits?)")
    return lo * y


def identification_condition(model: Model, task: Task) -> float:
    """The condition number ``chewbot identify`` reports at the start (unit-norm columns of the parameters it
    estimates by default, the samples where every crank turns) on the noise-free log of ``task``: the model's
    Newton-Euler torques with friction and the minimum-torque distribution, the exact rates; the log goes the
    identification's own way (:func:`chewbot.identification.motion.log_motion`)."""
    from chewbot.dynamics.registry import inverse_dynamics
    from chewbot.identification.estimate import ReducedProblem, condition_number
    from chewbot.identification.identifier import estimated_by_default, references
    from chewbot.identification.log import RobotLog
    from chewbot.identification.motion import log_motion
    from chewbot.identification.parameters import x_of
    from chewbot.kinematics.motion import solve_kinematics

    kin = solve_kinematics(model, task, ORIENTATION)
    tau = inverse_dynamics(model, kin, "newton-euler", friction=True).tau
    log = RobotLog(task.name, kin.t, kin.theta, kin.dtheta, kin.ddtheta, tau, np.zeros((kin.n, 3)), np.arange(kin.n) + 2)
    motion = log_motion(model, log, task.side)
    x0 = x_of(model)
    start = ReducedProblem(model, motion.kin, tau, motion.moving()).evaluate_at(x0, jacobian=True)
    free = np.flatnonzero(estimated_by_default(model))
    return condition_number(start.J[:, free] * references(model, x0)[free])[0]
