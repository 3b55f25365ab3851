"""The CasADi graphs of the fit to the robot: the weighted pose error, its Gauss-Newton kernel, the admissibility
constraints and the constrained problem. The only module of :mod:`chewbot.recordings` that builds CasADi graphs.

Unknowns are the mechanism's q_EE in XYZ Euler angles, scaled to millimetres and degrees (``z = q / scale``),
so that the solver's tolerances and the weights read in the registration's units.

The pose error of a pose q against a recorded pose (p_rec, R_rec), with the measure point b in {M}:

* position: e_p = (p + R b) - (p_rec + R_rec b), in mm;
* orientation: the rotation vector phi of R^T R_rec (R_rec = R exp([phi]x)), whose length is the angle
  between the two orientations, in degrees;

and the residual r = [w_p e_p / mm; w_o phi / deg] (``position_weight_per_mm``, ``orientation_weight_per_deg``):
the fit minimises abs(r)^2 over the admissible poses. Admissible: both condyles inside their sockets (target)
and every chain reachable with a transmission angle of at least a margin (:data:`MIN_TRANSMISSION_DEG` unless the
caller gives another; never below :data:`REACH_MARGIN` in sine, so that
:func:`chewbot.kinematics.ik.inverse_kinematics` accepts it).

Interface: :class:`FitFunctions`, whose methods take NumPy arrays, samples first: ``z`` (N, n), ``target`` (N, 12)
= [p_rec (m); R_rec column by column], ``settings`` (5,) = [b (m, in {M}); w_p; w_o].
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Callable

import casadi as ca
import numpy as np

from chewbot.compiled.cache import cached_graph, folded
from chewbot.compiled.kernels import compiled, evaluate
from chewbot.compiled.layout import Layout
from chewbot.analysis.checks import NEAR_SINGULAR_DEG
from chewbot.kinematics.ik import SINGULAR_TOLERANCE
from chewbot.kinematics.symbolic import COORDINATES, symbolic
from chewbot.model import Model
from chewbot.units import factor

MM, DEG = factor("mm"), factor("deg")
# Gauss-Newton iterations per frame inside the compiled kernel. From the previous frame's result or from the
# recorded pose's own coordinates, the fit's last step falls to rounding (1e-14 mm) in 4 iterations on a chewing
# recording at 100 Hz without noise and in 6 with 0.1 mm of marker noise (quadratic convergence where the robot
# can follow the recording exactly, linear otherwise); 8 leave a margin, and the caller checks the last step and
# runs the kernel again on the frames that need it.
GN_ITERATIONS = 8
# Frames per call of the sequential pass: the kernel runs over them in one C++ loop, each frame starting from
# the previous one's result; the Python loop is over chunks (a few dozen calls for a minute at 100 Hz).
CHUNK = 256
# Sine of the transmission angle that an admissible pose keeps on every chain: twice the inverse kinematics'
# singular tolerance, so that a pose on this boundary is still well inside what the kinematics accept.
REACH_MARGIN = 2 * SINGULAR_TOLERANCE
# The transmission angle an admissible pose keeps by default: the run's near-singular threshold, so that an imported
# task runs without near-singular samples (a free search otherwise ends on the chains' dead points, where a crank's
# speed is unbounded for a finite speed of the mandible).
MIN_TRANSMISSION_DEG = NEAR_SINGULAR_DEG
# A point of {M} this near the condylar axis (mm) has no opening direction of its own: no turn about the axis moves
# it down (a condyle glides instead).
MIN_LEVER_MM = 10.0
# SQP iterations per frame at most: a frame on the boundary takes about 3; one that stalls is started again
# elsewhere, or kept where it stalled if admissible (chewbot.recordings.fit).
SQP_ITERATIONS = 40
# The projection of the registration search (:meth:`FitFunctions.projected`): Levenberg-Marquardt steps on the pose
# error and an exterior penalty of the admissibility constraints, PENALTY per mm outside a socket and per
# REACH_UNIT of sine squared below a chain's floor (about a millimetre of the mandible's motion near the floor).
# Its optimum lies outside the admissible set by about (pose error's gradient) / PENALTY^2: 1e-5 mm for a frame
# 10 mm beyond the reach at 2 per mm, far below any tolerance of the fit. It is a start for the SQP, not its
# replacement: on the analyser recording like a real one (frames 10-40 mm beyond the reach) PROJECTION_ITERATIONS steps end at the
# SQP's answer (to 1e-8) in some calls and up to 2.8 mm or deg from it in others; a step that does not lower the
# cost is refused (the damping grows).
PENALTY = 1e3
REACH_UNIT = 0.01
PROJECTION_ITERATIONS = 40
_SQP = {
    # qpOASES (an active-set solver for small dense QPs, bundled with CasADi): on the frames of
    # the wide-opening analyser recording's that end 10-40 mm beyond the reach, qrqp took up to 5 ms per QP and left 12 of 141 frames
    # unconverged (stalled at costs up to 78 higher); qpOASES solved all 141 to a stationary point, ten times
    # faster, never at a higher cost (to 4e-12). Eigenvalues clipped where the Hessian is indefinite: qpOASES wants
    # a convex QP, and clipping keeps 3 iterations where "regularize" took ten times more
    "qpsol": "qpoases", "convexify_strategy": "eigen-clip", "max_iter_eig": 10000,
    "qpsol_options": {"printLevel": "none", "error_on_fail": False},
    "print_time": False, "print_header": False, "print_iteration": False, "print_status": False,
    "error_on_fail": False, "tol_pr": 1e-12, "tol_du": 1e-10, "max_iter": SQP_ITERATIONS,
}


@contextmanager
def _quiet():
    """Standard output closed at the file descriptor for a while: qpOASES prints its licence notice on stdout from C++
    whenever it makes a solver's memory, whatever its printLevel (casadi/casadi#1983, #3522), which would land in the
    commands' output."""
    sys.stdout.flush()
    saved, null = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


