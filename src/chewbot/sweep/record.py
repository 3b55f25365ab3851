"""The sweep folder: a record that grows while the sweep runs, each file in it whole at every moment.

A sweep takes minutes to hours, and what it has computed is worth keeping when it stops early. So its folder is
not written in a temporary place and renamed at the end, as a run's results folder is (docs/cli.md): it is
created at the start, holding ``run.json`` with ``"complete": false`` and the SPEC, and every finished chunk of
evaluations is written into ``chunks/`` as one Parquet file, under a temporary name renamed into place
(:func:`chewbot.files.atomic_member`). An interrupt therefore leaves the finished chunks (results, not partial
output) and nothing half written; ``--resume`` continues from them. The final files (``samples.parquet``, the
indices or the optimum, ``report.html``) are written the same way, and ``run.json`` says ``"complete": true``
last. ``--force`` replaces an existing sweep folder (only one chewbot wrote: its run.json has ``"chewbot_sweep"``)
when the new sweep starts.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from chewbot.errors import ChewbotError
from chewbot.files import Marker, OutputExistsError, atomic_folder, atomic_member, check_output, remove_stale, to_json

# Version of the sweep folder's format: run.json's "chewbot_sweep" (CHANGELOG.md).
SWEEP_FORMAT = 1
SWEEP_FOLDER = Marker("sweep folder", "run.json", "chewbot_sweep")
CHUNKS = "chunks"
# The files of a complete sweep folder besides run.json and spec.toml.
SAMPLES_FILE = "samples.parquet"
INDICES_FILE = "sobol_indices.csv"
OPTIMUM_FILE = "optimum.csv"
CONVERGENCE_FILE = "convergence.csv"
REPORT_FILE = "report.html"


class SweepFolder:
    """An open sweep folder: ``path``, its ``chunks`` folder, and its record (run.json) as a dict."""

    def __init__(self, path: Path, record: dict):
        self.path = Path(path)
        self.chunks = self.path / CHUNKS
        self.record = record

    @staticmethod
    def check(out: Path, force: bool = False, inputs=()) -> None:
        """Refuse to start a sweep in ``out`` (before any work) unless it is new, or a sweep folder chewbot wrote
        and ``force`` is given (:func:`chewbot.files.check_output`)."""
        out = Path(out)
        if SWEEP_FOLDER.present(out) and not force:
            state = "a complete sweep" if _read_record(out).get("complete") else "an incomplete sweep"
            raise OutputExistsError(f"{out}: exists ({state} written by chewbot); pass --resume to continue it, --force "
                                    "to start it over, or choose another --out")
        check_output(out, force, SWEEP_FOLDER, inputs)

    @classmethod
    def start(cls, out: Path, record: dict, spec_text: bytes, force: bool = False, inputs=()) -> SweepFolder:
        """A new sweep folder ``out`` with its record (``"complete": false``) and the SPEC as given (spec.toml);
        an existing sweep folder is replaced only with ``force`` (anything else chewbot did not write, never)."""
        out = Path(out)
        cls.check(out, force, inputs)
        record = {"chewbot_sweep": SWEEP_FORMAT, "complete": False, **record}
        with atomic_folder(out, force, SWEEP_FOLDER, inputs) as tmp:
            (tmp / CHUNKS).mkdir()
            (tmp / "spec.toml").write_bytes(spec_text)
            (tmp / "run.json").write_text(to_json(record))
        return cls(out, record)

    @classmethod
    def resume(cls, out: Path, digest: str, spec_dict: dict, inputs=()) -> SweepFolder:
        """The sweep folder ``out`` to continue: chewbot wrote it from a SPEC with the same ``digest``."""
        out = Path(out)
        if not (out.exists() or out.is_symlink()):
            raise ChewbotError(f"{out}: no such sweep folder to resume (run the sweep without --resume to start it)")
        check_output(out, True, SWEEP_FOLDER, inputs)  # a sweep folder chewbot wrote, not the current folder ...
        record = _read_record(out)
        if record.get("chewbot_sweep") != SWEEP_FORMAT:
            raise ChewbotError(f"{out / 'run.json'}: sweep format {record.get('chewbot_sweep')!r}; this chewbot resumes {SWEEP_FORMAT}")
        if record.get("spec_sha256") != digest:
            before = record.get("spec", {})
            changed = sorted(k for k in set(before) | set(spec_dict) if k != "source" and json.dumps(before.get(k), sort_keys=True, default=str)
                             != json.dumps(json.loads(to_json(spec_dict.get(k))), sort_keys=True, default=str))
            what = f"the SPEC's {', '.join(changed)} changed" if changed else "a file it reads (the model or the task) changed"
            raise ChewbotError(f"{out}: cannot resume: {what} since the sweep started; --resume continues the same sweep "
                               "only (start a new one with another --out, or --force to start over)")
        remove_stale(out)
        (out / CHUNKS).mkdir(exist_ok=True)
        remove_stale(out / CHUNKS)
        return cls(out, record)

    def save(self, **updates) -> None:
        """Update the record and write run.json (whole, by rename)."""
        self.record.update(updates)
        with atomic_member(self.path / "run.json") as tmp:
            tmp.write_text(to_json(self.record))

    def chunk_path(self, first: int) -> Path:
        """The file of the chunk whose first evaluation is ``first``."""
        return self.chunks / f"chunk-{first:09d}.parquet"

    def chunk_files(self) -> list[Path]:
        """The finished chunks, in the order of their first evaluation."""
        return sorted(self.chunks.glob("chunk-*.parquet"))

    def clear_chunks(self) -> None:
        """Remove the chunk files (their rows are in samples.parquet): the folder keeps one copy of the results."""
        shutil.rmtree(self.chunks, ignore_errors=True)


def _read_record(out: Path) -> dict:
    try:
        return json.loads((Path(out) / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ChewbotError(f"{out / 'run.json'}: cannot read it ({exc})") from None
