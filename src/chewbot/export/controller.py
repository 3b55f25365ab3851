"""The whole controller step as a self-contained C99 library: what ``chewbot export-controller`` writes.

One call per tick, ``chewbot_ctrl_step(ctx, t, theta_measured, tau_out, status_out)``, does what ``chewbot simulate``
does around its controller with the crank sensor (:mod:`chewbot.simulation.sensor`): the measured crank angles less
the encoder offsets, forward kinematics (Gauss-Newton warm-started from the last estimate, a fixed number of steps,
:func:`chewbot.simulation.sensor.gauss_newton_sx`), the rates by the filtered backward difference, the reference at t
(the task compiled in as a table, quintic Hermite between its samples as :class:`chewbot.simulation.reference.Reference`,
or set by the caller each tick), the control law (:func:`chewbot.simulation.controllers.control_function`: PD on the
cranks, or computed torque with the inverse dynamics of the chosen formulation and distribution), saturation, a
torque-rate limit, and the checks of the status word with their safe behaviour (docs/realtime.md, "The exported
controller step").

Two CasADi graphs carry the numerical work, generated as C with the model's numbers folded in and post-processed
so that they compile with ``-std=c99 -Wall -Wextra -Werror -pedantic``: ``chewbot_ctrl_fk`` (the estimate of the
pose from the angles, its residual, last step and conditioning, the pose X_EE, the transmission and the workspace
margin) and ``chewbot_ctrl_law`` (the torques, the HKP normal forces, the reference's workspace margin, for
Newton-Euler the distribution's last step and how far past the actuator limits it is). Their work arrays are members
of the caller's context: the library has no mutable static data, allocates nothing and does no I/O in the step
(tests hold all three on the object files). The rest is hand-written C in :data:`STEP_C`.

:class:`ExportedController` compiles the library as a shared object and runs its step through ctypes: a controller
for :func:`chewbot.simulation.simulator.simulate` (``chewbot simulate --exported``) that also evaluates the Python
controller on the same measured angles and records both.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import re
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from chewbot.compiled.cache import KERNELS, c_compiler, folded, symbols
from chewbot.dynamics.g1 import distribution_function
from chewbot.dynamics.formulations.newton_euler import coefficients_kernel, forces_sx, limit_bounds, n_unknowns
from chewbot.files import EXPORT_FOLDER, VERSION, atomic_folder, to_json
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.model import Model
from chewbot.dynamics.registry import formulation
from chewbot.simulation.controllers.law import CompiledLaw, control_function
from chewbot.simulation.controllers.table import EXPORTABLE, controller_row
from chewbot.simulation.interfaces import Column, ControllerCapabilities, State
from chewbot.simulation.options import InverseDynamics
from chewbot.simulation.forward import ORIENTATION, n_coordinates, workspace_margin_sx
from chewbot.simulation.plant import state_function
from chewbot.simulation.reference import HERMITE_COEFFICIENTS as HERMITE
from chewbot.simulation.sensor import FK_ITERATIONS, gauss_newton_sx

EXPORT_FORMAT = 1
PREFIX = "chewbot_ctrl"
# The flags the library must compile with, warning-free (the Makefile's CFLAGS; tested).
STRICT_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2")

# Status bits of the step (the header's CHEWBOT_CTRL_* names; docs/realtime.md gives each one's safe behaviour).
STATUS_BITS = {
    "FK_NOT_CONVERGED": 1 << 0,   # the pose estimate's last Gauss-Newton step or closure residual above tolerance
    "NEAR_SINGULAR": 1 << 1,      # the estimate's conditioning or transmission below its threshold
    "TORQUE_SATURATED": 1 << 2,   # a commanded torque beyond the torque limit, clipped
    "REFERENCE_OUTSIDE": 1 << 3,  # the reference at t outside the workspace: the last reference inside is held
    "WATCHDOG": 1 << 4,           # a step called later than the watchdog after the previous one (latched)
    "ESTOP": 1 << 5,              # the emergency stop is on: zero torques
    "RATE_LIMITED": 1 << 6,       # a torque change limited by the torque-rate limit
    "LIMIT_ACTIVE": 1 << 7,       # Newton-Euler: the distribution's torques exceed an actuator limit (power, loads)
    "DISTRIBUTION_NOT_CONVERGED": 1 << 8,  # Newton-Euler: the distribution's last Newton step above tolerance
    "HOLDING": 1 << 9,            # the torques are the last ones held (estimate unusable), or zero after too long
    "BAD_INPUT": 1 << 10,         # a measured angle or t not finite, or t before the previous step
}

# Defaults of the configuration the caller may change in ctx->config after chewbot_ctrl_init.
# m or rad: the last Gauss-Newton step of a converged estimate. Measured along the default task: 2e-12 with exact
# angles, 1.4e-10 with 1e-4 rad of encoder noise, 3e-9 with 1e-3 rad (the least-squares fit of the target's four
# coordinates to six noisy angles converges linearly); 1e-7 m or rad is far below what the noise does to the estimate.
FK_STEP_TOLERANCE = 1e-7
# The scaled closure residual (each chain's |S M|^2 - L^2 over L^2) at the estimate: about 1.3 times the encoders'
# noise (rad) for the least-squares fit, 0.15 times the error of one crank angle inconsistent with the others.
# Beyond 1e-2, an angle off by about 4 degrees, the angles are rejected.
FK_RESIDUAL_TOLERANCE = 1e-2
CONDITIONING_MIN = 1e-4           # det(J'J)^(1/n) / (trace/n) below this: near a direct-kinematics singularity
TRANSMISSION_MIN = 0.05           # sin of the smallest transmission angle below this: near a crank's dead point
DISTRIBUTION_STEP_TOLERANCE = 1e-6  # N: the distribution's last Newton step at a converged answer
MAX_HOLD_TICKS = 10               # ticks the last torques are held while the estimate is unusable, then zero
WATCHDOG_PERIODS = 1.5            # a step later than this many periods after the previous one trips the watchdog


# ------------------------------------------------------------------------------------------- the graphs


@dataclass(frozen=True)
class StepSpec:
    """What one exported step is: the controller's ``model``, law ``kind`` (pd or computed-torque), inverse dynamics
    ``method`` with ``goal`` and ``friction`` (Newton-Euler's), ``gains`` (the law's vector), the velocity filter's
    ``cutoff`` (Hz), the control ``rate`` (Hz), the bite ``side`` and the reference table ``t``, ``q``, ``dq``,
    ``ddq``, ``force`` (samples first; the force the controller knows), ``torque_rate_limit`` (N m/s, 0: off)."""

    model: Model
    kind: str
    method: str
    goal: str | None
    friction: bool
    gains: np.ndarray
    cutoff: float
    rate: float
    side: str
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    force: np.ndarray
    torque_rate_limit: float = 0.0

    @classmethod
    def of(cls, controller: CompiledLaw, rate: float, torque_rate_limit: float = 0.0) -> StepSpec:
        """The step of a simulation's built-in controller (its model, law, gains and reference)."""
        parts = controller.parts
        if not parts.row.exportable:
            raise ValueError(f"the exported step runs {' or '.join(EXPORTABLE)}, not {parts.row.name}")
        r, inverse = controller.reference, parts.inverse
        return cls(controller.model, parts.row.name, inverse.method, inverse.goal, bool(inverse.friction),
                   parts.gains_vector(), parts.gains["estimator"].cutoff_Hz, float(rate), r.side,
                   np.asarray(r.t, float), r.q, r.dq, r.ddq, controller.known_force(np.asarray(r.force, float)),
                   float(torque_rate_limit))

    @property
    def n(self) -> int:
        return n_coordinates(self.model.mechanism)

    @property
    def n_normal(self) -> int:
        return n_unknowns(self.model.mechanism)

    @property
    def distributes(self) -> bool:
        """The law distributes the target's torques by Newton-Euler's fixed-cost solver (limits checked)."""
        return (controller_row(self.kind).needs.inverse_dynamics and "goal" in formulation(self.method).sample_options
                and self.model.has_hkp)


