"""What the robot can play from home (chewbot.recordings.reach; chewbot check-model prints it), checked against the
kinematics' own functions and against random admissible poses, not against the search's own constraints."""

from __future__ import annotations

import numpy as np
from support import model, target_pose
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.kinematics.ik import transmission
from chewbot.recordings.reach import reach

MM, DEG = 1e-3, np.pi / 180
MARGIN = np.sin(np.radians(10.0))


pose = target_pose


def admissible(m, q, slack=0.0):
    """Condyles inside their sockets and every transmission angle >= 10 deg, from the kinematics' functions."""
    p, R = pose(m, q)
    h = m.hkp
    ok = np.ones(len(q), dtype=bool)
    for T, y in ((h.T_L, h.y_left), (h.T_R, h.y_right)):
        c = p + R @ T
        ok &= (c[:, 0] >= h.x_range[0] - slack) & (c[:, 0] <= h.x_range[1] + slack)
        ok &= (c[:, 1] >= y[0] - slack) & (c[:, 1] <= y[1] + slack)
    with np.errstate(invalid="ignore"):
        sin_mu = transmission(m, p, R)
    return ok & (np.nan_to_num(sin_mu, nan=-1.0) >= MARGIN - 1e-9).all(axis=1)


def test_each_coordinates_range_ends_where_the_pose_stops_being_admissible():
    """At each reported end the pose is admissible, and 1e-4 (mm or deg) beyond it is not; the ends of Y are the
    sockets' half width (3 mm: home in the middle of [69, 75] mm) and alpha's are symmetric (the robot is)."""
    m = model("target")
    r = reach(m)
    for j, name in enumerate(("X", "Y", "alpha", "beta")):
        unit = MM if r.units[name] == "mm" else DEG
        for end, sign in zip(r.coordinates[name], (-1, 1)):
            q = np.zeros((2, 4))
            q[0, j], q[1, j] = end * unit, (end + sign * 1e-4) * unit
            assert admissible(m, q).tolist() == [True, False], (name, end)
    assert np.allclose(r.coordinates["Y"], (-3.0, 3.0), atol=1e-6)
    assert np.isclose(-r.coordinates["alpha"][0], r.coordinates["alpha"][1], atol=1e-6)


def test_no_random_admissible_pose_moves_the_incisor_farther_than_reported():
    """Each reported extreme is reached by a pose that is admissible (by the kinematics' functions, 1e-8 mm of
    slack in the sockets) and carries the incisor that far; 2e5 random poses in a box around the workspace: none
    of the admissible ones carries the incisor beyond it (the search is local from home: a larger sampled value
    would expose a missed branch), and the best come within 30 % of it (the extremes are corners of the
    admissible set, which random poses approach slowly)."""
    m = model("target")
    r = reach(m)
    rng = np.random.default_rng(7)
    q = rng.uniform([-12e-3, -6e-3, -10 * DEG, -5 * DEG], [12e-3, 6e-3, 10 * DEG, 35 * DEG], size=(200_000, 4))
    q = q[admissible(m, q)]
    p, R = pose(m, q)
    moved = (p + R @ m.incisor - (pose(m, np.zeros((1, 4)))[0][0] + m.incisor)) / MM
    for label, d in (("forward (+x)", [1, 0, 0]), ("backward (-x)", [-1, 0, 0]), ("left (+y)", [0, 1, 0]),
                     ("right (-y)", [0, -1, 0]), ("up (+z)", [0, 0, 1]), ("down, opening (-z)", [0, 0, -1])):
        d = np.array(d, dtype=float)
        sampled = (moved @ d).max()
        assert sampled <= r.incisor[label] + 1e-6 and sampled >= 0.7 * r.incisor[label], (label, sampled, r.incisor[label])
        q_ext = r.incisor_poses[label][None]
        assert admissible(m, q_ext, slack=1e-11)[0]
        p_ext, R_ext = pose(m, q_ext)
        home = pose(m, np.zeros((1, 4)))[0][0] + m.incisor
        assert abs((p_ext[0] + R_ext[0] @ m.incisor - home) @ d / MM - r.incisor[label]) < 1e-6
    assert 35.0 < r.incisor["down, opening (-z)"] < 45.0  # what the robot's opening is known to be (about 40 mm)


def test_check_model_prints_the_reachable_ranges():
    result = CliRunner().invoke(app, ["check-model", "target", "--min-transmission", "5"])
    assert result.exit_code == 0, result.output
    assert ">= 5 deg" in result.output and "incisor I down, opening (-z)" in result.output
