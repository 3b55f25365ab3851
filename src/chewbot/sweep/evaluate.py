"""Evaluating a SPEC's model at many parameter sets: what a Dask worker runs for a chunk of evaluations.

:func:`evaluate_chunk` is the function the cluster maps over chunks: a SPEC and the parameter values of a
chunk's evaluations (rows) in, one column per output and an ``error`` column out. Each worker process keeps an
:class:`Evaluator` per SPEC: the parameter file parsed once, the task built once per set of task parameters, the
compiled kernels loaded once; an evaluation then costs the model's validation (about a millisecond, no graph is
built: the kernels take the parameter vector as an input) and the run's stages its outputs need.

An evaluation computes what ``chewbot run --set KEY=VALUE ...`` computes, with the same functions on the same
inputs, so its outputs equal the run's numbers. One that fails (a pose out of reach, a value the model refuses,
anything else) gives NaN outputs and its reason in ``error``: it never stops the sweep.
"""

from __future__ import annotations

from functools import cached_property
from pathlib import Path

import numpy as np

from chewbot.errors import ChewbotError
from chewbot.sweep.quantities import OUTPUTS
from chewbot.sweep.spec import COUNTERPARTS, Spec


class Evaluator:
    """Everything that stays the same over a SPEC's evaluations, and :meth:`evaluate` for a chunk of them."""

    def __init__(self, spec: Spec):
        from chewbot.model.params import read_parameter_file, resolve_model_path

        self.spec = spec
        self._raw = {}
        for name in (spec.model, spec.counterpart or COUNTERPARTS.get(spec.model)):
            if name is not None:
                path = resolve_model_path(name)
                raw = read_parameter_file(path)
                self._raw[name] = (path, raw.pop("__sha256__"), raw)
        self._tasks: dict = {}
        self.options = spec.run_options()
        # the formulation's Rates where the fused kernel gives what the outputs need (Evaluation.fused)
        self.rates = None
        if self.options.method and not any(OUTPUTS[name].whole for name in spec.computed_outputs):
            from chewbot.dynamics.registry import reduction_rates

            self.rates = reduction_rates(self.options.method, self.options.contact)

    def fused(self, model, kin) -> tuple[np.ndarray, np.ndarray] | None:
        """tau and MCI of the kinematics ``kin`` of ``model`` by the fused kernel, or None where it does not apply
        (:attr:`Evaluation.fused`)."""
        if self.rates is None:
            return None
        from chewbot.analysis.coupling import torques_coupling

        return torques_coupling(model, kin, self.options.method, self.rates)

    def kernels(self, model) -> list:
        """The compiled kernels the evaluations of ``model`` use besides the run's (prepared before the sweep)."""
        if self.rates is None:
            return []
        from chewbot.analysis.coupling import torques_coupling_kernel

        return [torques_coupling_kernel(model.mechanism, self.options.method, self.rates)]

    def model(self, overrides: dict[str, float], name: str | None = None):
        """The model (``name``: the SPEC's by default) with ``overrides``, as ``load_model(name, overrides)`` gives it."""
        from chewbot.model.params import apply_overrides, model_from_dict

        path, sha256, raw = self._raw[name or self.spec.model]
        if not overrides:
            return model_from_dict(raw, source=str(path), sha256=sha256)
        label = f"{path} (with {', '.join(f'--set {k}={v:g}' for k, v in overrides.items())})"
        return model_from_dict(apply_overrides(raw, overrides), source=str(path), sha256=sha256, label=label, overrides=overrides)

    def task(self, mechanism: str, overrides: dict[str, float]):
        """The SPEC's task for a mechanism (kept: it does not depend on the model's numbers). The default task is
        built in the target's four coordinates, which the kinematics lift to six on the 6RSS with its sockets."""
        key = (mechanism if self.spec.task != "default" else "", tuple(sorted(overrides.items())))
        if key not in self._tasks:
            if len(self._tasks) > 64:  # task parameters varied continuously: nothing to reuse
                self._tasks.clear()
            if self.spec.task == "default":
                from chewbot.task.default import default_task, parameters_with

                task = default_task(None, self.spec.side or "left", parameters_with(overrides) if overrides else None)
            else:
                from chewbot.task.csvio import read_task_csv

                task = read_task_csv(Path(self.spec.task), side=self.spec.side, mechanism=mechanism)
            self._tasks[key] = task
        return self._tasks[key]

    def evaluate(self, values: np.ndarray) -> dict:
        """The outputs of each row of ``values`` (n, len(spec.keys)): {output: (n,) floats, "error": [str | None]}."""
        names = self.spec.computed_outputs
        out = {name: np.full(len(values), np.nan) for name in names}
        errors: list[str | None] = [None] * len(values)
        for k, row in enumerate(np.atleast_2d(values)):
            overrides = {**self.spec.fixed, **{key: float(v) for key, v in zip(self.spec.keys, row)}}
            ev = Evaluation(self, overrides)
            try:
                for name in names:
                    o = OUTPUTS[name]
                    out[name][k] = np.nan if o.target_only and not ev.model.has_hkp else o.value(ev)
            except Exception as exc:  # noqa: BLE001  a failed evaluation is a row of NaN and its reason, never a crash
                for name in names:
                    out[name][k] = np.nan
                errors[k] = failure_reason(exc)
        out["error"] = errors
        return out


