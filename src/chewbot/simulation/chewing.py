"""A chewing sequence: the robot chews a food's portion for a number of cycles, the bolus broken stroke by stroke in
the plant (:class:`chewbot.simulation.bolus.BolusPlant`), and the bolus measured after each cycle (docs/bolus.md,
"Chewing with the robot").

**The cycle** (:func:`chewing_task`): the mandible starts at rest open, closes onto the bolus and reopens, C^2 at the
cycle's ends so that cycles join: q(s) = q_open + (q_closed - q_open) b(s), b(s) = 64 s^3 (1 - s)^3 of the phase s in
[0, 1] (b = 1 at s = 1/2, its rate and acceleration zero at both ends). The open pose has the incisal opening
``opening_mm`` (the incisor point I's drop from home), with beta (mouth opening) and X (protrusion, 0.4 mm per degree of
beta, as the default task's 4 mm at 10 deg); the closed pose is the open one scaled to the bite point's gap
``min_gap_mm``. The force reference (the task's Fz, which the hybrid controller follows once the teeth press on the
food) is a sin^2 burst of ``closing_force_N`` over the middle half of the cycle, its peak at the closed pose. The
stroke thus closes until the bed pushes with the closing force (under force control) or, where no food resists, until
the reference's closest gap (under position control). Or one cycle of a task CSV (:func:`repeated_task`), repeated.

**The sequence** (:func:`chew`): one simulation of every cycle (:func:`chewbot.simulation.run.compute` with the bolus
plant: the bed's parameters are inputs of the compiled step, nothing compiles per cycle); the strokes the plant applied
are replayed on the portion (:meth:`chewbot.food.bolus.Bolus.stroke`, deterministic: the same boluses) to give the
bolus after each cycle, its sieving and Rosin-Rammler fit, the cycle's peak force and closing work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from chewbot.errors import ChewbotError
from chewbot.food import CLOSING_FORCE_N, MIN_GAP_MM
from chewbot.food.bolus import Bolus, chew as ideal_chew, comminution_of
from chewbot.food.law import Food, load_food
from chewbot.food.sieving import RosinRammler
from chewbot.kinematics.task import TARGET_COORDS, Task
from chewbot.model import Model
from chewbot.units import factor

# The task's sample rate (Hz) and the protrusion that goes with the mouth's opening (m per rad: 0.4 mm/deg).
TASK_RATE_HZ = 1000.0
PROTRUSION_PER_RAD = 0.4e-3 * 180 / math.pi
# The force reference spans this share of the cycle, centred on its closest pose.
BURST_SHARE = 0.5
# A cycle from a task CSV must end where it starts, within this (m, rad), to be repeated.
CLOSURE_TOLERANCE = 1e-4
# --until-x50-mm: at most this many cycles beyond the ideal strokes' count (docs/bolus.md), and never more than MAX_CYCLES.
UNTIL_MARGIN = 1.5
MAX_CYCLES = 100


class ChewError(ChewbotError):
    """A chewing sequence cannot be set up (its cycle, its food): names the option and the reason."""


@dataclass(frozen=True)
class ChewingCycle:
    """The default cycle (module docstring): ``opening_mm`` incisal opening, ``frequency_Hz``, ``closing_force_N``,
    ``min_gap_mm`` (the reference's closest gap at the bite point)."""

    opening_mm: float = 18.0
    frequency_Hz: float = 1.3
    closing_force_N: float = CLOSING_FORCE_N
    min_gap_mm: float = MIN_GAP_MM

    @property
    def period(self) -> float:
        return 1.0 / self.frequency_Hz


def bump(s):
    """b(s) = 64 s^3 (1 - s)^3 and its first two derivatives in s."""
    u = 1 - s
    return 64 * s**3 * u**3, 192 * (s**2 * u**3 - s**3 * u**2), 192 * (2 * s * u**3 - 6 * s**2 * u**2 + 2 * s**3 * u)


def _incisal_opening(model: Model, q) -> float:
    """The incisor point's drop from home (m) at the target's pose q (X, Y, alpha, beta)."""
    from chewbot.rotation import matrix_from_euler_angles
    from chewbot.task.default import lift_to_full

    task = Task("pose", np.array([0.0]), TARGET_COORDS, np.atleast_2d(q), np.zeros((1, 4)), np.zeros((1, 4)), np.zeros((1, 3)), "left")
    X = lift_to_full(model, task).q[0]
    return float(model.incisor[2] - (X[2] + (matrix_from_euler_angles(X[None, 3:6])[0] @ model.incisor)[2]))


def cycle_poses(model: Model, side: str, cycle: ChewingCycle) -> tuple[np.ndarray, np.ndarray, float]:
    """The open and the closed pose (X, Y, alpha, beta) of the default cycle, and the gap (m) at the open one."""
    from scipy.optimize import brentq

    from chewbot.food.geometry import gap

    def pose(beta):
        return np.array([PROTRUSION_PER_RAD * beta, 0.0, 0.0, beta])

    opening, min_gap = cycle.opening_mm * factor("mm"), cycle.min_gap_mm * factor("mm")
    beta = brentq(lambda b: _incisal_opening(model, pose(b)) - opening, 1e-4, math.radians(20), xtol=1e-10)
    q_open = pose(beta)
    g_open = float(gap(model, side, q_open[None])["gap"][0])
    scale = brentq(lambda k: gap(model, side, (k * q_open)[None])["gap"][0] - min_gap, 0.0, 1.0, xtol=1e-12)
    return q_open, scale * q_open, g_open


def chewing_task(model: Model, side: str, cycles: int, cycle: ChewingCycle = ChewingCycle()) -> Task:
    """``cycles`` default cycles on the molar of ``side`` (module docstring), sampled at :data:`TASK_RATE_HZ`."""
    if not model.has_hkp:
        raise ChewError(f"--model {model.name}: the chewing cycle is the target's (its four coordinates); the 6RSS has no "
                        "sockets to guide it")
    q_open, q_closed, _ = cycle_poses(model, side, cycle)
    if side == "right":
        q_open, q_closed = q_open * [1, -1, -1, 1], q_closed * [1, -1, -1, 1]
    T = cycle.period
    n = int(round(cycles * T * TASK_RATE_HZ)) + 1
    t = np.linspace(0.0, cycles * T, n)
    s = np.minimum(t / T - np.floor(np.minimum(t / T, cycles - 1e-12)), 1.0)
    b, db, ddb = bump(s)
    d = q_closed - q_open
    q, dq, ddq = q_open + b[:, None] * d, (db / T)[:, None] * d, (ddb / T**2)[:, None] * d
    force = np.zeros((n, 3))
    force[:, 2] = -cycle.closing_force_N * _burst(s)
    meta = {"generator": "chewing cycle", "parameters": {**vars(cycle), "cycles": cycles, "burst_share": BURST_SHARE}}
    return Task(f"chewing-{side}", t, TARGET_COORDS, q, dq, ddq, force, side, meta=meta)


def _burst(s):
    """The force reference's envelope: sin^2 over the middle :data:`BURST_SHARE` of the cycle."""
    u = (s - 0.5) / BURST_SHARE + 0.5
    return np.where((u >= 0) & (u <= 1), np.sin(np.pi * np.clip(u, 0, 1)) ** 2, 0.0)


def repeated_task(model: Model, one: Task, cycles: int, closing_force: float) -> Task:
    """``cycles`` repetitions of the cycle ``one`` (a task CSV, e.g. import-motion's): it must end where it starts.
    Where it carries no Fz, the force reference is a burst of ``closing_force`` (N) over the middle half of the cycle
    around its closest gap."""
    from chewbot.food.geometry import gap

    if not model.has_hkp or tuple(one.coords) != TARGET_COORDS:
        raise ChewError(f"--task {one.source}: a chewing cycle is a motion of the target's {', '.join(TARGET_COORDS)}")
    jump = np.abs(np.concatenate([one.q[-1] - one.q[0], one.dq[-1] - one.dq[0]]))
    if jump.max() > CLOSURE_TOLERANCE:
        raise ChewError(f"--task {one.source}: a cycle must end where it starts to be repeated (pose and rate within "
                        f"{CLOSURE_TOLERANCE:g}); its last sample differs from its first by {jump.max():.3g}")
    T = float(one.t[-1] - one.t[0])
    local = one.t - one.t[0]
    force = np.array(one.force, float)
    if not np.any(force[:, 2] != 0):
        g = gap(model, one.side, one.q, one.dq)["gap"]
        s = (local - local[int(np.argmin(g))]) / T + 0.5
        force[:, 2] = -closing_force * _burst(s)
    k = np.arange(cycles)
    t = np.concatenate([local[:-1] + i * T for i in k] + [[cycles * T]])

    def tile(x):
        return np.concatenate([x[:-1]] * cycles + [x[-1:]])

    return Task(f"{one.name} x {cycles}", t, TARGET_COORDS, tile(one.q), tile(one.dq), tile(one.ddq), tile(force), one.side,
                one.source, meta={"generator": "repeated cycle", "cycle_s": T, "cycles": cycles})


def sequence_task(model: Model, food: Food, side: str, cycles: int, cycle: ChewingCycle, path=None, controller=None) -> tuple[Task, float]:
    """The task of a sequence and its cycle's period (s): ``cycles`` default cycles, or of the cycle in the task CSV
    ``path``; without its force where ``controller`` (a controller table's row) does not read the task's force as a
    force reference (it then follows the motion to its closest gap). The cycle must start with the teeth farther
    apart than the food's height (ChewError otherwise); a food without a ``[comminution]`` table is a FoodError naming it."""
    from chewbot.food.geometry import gap
    from chewbot.run.pipeline import load_task

    comminution_of(food)  # a food that cannot be chewed, before anything is built
    if path is None:
        task, period = chewing_task(model, side, cycles, cycle), cycle.period
    else:
        one = load_task(str(path), model, side, {})
        task = repeated_task(model, one, cycles, cycle.closing_force_N)
        period = float(one.t[-1] - one.t[0])
    g0 = float(gap(model, side, task.q[:1], task.dq[:1])["gap"][0])
    if g0 <= food.height:
        where = "--opening-mm" if path is None else f"--task {path}"
        raise ChewError(f"{where}: the cycle starts with a gap of {g0 * 1e3:.4g} mm at the {side} bite point, not above the "
                        f"{food.name}'s height ({food.height * 1e3:.4g} mm); open wider")
    if controller is not None and not controller.force_reference:
        task = replace(task, force=np.zeros_like(task.force))
    return task, period


# ------------------------------------------------------------------------------------------- the sequence


@dataclass(frozen=True)
class CycleRecord:
    """The bolus after a cycle (cycle 0: the intact portion): ``bolus``, ``fit`` (X50, b and flags), ``peak_force``
    (N), ``work`` (J, the teeth's work on the food while closing), ``strokes`` applied in the cycle."""

    cycle: int
    bolus: Bolus
    fit: RosinRammler
    peak_force: float
    work: float
    strokes: int


# The human references of the built-in foods' boluses (docs/bolus.md): X50 (mm) low, high, and where it is from.
HUMAN_X50_MM = {"peanut": (1.18, 1.26, "human, 20-26 chews (Hutchings et al. 2012)"),
                "carrot": (0.0, 4.0, "normal at swallow, X50 <= 4.0 mm (Woda et al. 2010)")}
# The bolus's texture test (--tpa-at): compression of its height (%), speed (mm/s), pause (s): the texture test's defaults.
BOLUS_TPA = (50.0, 2.0, 2.0)


@dataclass
class Chewing:
    """A chewing sequence: the ``food`` and its comminution ``table``, the simulation ``result``, the per-cycle
    ``records``, the cycle ``period`` (s), its ``checks``, ``target_x50_mm`` (--until-x50-mm), ``band`` the human
    reference's X50 (low, high mm, label) or None, ``tpa`` the bolus's texture tests (:func:`bolus_tpa`)."""

    food: Food
    table: object
    result: object
    records: list[CycleRecord]
    period: float
    checks: list = field(default_factory=list)
    target_x50_mm: float | None = None
    band: tuple | None = None
    tpa: list = field(default_factory=list)

    def record(self) -> dict:
        """run.json's ``chew``: the law, the stroke, the cycles' figures, the bolus's texture tests."""
        return {"food": self.food.name, "cycles": len(self.records) - 1, "period_s": self.period,
                "target_x50_mm": self.target_x50_mm, "human_x50_mm": None if self.band is None else list(self.band),
                "law": self.result.info.get("bolus", {}).get("law"),
                "per_cycle": [{"cycle": r.cycle, "x50_mm": r.fit.x50_mm, "b": r.fit.b, "extrapolated": r.fit.extrapolated,
                               "determined": r.fit.determined, "peak_force_N": r.peak_force, "work_J": r.work,
                               "strokes": r.strokes, "mass_g": r.bolus.total * 1e3} for r in self.records],
                "tpa": self.tpa}


def cycles_for(food: Food, x50_mm: float, cycle: ChewingCycle) -> int:
    """How many cycles to simulate for --until-x50-mm: the ideal strokes' count to reach it, with a margin."""
    c = comminution_of(food)
    ideal = ideal_chew(c, MAX_CYCLES, cycle.closing_force_N, cycle.min_gap_mm * factor("mm")).rosin_rammler()
    reach = next((k for k, r in enumerate(ideal) if r.determined and r.x50_mm <= x50_mm), MAX_CYCLES)
    return min(MAX_CYCLES, int(math.ceil(reach * UNTIL_MARGIN)) + 2)


def chew(options, task: Task, period: float, progress=None, check=None, target_x50_mm: float | None = None) -> Chewing:
    """Simulate ``task`` (cycles of ``period`` s) with the resolved simulation ``options`` (a food, ``bolus`` on) and
    measure the bolus after each cycle; with ``target_x50_mm`` the sequence ends at the first cycle whose X50 is at
    most that (the rest of the simulation is dropped)."""
    from chewbot.simulation.run import compute

    food = load_food(options.food)
    c = comminution_of(food)
    result = compute(options, progress=progress, check=check, task=task)
    sim = result.simulation
    cycles = int(round((task.t[-1] - task.t[0]) / period))
    strokes = result.info.get("bolus", {}).get("strokes", [])
    ends = np.array([s["t_s"] for s in strokes])
    in_cycle = np.minimum(np.floor((ends - task.t[0]) / period).astype(int) + 1, cycles)
    bolus = Bolus.portion(c)
    records = [CycleRecord(0, bolus, bolus.rosin_rammler(), 0.0, 0.0, 0)]
    cycle_of_row = np.minimum(np.floor((sim.t - task.t[0]) / period).astype(int) + 1, cycles)
    force, gap = sim.quantities["force"], food.height - sim.quantities["delta"]
    closing = np.maximum(-np.diff(gap), 0.0) * 0.5 * (force[1:] + force[:-1])  # F |dg| while the gap shrinks
    done = int(cycle_of_row[-1]) if sim.stopped is not None else cycles
    for k in range(1, done + 1):
        for s in (strokes[i] for i in np.flatnonzero(in_cycle == k)):
            bolus, _ = bolus.stroke(c, s["gap_m"], s["peak_force_N"])
        rows = cycle_of_row == k
        records.append(CycleRecord(k, bolus, bolus.rosin_rammler(), float(force[rows].max(initial=0.0)),
                                   float(closing[rows[1:]].sum()), int(np.sum(in_cycle == k))))
        if target_x50_mm is not None and records[-1].fit.determined and records[-1].fit.x50_mm <= target_x50_mm:
            break
    chewing = Chewing(food, c, result, records, period, target_x50_mm=target_x50_mm, band=HUMAN_X50_MM.get(options.food))
    chewing.checks = sequence_checks(chewing, cycles)
    return chewing


def bolus_tpa(chewing: Chewing, shares_percent) -> list[dict]:
    """The bolus's texture test after each share (%) of the cycles chewed: the ideal texture analyser
    (the protocol of :data:`BOLUS_TPA`, every stroke at its speed) on the intact food's bulk law at cycle 0, and on the
    particle bed's law (:func:`chewbot.food.bolus.bed_force`, the bolus after that cycle) after: Bourne's measures."""
    from chewbot.food.bolus import bed_force
    from chewbot.food.law import NUMPY
    from chewbot.food.tpa import ideal_test, protocol, settings, tpa_measures

    compression, speed, pause = BOLUS_TPA
    n = len(chewing.records) - 1
    out = []
    for share in shares_percent:
        k = int(round(share / 100 * n))
        if k == 0:
            height = chewing.food.height
            measures = ideal_test(chewing.food, settings(compression, speed, pause, pre_test_speed_mm_s=speed)).analysis.measures
        else:
            b = chewing.records[k].bolus.bed(chewing.table)
            height = float(b[0])
            p = protocol(height, compression, speed, pause)
            t = p.times()
            g = p.path(t)[0]
            measures = tpa_measures(t, g, bed_force(NUMPY, b, g))
        out.append({"share_percent": float(share), "cycle": k, "height_mm": height * 1e3, "measures": measures})
    return out


def sequence_checks(chewing: Chewing, cycles: int) -> list:
    """The sequence's checks: ``sequence-completed`` (every cycle simulated: the robot stayed in its workspace),
    ``mass-conserved`` (the bolus's mass within 1e-9 relative of the portion's), ``x50-monotone`` (X50 never rises
    where the sieving determines it), ``x50-reached`` (with --until-x50-mm); failures; with the simulation's own checks,
    its ``force-tracking`` over the strokes (:func:`stroke_force_check`)."""
    from chewbot.analysis.checks import CheckResult

    records = chewing.records
    stopped = chewing.result.simulation.stopped
    mass = np.array([r.bolus.total for r in records])
    drift = np.abs(mass / mass[0] - 1)
    x50 = np.array([r.fit.x50_mm if r.fit.determined else np.nan for r in records])
    valid = np.flatnonzero(np.isfinite(x50))
    rises = valid[1:][np.diff(x50[valid]) > 0]
    out = [
        CheckResult("sequence-completed", stopped is None, 0 if stopped is None else 1,
                    None if stopped is None else {"index": stopped["sample"], "t": stopped["t"]}, None,
                    f"all {cycles} cycles chewed" if stopped is None else
                    f"the sequence stopped in cycle {len(records)} of {cycles} at t = {stopped['t']:.4g} s: the robot left its "
                    f"workspace ({stopped['reason']})", "failure"),
        CheckResult("mass-conserved", bool(drift.max() <= 1e-9), int(np.sum(drift > 1e-9)), None,
                    {"value": float(drift.max()), "unit": "1"},
                    f"the bolus's mass over {len(records) - 1} cycles: largest relative change {drift.max():.3g} (bound 1e-9)",
                    "failure"),
        CheckResult("x50-monotone", bool(rises.size == 0), int(rises.size), None, None,
                    "X50 never rises" if rises.size == 0 else f"X50 rises at {rises.size} cycle(s), the first at cycle "
                    f"{int(rises[0])}", "failure"),
    ]
    if chewing.target_x50_mm is not None:
        last = records[-1].fit
        reached = bool(last.determined and last.x50_mm <= chewing.target_x50_mm)
        out.append(CheckResult("x50-reached", reached, 0 if reached else 1, None, None,
                               f"X50 {'reached' if reached else 'did not reach'} {chewing.target_x50_mm:g} mm in "
                               f"{len(records) - 1} cycles", "failure"))
    own = [c for c in (stroke_force_check(chewing),) if c is not None]
    return out + own + [c for c in chewing.result.checks if c.name not in {o.name for o in own}]


def stroke_force_check(chewing: Chewing):
    """``force-tracking`` of a sequence under a controller that switches to force control (results.csv's
    ``force_mode``), in place of the simulation's: the RMS of the food's force minus the reference within the
    simulation's bound (10 % of the reference's peak) over the rows where the teeth press on the bolus under force
    control, each stroke's first 4 / (2 pi ``force_frequency_Hz``) of the controller's gains left out (its force loop's
    settling: a critically damped loop is within 10 % of a step after it). The simulation's counts every row of the
    closing-force burst, which spans the middle half of the cycle, and the teeth reach a thinning bolus ever later in
    it: the rows before are the cycle's, and at the touch the reference is a step of some 90 N. None where the
    controller has no force mode."""
    from chewbot.analysis.checks import CheckResult
    from chewbot.simulation.run import FORCE_TRACKING_BOUND_PERCENT

    table, sim = chewing.result.table, chewing.result.simulation
    if "force_mode" not in table:
        return None
    f, f_ref = sim.quantities["force"], -chewing.result.reference.force_at(sim.t)[:, 2]
    rows = np.flatnonzero((table["force_mode"] > 0.5) & (f > 0) & (f_ref > 0))
    touch = np.maximum.accumulate(np.where(np.r_[True, np.diff(rows) > 1], sim.t[rows], -np.inf))  # each stroke's first
    settle = 4 / (2 * np.pi * chewing.result.gains[chewing.result.options.controller.gains].force_frequency_Hz)
    rows = rows[sim.t[rows] - touch >= settle]
    if not rows.size:
        return CheckResult("force-tracking", None, None, None, None, "not evaluated: the teeth never pressed on the bolus "
                           "under force control beyond the force loop's settling", "failure")
    e = f[rows] - f_ref[rows]
    peak = float(f_ref.max())
    rms = 100 * float(np.sqrt(np.mean(e**2))) / peak
    ok = bool(rms <= FORCE_TRACKING_BOUND_PERCENT)
    return CheckResult("force-tracking", ok, 0 if ok else int(rows.size), None, {"value": rms, "unit": "% RMS of the reference's peak"},
                       f"the food's force followed the closing force to {rms:.3g} % RMS of its peak ({peak:.4g} N) over the "
                       f"{rows.size} rows where the teeth pressed on the bolus under force control, {settle * 1e3:.3g} ms "
                       f"after each touch (largest error {np.abs(e).max():.3g} N); allowed {FORCE_TRACKING_BOUND_PERCENT:g} %",
                       "failure")


__all__ = ["BURST_SHARE", "ChewError", "bump", "Chewing", "ChewingCycle", "CycleRecord", "chew", "chewing_task", "cycle_poses",
           "cycles_for", "bolus_tpa", "repeated_task", "sequence_task", "stroke_force_check", "HUMAN_X50_MM"]
