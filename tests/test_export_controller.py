"""The exported controller step (chewbot export-controller) and software in the loop (chewbot simulate --exported).

The C step is held against the Python controller with the same sensor path (--sensor measured: forward kinematics of
the measured crank angles and the filtered difference), tick by tick, to 1e-9 of the largest torque: a bound far
above rounding (the two evaluate the same graphs, one folded and compiled with -O2, one with p as an input at -O1:
measured 1e-16 on the same ticks, 1e-13 between two closed loops) and far below any difference of algorithm (one
Gauss-Newton step fewer, a filter off by one tick, a reference off by one sample all show at 1e-4 or more).
The built-in models have a drive: the C step is then given the encoders' counts and commands currents, held against
the currents the Python loop makes of its controller's torques to the same 1e-9 (of the largest current), for the
same reasons (the loss law's inverse is the same eight Newton steps in both; measured 5e-16).
"""

from __future__ import annotations

import ctypes
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from recording_support import chewing_recording, registration
from typer.testing import CliRunner

from chewbot.cli import app
from chewbot.export.controller import (STATUS_BITS, STRUCTS, ExportedController, SharedLibrary, StepLibrary, StepSpec, build_shared,
                                       fk_function, law_function, structures)
from chewbot.simulation.options import resolve
from chewbot.simulation.run import build, compute
from chewbot.table import Table

runner = CliRunner()
# The flags of the issue, written out here (not taken from the code under test).
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2"]
LIBM = {"exp", "acos", "asin", "atan", "atan2", "cos", "sin", "sincos", "tan", "sqrt", "pow", "fmin", "fmax", "fabs", "log",
        "cosh", "sinh", "tanh", "floor", "ceil", "fmod", "hypot", "exp2", "log2", "cbrt", "erf"}
ALLOCATORS = {"malloc", "calloc", "realloc", "free", "aligned_alloc", "posix_memalign"}
TOLERANCE = 1e-9  # of max |tau|: see the module docstring


def tau_cmd(table: Table) -> np.ndarray:
    return np.column_stack([table[f"tau_cmd{i}"] for i in range(1, 7)])


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("controller") / "ct"
    result = runner.invoke(app, ["export-controller", "--out", str(out)])
    assert result.exit_code == 0, result.output
    # its Makefile builds the library with the strict flags (they are its CFLAGS): any warning fails the build
    assert f"CFLAGS ?= {' '.join(STRICT)}" in (out / "Makefile").read_text()
    done = subprocess.run(["make", "-C", str(out)], capture_output=True, text=True)
    assert done.returncode == 0 and "warning" not in done.stderr, done.stdout + done.stderr
    return out


