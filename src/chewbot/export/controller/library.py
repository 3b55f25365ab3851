"""The exported step run from Python: the library compiled as a shared object (:func:`build_shared`), called through
ctypes with its context mirrored from the field table (:class:`StepLibrary`), and a simulation's controller that runs
it each tick beside the Python controller (:class:`ExportedController`, ``chewbot simulate --exported``)."""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from chewbot.compiled.cache import KERNELS, c_compiler
from chewbot.export.controller.layout import CONTEXT, structures
from chewbot.export.controller.sources import STRICT_FLAGS, dimensions, filled, write_sources
from chewbot.export.controller.step import PREFIX, STATUS_BITS, StepSpec, fk_function, law_function
from chewbot.model import Model, drive
from chewbot.simulation.controllers.law import CompiledLaw
from chewbot.simulation.interfaces import Column, ControllerCapabilities, State


@dataclass(frozen=True)
class SharedLibrary:
    """A compiled step: the shared object's ``path`` and the ``dimensions`` of its header (the context's lengths)."""

    path: Path
    dimensions: Mapping[str, int]


def build_shared(spec: StepSpec, flags: tuple[str, ...] = STRICT_FLAGS) -> SharedLibrary:
    """The library of ``spec`` compiled as a shared object (with :data:`STRICT_FLAGS` and -fPIC), kept in the kernel
    cache under the SHA-256 of its generated sources and the flags (the graphs are built each time, about a second;
    the compilation only once)."""
    cc = c_compiler()
    if cc is None:
        raise RuntimeError("the exported controller needs a C compiler (set $CC, or install cc/gcc/clang)")
    root = KERNELS.folder() / "controllers"
    work = root / f"{PREFIX}.tmp{os.getpid()}"
    shutil.rmtree(work, ignore_errors=True)
    fk, law = fk_function(spec.model), law_function(spec)
    sources = write_sources(spec, work, fk, law)
    built = dimensions(spec, fk, law)
    digest = hashlib.sha256(repr((cc, flags)).encode())
    for path in sorted(work.rglob("*.[ch]")):
        digest.update(path.name.encode() + path.read_bytes())
    base = root / f"{PREFIX}-{digest.hexdigest()[:20]}"
    lib = base / f"lib{PREFIX}.so"
    if lib.exists():
        shutil.rmtree(work, ignore_errors=True)
        return SharedLibrary(lib, built)
    done = subprocess.run([cc, *flags, "-fPIC", "-shared", f"-I{work / 'include'}", "-o", str(work / lib.name), *map(str, sources), "-lm"],
                          capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"compiling the exported controller in {work} failed:\n{done.stderr[-4000:]}")
    try:
        work.replace(base)
    except OSError:  # another process put it there first
        shutil.rmtree(work, ignore_errors=True)
    return SharedLibrary(lib, built)


def double_views(part: ctypes.Structure) -> dict[str, np.ndarray]:
    """Each member of ``part`` (all doubles) as a writable NumPy view of its memory (a scalar: one element)."""
    views = {}
    for name, ctype in part._fields_:
        count = ctypes.sizeof(ctype) // ctypes.sizeof(ctypes.c_double)
        assert ctypes.sizeof(ctype) == count * ctypes.sizeof(ctypes.c_double), name
        views[name] = np.ctypeslib.as_array((ctypes.c_double * count).from_buffer(part, getattr(type(part), name).offset))
    return views


