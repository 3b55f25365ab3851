"""The whole controller step as a self-contained C99 library: what ``chewbot export-controller`` writes.

One call per tick, ``chewbot_ctrl_step(ctx, t, theta_measured, tau_out, status_out)``, does what ``chewbot simulate``
does around its controller with the crank sensor (:mod:`chewbot.simulation.sensor`): the measured crank angles less
the encoder offsets, forward kinematics (Gauss-Newton warm-started from the last estimate, a fixed number of steps,
:func:`chewbot.simulation.sensor.gauss_newton_sx`), the rates by the filtered backward difference, the reference at t
(the task compiled in as a table, quintic Hermite between its samples as :class:`chewbot.simulation.reference.Reference`,
or set by the caller each tick), the control law (:func:`chewbot.simulation.controllers.law.control_function`: PD on the
cranks, or computed torque with the inverse dynamics of the chosen formulation and distribution), saturation, a
torque-rate limit, and the checks of the status word with their safe behaviour (docs/realtime.md, "The exported
controller step").

- :mod:`~chewbot.export.controller.step`: what one exported step is (:class:`StepSpec`), its two CasADi graphs
  (``chewbot_ctrl_fk``, ``chewbot_ctrl_law``), its status bits and the defaults of its configuration;
- :mod:`~chewbot.export.controller.layout`: the context's members in one table, from which the header's structs and
  their ctypes mirror are both generated;
- :mod:`~chewbot.export.controller.sources`: the library's files, rendered from the C, header, Makefile, README and
  example templates in ``templates/`` (package data) and from the graphs generated as C, made to compile with
  ``-std=c99 -Wall -Wextra -Werror -pedantic``. The graphs' work arrays are members of the caller's context: the
  library has no mutable static data, allocates nothing and does no I/O in the step (tests hold all three on the
  object files);
- :mod:`~chewbot.export.controller.library`: the library compiled as a shared object and run through ctypes, and
  :class:`ExportedController`, a controller for :func:`chewbot.simulation.simulator.simulate` (``chewbot simulate
  --exported``) that also evaluates the Python controller on the same measured angles and records both.
"""

from chewbot.export.controller.layout import CONFIG, CONTEXT, OUTPUTS, STRUCTS, Field, Struct, c_typedefs, structures
from chewbot.export.controller.library import ExportedController, SharedLibrary, StepLibrary, build_shared, simulation_log
from chewbot.export.controller.sources import STRICT_FLAGS, export_controller, strict_c, write_sources
from chewbot.export.controller.step import (
    CONDITIONING_MIN, DISTRIBUTION_STEP_TOLERANCE, EXPORT_FORMAT, FK_RESIDUAL_TOLERANCE, FK_STEP_TOLERANCE, MAX_HOLD_TICKS, PREFIX,
    STATUS, STATUS_BITS, TRANSMISSION_MIN, WATCHDOG_PERIODS, StatusBit, StepSpec, fk_function, home_angles, law_function)

__all__ = [
    "CONDITIONING_MIN", "CONFIG", "CONTEXT", "DISTRIBUTION_STEP_TOLERANCE", "EXPORT_FORMAT", "FK_RESIDUAL_TOLERANCE",
    "FK_STEP_TOLERANCE", "MAX_HOLD_TICKS", "OUTPUTS", "PREFIX", "STATUS", "STATUS_BITS", "STRICT_FLAGS", "STRUCTS",
    "TRANSMISSION_MIN", "WATCHDOG_PERIODS", "ExportedController", "Field", "SharedLibrary", "StatusBit", "StepLibrary",
    "StepSpec", "Struct", "build_shared", "c_typedefs", "export_controller", "fk_function", "home_angles", "law_function",
    "simulation_log", "strict_c", "structures", "write_sources",
]
