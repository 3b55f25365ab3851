"""Parameter files: the built-in models load with the papers' numbers in SI, and each bad file names its key."""

from __future__ import annotations

import numpy as np
import pytest

from chewbot.errors import ParameterError
from chewbot.model.params import BUILTIN_MODELS, builtin_model_path, load_model


@pytest.mark.parametrize("name", BUILTIN_MODELS)
def test_builtin_models_load(name):
    m = load_model(name)
    assert m.mechanism == ("target" if name.startswith("target") else "6rss")
    assert len(m.sha256) == 64
    # R_C0 is the nearest rotation to the printed 4-digit matrices: orthonormal to rounding (1e-12)
    for r in m.R_C0:
        assert np.abs(r.T @ r - np.eye(3)).max() < 1e-12
        assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-12)


def test_si_conversion_against_model_md():
    m = load_model("target")
    # MODEL.md: m_EE = 340.22 g, coupler masses 4.466 g (33 mm) and 7.037 g (52 mm) at 7.8e-3 g/mm^3
    assert m.mandible_mass == pytest.approx(0.34022, rel=1e-12)
    assert m.coupler_mass[0] == pytest.approx(4.466e-3, abs=5e-7)  # printed to 4 digits
    assert m.coupler_mass[4] == pytest.approx(7.037e-3, abs=5e-7)
    assert m.G[2] == pytest.approx([0.04015, -0.05824, -0.03624], abs=1e-15)
    assert m.mandible_inertia[0, 0] == pytest.approx(820091.15e-9, rel=1e-12)  # g mm^2 -> kg m^2
    assert m.hkp.p2 == pytest.approx(-0.013215, rel=1e-12)
    printed = load_model("target-as-printed")
    assert printed.coupler_mass[0] == pytest.approx(1000 * m.coupler_mass[0], rel=1e-12)


def _variant(tmp_path, old: str, new: str):
    """The target's file with one textual change, written to tmp_path."""
    text = builtin_model_path("target").read_text()
    assert text.count(old) == 1, old
    path = tmp_path / "variant.toml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize(
    "old, new, key, reason",
    [
        ("[mandible]\n", "[mandible]\nfoo_mm = 1.0\n", "mandible.foo_mm", "unknown key"),
        ("area_mm2 = 17.3494\n", "", "couplers.area_mm2", "missing key"),
        ("[[ 0.8541,  0.5201, 0.0   ], [-0.5201,", "[[ 0.9541,  0.5201, 0.0   ], [-0.5201,", "chains.R_C0[1]", "not a rotation"),
        ("mass_g = 340.22", "mass_g = -340.22", "mandible.mass_g", "greater than 0"),
        ("[820091.15,", "[-820091.15,", "mandible.inertia_g_mm2", "not positive definite"),
        ("crank_length_mm = [10.0,", "crank_length_mm = [12.0,", "chains.crank_length_mm[1]", "disagrees"),
        ("coupler_length_mm = [33.0,", "coupler_length_mm = [30.0,", "chains.coupler_length_mm[1]", "disagrees"),
    ],
)
def test_bad_parameter_file_names_file_and_key(tmp_path, old, new, key, reason):
    path = _variant(tmp_path, old, new)
    with pytest.raises(ParameterError) as err:
        load_model(path)
    msg = str(err.value)
    assert str(path) in msg and f"'{key}'" in msg and reason in msg, msg


def test_missing_and_unknown_model(tmp_path):
    with pytest.raises(ParameterError, match="no such parameter file"):
        load_model(tmp_path / "absent.toml")
    with pytest.raises(ParameterError, match="unknown model"):
        load_model("no-such-model")
