"""Writing outputs: whole or not at all, never over what chewbot did not write, never leaving temporary files.

Every command writes through this module (docs/cli.md, "Writing a new command"):

* :func:`atomic_folder` for a folder (a run's results, a study, exported C), :func:`atomic_files` for one or
  more single files written together (a task and its residuals, a Markdown table). The output is written
  under a temporary name beside it and renamed into place once complete; an error or a signal removes it.
* ``--force`` replaces only an output that chewbot wrote, recognised by its :class:`Marker`: a file inside a
  folder (a results folder's ``run.json``); for a single file, a small JSON file beside it (its *sidecar*,
  ``task.csv.chewbot.json``, :func:`sidecar`) that records the SHA-256 of the file as written, for CSV tables, so
  that any reader takes them with no options (``pandas.read_csv(path)``); the first line of the file
  (:func:`marker_line`) for TOML and Markdown, and for the CSV tables written before the sidecars. Anything
  else is refused (:class:`OutputExistsError`, exit code 5) and left untouched. :func:`check_output` applies
  the rule before the work starts; the atomic writers apply it again before they rename.
* An output may not be the current folder or contain it, nor contain (or be) one of the command's inputs.
* Temporary names carry the process id (``.NAME.partial-PID-XXXXXXXX``, ``.NAME.replaced-PID-XXXXXXXX``);
  :func:`remove_stale` (run by each writer in the folder it writes to) removes those whose process no longer
  exists, and puts back an output that was moved aside and never replaced. Those of a live process stay.
* Folders and files get the permissions of the user's umask.
"""

from __future__ import annotations

import errno
import json
import math
import os
import re
import secrets
import shutil
import signal
import threading
import traceback
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from chewbot.errors import ChewbotError


class OutputError(ChewbotError):
    """The output cannot be written (names the path and the reason in plain words)."""


class OutputExistsError(OutputError):
    """The output exists, and ``force`` was not given or chewbot did not write it."""


# chewbot's version (chewbot.__version__): every output carries it, in its marker line or its record.
VERSION = "0.1.0"


# --- signals held back -------------------------------------------------------------------------------------------

SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def shield():
    """Hold SIGINT and SIGTERM back while the block runs; one that arrived meanwhile is handed, at the block's end,
    to the handler that was in place (the command's, which then raises): the short steps that must not be cut in
    half (renaming an output into place, removing temporary files) run whole. Python runs signal handlers in the
    main thread only, so elsewhere (and where a handler was not set from Python) the block just runs."""
    previous = {s: signal.getsignal(s) for s in SIGNALS}
    if threading.current_thread() is not threading.main_thread() or None in previous.values():
        yield
        return
    held: list[tuple[int, object]] = []
    for s in SIGNALS:
        signal.signal(s, lambda signum, frame: held.append((signum, frame)))
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    if held:
        signum, frame = held[0]
        handler = previous[signum]
        if callable(handler):
            handler(signum, frame)
        elif handler == signal.SIG_DFL:
            os.kill(os.getpid(), signum)


