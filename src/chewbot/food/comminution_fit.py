"""Fitting a food's selection and breakage to measured sievings (``chewbot fit-comminution``).

**SIEVING.csv** (docs/bolus.md): one row per sieve of a measured distribution, columns ``chews [1]`` (the number of
chewing strokes before the bolus was spat out), ``sieve [mm]`` (the aperture: 5.6, 4, 2.8, 2, 1.4, 1, 0.71, 0.5,
and 0 for the pan; another length unit in the brackets is converted), ``mass_fraction [1]`` (the mass retained on
it over the bolus's) and, optionally, ``subject`` (a text naming whose bolus it was). A distribution is the rows of
one subject and chew count: every sieve and the pan once, fractions summing to 1 within
:data:`FRACTION_SUM_TOLERANCE` (the rounding of a lab's table). Read with pyarrow (every cell as text), each row
validated by a strict model (:class:`SievingRow`); a mistake names the file, the row (1-based, the header is row 1)
and the column.

**The fit**: the food's ideal chewing sequence (:func:`chewbot.food.bolus.chew`, the strokes' force and gap given)
predicts the fractions after each measured chew count; SciPy's ``least_squares`` (trust region, bounds from each
key's plausible range) adjusts the chosen keys (:data:`DEFAULT_KEYS` unless told) to minimise the squared
differences of the fractions, every distribution weighted alike. The residuals and their exact Jacobian come from
one CasADi graph of the whole sequence (the laws of :mod:`chewbot.food.bolus` written once), so there is no finite
difference anywhere. Standard errors: s^2 (J^T J)^-1 at the optimum, s^2 the residual sum of squares over the degrees
of freedom, 8 per distribution (its nine fractions sum to 1) less the number of keys.

The food file is written back with the fitted values in place (:func:`fitted_food_text`, tomlkit: the layout and
comments kept), each with its standard error as a comment, and their keys listed in ``comminution.fitted``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, ValidationError

from chewbot.config import Strict, format_validation_error
from chewbot.errors import ChewbotError
from chewbot.files import without_marker
from chewbot.food.bolus import CLOSING_FORCE_N, MIN_GAP_MM, SIEVE, Bolus, ideal_stroke, stroke
from chewbot.food.comminution import FITTABLE, PARAMETERS, ComminutionTable
from chewbot.food.law import CASADI
from chewbot.food.sieving import SIEVES_MM, SIEVING_MM
from chewbot import units
from chewbot.units import HEADER_CELL, unit_factor
from chewbot.progress import SILENT, Progress

# The keys fitted unless the command names others: the rate of selection, the strength and the fragments' size.
DEFAULT_KEYS = ("placement", "strength_at_1mm_MPa", "fragment_size")
# How far a distribution's fractions may sum from 1 (a lab's table rounded to 3 decimals on 9 rows).
FRACTION_SUM_TOLERANCE = 0.01
COLUMNS = {"chews": "1", "sieve": "mm", "mass_fraction": "1", "subject": None}


class SievingError(ChewbotError):
    """A SIEVING.csv is malformed: names the file, row and column."""


class SievingRow(Strict):
    """One row of SIEVING.csv, its numbers parsed (the sieve in mm)."""

    chews: Annotated[int, Field(ge=0, le=1000)]
    sieve: Literal[SIEVING_MM]
    mass_fraction: Annotated[float, Field(ge=0, le=1)]
    subject: str = ""


@dataclass(frozen=True)
class Sieving:
    """Measured distributions: ``chews`` (per distribution), ``subjects``, ``fractions`` (distributions x
    :data:`~chewbot.food.sieving.SIEVING_MM`), ``rows`` (the first file row of each), ``source`` the file."""

    chews: np.ndarray
    subjects: list[str]
    fractions: np.ndarray
    rows: list[int]
    source: str

    @property
    def counts(self) -> list[int]:
        """The distinct chew counts, in order."""
        return sorted(set(int(n) for n in self.chews))


def read_sieving(path: Path | str) -> Sieving:
    """SIEVING.csv (the module's docstring); :class:`SievingError` naming the file, row and column."""
    import pyarrow as pa
    import pyarrow.csv as pc

    path = Path(path)
    if not path.is_file():
        raise SievingError(f"{path}: no such sieving file")
    ragged = []  # rows with another number of cells than the header (pyarrow gives their text, not their number)

    def invalid(row):
        ragged.append(row)
        return "skip"

    try:
        header = pc.read_csv(path, read_options=pc.ReadOptions(skip_rows_after_names=10**9)).column_names
        table = pc.read_csv(path, convert_options=pc.ConvertOptions(column_types={h: pa.string() for h in header},
                                                                    strings_can_be_null=False),
                            parse_options=pc.ParseOptions(invalid_row_handler=invalid))
    except (pa.ArrowInvalid, OSError, UnicodeDecodeError) as exc:
        raise SievingError(f"{path}: not a readable CSV ({exc})") from None
    if ragged:
        lines = path.read_text(encoding="utf-8").splitlines()
        row = next((i + 1 for i, line in enumerate(lines) if line == ragged[0].text), "?")
        raise SievingError(f"{path}: row {row}: {ragged[0].actual_columns} cell(s), the header has "
                           f"{ragged[0].expected_columns}")
    columns: dict[str, tuple[str, float]] = {}  # name -> (header cell, factor to the column's unit)
    for cell in header:
        m = HEADER_CELL.match(cell)
        name, unit = (m.group(1), m.group(2)) if m else (cell, None)
        if name not in COLUMNS:
            raise SievingError(f"{path}: column {cell!r}: not a column of a sieving (chews [1], sieve [mm], "
                               "mass_fraction [1], subject)")
        if name in columns:
            raise SievingError(f"{path}: column {cell!r}: given twice")
        want = COLUMNS[name]
        if name == "sieve":
            try:
                factor = unit_factor(unit or "", "length") / units.factor("mm")
            except ValueError as exc:
                raise SievingError(f"{path}: column {cell!r}: {exc}") from None
        elif unit not in (None, "", want) or (want is None and unit):
            raise SievingError(f"{path}: column {cell!r}: the unit of {name} is {want or 'none'}, not {unit!r}")
        else:
            factor = 1.0
        columns[name] = (cell, factor)
    for name in ("chews", "sieve", "mass_fraction"):
        if name not in columns:
            raise SievingError(f"{path}: no column {name} [{COLUMNS[name]}] (the columns: chews [1], sieve [mm], "
                               "mass_fraction [1], optional subject)")
    data = {name: table.column(cell).to_pylist() for name, (cell, _) in columns.items()}
    groups: dict[tuple[str, int], dict[float, tuple[int, float]]] = {}
    for i in range(table.num_rows):
        row = i + 2  # the header is row 1
        values = {}
        for name, (cell, factor) in columns.items():
            text = data[name][i].strip()
            if name == "subject":
                values[name] = text
                continue
            try:
                number = float(text)
            except ValueError:
                raise SievingError(f"{path}: row {row}, column {cell!r}: {text!r} is not a number") from None
            if name == "chews":
                if number != int(number):
                    raise SievingError(f"{path}: row {row}, column {cell!r}: {text!r} is not a whole number of chews")
                number = int(number)
            elif name == "sieve":
                number = number * factor
                match = [s for s in SIEVING_MM if math.isclose(number, s, rel_tol=1e-9, abs_tol=1e-9)]
                if not match:
                    raise SievingError(f"{path}: row {row}, column {cell!r}: {number:g} mm is not one of the sieves "
                                       f"({', '.join(f'{s:g}' for s in SIEVES_MM)} mm; 0 the pan)")
                number = match[0]
            values[name] = number
        try:
            parsed = SievingRow(**values)
        except ValidationError as exc:
            message = format_validation_error(f"{path}: row {row}", exc)
            raise SievingError(re.sub(r": key '(\w+)'", lambda m: f", column {columns[m.group(1)][0]!r}", message)) from None
        sieves = groups.setdefault((parsed.subject, parsed.chews), {})
        if parsed.sieve in sieves:
            raise SievingError(f"{path}: row {row}: sieve {parsed.sieve:g} mm of subject {parsed.subject!r} after "
                               f"{parsed.chews} chews given twice (also row {sieves[parsed.sieve][0]})")
        sieves[parsed.sieve] = (row, parsed.mass_fraction)
    if not groups:
        raise SievingError(f"{path}: no rows")
    chews, subjects, fractions, rows = [], [], [], []
    for (subject, n), sieves in groups.items():
        first = min(r for r, _ in sieves.values())
        missing = [s for s in SIEVING_MM if s not in sieves]
        who = f"subject {subject!r} after {n} chews" if subject else f"the distribution after {n} chews"
        if missing:
            raise SievingError(f"{path}: {who} (from row {first}): no row for sieve(s) "
                               f"{', '.join(f'{s:g} mm' for s in missing)} (0 is the pan)")
        f = np.array([sieves[s][1] for s in SIEVING_MM])
        if abs(f.sum() - 1) > FRACTION_SUM_TOLERANCE:
            raise SievingError(f"{path}: {who} (from row {first}): the mass fractions sum to {f.sum():.4g}, not 1 "
                               f"(within {FRACTION_SUM_TOLERANCE:g})")
        chews.append(n)
        subjects.append(subject)
        fractions.append(f / f.sum())
        rows.append(first)
    return Sieving(np.array(chews), subjects, np.array(fractions), rows, str(path))


# ------------------------------------------------------------------------------------------- prediction


def predicted_graph(table: ComminutionTable, keys, counts, closing_force: float, min_gap: float):
    """The CasADi function theta (``keys``' values in file units) -> the sieve fractions after each of ``counts``
    ideal strokes (the fractions of :data:`~chewbot.food.sieving.SIEVING_MM`, count after count), and its Jacobian.
    One stroke is an SX function of (theta, masses); the sequence chains it in an MX graph."""
    import casadi as ca

    theta = ca.SX.sym("theta", len(keys))
    mass = ca.SX.sym("mass", len(Bolus.portion(table).mass))
    c = dict(table.si())
    for k, key in enumerate(keys):
        c[key] = theta[k] * PARAMETERS[key][0]
    gap, force, _ = ideal_stroke(CASADI, c, mass, closing_force, min_gap)
    one = ca.Function("stroke", [theta, mass], [stroke(CASADI, c, mass, gap, force)[0]])
    theta_mx = ca.MX.sym("theta", len(keys))
    start = Bolus.portion(table).mass
    state = ca.MX(ca.DM(start))
    sieve = ca.DM(SIEVE) / float(np.sum(start))
    out = []
    for n in range(max(counts) + 1):
        if n in counts:
            out.append(ca.mtimes(sieve, state))
        if n < max(counts):
            state = one(theta_mx, state)
    flat = ca.vertcat(*out)
    return ca.Function("sieving", [theta_mx], [flat, ca.jacobian(flat, theta_mx)])


@dataclass(frozen=True)
class ComminutionFit:
    """A fit: the ``keys``, their ``start`` and fitted ``values`` and ``standard_errors`` (file units), the residual
    root mean square ``rms`` of the fractions, ``dof``, the ``correlation`` matrix of the estimates, the
    measured and fitted fractions per distribution, the fitted table."""

    keys: tuple[str, ...]
    start: np.ndarray
    values: np.ndarray
    standard_errors: np.ndarray
    rms: float
    dof: int
    correlation: np.ndarray
    measured: np.ndarray
    fitted: np.ndarray
    table: ComminutionTable
    converged: bool
    at_bound: tuple[str, ...] = field(default=())

    def rows(self) -> list[dict]:
        """One row per key: key, unit, start, estimate, standard error."""
        return [{"key": key, "unit": PARAMETERS[key][1], "start": float(s), "estimate": float(v),
                 "standard_error": float(e)} for key, s, v, e in zip(self.keys, self.start, self.values, self.standard_errors)]


def fit_comminution(table: ComminutionTable, sieving: Sieving, keys=DEFAULT_KEYS,
                    closing_force: float = CLOSING_FORCE_N, min_gap: float = MIN_GAP_MM * units.factor("mm"),
                    progress: Progress = SILENT, check=None) -> ComminutionFit:
    """Fit ``keys`` of ``table`` to ``sieving`` (module docstring); ``progress(message)`` is told of each evaluation,
    ``check()`` is called there (it raises to stop)."""
    from scipy.optimize import least_squares

    keys = tuple(keys)
    for key in keys:
        if key not in FITTABLE:
            raise ChewbotError(f"{key!r} is not a key a fit sets (those are {', '.join(FITTABLE)})")
    if len(set(keys)) != len(keys):
        raise ChewbotError("a key to fit is named twice")
    counts = sieving.counts
    graph = predicted_graph(table, keys, counts, closing_force, min_gap)
    where = [counts.index(int(n)) for n in sieving.chews]
    measured = sieving.fractions
    n_sieves = len(SIEVING_MM)
    evaluations = 0
    last: dict = {}

    def evaluate(theta):  # the residual and the Jacobian at one theta, computed once
        nonlocal evaluations
        if check is not None:
            check()
        if last.get("theta") is None or not np.array_equal(last["theta"], theta):
            value, jac = graph(theta)
            value = np.asarray(value).reshape(len(counts), n_sieves)
            jac = np.asarray(jac).reshape(len(counts), n_sieves, len(keys))
            evaluations += 1
            last.update(theta=np.array(theta), result=(value[where], jac[where]))
        return last["result"]

    def residual(theta):
        predicted, _ = evaluate(theta)
        r = (predicted - measured).ravel()
        progress(f"least squares: evaluation {evaluations}, cost {0.5 * float(r @ r):.4g}")
        return r

    def jacobian(theta):
        return evaluate(theta)[1].reshape(-1, len(keys))

    start = np.array([getattr(table, key) for key in keys], float)
    low = np.array([PARAMETERS[k][2] for k in keys])
    high = np.array([PARAMETERS[k][3] for k in keys])
    progress(f"least squares: {len(keys)} parameters, {len(measured)} distributions")
    sol = least_squares(residual, np.clip(start, low, high), jac=jacobian, bounds=(low, high), x_scale="jac",
                        xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    J = jacobian(sol.x)
    dof = (n_sieves - 1) * len(measured) - len(keys)
    rss = float(sol.fun @ sol.fun)
    info = J.T @ J
    if dof <= 0:
        raise ChewbotError(f"{sieving.source}: {len(measured)} distribution(s) give {(n_sieves - 1) * len(measured)} "
                           f"independent fractions, too few for {len(keys)} parameters and their standard errors")
    cov = rss / dof * np.linalg.pinv(info)
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    scale = np.where(se > 0, se, 1.0)
    correlation = cov / np.outer(scale, scale)
    values = {**table.model_dump(), **{k: float(v) for k, v in zip(keys, sol.x)}}
    values["fitted"] = sorted(set(table.fitted) | set(keys), key=FITTABLE.index)
    fitted_table = ComminutionTable(**values)
    at_bound = tuple(k for k, v, lo, hi in zip(keys, sol.x, low, high)
                     if math.isclose(v, lo, rel_tol=1e-6) or math.isclose(v, hi, rel_tol=1e-6))
    return ComminutionFit(keys, start, sol.x.copy(), se, math.sqrt(rss / sol.fun.size), dof, correlation, measured,
                          evaluate(sol.x)[0], fitted_table, bool(sol.status > 0), at_bound)


def fit_checks(fit: ComminutionFit, cycles: int, closing_force: float = CLOSING_FORCE_N,
               min_gap: float = MIN_GAP_MM * units.factor("mm")) -> list:
    """The validity checks of a fit (as run.json's ``"checks"``): the least squares converged; the fitted food's
    chewing sequence of ``cycles`` ideal strokes conserves the bolus's mass (1e-9 relative) and its X50 never
    rises; no key ended at the bound of its plausible range (a warning: the data push it out of what is
    plausible)."""
    from chewbot.analysis.checks import CheckResult
    from chewbot.food.bolus import chew

    chewing = chew(fit.table, cycles, closing_force, min_gap)
    total = chewing.boluses[0].total
    drift = np.array([abs(b.total - total) / total for b in chewing.boluses])
    x50 = np.array([r.x50_mm for r in chewing.rosin_rammler()])
    known = np.flatnonzero(np.isfinite(x50))
    rises = known[1:][np.diff(x50[known]) > 1e-9 * x50[known][:-1]]
    checks = [
        CheckResult("fit-converged", fit.converged, 0 if fit.converged else 1, None, None,
                    "the least squares converged" if fit.converged else "the least squares stopped without converging "
                    "(its evaluation limit)", "failure"),
        CheckResult("mass-conserved", bool(drift.max() <= 1e-9), int(np.sum(drift > 1e-9)), None,
                    {"value": float(drift.max()), "unit": "1"},
                    f"the bolus's mass over {cycles} strokes of the fitted food: largest relative change "
                    f"{drift.max():.3g} (bound 1e-9)", "failure"),
        CheckResult("x50-monotone", bool(rises.size == 0), int(rises.size), None, None,
                    f"X50 {'never rises' if rises.size == 0 else f'rises at {rises.size} stroke(s), the first at stroke {int(rises[0])}'} "
                    f"over {cycles} strokes of the fitted food", "failure"),
        CheckResult("parameter-at-bound", not fit.at_bound, len(fit.at_bound), None, None,
                    "every fitted key inside its plausible range" if not fit.at_bound else
                    f"at the bound of the plausible range: {', '.join(fit.at_bound)} (the data push it beyond what "
                    "is plausible; the standard errors there do not hold)", "warning"),
    ]
    return checks


# ------------------------------------------------------------------------------------------- the file


def fitted_food_text(source_text: str, fit: ComminutionFit, header: list[str]) -> str:
    """The food file's text with the fitted values of ``[comminution]`` in place (10 significant digits), each
    commented with its standard error, ``fitted`` listing the keys a fit set, and ``header`` lines on top (chewbot's
    marker first; a marker line the file had is replaced)."""
    import tomlkit

    doc = tomlkit.parse(without_marker(source_text))
    section = doc["comminution"]
    for key, value, se in zip(fit.keys, fit.values, fit.standard_errors):
        section[key] = tomlkit.item(float(f"{value:.10g}"))
        unit = PARAMETERS[key][1]
        section[key].comment(f"fitted: {value:.6g} +/- {se:.3g}{'' if unit == '1' else ' ' + unit} (standard error)")
    array = tomlkit.array()
    array.extend(fit.table.fitted)
    section["fitted"] = array
    return "".join(line + "\n" for line in header) + tomlkit.dumps(doc)


__all__ = ["COLUMNS", "DEFAULT_KEYS", "FRACTION_SUM_TOLERANCE", "ComminutionFit", "Sieving", "SievingError",
           "SievingRow", "fit_checks", "fit_comminution", "fitted_food_text", "predicted_graph", "read_sieving"]
