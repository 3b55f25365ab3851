"""Evaluating CasADi functions over whole trajectories, and compiling them to C.

A per-sample CasADi ``Function`` is mapped over the N samples of a trajectory in one call (no Python loop).
A kernel is described by a :class:`KernelSpec`: its C name, the function that builds its graph on the model's
numbers, and the key of what else determines the graph (mechanism, orientation, goal ...). A kernel's graph takes
the model's parameter vector p as its last input; :meth:`KernelSpec.folded` gives the same kernel with one model's
numbers folded in as constants (no p: what ``chewbot export-c`` writes for a robot's controller). :func:`native`
and :func:`compiled` turn a spec into a shared library with the system C compiler, kept in the kernel cache
(:mod:`chewbot.compiled.cache`); where no C compiler is found, the graph runs in CasADi's virtual machine (same
results, slower).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shutil
import subprocess
import threading
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import casadi as ca
import numpy as np

from chewbot.compiled.cache import KERNELS, LibraryKey, builder_modules, c_compiler, folded, symbols
from chewbot.model import Model
from chewbot.model.symbolic import SymbolicModel
from chewbot.model.vector import vector_digest
from chewbot.progress import SILENT, Progress

# Compiler flags of every kernel library. The kernels are long straight-line code: -O1 runs them as fast as -O2
# and -O3 (within 3 %) and compiles them about 35 % faster (docs/realtime.md).
FLAGS = ("-O1",)


@dataclass(frozen=True, eq=False)
class KernelSpec:
    """A per-sample kernel known before its graph is built.

    ``name``: the C function's name; ``build(params)``: returns the CasADi ``Function`` built on the model's numbers
    ``params`` (:class:`~chewbot.model.symbolic.SymbolicModel`: the symbol p of ``mechanism``, an input of the
    graph, or one model's constants; called once per process and numbers, and only when the kernel is not in the
    cache); ``key``: everything besides chewbot's source that determines the graph (mechanism, orientation,
    options); ``mechanism``: the robot the graph is of (empty for a graph of no model); ``model``: the model whose
    numbers are folded in (None: p is an input, one kernel for every model of the mechanism)."""

    name: str
    build: Callable = field(repr=False)
    key: tuple = ()
    mechanism: str = ""
    model: Model | None = field(default=None, repr=False)

    def params(self) -> SymbolicModel | None:
        """The numbers the graph is built on: the model's constants where folded, else the mechanism's symbol p."""
        if self.model is not None:
            return folded(self.model)
        return symbols(self.mechanism) if self.mechanism else None

    @property
    def cache_key(self) -> tuple:
        """The kernel's key with the digest of the numbers folded in (if any)."""
        return self.key if self.model is None else (*self.key, ("p", vector_digest(self.model)))

    def graph(self, params: SymbolicModel | None = None) -> ca.Function:
        """The CasADi function (built once per process and numbers): on ``params`` where given (a builder composing
        kernels passes its own), else on the spec's (:meth:`params`)."""
        if params is not None:
            numbers = params.key
        else:
            numbers = ("model", self.model.mechanism, vector_digest(self.model)) if self.model is not None else self.mechanism
        key = (self.name, self.key, numbers)

        def build():
            fn = self.build(params if params is not None else self.params())
            if fn.name() != self.name:
                raise ValueError(f"kernel {self.name!r}: its graph is named {fn.name()!r}")
            return fn

        return KERNELS.graph(("kernel", *key), build)

    def folded(self, model: Model) -> KernelSpec:
        """The same kernel with ``model``'s numbers folded in as constants (no input p), for that robot's controller."""
        if model.mechanism != self.mechanism:
            raise ValueError(f"kernel {self.name!r} is of the {self.mechanism}, the model {model.name!r} of the {model.mechanism}")
        return replace(self, model=model)

    def modules(self) -> tuple[str, ...]:
        """The chewbot modules the graph is built by (:func:`chewbot.compiled.cache.builder_modules`)."""
        return builder_modules(self.build)


def as_spec(kernel: KernelSpec | ca.Function) -> KernelSpec:
    """A spec for a function given as a graph: keyed by its serialised form (no code generation)."""
    if isinstance(kernel, KernelSpec):
        return kernel
    digest = hashlib.sha256(kernel.serialize().encode()).hexdigest()
    spec = KernelSpec(kernel.name(), lambda params: kernel, ("graph", digest))
    KERNELS.graph(("kernel", spec.name, spec.key, ""), lambda: kernel)
    return spec


