"""Seed 001's dynamic performances on our models: the equivalent of its Table 3 and Figs. 10–14.

Newton–Euler with friction on the default task (left side): the target under the three goals with Euler
parameters and with Euler angles, and the 6RSS (closed form) with both. Writes ``table3.csv`` and
``table3.md`` (indices F1..F7, the median time of the run, and whether each goal gives the smallest value of
its own index), ``claims.md``/``claims.csv`` (items 6, 7 and 9 of the papers' findings, docs/conventions.md),
``study.json`` and the figures: Figs. 10, 12, 13 for goal G1, Fig. 11 (friction share) for
each goal, and Fig. 14 (times, Euler parameters against Euler angles).
"""

from __future__ import annotations

import csv
import statistics
from functools import partial
from pathlib import Path

import numpy as np

from chewbot.analysis.checks import PULL_TOLERANCE_N
from chewbot.dynamics.indices import INDEX_UNITS
from chewbot.bench.benchmark import compare, interleaved
from chewbot.dynamics.formulations.newton_euler import newton_euler
from chewbot.dynamics.options import GOALS
from chewbot.kinematics.motion import solve_kinematics
from chewbot.kinematics.options import ORIENTATIONS
from chewbot.model.params import load_model
from chewbot.progress import SILENT, Progress
from chewbot.report import newton_euler_figures
from chewbot.report.plotting import save, subplots
from chewbot.run.columns import kinematics_table
from chewbot.study.claims import STUDY_FORMAT, Claim, write_claims
from chewbot.task.default import default_task

GOAL_LABELS = {"min-torque": "G1", "min-coupler-force": "G2", "min-hkp-force": "G3"}
OWN_INDEX = {"min-torque": "F1", "min-coupler-force": "F2", "min-hkp-force": "F3"}
REPEATS = 7  # timed runs per row after a first (warm-up) run, the rows interleaved (chewbot.bench.benchmark.interleaved)


def _rows(step) -> list[dict]:
    rows, runs = [], {}
    for name, goals in (("target", GOALS), ("6rss", ("min-torque",))):
        model = load_model(name)
        for orientation in ORIENTATIONS:
            step(f"Newton-Euler: {name}, {orientation}")
            kin = solve_kinematics(model, default_task(model, "left"), orientation)
            for goal in goals:
                dyn = newton_euler(model, kin, goal=goal)
                rows.append({"mechanism": name, "orientation": orientation,
                             "goal": GOAL_LABELS[goal] if name == "target" else "-",
                             **dyn.info["indices"], "infeasible_samples": len(dyn.info["infeasible"]),
                             "_dyn": dyn, "_kin": kin})
                runs[len(rows) - 1] = partial(newton_euler, model, kin, goal=goal)
    step("timing the rows, interleaved")
    for k, timing in interleaved(runs, REPEATS).items():
        rows[k]["time_s"], rows[k]["_timing"] = timing.median, timing
    for row in rows:
        if row["mechanism"] == "target":
            own = OWN_INDEX[next(g for g, lab in GOAL_LABELS.items() if lab == row["goal"])]
            peers = [r[own] for r in rows if r["mechanism"] == "target" and r["orientation"] == row["orientation"]]
            row["smallest_own_index"] = "yes" if row[own] <= min(peers) else "no"
        else:
            row["smallest_own_index"] = "-"
    return rows


COLUMNS = ["mechanism", "orientation", "goal", *INDEX_UNITS, "time_s", "infeasible_samples", "smallest_own_index"]


def _header() -> list[str]:
    return [f"{c} [{INDEX_UNITS[c]}]" if c in INDEX_UNITS else ("time [s]" if c == "time_s" else c) for c in COLUMNS]


def _cell(value) -> str:
    if isinstance(value, float):
        return "-" if np.isnan(value) else f"{value:.6g}"
    return str(value)


def _fig14(rows: list[dict], path: Path) -> Path:
    """Computation time of each row, Euler parameters beside Euler angles (seed 001, Fig. 14)."""
    fig, ax = subplots(figsize=(9, 4))
    labels = [f"{r['mechanism']} {r['goal']}" for r in rows if r["orientation"] == ORIENTATIONS[0]]
    xs = np.arange(len(labels))
    for k, orientation in enumerate(ORIENTATIONS):
        times = [r["time_s"] * 1e3 for r in rows if r["orientation"] == orientation]
        ax.bar(xs + (k - 0.5) * 0.4, times, width=0.4, label=orientation)
    ax.set_xticks(xs, labels)
    ax.set_ylabel("Newton–Euler, whole task (5001 samples) [ms]")
    ax.set_title("Computation time: Euler parameters against Euler angles (seed 001, Fig. 14)")
    ax.legend()
    ax.grid(alpha=0.3, axis="y")
    return save(fig, path)


