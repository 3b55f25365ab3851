"""What every inverse-dynamics formulation returns (:class:`Dynamics`), and what their per-sample graphs share
(:class:`Sample`: one sample's inputs and kinematics, as a controller's inverse dynamics takes them).

A formulation is a function ``f(model, kin, *, side=None, contact="bilateral", ...) -> Dynamics``: the model, the
kinematics of the whole task (:class:`~chewbot.kinematics.motion.Kinematics`), and the keyword options it takes (a
misspelt one is a TypeError). The formulations are named in one table, :mod:`chewbot.dynamics.registry`: adding one
is adding its module and a row there.

A run may give a long task in chunks of consecutive samples (:mod:`chewbot.run.pipeline`), one call per chunk. A
formulation whose samples depend on earlier ones (a solver warm-started from the previous sample's solution) takes
the option ``carry``, the previous chunk's :attr:`Dynamics.carry` (None for the task's first chunk), and returns
in ``carry`` what the next chunk needs: the chunks then give the results of the whole task in one call.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.kinematics.options import Orientation
from chewbot.compiled.cache import symbols
from chewbot.model.symbolic import SymbolicModel
from chewbot.table import Table


@dataclass(frozen=True, eq=False)
class Dynamics:
    """Result of an inverse-dynamics formulation along a task.

    ``tau``: (N, 6) actuator torques, N m. ``table``: further named columns with units (forces, friction,
    multipliers ...) that go into ``results.csv``. ``info``: scalars and notes for run.json and reports.
    ``carry``: the state the next chunk of the same task starts from (see the module docstring), e.g. the last
    sample's solution as a warm start; empty for a formulation whose samples are independent.
    """

    method: str
    tau: np.ndarray
    table: Table = field(default_factory=Table)
    info: dict = field(default_factory=dict)
    carry: dict = field(default_factory=dict)



@dataclass(frozen=True, eq=False)
class Sample:
    """One sample as a controller's inverse dynamics takes it: the symbols q, dq, ddq (the mechanism's independent
    coordinates in Euler angles and their rates), B (the bite point in {M}), F_B (the bite force in {S}), the
    model's numbers ``params`` (the symbol p), and the sample's kinematics (:data:`KINEMATICS_OUTPUTS` by name) as
    expressions of them. :meth:`function` makes the formulation's torques of these symbols one CasADi function."""

    params: SymbolicModel
    q: ca.SX
    dq: ca.SX
    ddq: ca.SX
    B: ca.SX
    F: ca.SX
    kinematics: dict

    @classmethod
    def of(cls, mechanism: str) -> Sample:
        m = symbols(mechanism)
        q, dq, ddq = (ca.SX.sym(name, m.dof) for name in ("q", "dq", "ddq"))
        B, F = ca.SX.sym("B", 3), ca.SX.sym("F_B", 3)
        kin = dict(zip(KINEMATICS_OUTPUTS, kinematics_kernel(mechanism, Orientation.euler_angles.value).graph()(q, dq, ddq, m.p)))
        return cls(m, q, dq, ddq, B, F, kin)

    def function(self, tau: ca.SX) -> ca.Function:
        """(q, dq, ddq, B, F_B, p) -> tau (N m)."""
        return ca.Function("inverse_dynamics", [self.q, self.dq, self.ddq, self.B, self.F, self.params.p], [tau],
                           ["q", "dq", "ddq", "B", "F_B", "p"], ["tau"])


def minimum_norm_sx(J_theta1, rhs, redundant: bool):
    """The least-norm tau with J_theta1' tau = rhs (Eq. 54; the unique solution where J_theta1 is square)."""
    return ca.mtimes(J_theta1, ca.solve(ca.mtimes(J_theta1.T, J_theta1), rhs)) if redundant else ca.solve(J_theta1.T, rhs)


def householder_minimum_norm_sx(J_theta1, rhs):
    """The least-norm tau with J_theta1' tau = rhs (m x n, m >= n, full column rank; Eq. 54) by Householder QR
    unrolled in the graph: J_theta1 = Q [R; 0], tau = Q [R'^-1 rhs; 0], as :func:`chewbot.dynamics.formulations.dalembert.minimum_norm`
    computes it with LAPACK. Backward stable without pivoting (its rounding grows with the condition number of
    J_theta1, not with its square as the normal equations of :func:`minimum_norm_sx` and CasADi's symbolic solve do);
    each reflection's sign is chosen against cancellation (v = x + sign(x_1) abs(x) e_1)."""
    A = ca.SX(J_theta1)
    m, n = A.shape
    reflections = []
    for k in range(min(n, m - 1)):  # a last column of one entry (m = n) is already triangular
        x = A[k:, k]
        sign = ca.if_else(x[0] >= 0, 1, -1)
        v = ca.vertcat(x[0] + sign * ca.norm_2(x), x[1:])
        v = v / ca.norm_2(v)
        A[k:, k:] = A[k:, k:] - 2 * ca.mtimes(v, ca.mtimes(v.T, A[k:, k:]))
        reflections.append(v)
    y = []  # R' y = rhs, R' lower triangular: forward substitution
    for i in range(n):
        y.append((rhs[i] - sum((A[j, i] * y[j] for j in range(i)), ca.SX(0))) / A[i, i])
    tau = ca.vertcat(*y, ca.SX(m - n, 1))
    for k in reversed(range(len(reflections))):  # tau = H_0 H_1 ... H_(n-1) [y; 0]
        v = reflections[k]
        tau[k:] = tau[k:] - 2 * v * ca.mtimes(v.T, tau[k:])
    return tau