def test_library_compiles_strictly_wherever_its_files_sit_and_links_no_allocator(exported, tmp_path):
    """Header and sources moved into unrelated folders compile warning-free with the issue's flags (the generated
    kernels include nothing but <math.h>: their object from the Makefile's build is taken as it is); the objects
    call nothing but libm and each other, hold no writable data (no .data, .bss or common symbols: no mutable static
    state), and no work array is static in the sources."""
    layout = {"include/chewbot_ctrl.h": "api/v1/chewbot_ctrl.h", "src/chewbot_ctrl.c": "core/step.c",
              "src/chewbot_ctrl_kernels.h": "generated/graphs/chewbot_ctrl_kernels.h", "src/chewbot_ctrl_task.c": "data/task.c"}
    for src, dst in layout.items():
        (tmp_path / dst).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(exported / src, tmp_path / dst)
    assert re.findall(r"#include\s*(\S+)", (exported / "src/chewbot_ctrl_kernels.c").read_text()) == ["<math.h>"]
    objects = [str(exported / "src/chewbot_ctrl_kernels.o")]
    includes = ["-I" + str(tmp_path / "api/v1"), "-I" + str(tmp_path / "generated/graphs")]
    for c in ("core/step.c", "data/task.c"):
        obj = tmp_path / (c.replace("/", "_") + ".o")
        done = subprocess.run(["cc", *STRICT, *includes, "-c", "-o", str(obj), str(tmp_path / c)], capture_output=True, text=True)
        assert done.returncode == 0 and not done.stderr, done.stderr
        objects.append(str(obj))
    symbols = subprocess.run(["nm", *objects], capture_output=True, text=True, check=True).stdout
    defined = set(re.findall(r"^[0-9a-f]+ [TtRr] (\w+)$", symbols, re.M))
    undefined = set(re.findall(r"^\s+U (\w+)$", symbols, re.M))
    assert undefined - defined <= LIBM, undefined - defined - LIBM
    assert not undefined & ALLOCATORS
    writable = re.findall(r"^[0-9a-f]* ?[BbDdCGgSs] (\w+)$", symbols, re.M)
    assert writable == [], writable
    generated = (exported / "src/chewbot_ctrl_kernels.c").read_text() + (exported / "src/chewbot_ctrl.c").read_text()
    assert not re.search(r"^\s*static (?!const|int casadi_f|casadi_real casadi_|void|int |unsigned|double [a-z_]+\()", generated, re.M)
    assert "malloc" not in generated and "printf" not in generated and "FILE" not in generated
    # the example links against these objects and passes on the log
    example = tmp_path / "example"
    done = subprocess.run(["cc", *STRICT, "-D_POSIX_C_SOURCE=199309L", *includes, "-o", str(example), str(exported / "example/example.c"),
                           *objects, "-lm"], capture_output=True, text=True)
    assert done.returncode == 0 and not done.stderr, done.stderr
    assert subprocess.run([str(example), str(exported / "example/log.csv")], capture_output=True).returncode == 0


