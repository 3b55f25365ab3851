"""docs/api.md and the other documents name the Python API as it is: every dotted ``chewbot.`` name imports,
every signature docs/api.md writes out matches the function's (its parameters in order, the defaults it gives), and
docs/api.md's examples run as written."""

from __future__ import annotations

import ast
import importlib
import inspect
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
API = ROOT / "docs" / "api.md"
DOCUMENTS = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]
# A dotted name, with the parameter list that follows it in the same code span.
NAME = re.compile(r"`((?:chewbot|model|task|kinematics|dynamics|analysis|simulation)(?:\.[A-Za-z_]\w*)+)(\([^`]*\))?`")
DOTTED = re.compile(r"(?<![.\w/-])chewbot(?:\.[A-Za-z_]\w*)+")  # not a file name such as task.csv.chewbot.json
SUBPACKAGES = {"model", "task", "kinematics", "dynamics", "analysis", "simulation"}


def resolve(dotted: str):
    """The object a dotted name denotes: the longest importable module, then attributes."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        for name in parts[k:]:
            obj = getattr(obj, name)
        return obj
    raise ModuleNotFoundError(dotted)


def documented_names() -> list[tuple[str, str | None, int]]:
    """(dotted name, its parameter list or None, line) for each name docs/api.md puts in a code span; the kernel
    table's names are relative to the package."""
    found = []
    for number, line in enumerate(API.read_text().splitlines(), 1):
        for m in NAME.finditer(line):
            name = m.group(1)
            if name.split(".")[0] in SUBPACKAGES:
                name = f"chewbot.{name}"
            found.append((name, m.group(2), number))
    return found


def test_every_dotted_name_in_the_documents_imports():
    bad = []
    for path in DOCUMENTS:
        text = path.read_text()
        for m in DOTTED.finditer(text):
            try:
                resolve(m.group(0).rstrip("."))
            except (ImportError, AttributeError):
                bad.append(f"{path.relative_to(ROOT)}:{text[:m.start()].count(chr(10)) + 1}: {m.group(0)}")
    assert not bad, "names that do not import:\n" + "\n".join(bad)


def test_the_documents_name_source_files_that_exist():
    missing = [f"{path.relative_to(ROOT)}: {m.group(0)}" for path in DOCUMENTS
               for m in re.finditer(r"src/chewbot/[\w/]+\.py", path.read_text()) if not (ROOT / m.group(0)).exists()]
    assert not missing


def test_the_api_document_names_its_signatures_as_they_are():
    names = documented_names()
    assert len(names) > 50  # the tables were read: a change of their format must not empty this test
    bad = []
    for name, params, line in names:
        try:
            obj = resolve(name)
        except (ImportError, AttributeError) as exc:
            bad.append(f"api.md:{line}: {name} does not import ({exc})")
            continue
        if params is None or params == "()" and inspect.isclass(obj):
            continue
        call = ast.parse(f"f{params}", mode="eval").body
        try:
            signature = inspect.signature(obj)
        except (TypeError, ValueError):
            bad.append(f"api.md:{line}: {name} is not callable")
            continue
        actual = list(signature.parameters.values())
        names_in_order = [p.name for p in actual]
        at = 0
        for arg in call.args:
            if isinstance(arg, ast.Starred) or not isinstance(arg, ast.Name):
                continue  # an example value (``RunOptions(...)``), not a parameter's name
            if arg.id not in names_in_order[at:]:
                bad.append(f"api.md:{line}: {name} has no parameter {arg.id!r} at its place (it has {names_in_order})")
                break
            at = names_in_order.index(arg.id, at) + 1
        written = {a.id for a in call.args if isinstance(a, ast.Name)} | {k.arg for k in call.keywords}
        if all(isinstance(a, ast.Name) for a in call.args):
            required = [p.name for p in actual if p.default is p.empty
                        and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
            if missing := [r for r in required if r not in written]:
                bad.append(f"api.md:{line}: {name} also needs {missing}")
        for keyword in call.keywords:
            if keyword.arg is None:
                continue
            if keyword.arg not in signature.parameters:
                bad.append(f"api.md:{line}: {name} has no parameter {keyword.arg!r}")
                continue
            if isinstance(keyword.value, ast.Constant) and keyword.value.value is Ellipsis:
                continue
            try:
                documented = ast.literal_eval(keyword.value)
            except ValueError:
                continue  # a constructed value (``ImportOptions(...)``): its name is checked, not its value
            default = signature.parameters[keyword.arg].default
            if default != documented:
                bad.append(f"api.md:{line}: {name}'s {keyword.arg} defaults to {default!r}, not {documented!r}")
    assert not bad, "\n".join(bad)


def test_the_api_document_s_examples_run(tmp_path, monkeypatch):
    """Every Python block of docs/api.md, in order in one namespace (later blocks use earlier names), in an empty
    folder: the example's files land there."""
    blocks = re.findall(r"```python\n(.*?)```", API.read_text(), re.S)
    assert len(blocks) >= 5
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for number, block in enumerate(blocks, 1):
        try:
            exec(compile(block, f"docs/api.md, Python block {number}", "exec"), namespace)
        except Exception as exc:  # the block that failed, in the message
            pytest.fail(f"docs/api.md's Python block {number} fails: {type(exc).__name__}: {exc}\n{block}")
    assert (tmp_path / "results.csv").is_file() and (tmp_path / "runs" / "right" / "report.html").is_file()