def fk_function(model: Model) -> ca.Function:
    """(theta, q_guess) -> q, X (pose X_EE), residual, step, conditioning (:func:`gauss_newton_sx`), transmission (the
    smallest sin of the chains' transmission angles), margin (> 0: the estimated pose inside the workspace), the
    model's numbers folded in."""
    m = folded(model)
    mech = model.mechanism
    n = n_coordinates(mech)
    theta, guess = ca.SX.sym("theta", 6), ca.SX.sym("q_guess", n)
    fk = gauss_newton_sx(mech, m, theta, guess)
    kin = dict(zip(KINEMATICS_OUTPUTS, kinematics_kernel(mech, ORIENTATION).graph()(fk["q"], ca.SX.zeros(n), ca.SX.zeros(n), m.p)))
    return ca.Function(f"{PREFIX}_fk", [theta, guess],
                       [fk["q"], kin["X"], fk["residual"], fk["step"], fk["conditioning"], ca.mmin(kin["transmission"]),
                        workspace_margin_sx(m, kin)],
                       ["theta", "q_guess"], ["q", "X", "residual", "step", "conditioning", "transmission", "margin"], {"cse": True})


def law_function(spec: StepSpec) -> ca.Function:
    """(q, dq, q_ref, dq_ref, ddq_ref, F_B, gains) -> tau (before saturation), N (the HKP normal forces), ref_margin
    (> 0: the reference inside the workspace), dist_step and limit_excess (Newton-Euler's distribution: its last Newton
    step, and the largest of |limit value| / bound - 1 over its 24 actuator limits; 0 and -1 otherwise), the model's
    numbers folded in.

    N: Newton-Euler's distribution's own where it distributes; else the normal forces that the controller's model
    without friction gives under the commanded torques at the estimated state (its forward dynamics: the accelerations
    and N that make the Newton-Euler equations hold, one linear solve)."""
    model, mech = spec.model, spec.model.mechanism
    m, p = folded(model), folded(model).p
    n, nN = spec.n, spec.n_normal
    q, dq, q_ref, dq_ref, ddq_ref = (ca.SX.sym(name, n) for name in ("q", "dq", "q_ref", "dq_ref", "ddq_ref"))
    F, gains = ca.SX.sym("F_B", 3), ca.SX.sym("gains", len(spec.gains))
    B = ca.DM(model.molar(spec.side))
    law = control_function(controller_row(spec.kind), mech, InverseDynamics(spec.method, spec.goal, spec.friction))
    tau = law(q, dq, q_ref, dq_ref, ddq_ref, F, gains, B, p)
    ref_margin = state_function(mech)(q_ref, dq_ref, p)[2]
    kin = kinematics_kernel(mech, ORIENTATION).graph()
    coefficients = coefficients_kernel(mech, ORIENTATION).graph()
    i_theta = KINEMATICS_OUTPUTS.index("theta")
    dist_step, excess = ca.SX(0), ca.SX(-1)
    if spec.distributes:
        ddq = ddq_ref + gains[n:] * (dq_ref - dq) + gains[:n] * (q_ref - q)
        D = coefficients(kin(q, dq, ddq, p)[i_theta], q, dq, ddq, F, B, p)[0]
        _, N, _, dist_step, limits = distribution_function(symbols(mech), ORIENTATION, spec.goal, 1.0 if spec.friction else 0.0)(D, p)
        bounds = ca.DM(limit_bounds(model))
        excess = ca.mmax(ca.fabs(limits) / bounds - 1)
    elif nN:
        x = ca.SX.sym("x", n + nN)  # accelerations and normal forces
        D = coefficients(kin(q, dq, x[:n], p)[i_theta], q, dq, x[:n], F, B, p)[0]
        model_tau = forces_sx(m, D, x[n:], 0.0)["tau"]  # linear in x
        A = ca.jacobian(model_tau, x)
        b = ca.substitute(model_tau, x, ca.SX.zeros(n + nN))
        A = ca.substitute(A, x, ca.SX.zeros(n + nN))
        N = ca.solve(A, tau - b)[n:]
    else:
        N = ca.SX(0, 1)
    return ca.Function(f"{PREFIX}_law", [q, dq, q_ref, dq_ref, ddq_ref, F, gains],
                       [tau, ca.densify(N) if nN else ca.SX.zeros(1), ref_margin, dist_step, excess],
                       ["q", "dq", "q_ref", "dq_ref", "ddq_ref", "F_B", "gains"], ["tau", "N", "ref_margin", "dist_step", "limit_excess"],
                       {"cse": True})


def home_angles(model: Model) -> np.ndarray:
    """The crank angles at the home pose (q = 0), the model's inverse kinematics (rad)."""
    n = n_coordinates(model.mechanism)
    out = kinematics_kernel(model.mechanism, ORIENTATION).graph()(np.zeros(n), np.zeros(n), np.zeros(n), model.vector())
    return np.asarray(out[KINEMATICS_OUTPUTS.index("theta")]).ravel()


# ------------------------------------------------------------------------------------------- the C sources


_FUNCTION = re.compile(r"^(?:[A-Za-z_][\w\s\*]*?)\b([A-Za-z_]\w*)\(([^()]*)\)\s*\{", re.M)


def strict_c(code: str) -> str:
    """CasADi's generated C made to compile with :data:`STRICT_FLAGS`: every parameter of every function is cast to
    void at its start (the generated functions leave some unused), and its one non-static helper made static."""
    def casts(match: re.Match) -> str:
        names = []
        for param in match.group(2).split(","):
            tokens = re.findall(r"[A-Za-z_]\w*", param)
            if tokens and tokens != ["void"]:
                names.append(tokens[-1])
        return match.group(0) + "".join(f" (void){name};" for name in names)

    code = _FUNCTION.sub(casts, code)
    return re.sub(r"^casadi_real casadi_(\w+)\(", r"static casadi_real casadi_\1(", code, flags=re.M)


def _array(values) -> str:
    return ", ".join(repr(float(v)) for v in np.ravel(values))


def _table(spec: StepSpec) -> np.ndarray:
    return np.column_stack([spec.t, spec.q, spec.dq, spec.ddq, spec.force])