def failure_reason(exc: BaseException) -> str:
    """The ``error`` text of a failed evaluation: chewbot's own message, or the exception's type and message."""
    if isinstance(exc, ChewbotError):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"


class Evaluation:
    """One parameter set, its run's stages computed when an output first needs them."""

    def __init__(self, evaluator: Evaluator, overrides: dict[str, float]):
        from chewbot.model.params import split_overrides

        self.evaluator = evaluator
        self.spec = evaluator.spec
        self.model_overrides, self.task_overrides = split_overrides(overrides)

    @cached_property
    def model(self):
        return self.evaluator.model(self.model_overrides)

    @cached_property
    def run(self):
        """This parameter set's run (:class:`chewbot.run.pipeline.Chunk`: the whole task as one chunk), each stage
        computed when an output first asks for it."""
        return self._run(self.model)

    def _run(self, model):
        from chewbot.run.pipeline import Chunk

        return Chunk(model, self.evaluator.task(model.mechanism, self.task_overrides), self.evaluator.options)

    @property
    def kinematics(self):
        return self.run.kinematics

    @property
    def dynamics(self):
        return self.run.dynamics

    @cached_property
    def fused(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(tau (N, 6), MCI (N, 6)) by one fused kernel (:func:`chewbot.analysis.coupling.torques_coupling_kernel`)
        where the SPEC's outputs need only these (no output reads the formulation's other columns or the checks)
        and the formulation's torques are the minimum-norm solution of Eq. (53) alone (a Lagrange-d'Alembert
        reduction under the bilateral contact model: :func:`chewbot.dynamics.registry.reduction_rates`); None
        otherwise (the run's stages compute them)."""
        return self.evaluator.fused(self.model, self.kinematics)

    @property
    def tau(self) -> np.ndarray:
        """The run's torques (N, 6), N m."""
        return self.dynamics.tau if self.fused is None else self.fused[0]

    @cached_property
    def mu(self) -> np.ndarray:
        """Transmission angles (N, 6), rad: results.csv's mu1..mu6."""
        columns = self.run.kinematic_columns
        return np.column_stack([columns[f"mu{i}"] for i in range(1, 7)])

    @property
    def mci(self) -> np.ndarray:
        return self.run.coupling.MCI if self.fused is None else self.fused[1]

    @cached_property
    def mean_mci(self) -> np.ndarray:
        return self.mci.mean(axis=0)

    @cached_property
    def counterpart_mean_mci(self) -> np.ndarray:
        """Mean MCI_i of the counterpart mechanism with the same values, on the same motion."""
        name = self.spec.counterpart or COUNTERPARTS[self.spec.model]
        return self._run(self.evaluator.model(self.model_overrides, name)).coupling.MCI.mean(axis=0)

    @cached_property
    def checks(self) -> list:
        """The validity checks of the run, on the columns its results.csv has."""
        from chewbot.analysis.checks import run_checks

        return run_checks(self.model, self.run.columns, self.dynamics.info or None, self.spec.contact)

    def check(self, name: str):
        """The result of the validity check ``name``."""
        return next(c for c in self.checks if c.name == name)

    @cached_property
    def failed_checks(self) -> list:
        return [c for c in self.checks if c.fails_run]

    @property
    def fails(self) -> bool:
        return bool(self.failed_checks)


_EVALUATORS: dict[str, object] = {}


def evaluate_chunk(spec: Spec, values: np.ndarray) -> dict:
    """What a worker computes for a chunk: the rows of ``values`` (parameter values, or poses for a grid over
    poses) -> {column: (n,) floats, "error": [str | None]}. The evaluator of a SPEC is kept in the worker."""
    key = spec.digest()
    evaluator = _EVALUATORS.get(key)
    if evaluator is None:
        if spec.over_poses:
            from chewbot.sweep.maps import PoseEvaluator

            evaluator = PoseEvaluator(spec)
        else:
            evaluator = Evaluator(spec)
        _EVALUATORS.clear()  # one SPEC at a time per worker
        _EVALUATORS[key] = evaluator
    return evaluator.evaluate(np.asarray(values, dtype=float))


def output_units(spec: Spec) -> dict[str, str]:
    """The unit of every output column of the sweep."""
    if spec.over_poses:
        from chewbot.sweep.maps import map_columns

        return {name: unit for name, (unit, _) in map_columns(spec).items()}
    return {name: OUTPUTS[name].unit for name in spec.computed_outputs}


def output_descriptions(spec: Spec) -> dict[str, dict]:
    if spec.over_poses:
        from chewbot.sweep.maps import map_columns

        return {name: {"unit": u, "description": d} for name, (u, d) in map_columns(spec).items()}
    return {name: {"unit": OUTPUTS[name].unit, "description": OUTPUTS[name].description} for name in spec.computed_outputs}
