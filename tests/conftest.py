"""Shared fixtures: the built-in models, both mechanisms, a small task file (helpers called with arguments are in
support.py)."""

from __future__ import annotations

import numpy as np
import pytest
from support import model


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


@pytest.fixture(scope="module")
def task_csv(tmp_path_factory):
    """A small reachable target task file: 0.5 s at 100 Hz, millimetres and degrees, a bite force of up to 20 N
    (one copy per test module)."""
    t = np.linspace(0.0, 0.5, 51)
    s = np.sin(np.pi * t / 0.5) ** 2
    rows = ["t,X[mm],Y[mm],alpha[deg],beta[deg],Fz"] + [f"{a:.3f},{2 * b:.6f},{b:.6f},{b:.6f},{5 * b:.6f},{-20 * b:.6f}" for a, b in zip(t, s)]
    path = tmp_path_factory.mktemp("tasks") / "task.csv"
    path.write_text("\n".join(rows) + "\n")
    return path
