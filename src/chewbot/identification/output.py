"""Writing an identification: the model file with the estimates in place, and the table of estimates beside it.

The model file is the start model's own TOML with its layout and comments kept (tomlkit): the identified values
replace the old ones (each with a comment giving its standard error), their keys move from ``assumed`` to the
top-level ``identified``, and a header of comments says where they come from. Its first line is chewbot's marker,
so that ``--force`` can replace it; a marker line the start file had (an identified model identified again) is
replaced, not repeated.

The table (CSV, the same as the printed one, ``MODEL.identification.csv``): one row per parameter, file units, with
the run's summary (log, condition number, residuals, non-identifiable combinations) as ``#`` lines above the header.
"""

from __future__ import annotations

import csv
import io

import tomlkit

from chewbot.files import without_marker

TABLE_COLUMNS = ("parameter", "key", "unit", "start", "estimate", "standard_error", "status")


def _format(value: float) -> float:
    """A value as written: 10 significant digits (far below any standard error), as a float."""
    return float(f"{value:.10g}")


def model_text(source_text: str, values: dict[str, object], identified: list[str], header: list[str],
               comments: dict[str, str], uncertainty: dict[str, object] | None = None) -> str:
    """The start model's TOML text with ``values`` (file key -> number or nested list) in place, their keys in
    ``identified`` and out of ``assumed``, ``comments`` (file key -> text) beside them, ``header`` lines on top
    (the marker line first) and ``uncertainty`` as its ``[uncertainty]`` section (the start file's replaced;
    none where it is empty)."""
    doc = tomlkit.parse(without_marker(source_text))
    for key, value in values.items():
        section, leaf = key.split(".")
        nested = isinstance(value, list) and isinstance(value[0], list)
        item = tomlkit.item([[_format(v) for v in row] for row in value] if nested else
                            [_format(v) for v in value] if isinstance(value, list) else _format(value))
        if nested:
            item.multiline(True)
        doc[section][leaf] = item
        if key in comments and not isinstance(value, list):
            doc[section][leaf].comment(comments[key])
    assumed = [k for k in doc.get("assumed", []) if k not in identified]
    previous = [k for k in doc.get("identified", []) if k not in identified]
    if "assumed" in doc:
        array = tomlkit.array()
        array.extend(assumed)
        array.multiline(True)
        doc["assumed"] = array
    array = tomlkit.array()
    array.extend(previous + identified)
    array.multiline(True)
    if "identified" in doc:
        doc["identified"] = array
    else:
        _insert_after(doc, "assumed" if "assumed" in doc else "gravity_m_per_s2", "identified", array)
    if "uncertainty" in doc:
        del doc["uncertainty"]
    if uncertainty:
        doc.add(tomlkit.nl())
        doc.add("uncertainty", _uncertainty_table(uncertainty))
    return "".join(line + "\n" for line in header) + tomlkit.dumps(doc)


def _uncertainty_table(uncertainty: dict[str, object]):
    """The ``[uncertainty]`` table: arrays of numbers to 10 digits, matrices one row a line."""
    table = tomlkit.table()
    table.comment("written by chewbot identify: how well the values above are known (docs/models.md)")
    notes = {"keys": "the estimated keys, as --set names them",
             "standard_error": "one per key, in the key's unit",
             "correlation": "of the keys' estimates (1)",
             "torque_error_Nm": "the torque error the model leaves, per actuator (N*m): sensors' noise and what it misses",
             "torque_error_correlation": "of that torque error between the actuators (1)"}
    for key, value in uncertainty.items():
        if value and isinstance(value[0], list):
            item = tomlkit.array()
            for row in value:
                item.append([_format(v) for v in row])
            item.multiline(True)
        else:
            item = tomlkit.array()
            item.extend([v if isinstance(v, str) else _format(v) for v in value])
            if key == "keys":
                item.multiline(True)
        table.add(tomlkit.comment(notes[key]))
        table.add(key, item)
    return table


def _insert_after(doc, after: str, key: str, value) -> None:
    """Put ``key`` into the top level of ``doc`` right after ``after`` (before the tables)."""
    items = list(doc.items())
    doc.clear()
    for k, v in items:
        doc[k] = v
        if k == after:
            doc[key] = value


def table_text(rows: list[dict]) -> str:
    """The CSV of the estimates: the header, a row per parameter (plain CSV: the marker and the fit's summary are
    in its sidecar, ``NAME.identification.csv.chewbot.json``)."""
    out = io.StringIO()
    writer = csv.DictWriter(out, TABLE_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow(row)
    return out.getvalue()