# A median share of the actuating torque above this counts as "a large share" of friction (item 7).
LARGE_SHARE = 50.0  # %


def claims(rows: list[dict]) -> list[Claim]:
    """Items 6 and 7 of the papers' findings (docs/conventions.md) from the rows of Table 3."""
    def row(mech, orientation, goal):
        return next(r for r in rows if r["mechanism"] == mech and r["orientation"] == orientation and r["goal"] == goal)

    out = []
    # the bench's rule (chewbot.bench.benchmark.compare): a ratio whose spreads overlap is "within noise", no speed-up
    ratio, noise = {}, {}
    for mech, goals in (("target", ("G1", "G2", "G3")), ("6rss", ("-",))):
        pairs = [compare(row(mech, "euler-parameters", g)["_timing"], row(mech, "euler-angles", g)["_timing"]) for g in goals]
        ratio[mech] = statistics.median(c.ratio for c in pairs)
        noise[mech] = sum(c.within_noise for c in pairs)
    ok6 = ratio["target"] < 0.5 and ratio["6rss"] < 0.8 and not any(noise.values())
    out.append(Claim(6, "default", "Euler parameters take ~23 % of the Euler-angle model's time (target), ~60 % (6RSS)",
                     f"Euler parameters / Euler angles, Newton-Euler with friction, whole task: {100 * ratio['target']:.0f} % "
                     f"(target, median over the goals; {noise['target']} of 3 within noise), {100 * ratio['6rss']:.0f} % "
                     f"(6RSS{', within noise' if noise['6rss'] else ''})", ok6,
                     "" if ok6 else "compiled graphs make the trigonometric functions of the parasitic gamma a few dozen "
                     "operations among thousands, and the distribution's Newton iterations dominate the time; the paper "
                     "timed MATLAB code"))
    for orientation in ORIENTATIONS:
        own = all(r["smallest_own_index"] == "yes" for r in rows if r["mechanism"] == "target" and r["orientation"] == orientation)
        g3, six = row("target", orientation, "G3"), row("6rss", orientation, "-")
        near = max(abs(g3[k] / six[k] - 1) for k in ("F1", "F2", "F4", "F5", "F6"))
        # the typical share (median over the samples, largest over the actuators): the maximum sits where a
        # torque crosses zero and the ratio is unbounded, which says nothing
        share = max(float(np.median(v)) for k, v in row("target", orientation, "G1")["_dyn"].table.columns.items()
                    if k.startswith("friction_share"))
        parts = {"a goal does not minimise its own index": own,
                 "the HKP forces under G3 are not near zero": g3["F3"] <= 1e-6 * row("target", orientation, "G1")["F3"],
                 "the G3 indices differ from the 6RSS's by 1 % or more": near < 0.01,
                 f"friction typically stays below {LARGE_SHARE:.0f} % of every torque": share >= LARGE_SHARE}
        ok7 = all(parts.values())
        out.append(Claim(7, orientation, "each goal minimises its own index F1..F3; under G3 the HKP forces are near zero "
                         "and the indices approach the 6RSS's; friction can be a large share of the torque (Eq. 75)",
                         f"own index smallest: {'yes' if own else 'no'}; F3 under G3 {g3['F3']:.2g} N; G3 vs 6RSS "
                         f"indices within {100 * near:.2f} %; friction share under G1, median over the task, up to "
                         f"{share:.0f} % (the actuator with the largest)", ok7,
                         "; ".join(k for k, v in parts.items() if not v)))
    return out


# Seed 001 on its Fig. 10 (goal G1, left-side chewing): "at most of the time instants" N_R < 0 and N_L > 0 (the
# right ball pressed by the upper surface of its socket, the left by the lower one), and N_R has the larger peaks.
# "Most" is read as more than half of the samples.
MOST = 0.5


