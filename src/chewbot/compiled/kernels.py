"""Evaluating CasADi functions over whole trajectories, and compiling them to C with a cache on disk.

A per-sample CasADi ``Function`` is mapped over the N samples of a trajectory in one call (no Python loop).
A kernel is described by a :class:`KernelSpec`: its C name, the function that builds its graph, and the key
of what else determines the graph (mechanism, orientation, goal, folded parameter values ...). :func:`native`
and :func:`compiled` turn a spec into a shared library with the system C compiler, kept in the kernel cache
(:func:`cache_root`) under a key computed without building the graph or generating code (:func:`kernel_key`):
on a hit the library is loaded and no graph is built. Where no C compiler is found, the graph runs in
CasADi's virtual machine (same results, slower).

The cache holds only chewbot's libraries, in one folder per chewbot and CasADi version; libraries of other
versions are removed, and the least recently used ones beyond ``$CHEWBOT_CACHE_MAX_MB`` (default
:data:`DEFAULT_MAX_MB`) when a new one is written. Libraries are written under a temporary name carrying the
process id and renamed into place (atomic: two processes compiling the same kernel both succeed); temporary
files are removed on failure and interrupt, and those of processes that no longer exist on the next write.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import json
import os
import platform
import re
import shutil
import subprocess
import threading
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import casadi as ca
import numpy as np

_MAPPED: dict[tuple[int, int], tuple[ca.Function, ca.Function]] = {}

DEFAULT_MAX_MB = 200  # cap of the kernel cache; a full set of chewbot's kernels takes about 4 MB
# Compiler flags of every kernel library. The kernels are long straight-line code: -O1 runs them as fast as -O2
# and -O3 (within 3 %) and compiles them about 35 % faster (docs/realtime.md).
FLAGS = ("-O1",)
# Modules of the package that build no compiled kernel, left out of the source hash of the cache key (so that
# editing them does not recompile every kernel). Everything else in the package is in it, new modules included.
NOT_IN_KEY = ("cli.py", "commands", "run", "files.py", "table.py", "outputs", "bench", "export", "report", "study", "task",
              "sweep")
_OWN_DIR = re.compile(r"^(chewbot-[^/]+-casadi-[^/]+|casadi-[0-9][^/]*)$")  # casadi-X: the layout before version folders
_TEMP = re.compile(r"^\.(?:.+)\.(?P<pid>\d+)\.[A-Za-z0-9_]+\.(?:tmp|build)$")
_GRAPHS: dict[tuple, ca.Function] = {}
_LOADED: dict[tuple, object] = {}
GRAPH_LOCK = threading.RLock()  # CasADi releases the GIL: graphs are built, generated and loaded one at a time


@dataclass(frozen=True, eq=False)
class KernelSpec:
    """A per-sample kernel known before its graph is built.

    ``name``: the C function's name; ``build``: returns the CasADi ``Function`` (called once per process, and
    only when the kernel is not in the cache); ``key``: everything besides chewbot's source that determines the
    graph (mechanism, orientation, options, the parameter values where they are folded in).
    """

    name: str
    build: Callable[[], ca.Function] = field(repr=False)
    key: tuple = ()

    def graph(self) -> ca.Function:
        """The CasADi function (built once per process)."""
        k = (self.name, self.key)
        with GRAPH_LOCK:
            if k not in _GRAPHS:
                fn = self.build()
                if fn.name() != self.name:
                    raise ValueError(f"kernel {self.name!r}: its graph is named {fn.name()!r}")
                _GRAPHS[k] = fn
            return _GRAPHS[k]


def as_spec(kernel: KernelSpec | ca.Function) -> KernelSpec:
    """A spec for a function given as a graph: keyed by its serialised form (no code generation)."""
    if isinstance(kernel, KernelSpec):
        return kernel
    digest = hashlib.sha256(kernel.serialize().encode()).hexdigest()
    spec = KernelSpec(kernel.name(), lambda: kernel, ("graph", digest))
    with GRAPH_LOCK:
        _GRAPHS.setdefault((spec.name, spec.key), kernel)
    return spec


# ----------------------------------------------------------------------------------------------- cache


def cache_root() -> Path:
    """The kernel cache: ``$CHEWBOT_CACHE``, else ``$XDG_CACHE_HOME/chewbot``, else ``~/.cache/chewbot``."""
    if os.environ.get("CHEWBOT_CACHE"):
        return Path(os.environ["CHEWBOT_CACHE"])
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]) / "chewbot"
    return Path(os.path.expanduser("~")) / ".cache" / "chewbot"


def _chewbot_version() -> str:
    from chewbot import __version__

    return __version__


def cache_dir() -> Path:
    """The folder of this chewbot and CasADi version in the cache (created)."""
    path = cache_root() / f"chewbot-{_chewbot_version()}-casadi-{ca.__version__}"
    path.mkdir(parents=True, exist_ok=True)
    return path


def max_cache_bytes() -> int:
    """The size cap of the cache: ``$CHEWBOT_CACHE_MAX_MB`` megabytes (default :data:`DEFAULT_MAX_MB`)."""
    value = os.environ.get("CHEWBOT_CACHE_MAX_MB", "")
    try:
        mb = float(value) if value else DEFAULT_MAX_MB
    except ValueError:
        raise ValueError(f"$CHEWBOT_CACHE_MAX_MB must be a number of megabytes, not {value!r}") from None
    return int(mb * 1e6)


@functools.cache
def source_digest(root: Path | None = None) -> str:
    """SHA-256 of the package's Python source (``root``: the package folder, by default this one's), without the
    modules of :data:`NOT_IN_KEY`."""
    root = root or Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        if rel.parts[0] in NOT_IN_KEY or "__pycache__" in rel.parts:
            continue
        h.update(str(rel.as_posix()).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def c_compiler() -> str | None:
    """The C compiler used for kernels (``$CC``, else cc/gcc/clang on the PATH), or None."""
    for name in filter(None, (os.environ.get("CC"), "cc", "gcc", "clang")):
        if shutil.which(name):
            return name
    return None


@functools.cache
def _compiler_identity(cc: str) -> str:
    """The compiler's path and version line, part of the cache key: another compiler, another library."""
    version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()
    return f"{shutil.which(cc)} {version[0] if version else ''}"


