"""Shared fixtures: the built-in models, both mechanisms, a small task file, a Dask scheduler and worker (helpers called
with arguments are in support.py)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from support import model

# pytest-xdist's workers inherit COLUMNS=80: a rich console first made under it keeps 80 columns for the whole worker,
# whatever width a test gives its runner
os.environ.pop("COLUMNS", None)

CLUSTER_WAIT_S = 120  # the scheduler and its worker must answer within this (a loaded 2-core machine)


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


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def dask_cluster():
    """A Dask scheduler and one worker, separate processes on a free port; killed at teardown."""
    from distributed import Client

    address = f"tcp://127.0.0.1:{_free_port()}"
    procs = []
    try:
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port",
                                       address.rsplit(":", 1)[1], "--no-dashboard", "--dashboard-address", ":0"], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL, start_new_session=True))
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address, "--nworkers", "1", "--nthreads", "1",
                                       "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                      start_new_session=True))
        deadline = time.monotonic() + CLUSTER_WAIT_S
        while True:
            try:
                with Client(address, timeout="2s") as client:
                    if client.nthreads():
                        break
            except OSError:
                pass
            if time.monotonic() > deadline or any(p.poll() is not None for p in procs):
                pytest.fail("the Dask scheduler and worker did not start")
            time.sleep(0.2)
        yield address
    finally:
        for p in procs:
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
