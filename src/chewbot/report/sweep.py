"""``report.html`` of a sweep: one self-contained page (plotly.js inlined) in the template of a run's report.

What it shows follows the kind: histograms of every output (all kinds but the maps), Sobol' first-order and total
indices with their confidence intervals as bars, heat maps of a grid (over two coordinates or parameters; over
more, the two first with the others reduced: the share of reachable poses, the smallest value of the others),
the convergence of a search and its optimum; then the failed evaluations grouped by reason, and the sweep's
details. The histograms are accumulated over the rows of samples.parquet batch by batch, so the page costs no
more memory for a million evaluations than for a thousand (the scatter plots show the first
:data:`SCATTER_POINTS` evaluations).
"""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import numpy as np
import plotly.graph_objects as go
import pyarrow.parquet as pq

from chewbot.report.html import escape, html_table, figure_layout, render_page
from chewbot.sweep.quantities import OUTPUTS

BINS = 40
SCATTER_POINTS = 2000
HEATMAP_CELLS = 250_000
NAV = (("summary", "Summary"), ("results", "Results"), ("failures", "Failures"), ("details", "Details"))


def write_report(result, path: Path) -> Path:
    """Write the report of a finished sweep (``result``: :class:`chewbot.outputs.sweep.SweepResult`)."""
    from chewbot.sweep.evaluate import output_descriptions
    from chewbot.sweep.record import SAMPLES_FILE

    spec = result.spec
    samples = pq.ParquetFile(result.folder / SAMPLES_FILE)
    columns = output_descriptions(spec)
    figures: dict[str, go.Figure] = {}
    body = [_summary(result), '<section id="results"><h2>Results</h2>']
    if result.indices:
        body.append(_sobol(result, columns, figures))
    if result.optimum is not None:
        body.append(_search(result, figures))
    if spec.kind == "grid":
        body.append(_heat_maps(spec, samples, columns, figures))
    else:
        body.append(_histograms(samples, columns, figures))
        body.append(_scatter(spec, samples, columns, figures))
    body.append("</section>")
    body.append(_failures(samples))
    body.append(_details(result))
    what = f"{spec.kind} sweep of {Path(spec.model).stem}"
    page = render_page(title=f"chewbot sweep: {what}", subtitle=f"{result.evaluations} evaluations · {spec.source}",
                       nav=NAV, body="\n".join(body), figures=figures)
    Path(path).write_text(page, encoding="utf-8")
    return Path(path)


def _label(name: str, columns: dict) -> str:
    unit = columns.get(name, {}).get("unit", "")
    return f"{name} [{unit}]" if unit else name


def _summary(result) -> str:
    spec = result.spec
    rows = [["kind", escape(spec.kind)], ["model", f"<code>{escape(spec.model)}</code>"], ["task", f"<code>{escape(spec.task)}</code>"]]
    if not spec.over_poses:
        rows.append(["run", escape(f"side {spec.side or 'left'}, {spec.orientation}, method {spec.method}"
                               + (f", goal {spec.goal}, friction {spec.friction}" if spec.goal or spec.friction else "")
                               + f", contact {spec.contact}")])
    rows.append(["evaluations", f"{result.evaluations} ({result.failed} failed: NaN outputs, the reason in <code>error</code>)"])
    if result.computed:
        rows.append(["evaluated", f"{result.computed} in {result.computed_chunks} chunk(s)"
                     + (f"; {result.reused_chunks} chunk(s) read back from the interrupted sweep" if result.reused_chunks else "")])
    if spec.fixed:
        rows.append(["set", ", ".join(f"<code>{escape(k)} = {v:g}</code>" for k, v in spec.fixed.items())])
    params = spec.poses or spec.parameters
    table = html_table(["varied", "how", "values"], [[f"<code>{escape(p.key)}</code>", escape(p.kind),
                                                  escape(", ".join(f"{v:g}" for v in p.args[:8]) + (" ..." if len(p.args) > 8 else ""))]
                                                 for p in params])
    return ('<section id="summary"><h2>Summary</h2>' + html_table(["", ""], rows).replace("<td>", "<td class=text>") + table
            + "</section>")


def _sobol(result, columns: dict, figures: dict) -> str:
    spec = result.spec
    parts = ["<h3>Sobol' indices</h3>", f'<p class="note">First-order (S1) and total (ST) indices of each output with '
             f"{100 * spec.confidence:g} % confidence intervals ({spec.resamples} bootstrap resamples, SALib); "
             "sobol_indices.csv has the numbers. ST - S1 is the share of the variance due to interactions.</p>"]
    for k, (name, ind) in enumerate(result.indices.items()):
        fig = go.Figure()
        for key, color in (("S1", "#1f77b4"), ("ST", "#d62728")):
            fig.add_trace(go.Bar(x=list(spec.keys), y=ind[key], name=key, marker_color=color,
                                 error_y=dict(type="data", array=ind[f"{key}_conf"], visible=True)))
        figure_layout(fig, 380)
        fig.update_layout(barmode="group", hovermode="closest", title=dict(text=f"{name}: {ind['blocks']} of "
                          f"{ind['blocks_total']} base samples used", font=dict(size=13)))
        fig.update_yaxes(title_text="index [1]")
        figures[f"sobol{k}"] = fig
        parts.append(f'<div id="sobol{k}" class="plot"></div>')
    return "\n".join(parts)


