"""chewbot: kinematics, inverse dynamics and inertia coupling of the bio-inspired chewing robot.

The names below are imported on first use, so that ``import chewbot`` (and the ``chewbot`` program's start,
which must take over SIGINT before anything heavy loads: :mod:`chewbot.commands.common`) costs nothing.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_LAZY = {
    "ChewbotError": "chewbot.errors",
    "KinematicsError": "chewbot.errors",
    "ParameterError": "chewbot.errors",
    "TaskError": "chewbot.errors",
    "Model": "chewbot.model",
    "BUILTIN_MODELS": "chewbot.model.params",
    "load_model": "chewbot.model.params",
}

__all__ = [*sorted(_LAZY), "__version__"]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'chewbot' has no attribute {name!r}")
