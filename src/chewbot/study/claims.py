"""The claims table of a study: a paper's finding, our figure, whether we reproduce it, and why not."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

# Version of study.json, the key "chewbot_study" by which chewbot recognises a study folder it wrote
# (chewbot.files.STUDY_FOLDER).
STUDY_FORMAT = 1


@dataclass(frozen=True)
class Claim:
    """One row of the claims table; ``item`` numbers the findings as docs/conventions.md lists them."""

    item: int
    variant: str
    claim: str
    ours: str
    reproduced: bool | None  # None: undetermined (a timing inside the run-to-run spread)
    reason: str = ""

    @property
    def verdict(self) -> str:
        return {True: "yes", False: "no", None: "undetermined"}[self.reproduced]


def write_claims(rows: list[Claim], folder: Path) -> None:
    """``claims.md`` and ``claims.csv`` in ``folder``."""
    lines = ["| item | model | the paper's claim | our figure | reproduced | reason where not |", "|---|---|---|---|---|---|"]
    lines += [f"| {r.item} | {r.variant} | {r.claim} | {r.ours} | {r.verdict} | {r.reason} |" for r in rows]
    (folder / "claims.md").write_text("\n".join(lines) + "\n")
    with open(folder / "claims.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["item", "model", "claim", "ours", "reproduced", "reason"])
        writer.writerows([r.item, r.variant, r.claim, r.ours, r.verdict, r.reason] for r in rows)


def claims_table(folder: Path):
    """The claims of a written study folder (its claims.csv) as a rich table, for the terminal."""
    from rich.markup import escape
    from rich.table import Table as RichTable

    with open(Path(folder) / "claims.csv", newline="") as f:
        rows = list(csv.reader(f))
    table = RichTable(title=f"claims: {escape(str(folder))}", title_justify="left", show_lines=True)
    for name in rows[0]:
        table.add_column(name, overflow="fold", justify="right" if name == "item" else "left")
    for row in rows[1:]:
        table.add_row(*(escape(cell) for cell in row))
    return table