def _search(result, figures: dict) -> str:
    spec, o = result.spec, result.optimum
    unit = OUTPUTS[spec.minimize].unit
    conv = result.convergence
    fig = go.Figure()
    if conv:
        g = [c["generation"] for c in conv]
        fig.add_trace(go.Scatter(x=g, y=[c["best"] for c in conv], mode="lines+markers", name=f"best {spec.minimize}"))
        fig.add_trace(go.Scatter(x=g, y=[c["convergence"] for c in conv], mode="lines", name="convergence [1]", yaxis="y2"))
    figure_layout(fig, 380)
    fig.update_layout(hovermode="x", yaxis2=dict(overlaying="y", side="right", title="SciPy's convergence measure [1]"))
    fig.update_xaxes(title_text="generation")
    fig.update_yaxes(title_text=f"best {spec.minimize} [{unit}]")
    figures["convergence"] = fig
    rows = [[f"<code>{escape(k)}</code>", f"{v:.6g}"] for k, v in o["parameters"].items()]
    rows += [[escape(k), f"{v:.6g} {escape(OUTPUTS[k].unit)}"] for k, v in o["outputs"].items()]
    rows += [["sample", str(o["sample"])], ["constraints met", "yes" if o["constraints_met"] else "no"],
             ["generations, evaluations", f"{o['generations']}, {o['evaluations']}"], ["SciPy", escape(o["message"])]]
    return ("<h3>Search</h3>" + f'<p class="note">Differential evolution minimising {escape(spec.minimize)}; the best feasible '
            "member of each generation (optimum.csv, convergence.csv).</p>" + '<div id="convergence" class="plot"></div>'
            + "<h3>Optimum</h3>" + html_table(["", ""], rows))


def _numeric(samples: pq.ParquetFile, columns: dict) -> list[str]:
    return [n for n in columns if n in samples.schema_arrow.names]


def _histograms(samples: pq.ParquetFile, columns: dict, figures: dict) -> str:
    names = _numeric(samples, columns)
    lo = {n: np.inf for n in names}
    hi = {n: -np.inf for n in names}
    for batch in samples.iter_batches(columns=names):
        for n in names:
            v = batch.column(n).to_numpy(zero_copy_only=False)
            v = v[np.isfinite(v)]
            if v.size:
                lo[n], hi[n] = min(lo[n], v.min()), max(hi[n], v.max())
    edges = {n: np.linspace(lo[n], hi[n] if hi[n] > lo[n] else lo[n] + 1, BINS + 1) for n in names if np.isfinite(lo[n])}
    counts = {n: np.zeros(BINS, int) for n in edges}
    for batch in samples.iter_batches(columns=list(edges)):
        for n in edges:
            v = batch.column(n).to_numpy(zero_copy_only=False)
            counts[n] += np.histogram(v[np.isfinite(v)], edges[n])[0]
    parts = ["<h3>Distributions of the outputs</h3>", '<p class="note">Histograms over the evaluations that succeeded.</p>',
             '<div class="grid">']
    for k, n in enumerate(edges):
        e = edges[n]
        fig = go.Figure(go.Bar(x=0.5 * (e[1:] + e[:-1]), y=counts[n], width=np.diff(e), marker_color="#2563a8",
                               hovertemplate=f"{n} = %{{x:.4g}}: %{{y}} evaluations<extra></extra>"))
        figure_layout(fig, 300)
        fig.update_layout(hovermode="closest")
        fig.update_xaxes(title_text=_label(n, columns))
        fig.update_yaxes(title_text="evaluations")
        figures[f"hist{k}"] = fig
        parts.append(f'<div id="hist{k}" class="plot"></div>')
    return "\n".join(parts) + "</div>"


def _scatter(spec, samples: pq.ParquetFile, columns: dict, figures: dict) -> str:
    names = _numeric(samples, columns)
    if not names:
        return ""
    first = next(samples.iter_batches(batch_size=SCATTER_POINTS, columns=[*spec.keys, *names]))
    parts = ["<h3>Outputs against the parameters</h3>",
             f'<p class="note">The first {first.num_rows} evaluations; pick the output in the menu.</p>', '<div class="grid">']
    for k, key in enumerate(spec.keys):
        x = first.column(key).to_numpy(zero_copy_only=False)
        fig = go.Figure()
        for j, n in enumerate(names):
            fig.add_trace(go.Scattergl(x=x, y=first.column(n).to_numpy(zero_copy_only=False), mode="markers", name=n,
                                       marker=dict(size=4, opacity=0.6), visible=j == 0))
        buttons = [dict(label=n, method="update", args=[{"visible": [i == j for i in range(len(names))]},
                                                         {"yaxis.title.text": _label(n, columns)}]) for j, n in enumerate(names)]
        figure_layout(fig, 320)
        fig.update_layout(hovermode="closest", showlegend=False, updatemenus=[dict(buttons=buttons, x=1, xanchor="right", y=1.15)])
        fig.update_xaxes(title_text=key)
        fig.update_yaxes(title_text=_label(names[0], columns))
        figures[f"scatter{k}"] = fig
        parts.append(f'<div id="scatter{k}" class="plot"></div>')
    return "\n".join(parts) + "</div>"


