"""Per-sample kernels for model-based control at 1 kHz: built once, compiled to C, callable from Python or C.

| kernel | inputs | outputs |
|---|---|---|
| ``tau_target``, ``tau_sixrss`` | q_EE, q_EE_dot, q_EE_ddot (Euler angles), B, F_B | minimum-norm (target) or unique (6RSS) tau, theta, theta_dot |
| ``dynamics_target``, ``dynamics_sixrss`` | the same | the same and J_theta1, M_f, C_f, G_f, Q_B of Eq. 53 |
| ``coupling_target``, ``coupling_sixrss`` | theta, q_EE | M_A, MCI |
| ``g1_target`` | theta, q_EE, rates, F_B, B | friction-aware minimum torques (goal G1), N_L/N_R, the gradient and last step, the limit values |

Every kernel takes the model's parameter vector p last (:meth:`chewbot.model.Model.vector`), so one compiled
kernel serves every model of its mechanism; :func:`kernels` gives them with one model's numbers folded in (no p,
:meth:`chewbot.compiled.kernels.KernelSpec.folded`), as ``chewbot export-c`` writes them for a robot's controller.

The torque kernels are the 6RSS-core formulation (:mod:`chewbot.dynamics.formulations.core6rss`), the coupling kernels
:func:`chewbot.analysis.coupling.coupling_kernel`, and ``g1_target`` the Newton–Euler model with friction with the
G1 problem solved inside the kernel at a fixed cost (:mod:`chewbot.dynamics.g1`).

:func:`chewbot.compiled.kernels.native` wraps a kernel for calls from Python through ctypes (one sample in a few
microseconds, or a whole trajectory in one C loop);
:func:`chewbot.export.c.export_c` writes them as C for the controller.
"""

from __future__ import annotations

import numpy as np

from chewbot.analysis.coupling import coupling_kernel
from chewbot.compiled.kernels import FLAGS, KernelSpec, native
from chewbot.dynamics.formulations.core6rss import dynamics_kernel, torque_kernel
from chewbot.dynamics.g1 import G1_ITERATIONS, G1_ORIENTATION, g1_kernel
from chewbot.export.c import Kernel
from chewbot.model import Model
from chewbot.simulation.forward import NEWTON_ITERATIONS, forward_kernel

# The example sample of the exported README: the peak of the second bite-force burst of the default task.
EXAMPLE_T = 2.44


# --- one sample at a time, from a Python control loop ---------------------------------------------------------

LOOP_KERNELS = ("tau", "dynamics", "coupling", "g1")


class LoopKernel:
    """A compiled per-sample kernel for a control loop in Python: built once, then each call evaluates one sample
    from preallocated input arrays into preallocated output arrays, with nothing allocated, converted or copied.

    ``inputs`` and ``outputs`` map the kernel's names to its arrays (vectors flat, matrices with their shape,
    views of column-major buffers); each is also an attribute (``k.q``, ``k.tau``). Calling ``k()`` evaluates
    the kernel on what the input arrays hold.

    Aliasing rule: the arrays are the kernel's own and stay the same objects for its lifetime. Write inputs into
    them (``k.q[:] = q``; ``k.q = q`` raises: it would leave the kernel reading the old array); an output array
    is overwritten by the next call: copy it (``k.tau.copy()``) to keep a sample's value. One object per thread.
    """

    def __init__(self, kernel: KernelSpec, flags: tuple[str, ...] = FLAGS):
        from chewbot.compiled.kernels import NativeFunction

        fn = native(kernel, flags)
        if not isinstance(fn, NativeFunction):
            raise RuntimeError(f"{kernel.name}: the in-loop kernels need a C compiler (set $CC) and the kernel cache")
        graph = fn.function
        self.name = fn.name
        self.inputs = {name: _view(buf, graph.size1_in(i), graph.size2_in(i)) for i, (name, buf) in enumerate(zip(graph.name_in(), fn.input_buffers))}
        self.outputs = {name: _view(buf, graph.size1_out(j), graph.size2_out(j)) for j, (name, buf) in enumerate(zip(graph.name_out(), fn.output_buffers))}
        clash = set(self.inputs) & set(self.outputs)
        if clash:
            raise ValueError(f"{self.name}: {sorted(clash)} name both an input and an output")
        self._native = fn  # keeps the library and the buffers alive
        self._run = fn.bound_call()
        self.__dict__.update(self.inputs)
        self.__dict__.update(self.outputs)

    def __setattr__(self, name: str, value) -> None:
        if name in getattr(self, "inputs", {}) or name in getattr(self, "outputs", {}):
            raise AttributeError(f"{name} is one of the kernel's arrays: assign into it ({name}[:] = ...), see LoopKernel")
        object.__setattr__(self, name, value)

    def __call__(self) -> None:
        if self._run():
            raise RuntimeError(f"kernel {self.name} failed")