class StepLibrary:
    """The compiled step through ctypes: :meth:`init`, :meth:`step`; the context (:attr:`context`, the ctypes mirror
    of ``chewbot_ctrl``), its settings and outputs as NumPy views by name (:attr:`fields`, also attributes)."""

    def __init__(self, spec: StepSpec, shared: SharedLibrary):
        self.spec, self.shared = spec, shared
        self.lib = ctypes.CDLL(str(shared.path))
        types = structures(shared.dimensions, filled(spec))
        self.context = types[CONTEXT.name]()
        self.lib.chewbot_ctrl_size.restype = ctypes.c_size_t
        if ctypes.sizeof(self.context) != self.lib.chewbot_ctrl_size():
            raise RuntimeError(f"the context's mirror has {ctypes.sizeof(self.context)} bytes, {shared.path}'s chewbot_ctrl "
                               f"{self.lib.chewbot_ctrl_size()}")
        self.ctx = ctypes.pointer(self.context)
        ctx, dp = ctypes.POINTER(types[CONTEXT.name]), ctypes.POINTER(ctypes.c_double)
        for name, restype, argtypes in (("init", None, [ctx, ctypes.c_double, dp]), ("home", None, [ctx, dp]),
                                        ("step", ctypes.c_uint, [ctx, ctypes.c_double, dp, dp, ctypes.POINTER(ctypes.c_uint)]),
                                        ("step_counts", ctypes.c_uint, [ctx, ctypes.c_double, ctypes.POINTER(ctypes.c_long), dp,
                                                                        ctypes.POINTER(ctypes.c_uint)]),
                                        ("set_reference", None, [ctx, dp, dp, dp, dp]), ("use_task", None, [ctx]),
                                        ("set_estop", None, [ctx, ctypes.c_int]), ("clear_faults", None, [ctx])):
            function = getattr(self.lib, f"{PREFIX}_{name}")
            function.restype, function.argtypes = restype, argtypes
        self._theta, self._tau, self._counts = np.zeros(6), np.zeros(6), np.zeros(6, dtype=ctypes.c_long)
        self._status = ctypes.c_uint(0)
        self._p_theta, self._p_tau = self._theta.ctypes.data_as(dp), self._tau.ctypes.data_as(dp)
        self._p_counts = self._counts.ctypes.data_as(ctypes.POINTER(ctypes.c_long))
        self.fields = {**double_views(self.context.config), **double_views(self.context.out)}

    def init(self, t0: float, offsets=None) -> None:
        off = None if offsets is None else np.ascontiguousarray(offsets, float)
        self.lib.chewbot_ctrl_init(self.ctx, float(t0), None if off is None else off.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))

    def step(self, t: float, theta) -> tuple[np.ndarray, int]:
        """One tick: the output torques (a copy) and the status word."""
        self._theta[:] = theta
        status = self.lib.chewbot_ctrl_step(self.ctx, float(t), self._p_theta, self._p_tau, ctypes.byref(self._status))
        return self._tau.copy(), int(status)

    def step_counts(self, t: float, counts) -> tuple[np.ndarray, int]:
        """One tick from the encoders' counts at the motors: the commanded currents (A, a copy) and the status word."""
        self._counts[:] = counts
        status = self.lib.chewbot_ctrl_step_counts(self.ctx, float(t), self._p_counts, self._p_tau, ctypes.byref(self._status))
        return self._tau.copy(), int(status)

    def set_reference(self, q_ref, dq_ref, ddq_ref, force) -> None:
        """The caller's reference for the next steps (chewbot_ctrl_set_reference)."""
        arrays = [np.ascontiguousarray(a, float) for a in (q_ref, dq_ref, ddq_ref, force)]
        dp = ctypes.POINTER(ctypes.c_double)
        self.lib.chewbot_ctrl_set_reference(self.ctx, *(a.ctypes.data_as(dp) for a in arrays))

    def use_task(self) -> None:
        self.lib.chewbot_ctrl_use_task(self.ctx)

    def set_estop(self, on: bool) -> None:
        self.lib.chewbot_ctrl_set_estop(self.ctx, int(on))

    def clear_faults(self) -> None:
        self.lib.chewbot_ctrl_clear_faults(self.ctx)

    def home(self, theta_raw) -> None:
        raw = np.ascontiguousarray(theta_raw, float)
        self.lib.chewbot_ctrl_home(self.ctx, raw.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))

    def __getattr__(self, name: str):
        fields = self.__dict__.get("fields", {})
        if name in fields:
            return fields[name]
        raise AttributeError(name)


