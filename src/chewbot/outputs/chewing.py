"""The folder of a chewing sequence (``chewbot chew``): the simulation's own files (results.csv of the motion with the
food's and the bolus's columns, run.json, its figures and report.html), cycles.csv (the bolus after each cycle),
psd.csv (its sieving), bolus_tpa.csv (with ``--tpa-at``), the figures of the bolus and chew.html, written whole through
:func:`chewbot.files.atomic_folder` and recognised later by run.json's key ``chewbot_chew``.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from chewbot.files import Marker, atomic_folder, to_json
from chewbot.food.sieving import SIEVING_MM
from chewbot.progress import SILENT, Progress
from chewbot.table import Table

CHEW_FORMAT = 1
CHEW_FOLDER = Marker("chewing folder", "run.json", "chewbot_chew")
CYCLES_FILE, PSD_FILE, TPA_FILE = "cycles.csv", "psd.csv", "bolus_tpa.csv"


def cycles_table(chewing) -> Table:
    """cycles.csv: one row per cycle, cycle 0 the intact portion."""
    r = chewing.records
    table = Table()
    table.add("cycle", np.array([x.cycle for x in r], float), "1", "chewing cycles done (0: the intact portion)")
    table.add("X50", np.array([x.fit.x50_mm for x in r]), "mm", "median particle size, Rosin-Rammler least squares on the "
              "cumulative mass passing each sieve (empty: not determined by the sieving)")
    table.add("b", np.array([x.fit.b for x in r]), "1", "Rosin-Rammler spread")
    table.add("x50_extrapolated", np.array([x.fit.extrapolated for x in r], float), "1", "1: X50 beyond the top sieve (5.6 mm), "
              "extrapolated")
    table.add("peak_force", np.array([x.peak_force for x in r]), "N", "the food's peak force on the teeth in the cycle")
    table.add("work", np.array([x.work for x in r]), "J", "the teeth's work on the food while closing in the cycle (sum of F |dg| "
              "where the gap shrinks)")
    table.add("particles", np.array([x.bolus.count(chewing.table) for x in r]), "1", "particles in the bolus, as spheres of "
              "their class's size (the fines dominate)")
    table.add("mass", np.array([x.bolus.total for x in r]) * 1e3, "g", "the bolus's mass")
    return table


def psd_table(chewing) -> Table:
    """psd.csv: per cycle and sieve, the mass fraction retained (the pan as sieve 0); each cycle's sum is 1."""
    r = chewing.records
    fractions = np.array([x.bolus.sieving() for x in r])
    table = Table()
    table.add("cycle", np.repeat([float(x.cycle) for x in r], len(SIEVING_MM)), "1", "chewing cycles done (0: the intact portion)")
    table.add("sieve", np.tile(np.array(SIEVING_MM, float), len(r)), "mm", "sieve aperture (0: the pan)")
    table.add("mass_fraction", fractions.ravel(), "1", "mass retained on the sieve over the bolus's")
    return table


def tpa_table(chewing) -> Table:
    """bolus_tpa.csv: the share of the cycles, the cycle, the bed's height and the bolus's TPA measures."""
    from chewbot.food.tpa import MEASURES
    from chewbot.units import key_unit

    rows = chewing.tpa
    table = Table()
    table.add("share", np.array([t["share_percent"] for t in rows], float), "%", "share of the cycles chewed before the test")
    table.add("cycle", np.array([t["cycle"] for t in rows], float), "1", "the cycle after which the bolus was tested")
    table.add("height", np.array([t["height_mm"] for t in rows], float), "mm", "the bolus's height at the test's trigger "
              "(the bed's loose height; the intact food's at cycle 0)")
    for m in MEASURES:
        name, unit = key_unit(m)
        table.add(name, np.array([np.nan if t["measures"][m] is None else t["measures"][m] for t in rows], float), unit or "1",
                  f"TPA {m}")
    return table


def write(chewing, out: Path, force: bool = False, progress: Progress = SILENT) -> Path:
    """Write the folder ``out`` of a chewing sequence (:class:`chewbot.simulation.chewing.Chewing`)."""
    from chewbot.outputs.simulation import write_into
    from chewbot.report.chew_figures import distribution, force_per_cycle, x50
    from chewbot.simulation.run import input_files

    out = Path(out)
    result = chewing.result
    result.info.update({"chewbot_chew": CHEW_FORMAT, "chew": chewing.record()})
    result.checks = chewing.checks
    cycles, psd = cycles_table(chewing), psd_table(chewing)
    with atomic_folder(out, force, CHEW_FOLDER, inputs=input_files(result.options)) as tmp:
        write_into(result, tmp, progress)
        cycles.to_csv(tmp / CYCLES_FILE)
        psd.to_csv(tmp / PSD_FILE)
        if chewing.tpa:
            tpa_table(chewing).to_csv(tmp / TPA_FILE)
        progress("drawing the bolus's figures")
        name = chewing.food.name
        fractions = np.array([x.bolus.sieving() for x in chewing.records])
        distribution(cycles["cycle"], np.array(SIEVING_MM), fractions, tmp / "psd.png", name)
        x50(cycles["cycle"][1:], cycles["X50"][1:], cycles["x50_extrapolated"][1:] > 0, tmp / "x50.png", chewing.band, name)
        force_per_cycle(cycles["cycle"][1:], cycles["peak_force"][1:], cycles["work"][1:], tmp / "force_per_cycle.png", name)
        (tmp / "chew.html").write_text(chew_html(chewing, cycles), encoding="utf-8")
    return out


def chew_html(chewing, cycles: Table) -> str:
    """A one-page report: the cycles' table, the figures, the checks and the record."""
    head = "".join(f"<th>{html.escape(n)} [{html.escape(cycles.units[n])}]</th>" for n in cycles.columns)
    body = "".join("<tr>" + "".join(f"<td>{v:.4g}</td>" for v in row) + "</tr>"
                   for row in zip(*(cycles[n] for n in cycles.columns)))
    failed = [c for c in chewing.checks if c.passed is False]
    checks = "".join(f"<li><b>{html.escape(c.name)}</b> ({c.severity}): {html.escape(c.message)}</li>" for c in failed) or "<li>none</li>"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Chewing: {html.escape(chewing.food.name)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}td,th{{padding:2px 8px;text-align:right}}
pre{{background:#f4f4f4;padding:8px;overflow:auto}}</style></head><body>
<h1>Chewing sequence: {html.escape(chewing.food.name)}</h1>
<p>The bolus after each cycle (docs/bolus.md). The motion's own report: <a href="report.html">report.html</a>.</p>
<h2>Failed checks</h2><ul>{checks}</ul>
<table><tr>{head}</tr>{body}</table>
<h2>X50 against cycles</h2><img src="x50.png" alt="X50 against cycles" width="800">
<h2>Particle size distribution</h2><img src="psd.png" alt="particle size distribution" width="800">
<h2>Force and work per cycle</h2><img src="force_per_cycle.png" alt="force and work per cycle" width="800">
<h2>The sequence</h2><pre>{html.escape(to_json(chewing.record()))}</pre>
</body></html>
"""


__all__ = ["CHEW_FOLDER", "CYCLES_FILE", "PSD_FILE", "TPA_FILE", "cycles_table", "psd_table", "tpa_table", "write"]
