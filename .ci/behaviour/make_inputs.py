"""Baseline inputs, generated once with chewbot at 7fc3973 (run from /work/before)."""
import sys
from pathlib import Path
import numpy as np
sys.path.insert(0, "tests")
import test_recordings as R
import test_identification as I
from conftest import default_kinematics, model  # noqa
from chewbot.task.incisor import incisor_path

out = Path(sys.argv[1])
m = R.model("target")
t, q = R.chewing()
force = np.zeros((len(t), 3)); force[:, 2] = -40 * np.sin(np.pi * t / t[-1]) ** 2
R.write_csv(out / "rec.csv", t, R.seen(*R.pose(m, q)), force=force)
R.registration(out)
mm, kin, tau = I.robot()
I.write_log(out / "log.csv", kin, tau, degrees=True)
kin = default_kinematics("target", "left", "euler-angles")
r = slice(1000, 1801, 8)
qq, dq, ddq = kin.q[r].copy(), kin.dq[r].copy(), kin.ddq[r].copy()
print("q shape", qq.shape)
qq[:, 2] = 0; dq[:, 2] = 0; ddq[:, 2] = 0
p, v, a = incisor_path(m, qq, dq, ddq)
tt = kin.t[r] - kin.t[r][0]
np.savetxt(out / "incisor.csv", np.column_stack([tt, p]), delimiter=",", header="t [s],Ix [m],Iy [m],Iz [m]", comments="", fmt="%.17g")
