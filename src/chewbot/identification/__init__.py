"""Identification: the friction and the mandible's inertia of a model from robot logs (docs/identification.md).

The stages, one module each, in the order the data takes: :mod:`~chewbot.identification.log` (reading a log),
:mod:`~chewbot.identification.motion` (poses from the crank angles, rates), :mod:`~chewbot.identification.parameters`
(what is estimated, its place in p, the physical parametrisation), :mod:`~chewbot.identification.regressor` (the
torque model of a sample and its exact derivatives, compiled), :mod:`~chewbot.identification.estimate` (bounded
least squares with the normal forces eliminated, standard errors, identifiability),
:mod:`~chewbot.identification.identifier` (all of them: :func:`identify`) and :mod:`~chewbot.identification.output`
(the model file and the table). The command line is :mod:`~chewbot.commands.identify`. This package holds only the
identifiability thresholds, so that the command line reads them without loading the solvers.
"""

from __future__ import annotations

# A direction of the parameters is not identifiable where its singular value (unit-norm columns) is below this
# fraction of the largest: the torques then change along it less than 1e-8 of what the best direction changes them.
RCOND = 1e-8
# ... or where its standard error exceeds this fraction of the parameters' reference magnitudes
# (:func:`chewbot.identification.estimate.references`): the log does not tell the value better than that, and the
# start value is kept.
MAX_RELATIVE_SE = 0.3
