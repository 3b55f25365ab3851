"""The texture test's faces: the path that keeps the lower tooth's face as parallel as a slide bound allows, held
against an independent per-depth optimisation (IPOPT); the food's law over the tilted face in the plant, against the
face's integral summed over a grid; a crushed sample's springiness = r over a tilted face."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from chewbot.compiled.cache import folded
from chewbot.food.geometry import face_path_task, gap, molar_path_task
from chewbot.food.law import food_from_dict
from chewbot.food.tpa import Protocol, ideal_test
from chewbot.kinematics.symbolic import symbolic
from chewbot.model.params import load_model

H0 = 5e-3  # m: the sample's top, where the slide is counted from (a condyle stays 2.5 mm behind its socket's cap)
SLIDE = 1e-3  # m


@pytest.fixture(scope="module")
def path():
    """A 5 mm sample's stroke at 1 mm/s: from 1 mm above its top to 3.5 mm into it (gaps 6 to 1.5 mm)."""
    model = load_model("target")
    t = np.linspace(0.0, 4.5, 2251)
    g = 6e-3 - 1e-3 * t
    task = face_path_task(model, "left", t, g, np.full(t.size, -1e-3), np.zeros(t.size), H0, SLIDE)
    return model, t, g, task, gap(model, "left", task.q, task.dq)


def test_the_path_holds_the_gap_and_the_slide_bound(path):
    """The bite point at its gap along the stroke (Newton's tolerance, 1e-12 m, with margin) and its rate (exact); its
    horizontal slide from the sample's top below the bound; the face parallel while the free slide v is well inside
    the bound: over the first 0.7 mm of the stroke (|v| < 0.64 L) the smooth bound falls short of v by v (|v| / L)^8 / 8
    < 2.3 um, which the face makes up by tilting 0.64 deg per mm: below 0.002 deg; the rates of the coordinates the derivatives of their positions (central
    differences over 2 ms: O(h^2) of ~1e-3 rad/s^3 terms, below 1e-7 rad/s)."""
    model, t, g, task, G = path
    assert np.abs(G["gap"] - g).max() < 1e-10 and np.abs(G["rate"] + 1e-3).max() < 1e-12
    top = int(np.argmin(np.abs(g - H0)))
    slide = np.linalg.norm(G["point"][:, :2] - G["point"][top, :2], axis=1)
    assert slide.max() < SLIDE
    early = (g <= H0) & (g >= H0 - 0.7e-3)
    assert np.degrees(G["tilt"][early]).max() < 0.002
    assert np.abs(np.gradient(task.q, t, axis=0) - task.dq)[2:-2].max() < 1e-7
    assert np.abs(np.gradient(task.dq, t, axis=0) - task.ddq)[2:-2].max() < 1e-6


def test_the_path_has_the_least_tilt_for_its_slide(path):
    """At depths beyond the bound, the path's tilt is the least any pose of the four coordinates reaches with the
    bite point at that gap and within the path's own slide of where it was at the sample's top: an independent
    optimisation by IPOPT (any direction of slide, alpha free; its constraints scaled by the bound, tolerances 1e-12),
    to 1e-6 deg (they agree to 1e-7).
    Beside it the tilt with the bite point held still, the path before this one: at half the sample's height the
    path tilts less (0.9 degrees instead of 1.6), at the sample's top not at all instead of 3.2."""
    model, t, g, task, G = path
    s = symbolic(folded(model), "euler-angles")
    B = s.point(ca.DM(np.asarray(model.molar("left"), float)))
    top = int(np.argmin(np.abs(g - H0)))
    P0 = G["point"][top]
    z_home = float(np.asarray(model.molar("left"), float)[2])
    gk, bound = ca.SX.sym("g"), ca.SX.sym("L")
    nlp = {"x": s.q, "p": ca.vertcat(gk, bound), "f": 1 - s.R[2, 2],
           "g": ca.vertcat((B[2] - (z_home - gk)) / bound, ca.sumsqr(B[:2] - P0[:2]) / bound**2 - 1)}
    solver = ca.nlpsol("least_tilt", "ipopt", nlp, {"ipopt.print_level": 0, "print_time": False, "ipopt.tol": 1e-12,
                                                     "ipopt.constr_viol_tol": 1e-12, "ipopt.sb": "yes"})
    for depth in (1.5e-3, 2.5e-3, 3.5e-3):
        k = int(np.argmin(np.abs(g - (H0 - depth))))
        used = float(np.linalg.norm(G["point"][k, :2] - P0[:2]))
        sol = solver(x0=task.q[k], p=[g[k], used], lbg=[0, -np.inf], ubg=[0, 0])
        assert solver.stats()["success"]
        least = np.degrees(np.arccos(1 - float(sol["f"])))
        assert np.degrees(G["tilt"][k]) == pytest.approx(least, abs=1e-6), depth
    held = gap(model, "left", molar_path_task(model, "left", t, g, np.zeros(t.size), np.zeros(t.size)).q)["tilt"]
    half = int(np.argmin(np.abs(g - H0 / 2)))
    assert np.degrees(G["tilt"][half]) < np.degrees(held[half]) - 0.5
    # at the top the smooth cap, 2.5 mm away, takes 0.3 mm log(1 + e^(-2.5 / 0.3)) = 0.07 um off the translation
    assert np.degrees(held[top]) > 3.0 and np.degrees(G["tilt"][top]) < 1e-4


