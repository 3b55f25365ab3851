"""The kernel cache: one object (:data:`KERNELS`) that keeps what building and compiling a kernel produced, in this
process and on disk.

In the process it keeps the CasADi graphs built (per kernel and the model's numbers they are built on: the
mechanism's symbol p, or one model's constants), the compiled libraries loaded, and the maps of a function over a
number of samples. On disk it keeps the shared libraries, in one folder per chewbot and CasADi version under
:meth:`KernelCache.root`, each named by its key (:meth:`KernelCache.key`), computed without building the graph or
generating code: on a hit the library is loaded and no graph is built.

The key says explicitly what determines a library (:class:`LibraryKey`): the kernel's name and key (mechanism,
orientation, options), the digest of the model's numbers where they are folded in, chewbot's and CasADi's versions,
the compiler and its flags, the processor where a flag builds for it, and the source of the modules the kernel's
graph is built from: the module of its builder and of the functions the builder was given, with every chewbot module
they import (imports inside functions included), read from the files. Editing any of them makes a new library;
editing anything else (a report, a command) keeps the cache.

Libraries of other versions are removed, and the least recently used ones beyond ``$CHEWBOT_CACHE_MAX_MB`` (default
:data:`DEFAULT_MAX_MB`) when a new one is written. Libraries are written under a temporary name carrying the
process id and renamed into place (atomic: two processes compiling the same kernel both succeed); temporary files
are removed on failure and interrupt, and those of processes that no longer exist on the next write.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import re
import shutil
import subprocess
import threading
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import casadi as ca

from chewbot.files import VERSION

DEFAULT_MAX_MB = 200  # cap of the kernel cache; a full set of chewbot's kernels takes about 4 MB
_OWN_DIR = re.compile(r"^(chewbot-[^/]+-casadi-[^/]+|casadi-[0-9][^/]*)$")  # casadi-X: the layout before version folders
TEMP = re.compile(r"^\.(?:.+)\.(?P<pid>\d+)\.[A-Za-z0-9_]+\.(?:tmp|build)$")
_IMPORT = re.compile(r"^[ \t]*(?:from[ \t]+(chewbot(?:\.\w+)*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#]+)|import[ \t]+(chewbot(?:\.\w+)*))", re.M)
_PACKAGE = Path(__file__).resolve().parent.parent  # chewbot's own folder


@dataclass(frozen=True)
class LibraryKey:
    """Everything that determines a kernel's library: its name, its key (mechanism, orientation, options and the
    digest of a model's numbers folded in), chewbot's and CasADi's versions, the compiler and its flags, the
    processor (for code built for it, ``-march=native``; empty otherwise) and the digest of the source it is built
    from (:meth:`KernelCache.source_digest`)."""

    name: str
    key: str
    chewbot: str
    casadi: str
    compiler: str
    flags: tuple[str, ...]
    processor: str
    source: str

    def digest(self) -> str:
        return hashlib.sha256(json.dumps(asdict(self)).encode()).hexdigest()[:24]


class KernelCache:
    """The kernel cache (see the module docstring): :meth:`graph`, :meth:`loaded`, :meth:`mapped` in the process,
    :meth:`library` on disk."""

    def __init__(self):
        self.lock = threading.RLock()  # CasADi releases the GIL: graphs are built, generated and loaded one at a time
        self._graphs: dict[tuple, object] = {}
        self._loaded: dict[tuple, object] = {}
        self._mapped: dict[tuple[int, int], tuple[ca.Function, ca.Function]] = {}
        self._sources: dict[str, frozenset[str]] = {}
        self._identities: dict[str, str] = {}

    # --- in this process -----------------------------------------------------------------------------------

    def graph(self, key: tuple, build: Callable[[], object]):
        """``build()`` once per ``key`` in this process (a graph, or any object built from graphs: the symbolic
        kinematics, a solver)."""
        with self.lock:
            if key not in self._graphs:
                self._graphs[key] = build()
            return self._graphs[key]

    def loaded(self, key: tuple, load: Callable[[], object]):
        """``load()`` (a library loaded) once per ``key`` in this process."""
        with self.lock:
            if key not in self._loaded:
                self._loaded[key] = load()
            return self._loaded[key]

    def mapped(self, fn: ca.Function, n: int) -> ca.Function:
        """``fn`` mapped over n samples (``fn`` itself for one), kept: building a map costs about 10 us per sample,
        more than a call of it."""
        entry = self._mapped.get((id(fn), n))
        if entry is None or entry[0] is not fn:  # the id of a collected function may be reused
            if len(self._mapped) > 256:
                self._mapped.clear()
            entry = self._mapped[id(fn), n] = (fn, fn.map(n, "serial") if n > 1 else fn)
        return entry[1]

    # --- on disk -------------------------------------------------------------------------------------------

    @staticmethod
    def root() -> Path:
        """``$CHEWBOT_CACHE``, else ``$XDG_CACHE_HOME/chewbot``, else ``~/.cache/chewbot``."""
        if os.environ.get("CHEWBOT_CACHE"):
            return Path(os.environ["CHEWBOT_CACHE"])
        if os.environ.get("XDG_CACHE_HOME"):
            return Path(os.environ["XDG_CACHE_HOME"]) / "chewbot"
        return Path(os.path.expanduser("~")) / ".cache" / "chewbot"

    def folder(self) -> Path:
        """The folder of this chewbot and CasADi version in the cache (created)."""
        path = self.root() / f"chewbot-{VERSION}-casadi-{ca.__version__}"
        path.mkdir(parents=True, exist_ok=True)
        return path

    @staticmethod
    def max_bytes() -> int:
        """The size cap: ``$CHEWBOT_CACHE_MAX_MB`` megabytes (default :data:`DEFAULT_MAX_MB`)."""
        value = os.environ.get("CHEWBOT_CACHE_MAX_MB", "")
        try:
            mb = float(value) if value else DEFAULT_MAX_MB
        except ValueError:
            raise ValueError(f"$CHEWBOT_CACHE_MAX_MB must be a number of megabytes, not {value!r}") from None
        return int(mb * 1e6)

    def key(self, name: str, key: tuple, modules: tuple[str, ...], flags: tuple[str, ...]) -> LibraryKey:
        """The :class:`LibraryKey` of the kernel ``name`` with its ``key``, built by the chewbot ``modules``, compiled
        with ``flags``."""
        cc = c_compiler() or ""
        native = any(flag.startswith("-march=native") or flag.startswith("-mcpu=native") for flag in flags)
        return LibraryKey(name, repr(key), VERSION, ca.__version__, self._identity("cc", cc) if cc else "",
                          tuple(flags), self._identity("processor") if native else "", self.source_digest(modules))

    def library(self, name: str, key: LibraryKey) -> Path:
        """The path of a kernel's library in the cache (which may not exist yet)."""
        return self.folder() / f"{name}-{key.digest()}.so"

    def source_digest(self, modules: tuple[str, ...], root: Path | None = None) -> str:
        """SHA-256 of the source of ``modules`` and of every chewbot module they import (transitively, imports inside
        functions included), file by file in ``root`` (chewbot's folder by default)."""
        root = root or _PACKAGE
        files = sorted(set().union(*(self._closure(m, root) for m in modules)) if modules else set())
        h = hashlib.sha256()
        for rel in files:
            h.update(rel.encode() + b"\0" + (root / rel).read_bytes() + b"\0")
        return h.hexdigest()

    def _closure(self, module: str, root: Path) -> frozenset[str]:
        """The files (relative to ``root``) of ``module`` and of the chewbot modules it imports, transitively."""
        cache_key = f"{root}:{module}"
        if cache_key in self._sources:
            return self._sources[cache_key]
        seen: set[str] = set()
        todo = [module]
        while todo:
            rel = _module_file(todo.pop(), root)
            if rel is None or rel in seen:
                continue
            seen.add(rel)
            for m in _IMPORT.finditer((root / rel).read_text(encoding="utf-8")):
                if m.group(3):
                    todo.append(m.group(3))
                    continue
                base = m.group(1)
                todo.append(base)
                todo += [f"{base}.{name.split(' as ')[0].strip()}" for name in m.group(2).strip("()").split(",") if name.strip()]
        self._sources[cache_key] = frozenset(seen)
        return self._sources[cache_key]

    def _identity(self, what: str, cc: str = "") -> str:
        """The compiler's path and version line (``cc``), or the processor's architecture and model: parts of the key."""
        k = f"{what}:{cc}"
        if k not in self._identities:
            if what == "cc":
                version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()
                self._identities[k] = f"{shutil.which(cc)} {version[0] if version else ''}"
            else:  # Linux: /proc/cpuinfo's "model name"; a cache shared between machines never hands it to another
                model = ""
                try:
                    with open("/proc/cpuinfo") as info:
                        model = next((line.split(":", 1)[1].strip() for line in info if line.startswith("model name")), "")
                except OSError:
                    pass
                self._identities[k] = f"{platform.machine()} {model or platform.processor()}"
        return self._identities[k]

    def remove_stale_temporaries(self, folder: Path) -> None:
        """Temporary files and folders of processes that no longer exist (killed while compiling)."""
        for path in folder.iterdir():
            m = TEMP.match(path.name)
            if m and not _pid_alive(int(m.group("pid"))):
                shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink(missing_ok=True)

    def evict(self, keep: set[Path] = frozenset()) -> None:
        """Remove the libraries of other chewbot or CasADi versions, then the least recently used beyond the size
        cap (:meth:`max_bytes`), never those in ``keep``."""
        root, current = self.root(), self.folder()
        for folder in root.iterdir():
            if folder.is_dir() and folder != current and _OWN_DIR.match(folder.name):
                _remove_folder(folder)
        libs = [(p.stat().st_mtime, p.stat().st_size, p) for p in current.glob("*.so")]
        total, cap = sum(size for _, size, _ in libs), self.max_bytes()
        for _, size, path in sorted(libs, key=lambda entry: entry[0]):
            if total <= cap:
                break
            if path not in keep:
                path.unlink(missing_ok=True)
                total -= size

    def info(self) -> dict:
        """The cache's location, and the number and total size (bytes) of chewbot's libraries in it."""
        root = self.root()
        libs = [p for d in (root.iterdir() if root.is_dir() else []) if d.is_dir() and _OWN_DIR.match(d.name)
                for p in d.glob("*.so")]
        return {"location": root, "libraries": len(libs), "bytes": sum(p.stat().st_size for p in libs),
                "max_bytes": self.max_bytes()}

    def clear(self) -> tuple[int, int]:
        """Remove chewbot's libraries and temporary files (nothing else); (libraries, bytes) removed."""
        root = self.root()
        count = size = 0
        if root.is_dir():
            for folder in root.iterdir():
                if folder.is_dir() and _OWN_DIR.match(folder.name):
                    c, s = _remove_folder(folder)
                    count, size = count + c, size + s
        return count, size


