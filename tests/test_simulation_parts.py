"""The simulation's parts as tables and declared interfaces: the controller table (each name in its row's module only;
the command line, the gains file and run.json read it; a new controller is one module and one row), the plant and
controller protocols (a plant written here runs through the simulator unchanged; no part is asked for its type), the
named layouts of the compiled steps (pack and unpack; the graphs equal those of the former numeric offsets), and the
options resolved once (each refusal raised by the resolver, with its message)."""

from __future__ import annotations

import ast
import dataclasses
import json
import sys
import types
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from typer.testing import CliRunner

import chewbot
from chewbot.cli import app
from chewbot.compiled.cache import symbols
from chewbot.compiled.layout import Layout
from chewbot.dynamics.formulations.newton_euler import n_unknowns
from chewbot.food.law import CASADI, N_FOOD, load_food, maxwell_force
from chewbot.model.params import load_model
from chewbot.model.vector import N_P
from chewbot.run.options import OptionError
from chewbot.simulation import engines
from chewbot.simulation.controllers import gains as gains_module
from chewbot.simulation.controllers import table
from chewbot.simulation.controllers.gains import Gains, Section
from chewbot.simulation.controllers.law import make_controller
from chewbot.simulation.food import FOOD_INPUTS, FOOD_SHARED, FoodPlant, _force_sx, food_geometry_sx, food_stage
from chewbot.simulation.forward import n_coordinates, residual_function
from chewbot.simulation.interfaces import PLANT_INPUTS, ControllerCapabilities, PlantCapabilities
from chewbot.simulation.mujoco_plant import MujocoPlant
from chewbot.simulation.options import SimulationOptions, resolve
from chewbot.simulation.plant import PLANT_SHARED, Plant, closed_loop_layouts, closed_loop_stage, held_stage
from chewbot.simulation.reference import Reference
from chewbot.simulation.run import compute
from chewbot.simulation.simulator import simulate
from chewbot.task.default import default_task, parameters_with

PACKAGE = Path(chewbot.__file__).resolve().parent
SHORT = {"task.cycles": 1, "task.rest_s": 0.2}
runner = CliRunner()


def _strings(path: Path):
    """The string constants of a module (f-strings' literal parts included)."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            yield node.value


# ---------------------------------------------------------------------------------------- the controller table


def test_each_controller_is_named_in_its_row_only():
    """No module but the table's spells a controller's name as a string: everything else reads the row."""
    where = {name: sorted(str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py") if name in set(_strings(p)))
             for name in table.CONTROLLERS}
    assert where == {name: ["simulation/controllers/table.py"] for name in table.CONTROLLERS}


def test_the_command_line_reads_the_table():
    """--controller's choices and help, --compare's controllers, export-controller's choices come from the rows."""
    help_text = runner.invoke(app, ["simulate", "--help"], env={"COLUMNS": "400"}).output
    for row in table.CONTROLLERS.values():
        assert row.name in help_text
    bad = runner.invoke(app, ["simulate", "--controller", "bang-bang", "--out", "x"])
    assert bad.exit_code == 2 and all(name in bad.output for name in table.NAMES)
    refused = runner.invoke(app, ["export-controller", "--controller", "feedforward", "--out", "x"])
    assert refused.exit_code == 2 and " or ".join(table.EXPORTABLE) in refused.output
    assert table.COMPARED == tuple(r.name for r in table.CONTROLLERS.values() if r.compared)


def test_the_gains_file_has_a_section_per_row():
    """Each controller with gains has its section, a strict model of its law's module; the built-in file has exactly
    the sections of the table and the other parts; each section's vector is laid out as its law reads it."""
    sections = gains_module.sections()
    rows = {r.gains: r for r in table.CONTROLLERS.values() if r.gains is not None}
    assert set(sections) == set(rows) | set(gains_module.PARTS)
    from chewbot.config import read_text

    assert set(read_text(gains_module.default_gains_file()).data) == set(sections)
    g = Gains.load(mechanism="target")
    for name, row in rows.items():
        assert issubclass(row.module().Gains, Section) and sections[name] is row.module().Gains
        assert g[name].vector().size == row.module().Gains.layout(n_coordinates("target")).size
    assert all(r.module().Gains is None for r in table.CONTROLLERS.values() if r.gains is None)


