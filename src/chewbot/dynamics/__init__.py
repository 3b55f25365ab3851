"""Inverse dynamics of both mechanisms; each formulation lives in a module of its own and registers itself."""

from chewbot.dynamics.base import METHODS, Dynamics, formulation_kernels, inverse_dynamics, register
from chewbot.dynamics import core6rss, hessian, lagrange, liang, newton_euler  # noqa: F401, E402  (each registers its formulation)

__all__ = ["METHODS", "Dynamics", "formulation_kernels", "inverse_dynamics", "register"]
