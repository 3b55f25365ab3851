"""Where the sample is: the bite point's gap, its rates, the lower tooth's tilt, and the molar point moved along z.

The sample sits on the lower molar at the model's bite point B of the side (``model.molar(side)``, in {M}). The
upper tooth is flat and fixed in {S}, at the height B has at the home pose ({M} = {S} there: the pose is occlusal).
The gap is measured along {S}'s z:

    g = B_z(home) - B_z(q),   delta = max(0, h0 - g),

and d(delta)/dt = dB_z/dt; the bite point's velocity in {S}'s x-y plane is the sliding velocity of the sample on the
upper tooth. The lower tooth's tilt theta is the angle between {M}'s z axis and {S}'s: cos theta = R_33 and sin theta
= |(R_13, R_23)|, the latter smoothed as sqrt(R_13^2 + R_23^2 + e^2) - e (e = :data:`SIN_TILT_SMOOTHING`) so that
its derivative is finite at theta = 0, where the food's law (:mod:`chewbot.food.law`) takes it.

The point-path task of a texture test (:func:`molar_path_task`) moves B along {S}'s z with B_x, B_y held at home and
one angle pinned (alpha = 0 by default, as ``chewbot track-incisor --pin``): three equations of the point and the pin
for the target's four coordinates, solved by Newton's method on all samples at once (CasADi's ``rootfinder`` mapped
over the samples, exact Jacobians), the rates from the exact first and second derivatives of B(q).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from chewbot.compiled.cache import cached_graph, symbols
from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.errors import KinematicsError, TaskError
from chewbot.kinematics.symbolic import symbolic
from chewbot.kinematics.task import TARGET_COORDS, Task
from chewbot.model import Model
from chewbot.units import factor

ORIENTATION = "euler-angles"
# Newton's tolerance on the bite point's position (m) for the point path.
PATH_TOLERANCE = 1e-12
# The gap at the start of a texture test is h0 + this (m): a texture analyser's probe starts a millimetre or so above the
# sample and finds it at its pre-test speed.
APPROACH = 1e-3
# e of the smoothed sin(tilt) (module docstring): it changes sin(tilt) by at most 1e-9, the half-spread of the
# compression across a 10 mm face by at most 5e-12 m.
SIN_TILT_SMOOTHING = 1e-9
# The face's path keeps each condyle this far behind the front of its socket (m), the translation capped smoothly
# over CAP_SCALE (m); where the face's rotation carries a condyle past it, the cap is lowered and the path made again,
# at most CAP_PASSES times, until no condyle is more than CAP_TOLERANCE (m) past it.
SOCKET_MARGIN = 0.2e-3
CAP_SCALE = 0.3e-3
CAP_PASSES = 6
CAP_TOLERANCE = 1e-6
CAP_STRIDE = 20


def bite_point_function(mechanism: str) -> ca.Function:
    """(q, dq, B, p) -> point (3, the bite point in {S}, m), velocity (3, m/s), cos_tilt (R_33) and sin_tilt
    (smoothed, module docstring), q in Euler angles."""
    m = symbols(mechanism)

    def build():
        s = symbolic(m, ORIENTATION)
        B = ca.SX.sym("B", 3)
        point = s.point(B)
        velocity = ca.jtimes(point, s.q, s.dq)
        e = SIN_TILT_SMOOTHING
        sin_tilt = ca.sqrt(s.R[0, 2] ** 2 + s.R[1, 2] ** 2 + e**2) - e
        return ca.Function("bite_point", [s.q, s.dq, B, m.p], [point, velocity, s.R[2, 2], sin_tilt],
                           ["q", "dq", "B", "p"], ["point", "velocity", "cos_tilt", "sin_tilt"])

    return cached_graph(m, ("food-bite-point-face",), build)


def bite_point_kernel(mechanism: str) -> KernelSpec:
    """:func:`bite_point_function` compiled: a whole trajectory's gaps in one C loop."""
    from chewbot.model.symbolic import c_name

    name = f"bite_point_{c_name(mechanism)}"

    def build(params):
        fn = bite_point_function(mechanism)
        x = fn.sx_in()
        return ca.Function(name, x, fn.call(x), fn.name_in(), fn.name_out(), {"cse": True})

    return KernelSpec(name, build, (mechanism, "food-bite-point-face"), mechanism)


