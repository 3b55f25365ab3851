"""The plant's integrator: one step of the three-stage Radau IIA method on the equations of motion, compiled.

Why Radau IIA. With friction the equations are stiff near rest: the regularised Coulomb friction of the actuators,
R mu_c abs(F_G) theta_dot / sqrt(theta_dot^2 + eps^2), acts below eps = 1e-3 rad/s as a viscous damper of
R mu_c abs(F_G) / eps (about 0.25 N m s/rad per newton of bearing load) on cranks whose reflected inertia is of order
1e-5 kg m^2, and the HKP friction likewise (eps = 1e-5 m/s): time constants of microseconds, a thousand times below
the control period. An explicit method would need such steps to stay stable; the three-stage Radau IIA method
(Hairer and Wanner, Solving ODEs II, Sect. IV.5: order 5, L-stable, stiffly accurate, the method of RADAU5) damps
these modes at any step and stays fifth-order accurate where the motion is smooth. It is a collocation method: the
step ends on its last stage, where the equations of motion hold exactly.

The equations are those of the Newton–Euler model as a residual r(q, q_dot, q_ddot, N, ...) = 0
(:func:`chewbot.simulation.forward.residual_function`), an index-1 system in which the accelerations and the HKP
normal forces are algebraic unknowns. The stage unknowns are therefore (q_ddot_k, N_k) of the three stages; with the
Radau matrix A and nodes c,

    Q_k = q0 + c_k h v0 + h^2 sum_j (A^2)_kj q_ddot_j,   V_k = v0 + h sum_j A_kj q_ddot_j,
    r(Q_k, V_k, q_ddot_k, N_k, w_k) = 0,  k = 1, 2, 3,

where w_k is what the step is given at the stage's time t0 + c_k h (the held torques and the bite force, or the
reference a controller evaluates at the stage). They are solved by the simplified Newton iteration of RADAU5: the
Jacobian of r with respect to (q_dot, q_ddot, N) at the start of the step gives the iteration matrix
I3 x dr/dz + h A x dr/dv (dr/dq enters with h^2 A^2 and is left out: it changes the iteration's rate by about
h^2 omega^2 ~ 1e-4, not its solution), at most :data:`SIMPLIFIED` corrections; where they have not converged,
at most :data:`NEWTON` full Newton corrections with each stage's own Jacobian; then the residual at the answer, so
that the caller can verify the step and split it where the iteration did not converge (near a stick-slip
transition of the regularised Coulomb friction, where r turns sharply within a step). The whole step is one MX
graph: the residual and its Jacobian are called as functions (compiled once each), the linear algebra is dense QR.

Measured accuracy (tests/test_simulation.py, docs/simulation.md): computed torque with the exact model evaluated at
every stage follows the whole default task to about 1e-12 m and rad; without friction the energy balance over
0.2 s holds to about 2e-10 of the work.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from chewbot.compiled.layout import Layout

# Radau IIA, three stages (Hairer & Wanner, Table IV.5.6): nodes c and matrix A.
_S6 = np.sqrt(6.0)
C = np.array([(4 - _S6) / 10, (4 + _S6) / 10, 1.0])
A = np.array([[(88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225],
              [(296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225],
              [(16 - _S6) / 36, (16 + _S6) / 36, 1 / 9]])
A2 = A @ A
STAGES = 3
# The iteration stops where the stages' residual is below TOLERANCE (N m: the torques are tenths of N m, rounding leaves
# about 1e-15), after at most SIMPLIFIED + NEWTON corrections. Measured along the default task: without friction each
# correction shrinks the residual about 300 times (2 or 3 corrections), with the default friction about 30 times away
# from stick-slip transitions; where the corrections are not enough, the caller splits the step
# (chewbot.simulation.plant).
TOLERANCE = 1e-10
SIMPLIFIED = 5
NEWTON = 4

STEP_OUTPUTS = ("q1", "v1", "z1", "residual")


def radau_step(name: str, stage: ca.Function, n: int, nN: int) -> ca.Function:
    """One Radau IIA step of the index-1 system stage(q, v, a, N, w, s) = 0 as an MX function
    ``name(q0, v0, z0, W, s, h) -> (q1, v1, z1, residual)``.

    ``stage``: the residual (6 values) of the equations of motion at one stage: q, v the coordinates and rates (n),
    a the accelerations (n), N the HKP normal forces (nN), w the stage's own inputs (a column of W, n_w x 3: one per
    stage time t0 + C_k h), s the inputs shared by all stages. z0 = (a, N) near the start (the previous step's end):
    the start is solved exactly from it (one Newton step on dr/dz, exact without friction) before the stages.
    q1, v1 the state at t0 + h, z1 = (a, N) there (the last stage), residual the largest abs(r) over the stages at the
    answer (in the units of r).
    """
    unknowns = Layout.of(a=n, N=nN)  # z: the accelerations and normal forces at one time; Z: every stage's, in order
    stacked = Layout(tuple((f"{name}{k}", size) for k in range(STAGES) for name, size in unknowns.blocks))
    nz = unknowns.size
    sx = [ca.SX.sym(nm, stage.size1_in(i), stage.size2_in(i)) for i, nm in enumerate(("q", "v", "a", "N", "w", "s"))]
    r = stage(*sx)
    jac = ca.Function(f"{name}_jacobian", sx, [r, ca.jacobian(r, sx[1]), ca.jacobian(r, ca.vertcat(sx[2], sx[3]))],
                      {"cse": True})

    q0, v0, z0 = ca.MX.sym("q0", n), ca.MX.sym("v0", n), ca.MX.sym("z0", nz)
    W = ca.MX.sym("W", stage.size1_in(4), STAGES)
    s, h = ca.MX.sym("s", stage.size1_in(5)), ca.MX.sym("h")
    start = unknowns.split(z0)
    r0, Rv, Rz = jac(q0, v0, start["a"], start["N"], W[:, 0], s)
    zs = z0 - ca.solve(Rz, r0, "qr")

    def positions(Z, q0, v0, h):
        blocks = stacked.split(Z)
        acc = [blocks[f"a{k}"] for k in range(STAGES)]
        Q = [q0 + C[k] * h * v0 + h * h * sum(A2[k, j] * acc[j] for j in range(STAGES)) for k in range(STAGES)]
        V = [v0 + h * sum(A[k, j] * acc[j] for j in range(STAGES)) for k in range(STAGES)]
        return Q, V, acc

    def stages(Z, q0, v0, W, s, h):
        Q, V, acc = positions(Z, q0, v0, h)
        blocks = stacked.split(Z)
        return ca.vertcat(*[stage(Q[k], V[k], acc[k], blocks[f"N{k}"], W[:, k], s) for k in range(STAGES)])

    def newton_matrix(Rv, Rz, h):
        """The iteration matrix from dr/dv and dr/dz per stage (one pair for all stages: the simplified iteration)."""
        Rv_z = [ca.horzcat(x, ca.MX(6, nN)) for x in Rv]  # dr/dv acts on the accelerations' columns only
        return ca.vertcat(*[ca.horzcat(*[h * A[k, j] * Rv_z[k] + (Rz[k] if k == j else 0) for j in range(STAGES)])
                            for k in range(STAGES)])

    M_inv = ca.solve(newton_matrix([Rv] * STAGES, [Rz] * STAGES, h), ca.MX.eye(STAGES * nz), "qr")

    # A correction is a function, skipped at run time once the residual is below the tolerance (a Switch: the C code
    # evaluates only the branch taken), so a step costs as many residuals as its iteration needs. First the
    # simplified corrections (the Jacobian of the start); where they have not converged (the regularised Coulomb
    # friction turning sharply within the step), Newton's, with each stage's own Jacobian.
    x = [ca.MX.sym(nm, sz) for nm, sz in (("Z", STAGES * nz), ("r", STAGES * 6), ("q0", n), ("v0", n))]
    x += [ca.MX.sym("W", W.sparsity()), ca.MX.sym("s", s.sparsity()), ca.MX.sym("h"), ca.MX.sym("M_inv", M_inv.sparsity())]
    Z_new = x[0] - ca.mtimes(x[7], x[1])
    simplified = ca.Function(f"{name}_simplified", x, [Z_new, stages(Z_new, *x[2:7])])
    Qx, Vx, acc = positions(x[0], x[2], x[3], x[6])
    local = [jac(Qx[k], Vx[k], acc[k], stacked.split(x[0])[f"N{k}"], x[4][:, k], x[5]) for k in range(STAGES)]
    Z_newton = x[0] - ca.solve(newton_matrix([j[1] for j in local], [j[2] for j in local], x[6]), x[1], "qr")
    newton = ca.Function(f"{name}_newton", x, [Z_newton, stages(Z_newton, *x[2:7])])
    keep = ca.Function(f"{name}_keep", x, [x[0], x[1]])
    Z = ca.repmat(zs, STAGES, 1)
    r = stages(Z, q0, v0, W, s, h)
    for correction, count in ((simplified, SIMPLIFIED), (newton, NEWTON)):
        iteration = ca.Function.if_else(f"{correction.name()}_unless_converged", keep, correction)
        for _ in range(count):
            Z, r = iteration(ca.norm_inf(r) <= TOLERANCE, Z, r, q0, v0, W, s, h, M_inv)
    Q, V, _ = positions(Z, q0, v0, h)
    last = stacked.split(Z)
    z1 = ca.vertcat(last[f"a{STAGES - 1}"], last[f"N{STAGES - 1}"])
    return ca.Function(name, [q0, v0, z0, W, s, h], [Q[-1], V[-1], z1, ca.norm_inf(r)],
                       ["q0", "v0", "z0", "W", "s", "h"], list(STEP_OUTPUTS))