def _view(buffer: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """A flat column-major buffer as a vector (one column) or a matrix, without a copy."""
    return buffer if cols == 1 else buffer.reshape((rows, cols), order="F")


# Compiler flags of the in-loop kernels: measured in docs/realtime.md ("The in-loop kernels").
LOOP_FLAGS = ("-O3", "-march=native")


def loop_spec(mechanism: str, kind: str) -> KernelSpec:
    """The kernel of :func:`loop_kernel`'s ``kind`` of a mechanism (p an input; :meth:`KernelSpec.folded` folds a
    model's numbers in)."""
    if kind not in LOOP_KERNELS:
        raise ValueError(f"kind must be one of {', '.join(LOOP_KERNELS)}, not {kind!r}")
    return {"tau": torque_kernel, "dynamics": dynamics_kernel, "coupling": coupling_kernel, "g1": g1_kernel}[kind](mechanism)


def loop_kernel(model: Model, kind: str = "tau", side: str = "left", folded: bool = True, flags: tuple[str, ...] = LOOP_FLAGS) -> LoopKernel:
    """A :class:`LoopKernel` of one robot: ``kind`` "tau" (minimum-norm (target) or unique (6RSS) torques: inputs
    q, dq, ddq in Euler angles, B, F_B), "dynamics" (the same with J_theta1, M_f, C_f, G_f, Q_B), "coupling" (M_A,
    MCI from theta, q) or "g1" (the friction-aware G1 distribution of the target: inputs theta, q, dq, ddq in Euler
    parameters, F_B, B). The bite point B is set to the molar of ``side``.

    ``folded``: the model's numbers folded into the compiled code (the fastest; compiled once per parameter set,
    kept in the kernel cache under their SHA-256); else the mechanism's kernel with p as its last input, set here.
    """
    spec = loop_spec(model.mechanism, kind)
    k = LoopKernel(spec.folded(model) if folded else spec, flags)
    if "B" in k.inputs:
        k.B[:] = model.molar(side)
    if not folded:
        k.inputs["p"][:] = model.vector()
    return k


def kernels(target: Model, sixrss: Model, sample: dict[str, dict[str, np.ndarray]] | None = None) -> list[Kernel]:
    """The exported kernels of a target model and its 6RSS counterpart, with their units.

    ``sample``: per kernel name, an example input (used by the example program and the README); by default a
    sample of the default task.
    """
    sample = sample or example_inputs(target, sixrss)
    torque_in = {"q": "m, rad (X, Y, alpha, beta) / (X, Y, Z, alpha, beta, gamma)", "dq": "m/s, rad/s", "ddq": "m/s^2, rad/s^2",
                 "B": "m, in {M}", "F_B": "N, in {S}, on the mandible"}
    torque_out = {"tau": "N m", "theta": "rad", "dtheta": "rad/s", "J_theta1": "rad/m, 1", "M_f": "kg, kg m, kg m^2",
                  "C_f": "kg/s, kg m/s, kg m^2/s", "G_f": "N, N m", "Q_B": "N, N m"}
    coupling_in = {"theta": "rad", "q": "m, rad (Euler angles)"}
    coupling_out = {"M_A": "kg m^2", "MCI": "1"}
    out = []
    for m in (target, sixrss):
        which = "minimum-norm actuator torques of the target (seed 000, Eq. 54)" if m.has_hkp else "actuator torques of the 6RSS (unique)"
        tag = m.mechanism.replace("6rss", "sixrss")
        out += [
            Kernel(torque_kernel(m.mechanism).folded(m), f"The {which}, from the 6RSS core with the HKPs projected out; the lean kernel "
                   "for a feedforward (no matrices formed).", torque_in, torque_out, sample[f"tau_{tag}"]),
            Kernel(dynamics_kernel(m.mechanism).folded(m), f"The {which} with the terms of Eq. 53: J_theta1, M_f, C_f, G_f, Q_B "
                   "(J_theta1' tau = M_f q_ddot + C_f q_dot + G_f - Q_B).", torque_in, torque_out, sample[f"tau_{tag}"]),
            Kernel(coupling_kernel(m.mechanism).folded(m), f"Joint-space inertia M_A and MCI (seed 000, Eqs. 58-60) of the {m.mechanism}.",
                   coupling_in, coupling_out, sample[f"coupling_{tag}"]),
        ]
    forward_in = {"q": torque_in["q"], "dq": torque_in["dq"], "tau": "N m", "B": torque_in["B"], "F_B": torque_in["F_B"],
                  "friction": "0 (off) or 1 (the model's HKP and actuator friction)"}
    for m in (target, sixrss):
        tag = m.mechanism.replace("6rss", "sixrss")
        out.append(Kernel(forward_kernel(m.mechanism).folded(m), f"Forward dynamics of the {m.mechanism}: the accelerations of the independent "
                          f"coordinates{' and the HKP normal forces N_L, N_R' if m.has_hkp else ''} under the torques tau, "
                          f"friction regularised as in the inverse dynamics; {NEWTON_ITERATIONS} Newton steps from the "
                          "frictionless solution (exact without friction). Check residual (N m, ~1e-15 when converged).",
                          forward_in, {"ddq": "m/s^2, rad/s^2", "N": "N (N_L, N_R along the planes' normal)",
                                       "residual": "N m"}, sample[f"forward_{tag}"]))
    out.append(
        Kernel(g1_kernel(target.mechanism).folded(target), f"Friction-aware optimal torque distribution, goal G1 (seed 001, Sect. 4.5), "
               f"{G1_ITERATIONS} safeguarded Newton steps from the best piecewise least-squares start; q in Euler "
               "parameters (X, Y, e0, e1, e2). Check step and grad (both ~0 at the optimum) and the limits.",
               {"theta": "rad", "q": "m, 1 (X, Y, e0, e1, e2)", "dq": "m/s, 1/s", "ddq": "m/s^2, 1/s^2",
                "F_B": "N, in {S}, on the mandible", "B": "m, in {M}"},
               {"tau": "N m", "N": "N (N_L, N_R along the planes' normal)", "grad": "N m^2 / N", "step": "N",
                "limits": "N m (tau 1-6), W (power 1-6), N (axial 1-6), N (radial 1-6)"}, sample["g1_target"]))
    return out


def example_inputs(target: Model, sixrss: Model, t: float = EXAMPLE_T) -> dict[str, dict[str, np.ndarray]]:
    """One sample of the default left-side task (at ``t`` s, inside a bite-force burst) as kernel inputs."""
    from chewbot.kinematics.motion import solve_kinematics
    from chewbot.task.default import default_task

    out = {}
    for m, tag in ((target, "target"), (sixrss, "sixrss")):
        task = default_task(m, "left")
        k = int(np.argmin(np.abs(task.t - t)))
        kin = solve_kinematics(m, task, "euler-angles")
        q, dq, ddq = (x[k] for x in kin.euler_angle_state())
        B = m.molar("left")
        out[f"tau_{tag}"] = {"q": q, "dq": dq, "ddq": ddq, "B": B, "F_B": kin.force[k]}
        out[f"coupling_{tag}"] = {"theta": kin.theta[k], "q": q}
        tau = np.asarray(torque_kernel(m.mechanism).folded(m).graph()(q, dq, ddq, B, kin.force[k])[0]).ravel()
        out[f"forward_{tag}"] = {"q": q, "dq": dq, "tau": tau, "B": B, "F_B": kin.force[k], "friction": np.array([1.0])}
        if m.has_hkp:
            kp = solve_kinematics(m, task, G1_ORIENTATION)
            out["g1_target"] = {"theta": kp.theta[k], "q": kp.q[k], "dq": kp.dq[k], "ddq": kp.ddq[k], "F_B": kp.force[k], "B": B}
    return out