def home_height(model: Model, side: str) -> float:
    """B_z at the home pose (m): {M} coincides with {S} there."""
    return float(np.asarray(model.molar(side), float)[2])


def gap(model: Model, side: str, q, dq=None) -> dict[str, np.ndarray]:
    """The gap g (m), its rate dg/dt (m/s), the sliding velocity (N, 2; m/s), the lower tooth's tilt (rad) and the bite
    point (N, 3; m, in {S}) along states ``q``, ``dq`` (N, n) in Euler angles."""
    q = np.atleast_2d(np.asarray(q, float))
    dq = np.zeros_like(q) if dq is None else np.atleast_2d(np.asarray(dq, float))
    point, velocity, cos_tilt, sin_tilt = evaluate(native(bite_point_kernel(model.mechanism)), q, dq,
                                                   np.asarray(model.molar(side), float), model.vector())
    return {"gap": home_height(model, side) - point[:, 2], "rate": -velocity[:, 2], "sliding": velocity[:, :2],
            "tilt": np.arctan2(sin_tilt[:, 0], cos_tilt[:, 0]), "point": point}


def _path_functions(model: Model, side: str):
    """The point path's residual and its levels on the target with alpha pinned: unknowns u = (X, Y, beta)."""
    from chewbot.compiled.cache import folded

    params = folded(model)

    def build():
        s = symbolic(params, ORIENTATION)
        B = ca.DM(np.asarray(model.molar(side), float))
        u, du, ddu = ca.SX.sym("u", 3), ca.SX.sym("du", 3), ca.SX.sym("ddu", 3)
        pinned = ca.SX.sym("alpha", 3)  # the pinned angle, its rate and acceleration

        point_fn = ca.Function("molar", [s.q], [s.point(B)])
        qfull = ca.vertcat(u[0], u[1], pinned[0], u[2])
        vfull = ca.vertcat(du[0], du[1], pinned[1], du[2])
        afull = ca.vertcat(ddu[0], ddu[1], pinned[2], ddu[2])
        P_q = point_fn(qfull)
        target = ca.SX.sym("target", 3)
        residual = ca.Function("molar_residual", [u, ca.vertcat(target, pinned)], [P_q - target])
        solver = ca.rootfinder("molar_path", "newton", residual, {"abstol": PATH_TOLERANCE, "max_iter": 50,
                                                                     "error_on_fail": False})
        J = ca.jacobian(P_q, qfull)
        v = ca.mtimes(J, vfull)
        a = ca.mtimes(J, afull) + ca.jtimes(v, qfull, vfull)
        levels = ca.Function("molar_levels", [u, du, ddu, pinned], [P_q, v, a, J[:, [0, 1, 3]]])
        return solver, levels

    return cached_graph(params, ("food-molar-path", side), build)