def test_gains_errors_name_the_file_or_override_and_the_key(tmp_path):
    bad = tmp_path / "g.toml"
    bad.write_text('[computed_torque]\nfrequency_Hz = "30"\n[pd]\nkp_Nm_per_rad = [1, 2]\n[observr]\ncutoff_Hz = 1\n')
    with pytest.raises(chewbot.errors.ChewbotError) as err:
        Gains.load(bad)
    assert f"{bad}: key 'computed_torque.frequency_Hz': '30' is not a number" in str(err.value)
    assert f"{bad}: key 'observr': unknown key" in str(err.value)
    bad.write_text("[pd]\nkp_Nm_per_rad = [1, 2]\n")
    with pytest.raises(chewbot.errors.ChewbotError, match=r"g\.toml: key 'pd\.kp_Nm_per_rad': expected one number or 6, got 2"):
        Gains.load(bad)
    with pytest.raises(chewbot.errors.ChewbotError, match=r"--gain pd\.kd_Nms_per_rad\[2\]=-1: key 'pd\.kd_Nms_per_rad': gains must"):
        Gains.load(overrides={"pd.kd_Nms_per_rad[2]": -1.0})
    with pytest.raises(chewbot.errors.ChewbotError, match=r"--gain pd\.kq=1: unknown key 'pd\.kq'"):
        Gains.load(overrides={"pd.kq": 1.0})
    partial = tmp_path / "partial.toml"
    partial.write_text("[pd]\nkp_Nm_per_rad = 3\n")
    g = Gains.load(partial)
    assert g["pd"].kp_Nm_per_rad == (3.0,) * 6 and "pd.kd_Nms_per_rad" in g.defaulted and "pd.kp_Nm_per_rad" not in g.defaulted


LAW = '''
"""A controller that commands no torque: the smallest law of the table's form."""
import casadi as ca

from chewbot.simulation.controllers.law import CompiledLaw

Gains = None


def law(x, mechanism, inverse):
    return ca.SX.zeros(6)


def build(parts):
    return CompiledLaw(parts)
'''


def test_a_new_controller_is_one_module_and_one_row(monkeypatch, tmp_path):
    """A module with its law and a row in the table: the options, the simulator, run.json and the report take it
    without any other change."""
    module = types.ModuleType("chewbot.simulation.controllers.zero")
    exec(compile(LAW, "zero.py", "exec"), module.__dict__)
    monkeypatch.setitem(sys.modules, module.__name__, module)
    row = table.ControllerRow("zero", "no torque at all", "zero")
    monkeypatch.setitem(table.CONTROLLERS, row.name, row)
    with pytest.raises(OptionError, match="method applies to the model-based controllers"):
        resolve("zero", method="liang", overrides=SHORT)
    r = compute(resolve("zero", overrides=SHORT))
    assert np.all(r.simulation.tau_cmd == 0) and r.info["simulation"]["controller"]["kind"] == "zero"
    assert r.record["controller"] == "zero"
    from chewbot.outputs.simulation import write

    out = write(r, tmp_path / "zero")
    assert json.loads((out / "run.json").read_text())["options"]["controller"] == "zero"
    assert "chewbot simulation: zero on" in (out / "report.html").read_text()


# ---------------------------------------------------------------------------------------- the interfaces


def _calls(path: Path):
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            yield node


PARTS = {"Plant", "FoodPlant", "MujocoPlant", "ClosedLoop", "Controller", "LawController", "LoopPlant", "CompiledLaw",
         "HybridController", "ExportedController"}


