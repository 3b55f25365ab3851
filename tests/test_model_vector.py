"""The parameter vector p: its layout against the parameter files, its symbolic view against the model, and
kernels evaluated for many models in one batched call."""

from __future__ import annotations

import tomllib

import casadi as ca
import numpy as np
import pytest
from support import default_kinematics, model

from chewbot.compiled.kernels import c_compiler, evaluate, native
from chewbot.dynamics.formulations.core6rss import torque_kernel
from chewbot.model.vector import BLOCKS, N_P, block_slice, parameter_index, parameter_names
from chewbot.model.symbolic import SymbolicModel
from chewbot.model.params import BUILTIN_MODELS, builtin_model_path, load_model


def _file_value(raw: dict, key: str):
    value = raw
    for part in key.split("."):
        value = value[part]
    return np.asarray(value, dtype=float)


@pytest.mark.parametrize("name", BUILTIN_MODELS)
def test_vector_holds_the_files_numbers_in_si(name):
    """Every block with a file key holds the file's numbers times the block's factor (read here from the TOML
    itself, not through the loader); R_C0 is the nearest rotation (printed to 4 digits); derived blocks follow
    from the loader's model."""
    m = load_model(name)
    raw = tomllib.loads(builtin_model_path(name).read_text())
    p = m.vector()
    assert p.shape == (N_P,) and not p.flags.writeable
    for b in BLOCKS:
        got = p[block_slice(b.name)]
        if b.key is None or b.key.startswith(("limits.theta_range", "contact.")):
            continue
        if b.absent is not None and b.key.split(".")[0] not in raw:  # an optional section the file leaves out
            assert got.tolist() == [b.absent], b.name
            continue
        want = _file_value(raw, b.key).ravel() * b.scale
        tol = 2e-4 if b.name == "R_C0" else 1e-15  # R_C0: the nearest rotation to a matrix printed to 4 digits
        assert np.abs(got - want).max() <= tol * max(np.abs(want).max(), 1), b.name
    assert np.array_equal(p[block_slice("coupler_mass")], m.coupler_mass)
    assert set(p[block_slice("branch")]) <= {-1.0, 1.0}
    # the optional keys the built-in files leave out: unbounded, no preload
    assert p[block_slice("limits.theta_range")].tolist() == [-np.inf, np.inf]
    assert p[parameter_index("contact.preload")] == 0.0


def test_names_and_indices():
    names = parameter_names()
    assert len(names) == N_P and len({n for n, _ in names}) == N_P
    m = model("target")
    p = m.vector()
    assert names[parameter_index("chains.G_mm[2][1]")] == ("G[2][1]", "m")
    assert p[parameter_index("chains.G_mm[2][1]")] == m.G[1, 0]
    assert p[parameter_index("crank_length[3]")] == p[parameter_index("chains.crank_length_mm[3]")] == m.crank_length[2]
    assert p[parameter_index("chains.R_C0[3][2][1]")] == m.R_C0[2][1, 0]  # row 2, column 1 of chain 3
    assert p[parameter_index("mandible_inertia[1][3]")] == m.mandible_inertia[0, 2]
    assert p[parameter_index("friction.hkp_coulomb")] == m.friction.hkp_coulomb
    assert p[parameter_index("gravity_m_per_s2")] == m.g
    for bad in ("chains.crank_length_mm[7]", "hkp.T_R_mm[1]", "branch", "crank_length"):
        with pytest.raises(KeyError, match="names no entry"):
            parameter_index(bad)


