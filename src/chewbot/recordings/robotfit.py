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

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from chewbot.compiled.cache import KERNELS, cached_graph, folded
from chewbot.compiled.kernels import compiled, evaluate
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
_SQP = {
    "qpsol": "qrqp", "convexify_strategy": "eigen-clip",  # "regularize" slows it tenfold here; clipping keeps 3 iterations
    # the QP's own feasibility tolerance (1e-8 by default) would accept a pose a few nanometres outside a socket
    "qpsol_options": {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False,
                      "constr_viol_tol": 1e-13},
    "print_time": False, "print_header": False, "print_iteration": False, "print_status": False,
    "error_on_fail": False, "tol_pr": 1e-12, "tol_du": 1e-10, "max_iter": 100,
}


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
    _nlp: ca.Function
    _stationarity: ca.Function
    _sequential: ca.Function
    _extreme: ca.Function
    _cost_gradient: ca.Function

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
        start that is not finite is replaced by the home pose. Returns z (m, n) and the multipliers lam_g
        (m, n_g), NaN for a sample whose functions could not be evaluated on the SQP's way."""
        m = z0.shape[0]
        z0 = np.where(np.isfinite(z0).all(axis=1, keepdims=True), z0, 0.0)
        params = np.vstack([target.T, np.tile(settings[:, None], (1, m))])
        bounds = {"lbg": np.tile(self.lbg[:, None], (1, m)), "ubg": np.tile(self.ubg[:, None], (1, m))}
        try:
            sol = KERNELS.mapped(self._nlp, m)(x0=z0.T, p=params, **bounds)
            return np.asarray(sol["x"]).T.reshape(m, -1), np.asarray(sol["lam_g"]).T.reshape(m, -1)
        except RuntimeError:  # an evaluation failed (a pose where a chain's closure is undefined): find which, alone
            z, lam = np.full((m, self.n), np.nan), np.full((m, self.lbg.size), np.nan)
            for k in range(m):
                try:
                    sol = self._nlp(x0=z0[k], p=params[:, k], lbg=self.lbg, ubg=self.ubg)
                    z[k], lam[k] = np.asarray(sol["x"]).ravel(), np.asarray(sol["lam_g"]).ravel()
                except RuntimeError:
                    pass
            return z, lam

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
    lam = ca.SX.sym("lam_g", g.numel())
    stationarity = ca.Function("fit_stationarity", [z, lam, target, settings],
                               [ca.gradient(f, z) + ca.mtimes(ca.jacobian(g, z).T, lam)])
    nlp = ca.nlpsol(f"fit_nlp_{model.mechanism}", "sqpmethod",
                    {"x": z, "p": ca.vertcat(target, settings), "f": f, "g": g}, _SQP)
    # the farthest a point of {M} reaches along a direction: minimise -d . (p + R b) in mm over the admissible poses
    reach = ca.SX.sym("reach", 6)
    extreme = ca.nlpsol(f"reach_nlp_{model.mechanism}", "ipopt",
                        {"x": z, "p": reach, "f": -ca.dot(reach[:3], p + ca.mtimes(R, reach[3:])) / MM, "g": g},
                        {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-10, "bound_relax_factor": 0.0}})
    return FitFunctions(coords, scale, np.array(lbg), np.array(ubg), tuple(names), gauss_newton, errors, constraints,
                        ca.Function("fit_pose_z", [z], [p, R], ["z"], ["p", "R"]), nlp, stationarity,
                        gauss_newton.mapaccum("fit_sequential", CHUNK), extreme,
                        ca.Function("fit_cost_gradient", [z, target, settings], [ca.gradient(f, target)]))



# ------------------------------------------------------------------------------------------ registration search

