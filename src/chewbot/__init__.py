"""chewbot: kinematics, inverse dynamics and inertia coupling of the bio-inspired chewing robot.

The names below are imported on first use, so that ``import chewbot`` (and the ``chewbot`` program's start,
which must take over SIGINT before anything heavy loads: :mod:`chewbot.__main__`) costs nothing. The verbs of the
Python API (``chewbot.inverse_dynamics(model, q, dq, ddq)``, ...) are those of :mod:`chewbot.api`.
"""

from __future__ import annotations

# The names of chewbot.api (its __all__, checked by the tests), given here without importing it.
API = ("ForwardDynamics", "InverseDynamics", "forward_dynamics", "forward_kinematics", "inverse_dynamics",
       "inverse_kinematics", "load_model", "read_results", "simulate")
ERRORS = ("ChewbotError", "KinematicsError", "ParameterError", "TaskError")

__all__ = sorted(["BUILTIN_MODELS", "Model", "__version__", *ERRORS, *API])


def __getattr__(name: str):
    if name == "__version__":
        from chewbot.files import VERSION

        return VERSION
    if name in ERRORS:
        from chewbot import errors

        return getattr(errors, name)
    if name == "Model":
        from chewbot.model import Model

        return Model
    if name == "BUILTIN_MODELS":
        from chewbot.model.params import BUILTIN_MODELS

        return BUILTIN_MODELS
    if name in API:
        from chewbot import api

        return getattr(api, name)
    raise AttributeError(f"module 'chewbot' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
