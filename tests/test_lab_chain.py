"""The lab's chain end to end on the command line, the "robot" chewbot's plant with parameters off from the nominal
model (docs/bite_force.md, "The lab's chain"): chewbot excite -> chewbot simulate --task EXC.csv --plant-set ... ->
chewbot identify RUN/results.csv -> chewbot tpa --plant target --plant-set ... --model ID.toml, and the same test with
--model target. The commands take minutes (the excitation's design, the identification's least squares, two texture
tests), so the chain is ``slow``; the estimator and the interval it rests on are held in the suite by
tests/test_texture.py and tests/test_calibration.py."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from chewbot.cli import app

runner = CliRunner()
# The robot as the lab has it: each off from the nominal model by an amount a lab does not know (the files' units):
# the actuators' Coulomb coefficient +30 %, the condyles' -20 %, the third crank's inertia +15 %, the mandible's
# mass +2.9 % (the file's, given to identify, is wrong).
PLANT = ("friction.actuator_coulomb=0.065", "friction.hkp_coulomb=0.08", "cranks.inertia_g_mm2[3]=7600",
         "mandible.mass_g=350")
# The motors' torque constant +2 %: in the error budget, not in the chain, because chewbot identify does not fit the
# torque constant's scale yet (its residual then leaves the crank inertias unidentifiable).
TORQUE_CONSTANT = "drive.torque_constant_mNm_per_A=26.4"
TPA = ("--food", "cheddar", "--speed", "4", "--pause", "0.5", "--plant", "target")


def _run(args: list[str]) -> None:
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    folder = tmp_path_factory.mktemp("chain")
    plant = [a for key in PLANT for a in ("--plant-set", key)]
    _run(["excite", "--model", "target", "--duration", "4", "--out", str(folder / "EXC.csv")])
    _run(["simulate", "--task", str(folder / "EXC.csv"), *plant, "--friction", "on", "--method", "newton-euler",
          "--out", str(folder / "RUN")])
    _run(["identify", str(folder / "RUN" / "results.csv"), "--model", "target", "--out", str(folder / "ID.toml")])
    records = {}
    for label, model in (("calibrated", str(folder / "ID.toml")), ("nominal", "target")):
        _run(["tpa", *TPA, *plant, "--model", model, "--out", str(folder / label)])
        records[label] = json.loads((folder / label / "tpa.json").read_text())
    return records


def _hardness(record: dict) -> tuple[float, float, list[float]]:
    return record["plant"]["hardness_N"], record["estimated"]["hardness_N"], record["estimated_ci95"]["hardness_N"]


@pytest.mark.slow
def test_the_calibrated_model_gives_the_plants_hardness_within_its_interval(chain):
    """With the identified model the hardness is within 2 % of the plant's (the issue's bar) and the plant's lies inside
    the estimate's 95 % interval."""
    plant, estimated, (low, high) = _hardness(chain["calibrated"])
    assert estimated == pytest.approx(plant, rel=0.02)
    assert low <= plant <= high


@pytest.mark.slow
def test_the_nominal_model_is_further_off(chain):
    """With the nominal model (what the controller and the estimator would use uncalibrated) the hardness is further
    off than with the calibrated one (measured: +1.89 % against +1.76 %; the two frictions' errors partly cancel)."""
    plant, calibrated, _ = _hardness(chain["calibrated"])
    _, nominal, _ = _hardness(chain["nominal"])
    assert abs(nominal - plant) > abs(calibrated - plant)


@pytest.mark.slow
@pytest.mark.xfail(strict=False, reason=(
    "the nominal model's interval does not say it is worse: without an [uncertainty] section its torque error is "
    "pooled from the log's residuals, which a friction or mass error barely enters (it lies in the span of the "
    "force's columns); measured [6.468, 7.462] N, as wide as the calibrated model's [6.436, 7.498] N, missing the "
    "plant's 6.466 N by 2 mN only because the two intervals sit 30 mN apart (issue 27, item 4)"))
def test_the_nominal_model_s_interval_says_it_is_worse(chain):
    _, _, (low, high) = _hardness(chain["calibrated"])
    plant, _, (n_low, n_high) = _hardness(chain["nominal"])
    assert not n_low <= plant <= n_high or n_high - n_low > 1.5 * (high - low)


@pytest.mark.slow
def test_error_budget(chain):
    """docs/bite_force.md's error budget: the hardness error (%) of the nominal model's estimate on the plant equal to
    the model (the estimator's own error, the baseline), then on a plant with each parameter of PLANT off alone (and
    the torque constant's), then all of PLANT together with the nominal and with the calibrated model (the chain's),
    printed as the table's rows (``pytest tests/test_lab_chain.py -m slow -k budget -s``). A parameter's contribution
    is its row less the baseline; to first order the contributions add up to the combined error less the baseline:
    within a fifth of it plus 0.3 % of the hardness (the cross terms)."""
    from chewbot.simulation.texture import resolve_tpa, run_tpa

    def error(record) -> float:
        plant, estimated, _ = _hardness(record)
        return 100 * (estimated / plant - 1)

    def alone(overrides) -> float:
        return error(run_tpa(resolve_tpa("cheddar", speed=4.0, pause=0.5, plant_overrides=overrides)).record())

    baseline = alone({})
    rows = {}
    for key in (*PLANT, TORQUE_CONSTANT):
        name, value = key.split("=")
        rows[key] = alone({name: float(value)}) - baseline
    print(f"\nbaseline (nothing off): {baseline:+.2f} %")
    print("| what is off in the plant | contribution to the hardness error, nominal model |\n|---|---|")
    for key, e in rows.items():
        print(f"| {key} | {e:+.2f} % |")
    combined = error(chain["nominal"]) - baseline
    print(f"| all of PLANT (nominal model) | {combined:+.2f} % (sum of its rows {sum(rows[key] for key in PLANT):+.2f} %) |")
    print(f"| all of PLANT (the model identified from the plant's excitation) | {error(chain['calibrated']) - baseline:+.2f} % |")
    assert abs(sum(rows[key] for key in PLANT) - combined) < 0.2 * abs(combined) + 0.3