def test_no_part_is_asked_for_its_type():
    """No isinstance on a plant or controller class or protocol anywhere in src/; no getattr or hasattr in the
    simulation layer (what a part can do is data: its row or its capabilities)."""
    typed, probed = [], []
    for path in PACKAGE.rglob("*.py"):
        for call in _calls(path):
            if call.func.id == "isinstance" and len(call.args) == 2:
                names = {n.id for n in ast.walk(call.args[1]) if isinstance(n, ast.Name)}
                typed += [f"{path.name}:{call.lineno}"] if names & PARTS else []
            if call.func.id in ("getattr", "hasattr") and "simulation" in path.parts:
                probed.append(f"{path.name}:{call.lineno}")
    assert typed == [] and probed == []


class PerturbedPlant:
    """A plant of the interface written here: chewbot's plant of a model whose mandible is 20 % heavier, wrapped (its
    own state is the wrapped plant's, kept as is)."""

    capabilities = PlantCapabilities()

    def __init__(self, model):
        self.inner = Plant(load_model(model.source, {"mandible.mass_g": 1.2 * model.mandible_mass * 1e3}))
        self.model, self.side, self.friction, self.splits = self.inner.model, "left", False, 0

    @property
    def mechanism(self):
        return self.model.mechanism

    def kernels(self):
        return self.inner.kernels()

    def initial(self, t, q, dq):
        return self.inner.initial(t, q, dq)

    def advance(self, state, h, inputs):
        return self.inner.advance(state, h, inputs)

    def outputs(self, t, q, dq, force, internal):
        return force, {}

    def forward(self, q, dq, tau, force):
        return self.inner.forward(q, dq, tau, force)

    def drift(self, kinematics, rows):
        return {}

    def info(self, sim):
        return {"simulation": {}}

    def files(self):
        return {}


def test_a_plant_written_here_runs_through_the_simulator():
    """The simulator takes a plant it has never seen (:class:`PerturbedPlant`) and gives, tick by tick, what chewbot's
    own plant of the same perturbed model gives: the simulator calls only the interface."""
    m = load_model("target")
    task = default_task(m, "left")
    ref = Reference.from_task(m, task)
    short = Reference(ref.t[:301], ref.q[:301], ref.dq[:301], ref.ddq[:301], ref.force[:301], "left")
    new = PerturbedPlant(m)
    ours = simulate(new, make_controller(table.controller_row("computed-torque"), m, short), short, 1000.0)
    same = simulate(Plant(new.model), make_controller(table.controller_row("computed-torque"), m, short), short, 1000.0)
    assert ours.n == same.n == 301 and np.array_equal(ours.q, same.q) and np.array_equal(ours.tau, same.tau)
    # the model error is felt: the motion differs from that of the plant of the controller's own model (measured 3e-8 m
    # in X; the drive's rotors, 500 times the cranks' inertia, take most of the 20 % heavier mandible's error)
    exact = simulate(Plant(m), make_controller(table.controller_row("computed-torque"), m, short), short, 1000.0)
    assert np.abs(ours.q - exact.q).max() > 1e-8


def _capabilities(plant: type) -> PlantCapabilities:
    return plant.__dataclass_fields__["capabilities"].default


def test_the_engine_rows_say_what_their_plants_can_do():
    """What the options refuse by an engine's row is what its plants declare: chewbot's plant closes the loop and its
    food plant holds a food; MuJoCo's does neither."""
    chewbot_row, mujoco_row = engines.ENGINES["chewbot"], engines.ENGINES["mujoco"]
    assert (chewbot_row.closes_loop, chewbot_row.food) == (_capabilities(Plant).closes_loop, _capabilities(FoodPlant).food) == (True, True)
    assert (mujoco_row.closes_loop, mujoco_row.food) == (_capabilities(MujocoPlant).closes_loop, _capabilities(MujocoPlant).food) == (False, False)
    assert ControllerCapabilities().continuous is False


