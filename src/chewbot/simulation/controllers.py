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
from chewbot.rotation import matrix_from_euler_angles_sx
from chewbot.run.options import Switch, resolve_dynamics
from chewbot.simulation.forward import ORIENTATION, n_coordinates
from chewbot.simulation import CONTROLLERS
from chewbot.simulation.reference import Reference

CONTROL_INPUTS = ("q", "dq", "q_ref", "dq_ref", "ddq_ref", "F_B", "gains", "B", "p")


@dataclass(frozen=True)
class State:
    """What a controller is given: q (n,) the independent coordinates (Euler angles; m, rad) and dq their rates;
    theta (6,) the crank angles the encoders read (rad), from which the estimate was made (None: not given);
    ``force`` (3,) the force observer's bite force on the mandible (N, {S}), None where no observer runs."""

    q: np.ndarray
    dq: np.ndarray
    theta: np.ndarray | None = None
    force: np.ndarray | None = None


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
    """Entries of a controller's gains vector: pd kp, kd per crank (12); computed-torque kp, kd per coordinate;
    impedance stiffness and damping, hybrid kp, kd per task coordinate (x, y, z of the molar point, alpha)."""
    n = n_coordinates(mechanism)
    return {"feedforward": 0, "pd": 12, "computed-torque": 2 * n, "impedance": 2 * n, "hybrid": 2 * n}[kind]


def task_space_sx(q: ca.SX, dq: ca.SX, B: ca.SX, p: ca.SX, mechanism: str = "target") -> dict:
    """The task coordinates of the impedance and hybrid controllers as expressions of the state: y = (x, y, z of
    the molar point B in {S}, alpha) (m, rad), its Jacobian J = dy/dq (q in Euler angles), y_dot = J q_dot, the
    bias J_dot q_dot, and J_theta1 = d theta / d q (the map of a generalised force onto the torques). The target
    only: its four coordinates are the point's three and the pinned angle (as chewbot track-incisor --pin alpha)."""
    if mechanism != "target":
        raise ValueError("the impedance and hybrid controllers are for the target (the molar point and alpha)")
    n = q.numel()
    out = dict(zip(KINEMATICS_OUTPUTS, kinematics_kernel(mechanism, ORIENTATION).graph()(q, dq, ca.SX.zeros(n), p)))
    X = out["X"]
    y = ca.vertcat(X[0:3] + ca.mtimes(matrix_from_euler_angles_sx(X[3], X[4], X[5]), B), q[2])
    J = ca.jacobian(y, q)
    dy = ca.mtimes(J, dq)
    return {"y": y, "J": J, "dy": dy, "bias": ca.jtimes(dy, q, dq), "J_theta1": out["J_theta1_angles"]}


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
    if kind == "impedance":
        # tau = ID(q, q_dot, q_ddot_ref) + the least-norm torques of the generalised force J' (K e + D e_dot), e the
        # task-space error: the molar point held to the reference by springs and dampers, alpha likewise
        ID = inverse_dynamics_function(mechanism, method, goal, friction)
        now, ref = task_space_sx(q, dq, B, p, mechanism), task_space_sx(q_ref, dq_ref, B, p, mechanism)
        n_y = now["y"].numel()
        wrench = gains[:n_y] * (ref["y"] - now["y"]) + gains[n_y:] * (ref["dy"] - now["dy"])
        J1 = now["J_theta1"]
        tau = ID(q, dq, ddq_ref, B, F, p) + ca.mtimes(J1, ca.solve(ca.mtimes(J1.T, J1), ca.mtimes(now["J"].T, wrench)))
    elif kind == "hybrid":
        tau = hybrid_function(mechanism, method, goal, friction)(q, dq, q_ref, dq_ref, ddq_ref, F, gains, B, p, 0, 0)[0]
    elif kind == "pd":
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


HYBRID_INPUTS = CONTROL_INPUTS + ("force_mode", "a_force")
HYBRID_OUTPUTS = ("tau", "y", "dy", "y_ref", "dy_ref")


def hybrid_function(mechanism: str, method: str = "hessian", goal: str | None = None, friction: bool = False) -> ca.Function:
    """The hybrid controller's law (:class:`HybridController`) as one CasADi function of :data:`HYBRID_INPUTS` ->
    :data:`HYBRID_OUTPUTS`: computed torque in the task coordinates of :func:`task_space_sx`,
    y_ddot = y_ddot_ref + kd (y_dot_ref - y_dot) + kp (y_ref - y) on x, y and alpha always and on z unless
    ``force_mode`` is 1, where z's acceleration is ``a_force`` (the force loop's); q_ddot = J^-1 (y_ddot - J_dot
    q_dot) and tau = ID(q, q_dot, q_ddot, F_B), F_B the bite force the controller knows (the observer's). Also
    returns y, y_dot and the reference's."""
    key = ("hybrid", method, goal, bool(friction))
    return cached_graph(symbols(mechanism), key, lambda: _hybrid(mechanism, method, goal, friction))


