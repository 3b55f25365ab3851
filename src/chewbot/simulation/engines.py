"""The plants' engines, in one table: what simulates the plant's model (``--plant-engine``).

Every engine is a row of :data:`ENGINES` (:class:`EngineRow`): its name (this module is the only one that spells it),
its help line, the module of its plant, and what its plants can do (their
:class:`~chewbot.simulation.interfaces.PlantCapabilities`, known here before a plant is built, so that the options
refuse what it cannot: ``--rate continuous``, ``--food``). :func:`make_plant` builds an engine's plant by its module's
``build(model, friction, side, food, write_mjcf)``. A new engine is a module with a plant that follows
:class:`chewbot.simulation.interfaces.Plant` and its ``build``, and a row here (a test holds each row's flags against
its plant's capabilities).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class EngineRow:
    """One engine: ``name`` (``--plant-engine``), ``help``, ``module`` (of its plant's ``build``, in this package:
    chewbot's is :mod:`chewbot.simulation.bolus`, which builds the plant without a food, with one, or with a food that
breaks into a bolus); ``closes_loop``: its
    plant integrates a controller's law inside its steps (``--rate continuous``); ``food``: its plant can hold a food
    (``--food``); ``bolus``: its plant can break its food into a bolus (``chewbot chew``); ``mjcf``: it simulates the model's MJCF text (``write_mjcf``, handed down from the export layer)."""

    name: str
    help: str
    module: str
    closes_loop: bool = False
    food: bool = False
    bolus: bool = False
    mjcf: bool = False


ENGINES: dict[str, EngineRow] = {e.name: e for e in (
    EngineRow("chewbot", "its Newton-Euler equations, Radau IIA", "bolus", closes_loop=True, food=True, bolus=True),
    EngineRow("mujoco", "MuJoCo's simulation of the model's MJCF, as chewbot export-model writes it; steps of 0.1 ms, "
              "unilateral condyle contacts; docs/mujoco.md", "mujoco_plant", mjcf=True),
)}
NAMES = tuple(ENGINES)
DEFAULT_ENGINE = "chewbot"


def engine_row(name: str) -> EngineRow:
    """The row of ``name``; ValueError names the engines there are."""
    if name not in ENGINES:
        raise ValueError(f"{name!r} is not a plant engine; choose one of {', '.join(NAMES)}")
    return ENGINES[name]


def make_plant(engine: EngineRow, model, friction: bool, side: str, food=None, write_mjcf=None, bolus: bool = False):
    """The plant of ``engine`` on ``model`` (its module's ``build``), with ``food`` on the molar of ``side`` where the
    engine holds one (with ``bolus``: breaking into a bolus, where the engine can); ``write_mjcf(model, friction)``: the MJCF writer (:func:`chewbot.export.mjcf.mjcf`), for an
    engine that simulates MJCF. The options have refused what the engine cannot do."""
    assert food is None or engine.food, f"the {engine.name} plant holds no food"
    assert not bolus or (engine.bolus and food is not None), f"the {engine.name} plant breaks no bolus"
    assert write_mjcf is not None or not engine.mjcf, f"the {engine.name} engine needs write_mjcf (chewbot.export.mjcf.mjcf)"
    return importlib.import_module(f"{__package__}.{engine.module}").build(model, friction, side, food=food, write_mjcf=write_mjcf,
                                                                                 bolus=bolus)