@dataclass(frozen=True, eq=False)
class FitFunctions:
    """The fit's per-sample functions for one model (built once, cached on the model), called on NumPy arrays
    (samples first; :func:`chewbot.compiled.kernels.evaluate`): the rest of :mod:`chewbot.recordings` never calls a
    CasADi function itself.

    ``coords``: names of q_EE; ``scale``: (n,) SI value of one unit of z (1e-3 for lengths, pi/180 for angles);
    admissible poses have ``lbg <= g <= ubg`` (condyle x, y in mm; sin^2 of the transmission angles), each entry
    of g named by ``constraint_names``.
    """

    coords: tuple[str, ...]
    scale: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    constraint_names: tuple[str, ...]
    _gauss_newton: ca.Function
    _errors: ca.Function
    _constraints: ca.Function
    _pose: ca.Function
    _nlp: Callable[[], ca.Function]
    _stationarity: ca.Function
    _sequential: ca.Function
    _extreme: ca.Function
    _cost_gradient: ca.Function
    _projected: ca.Function

    @property
    def n(self) -> int:
        return self.scale.size

    def gauss_newton(self, z0, target, settings) -> tuple[np.ndarray, np.ndarray]:
        """z (N, n) after :data:`GN_ITERATIONS` steps from z0 (N, n), and the size of the last step (N,) (mm, deg)."""
        z, last = evaluate(self._gauss_newton, z0, target, settings)
        return z, last[:, 0]

    def errors(self, z, target, settings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position error (N,) mm, orientation error (N,) deg and the weighted residual r (N, 6)."""
        e_p, e_o, r = evaluate(self._errors, z, target, settings)
        return e_p[:, 0], e_o[:, 0], r

    def constraints(self, z) -> np.ndarray:
        """g (N, n_g) of the poses z (N, n)."""
        return evaluate(self._constraints, z)[0]

    def pose(self, z) -> tuple[np.ndarray, np.ndarray]:
        """p (N, 3) m and R (N, 3, 3) in {S} of the poses z (N, n)."""
        p, R = evaluate(self._pose, z)
        return p, R

    def stationarity(self, z, lam_g, target, settings) -> np.ndarray:
        """The gradient of the constrained problem's Lagrangian (N, n): ~0 at a solution."""
        return evaluate(self._stationarity, z, lam_g, target, settings)[0]

    def sequential(self, z_first, target, settings) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`gauss_newton` over N frames in time order, each frame starting from the result of the previous
        one (``z_first`` for the first): one C++ loop per :data:`CHUNK` frames. Returns z (N, n), last step (N,)."""
        n_frames = target.shape[0]
        z, last = np.empty((n_frames, self.n)), np.empty(n_frames)
        start = np.asarray(z_first, dtype=float)
        st = np.tile(settings[:, None], (1, CHUNK))
        for lo in range(0, n_frames, CHUNK):
            hi = min(lo + CHUNK, n_frames)
            tg = np.empty((12, CHUNK))
            tg[:, : hi - lo] = target[lo:hi].T
            tg[:, hi - lo:] = target[hi - 1][:, None]  # the last chunk is padded with its last frame
            zc, lc = self._sequential(start, tg, st)
            zc, lc = np.asarray(zc), np.asarray(lc).ravel()
            z[lo:hi], last[lo:hi] = zc[:, : hi - lo].T, lc[: hi - lo]
            start = zc[:, hi - lo - 1]
        return z, last

    def constrained(self, z0, target, settings) -> tuple[np.ndarray, np.ndarray]:
        """The constrained problem (SQP) for m samples at once, in one mapped call, each from its z0 (m, n); a
        start that is not finite is replaced by the home pose. Each call makes its own solver (about 10 ms): qpOASES
        starts each QP from the last one its memory solved, which moves answers by 1e-13 with what ran before, and
        the registration search's path with them (its share on the suite's 2x chin cluster: 1 alone, 0.82 after
        other imports in the same process); a fresh solver makes every call's answer depend on its input alone. Returns z (m, n) and the multipliers lam_g
        (m, n_g), NaN for a sample whose functions could not be evaluated on the SQP's way."""
        m = z0.shape[0]
        z0 = np.where(np.isfinite(z0).all(axis=1, keepdims=True), z0, 0.0)
        params = np.vstack([target.T, np.tile(settings[:, None], (1, m))])
        bounds = {"lbg": np.tile(self.lbg[:, None], (1, m)), "ubg": np.tile(self.ubg[:, None], (1, m))}
        nlp = self._nlp()
        try:
            with _quiet():
                sol = (nlp.map(m, "serial") if m > 1 else nlp)(x0=z0.T, p=params, **bounds)
            return np.asarray(sol["x"]).T.reshape(m, -1), np.asarray(sol["lam_g"]).T.reshape(m, -1)
        except RuntimeError:  # an evaluation failed (a pose where a chain's closure is undefined): find which, alone
            z, lam = np.full((m, self.n), np.nan), np.full((m, self.lbg.size), np.nan)
            for k in range(m):
                try:
                    with _quiet():
                        sol = self._nlp()(x0=z0[k], p=params[:, k], lbg=self.lbg, ubg=self.ubg)
                    z[k], lam[k] = np.asarray(sol["x"]).ravel(), np.asarray(sol["lam_g"]).ravel()
                except RuntimeError:
                    pass
            return z, lam

    def projected(self, z0, target, settings) -> tuple[np.ndarray, np.ndarray]:
        """The penalised fit (see :data:`PENALTY`) from z0 (N, n) in one compiled call over the N frames, no SQP:
        z (N, n) and how far each ends outside the admissible set (N,) (mm in a socket, :data:`REACH_UNIT` of sine
        squared on a chain). The registration search's objective, whose gradient by the recorded pose is that of
        the pose error at this optimum (Danskin's theorem: the penalty does not depend on the recording)."""
        z, outside = evaluate(self._projected, z0, target, settings, self.lbg, self.ubg)
        return z, outside[:, 0]

    def cost_gradient(self, z, target, settings) -> np.ndarray:
        """The gradient (N, 12) of 0.5 abs(r)^2 with respect to the recorded pose [p_rec; R_rec column by column]:
        at a fitted pose, the derivative of the fit's optimal value (the constraints do not depend on the
        recorded pose: Danskin's theorem)."""
        return evaluate(self._cost_gradient, z, target, settings)[0]

    def extreme(self, z0, direction, point) -> tuple[np.ndarray, bool]:
        """The admissible pose z (n,) that carries ``point`` (3,) m in {M} farthest along ``direction`` (3,) in {S}
        (interior point method, IPOPT, exact Hessian), from z0; and whether IPOPT reports success."""
        sol = self._extreme(x0=z0, p=np.r_[direction, point], lbg=self.lbg, ubg=self.ubg)
        return np.asarray(sol["x"]).ravel(), bool(self._extreme.stats()["success"])


