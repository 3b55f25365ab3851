"""Controllers: small objects with one ``__call__(t, state) -> tau``, and the compiled graphs behind the built-in ones.

A controller sees the time and a state estimate (:class:`State`: the independent coordinates q, in Euler angles, and
their rates) and returns the six torques it commands (N m); the simulator saturates them at the actuators' limit and
holds them until the next tick (:mod:`chewbot.simulation.simulator`). Any object with that call is a controller.

The built-in controllers (:class:`ModelBasedController` of kind feedforward, pd or computed-torque) also have a CasADi
function of one signature, ``(q, dq, q_ref, dq_ref, ddq_ref, F_B, gains, B, p) -> tau``, which is what they evaluate, compiled,
at each tick, and what the simulator puts inside its integrator's stages for ``rate=None`` (``--rate continuous``).
Their model is the controller's (``--model`` with ``--set``), which may differ from the plant's; the bite force they
use is the task's, or zero when it is hidden from them (``--bite-unknown``).

* feedforward: tau = ID(q_ref, q_dot_ref, q_ddot_ref), no feedback;
* pd: tau_i = kp_i (theta_ref,i - theta_i) + kd_i (theta_dot_ref,i - theta_dot_i), independently on each crank, the
  crank angles and rates of the state and of the reference from the controller's model (inverse kinematics);
* computed-torque: tau = ID(q, q_dot, q_ddot_ref + kd e_dot + kp e), e = q_ref - q in the independent coordinates:
  with the exact model the error obeys e_ddot + kd e_dot + kp e = 0.

ID is the controller's inverse dynamics, chosen like ``chewbot run --method --goal``: the minimum-norm torques of
Eq. (54) (hessian, lagrange, liang, 6rss-core: each formulation's own per-sample graph) or Newton-Euler with the
optimal distribution of its goal (friction in the controller's model when asked: :func:`inverse_dynamics_function`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from chewbot.compiled.kernels import KernelSpec, native
from chewbot.dynamics.registry import formulation
from chewbot.errors import ChewbotError
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.model import Model
from chewbot.model.vector import N_P
from chewbot.kinematics.options import Orientation
from chewbot.compiled.cache import cached_graph, symbols
from chewbot.model.symbolic import c_name
from chewbot.run.options import Switch, resolve_dynamics
from chewbot.simulation.forward import ORIENTATION, n_coordinates
from chewbot.simulation import CONTROLLERS
from chewbot.simulation.reference import Reference

CONTROL_INPUTS = ("q", "dq", "q_ref", "dq_ref", "ddq_ref", "F_B", "gains", "B", "p")


@dataclass(frozen=True)
class State:
    """What a controller is given: q (n,) the independent coordinates (Euler angles; m, rad) and dq their rates, and
    theta (6,) the crank angles the encoders read (rad), from which the estimate was made (None: not given)."""

    q: np.ndarray
    dq: np.ndarray
    theta: np.ndarray | None = None


# ------------------------------------------------------------------------------------------- inverse dynamics


def inverse_dynamics_function(mechanism: str, method: str, goal: str | None = None, friction: bool = False) -> ca.Function:
    """The controller's inverse dynamics of one sample: (q, dq, ddq, B, F_B, p) -> tau (N m), q in Euler angles.

    Each formulation's own per-sample graph (:attr:`chewbot.dynamics.registry.Formulation.sample_torques`): the terms
    of Eq. (53) by the Hessian method or Liang's, Lagrange's D, J_theta, J_qEE and the minimum-norm torques, the 6RSS
    core's torques, Newton-Euler's data with the distribution of ``goal`` at a fixed cost (with the model's friction
    when ``friction``). Built once per (mechanism, method, goal, friction).
    """
    f = formulation(method)
    options = {k: v for k, v in (("goal", goal), ("friction", bool(friction))) if k in f.sample_options and v is not None}
    key = ("controller-inverse", method, *(options.get(k, dict(f.defaults).get(k)) for k in ("goal", "friction")))
    return cached_graph(symbols(mechanism), key, lambda: f.sample_torques(mechanism, **options))


# ------------------------------------------------------------------------------------------- control laws


def gain_count(kind: str, mechanism: str) -> int:
    """Entries of a controller's gains vector: pd kp, kd per crank (12); computed-torque kp, kd per coordinate."""
    return {"feedforward": 0, "pd": 12, "computed-torque": 2 * n_coordinates(mechanism)}[kind]


