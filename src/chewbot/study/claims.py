"""The claims table of a study: a paper's finding, our figure, whether we reproduce it, and why not."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path


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