def _hybrid(mechanism: str, method: str, goal: str | None, friction: bool) -> ca.Function:
    n = n_coordinates(mechanism)
    q, dq, q_ref, dq_ref, ddq_ref = (ca.SX.sym(name, n) for name in CONTROL_INPUTS[:5])
    F, gains, B, p = ca.SX.sym("F_B", 3), ca.SX.sym("gains", gain_count("hybrid", mechanism)), ca.SX.sym("B", 3), ca.SX.sym("p", N_P)
    mode, a_force = ca.SX.sym("force_mode"), ca.SX.sym("a_force")
    now, ref = task_space_sx(q, dq, B, p, mechanism), task_space_sx(q_ref, dq_ref, B, p, mechanism)
    ddy_ref = ca.mtimes(ref["J"], ddq_ref) + ref["bias"]
    a = ddy_ref + gains[n:] * (ref["dy"] - now["dy"]) + gains[:n] * (ref["y"] - now["y"])
    a = ca.vertcat(a[0:2], ca.if_else(mode > 0.5, a_force, a[2]), a[3:])
    ddq = ca.solve(now["J"], a - now["bias"])
    tau = inverse_dynamics_function(mechanism, method, goal, friction)(q, dq, ddq, B, F, p)
    return ca.Function("control_hybrid", [q, dq, q_ref, dq_ref, ddq_ref, F, gains, B, p, mode, a_force],
                       [tau, now["y"], now["dy"], ref["y"], ref["dy"]], list(HYBRID_INPUTS), list(HYBRID_OUTPUTS))


def hybrid_kernel(mechanism: str, method: str = "hessian", goal: str | None = None, friction: bool = False) -> KernelSpec:
    """:func:`hybrid_function` compiled, for the ticks of a simulation."""
    name = f"hybrid_{control_name('hybrid', mechanism, method, goal, friction)}"

    def build(params):
        fn = hybrid_function(mechanism, method, goal, friction)
        x = [ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(fn.n_in())]
        return ca.Function(name, x, fn.call(x), list(HYBRID_INPUTS), list(HYBRID_OUTPUTS), {"cse": True})

    return KernelSpec(name, build, (mechanism, "hybrid", method, goal, bool(friction)), mechanism)


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


# Sections a gains file may leave out: their keys then take the built-in values (recorded in run.json as such).
OPTIONAL_SECTIONS = ("impedance", "hybrid", "observer")