def molar_path_task(model: Model, side: str, t, g, dg, ddg, name: str = "texture test", pin_values=None,
                    shift=None) -> Task:
    """The target's motion that moves the bite point of ``side`` along {S}'s z through gaps ``g`` (m) with rates
    ``dg``, ``ddg`` at times ``t``, B_x and B_y held at home (``shift``: or moved from there by (N, 2) offsets, their
    rates and accelerations, m, m/s, m/s^2: sliding on the tooth), alpha pinned (``pin_values``: its value, rate,
    acceleration (N,) each; default 0). Raises :class:`KinematicsError` naming the first sample the robot cannot
    reach (Newton did not converge, or the pose leaves the workspace)."""
    if not model.has_hkp:
        raise TaskError(f"model {model.name!r}: a point path with one pinned angle needs the target's four coordinates "
                        "(the 6RSS has six)")
    t = np.asarray(t, float)
    n = t.size
    g, dg, ddg = (np.asarray(x, float).reshape(n) for x in (g, dg, ddg))
    pins = np.zeros((n, 3)) if pin_values is None else np.column_stack([np.asarray(x, float).reshape(n) for x in pin_values])
    home = np.asarray(model.molar(side), float)
    xy, v_xy, a_xy = (np.zeros((n, 2)),) * 3 if shift is None else (np.asarray(x, float).reshape(n, 2) for x in shift)
    target = np.column_stack([home[0] + xy[:, 0], home[1] + xy[:, 1], home[2] - g])
    solver, levels = _path_functions(model, side)
    # Newton from the home pose on every sample at once (the gaps of a texture test are within a few degrees of it)
    mapped = solver.map(n)
    u = np.asarray(mapped(np.zeros((3, n)), np.vstack([target.T, pins.T]))).T
    P, _, _, _ = evaluate(levels, u, np.zeros((n, 3)), np.zeros((n, 3)), pins)
    err = np.linalg.norm(P - target, axis=1)
    bad = np.flatnonzero(~(err <= 1e-9))
    if bad.size:
        k = int(bad[0])
        raise KinematicsError(f"the bite point cannot be moved to a gap of {g[k] / factor('mm'):.4g} mm along z with alpha pinned "
                              f"(position error {err[k]:.3g} m)", sample=k, time=float(t[k]))
    # rates: J du = v - (pinned angle's share), J ddu = a - J_dot du - (pinned share), from the exact derivatives
    J = evaluate(levels, u, np.zeros((n, 3)), np.zeros((n, 3)), pins)[3]
    v_target = np.column_stack([v_xy, -dg])
    a_target = np.column_stack([a_xy, -ddg])
    _, v_pin, _, _ = evaluate(levels, u, np.zeros((n, 3)), np.zeros((n, 3)), np.column_stack([pins[:, 0], pins[:, 1], np.zeros(n)]))
    du = np.linalg.solve(J, (v_target - v_pin)[..., None])[..., 0]
    _, _, a_rest, _ = evaluate(levels, u, du, np.zeros((n, 3)), pins)
    ddu = np.linalg.solve(J, (a_target - a_rest)[..., None])[..., 0]
    q = np.column_stack([u[:, 0], u[:, 1], pins[:, 0], u[:, 2]])
    dq = np.column_stack([du[:, 0], du[:, 1], pins[:, 1], du[:, 2]])
    ddq = np.column_stack([ddu[:, 0], ddu[:, 1], pins[:, 2], ddu[:, 2]])
    return Task(name=name, t=t, coords=TARGET_COORDS, q=q, dq=dq, ddq=ddq, force=np.zeros((n, 3)), side=side,
                source="texture test (point path of the molar)", meta={"generator": "tpa", "pin": "alpha"})


def _face_functions(model: Model, side: str):
    """The lower tooth translated (alpha = beta = 0, Y = 0: its face parallel to the upper tooth) by X along {S}'s x
    (the bite point then moves by X horizontally): Newton's method on the residual B_z(X) - B_z(home) + g; X's first
    and second derivatives along the gap g, dX/dg = -1 / B_z'(X), by the implicit function theorem with exact
    derivatives; the residual; and the condyles' x in {S} (2,) at a pose q (Euler angles)."""
    from chewbot.compiled.cache import folded

    params = folded(model)

    def build():
        s = symbolic(params, ORIENTATION)
        B = ca.DM(np.asarray(model.molar(side), float))
        X, g = ca.SX.sym("X"), ca.SX.sym("g")
        point = ca.Function("molar", [s.q], [s.point(B)])
        Z = point(ca.vertcat(X, 0, 0, 0))[2]
        dZ, ddZ = ca.jacobian(Z, X), ca.jacobian(ca.jacobian(Z, X), X)
        dX = -1.0 / dZ  # B_z(X(g)) = B_z(home) - g
        levels = ca.Function("face_levels", [X], [dX, -ddZ * dX**2 / dZ])
        residual = ca.Function("face_residual", [X, g], [Z - float(B[2]) + g])
        condyles = ca.Function("condyles_x", [s.q], [ca.vertcat(s.point(model.hkp.T_L)[0], s.point(model.hkp.T_R)[0])])
        return ca.rootfinder("face_path", "newton", residual, {"abstol": PATH_TOLERANCE, "max_iter": 50,
                                                                "error_on_fail": False}), levels, residual, condyles

    return cached_graph(params, ("food-face-path", side), build)