def fit_functions(model: Model, min_transmission_deg: float = MIN_TRANSMISSION_DEG) -> FitFunctions:
    """The fit's functions for ``model`` (target: X, Y, alpha, beta; 6RSS: X, Y, Z, alpha, beta, gamma), whose
    admissible poses keep every transmission angle at or above ``min_transmission_deg``."""
    fns = cached_graph(folded(model), ("recordings", "fit"), lambda: _build(model))
    reach = np.array(["reach" in name for name in fns.constraint_names])
    floor = max(np.sin(np.radians(min_transmission_deg)), REACH_MARGIN) ** 2
    return replace(fns, lbg=np.where(reach, floor, fns.lbg))


def _rotation_vector(A):
    """phi with A = exp([phi]x), for a rotation matrix A (smooth, exact derivatives at A = I too).

    With v = vee(A - A^T) / 2 = sin(theta) u and cos(theta) = (tr A - 1) / 2: phi = theta / sin(theta) v, the
    ratio written as a series in s = sin^2(theta) where s is tiny (the two agree to 1e-25 at the switch).
    """
    v = 0.5 * ca.vertcat(A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1])
    s = ca.sumsqr(v)
    c = 0.5 * (A[0, 0] + A[1, 1] + A[2, 2] - 1)
    ratio = ca.if_else(s < 1e-8, 1 + s / 6 + 3 * s**2 / 40, ca.atan2(ca.sqrt(s), c) / ca.sqrt(s))
    return ratio * v