def control_function(kind: str, mechanism: str, method: str = "hessian", goal: str | None = None,
                     friction: bool = False) -> ca.Function:
    """The control law ``kind`` as one CasADi function of :data:`CONTROL_INPUTS` -> tau (N m, before saturation):
    q, dq the state, q_ref, dq_ref, ddq_ref the reference at the same time, F_B the bite force the controller knows,
    gains (:func:`gain_count`), B the bite point in {M}, p the controller's model."""
    if kind not in CONTROLLERS:
        raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}, not {kind!r}")
    key = ("control", kind) + (() if kind == "pd" else (method, goal, bool(friction)))
    return cached_graph(symbols(mechanism), key, lambda: _control(kind, mechanism, method, goal, friction))


def _control(kind: str, mechanism: str, method: str, goal: str | None, friction: bool) -> ca.Function:
    n = n_coordinates(mechanism)
    q, dq, q_ref, dq_ref, ddq_ref = (ca.SX.sym(name, n) for name in CONTROL_INPUTS[:5])
    F, gains, B, p = ca.SX.sym("F_B", 3), ca.SX.sym("gains", gain_count(kind, mechanism)), ca.SX.sym("B", 3), ca.SX.sym("p", N_P)
    if kind == "pd":
        kin = kinematics_kernel(mechanism, ORIENTATION).graph()
        i_theta, i_dtheta = KINEMATICS_OUTPUTS.index("theta"), KINEMATICS_OUTPUTS.index("dtheta")
        now, ref = kin(q, dq, ca.SX.zeros(n), p), kin(q_ref, dq_ref, ca.SX.zeros(n), p)
        d_theta = ref[i_theta] - now[i_theta]
        d_theta = ca.atan2(ca.sin(d_theta), ca.cos(d_theta))  # the angles are within +-2 pi: their difference wrapped
        tau = gains[:6] * d_theta + gains[6:] * (ref[i_dtheta] - now[i_dtheta])
    else:
        ID = inverse_dynamics_function(mechanism, method, goal, friction)
        if kind == "feedforward":
            tau = ID(q_ref, dq_ref, ddq_ref, B, F, p)
        else:
            ddq = ddq_ref + gains[n:] * (dq_ref - dq) + gains[:n] * (q_ref - q)
            tau = ID(q, dq, ddq, B, F, p)
    return ca.Function(f"control_{kind.replace('-', '_')}", [q, dq, q_ref, dq_ref, ddq_ref, F, gains, B, p], [tau],
                       list(CONTROL_INPUTS), ["tau"])


def control_name(kind: str, mechanism: str, method: str, goal: str | None, friction: bool) -> str:
    """A C name for a control law's kernels: the kind, and for the model-based ones the inverse dynamics with the
    options its per-sample graph takes."""
    parts = [kind]
    if kind != "pd":
        parts.append(method)
        f = formulation(method)
        if "goal" in f.sample_options:
            parts.append(goal or dict(f.defaults)["goal"])
        if "friction" in f.sample_options:
            parts.append("friction" if friction else "frictionless")
    return "_".join(p.replace("-", "_").replace("6rss", "sixrss") for p in parts) + f"_{c_name(mechanism)}"


def control_kernel(kind: str, mechanism: str, method: str = "hessian", goal: str | None = None,
                   friction: bool = False) -> KernelSpec:
    """:func:`control_function` compiled, for the ticks of a held-rate simulation."""
    name = f"control_{control_name(kind, mechanism, method, goal, friction)}"

    def build(params):
        fn = control_function(kind, mechanism, method, goal, friction)
        x = [ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(fn.n_in())]
        return ca.Function(name, x, fn.call(x), list(CONTROL_INPUTS), ["tau"], {"cse": True})

    return KernelSpec(name, build, (mechanism, kind, method, goal, bool(friction)), mechanism)