@dataclass(frozen=True)
class Gains:
    """The controllers' gains (SI): ``pd_kp`` (6,) N m/rad and ``pd_kd`` (6,) N m s/rad on the crank angles;
    ``ct_frequency`` (n,) Hz and ``ct_damping`` (n,) of the computed-torque error dynamics (kp = (2 pi f)^2,
    kd = 2 zeta (2 pi f)); ``cutoff`` Hz of the velocity estimate's low-pass (with sensor noise only);
    ``imp_stiffness`` (3,) N/m, ``imp_damping`` (3,) N s/m of the molar point and ``imp_angle_stiffness`` (1,)
    N m/rad, ``imp_angle_damping`` (1,) N m s/rad of alpha (impedance); ``hy_frequency``, ``hy_damping`` (4,) of the
    hybrid controller's task-space position loop (x, y, z of the molar point, alpha), ``hy_force_frequency`` Hz and
    ``hy_force_damping`` of its force loop, ``hy_threshold`` N, ``hy_stiffness_min``, ``hy_stiffness_max`` N/m,
    ``hy_speed_limit`` m/s of the molar point along z under force control;
    ``observer_cutoff`` Hz of the force observer's low-pass. ``source``: the file they were read from; ``overrides``:
    the single values changed (``--gain``); ``defaulted``: keys the file left out (built-in values)."""

    pd_kp: np.ndarray
    pd_kd: np.ndarray
    ct_frequency: np.ndarray
    ct_damping: np.ndarray
    cutoff: float
    imp_stiffness: np.ndarray
    imp_damping: np.ndarray
    imp_angle_stiffness: np.ndarray
    imp_angle_damping: np.ndarray
    hy_frequency: np.ndarray
    hy_damping: np.ndarray
    hy_force_frequency: float
    hy_force_damping: float
    hy_threshold: float
    hy_stiffness_min: float
    hy_stiffness_max: float
    hy_speed_limit: float
    observer_cutoff: float
    source: str = ""
    overrides: dict = field(default_factory=dict)
    defaulted: tuple = ()

    KEYS = {"pd.kp_Nm_per_rad": ("pd_kp", 6), "pd.kd_Nms_per_rad": ("pd_kd", 6),
            "computed_torque.frequency_Hz": ("ct_frequency", None), "computed_torque.damping": ("ct_damping", None),
            "estimator.cutoff_Hz": ("cutoff", 0),
            "impedance.stiffness_N_per_m": ("imp_stiffness", 3), "impedance.damping_Ns_per_m": ("imp_damping", 3),
            "impedance.angle_stiffness_Nm_per_rad": ("imp_angle_stiffness", 1),
            "impedance.angle_damping_Nms_per_rad": ("imp_angle_damping", 1),
            "hybrid.frequency_Hz": ("hy_frequency", 4), "hybrid.damping": ("hy_damping", 4),
            "hybrid.force_frequency_Hz": ("hy_force_frequency", 0), "hybrid.force_damping": ("hy_force_damping", 0),
            "hybrid.threshold_N": ("hy_threshold", 0), "hybrid.stiffness_min_N_per_m": ("hy_stiffness_min", 0),
            "hybrid.stiffness_max_N_per_m": ("hy_stiffness_max", 0), "hybrid.speed_limit_m_per_s": ("hy_speed_limit", 0),
            "observer.cutoff_Hz": ("observer_cutoff", 0)}

    @classmethod
    def load(cls, path: str | Path | None = None, mechanism: str = "target", overrides: dict[str, float] | None = None) -> Gains:
        """Gains from a TOML file (default: the built-in ``gains.toml``), then single values ``overrides``
        (``{"pd.kp_Nm_per_rad": 3.0, "pd.kp_Nm_per_rad[2]": 4.0}``: a key sets every entry, KEY[i] the i-th, 1-based).
        A scalar in the file applies to every joint (pd: six cranks) or coordinate (computed-torque: n). The sections
        of :data:`OPTIONAL_SECTIONS` may be left out (their keys take the built-in values). Errors name the file and
        the key."""
        path = Path(path) if path is not None else _default_gains_file()
        values = _read_gains(path)
        known = set(cls.KEYS)
        defaulted = []
        missing = known - set(values)
        optional = {k for k in missing if k.split(".")[0] in OPTIONAL_SECTIONS}
        if optional and path != _default_gains_file():
            builtin = _read_gains(_default_gains_file())
            for key in sorted(optional):
                values[key] = builtin[key]
                defaulted.append(key)
            missing -= optional
        if missing:
            raise ChewbotError(f"{path}: missing key(s) {', '.join(sorted(missing))}")
        n = n_coordinates(mechanism)
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
        if arrays["hy_stiffness_min"] > arrays["hy_stiffness_max"]:
            raise ChewbotError(f"{path}: hybrid.stiffness_min_N_per_m ({arrays['hy_stiffness_min']:g}) is above "
                               f"hybrid.stiffness_max_N_per_m ({arrays['hy_stiffness_max']:g})")
        scalars = {attr for attr, size in cls.KEYS.values() if size == 0}
        return cls(**{attr: float(v) if attr in scalars else v for attr, v in arrays.items()}, source=str(path),
                   overrides=dict(overrides or {}), defaulted=tuple(defaulted))

    def vector(self, kind: str) -> np.ndarray:
        """The gains input of :func:`control_function` for ``kind``."""
        if kind == "pd":
            return np.concatenate([self.pd_kp, self.pd_kd])
        if kind == "computed-torque":
            w = 2 * np.pi * self.ct_frequency
            return np.concatenate([w**2, 2 * self.ct_damping * w])
        if kind == "impedance":
            return np.concatenate([self.imp_stiffness, self.imp_angle_stiffness, self.imp_damping, self.imp_angle_damping])
        if kind == "hybrid":
            w = 2 * np.pi * self.hy_frequency
            return np.concatenate([w**2, 2 * self.hy_damping * w])
        return np.zeros(0)

    def as_dict(self) -> dict:
        out = {"file": self.source, "overrides": self.overrides, "defaulted": list(self.defaulted)}
        for key, (attr, _) in self.KEYS.items():
            value = getattr(self, attr)
            out[key] = value.tolist() if isinstance(value, np.ndarray) else value
        return out