def _reach_sx(model: Model, p, R):
    """sin^2 of each chain's transmission angle, (A^2 + B^2 - C^2) / (2 L_c L_r)^2 (:func:`chewbot.kinematics.ik.transmission`):
    negative where a chain cannot close, 0 at its singular configuration."""
    out = []
    for i in range(6):
        d = p + ca.mtimes(R, ca.DM(model.M[i])) - ca.DM(model.G[i])
        Lc, Lr = model.crank_length[i], model.coupler_length[i]
        A = 2 * Lc * ca.dot(d, ca.DM(model.R_C0[i][:, 0]))
        B = 2 * Lc * ca.dot(d, ca.DM(model.R_C0[i][:, 1]))
        C = Lc**2 + ca.dot(d, d) - Lr**2
        out.append((A**2 + B**2 - C**2) / (2 * Lc * Lr) ** 2)
    return out


def _build(model: Model) -> FitFunctions:
    s = symbolic(folded(model), "euler-angles")
    coords = COORDINATES[(model.mechanism, "euler-angles")]
    scale = np.array([MM if c in ("X", "Y", "Z") else DEG for c in coords])
    n = len(coords)
    z = ca.SX.sym("z", n)
    target = ca.SX.sym("target", 12)
    settings = ca.SX.sym("settings", 5)
    pose = ca.Function("fit_pose", [s.q], [s.p, s.R])
    p, R = pose(ca.DM(scale) * z)
    p_rec, R_rec = target[:3], ca.reshape(target[3:], 3, 3)
    b, w_p, w_o = settings[:3], settings[3], settings[4]
    e_p = (p + ca.mtimes(R, b) - p_rec - ca.mtimes(R_rec, b)) / MM
    phi = _rotation_vector(ca.mtimes(R.T, R_rec)) / DEG
    r = ca.vertcat(w_p * e_p, w_o * phi)
    errors = ca.Function("fit_errors", [z, target, settings], [ca.norm_2(e_p), ca.norm_2(phi), r],
                         ["z", "target", "settings"], ["position_mm", "orientation_deg", "r"])

    J = ca.jacobian(r, z)
    JtJ = ca.mtimes(J.T, J)
    # Levenberg's damping, negligible beside J^T J (well conditioned in mm and deg): it only guards the solve
    step = -ca.solve(JtJ + 1e-12 * ca.trace(JtJ) * ca.SX.eye(n), ca.mtimes(J.T, r))
    one_step = ca.Function("fit_step", [z, target, settings], [z + step, ca.norm_2(step)])
    zk, size = ca.SX.sym("z0", n), ca.SX(0)
    z0 = zk
    for _ in range(GN_ITERATIONS):
        zk, size = one_step(zk, target, settings)
    gauss_newton = compiled(ca.Function(f"fit_gauss_newton_{model.mechanism}", [z0, target, settings], [zk, size],
                                        ["z0", "target", "settings"], ["z", "last_step"]))

    g, lbg, ubg, names = [], [], [], []
    if model.has_hkp:
        h = model.hkp
        for side, T, y in (("left", h.T_L, h.y_left), ("right", h.T_R, h.y_right)):
            x_S = (p + ca.mtimes(R, ca.DM(T))) / MM
            g += [x_S[0], x_S[1]]
            lbg += [h.x_range[0] / MM, y[0] / MM]
            ubg += [h.x_range[1] / MM, y[1] / MM]
            names += [f"{side} condyle x", f"{side} condyle y"]
    g += _reach_sx(model, p, R)
    lbg += [REACH_MARGIN**2] * 6
    ubg += [np.inf] * 6  # sin^2 <= 1 always: an upper bound of 1 would be a degenerate constraint at its maximum
    names += [f"chain {i + 1} reach" for i in range(6)]
    g = ca.vertcat(*g)
    constraints = ca.Function("fit_constraints", [z], [g], ["z"], ["g"])

    f = 0.5 * ca.sumsqr(r)
    projected = _projection(model, z, target, settings, r, g, ["reach" in nm for nm in names])
    lam = ca.SX.sym("lam_g", g.numel())
    stationarity = ca.Function("fit_stationarity", [z, lam, target, settings],
                               [ca.gradient(f, z) + ca.mtimes(ca.jacobian(g, z).T, lam)])
    problem = {"x": z, "p": ca.vertcat(target, settings), "f": f, "g": g}

    def nlp() -> ca.Function:
        with _quiet():
            return ca.nlpsol(f"fit_nlp_{model.mechanism}", "sqpmethod", problem, _SQP)

    # the farthest a point of {M} reaches along a direction: minimise -d . (p + R b) in mm over the admissible poses
    reach = ca.SX.sym("reach", 6)
    extreme = ca.nlpsol(f"reach_nlp_{model.mechanism}", "ipopt",
                        {"x": z, "p": reach, "f": -ca.dot(reach[:3], p + ca.mtimes(R, reach[3:])) / MM, "g": g},
                        {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-10, "bound_relax_factor": 0.0}})
    return FitFunctions(coords, scale, np.array(lbg), np.array(ubg), tuple(names), gauss_newton, errors, constraints,
                        ca.Function("fit_pose_z", [z], [p, R], ["z"], ["p", "R"]), nlp, stationarity,
                        gauss_newton.mapaccum("fit_sequential", CHUNK), extreme,
                        ca.Function("fit_cost_gradient", [z, target, settings], [ca.gradient(f, target)]), projected)


