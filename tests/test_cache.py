"""The kernel cache: where it is, what its key covers, no graph or code generation on a hit, concurrent
compilation, eviction, clean failures and the cache command."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import casadi as ca
import pytest
from typer.testing import CliRunner

import chewbot
from chewbot.cli import app
from chewbot.compiled import kernels as casadi_tools
from chewbot.compiled.cache import KERNELS, c_compiler
from chewbot.compiled.kernels import KernelSpec, compile_library

needs_compiler = pytest.mark.skipif(c_compiler() is None, reason="no C compiler: kernels run in CasADi's virtual machine")


TINY = """
import casadi as ca
from chewbot.compiled.kernels import KernelSpec


def tiny(tag):
    def build(params):
        x, p = ca.SX.sym("x", 2), ca.SX.sym("p", 1)
        return ca.Function(f"cache_test_{tag}", [x, p], [ca.sin(x) * p], ["x", "p"], ["y"])

    return KernelSpec(f"cache_test_{tag}", build, ("cache test", tag))
"""
_space: dict = {}
exec(TINY, _space)


def _tiny(tag: str) -> KernelSpec:
    """A small kernel of its own (one per tag): compiles in a fraction of a second."""
    return _space["tiny"](tag)


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_location(monkeypatch, tmp_path):
    monkeypatch.delenv("CHEWBOT_CACHE", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert KERNELS.root() == tmp_path / "home" / ".cache" / "chewbot"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert KERNELS.root() == tmp_path / "xdg" / "chewbot"
    monkeypatch.setenv("CHEWBOT_CACHE", str(tmp_path / "own"))
    assert KERNELS.root() == tmp_path / "own"
    assert KERNELS.folder() == tmp_path / "own" / f"chewbot-{chewbot.__version__}-casadi-{ca.__version__}"


def test_key_follows_the_source_the_kernel_is_built_from(tmp_path):
    """A kernel's key holds the source of the modules its graph is built by, found from the imports: an edit of one
    of them changes the key (an editable install never reuses a stale kernel), an edit of the report does not; a
    function handed to a shared builder (a formulation's derivation) counts with its module."""
    from chewbot.compiled.cache import KernelCache
    from chewbot.dynamics.formulations.dalembert import reduced_kernel
    from chewbot.dynamics.formulations.hessian import hessian_rates
    from chewbot.kinematics.functions import kinematics_kernel

    package = Path(casadi_tools.__file__).parent.parent
    copy = tmp_path / "chewbot"
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__"))
    modules = kinematics_kernel("target", "euler-angles").modules()
    assert modules == ("chewbot.kinematics.functions",)
    digest = KernelCache().source_digest(modules, package)
    assert KernelCache().source_digest(modules, copy) == digest
    (copy / "report" / "html.py").write_text((copy / "report" / "html.py").read_text() + "\n# edited\n")
    assert KernelCache().source_digest(modules, copy) == digest
    (copy / "kinematics" / "symbolic.py").write_text((copy / "kinematics" / "symbolic.py").read_text() + "\n# edited\n")
    assert KernelCache().source_digest(modules, copy) != digest
    assert "chewbot.dynamics.formulations.hessian" in reduced_kernel("target", "hessian", hessian_rates).modules()


def test_a_library_built_for_this_processor_is_keyed_by_it(monkeypatch):
    """-march=native code may not run on another processor: its key names the processor (a cache shared between
    machines never hands it over); portable flags leave the processor out of the key."""
    spec = _tiny("processor")
    native_flags, portable = ("-O3", "-march=native"), ("-O1",)
    here = casadi_tools.kernel_key(spec, native_flags), casadi_tools.kernel_key(spec, portable)
    identity = KERNELS._identity
    monkeypatch.setattr(KERNELS, "_identity", lambda what, cc="": "x86_64 another processor" if what == "processor" else identity(what, cc))
    assert casadi_tools.kernel_key(spec, native_flags) != here[0]
    assert casadi_tools.kernel_key(spec, portable) == here[1]


@needs_compiler
def test_a_warm_run_builds_no_graph(tmp_path):
    """After the kernels of a run are in the cache, a fresh process computes the run with CasADi's graph
    building and code generation made to fail: the libraries are found by their key and loaded."""
    from chewbot.model.params import load_model
    from chewbot.run.pipeline import run_kernels
    from chewbot.run.options import RunOptions

    options = RunOptions(method="hessian")
    casadi_tools.prepare(run_kernels(load_model("target"), options))
    script = textwrap.dedent("""
        import casadi as ca, numpy as np
        from chewbot.compiled import kernels as casadi_tools
        def refuse(*args, **kwargs):
            raise AssertionError("a CasADi graph was built or C generated on a cache hit")
        ca.SX.sym = ca.MX.sym = refuse
        ca.CodeGenerator = refuse
        casadi_tools.KernelSpec.graph = refuse
        from chewbot.run.pipeline import compute
        from chewbot.run.options import RunOptions
        result = compute(RunOptions(method="hessian"))
        assert np.isfinite(result.dynamics.tau).all() and np.abs(result.dynamics.tau).max() > 0.1
        print("ok")
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=os.environ.copy())
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == "ok"


@needs_compiler
def test_two_processes_compiling_the_same_kernel_both_succeed(tmp_path):
    """Two processes on an empty cache compile one kernel at the same moment: both load it, one library is
    left (the second rename replaces the first atomically) and no temporary file."""
    start = tmp_path / "go"
    script = TINY + textwrap.dedent(f"""
        import time
        from pathlib import Path
        from chewbot.compiled.kernels import native
        while not Path({str(start)!r}).exists():
            time.sleep(0.01)
        fn = native(tiny("concurrent"))
        print(float(fn([1.0, 1.0], 2.0)[0][0]))
    """)
    env = {**os.environ, "CHEWBOT_CACHE": str(tmp_path / "cache")}
    procs = [subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    time.sleep(1.0)  # both imported and waiting
    start.touch()
    outputs = [p.communicate(timeout=120) for p in procs]
    for p, (out, err) in zip(procs, outputs):
        assert p.returncode == 0, err[-3000:]
        assert float(out) == pytest.approx(2 * 0.8414709848078965, rel=1e-15)
    folder = next((tmp_path / "cache").iterdir())
    assert len(list(folder.glob("cache_test_concurrent-*.so"))) == 1 and _leftovers(folder) == []


@needs_compiler
def test_eviction(tmp_path, monkeypatch):
    """Compiling removes other chewbot/CasADi versions' libraries, then the least recently used above the cap,
    and nothing that is not chewbot's."""
    monkeypatch.setenv("CHEWBOT_CACHE", str(tmp_path))
    for old in ("chewbot-0.0.1-casadi-3.6.0", "casadi-3.6.5"):
        (tmp_path / old).mkdir()
        (tmp_path / old / "hessian_target-1234.so").write_bytes(b"\0" * 100)
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "mine.so").write_bytes(b"not chewbot's")
    (tmp_path / "README.txt").write_text("a user's file")
    first = compile_library(_tiny("lru_a"))
    assert not (tmp_path / "chewbot-0.0.1-casadi-3.6.0").exists() and not (tmp_path / "casadi-3.6.5").exists()
    assert (tmp_path / "notes" / "mine.so").exists() and (tmp_path / "README.txt").exists()
    second = compile_library(_tiny("lru_b"))
    os.utime(first, (time.time() - 100, time.time() - 100))  # a used first
    monkeypatch.setenv("CHEWBOT_CACHE_MAX_MB", str(2.5 * second.stat().st_size / 1e6))  # room for two and a half
    third = compile_library(_tiny("lru_c"))
    assert not first.exists() and second.exists() and third.exists()


@needs_compiler
def test_stale_temporaries_go_and_a_live_process_keeps_its_own(tmp_path, monkeypatch):
    monkeypatch.setenv("CHEWBOT_CACHE", str(tmp_path))
    folder = KERNELS.folder()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True).stdout.strip()
    stale = [folder / f".k-abc.{dead}.deadbeef.tmp", folder / f".k-abc.{dead}.deadbeef.build"]
    stale[0].write_bytes(b"half")
    stale[1].mkdir()
    live = folder / f".k-abc.{os.getpid()}.cafe.tmp"
    live.write_bytes(b"in progress")
    compile_library(_tiny("stale"))
    assert not any(p.exists() for p in stale) and live.exists()