# ---------------------------------------------------------------------------------------- the layouts


def test_a_layout_packs_and_unpacks():
    lay = Layout.of(B=3, friction=1, p=5)
    x = lay.pack(B=[1, 2, 3], friction=1.0, p=np.arange(5.0))
    assert x.tolist() == [1, 2, 3, 1, 0, 1, 2, 3, 4]
    back = lay.unpack(x)
    assert back["B"].tolist() == [1, 2, 3] and back["friction"].tolist() == [1] and back["p"].tolist() == [0, 1, 2, 3, 4]
    W = PLANT_INPUTS.pack(columns=3, tau=np.arange(6.0), F_B=np.ones((3, 3)))
    assert W.shape == (9, 3) and np.all(PLANT_INPUTS.unpack(W)["tau"] == np.arange(6.0)[:, None])
    food = FOOD_INPUTS.pack(columns=3, tau=np.zeros(6), elapsed=[1.0, 2.0, 3.0])  # a one-row block: its row
    assert FOOD_INPUTS.unpack(food)["elapsed"].tolist() == [[1.0, 2.0, 3.0]]
    assert (lay + Layout.of(gains=2)).names == ("B", "friction", "p", "gains")
    with pytest.raises(ValueError, match="missing"):
        lay.pack(B=[1, 2, 3], p=np.zeros(5))
    with pytest.raises(ValueError, match="once"):
        Layout.of(B=3) + Layout.of(B=1)


def _inputs(fn: ca.Function, s: np.ndarray, seed: int) -> list[np.ndarray]:
    """(q, v, a, N, w, s) of a stage residual: a state near home, random accelerations, normal forces and stage inputs,
    and the shared inputs ``s`` (a real model's numbers)."""
    rng = np.random.default_rng(seed)
    x = [rng.normal(scale=scale, size=fn.size_in(i)) for i, scale in enumerate((1e-3, 1e-2, 1.0, 1.0, 0.1))]
    return [*x, s]