def _projection(model: Model, z, target, settings, r, g, reach: list[bool]) -> ca.Function:
    """The compiled kernel of :meth:`FitFunctions.projected`: PROJECTION_ITERATIONS damped Newton steps on
    0.5 abs([r; PENALTY * (excess of g beyond its bounds, in mm and REACH_UNITs)])^2, each kept only where it
    lowers that cost (the damping then shrinks threefold, else grows fourfold)."""
    n, ng = z.numel(), g.numel()
    lbg, ubg = ca.SX.sym("lbg", ng), ca.SX.sym("ubg", ng)
    unit = ca.DM([REACH_UNIT if c else 1.0 for c in reach])
    outside = (ca.fmax(0, lbg - g) + ca.fmax(0, g - ubg)) / unit
    rp = ca.vertcat(r, PENALTY * outside)
    J = ca.jacobian(r, z)
    # Gauss-Newton's J^T J for the pose error, the penalty's exact Hessian (its constraints' curvature weighed by
    # their multipliers PENALTY^2 outside, as in an SQP's Lagrangian): without it the steps zigzag along a curved
    # boundary and the penalty refuses them
    H = ca.mtimes(J.T, J) + ca.hessian(0.5 * ca.sumsqr(PENALTY * outside), z)[0]
    mu = ca.SX.sym("mu")
    step = -ca.solve(H + mu * ca.diag(ca.diag(H)) + 1e-12 * ca.trace(H) * ca.SX.eye(n), ca.gradient(0.5 * ca.sumsqr(rp), z))
    cost = ca.Function("fit_penalised_cost", [z, target, settings, lbg, ubg], [ca.sumsqr(rp)])
    lm = ca.Function("fit_penalised_step", [z, target, settings, lbg, ubg, mu], [z + step])
    z0 = ca.MX.sym("z0", n)
    tg, st, lo, hi = ca.MX.sym("target", 12), ca.MX.sym("settings", 5), ca.MX.sym("lbg", ng), ca.MX.sym("ubg", ng)
    zk, mk, ck = z0, ca.MX(1e-3), cost(z0, tg, st, lo, hi)
    for _ in range(PROJECTION_ITERATIONS):
        trial = lm(zk, tg, st, lo, hi, mk)
        ct = cost(trial, tg, st, lo, hi)
        better = ct < ck
        zk, ck, mk = ca.if_else(better, trial, zk), ca.if_else(better, ct, ck), ca.if_else(better, mk / 3, mk * 4)
    out = ca.Function("fit_penalised_outside", [z, lbg, ubg], [ca.mmax(outside)])(zk, lo, hi)
    return compiled(ca.Function(f"fit_projection_{model.mechanism}", [z0, tg, st, lo, hi], [zk, out],
                                ["z0", "target", "settings", "lbg", "ubg"], ["z", "outside"]))