@functools.cache
def _processor_identity() -> str:
    """The processor's architecture and model (Linux: /proc/cpuinfo's "model name"), part of the key of a library
    built for this processor only (-march=native): a cache shared between machines never hands it to another."""
    model = ""
    try:
        with open("/proc/cpuinfo") as info:
            model = next((line.split(":", 1)[1].strip() for line in info if line.startswith("model name")), "")
    except OSError:
        pass
    return f"{platform.machine()} {model or platform.processor()}"


def kernel_key(spec: KernelSpec, flags: tuple[str, ...] = FLAGS) -> str:
    """The cache key of a kernel, from what determines its code, without building it: chewbot's source
    (:func:`source_digest`), the kernel's name and key, the chewbot and CasADi versions, the compiler and flags,
    and the processor where a flag builds for it (-march=native)."""
    cc = c_compiler() or ""
    parts = [source_digest(), spec.name, repr(spec.key), _chewbot_version(), ca.__version__,
             _compiler_identity(cc) if cc else "", list(flags)]
    if any(flag.startswith("-march=native") or flag.startswith("-mcpu=native") for flag in flags):
        parts.append(_processor_identity())
    return hashlib.sha256(json.dumps(parts).encode()).hexdigest()[:24]


def _library_path(spec: KernelSpec, flags: tuple[str, ...]) -> Path:
    return cache_dir() / f"{spec.name}-{kernel_key(spec, flags)}.so"


def _batch_wrapper(fn: ca.Function) -> str:
    """C source of ``NAME_batch``: the kernel called on n samples stored one after the other (stride 0: the
    same input for every sample), so a whole trajectory is one call with no copies."""
    name = fn.name()
    lines = [
        "",
        f"CASADI_SYMBOL_EXPORT int {name}_batch(long long n, const casadi_real** in, const long long* stride,",
        "                                      casadi_real** out, casadi_int* iw, casadi_real* w) {",
        f"  const casadi_real* arg[{max(fn.sz_arg(), 1)}] = {{0}};",
        f"  casadi_real* res[{max(fn.sz_res(), 1)}] = {{0}};",
        "  for (long long s = 0; s < n; ++s) {",
    ]
    lines += [f"    arg[{i}] = in[{i}] + s * stride[{i}];" for i in range(fn.n_in())]
    lines += [f"    res[{j}] = out[{j}] + s * {fn.nnz_out(j)};" for j in range(fn.n_out())]
    lines += [f"    if ({name}(arg, res, iw, w, 0)) return 1;", "  }", "  return 0;", "}", ""]
    return "\n".join(lines)