def _read_gains(path: Path) -> dict:
    """The keys of a gains file, ``section.key`` -> value; unknown sections and keys are errors naming the file."""
    import tomllib

    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ChewbotError(f"{path}: no such gains file") from None
    except (OSError, ValueError) as exc:
        raise ChewbotError(f"{path}: cannot read it as TOML ({exc})") from None
    known = set(Gains.KEYS)
    values = {}
    for section, content in raw.items():
        if not isinstance(content, dict):
            raise ChewbotError(f"{path}: {section!r} must be a table ([pd], [computed_torque], [estimator], "
                               "[impedance], [hybrid], [observer])")
        for key, value in content.items():
            full = f"{section}.{key}"
            if full not in known:
                raise ChewbotError(f"{path}: unknown key {full!r}; the keys are {', '.join(sorted(known))}")
            values[full] = value
    return values


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


def controller_dynamics(method: str, goal: str | None, friction: bool, has_hkp: bool) -> tuple[str | None, bool]:
    """A controller's goal and friction switch as a run resolves them (friction only where ``method`` takes it)."""
    takes_friction = "friction" in formulation(method).options
    d = resolve_dynamics(method, Orientation.euler_angles.value, goal, bool(friction) if takes_friction else None, has_hkp=has_hkp)
    return d.goal, d.friction == Switch.on


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
        if self.kind == "hybrid":
            raise ValueError("the hybrid controller switches on the observed force: it is a HybridController")
        if self.kind == "impedance" and not self.model.has_hkp:
            raise ChewbotError("--controller impedance is for the target (the molar point's x, y, z and alpha)")
        self.goal, self.friction = controller_dynamics(self.method, self.goal, self.friction, self.model.has_hkp)

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


TASK_STATE_OUTPUTS = ("y", "dy", "y_ref", "dy_ref")
# Memory (s) of the food-stiffness estimate of the hybrid controller's force loop, and the spread of the molar
# point's z (m) below which the estimate is not updated (the points do not tell a slope).
STIFFNESS_MEMORY_S = 0.05
STIFFNESS_SPREAD_M = 5e-6


def task_state_kernel(mechanism: str) -> KernelSpec:
    """(q, dq, q_ref, dq_ref, B, p) -> y, y_dot of the state and of the reference (:func:`task_space_sx`)."""
    name = f"task_state_{c_name(mechanism)}"

    def build(params):
        n = n_coordinates(mechanism)
        q, dq, q_ref, dq_ref = (ca.SX.sym(s, n) for s in ("q", "dq", "q_ref", "dq_ref"))
        B, p = ca.SX.sym("B", 3), ca.SX.sym("p", N_P)
        now, ref = task_space_sx(q, dq, B, p, mechanism), task_space_sx(q_ref, dq_ref, B, p, mechanism)
        return ca.Function(name, [q, dq, q_ref, dq_ref, B, p], [now["y"], now["dy"], ref["y"], ref["dy"]],
                           ["q", "dq", "q_ref", "dq_ref", "B", "p"], list(TASK_STATE_OUTPUTS), {"cse": True})

    return KernelSpec(name, build, (mechanism,), mechanism)


