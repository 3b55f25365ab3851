"""The package's structure: the layers of pyproject.toml's import-linter contracts hold, no import cycle (imports
inside functions counted), no private name imported across modules, at most eight modules at the top of the package
(docs/architecture.md)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import grimp

import chewbot

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = Path(chewbot.__file__).resolve().parent


def test_the_import_linter_contracts_hold():
    """``lint-imports`` on pyproject.toml's contracts: the layers over the whole package, the commands sharing
    only commands.common, the independent feature packages."""
    lint = Path(sys.executable).with_name("lint-imports")
    done = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert "0 broken" in done.stdout


def _cycles(graph: grimp.ImportGraph) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, found = {}, {}, [], set(), []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.find_modules_directly_imported_by(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(graph.modules):
        if module not in index:
            visit(module)
    return found


def test_no_import_cycle():
    """Every import statement counts, at a module's top or inside a function (grimp reads them all)."""
    assert _cycles(grimp.build_graph("chewbot")) == []


def test_no_private_name_is_imported_across_modules():
    """A name another module needs is public (``from chewbot.x import _name`` only within chewbot.x's own package
    for its private submodules)."""
    found = []
    for path in PACKAGE.rglob("*.py"):
        module = ".".join(("chewbot", *path.relative_to(PACKAGE).with_suffix("").parts)).removesuffix(".__init__")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("chewbot") and node.module != module:
                found += [f"{module}: {node.module}.{a.name}" for a in node.names
                          if a.name.startswith("_") and not a.name.startswith("__")]
    assert found == []


def test_at_most_eight_modules_at_the_top_of_the_package():
    top = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(top) <= 8, top
    assert {"__init__.py", "__main__.py", "cli.py"} <= set(top)


def test_no_test_module_imports_another():
    """What tests share lives in conftest.py (fixtures) and in modules that are not collected (support.py,
    recording_support.py), never in a test module another one imports."""
    found = []
    for path in Path(__file__).resolve().parent.glob("test_*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [node.module or ""] if isinstance(node, ast.ImportFrom) else \
                [a.name for a in node.names] if isinstance(node, ast.Import) else []
            found += [f"{path.name}: {n}" for n in names if n.split(".")[0].startswith("test_")]
    assert found == []