def cached_graph(params, key: tuple, build: Callable[[], object]):
    """``build()`` once per process for the model's numbers ``params`` (:class:`~chewbot.model.symbolic.SymbolicModel`:
    once per mechanism for the symbol p, once per model for its constants) and ``key``; numbers of no key (other
    expressions) are built each time."""
    return build() if params.key is None else KERNELS.graph((params.key, *key), build)


def symbols(mechanism: str):
    """The symbol p of ``mechanism`` as a :class:`~chewbot.model.symbolic.SymbolicModel`, one per process: the graphs
    of a mechanism are built on it."""
    from chewbot.model.symbolic import SymbolicModel

    return KERNELS.graph(("symbols", mechanism), lambda: SymbolicModel(mechanism))


def folded(model):
    """One model's numbers as constants (:meth:`chewbot.model.symbolic.SymbolicModel.of`), one per process and model:
    graphs built on them have the numbers folded in."""
    from chewbot.model.symbolic import SymbolicModel
    from chewbot.model.vector import vector_digest

    return KERNELS.graph(("symbols", "model", model.mechanism, vector_digest(model)), lambda: SymbolicModel.of(model))


def _module_file(module: str, root: Path) -> str | None:
    """The file of a chewbot module relative to ``root`` (its package's ``__init__.py`` for a package), or None."""
    parts = module.split(".")[1:]
    for rel in (Path(*parts).with_suffix(".py") if parts else None, Path(*parts, "__init__.py")):
        if rel is not None and (root / rel).is_file():
            return rel.as_posix()
    return None