def header(spec: StepSpec, fk: ca.Function, law: ca.Function) -> str:
    n, nN = spec.n, max(spec.n_normal, 1)
    sizes = {"ARG": max(fk.sz_arg(), law.sz_arg()), "RES": max(fk.sz_res(), law.sz_res()),
             "IW": max(fk.sz_iw(), law.sz_iw(), 1), "W": max(fk.sz_w(), law.sz_w(), 1)}
    bits = "\n".join(f"#define CHEWBOT_CTRL_{name} 0x{value:04x}u" for name, value in STATUS_BITS.items())
    return f"""/* {PREFIX}.h: the controller step of the chewing robot, generated by chewbot {VERSION} (export-controller).
   Model {spec.model.name} ({spec.model.mechanism}), {spec.kind}{' with ' + spec.method if _uses_inverse_dynamics(spec) else ''}.
   C99, libm only. No allocation, no global state, no I/O: every state lives in the caller's chewbot_ctrl.
   SI units throughout (m, rad, s, N, N m). See README.md. */
#ifndef CHEWBOT_CTRL_H
#define CHEWBOT_CTRL_H

#include <stddef.h>

#define CHEWBOT_CTRL_NQ {n}          /* independent coordinates (Euler angles): {', '.join(_coordinate_names(spec))} */
#define CHEWBOT_CTRL_NN {nN}          /* HKP normal forces N_L, N_R (1 unused slot for the 6RSS) */
#define CHEWBOT_CTRL_NG {len(spec.gains)}          /* gains */
#define CHEWBOT_CTRL_TASK_ROWS {len(spec.t)}
#define CHEWBOT_CTRL_TASK_COLUMNS {1 + 3 * n + 3}  /* t, q[NQ], dq[NQ], ddq[NQ], F_B[3] */
#define CHEWBOT_CTRL_WORK_ARG {sizes['ARG']}
#define CHEWBOT_CTRL_WORK_RES {sizes['RES']}
#define CHEWBOT_CTRL_WORK_IW {sizes['IW']}
#define CHEWBOT_CTRL_WORK_W {sizes['W']}

/* Status bits (README.md gives each one's safe behaviour). */
{bits}

/* The compiled-in reference task: CHEWBOT_CTRL_TASK_ROWS rows of CHEWBOT_CTRL_TASK_COLUMNS (read-only). */
extern const double chewbot_ctrl_task[];

/* Settings, set to their defaults by chewbot_ctrl_init; the caller may change them before the first step. */
typedef struct {{
  double gains[CHEWBOT_CTRL_NG];  /* {_gain_description(spec)} */
  double cutoff_hz;               /* velocity filter: v = b v + (1 - b) dq/dt, b = exp(-2 pi cutoff dt) */
  double torque_limit;            /* N m: |tau| saturates here */
  double torque_rate_limit;       /* N m/s: |dtau/dt| limit; 0 switches it off */
  double watchdog_s;              /* s: a step later than this after the previous one trips the (latched) watchdog */
  double fk_step_tolerance;       /* m or rad: the last Gauss-Newton step of a converged estimate */
  double fk_residual_tolerance;   /* scaled closure residual (1) above which the angles are rejected */
  double conditioning_min;        /* near-singular below this (direct kinematics) */
  double transmission_min;        /* near-singular below this (sin of the smallest transmission angle) */
  double distribution_step_tolerance; /* N: Newton-Euler distribution's last step */
  double max_hold_ticks;          /* ticks the last torques are held while the estimate is unusable, then zero */
}} chewbot_ctrl_config;

/* What the last step computed (all doubles). */
typedef struct {{
  double q[CHEWBOT_CTRL_NQ];        /* estimated pose, independent coordinates (m, rad) */
  double dq[CHEWBOT_CTRL_NQ];       /* estimated rates (filtered difference) */
  double pose[6];                   /* X_EE = X, Y, Z (m), alpha, beta, gamma (rad) of the estimate */
  double q_ref[CHEWBOT_CTRL_NQ];    /* the reference used */
  double dq_ref[CHEWBOT_CTRL_NQ];
  double ddq_ref[CHEWBOT_CTRL_NQ];
  double force[3];                  /* bite force the law used (N, in S) */
  double error[CHEWBOT_CTRL_NQ];    /* tracking error q_ref - q */
  double normal[CHEWBOT_CTRL_NN];   /* HKP normal forces N_L, N_R (N) */
  double tau_cmd[6];                /* the control law's torques before saturation and rate limit (N m) */
  double tau[6];                    /* the torques output (N m) */
  double fk_residual, fk_step, conditioning, transmission, pose_margin, ref_margin, dist_step, limit_excess, dt;
}} chewbot_ctrl_outputs;

/* The context: the caller owns it (static, stack or its own memory); one per controller. */
typedef struct {{
  chewbot_ctrl_config config;
  chewbot_ctrl_outputs out;
  double offsets[6];                /* encoder offsets: theta = theta_measured - offsets */
  double q[CHEWBOT_CTRL_NQ], dq[CHEWBOT_CTRL_NQ], t_estimate; /* the estimator's state */
  double tau_last[6], t_last;
  double held_q_ref[CHEWBOT_CTRL_NQ]; /* the last reference inside the workspace */
  double user_q_ref[CHEWBOT_CTRL_NQ], user_dq_ref[CHEWBOT_CTRL_NQ], user_ddq_ref[CHEWBOT_CTRL_NQ], user_force[3];
  long row, ticks, hold_ticks;
  int user_reference, estop, started;
  unsigned latched;
  const double* arg[CHEWBOT_CTRL_WORK_ARG];
  double* res[CHEWBOT_CTRL_WORK_RES];
  long long iw[CHEWBOT_CTRL_WORK_IW];
  double w[CHEWBOT_CTRL_WORK_W];
}} chewbot_ctrl;

/* Start a controller at time t0: defaults in config, the estimator at the reference's pose and rates at t0 (the robot
   is there and then), zero torques, offsets as given (NULL: zero). */
void chewbot_ctrl_init(chewbot_ctrl* ctx, double t0, const double offsets[6]);
/* Homing: set the offsets from the raw encoder angles read with the robot at its home pose (q = 0). */
void chewbot_ctrl_home(chewbot_ctrl* ctx, const double theta_raw_at_home[6]);
/* One tick: tau_out (N m) for the measured angles at time t (s); status_out the status bits. Returns the status. */
unsigned chewbot_ctrl_step(chewbot_ctrl* ctx, double t, const double theta_measured[6], double tau_out[6], unsigned* status_out);
/* The reference for the next steps, set by the caller (instead of the task table) until chewbot_ctrl_use_task. */
void chewbot_ctrl_set_reference(chewbot_ctrl* ctx, const double q_ref[CHEWBOT_CTRL_NQ], const double dq_ref[CHEWBOT_CTRL_NQ],
                                const double ddq_ref[CHEWBOT_CTRL_NQ], const double force[3]);
void chewbot_ctrl_use_task(chewbot_ctrl* ctx);
/* Emergency stop: on (nonzero) zeroes the torques at once, whatever else, until switched off. */
void chewbot_ctrl_set_estop(chewbot_ctrl* ctx, int on);
/* Clear the latched watchdog (and the hold counter) after the caller has made the robot safe. */
void chewbot_ctrl_clear_faults(chewbot_ctrl* ctx);
/* The crank angles at the home pose (rad). */
void chewbot_ctrl_home_angles(double theta[6]);
size_t chewbot_ctrl_size(void);

#endif
"""


def _coordinate_names(spec: StepSpec) -> list[str]:
    return ["X", "Y", "alpha", "beta"] if spec.model.has_hkp else ["X", "Y", "Z", "alpha", "beta", "gamma"]


def _gain_description(spec: StepSpec) -> str:
    return controller_row(spec.kind).module().Gains.VECTOR


def _uses_inverse_dynamics(spec: StepSpec) -> bool:
    return controller_row(spec.kind).needs.inverse_dynamics