def _heat_maps(spec, samples: pq.ParquetFile, columns: dict, figures: dict) -> str:
    params = spec.poses or spec.parameters
    names = _numeric(samples, columns)
    if np.prod([len(p.args) for p in params[:2]]) > HEATMAP_CELLS:
        return f'<p class="note">The grid has more than {HEATMAP_CELLS} cells in its two first coordinates: no heat maps.</p>'
    table = samples.read(columns=[*spec.keys, *names])
    shape = tuple(len(p.args) for p in params)
    parts = ["<h3>Maps</h3>"]
    if len(params) > 2:
        parts.append(f'<p class="note">Over {params[0].key} and {params[1].key}; the other coordinates are reduced: reachable '
                     "is the share of reachable poses, every other map the smallest value over them.</p>")
    parts.append('<div class="grid">')
    for k, n in enumerate(names):
        z = table.column(n).to_numpy(zero_copy_only=False).reshape(shape)
        if len(shape) > 2:
            axes = tuple(range(2, len(shape)))
            with np.errstate(all="ignore"):
                z = z.mean(axis=axes) if n == "reachable" else np.nanmin(z, axis=axes)
        if len(shape) == 1:
            fig = go.Figure(go.Scatter(x=params[0].args, y=z, mode="lines+markers"))
            fig.update_xaxes(title_text=params[0].key)
            fig.update_yaxes(title_text=_label(n, columns))
        else:
            z = np.where(np.isfinite(z), z, np.nan)
            fig = go.Figure(go.Heatmap(x=params[1].args, y=params[0].args, z=z, colorscale="Viridis",
                                       colorbar=dict(title=dict(text=_label(n, columns), side="right")),
                                       hovertemplate=f"{params[1].key} = %{{x:.4g}}<br>{params[0].key} = %{{y:.4g}}<br>"
                                                     f"{n} = %{{z:.4g}}<extra></extra>"))
            fig.update_xaxes(title_text=params[1].key)
            fig.update_yaxes(title_text=params[0].key)
        figure_layout(fig, 380)
        fig.update_layout(hovermode="closest", title=dict(text=_label(n, columns), font=dict(size=13)))
        figures[f"map{k}"] = fig
        parts.append(f'<div id="map{k}" class="plot"></div>')
    return "\n".join(parts) + "</div>"


_NUMBER = re.compile(r"-?\d+(\.\d+)?(e[-+]?\d+)?")


def _failures(samples: pq.ParquetFile) -> str:
    """The failed evaluations grouped by their reason with the numbers left out (one example of each shown)."""
    reasons, first = Counter(), {}
    for batch in samples.iter_batches(columns=["sample", "error"]):
        for s, e in zip(batch.column("sample").to_pylist(), batch.column("error").to_pylist()):
            if e is not None:
                kind = _NUMBER.sub("#", e)
                reasons[kind] += 1
                first.setdefault(kind, (s, e))
    if not reasons:
        return '<section id="failures"><h2>Failures</h2><p>Every evaluation succeeded.</p></section>'
    rows = [[str(c), str(first[r][0]), escape(first[r][1])] for r, c in reasons.most_common(20)]
    more = f"<p class=note>... and {len(reasons) - 20} other reasons (samples.parquet, column error).</p>" if len(reasons) > 20 else ""
    return ('<section id="failures"><h2>Failures</h2><p class="note">Evaluations with NaN outputs, grouped by the reason '
            "in their <code>error</code> column (its numbers aside): how many, and the first of each.</p>"
            + html_table(["evaluations", "first sample", "its reason"], rows)
            .replace("<td>", "<td class=text>") + more + "</section>")


def _details(result) -> str:
    import json

    record = json.loads((result.folder / "run.json").read_text())
    rows = [["SPEC", f"<code>{escape(result.spec.source)}</code> (a copy: spec.toml)"],
            ["cluster", escape(", ".join(f"{k} {v}" for k, v in record.get("cluster", {}).items()))],
            ["time", f"{result.elapsed_s:.1f} s"], ["started", escape(record.get("started", ""))],
            ["versions", escape(", ".join(f"{k} {v}" for k, v in record.get("versions", {}).items()))]]
    return '<section id="details"><h2>Details</h2>' + html_table(["", ""], rows).replace("<td>", "<td class=text>") + "</section>"