def test_the_steps_built_from_layouts_equal_those_of_the_former_offsets():
    """The stage residuals of the plant, of the closed loop and of the food plant, built by name, against the same
    graphs written with the numeric offsets they replaced (``s[:3], s[3], s[4:4 + N_P]``, ...): equal at a state near
    home with random inputs, to the last bit."""
    mech = "target"
    model = load_model(mech)
    n, nN = n_coordinates(mech), n_unknowns(mech)
    R = residual_function(symbols(mech))
    q, v, a, N = (ca.SX.sym(s, k) for s, k in (("q", n), ("v", n), ("a", n), ("N", nN)))
    plant = Plant(model, friction=True).shared()

    w, s = ca.SX.sym("w", 9), ca.SX.sym("s", 4 + N_P)
    old = ca.Function("old", [q, v, a, N, w, s], [R(q, v, a, N, w[:6], s[:3], w[6:], s[3], s[4:])])
    x = _inputs(old, plant, 1)
    ours = np.asarray(held_stage(mech)(*x))
    assert np.all(np.isfinite(ours)) and np.array_equal(ours, np.asarray(old(*x)))
    assert PLANT_SHARED.size == 4 + N_P and PLANT_INPUTS.size == 9

    controller = make_controller(table.controller_row("computed-torque"), model,
                                 Reference.from_task(model, default_task(model, "left")))
    law = controller.function()
    ng = law.size1_in(6)
    w, s = ca.SX.sym("w", 3 * n + 6), ca.SX.sym("s", 4 + N_P + ng + 3 + N_P + 1)
    gains, B_c, p_c, limit = s[4 + N_P: 4 + N_P + ng], s[4 + N_P + ng: 7 + N_P + ng], s[7 + N_P + ng: 7 + 2 * N_P + ng], s[-1]
    tau = ca.fmin(ca.fmax(law(q, v, w[:n], w[n:2 * n], w[2 * n:3 * n], w[3 * n:3 * n + 3], gains, B_c, p_c), -limit), limit)
    old = ca.Function("old", [q, v, a, N, w, s], [R(q, v, a, N, tau, s[:3], w[3 * n + 3:], s[3], s[4:4 + N_P])])
    c = controller.shared()
    x = _inputs(old, np.concatenate([plant, c["gains"], c["B"], c["p"], [0.05]]), 2)  # a limit the torques reach (N m)
    ours = np.asarray(closed_loop_stage(controller)(*x))
    assert np.all(np.isfinite(ours)) and np.array_equal(ours, np.asarray(old(*x)))
    assert [L.size for L in closed_loop_layouts(mech, ng)] == [3 * n + 6, 4 + N_P + ng + 3 + N_P + 1]

    w, s = ca.SX.sym("w", 7), ca.SX.sym("s", 4 + N_P + N_FOOD + 5 + 1)
    B, fl, p, f = s[:3], s[3], s[4:4 + N_P], s[4 + N_P:4 + N_P + N_FOOD]
    broken, F_m0, bFe0, delta_max0, tilt_max0 = (s[4 + N_P + N_FOOD + i] for i in range(5))
    delta, ddelta, bFe, velocity, sin_tilt = food_geometry_sx(mech, q, v, B, p, f, broken, s[-1], delta_max0, tilt_max0)
    F = _force_sx(f, delta, ddelta, broken, maxwell_force(CASADI, f, F_m0, bFe0, bFe, w[6]), ca.fmax(delta_max0, delta),
                  ca.if_else(delta > delta_max0, sin_tilt, tilt_max0), velocity, sin_tilt)[2]
    old = ca.Function("old", [q, v, a, N, w, s], [R(q, v, a, N, w[:6], B, F, fl, p)])
    food = FoodPlant(model, friction=True, food=load_food("cheddar"))
    shared = food.shared()
    FOOD_SHARED.unpack(shared)["F_m"][:] = 0.3  # N: a Maxwell force at the step's start
    x = _inputs(old, shared, 3)
    x[4][6] = 1e-4  # s since the step's start
    ours = np.asarray(food_stage(mech)(*x))
    assert np.all(np.isfinite(ours)) and np.array_equal(ours, np.asarray(old(*x)))
    assert FOOD_SHARED.size == 4 + N_P + N_FOOD + 5 + 1 and FOOD_INPUTS.size == 7


# ---------------------------------------------------------------------------------------- the options


def test_the_options_are_frozen_and_typed():
    o = resolve("pd", friction="on", side="right")
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.friction = False
    assert o.friction is True and o.controller is table.CONTROLLERS["pd"] and o.engine is engines.ENGINES["chewbot"]
    from chewbot.dynamics.registry import DEFAULT_METHOD
    from chewbot.kinematics.options import Orientation

    assert o.inverse.method == DEFAULT_METHOD[Orientation.euler_angles.value]
    assert o.record("right") == {**SimulationOptions(controller=table.CONTROLLERS["pd"]).record("right"), "friction": "on"}
    assert set(o.record("left")) == {"controller", "model", "task", "side", "method", "goal", "friction", "contact", "rate",
                                     "noise_rad", "seed", "plant", "overrides", "plant_overrides", "bite_unknown", "gains",
                                     "gain_overrides", "food", "sensor", "exported", "engine", "bolus"}