def normal_force_signs(rows: list[dict]) -> Claim:
    """Item 9 (seed 001, Fig. 10): the sign pattern of N_L, N_R under G1, with our shares under each goal (rows of
    Euler parameters, the paper's parametrisation; the other gives the same forces)."""
    shares = {}
    for r in rows:
        if r["mechanism"] == "target" and r["orientation"] == "euler-parameters":
            N = {j: r["_dyn"].table[f"N_{j}"] for j in "LR"}
            shares[r["goal"]] = {"L+": float(np.mean(N["L"] > PULL_TOLERANCE_N)), "R-": float(np.mean(N["R"] < -PULL_TOLERANCE_N)),
                                 "L-": float(np.mean(N["L"] < -PULL_TOLERANCE_N)), "R+": float(np.mean(N["R"] > PULL_TOLERANCE_N)),
                                 "peak": {j: float(np.abs(N[j]).max()) for j in "LR"}}
    g1 = shares["G1"]
    pattern = g1["R-"] > MOST and g1["L+"] > MOST
    peaks = g1["peak"]["R"] > g1["peak"]["L"]

    def figure(goal: str) -> str:
        s = shares[goal]
        if max(s["peak"].values()) <= PULL_TOLERANCE_N:
            return f"{goal}: N_L = N_R = 0 at every sample (the goal drives both to zero: no sign)"
        return (f"{goal}: N_L > 0 in {100 * s['L+']:.1f} %, < 0 in {100 * s['L-']:.1f} %; N_R > 0 in {100 * s['R+']:.1f} %, "
                f"< 0 in {100 * s['R-']:.1f} % of the samples; peaks abs(N_L) {s['peak']['L']:.3g} N, abs(N_R) {s['peak']['R']:.3g} N")

    reasons = []
    if not pattern:
        reasons.append(f"under G1 N_R < 0 at {100 * g1['R-']:.1f} % and N_L > 0 at {100 * g1['L+']:.1f} % of the samples. "
                       "The sign of N is not a property of the mechanism (the two redundant torques set N_L, N_R freely, "
                       "docs/contact.md); which one the minimum-torque split gives depends on values the paper does not "
                       "give (condyle centres, molar points, crank masses) and on its measured task and bite force, which "
                       "are not public")
    if not peaks:
        reasons.append("abs(N_L) has the larger peaks under G1")
    return Claim(9, "default, left side, friction on, bilateral contact",
                 "under G1, N_R < 0 and N_L > 0 at most instants (the right ball pressed by the upper surface of its "
                 "socket, the left by the lower), N_R with the larger peaks (Fig. 10)",
                 "; ".join(figure(g) for g in ("G1", "G2", "G3")), pattern and peaks, "; ".join(reasons))


def run(out: Path, force: bool = False, progress: Progress = SILENT) -> Path:
    """Run the study and write its folder ``out`` atomically (replaced only with ``force``)."""
    from chewbot.files import STUDY_FOLDER, atomic_folder, check_output, to_json

    out = Path(out)
    check_output(out, force, STUDY_FOLDER)
    rows = _rows(progress)
    with atomic_folder(out, force, STUDY_FOLDER) as tmp:
        with open(tmp / "table3.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(_header())
            writer.writerows([[repr(r[c]) if isinstance(r[c], float) else r[c] for c in COLUMNS] for r in rows])
        lines = ["| " + " | ".join(_header()) + " |", "|" + "---|" * len(COLUMNS)]
        lines += ["| " + " | ".join(_cell(r[c]) for c in COLUMNS) + " |" for r in rows]
        (tmp / "table3.md").write_text("\n".join(lines) + "\n")
        summary = {"chewbot_study": STUDY_FORMAT, "study": "seed001", "rows": [{c: r[c] for c in COLUMNS} for r in rows],
                   "notes": "Newton-Euler with friction, default task, left side; time: median of "
                            f"{REPEATS} interleaved runs after a warm-up, kinematics excluded"}
        (tmp / "study.json").write_text(to_json(summary))
        write_claims(claims(rows) + [normal_force_signs(rows)], tmp)
        progress("figures")
        for r in rows:
            if r["mechanism"] == "target" and r["orientation"] == "euler-parameters":
                table = kinematics_table(r["_kin"])
                table.add_block([f"tau{i + 1}" for i in range(6)], r["_dyn"].tau, "N*m")
                for name, values in r["_dyn"].table.columns.items():
                    table.add(name, values, r["_dyn"].table.units[name])
                newton_euler_figures.friction_share(table, tmp / f"fig11_friction_share_{r['goal']}.png")
                if r["goal"] == "G1":
                    newton_euler_figures.torques_and_contacts(table, tmp / "fig10_torques_contacts_G1.png")
                    newton_euler_figures.coupler_forces(table, tmp / "fig12_coupler_forces_G1.png")
                    newton_euler_figures.crank_moments(table, tmp / "fig13_crank_moments_G1.png")
        _fig14(rows, tmp / "fig14_times.png")
    return out