@dataclass(frozen=True, eq=False)
class RegistrationFunctions:
    """The graphs of the registration search (:mod:`chewbot.recordings.register`), for one model.

    The unknowns x (12,): the rest pose of {M} (the fit's n coordinates z0 in mm and deg, then, on the target,
    an offset of Z in mm and of gamma in deg off the robot's poses) and a correction of the markers' placement
    B = (R_B, t_B), {M} in the tracker's frame at rest: R_B = R_B,start exp(dr) (dr in deg), t_B = t_B,start + dt
    (mm). With the tracker's motion Y_k (Y_0 = I) and the scale s, frame k is at
    p_k = p_0 + s R_0 R_B^T ((R_Y,k - I) t_B + p_Y,k), R_k = R_0 R_B^T exp(s phi_k) R_B, phi_k the rotation vector
    of R_Y,k. Per frame [exp(s phi_k) (9); R_Y,k - I (9); p_Y,k (3)] (columns first), constants [R_B,start (9);
    t_B,start (3) m; s].
    """

    n_x: int
    _targets: ca.Function
    _placement: ca.Function

    def targets(self, x, frames, const) -> tuple[np.ndarray, np.ndarray]:
        """The recorded poses (N, 12) as the fit takes them and their Jacobians (N, 12, 12) by x."""
        t, J = evaluate(self._targets, frames, x, const)
        return t, J

    def placement(self, x, const) -> tuple[np.ndarray, np.ndarray]:
        """[R_0 R_B^T (9, the tracker's rotation); t_B (3) m; R_B (9)] of x, and its Jacobian (21, 12) by x."""
        v, J = evaluate(self._placement, x[None], const[None])
        return v[0], J[0]


def _expm(w):
    """exp([w]x) by Rodrigues' formula, written as series in theta^2 near 0 (exact derivatives at w = 0)."""
    t2 = ca.sumsqr(w)
    a = ca.if_else(t2 < 1e-8, 1 - t2 / 6 + t2**2 / 120, ca.sin(ca.sqrt(t2)) / ca.sqrt(t2))
    b = ca.if_else(t2 < 1e-8, 0.5 - t2 / 24 + t2**2 / 720, (1 - ca.cos(ca.sqrt(t2))) / t2)
    K = ca.skew(w)
    return ca.SX.eye(3) + a * K + b * ca.mtimes(K, K)


def registration_functions(model: Model) -> RegistrationFunctions:
    """The registration search's graphs for ``model`` (built once per process)."""
    return cached_graph(folded(model), ("recordings", "registration"), lambda: _build_registration(model))


def _build_registration(model: Model) -> RegistrationFunctions:
    s_model = symbolic(folded(model), "euler-angles")
    coords = COORDINATES[(model.mechanism, "euler-angles")]
    scale = np.array([MM if c in ("X", "Y", "Z") else DEG for c in coords])
    n = len(coords)
    x = ca.SX.sym("x", 12)
    p0, R0 = ca.Function("reg_pose", [s_model.q], [s_model.p, s_model.R])(ca.DM(scale) * x[:n])
    if n == 4:  # off the robot's poses: Z and gamma of the rest pose
        p0 = p0 + ca.vertcat(0, 0, x[4] * MM)
        c, s_ = ca.cos(x[5] * DEG), ca.sin(x[5] * DEG)
        R0 = ca.mtimes(R0, ca.vertcat(ca.horzcat(c, -s_, 0), ca.horzcat(s_, c, 0), ca.horzcat(0, 0, 1)))
    const = ca.SX.sym("const", 13)
    R_B = ca.mtimes(ca.reshape(const[:9], 3, 3), _expm(x[6:9] * DEG))
    t_B = const[9:12] + x[9:12] * MM
    scale_s = const[12]
    frame = ca.SX.sym("frame", 21)
    Rs, D, pY = ca.reshape(frame[:9], 3, 3), ca.reshape(frame[9:18], 3, 3), frame[18:21]
    A = ca.mtimes(R0, R_B.T)
    p_k = p0 + scale_s * ca.mtimes(A, ca.mtimes(D, t_B) + pY)
    R_k = ca.mtimes(ca.mtimes(A, Rs), R_B)
    target = ca.vertcat(p_k, ca.reshape(R_k, 9, 1))
    targets = ca.Function("reg_targets", [frame, x, const], [target, ca.jacobian(target, x)])
    placed = ca.vertcat(ca.reshape(A, 9, 1), t_B, ca.reshape(R_B, 9, 1))
    placement = ca.Function("reg_placement", [x, const], [placed, ca.jacobian(placed, x)])
    return RegistrationFunctions(12, targets, placement)


