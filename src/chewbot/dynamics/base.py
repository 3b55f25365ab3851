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
