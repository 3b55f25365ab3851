"""Every `chewbot ...` command of the README and of docs/*.md runs as written.

The commands are parsed from the Markdown code blocks (``sh`` or unlabelled fences; a line continued with ``\\``
joined; ``&&`` chains kept together; comments dropped; the parts of a line that are not chewbot, the setup of the
README's first line, left out), so that an example is tested the day it is written. Each runs in a new folder
holding a copy of ``examples/`` and of what the README says how to make (``my_robot.toml``, a copy of the built-in
target); where it reads what an earlier command of the same document writes (``runs/left/results.csv``,
``identified.toml``), that command runs first. It must exit 0 and write what the docs say it writes (its ``--out``
and the files in it, :func:`expected_outputs`).

Commands that compute over the default task, draw figures or start a cluster take from seconds to minutes: they run
under the ``slow`` mark (``.ci/slow``). The quick ones (reading and checking inputs, the short example files) run in
the suite. A sweep on an existing Dask cluster (``--scheduler tcp://HOST:PORT``, whatever address the docs write) runs
in the suite on a scheduler and a worker the test starts on 127.0.0.1 (conftest.py's ``dask_cluster``), its address
put in place of the documented one.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELL_FENCES = ("", "sh", "bash", "shell", "console")

SCHEDULER = "--scheduler"  # its documented address is a cluster elsewhere: the test's own cluster takes its place
# Subcommands that finish in a few seconds on the shipped examples; the others are slow.
QUICK = ("models", "check-model", "cache", "import-motion", "track-incisor", "fit-comminution")


@dataclass(frozen=True)
class Command:
    """One documented command line: ``parts`` the chewbot commands of the line (``&&`` chains), as argument lists."""

    doc: str
    line: int
    text: str
    parts: tuple[tuple[str, ...], ...]

    @property
    def id(self) -> str:
        return f"{Path(self.doc).name}:{self.line}"  # no slash: a test id that pytest's command line takes


def documented_commands(paths=DOCS) -> list[Command]:
    """The chewbot command lines of the shell code blocks of ``paths``, in order."""
    found = []
    for path in paths:
        fence, block, start = None, [], 0
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            m = re.match(r"^\s*```\s*(\w*)", line)
            if m and fence is None:
                fence, block = m.group(1), []
                continue
            if m and fence is not None:
                if fence in SHELL_FENCES:
                    found += _commands(path, block)
                fence = None
                continue
            if fence is not None:
                block.append((number, line))
    return found


def _commands(path: Path, block: list[tuple[int, str]]) -> list[Command]:
    out, pending, first = [], "", 0
    for number, line in block:
        if not pending:
            first = number
        if line.rstrip().endswith("\\"):
            pending += line.rstrip()[:-1] + " "
            continue
        text, pending = pending + line, ""
        if not re.search(r"(^|&&)\s*(\S*/)?chewbot\s", text):
            continue  # a setup line (cp, dask), or an unlabelled block's prose
        words = shlex.split(text, comments=True)
        parts, current = [], []
        for w in words + ["&&"]:
            if w == "&&":
                if current:
                    parts.append(current)
                current = []
            else:
                current.append(w)
        chewbot = [tuple(p[1:]) for p in parts if p and Path(p[0]).name == "chewbot"]
        if chewbot:
            name = path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else path.name
            out.append(Command(name, first, text.split(" #")[0].strip(), tuple(chewbot)))
    return out


def _option(args, name):
    return args[args.index(name) + 1] if name in args else None


def expected_outputs(args: tuple[str, ...]) -> list[str]:
    """What the docs say a command writes (README's and cli.md's tables), relative to where it runs."""
    sub, out = args[0], _option(args, "--out")
    if sub == "run":
        out = out or "runs/default"
        return [f"{out}/results.csv", f"{out}/run.json"] + ([] if "--no-report" in args else [f"{out}/report.html"])
    if sub == "simulate":
        out = out or "runs/simulation"
        inside = ([f"{c}/results.csv" for c in ("feedforward", "pd", "computed-torque")] if "--compare" in args
                  else [f"{e}/results.csv" for e in ("chewbot", "mujoco")] if "--compare-engines" in args else ["results.csv"])
        return [f"{out}/run.json", f"{out}/report.html"] + [f"{out}/{p}" for p in inside]
    if sub in ("import-motion", "track-incisor"):
        stem = out[: -len(".csv")]
        found = [f"{stem}.registration.toml"] if "--fit-registration" in args else []
        found += [f"{stem}.report.html"] if sub == "import-motion" else []
        return ([out, f"{stem}.residuals.csv"] if sub == "track-incisor" or "--no-residuals" not in args else [out]) + found
    if sub == "identify":
        return [out, out[: -len(".toml")] + ".identification.csv"]
    if sub == "excite":
        return [out, out + ".chewbot.json"]
    if sub == "sweep":
        return [f"{out}/run.json"]
    if sub == "study":
        return [f"{out}/study.json"] if out else []
    if sub == "export-c":
        return [f"{out}/chewbot-export.json"]
    if sub == "export-controller":
        return [f"{out}/chewbot-export.json", f"{out}/include/chewbot_ctrl.h", f"{out}/Makefile"]
    if sub in ("export-model", "estimate-force", "fit-comminution"):
        return [out or "robot.xml"]
    if sub == "tpa":
        return [f"{out}/tpa.json"] + ([] if "--log" in args else [f"{out}/results.csv", f"{out}/task.csv"])
    if sub == "chew":
        return [f"{out}/{name}" for name in ("cycles.csv", "psd.csv", "results.csv", "run.json", "chew.html")] + (
            [f"{out}/bolus_tpa.csv"] if "--tpa-at" in args else [])
    if sub == "bench":
        return [out] if out else []
    if sub == "report":
        return [f"{args[1]}/report.html"] if "--no-report" not in args else []
    return []


def _writes(command: Command) -> set[str]:
    return {Path(p).as_posix() for args in command.parts for p in expected_outputs(args)}


def _reads(command: Command) -> set[str]:
    """The paths a command names (arguments that are not options), which an earlier command may write."""
    names = set()
    for args in command.parts:
        for a in args[1:]:
            if not a.startswith("-"):
                names.add(Path(a).as_posix())
                names.add(Path(a).parent.as_posix())
    return names


def prerequisites(command: Command, commands: list[Command]) -> list[Command]:
    """The earlier commands of the same document whose outputs ``command`` reads, each with its own, in order."""
    before = [c for c in commands if c.doc == command.doc and c.line < command.line]
    needed: list[Command] = []
    wanted = _reads(command) - {Path(p).as_posix() for args in command.parts for p in [_option(args, "--out") or ""]
                                if "--resume" not in args}  # a resumed sweep reads its own folder
    for c in reversed(before):
        outs = _writes(c) | {Path(_option(a, "--out")).as_posix() for a in c.parts if _option(a, "--out")}
        if outs & wanted:
            for p in prerequisites(c, commands) + [c]:
                if p not in needed:
                    needed.append(p)
            wanted -= outs
    return sorted(needed, key=lambda c: c.line)


COMMANDS = documented_commands()


def _quick(command: Command) -> bool:
    return all(args[0] in QUICK for c in prerequisites(command, COMMANDS) + [command] for args in c.parts)


def _on_a_cluster(command: Command) -> bool:
    return any(SCHEDULER in args for args in command.parts)


def _params():
    for c in COMMANDS:
        if not _on_a_cluster(c):
            yield pytest.param(c, id=c.id, marks=[] if _quick(c) else [pytest.mark.slow])


def _run(args: tuple[str, ...], cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": "200"}
    if args[:2] == ("cache", "clear"):  # empties a cache of its own, not the suite's
        env["CHEWBOT_CACHE"] = str(cwd / "cache")
    return subprocess.run([sys.executable, "-m", "chewbot", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=3600)


def _workspace(tmp_path: Path) -> Path:
    from chewbot.model.params import builtin_model_path

    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    shutil.copyfile(builtin_model_path("target"), tmp_path / "my_robot.toml")  # README: "cp ... my_robot.toml"
    return tmp_path


def _runs_as_written(command: Command, where: Path, address: str | None = None) -> None:
    """``command`` after its prerequisites, each exiting 0 and writing what the docs say; ``address``: the scheduler
    put in place of the one a ``--scheduler`` names."""
    for c in prerequisites(command, COMMANDS) + [command]:
        for args in c.parts:
            if address is not None and SCHEDULER in args:
                at = args.index(SCHEDULER) + 1
                args = (*args[:at], address, *args[at + 1:])
            done = _run(args, where)
            assert done.returncode == 0, f"{c.id}: chewbot {shlex.join(args)} exited {done.returncode}\n{done.stderr[-3000:]}"
            missing = [p for p in expected_outputs(args) if not (where / p).exists()]
            assert not missing, f"{c.id}: chewbot {shlex.join(args)} did not write {missing}"


@pytest.mark.parametrize("command", list(_params()))
def test_the_documented_command_runs_as_written(command: Command, tmp_path):
    _runs_as_written(command, _workspace(tmp_path))


@pytest.mark.parametrize("command", [pytest.param(c, id=c.id) for c in COMMANDS if _on_a_cluster(c)])
def test_the_documented_sweep_on_a_cluster_runs_on_a_local_scheduler(command: Command, dask_cluster, tmp_path):
    """The docs write the address of a cluster elsewhere (tcp://10.0.0.5:8786, tcp://HOST:8786); the command runs as
    written with that of a scheduler and worker started on this machine, and its run.json names that scheduler."""
    import json

    assert re.search(rf"{SCHEDULER} tcp://\S+:\d+", command.text), command.text
    where = _workspace(tmp_path)
    _runs_as_written(command, where, dask_cluster)
    out = next(_option(args, "--out") for args in command.parts if SCHEDULER in args)
    assert json.loads((where / out / "run.json").read_text())["cluster"]["scheduler"] == dask_cluster


def test_the_commands_are_found_and_each_is_run_or_named():
    """The parser finds the documented commands (the README's quick start; every subcommand shown exists, the sweeps
    on a cluster among them), and a command runs after those whose outputs it reads."""
    from chewbot.cli import app

    subcommands = {args[0] for c in COMMANDS for args in c.parts}
    assert ("run", "--out", "runs/default") in {p for c in COMMANDS for p in c.parts}
    import typer

    shown = set(typer.main.get_command(app).commands)
    assert subcommands <= shown, subcommands - shown
    assert {"run", "simulate", "identify", "import-motion", "track-incisor", "sweep", "report", "check-model"} <= subcommands
    assert len(COMMANDS) > 40
    assert len([c for c in COMMANDS if _on_a_cluster(c)]) >= 2
    for c in COMMANDS:
        assert all(args and args[0] in shown for args in c.parts), c
    resumed = next(c for c in COMMANDS if any("--resume" in a for a in c.parts))
    assert prerequisites(resumed, COMMANDS), "a resumed sweep runs after the sweep it resumes"
    tracked = next(c for c in COMMANDS if c.parts[0][:3] == ("run", "--task", "runs/left/results.csv"))
    assert [p.parts[0] for p in prerequisites(tracked, COMMANDS)] == [("run", "--out", "runs/left")]


def test_the_parser_reads_continuations_chains_and_comments(tmp_path):
    doc = tmp_path / "x.md"
    doc.write_text("text\n```sh\nchewbot run --out runs/a \\\n    --side right   # a comment\n"
                   "python3 -m venv .venv && .venv/bin/chewbot models && chewbot report runs/a\ncp a b\n```\n"
                   "```python\nchewbot run --out nothing\n```\n")
    found = documented_commands([doc])
    assert [c.parts for c in found] == [(("run", "--out", "runs/a", "--side", "right"),), (("models",), ("report", "runs/a"))]


def test_the_readme_starts_with_two_commands_and_the_first_leaves_chewbot_found_by_the_next(tmp_path):
    """The README starts with exactly two command lines; the first activates the virtual environment it creates in the
    user's shell, so that the next command line finds ``chewbot``: its activation run as written, with the suite's own
    environment as ``.venv``, then ``chewbot --version`` as a command line of its own, on a PATH without chewbot."""
    from chewbot.files import VERSION

    block = re.search(r"```sh\n(.*?)```", (ROOT / "README.md").read_text(encoding="utf-8"), re.S).group(1).strip().splitlines()
    assert len(block) == 2, block
    parts = [p.strip() for p in block[0].split("&&")]
    assert parts[0] == "python3 -m venv .venv"
    activation = next(p for p in parts if p.split()[0] in (".", "source"))
    assert activation.split()[1] == ".venv/bin/activate"
    assert all(Path(shlex.split(p)[0]).name != "chewbot" or shlex.split(p)[0] == "chewbot" for p in parts)
    (tmp_path / ".venv").symlink_to(Path(sys.prefix), target_is_directory=True)
    env = {**{k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}, "PATH": "/usr/bin:/bin"}
    assert subprocess.run(["sh", "-c", "command -v chewbot"], cwd=tmp_path, env=env, capture_output=True).returncode != 0
    done = subprocess.run(["sh", "-c", f"{activation}\nchewbot --version"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0 and VERSION in done.stdout, done.stderr