# ------------------------------------------------------------------------------------------ registration search

# The rigid-body registration search's unknowns (relative to the prior) and constants (matrices column by column).
REGISTRATION_X = Layout((("turn", 3), ("shift", 3), ("placement_turn", 3), ("placement_shift", 3)))
REGISTRATION_CONST = Layout((("rotation", 9), ("origin", 3), ("centre", 3), ("R_B", 9), ("t_B", 3), ("scale", 1)))
# A frame of the recording relative to its first: [exp(s phi_k); R_Y,k - I; p_Y,k].
REGISTRATION_FRAME = Layout((("turned", 9), ("D", 9), ("p", 3)))


@dataclass(frozen=True, eq=False)
class RegistrationFunctions:
    """The graph of the registration search around its prior (:mod:`chewbot.recordings.register`), for one model.

    The prior (:func:`chewbot.recordings.anatomy.rigid_prior`): the tracker (A_p, o_p; p_S = A p_T + o) and the
    markers' placement B_p = (R_B,p, t_B,p), {M} in the tracker's frame at the first frame. The unknowns x
    (:data:`REGISTRATION_X`): the tracker turned by exp(w) (deg) about the prior's rest position of O_M h and
    shifted by v (mm) in {S}: A = exp(w) A_p, o = exp(w) (o_p - h) + h + v; the placement turned and shifted in
    {M}: R_B = R_B,p exp(w_B), t_B = t_B,p + R_B,p v_B (mm). With the tracker's motion Y_k (Y_0 = I) and the scale
    s, frame k is at p_k = p_0 + s A ((R_Y,k - I) t_B + p_Y,k), R_k = A exp(s phi_k) R_B, p_0 = A t_B + o, phi_k the
    rotation vector of R_Y,k. Constants :data:`REGISTRATION_CONST`, frames :data:`REGISTRATION_FRAME`.
    """

    _targets: ca.Function

    def targets(self, x, frames, const) -> tuple[np.ndarray, np.ndarray]:
        """The recorded poses (N, 12) as the fit takes them and their Jacobians (N, 12, 12) by x."""
        t, J = evaluate(self._targets, frames, x, const)
        return t, J


