"""The robot as a MuJoCo model (MJCF): the same bodies, masses, inertias, loops and contacts as chewbot's plant, for
an independent engine to simulate.

The bodies (SI units, the model's numbers; {S} = MuJoCo's world frame, gravity along -Z_S):

| body | parent, joint | inertial | from the model |
|---|---|---|---|
| ``mandible`` | world, free joint ``mandible`` at O_M | mass m_EE at O_M, ``fullinertia`` about O_M in {M} | ``mandible_mass``, ``mandible_inertia`` |
| ``crankI`` | world at G_i, frame R_C0,i, hinge ``crankI`` about its z (the shaft) | mass at G_i, diagonal (I, I, I); the hinge's ``armature`` J_r N^2 with a drive | ``crank_mass``, ``crank_inertia`` (axial), ``drive`` (the rotor reflected to the crank) |
| ``couplerI`` | ``crankI`` at S_i, hinges ``couplerI_a`` (local y), ``couplerI_b`` (local z) | m_i at the rod's middle, (0, m L^2/12, m L^2/12) + :data:`SPIN_INERTIA` | ``coupler_mass``, ``coupler_length`` |

- **Cranks.** Only the axial inertia of a crank turning about a fixed shaft enters the dynamics (its mass centre on
  the shaft: its weight does no work); the two inertias across the shaft, which MuJoCo needs positive, are set equal
  to the axial one and do nothing.
- **Couplers.** The model's coupler is a thin uniform rod with no inertia about its own axis (MODEL.md): its spin is
  an idle freedom. Here each rod hangs from its crank tip S_i on a universal joint (two hinges across the rod) and is
  tied to the mandible at M_i by a ball joint closing the loop (``connect`` equality between the sites
  ``couplerI_end`` and ``MI``): the universal joint removes
  the spin, so the rod's inertia about its axis is never excited and is given :data:`SPIN_INERTIA` (MuJoCo refuses a
  zero) only. A coupler of zero mass (a model with density 0) is written as a rod of :data:`MASSLESS_COUPLER` kg.
- **Loops.** Six ``connect`` constraints (the coupler's far end on M_i), stiff by :data:`EQUALITY_SOLREF` and
  :data:`SOLIMP`.
- **Condyles (target).** A sphere of :data:`CONDYLE_RADIUS` at T_L and T_R on the mandible, each in one explicit
  contact pair with a plane parallel to its socket's plane p1 x + z + p2 = 0, one radius below, so that the ball's
  centre lies on the socket's plane when the two touch. The contact is unilateral (the plane pushes, never pulls:
  chewbot's ``--contact unilateral`` reading of the HKP) and frictionless without friction (``condim`` 1). The
  sockets' x and y bounds are not modelled (the planes are unbounded); the MuJoCo plant stops the robot where a
  condyle leaves its socket, as chewbot's plant does.
- **Friction** (``friction=True``). At the condyles MuJoCo's Coulomb cone (``condim`` 3, elliptic, coefficient mu_c
  = ``friction.hkp_coulomb``) replaces the HKP Coulomb term mu_c abs(N) (the same law where the ball slides; MuJoCo
  also sticks, where chewbot's smoothed law creeps); the HKP viscous term mu_v v_T has no MuJoCo counterpart and is
  left out. At the cranks the viscous term mu_v,i theta_dot is the hinge's ``damping`` (exact); the Coulomb term
  R_i mu_c,i abs(F_G,i) grows with the bearing load, which MuJoCo's constant ``frictionloss`` cannot follow: left
  out. With friction the two engines therefore differ by these terms.
- **Actuators.** One ``motor`` per crank, named ``crank1`` ... ``crank6``, on its hinge, gear 1: the control is the
  torque in N m about the shaft (positive: increasing theta_i), unlimited (the simulator saturates).
- **Sites.** ``O_M`` at the mandible's origin, ``incisor``, ``molar_left``, ``molar_right``, ``T_L``, ``T_R``.

Solver settings (``<option>``), chosen to make the constraints stiff and the integration accurate at a 1 kHz control
rate: :data:`TIMESTEP`, the 4th-order Runge-Kutta integrator, the Newton solver to a tolerance of 1e-12 with the
dense Jacobian, ``solref`` with a time constant of two steps (the smallest MuJoCo accepts) and damping ratio 1,
``solimp`` with an impedance of 0.9999 at every violation (the constraint force then takes 99.99 % of the
constraint's reference acceleration); ``impratio`` 10 and the elliptic cone, so that friction is as stiff as the
normal direction; ``noslip`` iterations where friction is on.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from chewbot.files import marker_line
from chewbot.model import Model

TIMESTEP = 1e-4  # s: 10 steps per control tick at 1 kHz
EQUALITY_SOLREF = (2 * TIMESTEP, 1.0)  # time constant (s), damping ratio: the stiffest MuJoCo allows at TIMESTEP
CONTACT_SOLREF = (2 * TIMESTEP, 1.0)
SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)  # impedance at zero and large violation, width (m), midpoint, power
# m: the planes sit this much higher, so that a condyle whose centre is on its socket's plane to rounding (1e-17 m) is
# in contact (MuJoCo drops a contact at a distance of exactly 0); its reference acceleration k * 1e-12 m is ~1e-5 m/s^2
CONTACT_OVERLAP = 1e-12
CONDYLE_RADIUS = 0.004  # m, the condyle's ball (assumed: the papers give only the centre's plane)
SPIN_INERTIA = 1e-12  # kg m^2, a rod's inertia about its own axis (never excited: the universal joint holds it)
MASSLESS_COUPLER = 1e-9  # kg
NOSLIP_ITERATIONS = 10


def _vec(x) -> str:
    return " ".join(f"{float(v):.17g}" for v in np.ravel(x))


def _quat(R: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def _frame_along(d: np.ndarray) -> np.ndarray:
    """A rotation whose x axis is along d."""
    x = d / np.linalg.norm(d)
    helper = np.eye(3)[np.argmin(np.abs(x))]
    y = np.cross(helper, x)
    y /= np.linalg.norm(y)
    return np.column_stack([x, y, np.cross(x, y)])


def coupler_frames(model: Model) -> np.ndarray:
    """The reference frames of the couplers in their cranks' frames (6, 3, 3): x along S_i M_i at the home pose with
    theta = 0 (the rod then lies along its local x, and the universal joint's angles are zero)."""
    S0 = model.G + model.crank_length[:, None] * model.R_C0[:, :, 0]
    d = model.M - S0  # {M} = {S} at home
    return np.stack([_frame_along(model.R_C0[i].T @ d[i]) for i in range(6)])


def crank_inertia_diagonal(model: Model, i: int) -> np.ndarray:
    """The crank's diagonal inertia as written: the axial one on all three axes (only the axial one acts)."""
    return np.full(3, model.crank_inertia[i])


def coupler_inertia_diagonal(model: Model, i: int) -> tuple[float, np.ndarray]:
    """The coupler's mass and diagonal inertia about its middle, rod along x."""
    m = max(float(model.coupler_mass[i]), MASSLESS_COUPLER)
    across = m * model.coupler_length[i] ** 2 / 12
    return m, np.array([SPIN_INERTIA, across, across])


def plane_pose(model: Model, side: str) -> tuple[np.ndarray, np.ndarray]:
    """A point and the unit normal of the contact plane under the condyle of ``side`` (``"L"`` or ``"R"``): the socket's
    plane lowered by :data:`CONDYLE_RADIUS` less :data:`CONTACT_OVERLAP`; the point is under the condyle's centre at home."""
    n = model.hkp.normal
    T = model.hkp.T_L if side == "L" else model.hkp.T_R
    h = model.hkp
    distance = (h.p1 * T[0] + T[2] + h.p2) / np.hypot(h.p1, 1.0)  # of T (home) from the socket's plane, along n
    return T - (distance + CONDYLE_RADIUS - CONTACT_OVERLAP) * n, n


def mjcf(model: Model, friction: bool = True) -> str:
    """The MJCF text of ``model`` (the module's docstring says what is written and how), its first line chewbot's
    marker (:func:`chewbot.files.marker_line`)."""
    root = ET.Element("mujoco", model=f"chewbot {model.name}")
    ET.SubElement(root, "compiler", angle="radian", inertiafromgeom="false", autolimits="true")
    option = ET.SubElement(root, "option", timestep=f"{TIMESTEP:g}", gravity=_vec([0, 0, -model.g]), integrator="RK4",
                           solver="Newton", iterations="200", tolerance="1e-12", ls_iterations="50", jacobian="dense",
                           cone="elliptic", impratio="10", noslip_iterations=str(NOSLIP_ITERATIONS if friction else 0))
    ET.SubElement(option, "flag", warmstart="enable")
    default = ET.SubElement(root, "default")
    ET.SubElement(default, "geom", contype="0", conaffinity="0", group="1", rgba="0.6 0.6 0.7 1")
    ET.SubElement(default, "equality", solref=_vec(EQUALITY_SOLREF), solimp=_vec(SOLIMP))
    world = ET.SubElement(root, "worldbody")
    if model.has_hkp:
        for side in ("L", "R"):
            point, normal = plane_pose(model, side)
            ET.SubElement(world, "geom", name=f"socket_{side}", type="plane", size="0.02 0.02 0.001", pos=_vec(point),
                          zaxis=_vec(normal), group="0", rgba="0.8 0.7 0.6 0.5")

    mandible = ET.SubElement(world, "body", name="mandible", pos="0 0 0")
    ET.SubElement(mandible, "freejoint", name="mandible")
    I = model.mandible_inertia
    ET.SubElement(mandible, "inertial", pos="0 0 0", mass=f"{model.mandible_mass:.17g}",
                  fullinertia=_vec([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]))
    ET.SubElement(mandible, "site", name="O_M", pos="0 0 0", size="0.002")
    for i in range(6):
        ET.SubElement(mandible, "site", name=f"M{i + 1}", pos=_vec(model.M[i]), size="0.001")
    for name, point in (("incisor", model.incisor), ("molar_left", model.molar_left), ("molar_right", model.molar_right)):
        ET.SubElement(mandible, "site", name=name, pos=_vec(point), size="0.002")
    ET.SubElement(mandible, "geom", type="capsule", fromto=_vec([*model.molar_left, *model.incisor]), size="0.003")
    ET.SubElement(mandible, "geom", type="capsule", fromto=_vec([*model.molar_right, *model.incisor]), size="0.003")
    if model.has_hkp:
        for side, T in (("L", model.hkp.T_L), ("R", model.hkp.T_R)):
            ET.SubElement(mandible, "site", name=f"T_{side}", pos=_vec(T), size="0.001")
            ET.SubElement(mandible, "geom", name=f"condyle_{side}", type="sphere", pos=_vec(T), size=f"{CONDYLE_RADIUS:g}")

    frames = coupler_frames(model)
    for i in range(6):
        k = i + 1
        crank = ET.SubElement(world, "body", name=f"crank{k}", pos=_vec(model.G[i]), quat=_vec(_quat(model.R_C0[i])))
        joint = ET.SubElement(crank, "joint", name=f"crank{k}", type="hinge", axis="0 0 1",
                              damping=f"{model.friction.actuator_viscous if friction else 0.0:.17g}")
        if model.drive is not None:
            joint.set("armature", f"{model.drive.reflected_inertia:.17g}")
        ET.SubElement(crank, "inertial", pos="0 0 0", mass=f"{max(model.crank_mass[i], MASSLESS_COUPLER):.17g}",
                      diaginertia=_vec(crank_inertia_diagonal(model, i)))
        ET.SubElement(crank, "geom", type="capsule", fromto=_vec([0, 0, 0, model.crank_length[i], 0, 0]), size="0.002")
        coupler = ET.SubElement(crank, "body", name=f"coupler{k}", pos=_vec([model.crank_length[i], 0, 0]),
                                quat=_vec(_quat(frames[i])))
        ET.SubElement(coupler, "joint", name=f"coupler{k}_a", type="hinge", axis="0 1 0")
        ET.SubElement(coupler, "joint", name=f"coupler{k}_b", type="hinge", axis="0 0 1")
        mass, inertia = coupler_inertia_diagonal(model, i)
        L = model.coupler_length[i]
        ET.SubElement(coupler, "inertial", pos=_vec([L / 2, 0, 0]), mass=f"{mass:.17g}", diaginertia=_vec(inertia))
        ET.SubElement(coupler, "geom", type="capsule", fromto=_vec([0, 0, 0, L, 0, 0]), size="0.0015")
        ET.SubElement(coupler, "site", name=f"coupler{k}_end", pos=_vec([L, 0, 0]), size="0.001")

    if model.has_hkp:
        contact = ET.SubElement(root, "contact")
        for side in ("L", "R"):
            attrs = {"geom1": f"condyle_{side}", "geom2": f"socket_{side}", "solref": _vec(CONTACT_SOLREF), "solimp": _vec(SOLIMP)}
            if friction:
                mu = model.friction.hkp_coulomb
                attrs.update(condim="3", friction=_vec([mu, mu, 0, 0, 0]))
            else:
                attrs.update(condim="1")
            ET.SubElement(contact, "pair", name=f"hkp_{side}", **attrs)
    equality = ET.SubElement(root, "equality")
    for i in range(6):
        ET.SubElement(equality, "connect", name=f"loop{i + 1}", site1=f"coupler{i + 1}_end", site2=f"M{i + 1}")
    actuator = ET.SubElement(root, "actuator")
    for i in range(6):
        ET.SubElement(actuator, "motor", name=f"crank{i + 1}", joint=f"crank{i + 1}", gear="1")
    ET.indent(root)
    header = marker_line("<!--", f"chewbot export-model: the {model.name} model ({model.mechanism}) as MJCF, SI units, "
                                  f"friction {'on' if friction else 'off'}") + "\n"
    return header + ET.tostring(root, encoding="unicode") + "\n"


def write_mjcf(model: Model, path, friction: bool = True, force: bool = False, inputs=()) -> None:
    """Write :func:`mjcf` to ``path`` whole (:func:`chewbot.files.atomic_file`: never over a file chewbot did not
    write, over one it wrote only with ``force``)."""
    from chewbot.files import atomic_file

    with atomic_file(path, force, inputs) as tmp:
        tmp.write_text(mjcf(model, friction), encoding="utf-8")
