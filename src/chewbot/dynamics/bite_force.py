"""The bite force from the actuator torques: six equations, five unknowns, solved at every sample.

Given the motion of the mandible (angles, rates and accelerations of every sample) and the six measured torques
tau_m, the unknowns are u = (F_B, N) = (Fx, Fy, Fz, N_L, N_R): the food's force on the mandible at the molar B of
``side`` (in {S}) and the normal forces of the two planes on the condyles (:mod:`chewbot.dynamics.contact`). The
model is the Newton-Euler model of :mod:`chewbot.dynamics.formulations.newton_euler` with the model's friction (the one the
plant of ``chewbot simulate`` integrates, with the same smoothing of sgn and abs), so the equations are

    r(u) = tau_NE(q, q_dot, q_ddot, F_B, N) - tau_m = 0          (6 equations, 5 unknowns)

and u is their least-squares solution, min |r(u)|^2. Without friction r is affine in u (one linear least-squares
solve). With friction it is not: the HKP friction grows with |N_j| and the actuators' with |F_G,i|. As the
distribution of the redundant torques does (:func:`chewbot.dynamics.formulations.newton_euler.start_sx`), the kink of |N_j| is
handled by its sign pattern: on each pattern s of (N_L, N_R), |N_j| = s_j N_j and r is affine in u but for the
smooth actuator term, so a few Gauss-Newton steps (:data:`PATTERN_STEPS`) reach that piece's minimiser. Of the
pieces whose minimiser has the pattern's signs, the one of least |r| is kept, and :data:`POLISH_STEPS` damped
Gauss-Newton steps on the smoothed model (the plant's) finish it. Patterns: (+, +), (+, -), (-, +), (-, -) and the
kinks (0, +-), (+-, 0), (0, 0) (bilateral contact: N of either sign), or (+, +), (0, +), (+, 0), (0, 0) with
N >= 0 (unilateral: the bounded least squares, the best over the faces of the bounds, as
:mod:`chewbot.dynamics.distribution` solves its bounds). Every step runs on all samples at once (one compiled
kernel call over the samples: no loop per sample); the derivatives are CasADi's exact ones.

**Uncertainty.** Linearised at the answer, u moves by du = H^-1 G' dtau for a change dtau of the measured torques
(H = d(G'r)/du, the exact derivative of the optimality condition, G = dr/du: 6 x 5, N m per N), and by
du = -H^-1 d(G'r)/dp dp for a change dp of the model's numbers (the implicit function theorem, CasADi's exact
derivatives: :func:`sensitivity_kernel`). Three sources of error go through it (:func:`covariance`):

* the torque error: its covariance Sigma_tau (N^2 m^2), the model's ``uncertainty.torque_cov`` (the calibration's
  residuals: the sensors' noise and what the model misses) plus s^2 1, s^2 what the log's own residuals have in
  excess of it, pooled over the samples (each sample's residual has 6 - m_k degrees of freedom, m_k the unknowns
  free there: 5, fewer where a unilateral bound holds): a log noisier than the calibration's, or a model that fits
  this motion worse, widens the interval. Without a calibration s is the pooled torque error itself; a given
  ``sigma`` replaces both (Sigma_tau = sigma^2 1);
* the rates' error, where they were smoothed: each coordinate's rate and acceleration moved by their standard
  deviation (:class:`chewbot.task.smoothing.LocalFits`) both ways, the residual's change through the whole
  nonlinear model (a crank turning slower than its rate's error has a Coulomb friction of unknown direction: the
  change is then the whole friction, not its slope);
* the model's numbers: the covariance of the keys of its ``[uncertainty]`` (:class:`chewbot.model.Uncertainty`).

The standard errors are the square roots of the diagonal of the sum; the 95 % interval is u +- 1.96 of them. The
residual abs(r_k) (N m) measures what the model does not explain at sample k. A sample where G's condition number
exceeds :data:`MAX_CONDITION` is named in the warnings: its forces are poorly determined.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.formulations.newton_euler import DELTA_N, coefficients_kernel, forces_sx, n_unknowns
from chewbot.dynamics.options import check_contact
from chewbot.kinematics.motion import Kinematics
from chewbot.model import Model
from chewbot.model.symbolic import c_name, parameter_input
from chewbot.table import Table

ORIENTATION = "euler-angles"
UNKNOWNS = ("Fx", "Fy", "Fz", "N_L", "N_R")
# Gauss-Newton steps on each sign pattern (affine in u but for the actuators' smooth Coulomb term abs(F_G,i):
# two steps reach the piece's minimiser to ~1e-12 N on the default task), and damped steps on the smoothed model.
PATTERN_STEPS = 3
POLISH_STEPS = 6
# A sample whose polishing step is below this relative to its unknowns (1 + the largest abs(u), N) has converged to
# rounding: its line search is skipped (it could only move u by rounding, and its cost rarely falls by it).
POLISH_FLOOR = 1e-12
HALVINGS = 6
# A pattern's minimiser counts as having its signs down to this far on the wrong side (N): the smoothing of abs(N)
# (DELTA_N) blurs the kink over that width anyway.
SIGN_TOL = 10 * DELTA_N
# Without friction the pieces are exact linear least squares: a face's minimiser counts as inside the bounds down to
# rounding (N of tens of newtons carry ~1e-14 N).
BOUND_TOL = 1e-9
# Condition number of G (all unknowns in N, all equations in N m: no scaling needed) above which a sample is named:
# a relative torque error e then moves the forces by up to MAX_CONDITION e relative to their size.
MAX_CONDITION = 1e4
BILATERAL_PATTERNS = ((1, 1), (1, -1), (-1, 1), (-1, -1), (0, 1), (0, -1), (1, 0), (-1, 0), (0, 0))
UNILATERAL_PATTERNS = ((1, 1), (0, 1), (1, 0), (0, 0))


def residual_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (theta, q, dq, ddq, B, u, tau_m, signs, friction, p) -> r (6, N m), G = dr/du (6 x 5, m).

    q and its rates in Euler angles; u = (Fx, Fy, Fz, N_L, N_R) (N); tau_m the measured torques (N m); ``signs``
    (2): where s_j is +-1, abs(N_j) is s_j N_j (the sign pattern), where it is 0, N_j is held at 0 by the caller and
    abs(N_j) is the smoothed one of the model; ``friction`` 0 or 1. The target only (the 6RSS has no N)."""
    if mechanism != "target":
        raise ValueError("the bite-force estimator is for the target robot (five unknowns from six torques)")
    name = f"bite_force_{c_name(mechanism)}"

    def build(params):
        m = params
        coefficients = coefficients_kernel(mechanism, ORIENTATION).graph(params)
        extra, names = parameter_input(m)
        theta, q, dq, ddq = (ca.SX.sym(nm, coefficients.size1_in(i)) for i, nm in enumerate(("theta", "q", "dq", "ddq")))
        B, u, tau_m = ca.SX.sym("B", 3), ca.SX.sym("u", 5), ca.SX.sym("tau_m", 6)
        signs, fl = ca.SX.sym("signs", 2), ca.SX.sym("friction")
        N = u[3:5]
        D = coefficients(theta, q, dq, ddq, u[0:3], B, *extra)[0]
        smooth = ca.sqrt(N**2 + DELTA_N**2)
        absN = ca.vertcat(*[ca.if_else(signs[j] != 0, signs[j] * N[j], smooth[j]) for j in range(n_unknowns(mechanism))])
        r = forces_sx(m, D, N, fl, absN)["tau"] - tau_m
        return ca.Function(name, [theta, q, dq, ddq, B, u, tau_m, signs, fl, *extra], [r, ca.jacobian(r, u)],
                           ["theta", "q", "dq", "ddq", "B", "u", "tau_m", "signs", "friction", *names], ["r", "G"],
                           {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


def sensitivity_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (theta, q, dq, ddq, B, u, tau_m, friction, p, dp) -> H = d(G'r)/du (5 x 5, m^2) and g_p =
    d(G'r)/dp . dp (5, N m^2 per unit of dp): the derivatives of the estimate's optimality condition G'r = 0
    (G = dr/du) on the smoothed model (signs 0) with respect to the unknowns and along a change ``dp`` of the
    model's numbers (forward mode). du/dp . dp = -H^-1 g_p."""
    name = f"bite_force_sensitivity_{c_name(mechanism)}"

    def build(params):
        residual = residual_kernel(mechanism).graph(params)
        ins = [ca.SX.sym(residual.name_in(i), residual.sparsity_in(i)) for i in range(residual.n_in())]
        named = dict(zip(residual.name_in(), ins))
        r, G = residual(*[ca.DM.zeros(2) if k == "signs" else v for k, v in named.items()])
        g = ca.mtimes(G.T, r)
        p = named["p"]
        dp = ca.SX.sym("dp", p.numel())
        inputs = [v for k, v in named.items() if k != "signs"]
        return ca.Function(name, [*inputs, dp], [ca.jacobian(g, named["u"]), ca.jtimes(g, p, dp)],
                           [k for k in named if k != "signs"] + ["dp"], ["H", "g_p"], {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


# The 95 % interval: the estimate +- this many standard errors (the normal distribution's 97.5 % quantile).
Z95 = 1.959963984540054


@dataclass(frozen=True, eq=False)
class ForceEstimate:
    """The estimate along the samples (arrays samples first, SI).

    ``t`` (n,) s; ``F_B`` (n, 3) N, the food's force on the mandible at the molar in {S}; ``N`` (n, 2) N, the normal
    forces N_L, N_R of the planes on the condyles (> 0: pushing); ``se`` (n, 5) N, the standard errors of
    (Fx, Fy, Fz, N_L, N_R), all sources together; ``residual`` (n,) N m, abs(r) at the answer; ``sigma`` N m, the
    pooled torque error the log has beyond the sources (module docstring) and ``dof`` its degrees of freedom;
    ``condition`` (n,) the condition number of G; ``ill_conditioned`` the samples above :data:`MAX_CONDITION`;
    ``warnings`` what a person should read; ``info`` how it was solved (for a record); ``se_parts``: the standard
    errors (n, 5) of each source alone (``torque``, ``rates``, ``parameters``)."""

    t: np.ndarray
    F_B: np.ndarray
    N: np.ndarray
    se: np.ndarray
    residual: np.ndarray
    sigma: float
    dof: int
    condition: np.ndarray
    ill_conditioned: np.ndarray
    warnings: list[str] = field(default_factory=list)
    info: dict = field(default_factory=dict)
    se_parts: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.t.shape[0]

    @property
    def u(self) -> np.ndarray:
        """(n, 5): Fx, Fy, Fz, N_L, N_R."""
        return np.hstack([self.F_B, self.N])

    def interval(self) -> tuple[np.ndarray, np.ndarray]:
        """The 95 % intervals of (Fx, Fy, Fz, N_L, N_R): low and high, (n, 5) N each."""
        return self.u - Z95 * self.se, self.u + Z95 * self.se

    def table(self) -> Table:
        """FORCE.csv's columns: t, Fx, Fy, Fz, N_L, N_R, their standard errors sFx .. sN_R, their 95 % intervals
        Fx_low95, Fx_high95 .. N_R_high95, the residual."""
        table = Table()
        table.add("t", self.t, "s", "time of the log's sample")
        table.add_block(UNKNOWNS[:3], self.F_B, "N", "estimated force of the food on the mandible at the molar, {S}")
        table.add_block(UNKNOWNS[3:], self.N, "N", "estimated normal force of the plane on the condyle (> 0: pushes)")
        table.add_block([f"s{u}" for u in UNKNOWNS], self.se, "N",
                        "standard error: torque error, rates' error and the model's uncertainty (docs/bite_force.md)")
        low, high = self.interval()
        for j, name in enumerate(UNKNOWNS):
            table.add(f"{name}_low95", low[:, j], "N", f"95 % interval of {name}: estimate - 1.96 standard errors")
            table.add(f"{name}_high95", high[:, j], "N", f"95 % interval of {name}: estimate + 1.96 standard errors")
        table.add("residual", self.residual, "N*m", "abs(tau_model - tau_measured) at the estimate")
        return table


def estimate(model: Model, kin: Kinematics, tau: np.ndarray, *, side: str | None = None, contact: str = "bilateral",
             friction: bool = True, sigma: float | None = None, rate_sd: np.ndarray | None = None,
             acceleration_sd: np.ndarray | None = None) -> ForceEstimate:
    """The bite force F_B and the normal forces N along the motion ``kin`` of ``model`` from the measured torques
    ``tau`` (n, 6) N m (module docstring). ``side``: the molar where the food is (default: ``kin.side``);
    ``contact``: ``bilateral`` (N of either sign) or ``unilateral`` (N >= 0); ``friction``: the model's friction
    in the equations (off: the frictionless model); ``sigma``: the torques' standard deviation (N m) if known, else
    pooled from the residuals; ``rate_sd``, ``acceleration_sd`` (n, dof): the standard deviations of the motion's
    rates in Euler angles where they were estimated (None: exact). The model's ``uncertainty`` is used where it
    has one."""
    q, dq, ddq = kin.euler_angle_state()
    return estimate_states(model, kin.t, kin.theta, q, dq, ddq, tau, side=side or kin.side, contact=contact,
                           friction=friction, sigma=sigma, rate_sd=rate_sd, acceleration_sd=acceleration_sd)


def estimate_states(model: Model, t, theta, q, dq, ddq, tau, *, side: str = "left", contact: str = "bilateral",
                    friction: bool = True, sigma: float | None = None, rate_sd: np.ndarray | None = None,
                    acceleration_sd: np.ndarray | None = None) -> ForceEstimate:
    """:func:`estimate` on the states themselves: times ``t`` (n,), crank angles ``theta`` (n, 6), the independent
    coordinates in Euler angles ``q`` (n, 4) and their rates ``dq``, ``ddq``, torques ``tau`` (n, 6)."""
    fn = native(residual_kernel(model.mechanism))
    u, free, (r, G) = solve_states(model, theta, q, dq, ddq, tau, side=side, contact=contact, friction=friction, kernel=fn)
    B, p, fl = model.molar(side), model.vector(), 1.0 if friction else 0.0

    def residual(dq_, ddq_):
        return evaluate(fn, theta, q, dq_, ddq_, B, u, tau, np.zeros(2), fl, p)[0]

    sens = native(sensitivity_kernel(model.mechanism))
    H = evaluate(sens, theta, q, dq, ddq, B, u, tau, fl, p, np.zeros_like(p))[0].reshape(-1, 5, 5)
    parts = covariance(model, H, G, r, free, residual, dq, ddq, rate_sd, acceleration_sd, sigma,
                       lambda dp: evaluate(sens, theta, q, dq, ddq, B, u, tau, fl, p, dp)[1])
    return summarise(t, u, r, G, free, parts, info={"contact": contact, "friction": bool(friction), "side": side,
                                                    "equations": "newton-euler"})


def covariance(model: Model, H, G, r, free, residual, dq, ddq, rate_sd, acceleration_sd, sigma, along) -> dict:
    """The covariances (n, 5, 5) of u from each source (module docstring): ``torque``, ``rates``, ``parameters``, and
    ``sigma`` (the torque error the log has beyond them, N m) with its degrees of freedom ``dof``.

    ``H`` (n, 5, 5), ``G`` (n, 6, 5), ``r`` (n, 6) at the answer, ``free`` (n, 5) its free unknowns; ``residual(dq,
    ddq)`` the residual at the answer with other rates; ``along(dp)`` -> g_p of :func:`sensitivity_kernel`."""
    n = r.shape[0]
    A = np.zeros((n, 5, 6))  # du = A dtau, on the free unknowns
    P = np.zeros((n, 6, 6))  # the projector onto the free columns of G
    for pattern in np.unique(free, axis=0):
        rows = np.all(free == pattern, axis=1)
        Hf = H[rows][:, pattern][:, :, pattern]
        Gf = G[rows][:, :, pattern]
        A[np.ix_(rows, pattern, np.arange(6))] = np.linalg.solve(Hf, np.swapaxes(Gf, 1, 2))
        P[rows] = Gf @ np.linalg.pinv(Gf)
    Q = np.eye(6) - P
    # the rates: each coordinate's rate and acceleration moved by its standard deviation, both ways
    C_r = np.zeros((n, 6, 6))
    for sd, which in ((rate_sd, 0), (acceleration_sd, 1)):
        if sd is None:
            continue
        for j in range(sd.shape[1]):
            step = np.zeros_like(dq)
            step[:, j] = sd[:, j]
            up = residual(dq + step, ddq) if which == 0 else residual(dq, ddq + step)
            down = residual(dq - step, ddq) if which == 0 else residual(dq, ddq - step)
            d = (up - down) / 2
            C_r += d[:, :, None] * d[:, None, :]
    # the model's numbers
    C_p = np.zeros((n, 5, 5))
    unc = model.uncertainty
    if unc is not None:
        D = unc.directions(model.vector().size)
        du = []
        for j in range(D.shape[1]):
            g_p = along(D[:, j])
            step = np.zeros((n, 5))
            for pattern in np.unique(free, axis=0):
                rows = np.all(free == pattern, axis=1)
                step[np.ix_(rows, pattern)] = -np.linalg.solve(H[rows][:, pattern][:, :, pattern],
                                                               g_p[rows][:, pattern][..., None])[..., 0]
            du.append(step)
        du = np.stack(du, axis=2)  # (n, 5, k)
        C_p = du @ unc.cov @ np.swapaxes(du, 1, 2)
    base = np.zeros((6, 6)) if unc is None or unc.torque_cov is None else unc.torque_cov
    dof = int(np.sum(6 - free.sum(axis=1)))
    excess = np.einsum("ij,ij->i", r, r) - np.einsum("nij,ji->n", Q, base)
    if sigma is not None:
        s, base = float(sigma), np.zeros((6, 6))
    else:
        s = float(np.sqrt(max(excess.sum(), 0.0) / dof)) if dof > 0 else float("nan")
    torque = base + (s if np.isfinite(s) else 0.0) ** 2 * np.eye(6)
    At = np.swapaxes(A, 1, 2)
    return {"torque": A @ torque @ At, "rates": A @ C_r @ At, "parameters": C_p, "sigma": s, "dof": dof,
            "sigma_source": "given" if sigma is not None else
            ("the model's torque error and the log's excess" if unc is not None and unc.torque_cov is not None
             else "pooled residuals")}


def solve_states(model: Model, theta, q, dq, ddq, tau, *, side: str = "left", contact: str = "bilateral",
                 friction: bool = True, kernel=None, residuals: bool = True) -> tuple[np.ndarray, np.ndarray, tuple | None]:
    """The answer u (n, 5) of :func:`estimate_states`, which unknowns are free (n, 5), and (r, G) there (None without
    ``residuals``: the force observer's tick needs u alone), without the statistics. ``kernel``: the compiled
    :func:`residual_kernel` where the caller holds it."""
    check_contact(contact)
    if not model.has_hkp:
        raise ValueError(f"{model.name}: the bite-force estimator needs the target robot (six torques, five unknowns); "
                         "on the 6RSS the force has six components and the normal forces none")
    tau = np.asarray(tau, dtype=float)
    n = np.shape(q)[0]
    if tau.shape != (n, 6):
        raise ValueError(f"tau must be ({n}, 6), not {tau.shape}")
    fn = kernel if kernel is not None else native(residual_kernel(model.mechanism))
    B, p, fl = model.molar(side), model.vector(), 1.0 if friction else 0.0
    def residual(u, signs, rows=slice(None)):
        return evaluate(fn, theta[rows], q[rows], dq[rows], ddq[rows], B, u, tau[rows], signs, fl, p)

    theta, q, dq, ddq = (np.asarray(x, float) for x in (theta, q, dq, ddq))
    u, free = solve(residual, n, contact, fl)
    return u, free, tuple(evaluate(fn, theta, q, dq, ddq, B, u, tau, np.zeros(2), fl, p)) if residuals else None


def solve(residual, n: int, contact: str, friction: float) -> tuple[np.ndarray, np.ndarray]:
    """u (n, 5) minimising |r|^2 at every sample, and which unknowns are free (n, 5) (False: held at a bound).
    ``residual(u, signs, rows)`` -> r (k, 6), G (k, 6, 5) at the samples ``rows`` (default: all), u (k, 5) there
    (module docstring)."""
    r0, G0 = residual(np.zeros((n, 5)), np.zeros(2))
    everything = np.ones(5, dtype=bool)
    start = _lstsq(G0, -r0, everything)  # the friction-free answer: exact without friction, r being affine in u
    if contact == "bilateral" and not friction:
        return start, np.ones((n, 5), dtype=bool)
    patterns = BILATERAL_PATTERNS if contact == "bilateral" else UNILATERAL_PATTERNS
    best, best_cost, best_free = start.copy(), np.full(n, np.inf), np.ones((n, 5), dtype=bool)
    for signs in patterns:
        sign = np.array(signs, dtype=float)
        free = np.concatenate([[True] * 3, sign != 0])
        u = np.where(free, start, 0.0)
        for _ in range(PATTERN_STEPS if friction else 1):
            r, G = residual(u, sign)
            u = u + _lstsq(G, -r, free)
        r, _ = residual(u, sign)
        cost = np.einsum("ij,ij->i", r, r)
        # the piece's minimiser has the piece's signs (without friction: exactly, up to rounding)
        ok = np.all(sign * u[:, 3:] >= -(SIGN_TOL if friction else BOUND_TOL), axis=1)
        better = ok & (cost < best_cost)
        best[better], best_cost[better], best_free[better] = u[better], cost[better], free
    # a sample no piece claims (rounding at a kink): the friction-free answer, clipped to the bounds where unilateral
    if contact == "unilateral":
        best[:, 3:] = np.maximum(best[:, 3:], 0.0)
    if friction:
        if contact == "bilateral":  # the smoothed model is smooth through N = 0: every unknown free
            best_free[:] = True
        best = _polish(residual, best, best_free, contact)
    return best, best_free


def _polish(residual, u, free, contact):
    """Damped Gauss-Newton on the smoothed model (signs 0), the held unknowns kept, all samples at once; the line
    search on the samples whose step is above :data:`POLISH_FLOOR`, a halving on those whose step was not accepted
    yet."""
    zero = np.zeros(2)
    r, G = residual(u, zero)
    cost = np.einsum("ij,ij->i", r, r)
    patterns = [(pattern, np.all(free == pattern, axis=1)) for pattern in np.unique(free, axis=0)]
    for _ in range(POLISH_STEPS):
        step = np.zeros_like(u)
        for pattern, rows in patterns:
            step[rows] = _lstsq(G[rows], -r[rows], pattern)
        left, alpha = np.flatnonzero(np.abs(step).max(axis=1) > POLISH_FLOOR * (1.0 + np.abs(u).max(axis=1))), 1.0
        if not left.size:
            break
        for _ in range(HALVINGS):
            trial = u[left] + alpha * step[left]
            if contact == "unilateral":
                trial[:, 3:] = np.maximum(trial[:, 3:], 0.0)
            rt, Gt = residual(trial, zero, left)
            ct = np.einsum("ij,ij->i", rt, rt)
            good = ct <= cost[left]
            rows = left[good]
            u[rows], r[rows], G[rows], cost[rows] = trial[good], rt[good], Gt[good], ct[good]
            left = left[~good]
            if not left.size:
                break
            alpha /= 2
    return u


def _lstsq(G: np.ndarray, b: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Least-squares x (k, 5) of G x = b on the columns ``free`` (5,), zero elsewhere; batched, by QR."""
    x = np.zeros((G.shape[0], 5))
    if G.shape[0] == 0:
        return x
    Q, R = np.linalg.qr(G[:, :, free])
    x[:, free] = np.linalg.solve(R, np.einsum("nki,nk->ni", Q, b)[..., None])[..., 0]
    return x


def summarise(t, u, r, G, free, parts: dict, info: dict | None = None) -> ForceEstimate:
    """A :class:`ForceEstimate` of the answer u (n, 5) with its residuals r (n, 6), G (n, 6, 5) and the covariances of
    :func:`covariance` (``parts``): standard errors, condition numbers and warnings (module docstring)."""
    n = u.shape[0]
    res2 = np.einsum("ij,ij->i", r, r)
    sv = np.linalg.svd(G, compute_uv=False) if n else np.zeros((0, 5))
    with np.errstate(divide="ignore", invalid="ignore"):
        condition = sv[:, 0] / sv[:, -1]

    def se(cov):
        return np.sqrt(np.clip(np.einsum("nii->ni", cov), 0.0, None))

    sources = ("torque", "rates", "parameters")
    total = sum(parts[k] for k in sources)
    bad = np.flatnonzero(~(condition <= MAX_CONDITION))
    warnings = []
    if bad.size:
        listed = ", ".join(f"{int(k)} (t = {t[k]:.6g} s)" for k in bad[:10])
        warnings.append(f"{bad.size} sample(s) ill-conditioned (condition number of dtau/du above {MAX_CONDITION:g}): "
                        f"{listed}{' ...' if bad.size > 10 else ''}; their forces are poorly determined")
    info = dict(info or {})
    info.update({"sigma_Nm": parts["sigma"], "sigma_source": parts["sigma_source"], "dof": parts["dof"],
                 "pattern_steps": PATTERN_STEPS, "polish_steps": POLISH_STEPS, "max_condition": MAX_CONDITION,
                 "standard_error_rms_N": {k: dict(zip(UNKNOWNS, np.sqrt(np.mean(se(parts[k]) ** 2, axis=0)).tolist()))
                                          for k in sources} if n else {}})
    return ForceEstimate(np.asarray(t, float), u[:, :3].copy(), u[:, 3:].copy(), se(total), np.sqrt(res2), parts["sigma"],
                         parts["dof"], condition, bad, warnings, info, {k: se(parts[k]) for k in sources})
