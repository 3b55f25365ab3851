"""Inverse dynamics of both mechanisms; each formulation lives in a module of its own and registers itself."""

from chewbot.dynamics.base import METHODS, Dynamics, inverse_dynamics, register

__all__ = ["METHODS", "Dynamics", "inverse_dynamics", "register"]
