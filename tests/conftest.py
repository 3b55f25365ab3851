"""Shared fixtures: the built-in models and the kinematics of the default task, built once per session."""

from __future__ import annotations

import functools

import pytest

from chewbot import load_model
from chewbot.kinematics.motion import solve_kinematics
from chewbot.task.default import default_task


@functools.cache
def model(name: str):
    return load_model(name)


@functools.cache
def default_kinematics(name: str = "target", side: str = "left", orientation: str = "euler-angles"):
    m = model(name)
    return solve_kinematics(m, default_task(m, side), orientation)


@pytest.fixture(scope="session")
def target():
    return model("target")


@pytest.fixture(scope="session")
def sixrss():
    return model("6rss")


@pytest.fixture(params=["target", "6rss"])
def mechanism(request):
    """Both mechanisms, by name."""
    return request.param
