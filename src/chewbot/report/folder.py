"""The figures and report.html of a results folder, drawn from what the folder holds: its record as run.json has it
(read back from JSON, NaN as null) and the view of its results.csv (:class:`chewbot.report.view.RunView`, built as
the rows were written, or from reading them back). A run draws them right after writing its data, ``chewbot report
DIR`` later from the folder: the same inputs, the same drawings."""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path

from chewbot.model import Model
from chewbot.report.view import RunView


def drawing_names(record: dict, view: RunView, figures: bool = True, report: bool = True) -> list[str]:
    """The files :func:`draw` writes for a run with this record and view (the figures as asked, report.html)."""
    from chewbot.report.figures import figure_names

    return (figure_names(view.columns, record["options"].get("method")) if figures else []) + (["report.html"] if report else [])


def draw(folder: Path, record: dict, model: Model, view: RunView, figures: bool = True, report: bool = True, progress=None,
         beside: Path | None = None, drawer=None) -> list[Path]:
    """Draw the figures and write report.html (as asked) into ``folder``; their paths. The figures are drawn by two
    processes where there are two cores (:func:`chewbot.report.figures.drawn`; ``drawer``: a drawing process forked
    before, :func:`chewbot.report.figures.drawing_process`). The report links to results.csv, run.json, the figures
    drawn and those that ``beside`` (the folder these files will join) has."""
    from chewbot.report.figures import drawn, figure_names
    from chewbot.report.html import write_report

    step = progress or (lambda msg, done=None, total=None, stage=None: None)
    options = record["options"]
    method, contact = options.get("method"), options.get("contact", "bilateral")
    folder = Path(folder)
    with drawn(view.series, method, folder, contact, step, drawer) if figures else nullcontext([]) as written:
        if report:
            step("writing report.html")
            linked = {p.name for p in written} | {name for name in figure_names(view.columns, method)
                                                  if beside is not None and (beside / name).exists()}
            report_path = write_report(record, model, view, folder / "report.html", files=sorted(["results.csv", "run.json", *linked]))
    return [*written, *([report_path] if report else [])]
