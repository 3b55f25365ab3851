"""The torque model of one log sample and its exact derivatives, as compiled kernels.

The residual of sample k is r_k = tau(sample, N_k, x) - tau_measured,k (6 entries, N*m): tau from the
Newton-Euler model with friction (:func:`chewbot.dynamics.formulations.newton_euler.coefficients_kernel` and
:func:`~chewbot.dynamics.formulations.newton_euler.forces_sx`, with its smoothing of the non-smooth terms), N_k = (N_L, N_R)
the normal forces of the HKPs at the sample (free unknowns; none on the 6RSS) and x the identified parameters
(:mod:`chewbot.identification.parameters`) put in place in the model's vector p.

The dynamics are linear in the inertial parameters and in the viscous coefficients, and affine in N apart from
the Coulomb terms mu_H abs(N) and R mu_c abs(F_G(N, x)): d r / d x at N = N_k is the regressor of the inertial
and viscous parameters and the exact linearisation of the rest.

Two problems use it:

* N per sample (:func:`normal_force_kernel`): min over N_k of abs(r_k)^2 with x fixed, by Newton's method on
  every sample at once (:func:`chewbot.identification.estimate.normal_forces`);
* the global problem in x with N eliminated (variable projection): the reduced residual r_k(N_k(x), x) has the
  exact Jacobian d r / d x + d r / d N . d N_k / d x with d N_k / d x = -H_NN^-1 H_Nx from the optimality of
  N_k (g = (d r / d N)' r = 0; H_NN = d g / d N, H_Nx = d g / d x, second-order terms included):
  :func:`jacobian_kernel` gives r, d r / d N, d r / d x, H_NN and H_Nx of a sample.
"""

from __future__ import annotations

import casadi as ca

from chewbot.compiled.kernels import KernelSpec
from chewbot.dynamics.formulations.newton_euler import coefficients_kernel, forces_sx, n_unknowns
from chewbot.identification.parameters import N_X, p_entries
from chewbot.model.vector import N_P
from chewbot.model.symbolic import SymbolicModel, c_name

ORIENTATION = "euler-angles"


def with_x(p: ca.SX, x: ca.SX) -> ca.SX:
    """The symbol p with the entries that x sets replaced by their expressions of x."""
    entries = p_entries()
    return ca.vertcat(*[entries[k](x) if k in entries else p[k] for k in range(N_P)])


def normal_force_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (D, N, tau_measured, friction, p) -> r, dr_dN (6 x nN), H_NN (nN x nN): the residual at
    given normal forces from the Newton-Euler data D (:func:`~chewbot.dynamics.formulations.newton_euler.coefficients_kernel`
    at p with x in place), and what Newton's method on N needs; ``friction`` 0 or 1 switches friction off or on
    (off, r is affine in N)."""
    name = f"identify_{c_name(mechanism)}_normal_forces"

    def build(params):
        m = params
        D = ca.SX.sym("D", coefficients_kernel(mechanism, ORIENTATION).graph().size1_out(0))
        N, tau_m, fl = ca.SX.sym("N", n_unknowns(mechanism)), ca.SX.sym("tau_measured", 6), ca.SX.sym("friction")
        r = forces_sx(m, D, N, fl)["tau"] - tau_m
        dr_dN = ca.jacobian(r, N)
        H = ca.jacobian(ca.mtimes(dr_dN.T, r), N)
        return ca.Function(name, [D, N, tau_m, fl, m.p], [ca.densify(o) for o in (r, dr_dN, H)],
                           ["D", "N", "tau_measured", "friction", "p"], ["r", "dr_dN", "H_NN"], {"cse": True})

    return KernelSpec(name, build, (mechanism, "identify"), mechanism)


def jacobian_kernel(mechanism: str) -> KernelSpec:
    """Per-sample kernel (theta, q, dq, ddq, F_B, B, N, tau_measured, x, p) -> r, dr_dN (6 x nN), dr_dx (6 x N_X),
    H_NN (nN x nN), H_Nx (nN x N_X): see the module docstring. q and its rates in Euler angles."""
    name = f"identify_{c_name(mechanism)}_jacobian"

    def build(params):  # its own p, with x in place of the identified entries
        coefficients = coefficients_kernel(mechanism, ORIENTATION).graph()
        p, x = ca.SX.sym("p", N_P), ca.SX.sym("x", N_X)
        m = SymbolicModel(mechanism, with_x(p, x))
        nN = n_unknowns(mechanism)
        ins = [ca.SX.sym(coefficients.name_in(i), coefficients.sparsity_in(i)) for i in range(6)]
        N, tau_m = ca.SX.sym("N", nN), ca.SX.sym("tau_measured", 6)
        D = coefficients(*ins, m.p)[0]
        r = forces_sx(m, D, N, 1.0)["tau"] - tau_m
        dr_dN = ca.jacobian(r, N)
        g = ca.mtimes(dr_dN.T, r)  # half the gradient of abs(r)^2 in N: zero at N_k
        outs = [r, dr_dN, ca.jacobian(r, x), ca.jacobian(g, N), ca.jacobian(g, x)]
        return ca.Function(name, [*ins, N, tau_m, x, p], [ca.densify(o) for o in outs],
                           [*coefficients.name_in()[:6], "N", "tau_measured", "x", "p"],
                           ["r", "dr_dN", "dr_dx", "H_NN", "H_Nx"], {"cse": True})

    return KernelSpec(name, build, (mechanism, "identify"), mechanism)