@dataclass
class ExportedController:
    """A simulation's controller that runs the exported C step (``chewbot simulate --exported``) on the measured crank
    angles of the state it is given (:attr:`chewbot.simulation.interfaces.State.theta`) and returns its commanded
    torques (``tau_cmd``: before saturation; the simulator saturates them as it does the Python controller's). Where
    the controller's model has a drive with an encoder, the step is given the encoders' counts at the motors (the
    angles on the encoder's grid, :func:`chewbot.model.drive.quantise`, as whole counts: ``chewbot_ctrl_step_counts``)
    and commands currents. It evaluates the Python controller ``python`` on the same tick's estimate too, and the
    currents the simulator makes of its torques (saturated, through the model's drive at the state's crank rates),
    and keeps both, so a run states how far the two are apart tick by tick (:meth:`comparison`)."""

    python: CompiledLaw
    rate: float
    capabilities: ControllerCapabilities = field(default=ControllerCapabilities(), init=False)
    library: StepLibrary | None = None
    c_torques: list = field(default_factory=list)
    py_torques: list = field(default_factory=list)
    c_currents: list = field(default_factory=list)
    py_currents: list = field(default_factory=list)
    statuses: list = field(default_factory=list)

    def __post_init__(self):
        spec = StepSpec.of(self.python, self.rate)
        self.library = StepLibrary(spec, build_shared(spec))
        self._started = False

    @property
    def model(self) -> Model:
        return self.python.model

    @property
    def reference(self):
        return self.python.reference

    def __call__(self, t: float, state: State) -> np.ndarray:
        if state.theta is None:
            raise ValueError("the exported controller needs the measured crank angles (a State with theta)")
        if not self._started:
            self.library.init(t)
            self._started = True
        d = drive.of(self.model)
        if d.encoder_counts:
            self.c_currents.append(self.library.step_counts(t, np.rint(np.asarray(state.theta) / drive.count_angle(d)))[0])
        else:
            self.library.step(t, state.theta)
            self.c_currents.append(self.library.current.copy())
        tau = self.library.tau_cmd.copy()
        self.c_torques.append(tau)
        py = self.python(t, state)
        self.py_torques.append(py)
        limit = self.model.limits.torque
        dtheta = np.zeros(6) if state.dtheta is None else state.dtheta
        self.py_currents.append(drive.current(d, drive.motor_torque(d, np.clip(py, -limit, limit), dtheta)))
        self.statuses.append(int(self.library._status.value))
        return tau

    def kernels(self) -> list:
        return self.python.kernels()

    def columns(self, t: np.ndarray) -> list[Column]:
        return []

    def info(self) -> dict:
        """run.json's ``simulation.exported``: :meth:`comparison`."""
        return {"exported": self.comparison()}

    def comparison(self) -> dict:
        """The exported step's torques (N m) and currents (A) against the Python controller's on the same ticks."""
        def apart(c, py):
            c, py = np.array(c), np.array(py)
            largest = float(np.max(np.abs(c - py))) if len(c) else 0.0
            scale = float(np.max(np.abs(py))) if len(py) else 0.0
            return largest, scale, largest / scale if scale else 0.0

        largest, scale, relative = apart(self.c_torques, self.py_torques)
        amperes, current_scale, current_relative = apart(self.c_currents, self.py_currents)
        statuses = np.bitwise_or.reduce(np.array(self.statuses, dtype=np.int64)) if self.statuses else 0
        return {"library": str(self.library.shared.path), "ticks": len(self.c_torques), "largest_difference_Nm": largest,
                "largest_abs_tau_Nm": scale, "relative": relative, "encoder_counts": bool(drive.of(self.model).encoder_counts),
                "largest_current_difference_A": amperes, "largest_abs_current_A": current_scale,
                "current_relative": current_relative,
                "status_bits_seen": [name for name, bit in STATUS_BITS.items() if statuses & bit]}


def simulation_log(result) -> np.ndarray:
    """The rows of example/log.csv from a simulation of the controller with the measured sensor path
    (:class:`chewbot.simulation.run.SimulateResult`): t, the plant's crank angles as its encoders read them (noise-free;
    on their grid where the plant has a drive), the controller's commanded torques."""
    sim = result.simulation
    read = drive.quantise(drive.of(result.plant_model), result.kinematics.theta)
    return np.column_stack([sim.t, read, sim.tau_cmd])