STEP_C = r"""/* chewbot_ctrl.c: the controller step (hand-written part; the graphs are in chewbot_ctrl_kernels.c). */
#include <math.h>
#include <string.h>
#include "chewbot_ctrl.h"
#include "chewbot_ctrl_kernels.h"

#define NQ CHEWBOT_CTRL_NQ
#define NN CHEWBOT_CTRL_NN
#define COLS CHEWBOT_CTRL_TASK_COLUMNS
#define ROWS CHEWBOT_CTRL_TASK_ROWS

static const double HOME[6] = {@HOME@};
static const double HERMITE[6][6] = {@HERMITE@};
static const double GAINS[CHEWBOT_CTRL_NG] = {@GAINS@};

size_t chewbot_ctrl_size(void) { return sizeof(chewbot_ctrl); }

void chewbot_ctrl_home_angles(double theta[6]) {
  int i;
  for (i = 0; i < 6; ++i) theta[i] = HOME[i];
}

static int is_finite(double x) { return x - x == 0.0; }

/* The task's reference at t: quintic Hermite between the samples (the samples themselves at their times), the bite
   force linear; before the first sample the first, after the last the last with zero rates. ctx->row is a warm start. */
static void task_reference(chewbot_ctrl* ctx, double t, double q[NQ], double dq[NQ], double ddq[NQ], double force[3]) {
  const double* first = chewbot_ctrl_task;
  const double* last = chewbot_ctrl_task + (ROWS - 1) * COLS;
  const double* a;
  const double* b;
  double dt, s, c[6], ends[6], pw[6];
  long i = ctx->row;
  int j, k, m;
  if (ROWS < 2 || !(t >= first[0] && t <= last[0])) { /* outside the table: its nearest end, at rest */
    a = (ROWS < 2 || !(t > first[0])) ? first : last;
    for (j = 0; j < NQ; ++j) { q[j] = a[1 + j]; dq[j] = 0.0; ddq[j] = 0.0; }
    for (j = 0; j < 3; ++j) force[j] = a[1 + 3 * NQ + j];
    return;
  }
  while (i > 0 && chewbot_ctrl_task[i * COLS] > t) --i;
  while (i < ROWS - 2 && chewbot_ctrl_task[(i + 1) * COLS] <= t) ++i;
  ctx->row = i;
  a = chewbot_ctrl_task + i * COLS;
  b = a + COLS;
  dt = b[0] - a[0];
  s = (t - a[0]) / dt;
  pw[0] = 1.0;
  for (k = 1; k < 6; ++k) pw[k] = pw[k - 1] * s;
  for (j = 0; j < NQ; ++j) {
    double p = 0.0, dp = 0.0, ddp = 0.0;
    ends[0] = a[1 + j]; ends[1] = dt * a[1 + NQ + j]; ends[2] = dt * dt * a[1 + 2 * NQ + j];
    ends[3] = b[1 + j]; ends[4] = dt * b[1 + NQ + j]; ends[5] = dt * dt * b[1 + 2 * NQ + j];
    for (k = 0; k < 6; ++k) {
      c[k] = 0.0;
      for (m = 0; m < 6; ++m) c[k] += HERMITE[k][m] * ends[m];
    }
    for (k = 0; k < 6; ++k) p += c[k] * pw[k];
    for (k = 1; k < 6; ++k) dp += c[k] * k * pw[k - 1];
    for (k = 2; k < 6; ++k) ddp += c[k] * (k * (k - 1)) * pw[k - 2];
    q[j] = p; dq[j] = dp / dt; ddq[j] = ddp / (dt * dt);
  }
  for (j = 0; j < 3; ++j) force[j] = a[1 + 3 * NQ + j] + (t - a[0]) * ((b[1 + 3 * NQ + j] - a[1 + 3 * NQ + j]) / dt);
}

static void reference_at(chewbot_ctrl* ctx, double t, double q[NQ], double dq[NQ], double ddq[NQ], double force[3]) {
  int j;
  if (!ctx->user_reference) { task_reference(ctx, t, q, dq, ddq, force); return; }
  for (j = 0; j < NQ; ++j) { q[j] = ctx->user_q_ref[j]; dq[j] = ctx->user_dq_ref[j]; ddq[j] = ctx->user_ddq_ref[j]; }
  for (j = 0; j < 3; ++j) force[j] = ctx->user_force[j];
}

void chewbot_ctrl_init(chewbot_ctrl* ctx, double t0, const double offsets[6]) {
  double ddq[NQ], force[3];
  int i;
  memset(ctx, 0, sizeof *ctx);
  for (i = 0; i < CHEWBOT_CTRL_NG; ++i) ctx->config.gains[i] = GAINS[i];
  ctx->config.cutoff_hz = @CUTOFF@;
  ctx->config.torque_limit = @TORQUE_LIMIT@;
  ctx->config.torque_rate_limit = @RATE_LIMIT@;
  ctx->config.watchdog_s = @WATCHDOG@;
  ctx->config.fk_step_tolerance = @FK_STEP@;
  ctx->config.fk_residual_tolerance = @FK_RESIDUAL@;
  ctx->config.conditioning_min = @CONDITIONING@;
  ctx->config.transmission_min = @TRANSMISSION@;
  ctx->config.distribution_step_tolerance = @DIST_STEP@;
  ctx->config.max_hold_ticks = @MAX_HOLD@;
  for (i = 0; i < 6; ++i) ctx->offsets[i] = offsets ? offsets[i] : 0.0;
  reference_at(ctx, t0, ctx->q, ctx->dq, ddq, force);
  for (i = 0; i < NQ; ++i) ctx->held_q_ref[i] = ctx->q[i];
  ctx->t_estimate = t0;
  ctx->t_last = t0;
}

void chewbot_ctrl_home(chewbot_ctrl* ctx, const double theta_raw_at_home[6]) {
  int i;
  for (i = 0; i < 6; ++i) ctx->offsets[i] = theta_raw_at_home[i] - HOME[i];
}

void chewbot_ctrl_set_reference(chewbot_ctrl* ctx, const double q_ref[NQ], const double dq_ref[NQ], const double ddq_ref[NQ],
                                const double force[3]) {
  int j;
  for (j = 0; j < NQ; ++j) { ctx->user_q_ref[j] = q_ref[j]; ctx->user_dq_ref[j] = dq_ref[j]; ctx->user_ddq_ref[j] = ddq_ref[j]; }
  for (j = 0; j < 3; ++j) ctx->user_force[j] = force[j];
  ctx->user_reference = 1;
}

void chewbot_ctrl_use_task(chewbot_ctrl* ctx) { ctx->user_reference = 0; }
void chewbot_ctrl_set_estop(chewbot_ctrl* ctx, int on) { ctx->estop = on != 0; }
void chewbot_ctrl_clear_faults(chewbot_ctrl* ctx) { ctx->latched = 0; ctx->hold_ticks = 0; }

static void fk(chewbot_ctrl* ctx, const double theta[6], const double guess[NQ]) {
  chewbot_ctrl_outputs* o = &ctx->out;
  ctx->arg[0] = theta; ctx->arg[1] = guess;
  ctx->res[0] = o->q; ctx->res[1] = o->pose; ctx->res[2] = &o->fk_residual; ctx->res[3] = &o->fk_step;
  ctx->res[4] = &o->conditioning; ctx->res[5] = &o->transmission; ctx->res[6] = &o->pose_margin;
  chewbot_ctrl_fk(ctx->arg, ctx->res, ctx->iw, ctx->w, 0);
}

static void law(chewbot_ctrl* ctx) {
  chewbot_ctrl_outputs* o = &ctx->out;
  ctx->arg[0] = o->q; ctx->arg[1] = o->dq; ctx->arg[2] = o->q_ref; ctx->arg[3] = o->dq_ref; ctx->arg[4] = o->ddq_ref;
  ctx->arg[5] = o->force; ctx->arg[6] = ctx->config.gains;
  ctx->res[0] = o->tau_cmd; ctx->res[1] = o->normal; ctx->res[2] = &o->ref_margin; ctx->res[3] = &o->dist_step;
  ctx->res[4] = &o->limit_excess;
  chewbot_ctrl_law(ctx->arg, ctx->res, ctx->iw, ctx->w, 0);
}

unsigned chewbot_ctrl_step(chewbot_ctrl* ctx, double t, const double theta_measured[6], double tau_out[6], unsigned* status_out) {
  chewbot_ctrl_outputs* o = &ctx->out;
  double theta[6], guess[NQ];
  unsigned status = 0;
  int i, usable = 1, bad_time = 0;
  double dt = t - ctx->t_last;
  if (!is_finite(t) || (ctx->started && !(dt >= 0.0))) { status |= CHEWBOT_CTRL_BAD_INPUT; bad_time = 1; dt = 0.0; }
  if (ctx->started && dt > ctx->config.watchdog_s) ctx->latched |= CHEWBOT_CTRL_WATCHDOG;
  o->dt = dt;
  /* the pose estimate: Gauss-Newton from the last one */
  for (i = 0; i < 6; ++i) {
    theta[i] = theta_measured[i] - ctx->offsets[i];
    if (!is_finite(theta[i])) status |= CHEWBOT_CTRL_BAD_INPUT;
  }
  for (i = 0; i < NQ; ++i) guess[i] = ctx->q[i];
  if (!(status & CHEWBOT_CTRL_BAD_INPUT)) {
    fk(ctx, theta, guess);
    if (!(o->fk_step <= ctx->config.fk_step_tolerance && o->fk_residual <= ctx->config.fk_residual_tolerance))
      status |= CHEWBOT_CTRL_FK_NOT_CONVERGED;
    if (!(o->conditioning >= ctx->config.conditioning_min && o->transmission >= ctx->config.transmission_min))
      status |= CHEWBOT_CTRL_NEAR_SINGULAR;
    for (i = 0; i < NQ; ++i) if (!is_finite(o->q[i])) status |= CHEWBOT_CTRL_FK_NOT_CONVERGED;
  }
  usable = !(status & (CHEWBOT_CTRL_BAD_INPUT | CHEWBOT_CTRL_FK_NOT_CONVERGED | CHEWBOT_CTRL_NEAR_SINGULAR));
  if (usable) {
    /* the rates: the filtered backward difference of the estimates */
    double de = t - ctx->t_estimate;
    if (de > 0.0) {
      double bf = exp(-2.0 * 3.14159265358979323846 * ctx->config.cutoff_hz * de);
      for (i = 0; i < NQ; ++i) ctx->dq[i] = bf * ctx->dq[i] + (1.0 - bf) * (o->q[i] - ctx->q[i]) / de;
    }
    for (i = 0; i < NQ; ++i) ctx->q[i] = o->q[i];
    ctx->t_estimate = t;
  }
  for (i = 0; i < NQ; ++i) { o->q[i] = ctx->q[i]; o->dq[i] = ctx->dq[i]; }
  /* the reference and the law; a reference outside the workspace: hold the last one inside, at rest */
  reference_at(ctx, t, o->q_ref, o->dq_ref, o->ddq_ref, o->force);
  law(ctx);
  if (!(o->ref_margin > 0.0)) {
    double asked = o->ref_margin; /* reported: the margin of the reference asked for */
    status |= CHEWBOT_CTRL_REFERENCE_OUTSIDE;
    for (i = 0; i < NQ; ++i) { o->q_ref[i] = ctx->held_q_ref[i]; o->dq_ref[i] = 0.0; o->ddq_ref[i] = 0.0; }
    law(ctx);
    o->ref_margin = asked;
  } else {
    for (i = 0; i < NQ; ++i) ctx->held_q_ref[i] = o->q_ref[i];
  }
  for (i = 0; i < NQ; ++i) o->error[i] = o->q_ref[i] - o->q[i];
  for (i = 0; i < 6; ++i) if (!is_finite(o->tau_cmd[i])) usable = 0;
  if (o->limit_excess > 0.0) status |= CHEWBOT_CTRL_LIMIT_ACTIVE;
  if (!(o->dist_step <= ctx->config.distribution_step_tolerance)) status |= CHEWBOT_CTRL_DISTRIBUTION_NOT_CONVERGED;
  /* the torques */
  if (ctx->estop || (ctx->latched & CHEWBOT_CTRL_WATCHDOG)) {
    for (i = 0; i < 6; ++i) o->tau[i] = 0.0;
    if (ctx->estop) status |= CHEWBOT_CTRL_ESTOP;
  } else {
    if (usable) {
      ctx->hold_ticks = 0;
      for (i = 0; i < 6; ++i) {
        double lim = ctx->config.torque_limit, v = o->tau_cmd[i];
        if (v > lim || v < -lim) { status |= CHEWBOT_CTRL_TORQUE_SATURATED; v = v > lim ? lim : -lim; }
        o->tau[i] = v;
      }
    } else {
      status |= CHEWBOT_CTRL_HOLDING;
      ctx->hold_ticks += 1;
      for (i = 0; i < 6; ++i) o->tau[i] = ctx->hold_ticks <= ctx->config.max_hold_ticks ? ctx->tau_last[i] : 0.0;
    }
    if (ctx->config.torque_rate_limit > 0.0) {
      double step = ctx->config.torque_rate_limit * dt;
      for (i = 0; i < 6; ++i) {
        double d = o->tau[i] - ctx->tau_last[i];
        if (d > step || d < -step) { status |= CHEWBOT_CTRL_RATE_LIMITED; o->tau[i] = ctx->tau_last[i] + (d > 0 ? step : -step); }
      }
    }
  }
  status |= ctx->latched;
  for (i = 0; i < 6; ++i) { tau_out[i] = o->tau[i]; ctx->tau_last[i] = o->tau[i]; }
  if (!bad_time) ctx->t_last = t;
  ctx->started = 1;
  ctx->ticks += 1;
  if (status_out) *status_out = status;
  return status;
}
"""


