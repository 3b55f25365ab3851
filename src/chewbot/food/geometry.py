"""Where the sample is: the bite point's gap, its rates, the lower tooth's tilt, and the molar point moved along z.

The sample sits on the lower molar at the model's bite point B of the side (``model.molar(side)``, in {M}). The
upper tooth is flat and fixed in {S}, at the height B has at the home pose ({M} = {S} there: the pose is occlusal).
The gap is measured along {S}'s z:

    g = B_z(home) - B_z(q),   delta = max(0, h0 - g),

and d(delta)/dt = dB_z/dt; the bite point's velocity in {S}'s x-y plane is the sliding velocity of the sample on the
upper tooth. The laws assume parallel teeth: the lower tooth's tilt is the angle between {M}'s z axis and {S}'s,
arccos(R_33).

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


def bite_point_function(mechanism: str) -> ca.Function:
    """(q, dq, B, p) -> point (3, the bite point in {S}, m), velocity (3, m/s), cos_tilt (R_33), q in Euler angles."""
    m = symbols(mechanism)

    def build():
        s = symbolic(m, ORIENTATION)
        B = ca.SX.sym("B", 3)
        point = s.point(B)
        velocity = ca.jtimes(point, s.q, s.dq)
        return ca.Function("bite_point", [s.q, s.dq, B, m.p], [point, velocity, s.R[2, 2]],
                           ["q", "dq", "B", "p"], ["point", "velocity", "cos_tilt"])

    return cached_graph(m, ("food-bite-point",), build)


def bite_point_kernel(mechanism: str) -> KernelSpec:
    """:func:`bite_point_function` compiled: a whole trajectory's gaps in one C loop."""
    from chewbot.model.symbolic import c_name

    name = f"bite_point_{c_name(mechanism)}"

    def build(params):
        fn = bite_point_function(mechanism)
        x = fn.sx_in()
        return ca.Function(name, x, fn.call(x), fn.name_in(), fn.name_out(), {"cse": True})

    return KernelSpec(name, build, (mechanism, "food-bite-point"), mechanism)


def home_height(model: Model, side: str) -> float:
    """B_z at the home pose (m): {M} coincides with {S} there."""
    return float(np.asarray(model.molar(side), float)[2])


def gap(model: Model, side: str, q, dq=None) -> dict[str, np.ndarray]:
    """The gap g (m), its rate dg/dt (m/s), the sliding velocity (N, 2; m/s) and the lower tooth's tilt (rad) along
    states ``q``, ``dq`` (N, n) in Euler angles."""
    q = np.atleast_2d(np.asarray(q, float))
    dq = np.zeros_like(q) if dq is None else np.atleast_2d(np.asarray(dq, float))
    point, velocity, cos_tilt = evaluate(native(bite_point_kernel(model.mechanism)), q, dq, np.asarray(model.molar(side), float),
                                         model.vector())
    return {"gap": home_height(model, side) - point[:, 2], "rate": -velocity[:, 2], "sliding": velocity[:, :2],
            "tilt": np.arccos(np.clip(cos_tilt[:, 0], -1.0, 1.0))}


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


__all__ = ["APPROACH", "bite_point_function", "bite_point_kernel", "gap", "home_height", "largest_gap", "largest_height", "molar_path_task"]
