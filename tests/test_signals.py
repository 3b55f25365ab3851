"""SIGINT and SIGTERM sent to a real `chewbot` process at several stages: exit code 130 or 143, one line on
standard error and no traceback, no temporary folder or file left, an existing output untouched.

Each stage is reached without timing guesses: the test hook CHEWBOT_TEST_PAUSE=STAGE:FILE makes the process
create FILE and wait there (chewbot.commands.common.pause_for_tests); the compiler is caught as a child process of
chewbot; the NLP solver by the first call of CasADi's nlpsol, after which the signal comes from a timer while
the solver runs sample after sample.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from chewbot.commands.common import EXIT_INTERRUPTED, EXIT_TERMINATED, TEST_PAUSE_VARIABLE
from chewbot import load_model
from chewbot.kinematics.motion import solve_kinematics
from chewbot.model.params import builtin_model_path
from chewbot.task.default import ChewingParameters, default_task

WAIT_S = 120  # a stage must be reached within this (a cold kernel cache on a loaded 2-core machine)


def _start(args: list[str], cwd: Path, prelude: str = "", **env) -> subprocess.Popen:
    """`chewbot ARGS` in a new process (through chewbot.commands.common.main, as the installed program), ``prelude``
    run first (a test's own instrumentation)."""
    code = f"{prelude}\nimport sys\nfrom chewbot.__main__ import main\nsys.exit(main(sys.argv[1:]))"
    return subprocess.Popen([sys.executable, "-c", code, *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, **env})


def _wait_for(proc: subprocess.Popen, reached) -> None:
    deadline = time.monotonic() + WAIT_S
    while not reached():
        if proc.poll() is not None:
            pytest.fail(f"chewbot ended (exit {proc.returncode}) before the stage: {proc.communicate()[1][-2000:]}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail("the stage was not reached in time")
        time.sleep(0.01)


# A progress line, printed per stage where standard error is not a terminal: "LABEL: message (12.3 s)".
PROGRESS_LINE = re.compile(r"^[\w -]+: .+ \(\d+\.\d s\)$")


def _stop(proc: subprocess.Popen, signum: int, code: int) -> None:
    """Send ``signum``; the process ends with ``code`` and one line on standard error after the progress lines of
    the stages it went through, no traceback."""
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=WAIT_S)
    assert proc.returncode == code, err
    *stages, last = err.strip().splitlines()
    assert last.startswith(f"interrupted: {signal.Signals(signum).name}"), err
    assert all(PROGRESS_LINE.match(line) for line in stages), err


def _leftovers(folder: Path) -> list[str]:
    """chewbot's temporary names in a folder (.NAME.partial-PID-*, .NAME.replaced-PID-*)."""
    return [p.name for p in folder.iterdir() if re.match(r"^\..+\.(partial|replaced)-\d+-", p.name)]


def test_sigint_while_importing(tmp_path):
    flag = tmp_path / "flag"
    proc = _start(["run", "--out", "out"], tmp_path, **{TEST_PAUSE_VARIABLE: f"import:{flag}"})
    _wait_for(proc, flag.exists)
    _stop(proc, signal.SIGINT, EXIT_INTERRUPTED)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flag"]


def _compiler_child(pid: int) -> bool:
    """True while ``pid`` has a child process compiling a shared library (the kernel compiler)."""
    try:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
        return any(b"-shared" in Path(f"/proc/{c}/cmdline").read_bytes() for c in children)
    except OSError:
        return False


@pytest.mark.skipif(not Path(f"/proc/{os.getpid()}/task/{os.getpid()}/children").exists(), reason="needs Linux's /proc children list")
def test_sigint_while_compiling_a_kernel(task_csv, tmp_path):
    from chewbot.compiled.kernels import c_compiler

    if c_compiler() is None or os.environ.get("CHEWBOT_NO_COMPILE"):
        pytest.skip("no C compiler, or compiling is switched off: nothing is compiled")
    cache = tmp_path / "cache"
    proc = _start(["run", "--task", str(task_csv), "--out", "out"], tmp_path, CHEWBOT_CACHE=str(cache))
    _wait_for(proc, lambda: _compiler_child(proc.pid))
    _stop(proc, signal.SIGINT, EXIT_INTERRUPTED)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache"]
    hidden = [p.name for p in cache.rglob(".*")]
    assert hidden == []  # no partial library left behind


# The NLP solver's calls are counted; its first call creates the flag file the test waits for, and at exit the
# process writes how many calls it made.
NLP_PRELUDE = """
import atexit, casadi
calls = 0
_nlpsol = casadi.nlpsol
def nlpsol(*args, **kwargs):
    solver = _nlpsol(*args, **kwargs)
    class Solver:
        def __call__(self, **kw):
            global calls
            calls += 1
            if calls == 1:
                open({flag!r}, "w").close()
            return solver(**kw)
        def __getattr__(self, name):
            return getattr(solver, name)
    return Solver()
casadi.nlpsol = nlpsol
atexit.register(lambda: open({count!r}, "w").write(str(calls)))
"""


def test_sigint_in_the_nlp_solver(tmp_path):
    """5 s of chewing at 1 kHz against a torque limit of 0.005 N m: every one of the 5001 samples needs the SQP
    (0.1-0.5 ms each: the loop lasts long enough for the test to signal inside it even on a loaded machine), so
    SIGINT sent once the first has started lands in the solver's loop; the loop stops short (fewer calls than
    samples) and the run ends with 130."""
    t = np.arange(5001) / 1000
    s = np.sin(np.pi * t / 5) ** 2
    task = tmp_path / "task.csv"
    task.write_text("t,X[mm],Y[mm],alpha[deg],beta[deg],Fz\n" + "".join(f"{a:.3f},{2 * b:.9f},{b:.9f},{b:.9f},{5 * b:.9f},{-20 * b:.9f}\n" for a, b in zip(t, s)))
    weak = tmp_path / "weak.toml"
    weak.write_text(re.sub(r"^torque_Nm = .*$", "torque_Nm = 0.005", builtin_model_path("target").read_text(), flags=re.M))
    flag, count = tmp_path / "flag", tmp_path / "count"
    proc = _start(["run", "--model", str(weak), "--task", str(task), "--method", "newton-euler", "--out", "out"], tmp_path,
                  NLP_PRELUDE.format(flag=str(flag), count=str(count)))
    _wait_for(proc, flag.exists)
    _stop(proc, signal.SIGINT, EXIT_INTERRUPTED)
    assert 0 < int(count.read_text()) < len(t)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["count", "flag", "task.csv", "weak.toml"]


def test_sigterm_during_the_dynamics(task_csv, tmp_path):
    flag = tmp_path / "flag"
    proc = _start(["run", "--task", str(task_csv), "--out", "out"], tmp_path, **{TEST_PAUSE_VARIABLE: f"dynamics:{flag}"})
    _wait_for(proc, flag.exists)
    _stop(proc, signal.SIGTERM, EXIT_TERMINATED)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flag"]


def test_sigterm_while_writing_leaves_the_old_folder_as_it_was(task_csv, tmp_path):
    """--force over an existing results folder, stopped while the new one is being written (results.csv is in
    the temporary folder): the temporary folder is removed on the way out and the old folder is untouched."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text('{"chewbot_run": 2, "note": "an earlier run"}')  # chewbot's marker: --force may replace it
    (out / "results.csv").write_text("t [s]\n0.0\n")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    flag = tmp_path / "flag"
    proc = _start(["run", "--task", str(task_csv), "--out", str(out), "--force"], tmp_path, **{TEST_PAUSE_VARIABLE: f"writing:{flag}"})
    _wait_for(proc, flag.exists)
    (partial,) = _leftovers(tmp_path)
    assert partial.startswith(f".out.partial-{proc.pid}-") and (tmp_path / partial / "results.csv").exists()
    _stop(proc, signal.SIGTERM, EXIT_TERMINATED)
    assert _leftovers(tmp_path) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["flag", "out"]
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before



def test_sigint_in_the_identification_leaves_no_output(tmp_path):
    """`identify` stopped as its least squares start: exit 130, one line, neither the model nor the table written."""
    m = load_model("target")
    kin = solve_kinematics(m, default_task(m, "left", ChewingParameters(cycles=1, rest_s=0.0, rate_hz=250.0)), "euler-angles")
    cols = ["t", *[f"theta{i}" for i in range(1, 7)], *[f"tau{i}" for i in range(1, 7)]]
    # the angles of a real motion (the pose fit accepts them); the torques do not matter before the fit
    np.savetxt(tmp_path / "log.csv", np.column_stack([kin.t, kin.theta, 0.1 * np.tanh(kin.dtheta)]), delimiter=",",
               header=",".join(cols), comments="")
    flag = tmp_path / "flag"
    proc = _start(["identify", "log.csv", "--out", "model.toml"], tmp_path, **{TEST_PAUSE_VARIABLE: f"fit:{flag}"})
    _wait_for(proc, flag.exists)
    _stop(proc, signal.SIGINT, EXIT_INTERRUPTED)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flag", "log.csv"]


def test_sigint_in_the_excitation_design_leaves_no_output(tmp_path):
    """`excite` stopped as its design starts: exit 130, one line, no task written."""
    flag = tmp_path / "flag"
    proc = _start(["excite", "--duration", "2", "--out", "exc.csv"], tmp_path, **{TEST_PAUSE_VARIABLE: f"fit:{flag}"})
    _wait_for(proc, flag.exists)
    _stop(proc, signal.SIGINT, EXIT_INTERRUPTED)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flag"]


def test_sigint_while_chewing_leaves_no_output(tmp_path):
    """`chew` stopped as its simulation starts: exit 130, one line, no folder."""
    flag = tmp_path / "flag"
    proc = _start(["chew", "--food", "peanut", "--cycles", "1", "--out", "out"], tmp_path,
                  **{TEST_PAUSE_VARIABLE: f"simulation:{flag}"})
    _wait_for(proc, flag.exists)
    _stop(proc, signal.SIGINT, EXIT_INTERRUPTED)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flag"]
