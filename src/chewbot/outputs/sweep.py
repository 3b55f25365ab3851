"""A sweep from SPEC to folder: :func:`run_sweep` (what ``chewbot sweep`` does).

The SPEC is read and validated, its kernels compiled (once, before the workers start: they load them from the
kernel cache), the sweep folder started or resumed (:mod:`chewbot.sweep.record`), the design evaluated on the
cluster chunk by chunk (:mod:`chewbot.sweep.runner`), and at the end the chunks are merged into
``samples.parquet``, the kind's results written (Sobol' indices, the optimum and its convergence) with the
report, and run.json marked complete.
"""

from __future__ import annotations

import csv
import hashlib
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from chewbot.outputs.record import environment_record
from chewbot.progress import SILENT, Progress
from chewbot.sweep.quantities import OUTPUTS
from chewbot.sweep.evaluate import evaluate_chunk, output_descriptions, output_units
from chewbot.sweep.record import CONVERGENCE_FILE, INDICES_FILE, OPTIMUM_FILE, REPORT_FILE, SAMPLES_FILE, SweepFolder
from chewbot.sweep.runner import ChunkRunner, cluster_description, dask_client, merge_chunks
from chewbot.sweep.spec import COUNTERPARTS, Spec, read_spec, spec_path



@dataclass
class SweepResult:
    """What :func:`run_sweep` did: the folder, the evaluations (``computed`` now, ``reused`` from an interrupted
    run), how many failed, the kind's results (``indices`` per output, ``optimum``, ``convergence``)."""

    folder: Path
    spec: Spec
    evaluations: int = 0
    computed: int = 0
    reused_chunks: int = 0
    computed_chunks: int = 0
    failed: int = 0
    elapsed_s: float = 0.0
    indices: dict = field(default_factory=dict)
    optimum: dict | None = None
    convergence: list = field(default_factory=list)


def input_files(spec: Spec) -> dict[str, str]:
    """The files the sweep reads (the models, a task file) with their SHA-256: part of the SPEC's digest."""
    from chewbot.model.params import resolve_model_path

    paths = [resolve_model_path(m) for m in (spec.model, spec.counterpart or COUNTERPARTS.get(spec.model)) if m]
    if spec.task != "default":
        paths.append(Path(spec.task))
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in paths}


def prepare(spec: Spec, progress: Progress = SILENT) -> None:
    """Compile the kernels the evaluations use (missing ones, side by side, telling ``progress``), so that the workers
    only load them."""
    from chewbot.compiled.kernels import prepare_kernels
    from chewbot.model.params import load_model
    from chewbot.run.pipeline import run_kernels

    names = [spec.model] + ([spec.counterpart or COUNTERPARTS[spec.model]] if any("ratio_MCI" in o for o in spec.computed_outputs) else [])
    kernels = []
    for name in names:
        model = load_model(name)
        kernels += run_kernels(model, spec.run_options(name))
    if spec.over_poses:
        from chewbot.sweep.maps import map_kernels

        kernels += map_kernels(load_model(spec.model).mechanism)
    else:
        from chewbot.sweep.evaluate import Evaluator

        kernels += Evaluator(spec).kernels(load_model(spec.model))
    prepare_kernels(kernels, progress=progress)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def run_sweep(spec_source: str | Path, out: Path, *, scheduler: str | None = None, workers: int | None = None,
              resume: bool = False, force: bool = False, progress: Progress = SILENT, processes: bool = True,
              check=None) -> SweepResult:
    """Run the sweep of ``spec_source`` (a SPEC file or a built-in SPEC's name) into the folder ``out``.

    ``scheduler``: address of an existing Dask scheduler (default: a LocalCluster of ``workers`` processes, the
    cores by default; ``processes=False``: threads in this process, for tests). ``resume``: continue the
    interrupted sweep in ``out``; ``force``: replace an existing sweep folder. ``progress``: told each stage, and
    the evaluations done (``progress("evaluations", done, total)``, a chunk written as the stage ``chunk``);
    ``check()``: raises to stop (:class:`~chewbot.sweep.runner.ChunkRunner`).
    """
    spec = read_spec(spec_source)
    text = spec_path(spec_source).read_bytes()
    files = input_files(spec)
    digest = spec.digest(files)
    inputs = [Path(p) for p in files] + [spec_path(spec_source)]
    if resume:
        folder = SweepFolder.resume(out, digest, spec.as_dict(), inputs)
    else:
        SweepFolder.check(out, force, inputs)  # before the work, not after it
    progress("compiling kernels")
    prepare(spec, progress)
    if not resume:
        record = {"spec": spec.as_dict(), "spec_file": spec.source, "spec_sha256": digest, "inputs": files,
                  "outputs": output_descriptions(spec), "started": _now(), "command": sys.argv,
                  **environment_record("distributed", "SALib", "pyarrow")}
        folder = SweepFolder.start(out, record, text, force, inputs)
    result = SweepResult(folder.path, spec)
    started = time.perf_counter()
    progress("starting the Dask cluster" if scheduler is None else f"connecting to {scheduler}")
    with dask_client(scheduler, workers, processes) as client:
        cluster = cluster_description(client)
        folder.save(cluster=cluster, resumed=_now() if resume else None)
        progress(f"evaluating on {cluster['workers']} worker(s)")
        runner = ChunkRunner(client, folder, evaluate_chunk, spec, spec.chunk, output_units(spec), progress, check)
        _evaluate(spec, runner, result)
    result.elapsed_s = time.perf_counter() - started
    result.reused_chunks, result.computed_chunks, result.computed = runner.reused, runner.computed, runner.evaluations
    progress("writing samples.parquet")
    result.evaluations = merge_chunks(folder, folder.path / SAMPLES_FILE)
    result.failed = _failed(folder.path / SAMPLES_FILE)
    written = _write_results(result, folder)
    progress("writing report.html")
    from chewbot.report.sweep import write_report

    write_report(result, folder.path / REPORT_FILE)
    rate = runner.evaluations / runner.compute_s if runner.compute_s > 0 else None
    folder.save(complete=True, finished=_now(), evaluations=result.evaluations, failed_evaluations=result.failed,
                chunks={"size": spec.chunk, "computed": runner.computed, "reused": runner.reused},
                timings={"elapsed_s": result.elapsed_s, "evaluated": runner.evaluations, "evaluating_s": runner.compute_s,
                         "evaluations_per_s": rate,
                         "evaluations_per_s_per_thread": rate / cluster["threads"] if rate else None},
                files=sorted([SAMPLES_FILE, REPORT_FILE, "spec.toml", "run.json", *written]),
                **_summary(result))
    folder.clear_chunks()
    return result


