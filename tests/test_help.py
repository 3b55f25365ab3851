"""The command line's help, generated from the app itself: every command and subcommand, every option and argument has
help; every command shows examples; every option that takes a quantity names its unit (or says it is a count, a
fraction or a factor); ``--help`` and ``-h`` are the same everywhere, flags show as flags."""

from __future__ import annotations

import re
import typing

import click
import pytest
import typer
from typer.testing import CliRunner

from chewbot.cli import app

ROOT = typer.main.get_command(app)
# A unit in the help of an option that takes a quantity: SI and the files' units, or a word that says the number
# has none (a ratio, a factor).
UNIT = re.compile(r"(?<![\w.])(s|ms|Hz|rad|deg|mm|m|N|N·m|N\*m|W|kg|g|MM DEG)(?![\w.])|\b(fraction|factor|ratio)\b")


def _commands(command: click.Command = ROOT, path: tuple[str, ...] = ()):
    """(path, command) of every command and subcommand, the groups included."""
    yield path, command
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, (*path, name))


COMMANDS = list(_commands())
LEAVES = [(path, c) for path, c in COMMANDS if c.callback is not None and path]


def _takes_a_quantity(command: click.Command, param: click.Parameter) -> bool:
    """An option whose value is a number with a dimension: annotated float (alone, optional or in a tuple), or a
    text option whose default is a number (a rate given in Hz or as a word such as 'continuous')."""
    hint = typing.get_type_hints(command.callback).get(param.name)
    if float in (hint, *typing.get_args(hint)) or any(float in typing.get_args(a) for a in typing.get_args(hint)):
        return True
    try:
        float(param.default)
        return isinstance(param.default, str)
    except (TypeError, ValueError):
        return False


def test_the_walk_finds_every_command():
    names = {" ".join(path) for path, _ in LEAVES}
    assert {"run", "report", "simulate", "sweep", "identify", "import-motion", "track-incisor", "export-c", "study",
            "bench", "models", "check-model", "cache", "cache clear"} <= names


@pytest.mark.parametrize("path,command", COMMANDS, ids=[" ".join(p) or "chewbot" for p, _ in COMMANDS])
def test_every_command_has_help_with_examples(path, command):
    runner = CliRunner()
    long, short = (runner.invoke(app, [*path, flag], env={"COLUMNS": "200"}) for flag in ("--help", "-h"))
    assert long.exit_code == 0 and short.output == long.output, long.output
    assert "<bool>" not in long.output  # flags show as flags, not with a type they take no value of
    assert (command.help or "").strip(), path
    if command.callback is not None and path:
        assert "Example" in command.help, f"chewbot {' '.join(path)}: no example in its help"


@pytest.mark.parametrize("path,command", LEAVES, ids=[" ".join(p) for p, _ in LEAVES])
def test_every_option_has_help_and_a_quantity_names_its_unit(path, command):
    for param in command.params:
        if param.name in ("help",):
            continue
        text = getattr(param, "help", None) or ""
        assert text.strip(), f"chewbot {' '.join(path)} {param.opts[0]}: no help"
        if _takes_a_quantity(command, param):
            assert UNIT.search(text), f"chewbot {' '.join(path)} {param.opts[0]}: takes a quantity, its help names no unit: {text!r}"


def test_the_quantity_rule_sees_the_options_that_take_one():
    """The rule is not vacuous: the options known to take quantities are found by it."""
    found = {f"{' '.join(path)} {p.opts[0]}" for path, c in LEAVES for p in c.params if _takes_a_quantity(c, p)}
    assert {"simulate --noise", "simulate --rate", "identify --window", "import-motion --max-gap", "import-motion --cutoff",
            "import-motion --max-rigid", "import-motion --max-residual"} <= found