def step_source(spec: StepSpec) -> str:
    model = spec.model
    values = {"HOME": _array(home_angles(model)), "HERMITE": ", ".join("{" + _array(row) + "}" for row in HERMITE),
              "GAINS": _array(spec.gains), "CUTOFF": repr(float(spec.cutoff)), "TORQUE_LIMIT": repr(float(model.limits.torque)),
              "RATE_LIMIT": repr(float(spec.torque_rate_limit)), "WATCHDOG": repr(WATCHDOG_PERIODS / spec.rate),
              "FK_STEP": repr(FK_STEP_TOLERANCE), "FK_RESIDUAL": repr(FK_RESIDUAL_TOLERANCE), "CONDITIONING": repr(CONDITIONING_MIN),
              "TRANSMISSION": repr(TRANSMISSION_MIN), "DIST_STEP": repr(DISTRIBUTION_STEP_TOLERANCE), "MAX_HOLD": repr(float(MAX_HOLD_TICKS))}
    code = STEP_C
    for key, value in values.items():
        code = code.replace(f"@{key}@", value)
    return code


def task_source(spec: StepSpec) -> str:
    rows = _table(spec)
    lines = [f"/* The reference task compiled in: {rows.shape[0]} rows of t (s), q, dq, ddq (m, rad; /s; /s^2), F_B (N). */",
             f'#include "{PREFIX}.h"', "", "const double chewbot_ctrl_task[] = {"]
    lines += ["  " + _array(row) + "," for row in rows]
    lines.append("};")
    return "\n".join(lines) + "\n"


MAKEFILE = """# Builds the controller step library and the example that checks it against the log.
# Compiles warning-free with these flags; override CFLAGS for your target (e.g. -O3 -mcpu=...).
CC ?= cc
CFLAGS ?= -std=c99 -Wall -Wextra -Werror -pedantic -O2
SOURCES := $(wildcard src/*.c)
OBJECTS := $(SOURCES:.c=.o)

all: libchewbot_ctrl.a example/example

src/%.o: src/%.c include/chewbot_ctrl.h
\t$(CC) $(CFLAGS) -Iinclude -c -o $@ $<

libchewbot_ctrl.a: $(OBJECTS)
\tar rcs $@ $(OBJECTS)

example/example: example/example.c libchewbot_ctrl.a
\t$(CC) $(CFLAGS) -D_POSIX_C_SOURCE=199309L -Iinclude -o $@ example/example.c libchewbot_ctrl.a -lm

check: example/example
\t./example/example example/log.csv

clean:
\trm -f src/*.o libchewbot_ctrl.a example/example

.PHONY: all check clean
"""


EXAMPLE_C = r"""/* Runs the controller step against a log written by chewbot (a simulation of the same controller), checks the
   commanded torques against the logged ones, and prints the time per step.
   Usage: example LOG [REPEATS]  (LOG: t, theta1..6, tau_cmd1..6 per line after a header). Exit 1 on a mismatch.
   The check: |tau_cmd - logged| <= 1e-9 * max |logged| on every tick. REPEATS runs the whole log that many
   times for the timing (median, p99 and maximum over every step). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "chewbot_ctrl.h"

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int by_value(const void* a, const void* b) {
  double x = *(const double*)a, y = *(const double*)b;
  return (x > y) - (x < y);
}

int main(int argc, char** argv) {
  FILE* f;
  char line[4096];
  double* rows = NULL;
  double* times;
  long n = 0, capacity = 0, k, r, repeats, bad = 0, count;
  double scale = 0.0, worst = 0.0;
  static chewbot_ctrl ctx;
  if (argc < 2) { fprintf(stderr, "usage: %s LOG [REPEATS]\n", argv[0]); return 2; }
  repeats = argc > 2 ? atol(argv[2]) : 1;
  if (repeats < 1) repeats = 1;
  f = fopen(argv[1], "r");
  if (!f) { perror(argv[1]); return 2; }
  if (!fgets(line, sizeof line, f)) { fprintf(stderr, "%s: empty\n", argv[1]); return 2; }
  while (fgets(line, sizeof line, f)) {
    double* row;
    char* p = line;
    int j;
    if (n == capacity) {
      capacity = capacity ? 2 * capacity : 1024;
      rows = realloc(rows, (size_t)capacity * 13 * sizeof *rows);
      if (!rows) { fprintf(stderr, "out of memory\n"); return 2; }
    }
    row = rows + 13 * n;
    for (j = 0; j < 13; ++j) {
      char* end;
      row[j] = strtod(p, &end);
      if (end == p) { fprintf(stderr, "%s: line %ld: 13 numbers expected\n", argv[1], n + 2); return 2; }
      p = *end == ',' ? end + 1 : end;
    }
    for (j = 7; j < 13; ++j) if (fabs(row[j]) > scale) scale = fabs(row[j]);
    ++n;
  }
  fclose(f);
  if (n == 0) { fprintf(stderr, "%s: no rows\n", argv[1]); return 2; }
  times = malloc((size_t)(n * repeats) * sizeof *times);
  if (!times) { fprintf(stderr, "out of memory\n"); return 2; }
  for (r = 0; r < repeats; ++r) {
    chewbot_ctrl_init(&ctx, rows[0], NULL);
    for (k = 0; k < n; ++k) {
      const double* row = rows + 13 * k;
      double tau[6], t0;
      unsigned status;
      int j;
      t0 = now();
      chewbot_ctrl_step(&ctx, row[0], row + 1, tau, &status);
      times[r * n + k] = now() - t0;
      if (r == 0) {
        for (j = 0; j < 6; ++j) {
          double d = fabs(ctx.out.tau_cmd[j] - row[7 + j]);
          if (d > worst) worst = d;
          if (d > 1e-9 * scale) {
            if (bad < 5) fprintf(stderr, "t = %.6f s: tau_cmd%d = %.17g, the log %.17g\n", row[0], j + 1, ctx.out.tau_cmd[j], row[7 + j]);
            ++bad;
          }
        }
      }
    }
  }
  count = n * repeats;
  qsort(times, (size_t)count, sizeof *times, by_value);
  printf("steps %ld, largest difference from the log %.3g N m (%.3g of max |tau| %.4g N m)\n", n, worst, worst / scale, scale);
  printf("time per step over %ld steps: median %.2f us, p99 %.2f us, max %.2f us\n", count, 1e6 * times[count / 2],
         1e6 * times[(long)(0.99 * (double)(count - 1))], 1e6 * times[count - 1]);
  free(rows);
  free(times);
  if (bad) { fprintf(stderr, "%ld torques differ from the log by more than 1e-9 of max |tau|\n", bad); return 1; }
  printf("all torques equal the log's to 1e-9 of max |tau|\n");
  return 0;
}
"""


def readme(spec: StepSpec, fk: ca.Function, law: ca.Function, log_rows: int) -> str:
    return README_TEMPLATE.format(
        model=spec.model.name, mechanism=spec.model.mechanism, kind=spec.kind,
        method=spec.method if _uses_inverse_dynamics(spec) else "(none: PD on the crank angles)", goal=spec.goal or "-",
        friction="with" if spec.friction else "without", n=spec.n, coords=", ".join(_coordinate_names(spec)),
        gains=_gain_description(spec), rows=len(spec.t), t0=spec.t[0], t1=spec.t[-1], cutoff=spec.cutoff, rate=spec.rate,
        limit=spec.model.limits.torque, rate_limit=spec.torque_rate_limit, watchdog=WATCHDOG_PERIODS / spec.rate,
        fk_iterations=FK_ITERATIONS, fk_step=FK_STEP_TOLERANCE, fk_residual=FK_RESIDUAL_TOLERANCE,
        conditioning=CONDITIONING_MIN, transmission=TRANSMISSION_MIN, dist_step=DISTRIBUTION_STEP_TOLERANCE,
        max_hold=MAX_HOLD_TICKS, log_rows=log_rows, period_ms=1e3 / spec.rate, work_w=max(fk.sz_w(), law.sz_w()), version=VERSION,
        bits="\n".join(f"| `CHEWBOT_CTRL_{name}` | 0x{value:04x} | {STATUS_HELP[name]} |" for name, value in STATUS_BITS.items()))


README_TEMPLATE = """# chewbot_ctrl: the controller step of the chewing robot

Generated by chewbot {version} (`chewbot export-controller`) for model `{model}` ({mechanism}): controller `{kind}`,
inverse dynamics {method}, goal {goal}, {friction} friction in the controller's model. Plain C99, libm only: no
allocation, no global or static mutable state, no I/O in the step; every state lives in a `chewbot_ctrl` the caller
owns. The model's numbers, the gains and the reference task are folded into the sources. SI units throughout.

| file | what |
|---|---|
| `include/chewbot_ctrl.h` | the API (below), the context, configuration and output structs, the status bits |
| `src/chewbot_ctrl.c` | the step: offsets, estimator, reference, law, saturation, rate limit, watchdog, e-stop |
| `src/chewbot_ctrl_kernels.c`, `.h` | the pose estimate and the control law, generated from chewbot's CasADi graphs |
| `src/chewbot_ctrl_task.c` | the reference task: {rows} samples, t = {t0:g} ... {t1:g} s |
| `example/example.c` | runs the step against `example/log.csv` ({log_rows} ticks of a chewbot simulation of this controller), checks the torques, prints the time per step |

`make` builds `libchewbot_ctrl.a` and the example with `-std=c99 -Wall -Wextra -Werror -pedantic -O2`; `make check`
runs the example. The sources may sit in any folders: compile every `.c` of `src/` with `-I` pointing at the folder
of `chewbot_ctrl.h`, and link with `-lm`.

## API

```c
chewbot_ctrl ctx;                               /* the caller's memory: static, stack, or its own allocator */
chewbot_ctrl_init(&ctx, t0, NULL);              /* defaults; the estimator at the reference at t0, zero torques */
chewbot_ctrl_home(&ctx, theta_raw_at_home);     /* optional homing: offsets = raw angles at home - model's home angles */
ctx.config.torque_rate_limit = 2000.0;          /* optional: change any setting before the first step */
for (;;) {{                                      /* every {period_ms:g} ms */
  unsigned status;
  read_encoders(theta_raw);                     /* six crank angles (rad) */
  chewbot_ctrl_step(&ctx, t, theta_raw, tau, &status);
  write_drives(tau);                            /* six torques (N m) */
}}
```

- `void chewbot_ctrl_init(chewbot_ctrl* ctx, double t0, const double offsets[6])`: sets the defaults below in
  `ctx->config`, the encoder offsets (NULL: zero), starts the estimator at the reference's pose and rates at t0.
- `unsigned chewbot_ctrl_step(chewbot_ctrl* ctx, double t, const double theta_measured[6], double tau_out[6], unsigned* status_out)`:
  one tick at time t (s) from the six measured crank angles (rad): the torques (N m) and the status word (also returned).
- `void chewbot_ctrl_set_reference(ctx, q_ref, dq_ref, ddq_ref, force)`: the reference for the following steps, set by
  the caller each tick instead of the task table ({n} coordinates: {coords}; m, rad and their rates; the bite force
  on the mandible in N); `chewbot_ctrl_use_task(ctx)` returns to the table.
- `void chewbot_ctrl_set_estop(ctx, on)`: the emergency stop: zero torques from the next step on, while on.
- `void chewbot_ctrl_clear_faults(ctx)`: clears the latched watchdog.
- `void chewbot_ctrl_home(ctx, theta_raw_at_home)`, `void chewbot_ctrl_home_angles(theta)`: homing.
- After each step `ctx->out` holds the estimate `q`, `dq`, the pose `pose` (X, Y, Z, alpha, beta, gamma), the reference
  used, the tracking error `error` (q_ref - q), the HKP normal forces `normal` (N_L, N_R), the law's torques before
  saturation `tau_cmd`, the output `tau`, and the figures the status bits test (`fk_residual`, `fk_step`,
  `conditioning`, `transmission`, `ref_margin`, `dist_step`, `limit_excess`).

What one step does, in order: theta = theta_measured - offsets; the pose by {fk_iterations} Gauss-Newton steps on the six
closure equations from the last estimate; the rates by the filtered backward difference
v = b v + (1 - b) (q - q_last) / dt, b = exp(-2 pi cutoff dt) (dt = 0 on the first step: v stays); the reference at t
(quintic Hermite between the task's samples, the bite force linear; outside the table its nearest end at rest); the
control law ({gains}); saturation at the torque limit; the torque-rate limit. Exactly what `chewbot simulate --sensor
measured` does in Python (the tests hold the two equal tick by tick to 1e-9 of max |tau|).

## Configuration (`ctx->config`, defaults)

| field | default | meaning |
|---|---|---|
| `gains` | from the gains file | {gains} |
| `cutoff_hz` | {cutoff:g} | velocity filter's cut-off (Hz) |
| `torque_limit` | {limit:g} | N m, each actuator |
| `torque_rate_limit` | {rate_limit:g} | N m/s; 0: off |
| `watchdog_s` | {watchdog:g} | s between two steps beyond which the watchdog trips (1.5 periods of {rate:g} Hz) |
| `fk_step_tolerance` | {fk_step:g} | m or rad: the estimate's last Gauss-Newton step |
| `fk_residual_tolerance` | {fk_residual:g} | closure residual, each chain's divided by its coupler length squared |
| `conditioning_min` | {conditioning:g} | det(J'J)^(1/n) / (trace(J'J)/n) of the closure Jacobian: 1 well conditioned, 0 singular |
| `transmission_min` | {transmission:g} | smallest sin of the chains' transmission angles (0: a crank at its dead point) |
| `distribution_step_tolerance` | {dist_step:g} | N: Newton-Euler distribution's last Newton step |
| `max_hold_ticks` | {max_hold} | ticks the last torques are held while the estimate is unusable, then zero |

## Status bits and the safe behaviour of each

| bit | value | raised when, and what the step then does |
|---|---|---|
{bits}

Several bits may be set at once; the zeroing ones (ESTOP, WATCHDOG) win over holding, holding over the law.

## Timing on the robot's CPU

The step has a nearly fixed cost: no loop depends on the data but the table search, which moves one row per tick,
and a reference outside the workspace evaluates the law twice (the second time on the held reference). To time
it where it runs, build with the flags of the controller's build, pin the process to the core the loop will use,
and give it the priority it will have:

```sh
make CFLAGS="-std=c99 -O2 -mcpu=native" example/example
taskset -c 3 chrt -f 80 ./example/example example/log.csv 200
```

The example prints the median, the 99th percentile and the maximum time per step over every call (here 200 passes
over the log); the worst case is the figure to hold against the period. Work arrays: {work_w} doubles in the
context.
"""


STATUS_HELP = {
    "FK_NOT_CONVERGED": "the estimate's last Gauss-Newton step > `fk_step_tolerance` or its closure residual > "
                        "`fk_residual_tolerance`: the estimate is not updated; torques held (see HOLDING)",
    "NEAR_SINGULAR": "the estimate's conditioning < `conditioning_min` or its transmission < `transmission_min`: as "
                     "FK_NOT_CONVERGED (the angles no longer pin the pose down)",
    "TORQUE_SATURATED": "a commanded torque beyond `torque_limit`: that torque clipped to the limit, the others unchanged",
    "REFERENCE_OUTSIDE": "the reference at t is outside the workspace (a chain out of reach or near its dead point, a "
                         "condyle outside its socket): the last reference inside is held at rest (zero rate and "
                         "acceleration) and the law evaluated on it",
    "WATCHDOG": "the step was called more than `watchdog_s` after the previous one: latched; zero torques until "
                "`chewbot_ctrl_clear_faults`",
    "ESTOP": "the emergency stop is on: zero torques at once (no rate limit), the estimator keeps running",
    "RATE_LIMITED": "a torque changed faster than `torque_rate_limit`: its change limited to the limit times dt",
    "LIMIT_ACTIVE": "Newton-Euler distribution: its torques exceed an actuator limit (torque, power, axial or radial "
                    "load). Fallback: the distribution's torques, saturated at `torque_limit` (no constrained "
                    "re-solve in the step)",
    "DISTRIBUTION_NOT_CONVERGED": "Newton-Euler distribution: its last Newton step > `distribution_step_tolerance`: "
                                  "the torques still satisfy the equations of motion, but are not the optimum",
    "HOLDING": "the estimate is unusable (FK_NOT_CONVERGED, NEAR_SINGULAR, BAD_INPUT, or torques not finite): the "
               "last output torques are held, for at most `max_hold_ticks` ticks in a row, then zero",
    "BAD_INPUT": "a measured angle or t not finite, or t before the previous step's: as HOLDING, t not taken",
}


def export_controller(spec: StepSpec, out: Path, force: bool = False, inputs=(), log: np.ndarray | None = None) -> Path:
    """Write the library for ``spec`` into the folder ``out`` (written whole, replaced only with ``force`` and only if
    chewbot exported it): include/chewbot_ctrl.h, src/ (the step, the generated graphs, the task table), Makefile,
    README.md, example/example.c and, with ``log`` (rows t, theta1..6, tau_cmd1..6), example/log.csv."""
    fk, law = fk_function(spec.model), law_function(spec)
    with atomic_folder(Path(out), force, EXPORT_FOLDER, inputs) as tmp:
        write_sources(spec, tmp, fk, law)
        (tmp / "Makefile").write_text(MAKEFILE)
        (tmp / "example").mkdir()
        (tmp / "example" / "example.c").write_text(EXAMPLE_C)
        if log is not None:
            header_line = "t [s]," + ",".join(f"theta{i} [rad]" for i in range(1, 7)) + "," + ",".join(f"tau_cmd{i} [N*m]" for i in range(1, 7))
            body = "\n".join(",".join(repr(float(v)) for v in row) for row in log)
            (tmp / "example" / "log.csv").write_text(header_line + "\n" + body + "\n")
        (tmp / "README.md").write_text(readme(spec, fk, law, 0 if log is None else len(log)))
        (tmp / EXPORT_FOLDER.file).write_text(to_json({EXPORT_FOLDER.key: EXPORT_FORMAT, "chewbot": VERSION, "model": spec.model.name,
                                                       "prefix": PREFIX, "kind": "controller", "controller": spec.kind,
                                                       "method": spec.method, "goal": spec.goal, "friction": spec.friction}))
    return Path(out)


def write_sources(spec: StepSpec, folder: Path, fk: ca.Function | None = None, law: ca.Function | None = None) -> list[Path]:
    """The library's header and sources into ``folder`` (include/ and src/); returns the C files."""
    fk = fk if fk is not None else fk_function(spec.model)
    law = law if law is not None else law_function(spec)
    (folder / "include").mkdir(parents=True, exist_ok=True)
    (folder / "src").mkdir(parents=True, exist_ok=True)
    (folder / "include" / f"{PREFIX}.h").write_text(header(spec, fk, law))
    cg = ca.CodeGenerator(f"{PREFIX}_kernels.c", {"with_header": True})
    cg.add(fk)
    cg.add(law)
    cg.generate(f"{folder / 'src'}/")
    kernels = folder / "src" / f"{PREFIX}_kernels.c"
    kernels.write_text(strict_c(kernels.read_text()))
    (folder / "src" / f"{PREFIX}.c").write_text(step_source(spec))
    (folder / "src" / f"{PREFIX}_task.c").write_text(task_source(spec))
    return sorted((folder / "src").glob("*.c"))


# ------------------------------------------------------------------------------------------- through ctypes


def build_shared(spec: StepSpec, flags: tuple[str, ...] = STRICT_FLAGS) -> Path:
    """The library of ``spec`` compiled as a shared object (with :data:`STRICT_FLAGS` and -fPIC), kept in the kernel
    cache under the SHA-256 of its generated sources and the flags (the graphs are built each time, about a second;
    the compilation only once)."""
    cc = c_compiler()
    if cc is None:
        raise RuntimeError("the exported controller needs a C compiler (set $CC, or install cc/gcc/clang)")
    root = KERNELS.folder() / "controllers"
    work = root / f"{PREFIX}.tmp{os.getpid()}"
    shutil.rmtree(work, ignore_errors=True)
    sources = write_sources(spec, work)
    digest = hashlib.sha256(repr((cc, flags)).encode())
    for path in sorted(work.rglob("*.[ch]")):
        digest.update(path.name.encode() + path.read_bytes())
    base = root / f"{PREFIX}-{digest.hexdigest()[:20]}"
    lib = base / f"lib{PREFIX}.so"
    if lib.exists():
        shutil.rmtree(work, ignore_errors=True)
        return lib
    done = subprocess.run([cc, *flags, "-fPIC", "-shared", f"-I{work / 'include'}", "-o", str(work / lib.name), *map(str, sources), "-lm"],
                          capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"compiling the exported controller in {work} failed:\n{done.stderr[-4000:]}")
    try:
        work.replace(base)
    except OSError:  # another process put it there first
        shutil.rmtree(work, ignore_errors=True)
    return lib


class StepLibrary:
    """The compiled step through ctypes: :meth:`init`, :meth:`step`, and the context's outputs as NumPy views."""

    def __init__(self, spec: StepSpec, lib: Path):
        self.spec = spec
        self.lib = ctypes.CDLL(str(lib))
        self.lib.chewbot_ctrl_size.restype = ctypes.c_size_t
        self._ctx = np.zeros(self.lib.chewbot_ctrl_size() // 8 + 1, float)
        self.ctx = self._ctx.ctypes.data_as(ctypes.c_void_p)
        dp = ctypes.POINTER(ctypes.c_double)
        self.lib.chewbot_ctrl_step.restype = ctypes.c_uint
        self.lib.chewbot_ctrl_step.argtypes = [ctypes.c_void_p, ctypes.c_double, dp, dp, ctypes.POINTER(ctypes.c_uint)]
        self.lib.chewbot_ctrl_init.argtypes = [ctypes.c_void_p, ctypes.c_double, dp]
        self._theta, self._tau = np.zeros(6), np.zeros(6)
        self._status = ctypes.c_uint(0)
        self._p_theta, self._p_tau = self._theta.ctypes.data_as(dp), self._tau.ctypes.data_as(dp)
        n, nN = spec.n, max(spec.n_normal, 1)
        ng = len(spec.gains)
        # the context's layout: config (NG + 10 doubles), then the outputs (all doubles)
        sizes = [("gains", ng), ("cutoff_hz", 1), ("torque_limit", 1), ("torque_rate_limit", 1), ("watchdog_s", 1),
                 ("fk_step_tolerance", 1), ("fk_residual_tolerance", 1), ("conditioning_min", 1), ("transmission_min", 1),
                 ("distribution_step_tolerance", 1), ("max_hold_ticks", 1),
                 ("q", n), ("dq", n), ("pose", 6), ("q_ref", n), ("dq_ref", n), ("ddq_ref", n), ("force", 3), ("error", n),
                 ("normal", nN), ("tau_cmd", 6), ("tau", 6), ("fk_residual", 1), ("fk_step", 1), ("conditioning", 1),
                 ("transmission", 1), ("pose_margin", 1), ("ref_margin", 1), ("dist_step", 1), ("limit_excess", 1), ("dt", 1),
                 ("offsets", 6)]
        self.fields, at = {}, 0
        for name, size in sizes:
            self.fields[name] = self._ctx[at:at + size]
            at += size

    def init(self, t0: float, offsets=None) -> None:
        off = None if offsets is None else np.ascontiguousarray(offsets, float)
        self._offsets = off
        self.lib.chewbot_ctrl_init(self.ctx, float(t0), None if off is None else off.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))

    def step(self, t: float, theta) -> tuple[np.ndarray, int]:
        """One tick: the output torques (a copy) and the status word."""
        self._theta[:] = theta
        status = self.lib.chewbot_ctrl_step(self.ctx, float(t), self._p_theta, self._p_tau, ctypes.byref(self._status))
        return self._tau.copy(), int(status)

    def set_reference(self, q_ref, dq_ref, ddq_ref, force) -> None:
        """The caller's reference for the next steps (chewbot_ctrl_set_reference)."""
        arrays = [np.ascontiguousarray(a, float) for a in (q_ref, dq_ref, ddq_ref, force)]
        dp = ctypes.POINTER(ctypes.c_double)
        self.lib.chewbot_ctrl_set_reference(self.ctx, *(a.ctypes.data_as(dp) for a in arrays))

    def use_task(self) -> None:
        self.lib.chewbot_ctrl_use_task(self.ctx)

    def set_estop(self, on: bool) -> None:
        self.lib.chewbot_ctrl_set_estop(self.ctx, ctypes.c_int(int(on)))

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
    angles of the state it is given (:attr:`chewbot.simulation.controllers.State.theta`) and returns its commanded
    torques (``tau_cmd``: before saturation; the simulator saturates them as it does the Python controller's). It
    evaluates the Python controller ``python`` on the same tick's estimate too and keeps both, so a run states how
    far the two are apart tick by tick (:meth:`comparison`)."""

    python: CompiledLaw
    rate: float
    capabilities: ControllerCapabilities = field(default=ControllerCapabilities(), init=False)
    library: StepLibrary | None = None
    c_torques: list = field(default_factory=list)
    py_torques: list = field(default_factory=list)
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
        self.library.step(t, state.theta)
        tau = self.library.tau_cmd.copy()
        self.c_torques.append(tau)
        self.py_torques.append(self.python(t, state))
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
        """The exported step's torques against the Python controller's on the same ticks (N m)."""
        c, py = np.array(self.c_torques), np.array(self.py_torques)
        largest = float(np.max(np.abs(c - py))) if len(c) else 0.0
        scale = float(np.max(np.abs(py))) if len(py) else 0.0
        statuses = np.bitwise_or.reduce(np.array(self.statuses, dtype=np.int64)) if self.statuses else 0
        return {"library": str(self.library.lib._name), "ticks": len(c), "largest_difference_Nm": largest,
                "largest_abs_tau_Nm": scale, "relative": largest / scale if scale else 0.0,
                "status_bits_seen": [name for name, bit in STATUS_BITS.items() if statuses & bit]}


def simulation_log(result) -> np.ndarray:
    """The rows of example/log.csv from a simulation of the controller with the measured sensor path
    (:class:`chewbot.simulation.run.SimulateResult`): t, the plant's crank angles (what the encoders read: noise-free),
    the controller's commanded torques."""
    sim = result.simulation
    return np.column_stack([sim.t, result.kinematics.theta, sim.tau_cmd])