def _evaluate(spec: Spec, runner: ChunkRunner, result: SweepResult) -> None:
    from chewbot.sweep import samplers

    if spec.kind == "monte-carlo":
        runner.run(samplers.monte_carlo_design(spec))
    elif spec.kind == "sobol":
        kept = runner.run(samplers.sobol_design(spec), keep=spec.outputs)
        for name in spec.outputs:
            result.indices[name] = samplers.sobol_indices(spec.keys, spec.parameters, kept[name], spec.resamples,
                                                          spec.confidence, spec.seed)
    elif spec.kind == "grid":
        if spec.over_poses:
            from chewbot.sweep.maps import pose_design

            runner.run(pose_design(spec))
        else:
            runner.run(samplers.grid_design(spec.keys, spec.parameters))
    else:
        from chewbot.sweep.optimize import optimize

        result.optimum, result.convergence = optimize(spec, runner)


def _failed(path: Path) -> int:
    import pyarrow.parquet as pq

    return int(pq.read_table(path, columns=["error"]).column("error").is_valid().to_numpy(zero_copy_only=False).sum())


def _write_results(result: SweepResult, folder: SweepFolder) -> list[str]:
    """The kind's own result files (CSV, whole by rename); returns their names."""
    from chewbot.files import atomic_member

    spec, written = result.spec, []

    def write(name: str, header: list[str], rows: list[list]) -> None:
        with atomic_member(folder.path / name) as tmp:
            with open(tmp, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(header)
                w.writerows([repr(float(v)) if isinstance(v, (float, np.floating)) else v for v in row] for row in rows)
        written.append(name)

    if result.indices:
        rows = []
        for name, ind in result.indices.items():
            for j, key in enumerate(spec.keys):
                rows.append([name, key, ind["S1"][j], ind["S1_conf"][j], ind["ST"][j], ind["ST_conf"][j],
                             ind["blocks"], ind["blocks_total"]])
        level = f"{100 * spec.confidence:g}"
        write(INDICES_FILE, ["output", "parameter", "S1 [1]", f"S1_conf [1] (half-width, {level} %)", "ST [1]",
                             f"ST_conf [1] (half-width, {level} %)", "base_samples_used", "base_samples"], rows)
    if result.optimum is not None:
        o = result.optimum
        write(OPTIMUM_FILE, ["quantity", "value", "unit"],
              [[k, v, "the parameter file's (the key's suffix)"] for k, v in o["parameters"].items()]
              + [[k, v, OUTPUTS[k].unit] for k, v in o["outputs"].items()]
              + [["sample", o["sample"], ""], ["constraints_met", o["constraints_met"], ""]])
        write(CONVERGENCE_FILE, ["generation", "evaluations", f"best {spec.minimize} [{OUTPUTS[spec.minimize].unit}]",
                                 "convergence [1]", "feasible_in_population", *spec.keys],
              [[c["generation"], c["evaluations"], c["best"], c["convergence"], c["feasible"], *c["x"]]
               for c in result.convergence])
    return written


def _summary(result: SweepResult) -> dict:
    out = {}
    if result.indices:
        out["sobol_indices"] = {name: {"parameters": list(result.spec.keys), **{k: np.asarray(v).tolist() if np.ndim(v) else v
                                                                                for k, v in ind.items()}}
                                for name, ind in result.indices.items()}
    if result.optimum is not None:
        out["optimum"] = result.optimum
        out["convergence"] = result.convergence
    return out