def c_compiler() -> str | None:
    """The compiler used for kernels (``$CC``, else cc/gcc/clang on the PATH), or None."""
    for name in filter(None, (os.environ.get("CC"), "cc", "gcc", "clang")):
        if shutil.which(name):
            return name
    return None


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _own_files(folder: Path):
    """chewbot's files in a folder of the cache: libraries and temporaries."""
    for path in folder.iterdir():
        if path.suffix == ".so" and path.is_file() or TEMP.match(path.name):
            yield path


def _remove_folder(folder: Path) -> tuple[int, int]:
    count = size = 0
    for path in list(_own_files(folder)):
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            size += path.stat().st_size
            path.unlink(missing_ok=True)
            count += path.suffix == ".so"
    try:
        folder.rmdir()  # only when nothing else is left in it
    except OSError:
        pass
    return count, size


def builder_modules(build: Callable, depth: int = 3) -> tuple[str, ...]:
    """The chewbot modules a graph builder's code is in: its own and those of the functions it holds (a formulation's
    derivation handed to a shared builder, a problem's graph), ``depth`` levels down."""
    found: list[str] = []

    def visit(fn, level: int) -> None:
        module = getattr(fn, "__module__", None) or ""
        if module.startswith("chewbot") and module not in found:
            found.append(module)
        if level and getattr(fn, "__closure__", None):
            for cell in fn.__closure__:
                try:
                    value = cell.cell_contents
                except ValueError:  # an empty cell
                    continue
                if callable(value) and hasattr(value, "__module__"):
                    visit(value, level - 1)

    visit(build, depth)
    return tuple(sorted(found))


KERNELS = KernelCache()
