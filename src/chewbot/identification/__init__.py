"""Identification: the friction and the mandible's inertia of a model from robot logs (docs/identification.md).

The stages, one module each, in the order the data takes: :mod:`~chewbot.identification.log` (reading a log),
:mod:`~chewbot.identification.motion` (poses from the crank angles, rates), :mod:`~chewbot.identification.parameters`
(what is estimated, its place in p, the physical parametrisation), :mod:`~chewbot.identification.regressor` (the
torque model of a sample and its exact derivatives, compiled), :mod:`~chewbot.identification.estimate` (bounded
least squares with the normal forces eliminated, standard errors, identifiability),
:mod:`~chewbot.identification.identifier` (all of them: :func:`identify`) and :mod:`~chewbot.identification.output`
(the model file and the table). The command line is :mod:`~chewbot.commands.identify`. The names below load
on first use, so that the command line starts fast.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "identify": "identifier", "Identification": "identifier",
    "RobotLog": "log", "read_log": "log",
    "LogMotion": "motion", "log_motion": "motion", "fit_poses": "motion",
    "PARAMETERS": "parameters", "x_of": "parameters",
}
__all__ = sorted(_EXPORTS)

# A direction of the parameters is not identifiable where its singular value (unit-norm columns) is below this
# fraction of the largest: the torques then change along it less than 1e-8 of what the best direction changes them.
RCOND = 1e-8
# ... or where its standard error exceeds this fraction of the parameters' reference magnitudes
# (:func:`chewbot.identification.estimate.references`): the log does not tell the value better than that, and the
# start value is kept.
MAX_RELATIVE_SE = 0.3


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"chewbot.identification.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'chewbot.identification' has no attribute {name!r}")