class _Build:
    """One library being compiled: the C source in a temporary folder, the compiler running on it."""

    def __init__(self, spec: KernelSpec, lib: Path, flags: tuple[str, ...]):
        self.spec, self.lib = spec, lib
        tag = f"{os.getpid()}.{os.urandom(4).hex()}"
        self.folder = lib.parent / f".{lib.stem}.{tag}.build"
        self.partial = lib.parent / f".{lib.stem}.{tag}.tmp"
        self.process: subprocess.Popen | None = None
        try:
            self.folder.mkdir()
            fn = spec.graph()
            with GRAPH_LOCK:
                cg = ca.CodeGenerator(f"{spec.name}.c", {"with_header": False})
                cg.add(fn)
                cg.generate(f"{self.folder}{os.sep}")
            source = self.folder / f"{spec.name}.c"
            with open(source, "a") as f:
                f.write(_batch_wrapper(fn))
            cmd = [c_compiler(), *flags, "-fPIC", "-shared", "-o", str(self.partial), str(source), "-lm"]
            self.process = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        except BaseException:
            self.cleanup()
            raise

    def finish(self) -> Path:
        try:
            _, err = self.process.communicate()
            if self.process.returncode != 0:
                raise RuntimeError(f"compiling kernel {self.spec.name} failed:\n{err[-2000:]}")
            os.replace(self.partial, self.lib)  # atomic: a concurrent process never loads a half-written library
        finally:
            self.cleanup()
        return self.lib

    def cleanup(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.partial.unlink(missing_ok=True)
        shutil.rmtree(self.folder, ignore_errors=True)


def compile_library(kernel: KernelSpec | ca.Function, flags: tuple[str, ...] = FLAGS) -> Path:
    """The shared library of a kernel (with ``NAME_batch``, see :class:`NativeFunction`): from the cache, or
    built, compiled and stored there. Raises RuntimeError where there is no C compiler."""
    return prepare([kernel], flags)[0]


def prepare(kernels: list[KernelSpec | ca.Function], flags: tuple[str, ...] = FLAGS) -> list[Path]:
    """The libraries of several kernels, compiling the missing ones side by side: while the compiler works on
    one, the next graph is built (the C compilers run in parallel, one per available core)."""
    if c_compiler() is None:
        raise RuntimeError("no C compiler found (set $CC, or install cc/gcc/clang)")
    specs = [as_spec(k) for k in kernels]
    libs = [_library_path(s, flags) for s in specs]
    missing = [(s, lib) for s, lib in zip(specs, libs) if not lib.exists()]
    if missing:
        _remove_stale_temporaries(libs[0].parent)
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        running: list[_Build] = []
        try:
            for spec, lib in dict((lib, (spec, lib)) for spec, lib in missing).values():
                if len(running) >= cores:
                    running.pop(0).finish()
                running.append(_Build(spec, lib, flags))
            while running:
                running.pop(0).finish()
        finally:
            for build in running:
                build.cleanup()
        evict(keep=set(libs))
    for lib in libs:
        try:
            os.utime(lib)  # the least recently used are evicted first
        except OSError:
            pass
    return libs


def prepare_kernels(kernels: list[KernelSpec | ca.Function], flags: tuple[str, ...] = FLAGS) -> None:
    """Compile the kernels missing from the cache side by side (:func:`prepare`), before they are loaded one
    by one; nothing where they run in CasADi's virtual machine (no compiler, or the cache is unusable)."""
    if c_compiler() is None or os.environ.get("CHEWBOT_NO_COMPILE"):
        return
    try:
        prepare(kernels, flags)
    except OSError as exc:
        _cache_unusable(exc)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale_temporaries(folder: Path) -> None:
    """Temporary files and folders of processes that no longer exist (killed while compiling)."""
    for path in folder.iterdir():
        m = _TEMP.match(path.name)
        if m and not _pid_alive(int(m.group("pid"))):
            shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink(missing_ok=True)


def _own_files(folder: Path):
    """chewbot's files in a folder of the cache: libraries and temporaries."""
    for path in folder.iterdir():
        if path.suffix == ".so" and path.is_file() or _TEMP.match(path.name):
            yield path


def evict(keep: set[Path] = frozenset()) -> None:
    """Remove the libraries of other chewbot or CasADi versions, then the least recently used beyond the size
    cap (:func:`max_cache_bytes`), never those in ``keep``."""
    root, current = cache_root(), cache_dir()
    for folder in root.iterdir():
        if folder.is_dir() and folder != current and _OWN_DIR.match(folder.name):
            _remove_folder(folder)
    libs = [(p.stat().st_mtime, p.stat().st_size, p) for p in current.glob("*.so")]
    total, cap = sum(size for _, size, _ in libs), max_cache_bytes()
    for _, size, path in sorted(libs, key=lambda entry: entry[0]):
        if total <= cap:
            break
        if path not in keep:
            path.unlink(missing_ok=True)
            total -= size


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


def cache_info() -> dict:
    """The cache's location, and the number and total size (bytes) of chewbot's libraries in it."""
    root = cache_root()
    libs = [p for d in (root.iterdir() if root.is_dir() else []) if d.is_dir() and _OWN_DIR.match(d.name)
            for p in d.glob("*.so")]
    return {"location": root, "libraries": len(libs), "bytes": sum(p.stat().st_size for p in libs),
            "max_bytes": max_cache_bytes()}


def clear_cache() -> tuple[int, int]:
    """Remove chewbot's libraries and temporary files from the cache (nothing else); (libraries, bytes) removed."""
    root = cache_root()
    count = size = 0
    if root.is_dir():
        for folder in root.iterdir():
            if folder.is_dir() and _OWN_DIR.match(folder.name):
                c, s = _remove_folder(folder)
                count, size = count + c, size + s
    return count, size


# -------------------------------------------------------------------------------------- compiled kernels


def compiled(kernel: KernelSpec | ca.Function, flags: tuple[str, ...] = FLAGS) -> ca.Function:
    """The kernel compiled to C and loaded back as a CasADi function (``ca.external``); its graph in CasADi's
    virtual machine where there is no C compiler (or ``$CHEWBOT_NO_COMPILE`` is set): same results, slower."""
    return _load(kernel, flags, "external", lambda spec: ca.external(spec.name, str(compile_library(spec, flags))))


def native(kernel: KernelSpec | ca.Function, flags: tuple[str, ...] = FLAGS) -> "NativeFunction | ca.Function":
    """The kernel as a :class:`NativeFunction` (compiled, called through ctypes); its graph where there is no C
    compiler (or ``$CHEWBOT_NO_COMPILE`` is set): :func:`evaluate` takes either, with the same results."""
    return _load(kernel, flags, "native", lambda spec: NativeFunction(spec, flags))


def _load(kernel: KernelSpec | ca.Function, flags: tuple[str, ...], kind: str, load: Callable):
    """``load(spec)`` (a library loaded as ``kind``), kept for the process; the graph itself where nothing can be
    compiled or cached."""
    spec = as_spec(kernel)
    if c_compiler() is None or os.environ.get("CHEWBOT_NO_COMPILE"):
        return spec.graph()
    key = (kind, spec.name, spec.key, flags)
    with GRAPH_LOCK:
        if key not in _LOADED:
            try:
                _LOADED[key] = load(spec)
            except OSError as exc:
                _cache_unusable(exc)
                return spec.graph()
        return _LOADED[key]


def _cache_unusable(exc: OSError) -> None:
    warnings.warn(f"the kernel cache cannot be used ({exc}); running the CasADi graphs in its virtual machine "
                  "instead (same results, slower); set $CHEWBOT_CACHE to a writable folder", RuntimeWarning, stacklevel=3)


class NativeFunction:
    """A compiled kernel called straight through ctypes: one sample with little overhead, or a whole trajectory
    in one C loop with no conversion through CasADi's matrices.

    ``fn(*inputs)`` evaluates one sample (a few microseconds of overhead, where CasADi's own Python call costs
    tens) and returns the outputs as new NumPy arrays (vectors flat, matrices with their shape). Calls from
    several threads are serialised (the buffers are per instance).
    ``fn.batch(*inputs)`` evaluates N samples: inputs (N, k) (or (k,) for the same value at every sample, with
    no copy), outputs (N, rows) or (N, rows, cols), as :func:`evaluate` returns them. The kernels' parameter
    input ``p`` is such an input: ``(n_p,)`` for one model, ``(N, n_p)`` for a model per sample.
    ``function`` is the library loaded as a CasADi function (its names and sparsity come from the library).
    """

    def __init__(self, kernel: KernelSpec | ca.Function, flags: tuple[str, ...] = FLAGS):
        spec = as_spec(kernel)
        path = str(compile_library(spec, flags))
        fn = ca.external(spec.name, path)
        if any(fn.nnz_in(i) != fn.numel_in(i) for i in range(fn.n_in())) or any(fn.nnz_out(j) != fn.numel_out(j) for j in range(fn.n_out())):
            raise ValueError(f"{fn.name()}: NativeFunction needs dense inputs and outputs")
        self.function = fn
        self.name = fn.name()
        self._lib = ctypes.CDLL(path)
        dbl_p = ctypes.POINTER(ctypes.c_double)
        self._c = getattr(self._lib, self.name)
        self._c.restype = ctypes.c_int
        self._c.argtypes = [ctypes.POINTER(dbl_p), ctypes.POINTER(dbl_p), ctypes.POINTER(ctypes.c_longlong), dbl_p, ctypes.c_int]
        self._cb = getattr(self._lib, f"{self.name}_batch")
        self._cb.restype = ctypes.c_int
        self._cb.argtypes = [ctypes.c_longlong, ctypes.POINTER(dbl_p), ctypes.POINTER(ctypes.c_longlong),
                             ctypes.POINTER(dbl_p), ctypes.POINTER(ctypes.c_longlong), dbl_p]
        self._dbl_p = dbl_p
        self._in = [np.zeros(fn.nnz_in(i)) for i in range(fn.n_in())]
        self._out = [np.zeros(fn.nnz_out(j)) for j in range(fn.n_out())]
        self._shapes = [(fn.size1_out(j), fn.size2_out(j)) for j in range(fn.n_out())]
        self._arg = (dbl_p * max(fn.sz_arg(), 1))(*[a.ctypes.data_as(dbl_p) for a in self._in])
        self._res = (dbl_p * max(fn.sz_res(), 1))(*[a.ctypes.data_as(dbl_p) for a in self._out])
        self._iw = (ctypes.c_longlong * max(fn.sz_iw(), 1))()
        self._w = (ctypes.c_double * max(fn.sz_w(), 1))()
        self._lock = threading.Lock()

    def name_out(self) -> list[str]:
        """The names of the outputs, as the CasADi function's."""
        return self.function.name_out()

    @property
    def input_buffers(self) -> list[np.ndarray]:
        """The arrays the kernel reads its inputs from (flat, matrices column-major), one per input."""
        return self._in

    @property
    def output_buffers(self) -> list[np.ndarray]:
        """The arrays the kernel writes its outputs to (flat, matrices column-major), one per output."""
        return self._out

    def bound_call(self):
        """A function of no argument that evaluates the kernel on :attr:`input_buffers` into
        :attr:`output_buffers` (nothing converted, nothing copied, no lock) and returns the kernel's status
        (0: success). For one thread: the buffers and work arrays are this object's."""
        return functools.partial(self._c, self._arg, self._res, self._iw, self._w, 0)

    def _check_count(self, inputs) -> None:
        if len(inputs) != self.function.n_in():
            raise ValueError(f"{self.name}: {len(inputs)} inputs given, it takes {self.function.n_in()} "
                             f"({', '.join(self.function.name_in())})")

    def __call__(self, *inputs) -> list[np.ndarray]:
        self._check_count(inputs)
        fn = self.function
        with self._lock:  # the buffers are shared, and ctypes releases the GIL during the call
            for i, (buf, x) in enumerate(zip(self._in, inputs)):
                x = np.ravel(np.asarray(x, dtype=float), order="F")
                if x.size != buf.size:
                    raise ValueError(f"{self.name}: input {fn.name_in(i)} has {x.size} entries, expected {buf.size}")
                buf[:] = x
            if self._c(self._arg, self._res, self._iw, self._w, 0):
                raise RuntimeError(f"kernel {self.name} failed")
            return [o.reshape(shape, order="F").copy() if shape[1] > 1 else o.copy() for o, shape in zip(self._out, self._shapes)]

    def batch(self, *inputs) -> list[np.ndarray]:
        self._check_count(inputs)
        fn = self.function
        n = _samples(inputs)
        arrays, strides = [], []
        for i, x in enumerate(inputs):
            a = np.ascontiguousarray(x, dtype=float)
            if a.ndim == 1 and fn.nnz_in(i) == 1 and a.size == n:  # a scalar per sample
                a = a.reshape(n, 1)
            if a.ndim == 2:
                if a.shape != (n, fn.nnz_in(i)):
                    raise ValueError(f"{self.name}: input {fn.name_in(i)} has shape {a.shape}, expected {(n, fn.nnz_in(i))}")
                strides.append(fn.nnz_in(i))
            else:
                a = np.ascontiguousarray(np.ravel(a, order="F"))
                if a.size != fn.nnz_in(i):
                    raise ValueError(f"{self.name}: input {fn.name_in(i)} has {a.size} entries, expected {fn.nnz_in(i)}")
                strides.append(0)
            arrays.append(a)
        outs = [np.empty((n, fn.nnz_out(j))) for j in range(fn.n_out())]
        dbl_p = self._dbl_p
        ins = (dbl_p * len(arrays))(*[a.ctypes.data_as(dbl_p) for a in arrays])
        res = (dbl_p * len(outs))(*[o.ctypes.data_as(dbl_p) for o in outs])
        with self._lock:  # the work arrays are shared
            if self._cb(n, ins, (ctypes.c_longlong * len(strides))(*strides), res, self._iw, self._w):
                raise RuntimeError(f"kernel {self.name} failed")
        return [o if c == 1 else o.reshape(n, c, r).transpose(0, 2, 1) for o, (r, c) in zip(outs, self._shapes)]


def _samples(inputs) -> int:
    """N: the rows of the (N, k) inputs, which must agree."""
    rows = {np.shape(x)[0] for x in inputs if np.ndim(x) == 2}
    if not rows:
        raise ValueError("evaluate needs at least one (N, k) input to know the number of samples")
    if len(rows) > 1:
        raise ValueError(f"the (N, k) inputs disagree on the number of samples: {sorted(rows)}")
    return rows.pop()


def mapped(fn: ca.Function, n: int) -> ca.Function:
    """``fn`` mapped over n samples (``fn`` itself for one), kept: building a map costs about 10 us per sample,
    more than a call of it."""
    entry = _MAPPED.get((id(fn), n))
    if entry is None or entry[0] is not fn:  # the id of a collected function may be reused
        if len(_MAPPED) > 256:
            _MAPPED.clear()
        entry = _MAPPED[id(fn), n] = (fn, fn.map(n, "serial") if n > 1 else fn)
    return entry[1]


def evaluate(fn: ca.Function | NativeFunction, *inputs: np.ndarray) -> list[np.ndarray]:
    """Evaluate a per-sample function over N samples at once (a :class:`NativeFunction` in one C loop).

    Each input is (N, k) (or (N,) for a scalar, or (k,) to use the same value for every sample, e.g. one
    model's parameter vector p, with no copy); each output comes back as (N, rows) for a column output and
    (N, rows, cols) for a matrix output.
    """
    if isinstance(fn, NativeFunction):
        return fn.batch(*inputs)
    n = _samples(inputs)
    args = []
    for i, x in enumerate(inputs):
        x = np.asarray(x, dtype=float)
        if x.ndim == 2:
            args.append(x.T)
        elif x.ndim == 1 and fn.numel_in(i) == 1 and x.shape[0] == n:
            args.append(x[None, :])
        else:
            args.append(x.reshape(-1, 1))  # the map broadcasts an input of one sample's size
    out = mapped(fn, n).call(args)
    result = []
    for j, o in enumerate(out):
        arr = np.asarray(o)  # (rows, cols * n)
        rows, cols = fn.size1_out(j), fn.size2_out(j)
        if cols == 1:
            result.append(arr.T.copy())
        else:
            result.append(arr.reshape(rows, n, cols).transpose(1, 0, 2).copy())
    return result