# ------------------------------------------------------------------------------------------- gains


def _default_gains_file() -> Path:
    return Path(__file__).with_name("gains.toml")


@dataclass(frozen=True)
class Gains:
    """The controllers' gains (SI): ``pd_kp`` (6,) N m/rad and ``pd_kd`` (6,) N m s/rad on the crank angles;
    ``ct_frequency`` (n,) Hz and ``ct_damping`` (n,) of the computed-torque error dynamics (kp = (2 pi f)^2,
    kd = 2 zeta (2 pi f)); ``cutoff`` Hz of the velocity estimate's low-pass (with sensor noise only).
    ``source``: the file they were read from; ``overrides``: the single values changed (``--gain``)."""

    pd_kp: np.ndarray
    pd_kd: np.ndarray
    ct_frequency: np.ndarray
    ct_damping: np.ndarray
    cutoff: float
    source: str = ""
    overrides: dict = field(default_factory=dict)

    KEYS = {"pd.kp_Nm_per_rad": ("pd_kp", 6), "pd.kd_Nms_per_rad": ("pd_kd", 6),
            "computed_torque.frequency_Hz": ("ct_frequency", None), "computed_torque.damping": ("ct_damping", None),
            "estimator.cutoff_Hz": ("cutoff", 0)}

    @classmethod
    def load(cls, path: str | Path | None = None, mechanism: str = "target", overrides: dict[str, float] | None = None) -> Gains:
        """Gains from a TOML file (default: the built-in ``gains.toml``), then single values ``overrides``
        (``{"pd.kp_Nm_per_rad": 3.0, "pd.kp_Nm_per_rad[2]": 4.0}``: a key sets every entry, KEY[i] the i-th, 1-based).
        A scalar in the file applies to every joint (pd: six cranks) or coordinate (computed-torque: n). Errors name
        the file and the key."""
        import tomllib

        path = Path(path) if path is not None else _default_gains_file()
        try:
            raw = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ChewbotError(f"{path}: no such gains file") from None
        except (OSError, ValueError) as exc:
            raise ChewbotError(f"{path}: cannot read it as TOML ({exc})") from None
        n = n_coordinates(mechanism)
        values = {}
        known = set(cls.KEYS)
        for section, content in raw.items():
            if not isinstance(content, dict):
                raise ChewbotError(f"{path}: {section!r} must be a table ([pd], [computed_torque], [estimator])")
            for key, value in content.items():
                full = f"{section}.{key}"
                if full not in known:
                    raise ChewbotError(f"{path}: unknown key {full!r}; the keys are {', '.join(sorted(known))}")
                values[full] = value
        missing = known - set(values)
        if missing:
            raise ChewbotError(f"{path}: missing key(s) {', '.join(sorted(missing))}")
        arrays = {}
        for full, (attr, size) in cls.KEYS.items():
            size = n if size is None else size
            arrays[attr] = _gain_value(values[full], size, f"{path}: {full}")
        for key, value in (overrides or {}).items():
            base, _, index = key.partition("[")
            if base not in cls.KEYS:
                raise ChewbotError(f"--gain {key}={value:g}: unknown key {base!r}; the keys are {', '.join(sorted(known))}")
            attr, size = cls.KEYS[base]
            target = arrays[attr]
            if index:
                try:
                    i = int(index.rstrip("]")) - 1
                except ValueError:
                    raise ChewbotError(f"--gain {key}={value:g}: the index must be a whole number (1-based)") from None
                if size == 0 or not 0 <= i < target.size:
                    raise ChewbotError(f"--gain {key}={value:g}: {base} has {np.size(target)} entr{'ies' if np.size(target) > 1 else 'y'}")
                target = target.copy()
                target[i] = value
            else:
                target = np.full_like(target, value)
            arrays[attr] = _gain_value(target, 0 if size == 0 else target.size, f"--gain {key}={value:g}")
        return cls(arrays["pd_kp"], arrays["pd_kd"], arrays["ct_frequency"], arrays["ct_damping"], float(arrays["cutoff"]),
                   str(path), dict(overrides or {}))

    def vector(self, kind: str) -> np.ndarray:
        """The gains input of :func:`control_function` for ``kind``."""
        if kind == "pd":
            return np.concatenate([self.pd_kp, self.pd_kd])
        if kind == "computed-torque":
            w = 2 * np.pi * self.ct_frequency
            return np.concatenate([w**2, 2 * self.ct_damping * w])
        return np.zeros(0)

    def as_dict(self) -> dict:
        return {"file": self.source, "overrides": self.overrides, "pd.kp_Nm_per_rad": self.pd_kp.tolist(),
                "pd.kd_Nms_per_rad": self.pd_kd.tolist(), "computed_torque.frequency_Hz": self.ct_frequency.tolist(),
                "computed_torque.damping": self.ct_damping.tolist(), "estimator.cutoff_Hz": self.cutoff}