def test_make_check_runs_the_example_and_a_changed_log_fails_it(exported, tmp_path):
    done = subprocess.run(["make", "-s", "-C", str(exported), "check"], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "all torques equal the log's to 1e-9 of max |tau|" in done.stdout
    assert re.search(r"median [\d.]+ us, p99 [\d.]+ us, max [\d.]+ us", done.stdout)
    lines = (exported / "example/log.csv").read_text().splitlines()
    assert len(lines) == 5002 and lines[0].startswith("t [s],theta1 [rad]")
    row = lines[2500].split(",")
    row[9] = repr(float(row[9]) * (1 + 1e-6) + 1e-6)  # tau_cmd3 of one tick moved by about 1e-6 N m
    lines[2500] = ",".join(row)
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    bad = subprocess.run([str(exported / "example/example"), str(tmp_path / "log.csv")], capture_output=True, text=True)
    assert bad.returncode == 1 and "tau_cmd3" in bad.stderr


@pytest.mark.parametrize("kind", ["computed-torque", "pd"])
def test_exported_step_equals_the_python_controller_tick_by_tick(kind):
    """On the default task: the C step's commanded torques equal the Python controller's with --sensor measured, on
    the ticks of the same run (both fed the same measured angles) and between two separate closed-loop runs."""
    c = compute(resolve(kind, exported=True), exported=ExportedController)  # the default gains
    py = compute(resolve(kind, sensor="measured"))
    assert c.metrics["stopped"] is None and py.metrics["stopped"] is None
    same_run = c.info["simulation"]["exported"]
    assert same_run["ticks"] == 5001 and same_run["relative"] <= TOLERANCE and same_run["status_bits_seen"] == []
    # the drive robot: the step read the encoders' counts and its currents are the Python controller's
    assert same_run["encoder_counts"] and same_run["current_relative"] <= TOLERANCE and same_run["largest_abs_current_A"] > 0.1
    a, b = tau_cmd(c.table), tau_cmd(py.table)
    assert a.shape == b.shape == (5001, 6)
    assert np.max(np.abs(a - b)) <= TOLERANCE * np.max(np.abs(b))
    assert np.max(np.abs(b)) > 0.1  # N m: the torques are not trivially zero


def test_exported_step_with_noisy_encoders_sees_what_the_python_controller_sees():
    """With 1e-4 rad of encoder noise both controllers are fed the same noisy angles each tick: their torques agree
    on the same ticks as without noise."""
    c = compute(resolve(noise_rad=1e-4, seed=2, exported=True), exported=ExportedController)
    same_run = c.info["simulation"]["exported"]
    assert same_run["ticks"] == 5001 and same_run["relative"] <= TOLERANCE and same_run["current_relative"] <= TOLERANCE
    assert c.info["simulation"]["sensor"]["noise_rad"] == 1e-4 and c.metrics["stopped"] is None


def test_exported_step_on_a_coarse_encoder_commands_the_python_controllers_currents():
    """A coarse encoder (200 counts per motor turn: 6.2e-4 rad at the crank, ten times the built-in one's) on the
    robot and in the controller's model, over the first chewing cycle of the default task (1.0 to 1.8 s): the step,
    given whole counts, commands the currents the Python loop commands on the same ticks (1e-9 of the largest); the
    angles it turned the counts into are on the encoder's grid (whole counts to 1e-9 of a count), and the currents differ from a
    run with the built-in encoder by far more than that (the quantisation is felt: the test can fail)."""
    from chewbot.model import drive

    runs = {}
    for counts in (200.0, 2000.0):
        sets = {"drive.encoder_counts_per_rev": counts}
        options = resolve("computed-torque", exported=True, overrides=sets, plant_overrides=sets)
        task = build(options).task.window(1000, 1801)
        captured = []

        def exported(controller, rate, captured=captured):
            captured.append(ExportedController(controller, rate))
            return captured[-1]

        result = compute(options, task=task, exported=exported)
        same_run = result.info["simulation"]["exported"]
        assert same_run["ticks"] == 801 and same_run["encoder_counts"] and result.metrics["stopped"] is None
        assert same_run["current_relative"] <= TOLERANCE and same_run["relative"] <= TOLERANCE
        runs[counts] = np.array(captured[0].c_currents)
        last = np.asarray(captured[0].library.context.theta_last) / drive.count_angle(drive.of(captured[0].model))
        assert np.max(np.abs(last - np.rint(last))) < 1e-9  # the last tick's angles: whole counts
    assert np.max(np.abs(runs[200.0] - runs[2000.0])) > 1e3 * TOLERANCE * np.max(np.abs(runs[2000.0]))


def test_exported_on_an_imported_recording_from_the_command_line(tmp_path):
    """A recording (synthetic markers of one chewing cycle) imported with import-motion, then simulate --exported and
    simulate --sensor measured on it: results.csv's tau_cmd1..6 equal tick by tick."""
    rec = chewing_recording(tmp_path, 30.0)[0]
    task = tmp_path / "task.csv"
    assert runner.invoke(app, ["import-motion", rec, "--registration", registration(tmp_path), "--out", str(task)]).exit_code == 0
    folders = {}
    for name, extra in (("c", ["--exported"]), ("py", ["--sensor", "measured"])):
        folders[name] = tmp_path / name
        done = runner.invoke(app, ["simulate", "--task", str(task), *extra, "--out", str(folders[name]), "-q"])
        assert done.exit_code == 0, done.output
    a, b = (tau_cmd(Table.read_csv(folders[k] / "results.csv")) for k in ("c", "py"))
    assert a.shape == b.shape == (901, 6)
    assert np.max(np.abs(a - b)) <= TOLERANCE * np.max(np.abs(b))


def test_exported_needs_the_measured_sensor_and_a_held_rate(tmp_path):
    for args, words in ((["--exported", "--sensor", "exact"], "--sensor measured"), (["--exported", "--rate", "continuous"], "continuous"),
                        (["--exported", "--controller", "feedforward"], "pd or computed-torque"), (["--exported", "--compare"], "--compare"),
                        (["--noise", "1e-4", "--sensor", "exact"], "--sensor measured")):
        done = runner.invoke(app, ["simulate", *args, "--out", str(tmp_path / "x")])
        assert done.exit_code == 2 and words in done.output, (args, done.output)


# ------------------------------------------------------------------ the status word, case by case


@pytest.fixture(scope="module")
def step():
    """The default computed-torque step (the library simulate --exported compiles) and the first reference sample."""
    controller = build(resolve("computed-torque", sensor="measured")).controller
    spec = StepSpec.of(controller, 1000.0)
    return StepLibrary(spec, build_shared(spec)), spec


def home(spec):
    from chewbot.export.controller import home_angles

    return home_angles(spec.model)


@pytest.mark.parametrize("options", [dict(controller="computed-torque"), dict(controller="pd", model="6rss"),
                                     dict(controller="computed-torque", method="newton-euler", friction="on")])
def test_context_mirror_has_the_c_compilers_layout(options, tmp_path):
    """The header's structs, compiled with the strict flags by a small program printing each member's offsetof and
    sizeof and each struct's sizeof (tests/c/struct_layout.c), against their ctypes mirror, both generated from the
    one field table: the same members at the same offsets with the same sizes (exact: bytes). On the target with
    computed torque and with Newton-Euler (two normal forces, 8 gains, their own work sizes) and on the 6RSS with PD
    (one unused normal-force slot, 12 gains)."""
    from chewbot.export.controller.sources import dimensions, filled, header

    spec = StepSpec.of(build(resolve(sensor="measured", **options)).controller, 1000.0)
    fk, law = fk_function(spec.model), law_function(spec)
    (tmp_path / "chewbot_ctrl.h").write_text(header(spec, fk, law))
    mirror = structures(dimensions(spec, fk, law), filled(spec))
    members, expected = [], []
    for struct in STRUCTS:
        kind = mirror[struct.name]
        assert [name for name, _ in kind._fields_] == [f.name for f in struct.fields]
        for name, _ in kind._fields_:
            members.append(f"MEMBER({struct.name}, {name})")
            expected.append(f"{struct.name} {name} {getattr(kind, name).offset} {getattr(kind, name).size}")
        members.append(f"STRUCT({struct.name})")
        expected.append(f"{struct.name} - 0 {ctypes.sizeof(kind)}")
    (tmp_path / "struct_members.h").write_text("\n".join(members) + "\n")
    program = tmp_path / "layout"
    done = subprocess.run(["cc", *STRICT, f"-I{tmp_path}", "-o", str(program), str(Path(__file__).parent / "c" / "struct_layout.c")],
                          capture_output=True, text=True)
    assert done.returncode == 0 and not done.stderr, done.stderr
    assert subprocess.run([str(program)], capture_output=True, text=True, check=True).stdout.splitlines() == expected


def test_a_mirror_of_another_size_is_refused(step):
    """A context mirror whose size differs from the library's sizeof(chewbot_ctrl) (here one work double more) is
    refused before any call: a step through it would write past the context."""
    lib, spec = step
    shared = SharedLibrary(lib.shared.path, {**lib.shared.dimensions, "WORK_W": lib.shared.dimensions["WORK_W"] + 1})
    with pytest.raises(RuntimeError, match="bytes"):
        StepLibrary(spec, shared)


def test_templates_are_filled_whole():
    """A template's placeholder left without a value, or a value without a placeholder, is an error, not a file with
    a hole in it or a value silently dropped."""
    from chewbot.export.controller.sources import render

    values = dict(rows="1", table="  0.0,")
    assert render("chewbot_ctrl_task.c", **values).endswith("{\n  0.0,\n};\n")
    with pytest.raises(KeyError):
        render("chewbot_ctrl_task.c", rows="1")
    with pytest.raises(ValueError, match="no placeholder for extra"):
        render("chewbot_ctrl_task.c", **values, extra="x")


def test_the_step_at_rest_at_home_is_quiet(step):
    lib, spec = step
    lib.init(0.0)
    tau, status = lib.step(0.0, home(spec))
    assert status == 0 and np.all(np.abs(lib.q) < 1e-12) and np.all(np.isfinite(tau)) and np.any(tau != 0)
    assert lib.fk_step[0] < 1e-9 and 0 < lib.conditioning[0] <= 1 and lib.transmission[0] > 0.05


def test_fk_failure_holds_the_last_torques_then_zeroes_them(step):
    lib, spec = step
    lib.init(0.0)
    theta = home(spec)
    tau0, _ = lib.step(0.0, theta)
    wrong = theta.copy()
    wrong[2] += 1.0  # rad: crank 3 turned a radian against the others: no pose closes the six chains
    tau1, status = lib.step(0.001, wrong)
    assert status & STATUS_BITS["FK_NOT_CONVERGED"] and status & STATUS_BITS["HOLDING"]
    assert lib.fk_residual[0] > 1e-2 and np.array_equal(tau1, tau0) and np.all(np.abs(lib.q) < 1e-12)  # estimate kept
    for k in range(2, 12):
        tau, status = lib.step(0.001 * k, wrong)
    assert np.all(tau == 0) and status & STATUS_BITS["HOLDING"]  # past max_hold_ticks (10)
    tau, status = lib.step(0.012, theta)
    assert status == 0 and np.any(tau != 0)


def test_near_singular_near_a_cranks_dead_point(step):
    """The crank angles of a pose moved sideways (Y) towards a chain's dead point, tick by tick: the estimate follows
    them (converged), and the bit rises where the smallest transmission sine falls below 0.05 (Y = 11.000 mm: 0.0586,
    11.025 mm: 0.030, from the kinematics' transmission output), the torques then held. The conditioning bit by its
    threshold: no pose of the default task comes near a direct-kinematics singularity."""
    from chewbot.kinematics.functions import KINEMATICS_OUTPUTS, kinematics_kernel

    lib, spec = step
    kin = kinematics_kernel("target", "euler-angles").graph()

    def angles(y):
        out = kin(np.array([0.0, y, 0.0, 0.0]), np.zeros(4), np.zeros(4), spec.model.vector())
        return np.asarray(out[KINEMATICS_OUTPUTS.index("theta")]).ravel(), float(np.min(np.asarray(out[KINEMATICS_OUTPUTS.index("transmission")])))

    lib.init(0.0)
    path = np.append(np.linspace(0.0, 0.011, 201), 0.011025)
    for k, y in enumerate(path):
        theta, transmission = angles(y)
        tau, status = lib.step(0.001 * k, theta)
        near = bool(status & STATUS_BITS["NEAR_SINGULAR"])
        assert not status & STATUS_BITS["FK_NOT_CONVERGED"] and near == (transmission < 0.05), (y, transmission)
        assert abs(lib.q[1] - (path[k - 1] if near else y)) < 1e-9  # near-singular: the estimate is not taken
    assert status & STATUS_BITS["HOLDING"] and lib.transmission[0] == pytest.approx(transmission, rel=1e-6)
    lib.init(0.0)
    lib.fields["conditioning_min"][0] = 1.0 + 1e-12  # the ratio of two means never exceeds 1
    _, status = lib.step(0.0, home(spec))
    assert status & STATUS_BITS["NEAR_SINGULAR"] and status & STATUS_BITS["HOLDING"] and 0 < lib.conditioning[0] <= 1


def test_reference_outside_the_workspace_holds_the_last_one_inside(step):
    lib, spec = step
    lib.init(0.0)
    lib.step(0.0, home(spec))
    held = lib.q_ref.copy()
    q_out = np.zeros(spec.n)
    q_out[0] = 0.012  # m: X = 12 mm takes the condyles past the sockets' front (x <= 5 mm)
    lib.set_reference(q_out, np.zeros(spec.n), np.zeros(spec.n), np.zeros(3))
    _, status = lib.step(0.001, home(spec))
    assert status & STATUS_BITS["REFERENCE_OUTSIDE"] and lib.ref_margin[0] <= 0
    assert np.array_equal(lib.q_ref, held) and np.all(lib.dq_ref == 0) and np.all(lib.ddq_ref == 0)
    q_in = np.zeros(spec.n)
    q_in[0] = 0.001
    lib.set_reference(q_in, np.zeros(spec.n), np.zeros(spec.n), np.zeros(3))
    _, status = lib.step(0.002, home(spec))
    assert not status & STATUS_BITS["REFERENCE_OUTSIDE"] and np.array_equal(lib.q_ref, q_in)


def test_saturation_rate_limit_watchdog_and_estop(step):
    lib, spec = step
    theta = home(spec)
    lib.init(0.0)
    free, _ = lib.step(0.0, theta)
    limit = 0.5 * np.max(np.abs(free))
    lib.init(0.0)
    lib.fields["torque_limit"][0] = limit
    tau, status = lib.step(0.0, theta)
    assert status & STATUS_BITS["TORQUE_SATURATED"] and np.max(np.abs(tau)) == limit
    assert np.array_equal(tau, np.clip(free, -limit, limit))
    # the rate limit: 1 N m/s allows 1e-3 N m per millisecond from zero
    lib.init(0.0)
    lib.fields["torque_rate_limit"][0] = 1.0
    tau, status = lib.step(0.0, theta)
    assert status & STATUS_BITS["RATE_LIMITED"] and np.all(tau == 0)  # dt = 0 on the first step
    tau, status = lib.step(0.001, theta)
    assert status & STATUS_BITS["RATE_LIMITED"] and np.max(np.abs(tau)) == pytest.approx(1e-3, rel=1e-12)
    # the watchdog: a step 5 ms after the previous one trips it, latched until cleared
    lib.init(0.0)
    lib.step(0.0, theta)
    tau, status = lib.step(0.005, theta)
    assert status & STATUS_BITS["WATCHDOG"] and np.all(tau == 0)
    tau, status = lib.step(0.006, theta)
    assert status & STATUS_BITS["WATCHDOG"] and np.all(tau == 0)
    lib.clear_faults()
    tau, status = lib.step(0.007, theta)
    assert status == 0 and np.any(tau != 0)
    # the emergency stop zeroes the torques at once, whatever the rate limit
    lib.fields["torque_rate_limit"][0] = 1e-6
    lib.set_estop(True)
    tau, status = lib.step(0.008, theta)
    assert status & STATUS_BITS["ESTOP"] and np.all(tau == 0)
    lib.set_estop(False)
    lib.fields["torque_rate_limit"][0] = 0.0
    tau, status = lib.step(0.009, theta)
    assert status == 0 and np.any(tau != 0)


def test_encoder_offsets_and_homing(step):
    """Raw angles with offsets give the same torques as the true angles without; homing sets the offsets from the raw
    angles read at home."""
    lib, spec = step
    theta = home(spec)
    lib.init(0.0)
    plain, _ = lib.step(0.0, theta)
    offsets = np.array([0.1, -0.2, 0.3, -0.4, 0.5, -0.6])
    lib.init(0.0, offsets)
    shifted, status = lib.step(0.0, theta + offsets)
    assert status == 0 and np.max(np.abs(shifted - plain)) <= 1e-12 * np.max(np.abs(plain))
    lib.init(0.0)
    lib.home(theta + offsets)
    assert np.allclose(lib.context.offsets, offsets, atol=1e-15)
    again, _ = lib.step(0.0, theta + offsets)
    assert np.max(np.abs(again - plain)) <= 1e-12 * np.max(np.abs(plain))


def test_bad_input_holds(step):
    lib, spec = step
    lib.init(0.0)
    tau0, _ = lib.step(0.0, home(spec))
    theta = home(spec)
    theta[0] = np.nan
    tau, status = lib.step(0.001, theta)
    assert status & STATUS_BITS["BAD_INPUT"] and status & STATUS_BITS["HOLDING"] and np.array_equal(tau, tau0)
    good, status = lib.step(0.002, home(spec))
    assert status == 0
    tau, status = lib.step(0.0015, home(spec))  # before the previous step's time
    assert status & STATUS_BITS["BAD_INPUT"] and np.array_equal(tau, good)


@pytest.mark.slow
def test_g1_with_friction_exported_equals_python_and_reports_active_limits():
    """Newton-Euler with G1 and friction: the C step equals the Python controller on the default task; a reference
    with an acceleration far beyond the actuators raises LIMIT_ACTIVE (and saturation); DISTRIBUTION_NOT_CONVERGED
    by its tolerance."""
    options = dict(controller="computed-torque", method="newton-euler", friction="on")
    c = compute(resolve(**options, exported=True), exported=ExportedController)
    py = compute(resolve(**options, sensor="measured"))
    a, b = tau_cmd(c.table), tau_cmd(py.table)
    assert np.max(np.abs(a - b)) <= TOLERANCE * np.max(np.abs(b))
    controller = build(resolve(**options, sensor="measured")).controller
    spec = StepSpec.of(controller, 1000.0)
    lib = StepLibrary(spec, build_shared(spec))
    lib.init(0.0)
    ddq = np.array([0.0, 0.0, 0.0, 1e5])  # rad/s^2 on beta: torques up to about 12 N m, beyond the 5 N m limit
    lib.set_reference(np.zeros(4), np.zeros(4), ddq, np.zeros(3))
    tau, status = lib.step(0.0, home(spec))
    assert status & STATUS_BITS["LIMIT_ACTIVE"] and status & STATUS_BITS["TORQUE_SATURATED"] and lib.limit_excess[0] > 0
    assert np.max(np.abs(tau)) == pytest.approx(spec.model.limits.torque, abs=0)
    # the distribution's convergence: its last Newton step (~1e-14 N at the optimum) against a tolerance of zero
    lib.init(0.0)
    lib.fields["distribution_step_tolerance"][0] = 0.0
    _, status = lib.step(0.0, home(spec))
    assert status & STATUS_BITS["DISTRIBUTION_NOT_CONVERGED"] and 0 < lib.dist_step[0] < 1e-9
    assert not status & STATUS_BITS["HOLDING"]  # the torques are used: they satisfy the equations of motion


def test_outputs_pose_error_and_normal_forces_by_other_routes(step, exported):
    """Along the log of the export: the step's normal forces equal those of the plant's forward dynamics (another
    implementation: Newton iterations on the equations of motion) under the law's torques at the step's estimate,
    without friction (1e-9 of the largest); the pose's parasitic Z and gamma satisfy the sockets' plane equations
    (1e-12 m); the tracking error is the reference less the estimate."""
    from chewbot.simulation.forward import forward_dynamics

    lib, spec = step
    log = np.loadtxt(exported / "example/log.csv", delimiter=",", skiprows=1)
    rows = range(0, len(log), 50)
    lib.init(log[0, 0])
    q, dq, tau, force, N, pose, error, q_ref = [], [], [], [], [], [], [], []
    for k in range(len(log)):
        lib.step(log[k, 0], log[k, 1:7])
        if k in rows:
            for store, value in ((q, lib.q), (dq, lib.dq), (tau, lib.tau_cmd), (force, lib.force), (N, lib.normal), (pose, lib.pose),
                                 (error, lib.error), (q_ref, lib.q_ref)):
                store.append(value.copy())
    q, dq, tau, force, N, pose, error, q_ref = map(np.array, (q, dq, tau, force, N, pose, error, q_ref))
    fwd = forward_dynamics(spec.model, q, dq, tau, force, spec.side, friction=False)
    assert np.max(np.abs(N - fwd.N)) <= 1e-9 * np.max(np.abs(fwd.N)) and np.max(np.abs(fwd.N)) > 1.0  # N
    from scipy.spatial.transform import Rotation

    h = spec.model.hkp
    R = Rotation.from_euler("XYZ", pose[:, 3:]).as_matrix()
    for T in (h.T_L, h.T_R):
        ball = pose[:, :3] + R @ T
        assert np.max(np.abs(h.p1 * ball[:, 0] + ball[:, 2] + h.p2)) < 1e-12
    assert np.array_equal(pose[:, [0, 1, 3, 4]], q)
    assert np.array_equal(error, q_ref - q) and np.max(np.abs(error)) > 0
    # the reference at the log's ticks is the task's (quintic Hermite at the samples: the samples themselves)
    assert np.max(np.abs(q_ref - spec.q[list(rows)])) <= 1e-15 * np.max(np.abs(spec.q))


def test_export_refuses_a_log_of_a_failing_loop_and_takes_a_gains_file(tmp_path):
    """PD with gains tuned on the plant's own rate (chewbot's earlier defaults: k_p 10, k_d 0.01, cut-off 50 Hz)
    topples the robot on the measured state (docs/simulation.md): the export says so (exit 2) instead of writing a
    log of a failing loop; --no-log exports it; a --gains file's values are the library's defaults; an existing
    folder is not replaced without --force."""
    out = tmp_path / "pd"
    unstable = tmp_path / "unstable.toml"
    unstable.write_text("[pd]\nkp_Nm_per_rad = 10.0\nkd_Nms_per_rad = 0.01\n"
                        "[computed_torque]\nfrequency_Hz = 30.0\ndamping = 1.0\n[estimator]\ncutoff_Hz = 50.0\n")
    done = runner.invoke(app, ["export-controller", "--controller", "pd", "--gains", str(unstable), "--out", str(out)])
    assert done.exit_code == 2 and "leaves the workspace" in done.output and "--no-log" in done.output and not out.exists()
    gains = tmp_path / "gains.toml"
    gains.write_text("[pd]\nkp_Nm_per_rad = 2.0\nkd_Nms_per_rad = [0.005, 0.005, 0.006, 0.006, 0.007, 0.007]\n"
                     "[computed_torque]\nfrequency_Hz = 30.0\ndamping = 1.0\n[estimator]\ncutoff_Hz = 200.0\n")
    done = runner.invoke(app, ["export-controller", "--controller", "pd", "--gains", str(gains), "--no-log", "--out", str(out)])
    assert done.exit_code == 0, done.output
    step_c = (out / "src/chewbot_ctrl.c").read_text()
    assert "GAINS[CHEWBOT_CTRL_NG] = {2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 0.005, 0.005, 0.006, 0.006, 0.007, 0.007}" in step_c
    assert "ctx->config.cutoff_hz = 200.0;" in step_c and not (out / "example/log.csv").exists()
    again = runner.invoke(app, ["export-controller", "--controller", "pd", "--no-log", "--out", str(out)])
    assert again.exit_code == 5
    for bad, words in ((["--controller", "feedforward"], "pd or computed-torque"), (["--method", "euler"], "--method")):
        done = runner.invoke(app, ["export-controller", *bad, "--no-log", "--out", str(tmp_path / "x")])
        assert done.exit_code == 2 and words in done.output, done.output


def test_step_counts_reads_the_encoders_and_commands_currents_through_the_drive(step):
    """``chewbot_ctrl_step_counts``: counts at the motors are the angles counts * 2 pi / (counts per turn N) (the same
    torques as ``chewbot_ctrl_step`` on those angles, exactly); the crank rates are the filtered difference of the
    angles (the sensor's formula, written out here); the currents are the drive's loss law inverted at those rates,
    checked by the forward law (the crank torque of k_t i equals the output torque to 1e-12 relative); a changed
    torque constant in the configuration scales the currents; without an encoder the counts are refused (BAD_INPUT)."""
    from chewbot.model import drive

    lib, spec = step
    d = spec.model.drive
    angle = drive.count_angle(d)
    home_counts = np.rint(home(spec) / angle)
    ticks = [home_counts + np.array([0, 1, -1, 2, -2, 3]) * k for k in range(4)]  # cranks turning both ways
    lib.init(0.0)
    plain = [lib.step(0.001 * k, c * angle)[0] for k, c in enumerate(ticks)]
    lib.init(0.0)
    rates, b = np.zeros(6), np.exp(-2 * np.pi * spec.cutoff * 0.001)
    for k, c in enumerate(ticks):
        current, status = lib.step_counts(0.001 * k, c)
        assert status == 0 and np.array_equal(lib.tau, plain[k])
        if k:
            rates = b * rates + (1 - b) * (c - ticks[k - 1]) * angle / 0.001
        assert np.allclose(lib.fields["dtheta"], rates, rtol=1e-12, atol=1e-12)
        back = drive.crank_torque(d, drive.torque_of_current(d, current), lib.fields["dtheta"])
        assert np.max(np.abs(back - lib.tau)) <= 1e-12 * np.max(np.abs(lib.tau))
    assert np.any(lib.fields["dtheta"] > 0) and np.any(lib.fields["dtheta"] < 0)
    lib.fields["torque_constant"][0] *= 2
    doubled, _ = lib.step_counts(0.004, ticks[-1])
    assert np.allclose(doubled * 2, lib.tau_motor / d.torque_constant, rtol=1e-12)
    lib.fields["encoder_counts"][0] = 0.0
    _, status = lib.step_counts(0.005, ticks[-1])
    assert status & STATUS_BITS["BAD_INPUT"] and status & STATUS_BITS["HOLDING"]