@needs_compiler
def test_a_failed_or_interrupted_compilation_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("CHEWBOT_CACHE", str(tmp_path))
    folder = KERNELS.folder()
    monkeypatch.setenv("CC", "false")  # a "compiler" that always fails
    with pytest.raises(RuntimeError, match="compiling kernel cache_test_fails failed"):
        compile_library(_tiny("fails"))
    assert list(folder.iterdir()) == []
    monkeypatch.delenv("CC")

    def interrupted(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(subprocess.Popen, "communicate", interrupted)
    with pytest.raises(KeyboardInterrupt):
        compile_library(_tiny("interrupted"))
    assert list(folder.iterdir()) == []


@needs_compiler
def test_cache_command(tmp_path, monkeypatch):
    """chewbot cache shows the location, the libraries and their size; chewbot cache clear removes chewbot's
    libraries and nothing else."""
    monkeypatch.setenv("CHEWBOT_CACHE", str(tmp_path))
    (tmp_path / "README.txt").write_text("a user's file")
    compile_library(_tiny("command"))
    runner = CliRunner()
    shown = runner.invoke(app, ["cache"])
    assert shown.exit_code == 0 and f"location: {tmp_path}" in shown.output and "libraries: 1" in shown.output
    cleared = runner.invoke(app, ["cache", "clear"])
    assert cleared.exit_code == 0 and "removed 1 libraries" in cleared.output
    assert [p.name for p in tmp_path.iterdir()] == ["README.txt"]
    assert "libraries: 0" in runner.invoke(app, ["cache"]).output
