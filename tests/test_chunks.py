"""A task processed in chunks gives what the whole task in one piece gives: every column, the validity checks and
run.json's numbers; the folder written chunk by chunk equals the one written from memory; the decimated view
keeps every peak and does not depend on the chunks it is given."""

from __future__ import annotations

import json

from dataclasses import replace

import numpy as np
import pytest

from chewbot.kinematics.ik import continuous
from chewbot.outputs.writer import write, write_run as run
from chewbot.run.pipeline import compute
from chewbot.run.options import RunOptions
from chewbot.report.summary import column_stats, near_singular
from chewbot.report.view import ViewBuilder
from chewbot.table import Table

CHUNK = 1000  # five full chunks and one of a single sample over the default task's 5001 samples


def _same_columns(a: Table, b: Table, rtol: float = 0.0) -> None:
    assert list(a.columns) == list(b.columns)
    for name in a.columns:
        x, y = a[name], b[name]
        if rtol == 0.0:
            assert np.array_equal(x, y, equal_nan=True), name
        else:
            assert np.allclose(x, y, rtol=rtol, atol=0.0, equal_nan=True), name


def _same_numbers(a, b, rtol: float) -> None:
    """Nested dicts and lists of run.json equal, numbers to ``rtol`` (NaN equal to NaN)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            _same_numbers(a[key], b[key], rtol)
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            _same_numbers(x, y, rtol)
    elif isinstance(a, float) or isinstance(b, float):
        assert (np.isnan(a) and np.isnan(b)) or a == pytest.approx(b, rel=rtol, abs=0.0)
    else:
        assert a == b


OPTIONS = [
    RunOptions(method="hessian"),
    RunOptions(method="lagrange"),
    RunOptions(method="liang"),
    RunOptions(method="6rss-core"),
    RunOptions(model="6rss", method="hessian", side="right"),
    RunOptions(method="newton-euler", orientation="euler-parameters", goal="min-torque", friction="on"),
    RunOptions(method="newton-euler", goal="min-hkp-force", friction="on"),
    RunOptions(model="6rss", method="newton-euler", goal=None, friction="on"),
    # torque limit below the peaks: the distribution's SQP at a few hundred samples, warm-started from the sample
    # before, across the chunks' boundaries too
    RunOptions(method="newton-euler", goal="min-torque", friction="on", overrides={"limits.torque_Nm": 0.28}),
    # the unilateral contact: the minimum-norm formulations' fallback and the distribution's bounds on N
    RunOptions(method="liang", contact="unilateral"),
    RunOptions(method="newton-euler", goal="min-torque", friction="on", contact="unilateral"),
]


@pytest.mark.parametrize("options", OPTIONS, ids=lambda o: f"{o.model}-{o.method}-{o.goal}-{o.orientation}-{o.contact}-{len(o.overrides)}")
def test_chunks_give_the_whole_task(options):
    """Every column bit for bit; the checks' verdicts equal; the formulation's indices and the coupling means
    (means over the samples, summed chunk by chunk) to 1e-12 relative, their other entries equal."""
    whole = compute(options, chunk=None)
    parts = compute(options, chunk=CHUNK)
    _same_columns(parts.table, whole.table)
    if options.model == "target":  # the normal forces are among the columns compared
        assert {"N_L", "N_R"} <= set(whole.table.columns)
    assert [c.as_dict() for c in parts.checks] == [c.as_dict() for c in whole.checks]
    info = {k: v for k, v in whole.info.items() if k != "timings"}
    _same_numbers({k: v for k, v in parts.info.items() if k != "timings"}, info, rtol=1e-12)
    if options.overrides:  # the case is what it claims to be: samples solved by the SQP
        assert whole.info["dynamics"]["constrained_samples"] > 50


def test_the_warm_start_is_carried_across_chunks(monkeypatch):
    """A chunk that starts at a sample the SQP solves, after one it solved too, gives the whole task's results,
    and the distribution of each chunk is warm-started from the previous chunk's last solution (N_L, N_R of the
    sample before), as the whole task's SQP is from the sample before."""
    import chewbot.dynamics.formulations.newton_euler as ne

    options = OPTIONS[-3]  # the torque limit below the peaks
    whole = compute(options, chunk=None)
    tau = np.column_stack([whole.table[f"tau{i}"] for i in range(1, 7)])
    on_limit = np.abs(tau).max(axis=1) >= 0.28 * (1 - 1e-9)  # the samples the SQP solved
    pairs = np.flatnonzero(on_limit[1:] & on_limit[:-1]) + 1
    k = int(pairs[len(pairs) // 2])
    starts = []
    solve = ne.solve
    monkeypatch.setattr(ne, "solve", lambda *a, previous=None, **o: starts.append(previous) or solve(*a, previous=previous, **o))
    _same_columns(compute(options, chunk=k).table, whole.table)
    N = np.column_stack([whole.table["N_L"], whole.table["N_R"]])
    assert starts[0] is None and len(starts) >= 2
    for j, previous in enumerate(starts[1:], start=1):
        assert np.array_equal(previous, N[j * k - 1])


def test_theta_continues_across_chunks_as_unwrap_of_the_whole_task():
    """Crank angles that wrap around +-pi (a crank turning): each chunk made continuous on its own and shifted by
    whole turns to continue the one before equals NumPy's unwrap of the whole sequence."""
    from chewbot.run.pipeline import _continued

    rng = np.random.default_rng(3)
    turning = np.cumsum(rng.uniform(-0.4, 0.6, size=(2500, 6)), axis=0)
    raw = (turning + np.pi) % (2 * np.pi) - np.pi  # what a kernel gives: angles in (-pi, pi]
    whole = continuous(raw)
    parts, before = [], None
    for start in range(0, len(raw), 333):
        part = _continued(continuous(raw[start:start + 333]), before)
        before = part[-1]
        parts.append(part)
    assert np.abs(np.concatenate(parts) - whole).max() <= 1e-12  # whole turns added in another order: rounding
    assert np.abs(np.diff(whole, axis=0)).max() < np.pi


def test_a_folder_written_in_chunks_equals_the_one_written_from_memory(tmp_path):
    options = RunOptions(method="hessian")
    streamed = run(options, tmp_path / "streamed", chunk=CHUNK, figures=False)  # figures: tests/test_report.py
    result = compute(options, chunk=None)
    write(result, tmp_path / "memory", figures=False)
    assert (tmp_path / "streamed" / "results.csv").read_bytes() == (tmp_path / "memory" / "results.csv").read_bytes()
    a, b = (json.loads((tmp_path / name / "run.json").read_text()) for name in ("streamed", "memory"))
    for record in (a, b):
        record.pop("timings")
    _same_numbers(a, b, rtol=1e-12)
    assert streamed.record["checks"] == b["checks"]
    assert sorted(p.name for p in (tmp_path / "streamed").iterdir()) == sorted(p.name for p in (tmp_path / "memory").iterdir())


def test_an_unreachable_sample_in_a_later_chunk_is_named_by_its_sample_and_line(tmp_path):
    """The error of a chunk's kinematics names the task's sample and the file's line, not the chunk's."""
    from chewbot.errors import KinematicsError

    t = np.arange(2500) / 1000
    beta = np.where(np.arange(2500) == 1700, 80.0, 5.0)  # one pose far out of reach
    path = tmp_path / "task.csv"
    path.write_text("# a comment line\nt,X,Y,alpha,beta[deg],dX,dY,dalpha,dbeta,ddX,ddY,ddalpha,ddbeta\n"
                    + "".join(f"{a},0,0,0,{b},0,0,0,0,0,0,0,0\n" for a, b in zip(t, beta)))
    with pytest.raises(KinematicsError, match=r"line 1703: sample 1700, t = 1\.7 s") as caught:
        compute(RunOptions(task=str(path), method=None), chunk=CHUNK)
    assert caught.value.sample == 1700


# --- the view ----------------------------------------------------------------------------------------------


def _table(n: int, seed: int = 0) -> Table:
    rng = np.random.default_rng(seed)
    table = Table()
    table.add("t", np.arange(n) / 1000, "s")
    table.add("a", np.cumsum(rng.standard_normal(n)), "N")
    table.add("b", rng.standard_normal(n) * np.exp(-np.arange(n) / n), "m")
    spikes = np.zeros(n)
    spikes[rng.integers(0, n, 7)] = rng.choice([-50.0, 50.0], 7)  # lone samples: a stride would miss them
    table.add("c", spikes, "N")
    for i in range(1, 7):
        table.add(f"mu{i}", np.radians(9.0 + 3 * np.sin(np.arange(n) / (50.0 * i))), "rad")
    return table


def _view(table: Table, sizes) -> object:
    builder = ViewBuilder(table["t"])
    start = 0
    for size in sizes:
        builder.update(table.rows(start, start + size))
        start += size
    assert start == table.n
    return builder.result()


def test_the_view_does_not_depend_on_the_chunks():
    table = _table(40_001)
    one = _view(table, [table.n])
    other = _view(table, [1, 999, 12_345, 7, 20_000, 6_649])
    for a, b in ((one.series, other.series), (one.plot, other.plot), (one.rows, other.rows)):
        _same_columns(a, b)
    assert one.stats == other.stats and one.near_singular == other.near_singular and one.first == other.first


def test_the_envelope_keeps_every_bin_s_extremes():
    """Long enough to be decimated: each pair of points of the envelope is the smallest and the largest value of
    its bin of consecutive samples, in the order they occur, so the lone spikes are all drawn."""
    table = _table(40_001)
    view = _view(table, [5_000] * 8 + [1])
    for envelope in (view.series, view.plot):
        pairs = envelope.n // 2
        size = int(np.ceil(table.n / pairs))
        assert size > 1
        for name in ("a", "b", "c"):
            y, env = table[name], envelope[name].reshape(-1, 2)
            for k in range(pairs):
                part = y[k * size:(k + 1) * size]
                first, second = sorted((int(np.argmin(part)), int(np.argmax(part))))
                assert list(env[k]) == [part[first], part[second]], (name, k)
        spikes = np.flatnonzero(table["c"] != 0)
        assert set(np.flatnonzero(envelope["c"] != 0) // 2) == set(spikes // size)


def test_the_view_s_statistics_and_near_singular_runs_are_the_whole_column_s():
    table = _table(30_000)
    view = _view(table, [4_096, 10_000, 15_904])
    for whole in column_stats(table, ["a", "b", "c"]):
        s = view.stats[whole.name]
        # The peaks and their times are samples picked from the column, not computed: the same numbers to the last bit
        # on any machine (rel 1e-15, below one unit in the last place of 1, states it). The mean and RMS are sums
        # taken chunk by chunk in the view and at once here: their rounding differs by a few ulp (rel 1e-12).
        picked, expected = (s.peak, s.t_peak, s.min, s.t_min, s.max, s.t_max), (whole.peak, whole.t_peak, whole.min, whole.t_min, whole.max, whole.t_max)
        assert picked == pytest.approx(expected, rel=1e-15, abs=0.0)
        assert s.mean == pytest.approx(whole.mean, rel=1e-12, abs=1e-12) and s.rms == pytest.approx(whole.rms, rel=1e-12)
    sin_mu = np.sin(np.column_stack([table[f"mu{i}"] for i in range(1, 7)]))
    # The reference goes through sin and back (arcsin): its smallest angle may differ from the view's, taken from mu
    # itself, in the last bits (a few 1e-16 relative); the runs' samples and times must be the same exactly.
    expected = near_singular(table["t"], sin_mu)
    assert [replace(r, min_deg=0.0) for r in view.near_singular] == [replace(r, min_deg=0.0) for r in expected]
    assert [r.min_deg for r in view.near_singular] == pytest.approx([r.min_deg for r in expected], rel=1e-12)
