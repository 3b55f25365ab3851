"""Optimal distribution of the redundant unknowns of an inverse-dynamics model (seed 001, Sect. 4.5).

A problem is given by two CasADi expressions of (D, x, friction, p): D the sample's data, x the free unknowns,
p the model's parameters: ``residual`` r, whose squared norm is the goal (minimise |r|^2), and ``limits`` c with
|c| <= bound component-wise (the actuators' physical limits, given per model), and optionally lower bounds on x
(the unilateral contact's N >= preload, :mod:`chewbot.dynamics.contact`). Each sample is solved in two stages:

1. Unconstrained, all samples at once: x starts at the problem's ``start`` (for the Newton–Euler goals the
   best of the piecewise least-squares minimisers, :func:`chewbot.dynamics.formulations.newton_euler.start_sx`), or at
   the friction-free optimum (r is affine in x then: one Newton step from 0 gives it), then damped Newton on the
   exact Hessian (Gauss-Newton where the exact one is not positive definite) with an Armijo backtracking
   line search, vectorised over the samples that have not converged.
2. Where that optimum breaks a lower bound on x: the best of the minimisers over the faces of the bounds, by
   the same vectorised Newton with the face's components held at their bounds.
3. Where a limit or a bound is still broken: SQP (CasADi ``sqpmethod``, exact Hessian) with the limits as
   inequality constraints and the bounds on x, sample after sample in time order, each warm-started from the solution of the
   previous sample. A sample where no admissible x is found is recorded (which sample, which limit, and the
   SQP's return status, which tells a proven infeasible problem from a failure to converge), never clipped;
   ``strict`` raises :class:`~chewbot.errors.InfeasibleError` instead.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Callable

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.errors import InfeasibleError

# Newton stops when the step is below STEP_TOL (1 + |x|) (x in N: 1e-10 N on forces of tens of newtons).
STEP_TOL = 1e-10
MAX_NEWTON = 60
MAX_HALVINGS = 40
ARMIJO = 1e-4
# Relative decrease of J below which a line search cannot tell progress from rounding (J carries ~1e-16).
MEASURABLE = 1e-10
# A limit counts as broken above bound (1 + LIMIT_RTOL): the SQP's own feasibility tolerance is 1e-8 or so.
LIMIT_RTOL = 1e-6
# A lower bound l on x counts as broken below l - LOWER_TOL (1 + |l|): the SQP's active-set QP puts x on an
# active bound up to rounding; the check is a thousand times finer than the limits' (N: 1e-9 N at a zero bound).
LOWER_TOL = 1e-9


@dataclass(frozen=True)
class ProblemGraph:
    """The symbols and expressions of a distribution problem: the sample's data ``D``, the unknowns ``x``, the
    friction flag, ``params`` (``[p]``, or ``[]`` when the model's numbers are folded in); the goal's residual,
    the limits c (|c| <= bound), and ``start`` (an expression of D and p; None: the friction-free optimum)."""

    D: ca.SX
    x: ca.SX
    friction: ca.SX
    params: list
    residual: ca.SX
    limits: ca.SX
    start: ca.SX | None = None


@dataclass
class Problem:
    """A distribution problem: the goal's residual and the limits, as compiled per-sample CasADi functions,
    each taking the model's parameters p last (where the graph has them as an input).

    ``objective``: (D, x, friction, p) -> J = |r|^2, grad J, exact Hessian, Gauss-Newton Hessian (compiled
    kernels, :func:`chewbot.compiled.kernels.native`);
    ``value``: (D, x, friction, p) -> J alone (for the line search);
    ``limits``: (D, x, friction, p) -> c (|c| <= the bound :func:`solve` is given); ``limit_names``: a label per
    entry of c; ``start``: (D, p) -> x, where Newton starts with friction (None: the friction-free optimum);
    ``nlp``: the SQP solver over x with parameters (D, friction, p), built on first use (the only part that needs
    the graph when the kernels are in the cache).
    """

    objective: object
    value: object
    limits: object
    limit_names: list[str]
    nx: int
    start: object | None = None
    _graph: Callable[[], ProblemGraph] | None = field(repr=False, default=None)
    _nlp: object = field(repr=False, default=None)

    @property
    def nlp(self):
        if self._nlp is None:
            g = self._graph()
            nlp = {"x": g.x, "p": ca.vertcat(g.D, g.friction, *g.params), "f": ca.sumsqr(g.residual), "g": g.limits}
            opts = {"qpsol": "qrqp", "print_header": False, "print_iteration": False, "print_time": False,
                    "print_status": False, "error_on_fail": False, "max_iter": 200,
                    "qpsol_options": {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False}}
            self._nlp = ca.nlpsol("distribution", "sqpmethod", nlp, opts)
        return self._nlp


def problem_kernels(name: str, graph: Callable[[], ProblemGraph], key: tuple, has_start: bool = True) -> list[KernelSpec]:
    """The kernels of a :class:`Problem` (objective, value, limits and start, see there) named ``name_...``, of the
    expressions ``graph()`` returns; ``key``: what determines the graph besides chewbot's source (see
    :class:`~chewbot.compiled.kernels.KernelSpec`)."""

    def objective(g: ProblemGraph) -> list:
        J = ca.sumsqr(g.residual)
        Jr = ca.jacobian(g.residual, g.x)
        H, grad = ca.hessian(J, g.x)
        return [J, grad, H, 2 * ca.mtimes(Jr.T, Jr)]

    def spec(suffix: str, outputs: Callable[[ProblemGraph], list], out_names: list[str]) -> KernelSpec:
        def build(params):  # the problem's expressions hold their own numbers
            g = graph()
            ins, names = ([g.D], ["D"]) if suffix == "start" else ([g.D, g.x, g.friction], ["D", "x", "friction"])
            return ca.Function(f"{name}_{suffix}", ins + g.params, [ca.densify(o) for o in outputs(g)],
                               names + ["p"] * len(g.params), out_names, {"cse": True})

        return KernelSpec(f"{name}_{suffix}", build, key)

    kernels = [spec("objective", objective, ["J", "grad", "H", "H_gn"]), spec("value", lambda g: [ca.sumsqr(g.residual)], ["J"]),
               spec("limits", lambda g: [g.limits], ["c"])]
    return kernels + [spec("start", lambda g: [g.start], ["x"])] if has_start else kernels


def build_problem(name: str, graph: Callable[[], ProblemGraph], nx: int, limit_names, has_start: bool,
                  key: tuple | None = None) -> Problem:
    """The compiled :class:`Problem` of the expressions ``graph()`` returns: ``name`` prefixes the kernels'
    names, ``nx`` is the number of unknowns. ``key``: what determines the graph besides chewbot's source (see
    :func:`problem_kernels`; the graph is then built only for kernels missing from the cache), or None for a
    graph defined outside chewbot (built, and its kernels keyed by their serialised form)."""
    kernels = problem_kernels(name, graph, () if key is None else key, has_start)
    loaded = [native(k if key is not None else k.build(None)) for k in kernels]
    return Problem(*loaded[:3], list(limit_names), nx, loaded[3] if has_start else None, graph)


@dataclass
class Solution:
    """The distributed unknowns x (N, nx) and what it took: iterations, SQP samples, infeasible samples."""

    x: np.ndarray
    newton_iterations: int
    unconverged: list[int]
    constrained: list[int]
    infeasible: list[dict]


class SampleData:
    """The per-sample data of a whole task (N, k), samples first, and the model's parameters p that every function
    takes last (none: ``p`` empty). ``D`` may be given as a CasADi matrix with one column per sample.

    Each call runs a compiled kernel over every sample in one C loop (:func:`chewbot.compiled.kernels.evaluate`, no
    conversion through CasADi's matrices: a kernel mapped by CasADi over the samples costs 40 times as much).
    """

    def __init__(self, D, p: np.ndarray | None = None):
        self.D = np.ascontiguousarray(D.full().T if isinstance(D, ca.DM) else D, dtype=float)
        self.n = self.D.shape[0]
        self.p = [] if p is None else [np.asarray(p, dtype=float)]

    def take(self, rows: np.ndarray) -> SampleData:
        """The samples ``rows`` alone (then calls cost as many samples)."""
        sub = SampleData(self.D[np.asarray(rows, dtype=int)])
        sub.p = self.p
        return sub

    def column(self, k: int) -> np.ndarray:
        return self.D[k]

    def __call__(self, fn, *args) -> list[np.ndarray]:
        """``fn(D, *args)`` on every sample; args (N, k) or scalars; outputs as
        :func:`chewbot.compiled.kernels.evaluate` gives them: (N, rows) or (N, rows, cols)."""
        return evaluate(fn, self.D, *args, *self.p)


def broken_limits(problem: Problem, data: SampleData, x: np.ndarray, friction: float, bound: np.ndarray,
                  lower: np.ndarray | None = None) -> np.ndarray:
    """(N, n_limits [+ nx]) boolean: which limits each sample breaks, then (with ``lower``) which lower bounds on x."""
    (c,) = data(problem.limits, x, friction)
    broken = np.abs(c) > bound * (1 + LIMIT_RTOL)
    return broken if lower is None else np.hstack([broken, x < lower - LOWER_TOL * (1 + np.abs(lower))])


def solve(problem: Problem, data: SampleData, friction: float, t: np.ndarray, bound: np.ndarray, strict: bool = False,
          lower: np.ndarray | None = None, lower_names: list[str] | None = None, previous: np.ndarray | None = None,
          check: Callable[[], None] | None = None) -> Solution:
    """Distribute x at every sample (see the module docstring). ``t``: sample times, for the reports;
    ``bound``: the limits' bounds, |c| <= bound; ``lower``: lower bounds on x (nx,), constraints of the problem like
    the limits (None: x is free), named ``lower_names`` where a sample breaks them; ``previous``: the solution of
    the sample before the first one (a task solved in chunks), the SQP's warm start there; ``check()``: called before
    each sample's SQP, raises to stop (CasADi's solver may swallow a signal: the command line passes a check that
    raises when one arrived)."""
    bound = np.asarray(bound, dtype=float)
    if lower is not None:
        lower = np.broadcast_to(np.asarray(lower, dtype=float), (problem.nx,))
    names = list(problem.limit_names) + ([] if lower is None else list(lower_names or [f"x{j + 1} >= {v:g}" for j, v in enumerate(lower)]))
    x = np.zeros((data.n, problem.nx))
    iterations, unconverged = 0, []
    if problem.nx:
        if friction and problem.start is not None:
            (x,) = data(problem.start)
        else:
            _, g, H, _ = data(problem.objective, x, 0.0)
            x = -np.linalg.solve(H, g[..., None])[..., 0]  # friction-free optimum: r is affine in x there
        if friction:
            x, iterations, unconverged = _newton(problem, data, x, friction)
    broken = broken_limits(problem, data, x, friction, bound, lower)
    if lower is not None and problem.nx:
        x = _on_bounds(problem, data, x, friction, lower, broken[:, -problem.nx:].any(axis=1))
        broken = broken_limits(problem, data, x, friction, bound, lower)
    rows = np.flatnonzero(broken.any(axis=1))
    constrained, infeasible = [], []
    status = {}
    if problem.nx and rows.size:
        x, constrained, status = _constrained(problem, data, x, friction, rows, bound, lower, previous, check)
        broken = broken_limits(problem, data, x, friction, bound, lower)
        rows = np.flatnonzero(broken.any(axis=1))
    for k in rows:
        broke = [names[j] for j in np.flatnonzero(broken[k])]
        infeasible.append({"sample": int(k), "t": float(t[k]), "limits": broke,
                           "solver": status.get(int(k), "none: no redundancy to distribute" if not problem.nx else "unknown")})
    if infeasible and strict:
        first = infeasible[0]
        raise InfeasibleError(f"sample {first['sample']} (t = {first['t']:.6g} s): no distribution within the limits found "
                              f"(SQP: {first['solver']}); limits broken: {', '.join(first['limits'])} "
                              f"({len(infeasible)} sample(s) in all)")
    return Solution(x, iterations, unconverged, constrained, infeasible)


def _newton(problem: Problem, data: SampleData, x, friction, fixed: np.ndarray | None = None):
    """Damped Newton on all samples at once; returns x, the iteration count, the samples left unconverged.
    ``fixed``: (nx,) boolean, components of x held where they are (Newton on the others)."""
    active = np.ones(data.n, dtype=bool)
    eye = np.eye(problem.nx)
    for it in range(1, MAX_NEWTON + 1):
        J, g, H, H_gn = data(problem.objective, x, friction)
        convex = np.linalg.eigvalsh(H).min(axis=1) > 0
        H = np.where(convex[:, None, None], H, H_gn + 1e-12 * eye)
        if fixed is not None:  # a zero step on the fixed components: their gradient out, their rows of H the identity's
            g = np.where(fixed, 0.0, g)
            H = np.where(fixed[:, None] | fixed[None, :], eye, H)
        step = np.where(active[:, None], -np.linalg.solve(H, g[..., None])[..., 0], 0.0)
        slope = np.einsum("ij,ij->i", g, step)
        alpha = np.ones(data.n)
        # Near the optimum the predicted decrease -slope/2 falls to the rounding level of J, where the Armijo
        # test is noise: there the full Newton step is taken (quadratic convergence region).
        todo = -slope > MEASURABLE * np.abs(J[:, 0])
        for _ in range(MAX_HALVINGS):
            if not todo.any():
                break
            (Jt,) = data(problem.value, x + alpha[:, None] * step, friction)
            todo &= Jt[:, 0] > J[:, 0] + ARMIJO * alpha * slope
            alpha[todo] /= 2
        alpha[todo] = 0.0  # no decrease along a descent direction: the sample is at its optimum to rounding
        moved = alpha[:, None] * step
        x = x + moved
        active &= np.abs(moved).max(axis=1) > STEP_TOL * (1 + np.abs(x).max(axis=1))
        if not active.any():
            return x, it, []
    return x, MAX_NEWTON, np.flatnonzero(active).tolist()


def _on_bounds(problem: Problem, data: SampleData, x, friction, lower, below):
    """Where x is below its lower bounds (``below``, (N,)): the best minimiser over the faces of the bounds, all
    those samples at once. The bounded optimum minimises the goal on the face of its active bounds, and it is the
    feasible face-minimiser of least goal (exact for a convex goal; with the smoothed friction terms, Newton's local
    optimum on each face). Each face is one Newton run with the face's components held at their bounds: 2^nx - 1
    faces, three for the two normal forces. A sample that they leave infeasible goes on to the SQP."""
    rows = np.flatnonzero(below)
    if not rows.size:
        return x
    sub, x_rows = data.take(rows), x[rows]
    best, best_J = x_rows.copy(), np.full(rows.size, np.inf)
    for face in itertools.product((False, True), repeat=problem.nx):
        fixed = np.array(face)
        if not fixed.any():
            continue
        xf, _, unconverged = _newton(problem, sub, np.where(fixed, lower, x_rows), friction, fixed)
        (J,) = sub(problem.value, xf, friction)
        ok = np.all(xf >= lower - LOWER_TOL * (1 + np.abs(lower)), axis=1)
        ok[unconverged] = False
        better = ok & (J[:, 0] < best_J)
        best[better], best_J[better] = xf[better], J[better, 0]
    x = x.copy()
    x[rows] = best
    return x


def _constrained(problem: Problem, data: SampleData, x, friction, rows, bound, lower, previous=None, check=None):
    """SQP with the limits (and the lower bounds on x), sample after sample in time order, each warm-started from
    the previous one (the first sample from ``previous``, the solution before it, where given; else from its own
    optimum without the limits)."""
    x = x.copy()
    solver = problem.nlp
    status = {}
    params = [np.asarray(p).ravel() for p in data.p]
    lbx = -np.inf if lower is None else lower
    for k in rows:
        if check:  # CasADi's solver may catch a SIGINT and return a failure status: stop here
            check()
        x0 = x[k - 1] if k > 0 else x[k] if previous is None else previous
        sol = solver(x0=x0, p=np.concatenate([data.column(k), [friction], *params]), lbg=-bound, ubg=bound, lbx=lbx)
        xk = np.asarray(sol["x"]).ravel()
        c = np.asarray(sol["g"]).ravel()
        if np.all(np.abs(c) <= bound * (1 + LIMIT_RTOL)) and (lower is None or np.all(xk >= lower - LOWER_TOL * (1 + np.abs(lower)))):
            x[k] = xk
        else:  # what the solver said: a proven infeasible problem and a failure to converge read differently
            status[int(k)] = str(solver.stats().get("return_status", "unknown"))
    return x, [int(k) for k in rows], status