@dataclass
class HybridController:
    """Position control while the teeth are apart, force control along z once they bite (``--controller hybrid``).

    The task coordinates are those of :func:`task_space_sx`: the molar point's x, y, z and alpha. x, y and alpha are
    always position-controlled (computed torque in task space, ``hybrid.frequency_Hz``, ``hybrid.damping``); z too
    until the observed force f = -F_z (the observer's, ``State.force``) reaches ``hybrid.threshold_N``. Then z's
    acceleration follows the force loop, with f_ref = -F_z of the task (its Fz is the force reference):

        a_z = [kv (f_ref_dot - k_hat z_dot) + kp (f_ref - f)] / k_hat,   kp = (2 pi f_F)^2, kv = 2 zeta_F (2 pi f_F),

    which for a food of stiffness k_hat (f_dot = k z_dot) makes the force error obey e'' + kv e' + kp e = 0 whatever
    the stiffness. Written as a velocity loop, a_z = kv (z_dot_cmd - z_dot) with z_dot_cmd = (f_ref_dot + kp/kv
    (f_ref - f)) / k_hat, the commanded speed is held within ``hybrid.speed_limit_m_per_s`` (a force the food
    cannot give, or a soft food far from its force, would otherwise drive the teeth together at metres per second).
    The inverse dynamics is given F_z = -f_ref under force control (the force the food should push with; the
    observer's lags the motion), the observed F_x, F_y, and the observed force under position control. k_hat is estimated on line: the slope of the observed force against the molar point's z (passed
    through the observer's low-pass, so that both lag alike) by least squares with exponential forgetting
    (:data:`STIFFNESS_MEMORY_S`), within ``hybrid.stiffness_min_N_per_m`` .. ``stiffness_max_N_per_m``, starting at
    the maximum (a stiffness overestimated by c slows the loop by c; underestimated, it makes it faster). The force
    loop is left when the force reference is below the threshold, the observed force too, and the task's z
    reference lies below the point (the task opens)."""

    model: Model
    reference: Reference
    gains: Gains
    method: str = "hessian"
    goal: str | None = None
    friction: bool = False
    kind: str = field(default="hybrid", init=False)
    bite_known: bool = field(default=True, init=False)
    log: list = field(default_factory=list, init=False, repr=False)
    _kernels: tuple = field(default=(), init=False, repr=False)
    _mode: int = field(default=0, init=False, repr=False)
    _k: float = field(default=0.0, init=False, repr=False)
    _moments: np.ndarray = field(default=None, init=False, repr=False)
    _z: float | None = field(default=None, init=False, repr=False)
    _t: float | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        if not self.model.has_hkp:
            raise ChewbotError("--controller hybrid is for the target (the molar point's x, y, z and alpha)")
        self.goal, self.friction = controller_dynamics(self.method, self.goal, self.friction, True)
        self._k = self.gains.hy_stiffness_max

    @property
    def mechanism(self) -> str:
        return self.model.mechanism

    def kernel_specs(self) -> list[KernelSpec]:
        return [hybrid_kernel(self.mechanism, self.method, self.goal, self.friction), task_state_kernel(self.mechanism)]

    def __call__(self, t: float, state: State) -> np.ndarray:
        if state.force is None:
            raise ValueError("the hybrid controller needs the force observer's estimate (State.force)")
        if not self._kernels:
            self._kernels = tuple(native(k) for k in self.kernel_specs())
            self._shared = (self.gains.vector("hybrid"), self.model.molar(self.reference.side), self.model.vector())
        law, task = self._kernels
        gains, B, p = self._shared
        q_ref, dq_ref, ddq_ref, force = self.reference.state(t)
        y, dy, y_ref, dy_ref = (np.asarray(v).ravel() for v in task(state.q, state.dq, q_ref, dq_ref, B, p))
        g = self.gains
        f, f_ref = -float(state.force[2]), -float(force[2])
        h = 0.0 if self._t is None else t - self._t
        self._t = t
        # z through the observer's low-pass, so that the stiffness's two signals lag alike
        b = np.exp(-2 * np.pi * g.observer_cutoff * h)
        self._z = y[2] if self._z is None else b * self._z + (1 - b) * y[2]
        if self._mode == 0 and f >= g.hy_threshold:
            self._mode, self._moments = 1, np.zeros(5)
        elif self._mode == 1 and f_ref < g.hy_threshold and f < g.hy_threshold and y_ref[2] < y[2]:
            self._mode = 0
        a_force = 0.0
        if self._mode == 1:
            if f >= g.hy_threshold:  # in contact: a point of the food's force against z
                lam = np.exp(-h / STIFFNESS_MEMORY_S)
                self._moments = lam * self._moments + np.array([1.0, self._z, f, self._z**2, self._z * f])
            w, sz, sf, szz, szf = self._moments
            spread = szz / w - (sz / w) ** 2 if w > 0 else 0.0
            if spread > STIFFNESS_SPREAD_M**2:
                slope = (szf / w - sz * sf / w**2) / spread
                self._k = float(np.clip(slope, g.hy_stiffness_min, g.hy_stiffness_max))
            dt = 1e-3
            df_ref = -(self.reference.force_at([t + dt / 2])[0, 2] - self.reference.force_at([t - dt / 2])[0, 2]) / dt
            w_f = 2 * np.pi * g.hy_force_frequency
            kv, kp = 2 * g.hy_force_damping * w_f, w_f**2
            # the law written as a velocity loop, kv (z_dot_cmd - z_dot), with z_dot_cmd within the speed limit
            dz_cmd = np.clip((df_ref + kp / kv * (f_ref - f)) / self._k, -g.hy_speed_limit, g.hy_speed_limit)
            a_force = kv * (dz_cmd - dy[2])
        self.log.append((t, self._mode, self._k))
        known = np.array([state.force[0], state.force[1], -f_ref]) if self._mode else state.force
        return np.asarray(law(state.q, state.dq, q_ref, dq_ref, ddq_ref, known, gains, B, p, float(self._mode), a_force)[0]).ravel()