def _gain_value(value, size: int, where: str) -> np.ndarray | float:
    """A scalar, or ``size`` entries, all finite and non-negative (``size`` 0: a single positive number)."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ChewbotError(f"{where}: {value!r} is not a number or a list of numbers") from None
    if size == 0:
        if arr.ndim or not np.isfinite(arr) or arr <= 0:
            raise ChewbotError(f"{where}: expected one positive number, not {value!r}")
        return float(arr)
    if arr.ndim == 0:
        arr = np.full(size, float(arr))
    if arr.shape != (size,):
        raise ChewbotError(f"{where}: expected one number or {size}, got {arr.size}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ChewbotError(f"{where}: gains must be finite and non-negative, got {arr.tolist()}")
    return arr


# ------------------------------------------------------------------------------------------- controller objects


@dataclass
class ModelBasedController:
    """A built-in controller (``kind``: feedforward, pd or computed-torque) on the controller's ``model``: it follows
    ``reference`` with the inverse dynamics ``method`` (``goal``, ``friction``: Newton-Euler's) and ``gains``;
    ``bite_known`` False hides the bite force from it. ``__call__(t, state)`` evaluates the compiled law at one tick;
    :meth:`function` is the same law as a CasADi function, :meth:`inputs` its inputs other than the state."""

    kind: str
    model: Model
    reference: Reference
    gains: Gains
    method: str = "hessian"
    goal: str | None = None
    friction: bool = False
    bite_known: bool = True
    _kernel: object = field(default=None, init=False, repr=False)
    _shared: tuple = field(default=(), init=False, repr=False)

    def __post_init__(self):
        if self.kind not in CONTROLLERS:
            raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}, not {self.kind!r}")
        takes_friction = "friction" in formulation(self.method).options
        d = resolve_dynamics(self.method, Orientation.euler_angles.value, self.goal, bool(self.friction) if takes_friction else None,
                             has_hkp=self.model.has_hkp)
        self.goal, self.friction = d.goal, d.friction == Switch.on

    @property
    def mechanism(self) -> str:
        return self.model.mechanism

    def function(self) -> ca.Function:
        """The control law (:func:`control_function`) of this controller."""
        return control_function(self.kind, self.mechanism, self.method, self.goal, self.friction)

    def kernel_spec(self) -> KernelSpec:
        return control_kernel(self.kind, self.mechanism, self.method, self.goal, self.friction)

    def shared(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The inputs that do not change during a simulation: gains, B, p."""
        return self.gains.vector(self.kind), self.model.molar(self.reference.side), self.model.vector()

    def known_force(self, force: np.ndarray) -> np.ndarray:
        """The bite force the controller uses: the task's, or zero where it is hidden from it."""
        return force if self.bite_known else np.zeros_like(force)

    def __call__(self, t: float, state: State) -> np.ndarray:
        if self._kernel is None:
            self._kernel, self._shared = native(self.kernel_spec()), self.shared()
        q_ref, dq_ref, ddq_ref, force = self.reference.state(t)
        return self._kernel(state.q, state.dq, q_ref, dq_ref, ddq_ref, self.known_force(force), *self._shared)[0]