@pytest.mark.parametrize("name", ["target", "6rss"])
def test_symbolic_view_mirrors_the_model(name):
    """SymbolicModel.of(model): every attribute a graph builder reads equals the model's (T_R as the mirror of
    T_L, the planes' normal, the working branches of the NumPy inverse kinematics)."""
    from chewbot.model.chains import working_branches as branches

    m = model(name)
    s = SymbolicModel.of(m)

    def num(x):
        return np.array(ca.evalf(x), dtype=float).squeeze()

    for i in range(6):
        assert np.array_equal(num(s.G[i]), m.G[i]) and np.array_equal(num(s.M[i]), m.M[i])
        assert np.array_equal(num(s.R_C0[i]), m.R_C0[i])
    for attr in ("crank_length", "coupler_length", "crank_inertia", "crank_mass", "coupler_mass", "mandible_inertia",
                 "incisor", "molar_left", "molar_right"):
        assert np.array_equal(num(getattr(s, attr)), getattr(m, attr)), attr
    for attr in ("p1", "p2", "T_L", "T_R", "x_range", "y_left", "y_right", "normal"):
        assert np.allclose(num(getattr(s.hkp, attr)), getattr(m.hkp, attr), rtol=1e-15, atol=0), attr
    assert num(s.g) == m.g and num(s.mandible_mass) == m.mandible_mass
    assert num(s.friction.actuator_arm) == m.friction.actuator_arm and num(s.limits.torque) == m.limits.torque
    assert np.array_equal(num(s.branch), branches(m))
    assert s.has_hkp == m.has_hkp and np.array_equal(num(s.molar("right")), m.molar_right)


def _models():
    """Three target models that differ in the coupler density, a crank length and the bite points."""
    return [load_model("target"), load_model("target", {"couplers.density_g_per_mm3": 2.7e-3}),
            load_model("target", {"chains.crank_length_mm[3]": 13.0, "points.molar_left_mm[2]": 20.0})]


@pytest.mark.parametrize("compiled", [True, False], ids=["native", "virtual-machine"])
def test_one_batch_evaluates_a_model_per_sample(compiled):
    """A kernel called with p as (N, n_p), a model per sample (a sweep's batch), equals the same kernel called
    model by model with p as (n_p,) (stride 0): the same arithmetic, so equal to rounding."""
    if compiled and c_compiler() is None:
        pytest.skip("no C compiler: kernels run in CasADi's virtual machine")
    spec = torque_kernel("target")
    fn = native(spec) if compiled else spec.graph()
    kin = default_kinematics("target")
    rows = np.arange(2000, 2600, 50)
    q, dq, ddq = (x[rows] for x in kin.euler_angle_state())
    models = _models()
    which = np.arange(rows.size) % len(models)
    P = np.array([models[k].vector() for k in which])  # (N, n_p)
    B = np.array([models[k].molar_left for k in which])
    batch = evaluate(fn, q, dq, ddq, B, kin.force[rows], P)
    for k, m in enumerate(models):
        sel = which == k
        alone = evaluate(fn, q[sel], dq[sel], ddq[sel], m.molar_left, kin.force[rows][sel], m.vector())
        for a, b in zip(batch, alone):
            assert np.abs(a[sel] - b).max() <= 1e-15 * np.abs(b).max()
    tau = batch[0]
    assert np.abs(tau[which == 1] - evaluate(fn, q, dq, ddq, models[0].molar_left, kin.force[rows], models[0].vector())[0][which == 1]).max() > 1e-6


def test_parametric_kernel_equals_the_folded_one():
    """The kernel with p as an input, evaluated at a model's p, equals the same kernel with that model's numbers
    folded in as constants (what chewbot export-c writes)."""
    m = _models()[2]
    kin = default_kinematics("target")
    q, dq, ddq = kin.euler_angle_state()
    folded = evaluate(torque_kernel("target").folded(m).graph(), q, dq, ddq, m.molar_left, kin.force)
    param = evaluate(native(torque_kernel("target")), q, dq, ddq, m.molar_left, kin.force, m.vector())
    assert "p" not in torque_kernel("target").folded(m).graph().name_in()
    for a, b in zip(folded, param):
        # constant folding reorders a few operations: rounding only
        assert np.abs(a - b).max() <= 1e-12 * np.abs(a).max()
