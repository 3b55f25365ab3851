"""The figures and report.html of a results folder, drawn from what the folder holds: its record as run.json has it
(read back from JSON, NaN as null) and the view of its results.csv (:class:`chewbot.report.view.RunView`, built as
the rows were written, or from reading them back). A run draws them right after writing its data, ``chewbot report
DIR`` later from the folder: the same inputs, the same drawings."""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path

from chewbot.model import Model
from chewbot.progress import SILENT, Progress
from chewbot.report.view import RunView


def drawing_names(record: dict, view: RunView, figures: bool = True, report: bool = True) -> list[str]:
    """The files :func:`draw` writes for a run with this record and view (the figures as asked, report.html)."""
    from chewbot.report.figures import figure_names

    return (figure_names(view.columns, record["options"].get("method")) if figures else []) + (["report.html"] if report else [])


def figures_drawn(folder: Path, view: RunView, method: str | None, contact: str = "bilateral", figures: bool = True,
                  progress: Progress = SILENT, drawer=None):
    """A block during which the figures of a run (none unless ``figures``) are drawn into ``folder`` from ``view``'s
    series; it yields their paths. They are drawn by two processes where there are two cores
    (:func:`chewbot.report.figures.drawn`; ``drawer``: a drawing process forked before,
    :func:`chewbot.report.figures.drawing_process`), so that what the block does (a run's last rows, its run.json,
    the report) is done meanwhile."""
    from chewbot.report.figures import drawn

    return drawn(view.series, method, Path(folder), contact, progress, drawer) if figures else nullcontext([])


def write_page(folder: Path, record: dict, model: Model, view: RunView, figures: list[Path], progress: Progress = SILENT,
               beside: Path | None = None) -> Path:
    """report.html in ``folder``, from the record as run.json has it and the view; it links to results.csv, run.json,
    ``figures`` and those of the run's figures that ``beside`` (the folder these files will join) has."""
    from chewbot.report.figures import figure_names
    from chewbot.report.html import write_report

    progress("writing report.html")
    linked = {p.name for p in figures} | {name for name in figure_names(view.columns, record["options"].get("method"))
                                          if beside is not None and (beside / name).exists()}
    return write_report(record, model, view, Path(folder) / "report.html", files=sorted(["results.csv", "run.json", *linked]))


def draw(folder: Path, record: dict, model: Model, view: RunView, figures: bool = True, report: bool = True,
         progress: Progress = SILENT, beside: Path | None = None, drawer=None) -> list[Path]:
    """Draw the figures and write report.html (as asked) into ``folder``; their paths (:func:`figures_drawn`,
    :func:`write_page`)."""
    options = record["options"]
    with figures_drawn(folder, view, options.get("method"), options.get("contact", "bilateral"), figures, progress, drawer) as written:
        page = [write_page(folder, record, model, view, written, progress, beside)] if report else []
    return [*written, *page]