@dataclass(frozen=True, eq=False)
class PointRegistrationFunctions:
    """The graphs of the registration search for an incisal-point recording (``tracked = "incisor"``,
    :mod:`chewbot.recordings.register_point`), for one model.

    The unknowns x (6,): a turn dr (deg) of the tracker's rotation, A = exp(dr) A_start, and the rest incisor's
    offset o (mm) from the home incisor I_home in {S}. Frame k's tracked point, relative to the first frame in the
    tracker's frame, is d_k (m); at the scale s the registered point is Q_k = I_home + o + s A d_k, and the pose the
    fit is given is the hinge guess of :func:`chewbot.recordings.importer.hinge_angle` written again here: R_k the
    rotation about y by beta_k = psi + asin(-(s (A d_k)_z + r_z) / abs(r_xz)) (r = I - C in {M}, C the condyles'
    middle, psi = atan2(r_z, r_x)), p_k = Q_k - R_k I. Constants [A_start (9, columns first); s; I_home (3) m;
    A_file (9)].
    """

    _targets: ca.Function
    _turn: ca.Function

    def targets(self, x, frames, const) -> tuple[np.ndarray, np.ndarray]:
        """The recorded poses (N, 12) as the fit takes them, and their Jacobians (N, 12, 6) by x; ``frames`` (N, 3)."""
        t, J = evaluate(self._targets, frames, x, const)
        return t, J

    def turn(self, x, const) -> tuple[np.ndarray, float, np.ndarray]:
        """The tracker's rotation A (3, 3), its angle from the file's (deg) and that angle's gradient (6,) by x."""
        a, angle, grad = evaluate(self._turn, x[None], const[None])
        return a[0].reshape(3, 3).T, float(angle[0, 0]), grad[0]


def point_registration_functions(model: Model) -> PointRegistrationFunctions:
    """The incisal-point registration search's graphs for ``model`` (built once per process)."""
    return cached_graph(folded(model), ("recordings", "point registration"), lambda: _build_point_registration(model))


def _build_point_registration(model: Model) -> PointRegistrationFunctions:
    x = ca.SX.sym("x", 6)
    const = ca.SX.sym("const", 22)
    d = ca.SX.sym("d", 3)
    A = ca.mtimes(_expm(x[:3] * DEG), ca.reshape(const[:9], 3, 3))
    s, home, A_file = const[9], const[10:13], ca.reshape(const[13:22], 3, 3)
    v = s * ca.mtimes(A, d)
    Q = home + x[3:6] * MM + v
    incisor = ca.DM(model.incisor)
    r = model.incisor - 0.5 * (model.hkp.T_L + model.hkp.T_R)
    size, psi = float(np.hypot(r[0], r[2])), float(np.arctan2(r[2], r[0]))
    beta = psi + ca.asin(ca.fmin(1, ca.fmax(-1, -(v[2] + r[2]) / size)))
    c, s_ = ca.cos(beta), ca.sin(beta)
    R = ca.vertcat(ca.horzcat(c, 0, s_), ca.horzcat(0, 1, 0), ca.horzcat(-s_, 0, c))
    target = ca.vertcat(Q - ca.mtimes(R, incisor), ca.reshape(R, 9, 1))
    targets = ca.Function("point_reg_targets", [d, x, const], [target, ca.jacobian(target, x)])
    cos = ca.fmin(1, ca.fmax(-1, 0.5 * (ca.trace(ca.mtimes(A_file.T, A)) - 1)))
    angle = ca.acos(cos) / DEG
    turn = ca.Function("point_reg_turn", [x, const], [ca.reshape(A, 9, 1), angle, ca.gradient(angle, x)])
    return PointRegistrationFunctions(targets, turn)