def _bounded(v, dv, ddv, bound: float):
    """sigma(v) = v (1 + (|v| / L)^8)^(-1/8) (L = ``bound``) and its first and second derivatives along the gap, from
    those of v (N,): the slide v, smoothly kept below L (|sigma| < L; sigma = v (1 - O((|v| / L)^8)) well inside it,
    |sigma| = 0.917 L at |v| = L, 0.996 L at 1.5 L)."""
    w = v * v / bound**2  # (|v| / L)^2
    dw = 2 * v * dv / bound**2
    ddw = 2 * (dv * dv + v * ddv) / bound**2
    psi = (1 + w**4) ** -0.125
    dpsi_dw = -0.5 * w**3 * (1 + w**4) ** -1.125
    ddpsi_dw = -1.5 * w**2 * (1 + w**4) ** -1.125 + 2.25 * w**6 * (1 + w**4) ** -2.125
    dpsi = dpsi_dw * dw
    ddpsi = ddpsi_dw * dw**2 + dpsi_dw * ddw
    return v * psi, dv * psi + v * dpsi, ddv * psi + 2 * dv * dpsi + v * ddpsi


def _capped(x, dx, ddx, cap: float, scale: float = CAP_SCALE):
    """min(x, cap) smoothly, x - s log(1 + e^((x - cap) / s)) (s = ``scale``: within 0.7 s of the cap where x reaches
    it, x itself 3 s below it to 5 % of s), and its first and second derivatives along the gap from x's."""
    z = (x - cap) / scale
    soft = np.logaddexp(0.0, z)
    sig = np.exp(z - soft)  # 1 / (1 + e^-z)
    d1 = 1.0 - sig
    d2 = -sig * (1.0 - sig) / scale
    return x - scale * soft, d1 * dx, d2 * dx**2 + d1 * ddx