# --- what chewbot wrote ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Marker:
    """How chewbot recognises an output of one kind that it wrote itself.

    A folder carries a JSON file ``file`` whose top level has the key ``key`` (the format's version); a single
    file (``file`` None) starts with the line of :func:`marker_line`.
    """

    kind: str
    file: str | None = None
    key: str | None = None


    @property
    def is_folder(self) -> bool:
        return self.file is not None

    def present(self, path: Path) -> bool:
        """True if ``path`` is an output of this kind written by chewbot."""
        path = Path(path)
        if path.is_symlink():  # chewbot never writes links: replacing one would replace what it points to
            return False
        if not self.is_folder:
            return path.is_file() and (_starts_with_marker(path) or _sidecar_marks(path))
        try:
            content = json.loads((path / self.file).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        return isinstance(content, dict) and isinstance(content.get(self.key), int)


RESULTS_FOLDER = Marker("results folder", "run.json", "chewbot_run")
STUDY_FOLDER = Marker("study folder", "study.json", "chewbot_study")
EXPORT_FOLDER = Marker("exported C folder", "chewbot-export.json", "chewbot_export")
WRITTEN_FILE = Marker("file")

_MARKER_TEXT = "written by chewbot"
_MARKER_LINE = re.compile(r"^\ufeff?\s*(#|<!--|//|;)\s*" + _MARKER_TEXT + r"\b")


def marker_line(comment: str = "#", about: str = "") -> str:
    """The first line of a single file chewbot writes (without the newline): ``# written by chewbot 0.2.0: about``.

    ``comment`` opens a comment in the file's format: ``#`` for CSV (the task reader skips such lines) and
    TOML, ``<!--`` for Markdown and HTML (closed on the same line).
    """
    text = f"{comment} {_MARKER_TEXT} {VERSION}" + (f": {about}" if about else "")
    return text + " -->" if comment == "<!--" else text


def without_marker(text: str) -> str:
    """``text`` without its first line where that is chewbot's marker line (a file chewbot wrote, rewritten: its new
    marker replaces the old one instead of repeating it)."""
    first, _, rest = text.partition("\n")
    return rest if _MARKER_LINE.match(first) else text


SIDECAR_SUFFIX = ".chewbot.json"
SIDECAR_KEY = "chewbot_file"
_SIDECAR_FORMATS = (".csv",)  # tables whose readers take no comment line: their marker is a sidecar


def sidecar(path: Path) -> Path:
    """The sidecar of a table chewbot writes (``task.csv`` -> ``task.csv.chewbot.json``): ``{"chewbot_file": 1,
    "version", "file", "about", "sha256", ...}``, the marker of :mod:`chewbot.files`'s module docstring. A file whose
    content no longer has the recorded SHA-256 (edited since) is no longer chewbot's: ``--force`` refuses it."""
    path = Path(path)
    return path.with_name(path.name + SIDECAR_SUFFIX)


def uses_sidecar(path: Path) -> bool:
    """True for the files whose marker is a sidecar (CSV tables), False for those that begin with the marker line."""
    return Path(path).suffix.lower() in _SIDECAR_FORMATS


def file_sha256(path: Path) -> str:
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_sidecar(path: Path, side: Path | None = None) -> dict | None:
    """The sidecar of ``path`` (or the file ``side``) as a dict, if it is chewbot's; None otherwise."""
    try:
        content = json.loads(Path(side or sidecar(path)).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return content if isinstance(content, dict) and isinstance(content.get(SIDECAR_KEY), int) else None


def _sidecar_marks(path: Path, side: Path | None = None) -> bool:
    content = read_sidecar(path, side)
    try:
        return content is not None and content.get("sha256") == file_sha256(path)
    except OSError:
        return False


def sidecar_text(path: Path, name: str, about: str = "", **extra) -> str:
    """The sidecar's JSON for the file ``path`` as written (its SHA-256), to be named after ``name``."""
    return to_json({SIDECAR_KEY: 1, "version": VERSION, "file": name, "about": about, **extra, "sha256": file_sha256(path)})


def _starts_with_marker(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            first = f.readline(400).decode("utf-8", errors="replace")
    except OSError:
        return False
    return bool(_MARKER_LINE.match(first))


# --- the rule ----------------------------------------------------------------------------------------------


def _inside(path: Path, folder: Path) -> bool:
    p, f = Path(path).resolve(), Path(folder).resolve()
    return p == f or f in p.parents


def check_output(out: Path, force: bool, marker: Marker = RESULTS_FOLDER, inputs=()) -> None:
    """Refuse ``out`` (raise :class:`OutputError`, exit code 5) unless it may be written:

    * it is not the current folder and does not contain it, and no input (``inputs``: paths, None skipped)
      lies inside it (or is it);
    * it does not exist, or it is an output of ``marker``'s kind that chewbot wrote and ``force`` is given.

    The folder ``out`` is in is tidied first (:func:`remove_stale`): an output of a killed process that was
    moved aside is back in place before the rule looks at it.
    """
    out = Path(out)
    remove_stale(out.parent)
    if _inside(Path.cwd(), out):
        raise OutputError(f"{out}: is the current folder or contains it; chewbot writes a new {marker.kind} of its own, "
                          "it does not write over the folder it runs in: choose another --out, e.g. runs/NAME")
    for given in inputs:
        if given is not None and _inside(Path(given), out):
            raise OutputError(f"{out}: the input {given} is {'this file' if Path(given).resolve() == out.resolve() else 'inside it'}; "
                              f"writing the {marker.kind} would replace its own input: choose another --out")
    if not (out.exists() or out.is_symlink()):
        return
    if marker.present(out):
        if not force:
            raise OutputExistsError(f"{out}: exists (a {marker.kind} written by chewbot); pass --force to replace it, "
                                    "or choose another --out")
        return
    if marker.is_folder:
        what = f"has no {marker.file} of chewbot"
    elif read_sidecar(out) is not None:
        what = f"it changed since chewbot wrote it: its content is not that recorded in {sidecar(out).name}"
    else:
        what = f"has no {sidecar(out).name} beside it and does not start with chewbot's line '{marker_line()}'"
    if out.is_symlink():
        what = "is a symbolic link"
    elif marker.is_folder != out.is_dir():
        what = f"is a {'folder' if out.is_dir() else 'file'}, not a {marker.kind}"
    raise OutputExistsError(f"{out}: exists and was not written by chewbot ({what}); chewbot never replaces it, "
                            "not even with --force: choose another --out")


# --- plain reasons -----------------------------------------------------------------------------------------

_REASONS = {
    errno.EACCES: "permission denied: you may not write there",
    errno.EPERM: "the operation is not permitted there",
    errno.EROFS: "the file system is read-only",
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "your disk quota is used up",
    errno.ENOTDIR: "a part of the path is a file, not a folder",
    errno.EISDIR: "it is a folder",
    errno.ENOENT: "a folder on the way does not exist",
    errno.ENAMETOOLONG: "the name is too long",
    errno.EEXIST: "a file of that name is in the way",
    errno.ENOTEMPTY: "a folder of that name is in the way",
    errno.EXDEV: "it is on another file system than its temporary copy",
}


def plain_reason(exc: OSError) -> str:
    """The reason of a file-system error in plain words."""
    return _REASONS.get(exc.errno, exc.strerror or str(exc))


def cannot_write(path: Path, exc: OSError, what: str = "write it") -> OutputError:
    """An :class:`OutputError` naming ``path``, what could not be done and the reason of ``exc`` in plain words."""
    return OutputError(f"{path}: cannot {what}: {plain_reason(exc)}")


# --- temporary names ---------------------------------------------------------------------------------------

_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.(?P<state>partial|replaced)-(?P<pid>\d+)-[0-9a-f]{8}$")


def _temporary(path: Path, state: str) -> Path:
    return path.with_name(f".{path.name}.{state}-{os.getpid()}-{secrets.token_hex(4)}")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def remove_stale(folder: Path) -> list[Path]:
    """Remove the temporary outputs in ``folder`` left by chewbot processes that no longer exist (killed, or
    the machine stopped); an output that such a process had moved aside and not yet replaced is put back.
    Those of live processes (a concurrent run) are left alone. Returns what was removed or put back."""
    done = []
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return done
    for entry in entries:
        m = _TEMPORARY.match(entry.name)
        if m is None or int(m["pid"]) == os.getpid() or _alive(int(m["pid"])):
            continue
        target = entry.with_name(m["name"])
        try:
            with shield():
                if m["state"] == "replaced" and not (target.exists() or target.is_symlink()):
                    os.replace(entry, target)
                elif entry.is_dir() and not entry.is_symlink():
                    shutil.rmtree(entry)
                else:
                    entry.unlink()
            done.append(entry)
        except OSError:
            pass  # not ours to fight over (permissions): it stays
    return done


def _prepare_folder(folder: Path, out: Path) -> None:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise cannot_write(out, exc, f"create the folder {folder} for it") from exc


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


# --- the writers -------------------------------------------------------------------------------------------


@contextmanager
def atomic_folder(out: Path, force: bool = False, marker: Marker = RESULTS_FOLDER, inputs=()):
    """Yield a new temporary folder beside ``out`` to write into; when the block ends without an error it
    becomes ``out``, replacing an existing one only as :func:`check_output` allows. On an error or a signal
    the temporary folder is removed and ``out`` stays as it was.

    The block must write ``marker``'s file into the folder (a folder chewbot cannot recognise later could never
    be replaced): its absence is a bug (RuntimeError). The old folder is moved aside, not deleted, until the new
    one is in place, and put back if that fails: there is no moment without a complete output. File-system
    errors become :class:`OutputError` naming the path and the reason.
    """
    out = Path(out)
    check_output(out, force, marker, inputs)
    _prepare_folder(out.parent, out)
    tmp = _temporary(out, "partial")
    try:
        tmp.mkdir()  # not tempfile.mkdtemp: its mode 0700 would ignore the umask
    except OSError as exc:
        raise cannot_write(out, exc, "create its temporary folder beside it") from exc
    with _committed([(tmp, out)], force, marker):
        yield tmp


@contextmanager
def atomic_files(paths, force: bool = False, inputs=(), about: dict | None = None):
    """Yield one temporary path beside each of ``paths`` (single files written together, e.g. a task and its
    residuals); when the block ends without an error each becomes its path, all or none. A CSV table gets its
    sidecar (:func:`sidecar`, written here, with ``about[path]``: a dict of what it holds, or a string), every
    other file must start with :func:`marker_line` (its absence is a bug); an existing file is replaced only as
    :func:`check_output` allows. On an error or a signal the temporary files are removed and the paths stay as
    they were."""
    paths = [Path(p) for p in paths]
    for p in paths:
        check_output(p, force, WRITTEN_FILE, inputs)
        if uses_sidecar(p) and (sidecar(p).exists() or sidecar(p).is_symlink()) and read_sidecar(p) is None:
            raise OutputExistsError(f"{sidecar(p)}: exists and is not a sidecar of chewbot's; chewbot never replaces it: "
                                    "choose another --out")
    for p in paths:
        _prepare_folder(p.parent, p)
    pairs = [(_temporary(p, "partial"), p) for p in paths]
    sides = [(_temporary(sidecar(p), "partial"), sidecar(p), tmp, p) for tmp, p in pairs if uses_sidecar(p)]

    def mark():
        for side_tmp, _, tmp, p in sides:
            what = (about or {}).get(p, (about or {}).get(str(p), ""))
            extra = what if isinstance(what, dict) else {"about": what}
            side_tmp.write_text(sidecar_text(tmp, p.name, **{"about": "", **extra}), encoding="utf-8")

    with _committed(pairs + [(s, o) for s, o, _, _ in sides], force, WRITTEN_FILE, mark, {tmp: s for s, _, tmp, _ in sides}):
        yield [tmp for tmp, _ in pairs]


@contextmanager
def atomic_file(path: Path, force: bool = False, inputs=(), about: dict | None = None):
    """:func:`atomic_files` for one file: yields its temporary path."""
    with atomic_files([path], force, inputs, about) as (tmp,):
        yield tmp


@contextmanager
def atomic_members(folder: Path, names: list[str], force: bool = False, marker: Marker = RESULTS_FOLDER):
    """Yield a new temporary folder inside ``folder`` to write the files ``names`` into; when the block ends without
    an error each becomes ``folder/NAME``, all or none: files added to an output of ``marker``'s kind that chewbot
    wrote (a results folder's figures and report), every other file of it left as it is.

    ``folder`` must carry ``marker`` (else :class:`OutputError`: chewbot writes into its own folders only); a file
    of ``names`` that exists is replaced only with ``force`` (else :class:`OutputExistsError`), moved aside until
    the new one is in place and put back if that fails. On an error or a signal the temporary folder is removed
    and ``folder`` stays as it was. The block must write every file of ``names`` (a missing one is a bug).
    """
    folder = Path(folder)
    remove_stale(folder)
    if not marker.present(folder):
        raise OutputError(f"{folder}: not a {marker.kind} written by chewbot (no {marker.file} of chewbot's); chewbot adds "
                          f"files to its own {marker.kind}s only")
    existing = [name for name in names if (folder / name).exists() or (folder / name).is_symlink()]
    if existing and not force:
        raise OutputExistsError(f"{folder}: {', '.join(existing)} exist(s); pass --force to replace "
                                f"{'it' if len(existing) == 1 else 'them'}")
    staging = _temporary(folder / "members", "partial")
    try:
        staging.mkdir()
    except OSError as exc:
        raise cannot_write(folder, exc, "create a temporary folder in it") from exc
    aside: dict[Path, Path] = {}
    placed: list[Path] = []
    try:
        yield staging
        missing = [name for name in names if not (staging / name).is_file()]
        if missing:
            raise RuntimeError(f"{folder}: the command did not write {', '.join(missing)}")
        with shield():
            for name in names:
                out = folder / name
                if out.exists() or out.is_symlink():
                    aside[out] = _temporary(out, "replaced")
                    os.replace(out, aside[out])
            for name in names:
                os.replace(staging / name, folder / name)
                placed.append(folder / name)
    except BaseException as exc:
        with shield():
            for out in placed:
                _remove(out)
            for out, old in aside.items():
                if not (out.exists() or out.is_symlink()):
                    os.replace(old, out)
            _remove(staging)
        if isinstance(exc, OSError):
            raise cannot_write(folder, exc, "write into it") from exc
        raise
    with shield():
        _remove(staging)
        for old in aside.values():
            _remove(old)


@contextmanager
def atomic_member(path: Path):
    """Yield a temporary path beside ``path``, a file inside an output folder that chewbot is writing and marks
    itself (a sweep's chunk, its run.json); when the block ends without an error it becomes ``path`` (replacing
    an older version of it), on an error or a signal it is removed: the file is whole or absent, never half
    written. The temporary name carries the process id, so :func:`remove_stale` removes it if the process dies."""
    path = Path(path)
    tmp = _temporary(path, "partial")
    try:
        yield tmp
        with shield():
            os.replace(tmp, path)
    except BaseException as exc:
        with shield():
            _remove(tmp)
        if isinstance(exc, OSError):
            raise cannot_write(path, exc) from exc
        raise


@contextmanager
def _committed(pairs: list[tuple[Path, Path]], force: bool, marker: Marker, mark=None, sidecars: dict | None = None):
    """Run the block, then rename each (temporary, output) pair into place, moving an existing output aside
    first; on any error or signal remove the temporaries and the outputs placed so far, and put back what was
    moved aside: all the outputs or none. ``mark()`` writes the sidecars after the block; ``sidecars`` maps a
    temporary file to its temporary sidecar (the sidecars are pairs too, marked by their content)."""
    aside: dict[Path, Path] = {}
    placed: list[Path] = []
    current = pairs[0][1]
    sidecars = sidecars or {}
    side_tmps = set(sidecars.values())
    try:
        yield
        if mark is not None:
            mark()
        for tmp, out in pairs:
            if tmp in side_tmps:
                continue
            if tmp in sidecars:
                if not _sidecar_marks(tmp, sidecars[tmp]):
                    raise RuntimeError(f"{out}: its sidecar does not record it")
            elif not marker.present(tmp):
                raise RuntimeError(f"{out}: the command did not mark its output "
                                   f"({marker.file or repr(marker_line())}); chewbot could not recognise it later")
        with shield():
            for tmp, out in pairs:
                current = out
                if tmp not in side_tmps:
                    check_output(out, force, marker)  # again: a concurrent process may have written it meanwhile
                if out.exists() or out.is_symlink():
                    aside[out] = _temporary(out, "replaced")
                    os.replace(out, aside[out])
            for tmp, out in pairs:
                current = out
                os.replace(tmp, out)
                placed.append(out)
    except BaseException as exc:
        with shield():
            for tmp, _ in pairs:
                _remove(tmp)
            for out in placed:
                _remove(out)
            for out, old in aside.items():
                if not (out.exists() or out.is_symlink()):
                    os.replace(old, out)
        if isinstance(exc, OSError):
            raise cannot_write(current, exc) from exc
        raise
    with shield():
        for old in aside.values():
            _remove(old)


def to_json(obj) -> str:
    """Standard JSON (RFC 8259) of ``obj``: NumPy arrays and scalars as lists and numbers, paths as strings,
    NaN and infinities (an index that does not apply, an infinite ratio) as null."""

    def clean(o):
        if isinstance(o, dict):
            return {str(k): clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        if hasattr(o, "tolist"):  # NumPy arrays and scalars (tolist gives Python numbers)
            return clean(o.tolist())
        if isinstance(o, float) and not math.isfinite(o):
            return None
        if isinstance(o, Path):
            return str(o)
        return o

    return json.dumps(clean(obj), indent=2, allow_nan=False) + "\n"


def forked(work: Callable[[], None], close: tuple[int, ...] = ()) -> tuple[int, int]:
    """Run ``work`` in a forked process (POSIX) that stops at Ctrl-C or SIGTERM as the process group gets them and
    closes the descriptors ``close`` it does not use: its id, and the read end of a pipe on which it writes its
    traceback if ``work`` raises (read by :func:`reap`). The process never returns into the caller's frames."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        code = 0
        try:
            signal.signal(signal.SIGINT, signal.SIG_DFL)  # Ctrl-C reaches the process group: just stop
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            for fd in (read, *close):
                os.close(fd)
            work()
        except BaseException:
            code = 1
            os.write(write, traceback.format_exc().encode()[-20000:])
        finally:
            os._exit(code)
    os.close(write)
    return pid, read


def reap(pid: int, report: int, failure: str) -> None:
    """Wait for the forked process ``pid`` and read what it wrote to the pipe ``report`` (closed here); a process that
    did not exit 0 raises RuntimeError, ``failure`` followed by what it wrote (its traceback)."""
    _, status = os.waitpid(pid, 0)
    message = b""
    while chunk := os.read(report, 65536):
        message += chunk
    os.close(report)
    if status != 0:
        raise RuntimeError(f"{failure}:\n" + message.decode(errors="replace"))


def kill(pid: int) -> None:
    """Stop the forked process ``pid`` at once and reap it (gone already: nothing to do)."""
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass
