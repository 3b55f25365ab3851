"""A second plant: MuJoCo's simulation of the robot from its MJCF model (as ``chewbot export-model`` writes it,
:mod:`chewbot.export.mjcf`; the text is handed in, the export layer being above this one).

:class:`MujocoPlant` is a plant of :class:`chewbot.simulation.interfaces.Plant`, so that chewbot's controllers run
unchanged against an engine that shares none of chewbot's equations: MuJoCo integrates the 24
coordinates of the mandible's free body, the cranks and the couplers' universal joints, closes the six loops by
``connect`` constraints and presses the condyles on their planes by unilateral contacts.

The two sides meet in the independent coordinates (Euler angles: X, Y, alpha, beta for the target, X_EE for the
6RSS):

- **chewbot -> MuJoCo** (:meth:`MujocoPlant.set_state`): the pose and its rates from chewbot's kinematics (the
  parasitic Z, gamma and the crank angles of the closed-form inverse kinematics), the couplers' joint angles from
  the directions S_i M_i and their rates from the loops' constraint Jacobian (MuJoCo's own ``efc_J``): a state that
  satisfies every constraint of both models.
- **MuJoCo -> chewbot** (:meth:`MujocoPlant.read_state`): X, Y (Z) of the mandible's origin, the XYZ Euler angles
  of its rotation and their rates from its angular velocity (omega = R_omega [alpha_dot, beta_dot, gamma_dot]),
  the crank angles and rates of MuJoCo's hinges (what encoders on the shafts would read).

Between two control ticks the torques are held on the motors ``crank1..6`` and the bite force acts at the molar
(``xfrc_applied`` on the mandible, as the force and its moment about the mass centre), averaged over each MuJoCo
step with the Radau weights of the stage values the simulator hands out; MuJoCo steps at
the file's timestep. Its own state (:class:`MujocoState`) is MuJoCo's qpos and qvel. The workspace margin is
chewbot's (:func:`chewbot.simulation.plant.state_function` at the state read back): MuJoCo's planes are unbounded,
and the robot is stopped where a condyle leaves its socket.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from chewbot.compiled.kernels import KernelSpec, native
from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel
from chewbot.model import Model
from chewbot.rotation import R_omega, R_omega_dot, euler_angles_from_matrix, matrix_from_euler_angles
from chewbot.simulation.forward import ORIENTATION, Forward, n_coordinates
from chewbot.simulation.integrator import A as RADAU_A
from chewbot.simulation.interfaces import PLANT_INPUTS, Column, PlantCapabilities, PlantState, StageInputs
from chewbot.simulation.plant import STATE_OUTPUTS, SimulationError, plant_residual, state_function


def _quat_from_matrix(R: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R).ravel())
    return q


@dataclass(frozen=True)
class MujocoState:
    """The MuJoCo plant's own state: MuJoCo's ``qpos`` and ``qvel`` (its 24 coordinates and their rates)."""

    qpos: np.ndarray
    qvel: np.ndarray


@dataclass
class MujocoPlant:
    """The robot simulated by MuJoCo: ``model`` (the plant's numbers), ``xml`` its MJCF text (bodies, joints, sites
    and actuators named as :mod:`chewbot.export.mjcf` names them), ``friction`` (whether that text has the model's
    friction: chewbot's residual at MuJoCo's answer is then computed with it), ``side`` (the molar where the bite force
    acts)."""

    model: Model
    xml: str = field(repr=False)
    friction: bool = False
    side: str = "left"
    capabilities: PlantCapabilities = field(default=PlantCapabilities(), init=False)
    splits: int = field(default=0, init=False)  # kept for the simulator's report: MuJoCo's steps are never split
    _violations: list = field(default_factory=list, init=False, repr=False)  # (loops, HKP) of each state returned, m

    def __post_init__(self):
        import mujoco

        self.mj = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.mj)
        self._mandible = self.mj.body("mandible").id
        self._qadr = self.mj.jnt_qposadr[self.mj.joint("mandible").id]
        self._vadr = self.mj.jnt_dofadr[self.mj.joint("mandible").id]
        self._crank_q = np.array([self.mj.jnt_qposadr[self.mj.joint(f"crank{i + 1}").id] for i in range(6)])
        self._crank_v = np.array([self.mj.jnt_dofadr[self.mj.joint(f"crank{i + 1}").id] for i in range(6)])
        self._coupler_q = np.array([self.mj.jnt_qposadr[self.mj.joint(f"coupler{i + 1}_{h}").id] for i in range(6) for h in "ab"])
        self._coupler_v = np.array([self.mj.jnt_dofadr[self.mj.joint(f"coupler{i + 1}_{h}").id] for i in range(6) for h in "ab"])
        self._actuators = np.array([self.mj.actuator(f"crank{i + 1}").id for i in range(6)])
        self._kinematics = native(kinematics_kernel(self.mechanism, ORIENTATION))
        self._margin = native(state_function(self.mechanism))
        self._bite = np.asarray(self.model.molar(self.side), float)
        self._ends = np.array([[self.mj.site(f"coupler{i + 1}_end").id, self.mj.site(f"M{i + 1}").id] for i in range(6)])
        self._condyles = np.array([self.mj.site(f"T_{s}").id for s in "LR"]) if self.model.has_hkp else np.zeros(0, int)

    @property
    def mechanism(self) -> str:
        return self.model.mechanism

    def kernels(self) -> list[KernelSpec]:
        return [kinematics_kernel(self.mechanism, ORIENTATION)]

    # ------------------------------------------------------------------ chewbot's state <-> MuJoCo's

    def set_state(self, q, dq) -> None:
        """Put MuJoCo's data at the state (q, dq) of the independent coordinates: every loop closed, every contact
        touching (the condyles' centres on their socket planes), velocities consistent with the constraints."""
        import mujoco

        out = dict(zip(KINEMATICS_OUTPUTS, self._kinematics(np.asarray(q, float), np.asarray(dq, float),
                                                             np.zeros(len(q)), self.model.vector())))
        X, dX = np.ravel(out["X"]), np.ravel(out["dX"])
        if not (np.all(np.isfinite(out["theta"])) and np.all(np.isfinite(dX))):
            raise SimulationError(f"the state q = {np.asarray(q).tolist()} is out of the robot's reach (no crank angles)")
        R = matrix_from_euler_angles(X[3:6])[0]
        omega = R_omega(X[3:6])[0] @ dX[3:6]  # in {S}
        d = self.data
        d.qpos[:] = self.mj.qpos0
        d.qvel[:] = 0
        d.qpos[self._qadr:self._qadr + 3] = X[:3]
        d.qpos[self._qadr + 3:self._qadr + 7] = _quat_from_matrix(R)
        d.qvel[self._vadr:self._vadr + 3] = dX[:3]
        d.qvel[self._vadr + 3:self._vadr + 6] = R.T @ omega  # MuJoCo: a free body's angular velocity in its own frame
        d.qpos[self._crank_q] = np.ravel(out["theta"])
        d.qvel[self._crank_v] = np.ravel(out["dtheta"])
        mujoco.mj_kinematics(self.mj, d)
        for i in range(6):  # the universal joints' angles from the rods' directions
            body = self.mj.body(f"coupler{i + 1}").id
            S = d.xpos[body]
            frame = d.xmat[body].reshape(3, 3)  # the coupler's frame with both hinges at 0
            M = X[:3] + R @ self.model.M[i]
            u = frame.T @ (M - S) / np.linalg.norm(M - S)
            # the rod (local x) after the hinge a (local y) then b (its local z): (cos a cos b, sin b, -sin a cos b)
            d.qpos[self._coupler_q[2 * i]] = np.arctan2(-u[2], u[0])
            d.qpos[self._coupler_q[2 * i + 1]] = np.arcsin(np.clip(u[1], -1, 1))
        mujoco.mj_forward(self.mj, d)
        # the couplers' joint rates that keep the loops closed: J_c v_c = -J_o v_o over the equality rows
        rows = d.efc_type[:d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY
        J = d.efc_J[:d.nefc * self.mj.nv].reshape(d.nefc, self.mj.nv)[rows]
        v = d.qvel.copy()
        v[self._coupler_v] = 0
        d.qvel[self._coupler_v] = np.linalg.lstsq(J[:, self._coupler_v], -J @ v, rcond=None)[0]
        mujoco.mj_forward(self.mj, d)

    def read_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """q, dq (independent coordinates), theta, dtheta (MuJoCo's crank hinges) of MuJoCo's data."""
        d = self.data
        R = d.xmat[self._mandible].reshape(3, 3)
        pos = d.qpos[self._qadr:self._qadr + 3].copy()
        angles = euler_angles_from_matrix(R[None])[0]
        omega = R @ d.qvel[self._vadr + 3:self._vadr + 6]
        rates = np.linalg.solve(R_omega(angles)[0], omega)
        X, dX = np.concatenate([pos, angles]), np.concatenate([d.qvel[self._vadr:self._vadr + 3], rates])
        idx = [0, 1, 3, 4] if self.model.has_hkp else list(range(6))
        return X[idx], dX[idx], d.qpos[self._crank_q].copy(), d.qvel[self._crank_v].copy()

    def accelerations(self) -> np.ndarray:
        """ddq of the independent coordinates from MuJoCo's qacc (after ``mj_forward``)."""
        d = self.data
        R = d.xmat[self._mandible].reshape(3, 3)
        q, dq, _, _ = self.read_state()
        angles = euler_angles_from_matrix(R[None])
        omega = R @ d.qvel[self._vadr + 3:self._vadr + 6]
        rates = np.linalg.solve(R_omega(angles)[0], omega)
        omega_dot = R @ d.qacc[self._vadr + 3:self._vadr + 6]  # d/dt (R w_local) = R w_local_dot (w x w = 0)
        accel = np.linalg.solve(R_omega(angles)[0], omega_dot - R_omega_dot(angles, rates[None])[0] @ rates)
        ddX = np.concatenate([d.qacc[self._vadr:self._vadr + 3], accel])
        return ddX[[0, 1, 3, 4]] if self.model.has_hkp else ddX

    def normal_forces(self) -> np.ndarray:
        """N_L, N_R: the normal forces of MuJoCo's contacts (0 where a condyle is off its plane)."""
        import mujoco

        N = np.zeros(2)
        force = np.zeros(6)
        for j in range(self.data.ncon):
            c = self.data.contact[j]
            names = {self.mj.geom(c.geom1).name, self.mj.geom(c.geom2).name}
            mujoco.mj_contactForce(self.mj, self.data, j, force)
            N[0 if "condyle_L" in names else 1] += force[0]
        return N

    def _load(self, tau: np.ndarray, force: np.ndarray) -> None:
        """The torques on the motors and the bite force at the molar (force and moment about the mass centre)."""
        d = self.data
        d.ctrl[self._actuators] = tau
        R = d.xmat[self._mandible].reshape(3, 3)
        arm = d.xpos[self._mandible] + R @ self._bite - d.xipos[self._mandible]
        d.xfrc_applied[self._mandible, :3] = force
        d.xfrc_applied[self._mandible, 3:] = np.cross(arm, force)

    # ------------------------------------------------------------------ the plant's interface

    def initial(self, t: float, q, dq) -> PlantState:
        self.set_state(q, dq)
        self._t = float(t)
        return self._state(t)

    def violations(self) -> tuple[float, float]:
        """MuJoCo's own constraint violations at its data (m): the largest gap of a loop (a coupler's end from its M_i)
        and the largest distance of a condyle's centre from its socket's plane (0 for the 6RSS)."""
        x = self.data.site_xpos
        loops = float(np.max(np.linalg.norm(x[self._ends[:, 0]] - x[self._ends[:, 1]], axis=1)))
        if not self.model.has_hkp:
            return loops, 0.0
        h = self.model.hkp
        T = x[self._condyles]
        return loops, float(np.max(np.abs(h.p1 * T[:, 0] + T[:, 2] + h.p2)) / np.hypot(h.p1, 1.0))

    def _state(self, t: float) -> PlantState:
        self._violations.append(self.violations())
        q, dq, theta, dtheta = self.read_state()
        margin = float(dict(zip(STATE_OUTPUTS, self._margin(q, dq, self.model.vector())))["margin"][0])
        return PlantState(t, q, dq, theta, dtheta, margin, MujocoState(self.data.qpos.copy(), self.data.qvel.copy()))

    def advance(self, state: PlantState, h: float, inputs: StageInputs) -> PlantState:
        """The state after h seconds under ``inputs(t0, dt)`` (W = torques and bite forces at the Radau stages of a step
        from t0 to t0 + dt; the torques held), in MuJoCo steps of the file's timestep. ``state`` must be the last one
        this plant returned."""
        import mujoco

        self.data.qpos[:], self.data.qvel[:] = state.internal.qpos, state.internal.qvel
        dt = self.mj.opt.timestep
        steps = max(1, int(round(h / dt)))
        if abs(steps * dt - h) > 1e-9 * max(h, 1.0):
            raise SimulationError(f"the MuJoCo plant steps {dt:g} s: the control interval {h:g} s is not a multiple of it")
        t = state.t
        tau, force = (PLANT_INPUTS.slices()[name] for name in ("tau", "F_B"))
        for _ in range(steps):
            W = inputs(t, dt)
            self._load(W[tau, 0], W[force] @ RADAU_A[-1])
            mujoco.mj_step(self.mj, self.data)
            t += dt
        if not np.all(np.isfinite(self.data.qpos)):
            raise SimulationError(f"MuJoCo's simulation diverged near t = {state.t:.6g} s")
        return self._state(state.t + h)

    def outputs(self, t: np.ndarray, q: np.ndarray, dq: np.ndarray, force: np.ndarray, internal: list) -> tuple[np.ndarray, dict]:
        """The bite force at the rows (the task's, given as ``force``) and no quantities of its own: the MuJoCo plant
        holds no food."""
        return force, {}

    def columns(self, quantities: dict) -> list[Column]:
        return []

    def drift(self, kinematics, rows: int) -> dict[str, np.ndarray]:
        """MuJoCo's own constraint violations at the first ``rows`` states (:meth:`violations`): chewbot's kinematics of
        q closes every constraint, MuJoCo's state need not."""
        d = np.asarray(self._violations)[:rows]
        return {"drift_chains": d[:, 0], **({"drift_hkp": d[:, 1]} if self.model.has_hkp else {})}

    def info(self, sim) -> dict:
        """run.json's ``simulation.plant`` of a MuJoCo simulation: the engine, its version and the solver settings read
        from the model."""
        import mujoco

        o = self.mj.opt
        return {"simulation": {"plant": {
            "engine": "mujoco", "mujoco_version": mujoco.__version__, "model": self.model.name, "file": self.model.source,
            "mjcf": "robot.xml", "friction": self.friction,
            "contact": "unilateral: a sphere on a plane per condyle (MuJoCo contact pairs), N_L, N_R >= 0" if self.model.has_hkp else None,
            "solver": {"timestep_s": float(o.timestep), "integrator": mujoco.mjtIntegrator(o.integrator).name,
                       "solver": mujoco.mjtSolver(o.solver).name, "iterations": int(o.iterations), "tolerance": float(o.tolerance),
                       "cone": mujoco.mjtCone(o.cone).name, "impratio": float(o.impratio), "noslip_iterations": int(o.noslip_iterations),
                       "equality_solref": self.mj.eq_solref[0].tolist(), "equality_solimp": self.mj.eq_solimp[0].tolist()},
            "residual": "residual column: chewbot's equations of motion at MuJoCo's accelerations and normal forces"}}}

    def files(self) -> dict[str, str]:
        return {"robot.xml": self.xml}

    def forward(self, q, dq, tau, force) -> Forward:
        """MuJoCo's accelerations and contact normal forces at states (q, dq) (N, n) under torques (N, 6) and bite
        forces (N, 3), each state put in MuJoCo by :meth:`set_state`; the residual is that of chewbot's equations of
        motion at MuJoCo's answer (N m), a measure of the engines' disagreement."""
        import mujoco

        q, dq, tau, force = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, tau, force))
        n = q.shape[0]
        ddq, N = np.zeros((n, n_coordinates(self.mechanism))), np.zeros((n, 2 if self.model.has_hkp else 0))
        for k in range(n):
            self.set_state(q[k], dq[k])
            self._load(tau[k], force[k])
            mujoco.mj_forward(self.mj, self.data)
            ddq[k] = self.accelerations()
            if self.model.has_hkp:
                N[k] = self.normal_forces()
        return Forward(ddq, N, plant_residual(self.model, q, dq, ddq, N, tau, force, self.side, self.friction))


def build(model: Model, friction: bool, side: str, food=None, write_mjcf=None, bolus: bool = False) -> MujocoPlant:
    """MuJoCo's plant (the engine table's builder) of the MJCF text ``write_mjcf(model, friction)``."""
    return MujocoPlant(model, write_mjcf(model, friction), friction=friction, side=side)