@pytest.mark.parametrize("h0_mm", [10.0, 15.0])
def test_a_tall_samples_path_keeps_the_condyles_in_their_sockets(h0_mm):
    """A sample taller than the parallel face allows (a condyle reaches the front of its socket at a gap of about
    6.8 mm): from 1 mm above it to half its height, no condyle passes the front less its margin (to the cap's
    tolerance) and the kinematics solve inside the workspace. The 10 mm sample's face tilts at its top less than half
    as much as with the bite point held still (3.1 degrees instead of 6.4); the 15 mm one's, where the sockets bind
    throughout, within 0.5 degrees of it (9.8 instead of 9.5: the margin and the smooth cap)."""
    from chewbot.food.geometry import CAP_TOLERANCE, SOCKET_MARGIN
    from chewbot.kinematics.motion import solve_kinematics

    model = load_model("target")
    h0 = h0_mm * 1e-3
    t = np.linspace(0.0, h0_mm / 2 + 1, 601)
    g = h0 + 1e-3 - 1e-3 * t
    task = face_path_task(model, "left", t, g, np.full(t.size, -1e-3), np.zeros(t.size), h0, SLIDE)
    solve_kinematics(model, task)
    s = symbolic(folded(model), "euler-angles")
    T = ca.Function("T", [s.q], [ca.vertcat(s.point(model.hkp.T_L)[0], s.point(model.hkp.T_R)[0])])
    front = float(model.hkp.x_range[1]) - SOCKET_MARGIN
    assert np.asarray(T.map(t.size)(task.q.T)).max() <= front + CAP_TOLERANCE
    held = gap(model, "left", molar_path_task(model, "left", t, g, np.zeros(t.size), np.zeros(t.size)).q)["tilt"]
    top = int(np.argmin(np.abs(g - h0)))
    tilt = gap(model, "left", task.q)["tilt"][top]
    if h0_mm == 10.0:
        assert tilt < held[top] / 2
    else:
        assert abs(tilt - held[top]) < np.radians(0.5)


def test_a_crushed_sample_springs_back_by_r_over_a_tilted_face():
    """The ideal analyser with the faces at a constant 3 degrees: the crushed sample's set is a field over its face,
    each fibre keeping (1 - r) of its own deepest compression, so its top is inclined as the face was; the second bite
    meets it nearly parallel and its springiness is r (0.1) within 0.02 on a 13.5 mm face (0.098; 0.0998 with
    parallel faces). With a flat set at the centre's (1 - r) delta_max the tilted face would touch the crushed sample
    with its edge, a sin(3 deg) = 0.35 mm early, and read 0.151."""
    food = food_from_dict({"food": {"name": "crushing", "shape": "cylinder", "height_mm": 10.0, "diameter_mm": 13.5,
                                    "young_modulus_kPa": 7000.0, "fracture_strain": 0.1, "stiffness_after_fracture": 0.3,
                                    "recovery_after_fracture": 0.1, "tooth_friction": 0.3}})
    for tilt in (0.0, np.radians(3.0)):
        test = ideal_test(food, Protocol(), tilt=tilt)
        assert test.analysis.measures["springiness"] == pytest.approx(0.1, abs=0.02), tilt
        assert [e["event"] for e in test.events].count("fracture") == 1