def kernel_key(spec: KernelSpec, flags: tuple[str, ...] = FLAGS) -> LibraryKey:
    """The cache key of a kernel's library (:meth:`chewbot.compiled.cache.KernelCache.key`), computed without
    building it."""
    return KERNELS.key(spec.name, spec.cache_key, spec.modules(), flags)


def _library_path(spec: KernelSpec, flags: tuple[str, ...]) -> Path:
    return KERNELS.library(spec.name, kernel_key(spec, flags))


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
            with KERNELS.lock:
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


def prepare(kernels: list[KernelSpec | ca.Function], flags: tuple[str, ...] = FLAGS, progress: Progress = SILENT) -> list[Path]:
    """The libraries of several kernels, compiling the missing ones side by side: while the compiler works on
    one, the next graph is built (the C compilers run in parallel, one per available core). ``progress`` is told
    each graph built and each library compiled (``compiling kernels: 1 of 4 done, building NAME``)."""
    if c_compiler() is None:
        raise RuntimeError("no C compiler found (set $CC, or install cc/gcc/clang)")
    specs = [as_spec(k) for k in kernels]
    libs = [_library_path(s, flags) for s in specs]
    missing = [(s, lib) for s, lib in zip(specs, libs) if not lib.exists()]
    if missing:
        KERNELS.remove_stale_temporaries(libs[0].parent)
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        running: list[_Build] = []
        todo = list(dict((lib, (spec, lib)) for spec, lib in missing).values())
        done = 0

        def finish() -> None:
            nonlocal done
            running.pop(0).finish()
            done += 1
            progress(f"compiling kernels: {done} of {len(todo)} done (kept in the kernel cache for the next runs)")

        try:
            for spec, lib in todo:
                if len(running) >= cores:
                    finish()
                progress(f"compiling kernels: {done} of {len(todo)} done, building {spec.name}")
                running.append(_Build(spec, lib, flags))
            while running:
                finish()
        finally:
            for build in running:
                build.cleanup()
        KERNELS.evict(keep=set(libs))
    for lib in libs:
        try:
            os.utime(lib)  # the least recently used are evicted first
        except OSError:
            pass
    return libs


def prepare_kernels(kernels: list[KernelSpec | ca.Function], flags: tuple[str, ...] = FLAGS, progress: Progress = SILENT) -> None:
    """Compile the kernels missing from the cache side by side (:func:`prepare`, telling ``progress``), before they
    are loaded one by one; nothing where they run in CasADi's virtual machine (no compiler, or the cache is
    unusable)."""
    if c_compiler() is None or os.environ.get("CHEWBOT_NO_COMPILE"):
        return
    try:
        prepare(kernels, flags, progress)
    except OSError as exc:
        _cache_unusable(exc)


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
    try:
        return KERNELS.loaded((kind, spec.name, spec.cache_key, flags), lambda: load(spec))
    except OSError as exc:
        _cache_unusable(exc)
        return spec.graph()


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
        if len(inputs) != len(self._in):
            raise ValueError(f"{self.name}: {len(inputs)} inputs given, it takes {self.function.n_in()} "
                             f"({', '.join(self.function.name_in())})")

    def __call__(self, *inputs) -> list[np.ndarray]:
        self._check_count(inputs)
        fn = self.function
        with self._lock:  # the buffers are shared, and ctypes releases the GIL during the call
            for i, (buf, x) in enumerate(zip(self._in, inputs)):
                if type(x) is np.ndarray and x.shape == buf.shape:  # a vector as the kernel takes it (most calls in a loop)
                    buf[:] = x
                    continue
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
    out = KERNELS.mapped(fn, n).call(args)
    result = []
    for j, o in enumerate(out):
        arr = np.asarray(o)  # (rows, cols * n)
        rows, cols = fn.size1_out(j), fn.size2_out(j)
        if cols == 1:
            result.append(arr.T.copy())
        else:
            result.append(arr.reshape(rows, n, cols).transpose(1, 0, 2).copy())
    return result
