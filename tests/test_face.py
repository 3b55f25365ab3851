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

H0 = 10e-3  # m: the sample's top, where the slide is counted from
SLIDE = 1e-3  # m


@pytest.fixture(scope="module")
def path():
    """A 10 mm sample's stroke at 1 mm/s: from 1 mm above its top to 5 mm into it (gaps 11 to 5 mm)."""
    model = load_model("target")
    t = np.linspace(0.0, 6.0, 3001)
    g = 11e-3 - 1e-3 * t
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
    Beside it the tilt with the bite point held still, the path before this one: at 5 mm into the sample (gap 5 mm)
    the path tilts 2.5 degrees instead of 3.2, at the sample's top none instead of 6.4."""
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
    for depth in (1.5e-3, 3e-3, 5e-3):
        k = int(np.argmin(np.abs(g - (H0 - depth))))
        used = float(np.linalg.norm(G["point"][k, :2] - P0[:2]))
        sol = solver(x0=task.q[k], p=[g[k], used], lbg=[0, -np.inf], ubg=[0, 0])
        assert solver.stats()["success"]
        least = np.degrees(np.arccos(1 - float(sol["f"])))
        assert np.degrees(G["tilt"][k]) == pytest.approx(least, abs=1e-6), depth
    held = gap(model, "left", molar_path_task(model, "left", t, g, np.zeros(t.size), np.zeros(t.size)).q)["tilt"]
    deepest = int(np.argmin(np.abs(g - 5e-3)))
    assert np.degrees(G["tilt"][deepest]) < np.degrees(held[deepest]) - 0.5
    assert np.degrees(held[top]) > 6.0 and np.degrees(G["tilt"][top]) < 1e-6


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
