"""Designs (the parameter values of a sweep's evaluations) and the Sobol' analysis of their outputs.

* ``monte-carlo``: evaluation i draws its parameters, in the SPEC's order, from a random generator seeded with
  (seed, i) (NumPy's PCG64 through ``SeedSequence``): a sample's values depend on the seed and its index only,
  not on the chunks nor on how many samples the sweep has, and rows are drawn when their chunk is sent.
* ``sobol``: Saltelli's scheme as SALib implements it (``SALib.sample.sobol``: a scrambled Sobol' sequence of
  2 D dimensions, N base samples, N (D + 2) evaluations for first-order and total indices), transformed to the
  parameters' distributions by SALib; the indices and their bootstrap confidence intervals by
  ``SALib.analyze.sobol`` (Saltelli 2010 for S1, Jansen 1999 for ST).
* ``grid``: the Cartesian product of the values, the last key varying fastest.

Distributions: ``uniform = [low, high]``, ``normal = [mean, sd]``, ``lognormal = [mu, sigma]`` (ln x is normal with
mean mu and standard deviation sigma, SALib's and NumPy's convention: the median is exp(mu)).
"""

from __future__ import annotations

import numpy as np

from chewbot.sweep.runner import Design
from chewbot.sweep.spec import Parameter, Spec

SALIB_DISTRIBUTIONS = {"uniform": "unif", "normal": "norm", "lognormal": "lognorm"}


def _draw(rng: np.random.Generator, p: Parameter) -> float:
    a, b = p.args
    if p.kind == "uniform":
        return rng.uniform(a, b)
    if p.kind == "normal":
        return rng.normal(a, b)
    return rng.lognormal(a, b)


def monte_carlo_design(spec: Spec) -> Design:
    """``spec.samples`` evaluations, sample i drawn from the generator seeded with (seed, i)."""
    params = spec.parameters

    def rows(a: int, b: int) -> np.ndarray:
        out = np.empty((b - a, len(params)))
        for k, i in enumerate(range(a, b)):
            rng = np.random.default_rng([spec.seed, i])
            out[k] = [_draw(rng, p) for p in params]
        return out

    return Design(spec.keys, spec.samples, rows)


def salib_problem(names, parameters: tuple[Parameter, ...]) -> dict:
    """The SALib problem of the parameters."""
    return {"num_vars": len(parameters), "names": list(names), "bounds": [list(p.args) for p in parameters],
            "dists": [SALIB_DISTRIBUTIONS[p.kind] for p in parameters]}


def sobol_design(spec: Spec) -> Design:
    """Saltelli's N (D + 2) evaluations for first-order and total indices (``SALib.sample.sobol``)."""
    from SALib.sample import sobol

    problem = salib_problem(spec.keys, spec.parameters)
    values = sobol.sample(problem, spec.samples, calc_second_order=False, scramble=True, seed=spec.seed)
    return Design.of(spec.keys, values)


def grid_design(keys, parameters: tuple[Parameter, ...]) -> Design:
    """Every combination of the parameters' values, the last varying fastest."""
    axes = [np.asarray(p.args) for p in parameters]
    shape = tuple(len(a) for a in axes)

    def rows(a: int, b: int) -> np.ndarray:
        idx = np.unravel_index(np.arange(a, b), shape)
        return np.column_stack([axis[i] for axis, i in zip(axes, idx)])

    return Design(tuple(keys), int(np.prod(shape)), rows)


def sobol_indices(names, parameters: tuple[Parameter, ...], Y: np.ndarray, resamples: int = 100,
                  confidence: float = 0.95, seed: int = 0) -> dict:
    """First-order and total Sobol' indices of one output ``Y`` (N (D + 2) values in the design's order) with their
    confidence intervals (half-widths at ``confidence``, from ``resamples`` bootstrap resamples).

    A failed evaluation (NaN) removes its whole block of D + 2 rows: the estimators are means over the base
    samples, so the indices are those of the remaining blocks (conditional on the evaluations succeeding; the
    number of blocks used is returned). Returns ``{"S1", "S1_conf", "ST", "ST_conf"}`` (arrays, one entry per
    parameter), ``"blocks"`` used and ``"blocks_total"``.
    """
    from SALib.analyze import sobol

    D = len(parameters)
    blocks = np.asarray(Y, dtype=float).reshape(-1, D + 2)
    good = np.isfinite(blocks).all(axis=1)
    result = {"blocks": int(good.sum()), "blocks_total": int(blocks.shape[0])}
    nan = np.full(D, np.nan)
    if good.sum() < 2 or np.ptp(blocks[good]) == 0:  # nothing varies, or too little left: the indices are undefined
        return {**result, "S1": nan, "S1_conf": nan, "ST": nan, "ST_conf": nan}
    problem = salib_problem(names, parameters)
    Si = sobol.analyze(problem, blocks[good].ravel(), calc_second_order=False, num_resamples=resamples,
                       conf_level=confidence, print_to_console=False, seed=seed)
    return {**result, **{k: np.asarray(Si[k], dtype=float) for k in ("S1", "S1_conf", "ST", "ST_conf")}}
