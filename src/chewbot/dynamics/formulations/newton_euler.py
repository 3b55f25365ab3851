"""Newton–Euler inverse dynamics with friction at the HKPs and the actuators (seed 001, Sects. 4.1–4.4).

Free bodies and the forces they exchange (all vectors in {S}):

* coupler i, a uniform thin rod S_i M_i (mass m_i, length L_i, unit axis u_i from S_i to M_i): the crank
  pushes on it at S_i with ``f_i`` ("FS"), the mandible at M_i with ``-g_i``. Newton and the two transverse
  Euler equations about its centre E_i (its angular momentum is m L^2/12 u x u_dot; the spin is idle)
  fix the transverse part of g_i; the axial force k_i = g_i . u_i is the one unknown per coupler
  (seed 001, Eqs. 33–36):  u x g_i = u x c_i,  c_i = -(m_i/2)(a_E - g) - (m_i L_i/12) u_ddot,
  f_i = g_i + m_i (a_E - g).
* mandible: the six g_i at M_i, the normal forces N_j n of the two planes at T_j (n = (p1, 0, 1)/|.|,
  N_j > 0 pushes the ball up), their friction forces f_T,j, the bite force F_B at B, gravity
  (Eqs. 28–32): m a_O = sum g_i + sum (N_j n + f_T,j) + F_B + m g,
  I w_dot + w x I w = sum r_i x g_i + sum r_T,j x (N_j n + f_T,j) + r_B x F_B, I = R I_M R'.
  Six equations, linear in k, give k = A^-1 (...) as an affine function of N and |N| (Eqs. 45–49).
* crank i, turning about its shaft z_i at G_i with its mass centre on the shaft (axisymmetric, so
  w x I w = 0): the base holds it at G_i with the force ``F_G,i`` and the moment ``M_G,i`` (across z_i),
  the actuator drives it with tau_i and loses tau_f,i to friction (Eqs. 37–44):
  F_G,i = f_i - m_c,i g,  M_G,i = ((S_i - G_i) x f_i) across z_i,
  tau_i = I_i theta_ddot_i + z_i . ((S_i - G_i) x f_i) + tau_f,i.

Friction (docs/conventions.md): f_T,j = -(mu_c |N_j| + mu_v |v_T,j|) v_T,j/|v_T,j| and
tau_f,i = R_i mu_c,i |F_G,i| sgn(theta_dot_i) + mu_v,i theta_dot_i. The velocity directions are inputs and
are regularised, v/sqrt(|v|^2 + eps^2); the magnitudes |N_j| and |F_G,i| depend on the unknowns and are
smoothed, sqrt(x^2 + delta^2) (max error delta). The constants are below; docs/newton_euler.md explains them.

The unknowns N_L, N_R (two for the target, none for the 6RSS) are distributed by
:mod:`chewbot.dynamics.distribution`; the six torques then follow in closed form (Eq. 50).
The equations are built from the kinematics of the chosen parametrisation (Euler angles or Euler
parameters, :func:`chewbot.kinematics.symbolic.symbolic`), each a complete model of its own.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from chewbot.dynamics.indices import friction_share, performance_indices
from chewbot.compiled.kernels import KernelSpec, evaluate, native
from chewbot.dynamics.base import Dynamics
from chewbot.dynamics.contact import add_normal_forces, bound_names
from chewbot.dynamics.options import check_contact, check_goal
from chewbot.dynamics.distribution import Problem, ProblemGraph, SampleData, build_problem, problem_kernels, solve
from chewbot.kinematics.motion import Kinematics
from chewbot.kinematics.symbolic import symbolic
from chewbot.model import Model
from chewbot.compiled.cache import cached_graph, symbols
from chewbot.model.symbolic import SymbolicModel, c_name, parameter_input
from chewbot.table import Table

# Regularisation of sgn(theta_dot) and v_T/|v_T| (known inputs per sample): below these speeds Coulomb
# friction fades linearly to zero instead of jumping (static friction is indeterminate at rest anyway).
EPS_THETA_DOT = 1e-3  # rad/s
EPS_V_T = 1e-5  # m/s
# Smoothing of |N_j| and |F_G,i| (functions of the unknowns): sqrt(x^2 + delta^2) - |x| lies in (0, delta],
# so the friction forces are off by at most mu_c delta = 1e-4 N (HKP) and R mu_c delta = 2.5e-7 N m (actuator).
DELTA_N = 1e-3  # N
DELTA_F_G = 1e-3  # N

LIMIT_NAMES = ("torque", "power", "axial_load", "radial_load")


def n_unknowns(mechanism: str) -> int:
    """Number of HKP normal forces to distribute: 2 for the target, 0 for the 6RSS."""
    return 2 if mechanism == "target" else 0


def _layout(nN: int) -> dict[str, tuple[int, int]]:
    """Offsets of the blocks of the per-sample data vector D (what the distribution needs of a sample)."""
    sizes = {"f0": 18, "fV": 18, "F1": 18 * nN, "F2": 18 * nN, "fE": 18, "r_GS": 18, "inertial": 6, "dtheta": 6}
    out, at = {}, 0
    for key, size in sizes.items():
        out[key] = (at, at + size)
        at += size
    out["size"] = (at, at)
    return out


def coefficients_kernel(mechanism: str, orientation: str) -> KernelSpec:
    """Per-sample kernel (theta, q, dq, ddq, F_B, B, p) -> D: the sample's equations with N and |N| left free.

    D packs (see :func:`_layout`) the forces f_i at S_i as f = f0 + fV + F1 N + F2 |N| (fV: the share of
    the HKP viscous friction, F2: of the HKP Coulomb friction, both to be switched with the friction flag),
    m_i (a_E,i - g) (so that the force on the mandible at M_i is f_i - m_i (a_E,i - g)), the crank vectors S_i - G_i, the crank inertia torques I_i theta_ddot_i and theta_dot. Also returned:
    the unit direction v_T/|v_T| (regularised, 3 x nN) and velocity v_T (3 x nN) of the ball centres.
    """
    name = f"ne_coefficients_{c_name(mechanism)}_{orientation.replace('-', '_')}"

    def build(params):
        s = symbolic(params, orientation)
        m = s.params
        nN = n_unknowns(m.mechanism)
        F_B, B = ca.SX.sym("F_B", 3), ca.SX.sym("B", 3)
        dth, ddth = s.theta_rates()
        tw, twr = s.twist(), s.twist_rate()
        v_O, w, a_O, dw = tw[0:3], tw[3:6], twr[0:3], twr[3:6]
        grav = ca.vertcat(0.0, 0.0, -m.g)
        I_S = ca.mtimes([s.R, m.mandible_inertia, s.R.T])
        r_B = ca.mtimes(s.R, B)

        cols_A, rest_F, rest_M, f_const, u_all, r_GS, fE = [], ca.SX.zeros(3), ca.SX.zeros(3), [], [], [], []
        for i in range(6):
            z = m.R_C0[i][:, 2]
            rGS = s.crank_tip(i) - m.G[i]
            a_S = ddth[i] * ca.cross(z, rGS) - dth[i] ** 2 * rGS
            r_i = ca.mtimes(s.R, m.M[i])
            a_M = a_O + ca.cross(dw, r_i) + ca.cross(w, ca.cross(w, r_i))
            L, mc = m.coupler_length[i], m.coupler_mass[i]
            u = (s.p + r_i - s.crank_tip(i)) / L
            u_ddot = (a_M - a_S) / L
            a_E = (a_S + a_M) / 2
            c = -(mc / 2) * (a_E - grav) - (mc * L / 12) * u_ddot
            g_perp = c - ca.dot(u, c) * u  # transverse force on the mandible, fixed by the rod's Euler equations
            cols_A.append(ca.vertcat(u, ca.cross(r_i, u)))
            rest_F += g_perp
            rest_M += ca.cross(r_i, g_perp)
            fE.append(mc * (a_E - grav))
            f_const.append(g_perp + fE[-1])
            u_all.append(u)
            r_GS.append(rGS)
        A = ca.horzcat(*cols_A)
        wrench = ca.vertcat(
            m.mandible_mass * (a_O - grav) - F_B - rest_F,
            ca.mtimes(I_S, dw) + ca.cross(w, ca.mtimes(I_S, w)) - ca.cross(r_B, F_B) - rest_M,
        )
        fr = m.friction
        rhs = [wrench, ca.SX.zeros(6)]
        P, Q, vhat, v_T = [], [], [], []
        if nN:
            n = m.hkp.normal
            for T in (m.hkp.T_L, m.hkp.T_R):
                r_T = ca.mtimes(s.R, T)
                v = v_O + ca.cross(w, r_T)
                e = v / ca.sqrt(ca.sumsqr(v) + EPS_V_T**2)
                P.append(ca.vertcat(n, ca.cross(r_T, n)))
                Q.append(ca.vertcat(e, ca.cross(r_T, e)))
                rhs[1] += fr.hkp_viscous * ca.vertcat(v, ca.cross(r_T, v))
                vhat.append(e)
                v_T.append(v)
            # A k = wrench - P N - sum_j wrench of f_T,j, f_T,j = -mu_c |N_j| e_j - mu_v v_j
            rhs += [-ca.horzcat(*P), fr.hkp_coulomb * ca.horzcat(*Q)]
        X = ca.solve(A, ca.horzcat(*rhs))
        k0, kV = X[:, 0], X[:, 1]
        U = ca.horzcat(*u_all)  # 3 x 6
        f0 = ca.vertcat(*[k0[i] * U[:, i] + f_const[i] for i in range(6)])
        fV = ca.vertcat(*[kV[i] * U[:, i] for i in range(6)])
        blocks = [f0, fV]
        if nN:
            blocks += [ca.vec(ca.vertcat(*[ca.mtimes(U[:, i], X[i, 2 + 2 * j: 4 + 2 * j]) for i in range(6)]))
                       for j in range(2)]
        inertial = m.crank_total_inertia * ddth
        D = ca.vertcat(*blocks, *fE, *r_GS, inertial, dth)
        vh = ca.horzcat(*vhat) if nN else ca.SX(3, 0)
        vt = ca.horzcat(*v_T) if nN else ca.SX(3, 0)
        extra, names = parameter_input(m)
        return ca.Function(name, [s.theta, s.q, s.dq, s.ddq, F_B, B, *extra], [ca.densify(x) for x in (D, vh, vt)],
                           ["theta", "q", "dq", "ddq", "F_B", "B", *names], ["D", "vhat_T", "v_T"], {"cse": True})

    return KernelSpec(name, build, (mechanism, orientation), mechanism)


def _unpack(D, nN: int) -> dict:
    lay = _layout(nN)
    out = {key: D[a:b] for key, (a, b) in lay.items() if key != "size"}
    out["F1"] = ca.reshape(out["F1"], 18, nN)
    out["F2"] = ca.reshape(out["F2"], 18, nN)
    return out


def forces_sx(params: SymbolicModel, D, N, friction, absN=None):
    """Every force of the sample as CasADi expressions of the data D, the normal forces N, the friction
    flag (0 or 1) and the model's numbers ``params``: a dict of tau, tau_f, tau_fT (HKP friction mapped onto the
    shafts), f (FS), F_G, M_G, axial and radial loads at G_i, |N| smoothed, f_M (force of coupler i on the
    mandible at M_i). Shared by the solver, its limits and the outputs. ``absN`` replaces the smoothed |N|
    (for :func:`start_sx`).
    """
    m, fr = params, params.friction
    nN = N.numel()
    d = _unpack(D, nN)
    absN = ca.sqrt(N**2 + DELTA_N**2) if absN is None else absN
    f_fT = friction * (d["fV"] + (ca.mtimes(d["F2"], absN) if nN else 0))  # HKP friction's share of f
    f = d["f0"] + f_fT + (ca.mtimes(d["F1"], N) if nN else 0)
    dth = d["dtheta"]
    sgn = dth / ca.sqrt(dth**2 + EPS_THETA_DOT**2)
    tau, tau_f, tau_fT, F_G, M_G, axial, radial = [], [], [], [], [], [], []
    for i in range(6):
        x, y, z = (m.R_C0[i][:, k] for k in range(3))
        fi, ri = f[3 * i: 3 * i + 3], d["r_GS"][3 * i: 3 * i + 3]
        FG = fi + ca.vertcat(0.0, 0.0, m.crank_mass[i] * m.g)
        tf = friction * (fr.actuator_arm * fr.actuator_coulomb * ca.sqrt(ca.sumsqr(FG) + DELTA_F_G**2) * sgn[i]
                         + fr.actuator_viscous * dth[i])
        tau.append(d["inertial"][i] + ca.dot(ca.cross(z, ri), fi) + tf)
        tau_f.append(tf)
        tau_fT.append(ca.dot(ca.cross(z, ri), f_fT[3 * i: 3 * i + 3]))
        F_G.append(FG)
        M_G.append(ca.vertcat(ca.dot(ca.cross(x, ri), fi), ca.dot(ca.cross(y, ri), fi)))
        ax = ca.dot(z, FG)
        axial.append(ax)
        radial.append(ca.sqrt(ca.sumsqr(FG - ax * z)))
    return {"tau": ca.vertcat(*tau), "tau_f": ca.vertcat(*tau_f), "tau_fT": ca.vertcat(*tau_fT), "f": f,
            "F_G": ca.vertcat(*F_G), "M_G": ca.vertcat(*M_G), "axial": ca.vertcat(*axial),
            "radial": ca.vertcat(*radial), "absN": absN, "f_M": f - d["fE"]}


def forces_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (D, N, friction, p) -> tau, tau_f, tau_fT, f (FS), F_G, M_G, axial, radial, |N|, f_M."""
    name = f"ne_forces_{c_name(mechanism)}"

    def build(params):
        m = params
        nN = n_unknowns(m.mechanism)
        D, N, fl = ca.SX.sym("D", _layout(nN)["size"][0]), ca.SX.sym("N", nN), ca.SX.sym("friction")
        out = forces_sx(m, D, N, fl)
        extra, names = parameter_input(m)
        return ca.Function(name, [D, N, fl, *extra], [ca.densify(x) for x in out.values()], ["D", "N", "friction", *names],
                           list(out), {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


def sample_data(model: Model, kin: Kinematics, side: str | None = None):
    """Per-sample data D (N, k), ball-centre directions and velocities (N, 3, nN) along the task."""
    B = model.molar(side or kin.side)
    fn = native(coefficients_kernel(model.mechanism, kin.orientation))
    D, vhat, v_T = evaluate(fn, kin.theta, kin.q, kin.dq, kin.ddq, kin.force, B, model.vector())
    return SampleData(D, model.vector()), vhat, v_T


def limit_bounds(model: Model) -> np.ndarray:
    """The bounds of the distribution's 24 limits (:func:`problem`), from the model's actuator limits."""
    lim = model.limits
    return np.repeat([lim.torque, lim.power, lim.axial_load, lim.radial_load], 6).astype(float)


def problem(mechanism: str, goal: str) -> Problem:
    """The distribution problem of ``goal`` on a mechanism (seed 001, Eqs. 52–54), with the actuator limits.

    Goals: ``min-torque`` (G1, |tau|^2), ``min-coupler-force`` (G2, sum |f_i|^2 over S_1..S_6),
    ``min-hkp-force`` (G3, N_L^2 + N_R^2). Limits (docs/conventions.md): |tau_i| <= torque, |tau_i theta_dot_i| <= power,
    |F_G,i . z_i| <= axial load, |F_G,i x z_i| <= radial load (bounds: :func:`limit_bounds` of a model).
    """
    check_goal(goal)
    names = [f"{what} (actuator {i + 1})" for what in LIMIT_NAMES for i in range(6)]
    return cached_graph(symbols(mechanism), ("ne-problem-kernels", goal), lambda: build_problem(
        _problem_name(mechanism, goal), _problem_graph(mechanism, goal), n_unknowns(mechanism), names, has_start=True,
        key=(mechanism, goal)))


def _problem_name(mechanism: str, goal: str) -> str:
    return f"ne_{c_name(mechanism)}_{goal.replace('-', '_')}"


def _problem_graph(mechanism: str, goal: str):
    """A function that builds (once) the expressions of the distribution problem of ``goal``."""
    nN = n_unknowns(mechanism)

    def build():
        m = symbols(mechanism)
        D, N, fl = ca.SX.sym("D", _layout(nN)["size"][0]), ca.SX.sym("N", nN), ca.SX.sym("friction")
        out = forces_sx(m, D, N, fl)
        dth = _unpack(D, nN)["dtheta"]
        limits = ca.vertcat(out["tau"], out["tau"] * dth, out["axial"], out["radial"])
        return ProblemGraph(D, N, fl, [m.p], goal_residual(m, goal, D, N, fl), limits,
                            start_sx(m, goal, D) if nN else ca.SX(0, 1))

    return lambda: cached_graph(symbols(mechanism), ("ne-problem", goal), build)


def kernels(mechanism: str, orientation: str, goal: str = "min-torque") -> list[KernelSpec]:
    """The compiled kernels of a Newton–Euler run: the sample's coefficients, the forces and the distribution
    problem of ``goal``."""
    return [coefficients_kernel(mechanism, orientation), forces_kernel(mechanism),
            *problem_kernels(_problem_name(mechanism, goal), _problem_graph(mechanism, goal), (mechanism, goal))]


GOAL_RESIDUALS = {"min-torque": "tau", "min-coupler-force": "f"}


def goal_residual(params: SymbolicModel, goal: str, D, N, friction, absN=None):
    """The residual r whose squared norm the goal minimises (seed 001, Eqs. 52-54)."""
    if goal == "min-hkp-force":
        return N
    return forces_sx(params, D, N, friction, absN)[GOAL_RESIDUALS[goal]]


def start_sx(params: SymbolicModel, goal: str, D) -> ca.SX:
    """A start for the distribution: the best of nine piecewise least-squares candidates (2 unknowns).

    With friction the goal's residual is affine in N and |N| (apart from the small, smooth actuator-friction
    term): on each sign pattern of (N_L, N_R), and on each kink N_j = 0, it is affine in N, so one Gauss-Newton
    step from 0 gives that piece's minimiser. The candidate with the smallest (smoothed) goal is the start.
    The optimum often lies on a kink (one condyle nearly unloaded), where Newton from the friction-free optimum
    converges slowly or to another local minimum; from this start it converges in a few steps.
    """
    N = ca.SX.sym("N", n_unknowns(params.mechanism))
    best, best_J = None, None
    # (0, 0) first: always finite, so a singular piece (NaN) never becomes the start (NaN < x is false)
    for signs in ((0, 0), (1, 1), (1, -1), (-1, 1), (-1, -1), (0, 1), (0, -1), (1, 0), (-1, 0)):
        free = [j for j in range(2) if signs[j]]
        Nc = ca.vertcat(*[N[j] if signs[j] else 0 for j in range(2)])
        r = goal_residual(params, goal, D, Nc, 1.0, absN=ca.vertcat(*[signs[j] * N[j] for j in range(2)]))
        cand = ca.SX.zeros(2)
        if free:
            r0, A = ca.substitute([r, ca.jacobian(r, N[free])], [N], [ca.DM.zeros(2)])
            step = -ca.solve(ca.mtimes(A.T, A), ca.mtimes(A.T, r0))
            for k, j in enumerate(free):
                cand[j] = step[k]
        J = ca.sumsqr(goal_residual(params, goal, D, cand, 1.0))
        if best is None:
            best, best_J = cand, J
        else:
            better = J < best_J
            best, best_J = ca.if_else(better, cand, best), ca.if_else(better, J, best_J)
    return best


def newton_euler(model: Model, kin: Kinematics, *, side: str | None = None, goal: str = "min-torque",
                 friction: bool = True, contact: str = "bilateral", strict: bool = False, carry: dict | None = None,
                 check=None) -> Dynamics:
    """Newton–Euler inverse dynamics with friction and optimal distribution (seed 001, Sect. 4).

    ``goal``: see :func:`problem` (the 6RSS has nothing to distribute: its torques are closed form);
    ``friction``: HKP and actuator friction on or off; ``contact``: ``"unilateral"`` adds N_L, N_R >=
    ``model.contact.preload`` to the distribution's constraints (:mod:`chewbot.dynamics.contact`); ``strict``: raise
    :class:`~chewbot.errors.InfeasibleError` at a sample with no admissible distribution instead of recording
    it in ``info["infeasible"]``; ``carry``: the previous chunk's ``Dynamics.carry`` (its last distribution, the
    warm start of the SQP at this chunk's first sample); ``check``: called between the samples the SQP solves (see
    :func:`chewbot.dynamics.distribution.solve`). Columns of the table: see docs/newton_euler.md.
    """
    check_goal(goal)
    check_contact(contact)
    fl = 1.0 if friction else 0.0
    data, vhat, v_T = sample_data(model, kin, side)
    unilateral = contact == "unilateral" and model.has_hkp
    preload = model.contact.preload
    sol = solve(problem(model.mechanism, goal), data, fl, kin.t, limit_bounds(model), strict=strict,
                lower=np.full(2, preload) if unilateral else None, lower_names=bound_names(preload),
                previous=(carry or {}).get("x"), check=check)
    forces = native(forces_kernel(model.mechanism))
    out = dict(zip(forces.name_out(), data(forces, sol.x, fl)))
    table = Table()
    table.add_block([f"tau_f{i + 1}" for i in range(6)], out["tau_f"], "N*m", "actuator friction torque (in tau)")
    table.add_block([f"tau_fT{i + 1}" for i in range(6)], out["tau_fT"], "N*m",
                    "HKP friction mapped onto the actuator shaft (in tau)")
    fT = np.zeros((kin.n, 3, 0))
    if model.has_hkp:
        fr = model.friction
        fT = -fl * (fr.hkp_coulomb * out["absN"][:, None, :] * vhat + fr.hkp_viscous * v_T)
        add_normal_forces(table, sol.x)
        table.add_block([f"fT_{j}_{c}" for j in "LR" for c in "xyz"], fT.transpose(0, 2, 1).reshape(kin.n, 6), "N",
                        "HKP friction force on the condyle, {S}")
    table.add_block([f"FS{i + 1}_{c}" for i in range(6) for c in "xyz"], out["f"], "N", "force of crank i on coupler i at S_i, {S}")
    table.add_block([f"FM{i + 1}_{c}" for i in range(6) for c in "xyz"], out["f_M"], "N", "force of coupler i on the mandible at M_i, {S}")
    table.add_block([f"FG{i + 1}_{c}" for i in range(6) for c in "xyz"], out["F_G"], "N", "force of the base on crank i at G_i, {S}")
    table.add_block([f"MG{i + 1}_{c}" for i in range(6) for c in "xy"], out["M_G"], "N*m",
                    "constraint moment of the base on crank i at G_i, about x, y of {C_i0}")
    table.add_block([f"FG{i + 1}_axial" for i in range(6)], out["axial"], "N", "F_G,i along the shaft z_i")
    table.add_block([f"FG{i + 1}_radial" for i in range(6)], out["radial"], "N", "abs(F_G,i) across the shaft z_i")
    share = friction_share(out["tau"], out["tau_f"], out["tau_fT"])
    table.add_block([f"friction_share{i + 1}" for i in range(6)], share, "%", "friction torque over actuating torque (seed 001, Eq. 75)")
    indices = performance_indices(out["tau"], out["f"], sol.x, out["tau_f"], out["M_G"], out["F_G"],
                                  fT.reshape(kin.n, -1) if model.has_hkp else None)
    info = {"goal": goal if model.has_hkp else "none (6RSS: closed form)", "friction": bool(friction),
            "orientation": kin.orientation, "indices": indices,
            "newton_iterations": sol.newton_iterations, "unconverged": sol.unconverged,
            "constrained_samples": len(sol.constrained), "infeasible": sol.infeasible,
            "smoothing": {"eps_theta_dot_rad_s": EPS_THETA_DOT, "eps_v_T_m_s": EPS_V_T, "delta_N_N": DELTA_N,
                          "delta_F_G_N": DELTA_F_G}}
    if model.has_hkp:
        info["contact"] = ({"model": "unilateral", "preload_N": preload,
                            "distribution": f"goal {goal} with N_L, N_R >= contact.preload_N as constraints"} if unilateral
                           else {"model": "bilateral", "normal_forces": "N_L, N_R are unknowns of the distribution"})
    return Dynamics("newton-euler", out["tau"], table, info, carry={"x": sol.x[-1].copy()} if kin.n else {})
