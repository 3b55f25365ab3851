"""The in-loop kernels (chewbot.export.realtime.loop_kernel): one sample at a time from preallocated arrays, against the
batch API on the same samples of the default task; and the arrays are the kernel's own, written in place."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from support import default_kinematics, model

from chewbot.analysis.coupling import coupling
from chewbot.compiled.kernels import FLAGS, c_compiler
from chewbot.dynamics.registry import inverse_dynamics
from chewbot.dynamics.g1 import g1_distribution
from chewbot.export.realtime import loop_kernel

pytestmark = pytest.mark.skipif(c_compiler() is None, reason="the in-loop kernels need a C compiler")

# Samples at rest, in the opening, inside a bite-force burst and at the end of the task.
SAMPLES = (0, 1100, 2000, 2150, 3333, 5000)
# The in-loop kernel and the batch route evaluate the same expressions, but compiled apart (the model's numbers
# folded in or not, other flags): the operations may be reordered, so equal to rounding, relative to the peak.
ROUNDING = 1e-12


def _rel(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(b)).max()


@functools.cache
def batch(name: str, kind: str):
    m = model(name)
    if kind == "g1":
        out = g1_distribution(m, default_kinematics(name, "left", "euler-parameters"))
        return {"tau": out["tau"], "N": out["N"]}  # grad and step are rounding-level at the answer: nothing to compare
    kin = default_kinematics(name)
    if kind == "coupling":
        c = coupling(m, kin)
        return {"M_A": c.M_A, "MCI": c.MCI}
    return {"tau": inverse_dynamics(m, kin, "6rss-core").tau}


def _fill(k, kin, i: int) -> None:
    """Write sample ``i`` of ``kin`` into the kernel's input arrays, as a control loop does."""
    q, dq, ddq = (x[i] for x in kin.euler_angle_state()) if kin.orientation == "euler-angles" else (kin.q[i], kin.dq[i], kin.ddq[i])
    values = {"theta": kin.theta[i], "q": q, "dq": dq, "ddq": ddq, "F_B": kin.force[i]}
    for name, array in k.inputs.items():
        if name in values:
            array[:] = values[name][: array.size]


# Every kind with p as an input and the batch API's compiler flags (the batch API's own compiled kernel, from the
# cache: the test costs no compilation), and one kind as a controller uses it: the model folded in, -O3.
CASES = [(name, kind, False) for name, kind in (("target", "tau"), ("6rss", "tau"), ("target", "coupling"),
                                                 ("6rss", "coupling"), ("target", "g1"))] + [("target", "tau", True)]


@pytest.mark.parametrize("name, kind, folded", CASES, ids=lambda v: {True: "folded", False: "p-input"}.get(v, v) if isinstance(v, bool) else v)
def test_in_loop_calls_equal_the_batch_api(name, kind, folded):
    m = model(name)
    k = loop_kernel(m, kind, folded=folded) if folded else loop_kernel(m, kind, folded=False, flags=FLAGS)
    kin = default_kinematics(name, "left", "euler-parameters" if kind == "g1" else "euler-angles")
    whole = batch(name, kind)
    arrays = {key: id(a) for key, a in {**k.inputs, **k.outputs}.items()}
    for i in SAMPLES:
        _fill(k, kin, i)
        k()
        for out, values in whole.items():
            assert np.abs(k.outputs[out] - values[i]).max() <= ROUNDING * np.abs(values).max(), (out, i)
    # the same arrays throughout: nothing was reallocated
    assert {key: id(a) for key, a in {**k.inputs, **k.outputs}.items()} == arrays


def test_the_dynamics_kernel_gives_the_torques_and_the_terms():
    """kind "dynamics" (the torques with J_theta1, M_f, C_f, G_f, Q_B) gives the torques of kind "tau"."""
    m = model("6rss")
    kin = default_kinematics("6rss")
    k, tau = (loop_kernel(m, kind, folded=False, flags=FLAGS) for kind in ("dynamics", "tau"))
    for i in SAMPLES:
        for kernel in (k, tau):
            _fill(kernel, kin, i)
            kernel()
        assert _rel(k.tau, tau.tau) <= ROUNDING


def test_the_arrays_are_written_in_place_not_replaced():
    k = loop_kernel(model("target"), "tau", folded=False, flags=FLAGS)
    with pytest.raises(AttributeError, match=r"q\[:\] = "):
        k.q = np.zeros(6)
    out = k.tau
    k()
    assert k.tau is out  # the output array is overwritten by each call, not a new one
