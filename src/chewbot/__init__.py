"""chewbot: kinematics, inverse dynamics and inertia coupling of the bio-inspired chewing robot.

The names below are imported on first use, so that ``import chewbot`` (and the ``chewbot`` program's start,
which must take over SIGINT before anything heavy loads: :mod:`chewbot.__main__`) costs nothing.
"""

from __future__ import annotations

__all__ = ["BUILTIN_MODELS", "ChewbotError", "KinematicsError", "Model", "ParameterError", "TaskError", "__version__",
           "load_model", "read_results", "simulate"]


def __getattr__(name: str):
    if name == "__version__":
        from chewbot.files import VERSION

        return VERSION
    if name in ("ChewbotError", "KinematicsError", "ParameterError", "TaskError"):
        from chewbot import errors

        return getattr(errors, name)
    if name == "Model":
        from chewbot.model import Model

        return Model
    if name in ("BUILTIN_MODELS", "load_model"):
        from chewbot.model import params

        return getattr(params, name)
    if name == "simulate":
        from chewbot.api.simulation import simulate

        return simulate
    if name == "read_results":
        from chewbot.outputs.record import read_frame

        return read_frame
    raise AttributeError(f"module 'chewbot' has no attribute {name!r}")