def face_path_task(model: Model, side: str, t, g, dg, ddg, contact_gap: float, slide: float,
                   name: str = "texture test") -> Task:
    """The texture test's path (the four coordinates over the stroke) that keeps the lower tooth's face as parallel to
    the upper one as the condyles' sockets and a horizontal slide of the bite point of at most ``slide`` (m) from
    where it is at ``contact_gap`` (m, the sample's top) allow, the bite point at gaps ``g`` (m) with rates ``dg``,
    ``ddg`` at times ``t``.

    The robot can keep its face parallel only by translating it (alpha = beta = 0), and its condyles' planes then
    make the bite point move forward as it goes down, by X(g) (:func:`_face_functions`: about 0.9 mm per mm of gap on
    the target). That translation is capped smoothly (:func:`_capped`) where a condyle would reach the front of its
    socket (less :data:`SOCKET_MARGIN`); the bite point follows the capped translation from where it is at the
    sample's top, its slide from there smoothly bounded by ``slide`` (:func:`_bounded`), and the lower tooth tilts
    (beta, alpha pinned at 0: :func:`molar_path_task` with the bite point's position as its shift) just as far as the
    gap needs there. Where the rotation carries a condyle past the cap's margin, the cap is lowered (the secant on the
    excess) and the path made again (a few passes over the whole path, each vectorised). Within the bound and the sockets the
    face is parallel; beyond them the tilt is the least at that depth for the bite point's position. Every sample is
    solved at once (CasADi's Newton mapped over the samples), the rates from exact first and second derivatives."""
    t = np.asarray(t, float)
    n = t.size
    g, dg, ddg = (np.asarray(x, float).reshape(n) for x in (g, dg, ddg))
    if not slide > 0:
        raise TaskError(f"the slide bound must be positive, not {slide / factor('mm'):g} mm")
    solver, levels, residual, condyles = _face_functions(model, side)
    gaps = np.append(g, contact_gap)[None, :]
    X = np.asarray(solver.map(n + 1)(np.zeros((1, n + 1)), gaps)).ravel()
    miss = np.abs(np.asarray(residual.map(n + 1)(X[None, :], gaps)).ravel())
    if not np.all(miss <= 1e-9):
        k = int(np.argmax(~(miss <= 1e-9)))
        raise KinematicsError(f"the lower tooth cannot be translated to a gap of {gaps[0, k] / factor('mm'):.4g} mm "
                              f"with its face parallel (position error {miss[k]:.3g} m)", sample=min(k, n - 1),
                              time=float(t[min(k, n - 1)]))
    dX, ddX = (np.asarray(a).ravel() for a in levels.map(n + 1)(X[None, :]))
    front = float(model.hkp.x_range[1]) - SOCKET_MARGIN
    cap = front - max(float(model.hkp.T_L[0]), float(model.hkp.T_R[0]))  # the translation that brings a condyle there

    def path(cap: float, k: np.ndarray) -> Task:
        x, dx, ddx = _capped(X[np.append(k, n)], dX[np.append(k, n)], ddX[np.append(k, n)], cap)
        m = k.size
        v, dv, ddv = _bounded(x[:m] - x[m], dx[:m], ddx[:m], slide)
        shift = np.column_stack([x[m] + v, np.zeros(m)])
        rates = np.column_stack([dv * dg[k], np.zeros(m)]), np.column_stack([ddv * dg[k]**2 + dv * ddg[k], np.zeros(m)])
        return molar_path_task(model, side, t[k], g[k], dg[k], ddg[k], name=name, shift=(shift, *rates))

    # the cap is found on every CAP_STRIDE-th sample, the first and the last (the condyles move by micrometres between
    # them), then the path made on all
    coarse = np.unique(np.r_[0:n:CAP_STRIDE, n - 1])
    previous = None
    for _ in range(CAP_PASSES):
        excess = float(np.max(evaluate(condyles, path(cap, coarse).q)[0])) - front
        if excess <= CAP_TOLERANCE:
            break
        # the secant on the excess as a function of the cap (nearly linear: the face's rotation takes back about
        # half of the cap's change), the first pass taking the cap back by the excess itself
        step = excess if previous is None else excess * (cap - previous[0]) / (excess - previous[1])
        previous = (cap, excess)
        cap -= step + CAP_TOLERANCE
    task = path(cap, np.arange(n))
    return Task(name=task.name, t=task.t, coords=task.coords, q=task.q, dq=task.dq, ddq=task.ddq, force=task.force,
                side=side, source="texture test (the face as parallel as the sockets and the slide bound allow)",
                meta={"generator": "tpa", "pin": "alpha", "slide_bound_m": slide})


def largest_gap(model: Model, side: str, upper: float = 0.04, tolerance: float = 1e-5) -> float:
    """The largest gap (m) the bite point of ``side`` reaches along {S}'s z from home with alpha = 0 inside the
    workspace (reach of every chain, transmission, sockets), by bisection to ``tolerance`` (m)."""
    from chewbot.kinematics.motion import solve_kinematics

    def inside(g: float) -> bool:
        try:
            task = molar_path_task(model, side, [0.0, 1.0], [g, g], [0.0, 0.0], [0.0, 0.0])
            solve_kinematics(model, task)
        except KinematicsError:
            return False
        return True

    low, high = 0.0, upper
    if inside(high):
        return high
    while high - low > tolerance:
        mid = (low + high) / 2
        low, high = (mid, high) if inside(mid) else (low, mid)
    return low


def largest_height(model: Model, side: str) -> float:
    """The largest sample height (m) a texture test can take at ``side``: the largest gap less :data:`APPROACH`."""
    return largest_gap(model, side) - APPROACH


__all__ = ["APPROACH", "SIN_TILT_SMOOTHING", "bite_point_function", "bite_point_kernel", "face_path_task", "gap", "home_height",
           "largest_gap", "largest_height", "molar_path_task"]
