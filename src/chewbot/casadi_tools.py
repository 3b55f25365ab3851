"""Evaluating CasADi functions over whole trajectories, and compiling them to C.

A per-sample CasADi ``Function`` is mapped over the N samples of a trajectory in one call (no Python loop).
:func:`compiled` turns a function into a shared library with the system C compiler (cached on disk by the hash
of its generated source) and falls back to CasADi's virtual machine where no compiler is found.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
import warnings
from pathlib import Path

import casadi as ca
import numpy as np

_MAPPED: dict[tuple[int, int], tuple[ca.Function, ca.Function]] = {}


def cache_dir() -> Path:
    """Where compiled kernels are kept: ``$CHEWBOT_CACHE`` or ``~/.cache/chewbot``."""
    root = os.environ.get("CHEWBOT_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "chewbot")
    path = Path(root) / f"casadi-{ca.__version__}"
    path.mkdir(parents=True, exist_ok=True)
    return path


def c_compiler() -> str | None:
    """The C compiler used for kernels (``$CC``, else cc/gcc/clang on the PATH), or None."""
    for name in filter(None, (os.environ.get("CC"), "cc", "gcc", "clang")):
        if shutil.which(name):
            return name
    return None


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


def compile_library(fn: ca.Function, flags: tuple[str, ...] = ("-O2",), batch: bool = False) -> Path:
    """Generate C for ``fn``, compile it to a shared library with the system C compiler and return its path.

    ``batch`` adds ``NAME_batch`` (see :class:`NativeFunction`).
    The library is cached under :func:`cache_dir` by the SHA-256 of the generated C source and the flags, so a
    kernel is compiled once per machine. Raises RuntimeError where there is no C compiler.
    """
    cc = c_compiler()
    if cc is None:
        raise RuntimeError("no C compiler found (set $CC, or install cc/gcc/clang)")
    with tempfile.TemporaryDirectory() as tmp:
        cname = f"{fn.name()}.c"
        cg = ca.CodeGenerator(cname, {"with_header": False})
        cg.add(fn)
        cg.generate(f"{tmp}{os.sep}")
        if batch:
            with open(Path(tmp, cname), "a") as f:
                f.write(_batch_wrapper(fn))
        source = Path(tmp, cname).read_bytes()
        digest = hashlib.sha256(source + " ".join([_compiler_identity(cc), *flags]).encode()).hexdigest()[:20]
        lib = cache_dir() / f"{fn.name()}_{digest}.so"
        if not lib.exists():
            fd, partial = tempfile.mkstemp(suffix=".tmp", prefix=f".{lib.stem}.", dir=lib.parent)
            os.close(fd)
            try:
                cmd = [cc, *flags, "-fPIC", "-shared", "-o", partial, str(Path(tmp, cname)), "-lm"]
                result = subprocess.run(cmd, capture_output=True, text=True)
                if result.returncode != 0:
                    raise RuntimeError(f"compiling kernel {fn.name()} failed:\n{result.stderr[-2000:]}")
                os.replace(partial, lib)  # atomic: a concurrent process or thread never loads a half-written library
            finally:
                Path(partial).unlink(missing_ok=True)
    return lib


@functools.cache
def _compiler_identity(cc: str) -> str:
    """The compiler's path and version line, part of the cache key: another compiler, another library."""
    version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()
    return f"{shutil.which(cc)} {version[0] if version else ''}"


def compiled(fn: ca.Function, flags: tuple[str, ...] = ("-O2",)) -> ca.Function:
    """``fn`` compiled to C and loaded back as a CasADi function; ``fn`` itself if there is no C compiler
    (or ``$CHEWBOT_NO_COMPILE`` is set): the results are the same, only slower."""
    if c_compiler() is None or os.environ.get("CHEWBOT_NO_COMPILE"):
        return fn
    try:
        return ca.external(fn.name(), str(compile_library(fn, flags)))
    except OSError as exc:
        _cache_unusable(exc)
        return fn


def native(fn: ca.Function) -> "NativeFunction | ca.Function":
    """``fn`` as a :class:`NativeFunction` (compiled, called through ctypes); ``fn`` itself where there is no C
    compiler (or ``$CHEWBOT_NO_COMPILE`` is set): :func:`evaluate` takes either, with the same results."""
    if c_compiler() is None or os.environ.get("CHEWBOT_NO_COMPILE"):
        return fn
    try:
        return NativeFunction(fn)
    except OSError as exc:
        _cache_unusable(exc)
        return fn


def _cache_unusable(exc: OSError) -> None:
    warnings.warn(f"the kernel cache cannot be used ({exc}); running the CasADi graphs in its virtual machine "
                  "instead (same results, slower); set $CHEWBOT_CACHE to a writable folder", RuntimeWarning, stacklevel=3)


class NativeFunction:
    """A compiled kernel called straight through ctypes: one sample with little overhead, or a whole trajectory
    in one C loop with no conversion through CasADi's matrices.

    ``fn(*inputs)`` evaluates one sample (a few microseconds of overhead, where CasADi's own Python call costs
    tens) and returns the outputs as new NumPy arrays (vectors flat, matrices with their shape). Calls from
    several threads are serialised (the buffers are per instance).
    ``fn.batch(*inputs)`` evaluates N samples: inputs (N, k) (or (k,) for the same value at every sample),
    outputs (N, rows) or (N, rows, cols), as :func:`evaluate` returns them.
    """

    def __init__(self, fn: ca.Function, flags: tuple[str, ...] = ("-O3",)):
        if any(fn.nnz_in(i) != fn.numel_in(i) for i in range(fn.n_in())) or any(fn.nnz_out(j) != fn.numel_out(j) for j in range(fn.n_out())):
            raise ValueError(f"{fn.name()}: NativeFunction needs dense inputs and outputs")
        self.function = fn
        self.name = fn.name()
        self._lib = ctypes.CDLL(str(compile_library(fn, flags, batch=True)))
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
        n = next((np.shape(x)[0] for x in inputs if np.ndim(x) == 2), None)
        if n is None:
            raise ValueError("batch needs at least one (N, k) input to know the number of samples")
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

    Each input is (N, k) (or (N,) for a scalar, or (k,) to use the same value for every sample); each output
    comes back as (N, rows) for a column output and (N, rows, cols) for a matrix output.
    """
    if isinstance(fn, NativeFunction):
        return fn.batch(*inputs)
    matrices = [np.shape(x)[0] for x in inputs if np.ndim(x) == 2]
    if not matrices:
        raise ValueError("evaluate needs at least one (N, k) input to know the number of samples")
    n = matrices[0]
    args = []
    for i, x in enumerate(inputs):
        x = np.asarray(x, dtype=float)
        if x.ndim == 2:
            if x.shape[0] != n:
                raise ValueError(f"input {i} has {x.shape[0]} samples, expected {n}")
            args.append(x.T)
        elif x.ndim == 1 and fn.numel_in(i) == 1 and x.shape[0] == n:
            args.append(x[None, :])
        else:
            args.append(np.tile(x.reshape(-1, 1), (1, n)))
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