@pytest.mark.parametrize("options, words", [
    (dict(noise_rad=1e-4, rate="continuous"), "noise needs a control rate"),
    (dict(sensor="measured", rate="continuous"), "sensor reads the encoders at the ticks"),
    (dict(controller="hybrid", food="cheddar", rate="continuous"), "controller hybrid is evaluated at the ticks of a control rate"),
    (dict(engine="mujoco", rate="continuous"), "plant-engine mujoco runs the controller at the ticks"),
    (dict(compare_engines=True, rate="continuous"), "compare-engines needs a control rate"),
    (dict(food="cheddar", rate="continuous"), "food the food's events are located between the ticks"),
    (dict(noise_rad=1e-4, sensor="exact"), "noise on the encoders needs --sensor measured"),
    (dict(exported=True, sensor="exact"), "--exported needs --sensor measured"),
    (dict(exported=True, controller="feedforward"), "exported runs pd or computed-torque, not feedforward"),
    (dict(exported=True, compare=True), "exported and compare exclude each other"),
    (dict(compare=True, compare_engines=True), "compare and compare-engines exclude each other"),
    (dict(controller="hybrid"), "controller hybrid follows the task's Fz as a force reference by pressing on a food"),
    (dict(controller="hybrid", food="cheddar", bite_unknown=True), "bite-unknown does not apply"),
    (dict(controller="impedance", model="6rss"), "controller impedance is for the target"),
    (dict(controller="pd", goal="min-torque"), "goal applies to the model-based controllers"),
    (dict(food="cheddar", engine="mujoco"), "it is not in the mujoco plant"),
    (dict(controller="pd", gain_overrides={"computed_torque.damping": 0.7}), "it is a gain of --controller computed-torque"),
    (dict(gain_overrides={"estimator.cutoff_Hz": 100.0}), "the estimator runs only with sensor noise"),
    (dict(plant_overrides={"task.cycles": 2}), "plant-set task.cycles=2 changes the plant's model only"),
    (dict(overrides={"friction.hkp_coulomb": 0.2}), "used by the plant with --friction on"),
    (dict(rate=-5.0), "rate must be a positive number"),
    (dict(rate="fast"), "rate must be a positive number of Hz or 'continuous', not 'fast'"),
    (dict(controller="bang-bang"), "controller must be one of"),
    (dict(engine="bullet"), "plant-engine must be one of"),
    (dict(friction="maybe"), "friction must be one of on, off"),
    (dict(sensor="both"), "sensor must be one of exact, measured"),
])
def test_each_refusal_is_the_resolver_s(options, words):
    with pytest.raises(OptionError) as err:
        resolve(**options)
    assert words in str(err.value), str(err.value)


# ---------------------------------------------------------------------------------------- chewbot.simulate


def test_chewbot_simulate_is_the_command_in_memory(tmp_path, monkeypatch):
    """chewbot.simulate gives what compute gives for the same options (the same resolver), writes nothing unless
    asked, takes a Model and a Task as values, and refuses what the command refuses."""
    monkeypatch.chdir(tmp_path)
    m = load_model("target")
    task = default_task(m, "left", parameters_with({"cycles": 1, "rest_s": 0.2}))
    r = chewbot.simulate(m, task, controller="pd")
    assert list(tmp_path.iterdir()) == []
    same = compute(resolve("pd", task=task.source), task=task)
    assert np.array_equal(r.simulation.q, same.simulation.q) and np.array_equal(r.table["tau1"], same.table["tau1"])
    frame = r.frame()
    assert frame.attrs["units"]["tau1"] == "N*m" and np.array_equal(frame["tau1"].to_numpy(), r.table["tau1"])
    assert r.record["controller"] == "pd" and r.metrics["samples"] == task.t.size
    with pytest.raises(OptionError, match="method applies to the model-based controllers"):
        chewbot.simulate(m, task, controller="pd", method="liang")
    with pytest.raises(OptionError, match="overrides change a model read from its file"):
        chewbot.simulate(m, task, overrides={"mandible.mass_g": 400})
    out = tmp_path / "pd"
    chewbot.simulate("target", controller="pd", overrides=SHORT, out=out)
    assert json.loads((out / "run.json").read_text())["options"]["controller"] == "pd"
    with pytest.raises(chewbot.ChewbotError):  # an existing folder is not replaced without force
        chewbot.simulate("target", controller="pd", overrides=SHORT, out=out)