def _expm(w):
    """exp([w]x) by Rodrigues' formula, written as series in theta^2 near 0 (exact derivatives at w = 0)."""
    t2 = ca.sumsqr(w)
    a = ca.if_else(t2 < 1e-8, 1 - t2 / 6 + t2**2 / 120, ca.sin(ca.sqrt(t2)) / ca.sqrt(t2))
    b = ca.if_else(t2 < 1e-8, 0.5 - t2 / 24 + t2**2 / 720, (1 - ca.cos(ca.sqrt(t2))) / t2)
    K = ca.skew(w)
    return ca.SX.eye(3) + a * K + b * ca.mtimes(K, K)


def registration_functions(model: Model) -> RegistrationFunctions:
    """The registration search's graph (built once per process; it does not depend on the model)."""
    return cached_graph(folded(model), ("recordings", "registration", "prior"), _build_registration)


def _build_registration() -> RegistrationFunctions:
    x = ca.SX.sym("x", REGISTRATION_X.size)
    const = ca.SX.sym("const", REGISTRATION_CONST.size)
    frame = ca.SX.sym("frame", REGISTRATION_FRAME.size)
    u, c, f = REGISTRATION_X.split(x), REGISTRATION_CONST.split(const), REGISTRATION_FRAME.split(frame)
    turn = _expm(u["turn"] * DEG)
    A = ca.mtimes(turn, ca.reshape(c["rotation"], 3, 3))
    o = ca.mtimes(turn, c["origin"] - c["centre"]) + c["centre"] + u["shift"] * MM
    R_Bp = ca.reshape(c["R_B"], 3, 3)
    R_B = ca.mtimes(R_Bp, _expm(u["placement_turn"] * DEG))
    t_B = c["t_B"] + ca.mtimes(R_Bp, u["placement_shift"] * MM)
    p_k = ca.mtimes(A, t_B) + o + c["scale"] * ca.mtimes(A, ca.mtimes(ca.reshape(f["D"], 3, 3), t_B) + f["p"])
    R_k = ca.mtimes(ca.mtimes(A, ca.reshape(f["turned"], 3, 3)), R_B)
    target = ca.vertcat(p_k, ca.reshape(R_k, 9, 1))
    return RegistrationFunctions(ca.Function("reg_targets", [frame, x, const], [target, ca.jacobian(target, x)]))


# The point-path registration search's unknowns and constants.
POINT_X = Layout((("turn", 3), ("rest", 3)))
POINT_CONST = Layout((("rotation", 9), ("scale", 1), ("home", 3), ("point", 3)))


