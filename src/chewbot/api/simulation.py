"""``chewbot.simulate``: what ``chewbot simulate`` does, from Python, in memory unless a folder is asked for.

The options are those of the command line as Python values (a :class:`~chewbot.model.Model` or a built-in name or
file, a :class:`~chewbot.kinematics.task.Task` or a task file or None for the default task, strings or enums),
resolved by the one resolver of the simulation's options (:func:`chewbot.simulation.options.resolve`, whose
:class:`~chewbot.run.options.OptionError` names the option that does not apply). The result is
:class:`chewbot.simulation.run.SimulateResult`: ``table`` (results.csv's columns with their units; ``frame()`` as a
pandas DataFrame), ``simulation`` (the arrays of the loop: ``t``, ``q``, ``tau``, ...), ``metrics`` (the tracking
figures), ``checks`` (the validity checks), ``info`` (what run.json adds). Nothing is written unless ``out`` is given;
then the folder is the command's, written whole, and an existing folder is replaced only with ``force`` and only if
chewbot wrote it.
"""

from __future__ import annotations

from pathlib import Path

from chewbot.dynamics.options import Contact
from chewbot.kinematics.options import Side
from chewbot.kinematics.task import Task
from chewbot.model import Model
from chewbot.progress import SILENT, Progress
from chewbot.run.options import OptionError
from chewbot.simulation.controllers.table import DEFAULT_CONTROLLER, ControllerRow
from chewbot.simulation.engines import DEFAULT_ENGINE, EngineRow
from chewbot.simulation.options import DEFAULT_RATE, resolve
from chewbot.simulation import run
from chewbot.simulation.run import SimulateResult


def simulate(model: Model | str = "target", task: Task | str | None = None, *, controller: ControllerRow | str = DEFAULT_CONTROLLER,
             side: Side | str | None = None, method: str | None = None, goal: str | None = None, friction: bool | str = False,
             contact: Contact | str = Contact.bilateral, rate: float | str | None = DEFAULT_RATE, noise: float = 0.0, seed: int = 0,
             sensor: str | None = None, exported: bool = False, plant: Model | str | None = None,
             engine: EngineRow | str = DEFAULT_ENGINE, overrides: dict[str, float] | None = None,
             plant_overrides: dict[str, float] | None = None, bite_unknown: bool = False, food: str | None = None,
             gains: str | Path | None = None, gain_overrides: dict[str, float] | None = None, compare: bool = False,
             compare_engines: bool = False, out: str | Path | None = None, force: bool = False,
             progress: Progress = SILENT) -> SimulateResult | dict[str, SimulateResult]:
    """Simulate ``controller`` driving the robot of ``plant`` (default: ``model``'s) along ``task`` (None: the default
    task, with the ``task.NAME`` keys of ``overrides``), as ``chewbot simulate`` with the same options: ``rate`` in Hz
    or "continuous", ``noise`` in rad, ``overrides`` and ``plant_overrides`` as ``--set`` and ``--plant-set``,
    ``gain_overrides`` as ``--gain``. ``compare`` / ``compare_engines``: the simulations of ``--compare`` /
    ``--compare-engines``, returned by label. ``out``: also write the results folder there (``force``: replace one
    chewbot wrote). ``progress`` (:class:`chewbot.progress.Progress`) is told each stage."""
    models = [m if isinstance(m, Model) else None for m in (model, plant)]
    for given, keys, option in ((models[0], overrides, "overrides"), (models[1] or models[0], plant_overrides, "plant_overrides")):
        if given is not None and any(not k.startswith("task.") for k in (keys or {})):
            raise OptionError(option, "change a model read from its file: give the model by its name or file, not a Model")
    task_name = "default" if task is None else task.source if isinstance(task, Task) else str(task)
    options = resolve(controller, models[0].source if models[0] else model, task_name,
                      side, method, goal, friction, contact, rate, noise, seed, models[1].source if models[1] else plant, overrides,
                      plant_overrides, bite_unknown, None if gains is None else str(gains), gain_overrides, food, sensor, exported,
                      engine, compare, compare_engines, has_hkp=models[0].has_hkp if models[0] else None)
    from chewbot.export.mjcf import mjcf

    if out is not None:
        from chewbot.files import check_output
        from chewbot.outputs.simulation import SIMULATION_FOLDER
        from chewbot.simulation.run import input_files

        check_output(Path(out), force, SIMULATION_FOLDER, inputs=input_files(options))  # before the work, not after it
    given = {"task": task if isinstance(task, Task) else None, "models": models}
    if compare or compare_engines:
        results = run.compare(options, progress, write_mjcf=mjcf, **given)
        if out is not None:
            from chewbot.outputs.simulation import write_comparison

            write_comparison(results, Path(out), force=force, progress=progress)
        return results
    exported_step = None
    if exported:
        from chewbot.export.controller import ExportedController as exported_step
    result = run.compute(options, progress, exported=exported_step, write_mjcf=mjcf, **given)
    if out is not None:
        from chewbot.outputs.simulation import write

        write(result, Path(out), force=force, progress=progress)
    return result
