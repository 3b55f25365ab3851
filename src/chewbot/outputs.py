"""Writing result folders: all or nothing, and never over an existing result without being asked."""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from chewbot.errors import ChewbotError


class OutputError(ChewbotError):
    """The results folder cannot be written (the file system refused; names the folder and the reason)."""


class OutputExistsError(OutputError):
    """The results folder exists and ``force`` was not given."""


@contextmanager
def atomic_folder(out: Path, force: bool = False):
    """Yield a temporary sibling folder of ``out`` to write into; it becomes ``out`` when the block ends without
    an error (replacing ``out`` only with ``force``), and is removed otherwise.

    The old folder is moved aside, not deleted, until the new one is in place, and restored if that fails:
    there is no moment without a complete result. File-system errors become :class:`OutputError`.
    """
    out = Path(out)
    check_output(out, force)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    except OSError as exc:
        raise OutputError(f"{out}: cannot create the results folder ({exc.strerror or exc})") from exc
    old = out.parent / f".{out.name}.replaced-{tmp.name.rsplit('-', 1)[-1]}"
    try:
        yield tmp
        if out.exists():
            os.replace(out, old)
        os.replace(tmp, out)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if old.exists() and not out.exists():
            os.replace(old, out)
        if isinstance(exc, OSError):
            raise OutputError(f"{out}: cannot write the results ({exc.strerror or exc}{f': {exc.filename}' if exc.filename else ''})") from exc
        raise
    shutil.rmtree(old, ignore_errors=True)


def check_output(out: Path, force: bool) -> None:
    """Refuse an ``out`` that exists and is not a folder, or exists at all without ``force``."""
    if out.exists() and not out.is_dir():
        raise OutputExistsError(f"{out}: exists and is not a folder; choose another --out")
    if out.exists() and not force:
        raise OutputExistsError(f"{out}: the results folder exists; choose another --out or pass --force to replace it")


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary sibling: the file is whole or untouched."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)


def to_json(obj) -> str:
    """Standard JSON (RFC 8259) of ``obj``: NumPy arrays and scalars as lists and numbers, paths as strings,
    NaN and infinities (an index that does not apply, an infinite ratio) as null."""

    def clean(o):
        if isinstance(o, dict):
            return {str(k): clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        if isinstance(o, np.ndarray):
            return clean(o.tolist())
        if isinstance(o, (np.floating, np.integer, np.bool_)):
            return clean(o.item())
        if isinstance(o, float) and not math.isfinite(o):
            return None
        if isinstance(o, Path):
            return str(o)
        return o

    return json.dumps(clean(obj), indent=2, allow_nan=False) + "\n"