@dataclass(frozen=True, eq=False)
class PointRegistrationFunctions:
    """The graph of the registration search for a point path (:mod:`chewbot.recordings.register_point`), for one
    model.

    The unknowns x (:data:`POINT_X`): a turn w (deg) of the tracker's rotation about the prior's, A = exp(w) A_p,
    and the first frame's point's offset o (mm) from where the tracked point b of {M} is at home, Q_home, in {S}.
    Frame k's point, relative to the first frame in the tracker's frame, is d_k (m); at the scale s the
    registered point is Q_k = Q_home + o + s A d_k, and the pose the fit is given is the hinge guess
    (:func:`hinge_beta`, the import's too): R_k the rotation about y by beta_k = psi + asin(-(s (A d_k)_z + r_z) /
    abs(r_xz)) (r = b - C in {M}, C the condyles' middle, psi = atan2(r_z, r_x); none for a point within
    :data:`MIN_LEVER_MM` of the condylar axis), p_k = Q_k - R_k b. Constants :data:`POINT_CONST`: A_p, s, Q_home
    (m), b (m).
    """

    _targets: ca.Function

    def targets(self, x, frames, const) -> tuple[np.ndarray, np.ndarray]:
        """The recorded poses (N, 12) as the fit takes them, and their Jacobians (N, 12, 6) by x; ``frames`` (N, 3)."""
        t, J = evaluate(self._targets, frames, x, const)
        return t, J


def point_registration_functions(model: Model) -> PointRegistrationFunctions:
    """The point-path registration search's graph for ``model`` (built once per process)."""
    return cached_graph(folded(model), ("recordings", "point registration", "prior"), lambda: _build_point_registration(model))


def hinge_beta(model: Model, b, drop):
    """The rotation about the condylar axis (+y of {M} through the condyles' midpoint C) that moves the point b
    of {M} by ``drop`` along z (m; negative: down), the condyles held: -abs(r_xz) sin(beta - psi) = drop + r_z,
    r = b - C, psi = atan2(r_z, r_x); beta = 0 at drop = 0 (the argument of arcsin clipped to [-1, 1]). For NumPy
    or CasADi values of b and drop; 0 for a point within MIN_LEVER_MM of the axis, which no turn moves down."""
    is_ca = isinstance(drop, (ca.SX, ca.MX)) or isinstance(b, (ca.SX, ca.MX))
    lib = ca if is_ca else np
    C = 0.5 * (model.hkp.T_L + model.hkp.T_R)
    rx, rz = b[0] - C[0], b[2] - C[2]
    size = lib.sqrt(rx**2 + rz**2 + 1e-18)  # (1e-9 m)^2: a finite derivative on the axis, where the guess is 0
    psi = lib.arctan2(rz, rx) if not is_ca else ca.atan2(rz, rx)
    arg = -(drop + rz) / lib.fmax(size, 1e-9) if is_ca else -(drop + rz) / max(float(size), 1e-9)
    arg = ca.fmin(1, ca.fmax(-1, arg)) if is_ca else np.clip(arg, -1.0, 1.0)
    beta = psi + (ca.asin(arg) if is_ca else np.arcsin(arg))
    if is_ca:
        return ca.if_else(size < MIN_LEVER_MM * MM, 0, beta)
    return np.zeros_like(np.asarray(drop, dtype=float)) if size < MIN_LEVER_MM * MM else beta


def _build_point_registration(model: Model) -> PointRegistrationFunctions:
    x = ca.SX.sym("x", POINT_X.size)
    const = ca.SX.sym("const", POINT_CONST.size)
    d = ca.SX.sym("d", 3)
    u, c = POINT_X.split(x), POINT_CONST.split(const)
    A = ca.mtimes(_expm(u["turn"] * DEG), ca.reshape(c["rotation"], 3, 3))
    v = c["scale"] * ca.mtimes(A, d)
    Q = c["home"] + u["rest"] * MM + v
    b = c["point"]
    beta = hinge_beta(model, b, v[2])
    cb, sb = ca.cos(beta), ca.sin(beta)
    R = ca.vertcat(ca.horzcat(cb, 0, sb), ca.horzcat(0, 1, 0), ca.horzcat(-sb, 0, cb))
    target = ca.vertcat(Q - ca.mtimes(R, b), ca.reshape(R, 9, 1))
    return PointRegistrationFunctions(ca.Function("point_reg_targets", [d, x, const], [target, ca.jacobian(target, x)]))
