"""Uncertainty of coverage errors: bootstrap intervals, paired comparisons, breakdowns by group.

Coverage errors come in as fractions (``estimated - true``) and go out in percentage points. The
functions on per-segment results score a failed segment as the farther of coverage 0 and 1
(:func:`colonbench.benchmark.summary.scored_errors`); a NaN error (nothing to score) is left out. Each table cell draws
from its own ``np.random.default_rng(SeedSequence([seed, crc32(cell key)]))``, so its interval
does not depend on which other cells are computed, or in which order.
"""

from __future__ import annotations

import zlib

import numpy as np
import pandas as pd

from colonbench.benchmark.summary import KEY_COLUMNS, error_stats, interval_stats, scored_errors
from colonbench.errors import InputError

#: Edges of the true-coverage bins of :func:`breakdown`: [lo, hi), the last one [0.9, 1.0].
coverage_bins = (0.0, 0.5, 0.7, 0.8, 0.9, 1.0)
#: The groupings :func:`breakdown` knows.
BREAKDOWNS = ("hole_model", "length_mm", "true_coverage", "unseen_end", "noise_mm")
PAIRED_COLUMNS = ["noise_mm", "method", "reference", "diff", "diff_lo", "diff_hi", "pairs"]
BREAKDOWN_COLUMNS = ["noise_mm", "method", "by", "group", "segments", "mae", "mae_lo", "mae_hi", "bias",
                     "interval_covered", "interval_width"]
_CHUNK_ELEMENTS = 2 ** 20  # per chunk of resamples: index matrix + gathered values, about 16 MB


def _count(x, name: str, least: int) -> int:
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < least:
        raise InputError(f"{name} must be an integer >= {least}, got {x!r}")
    return int(x)


def _cell_seed(seed, *key) -> np.random.SeedSequence:
    return np.random.SeedSequence([_count(seed, "seed", 0), zlib.crc32("|".join(map(str, key)).encode())])


def _check(level, resamples) -> None:
    if not 0 < level < 1:
        raise InputError(f"level must lie strictly between 0 and 1, got {level!r}")
    _count(resamples, "resamples", 1)


def _need(frame: pd.DataFrame, columns, what: str) -> None:
    if missing := [c for c in columns if c not in frame.columns]:
        raise InputError(f"{what} lack the column(s) {', '.join(missing)}")


def bootstrap_ci(values, statistic=np.mean, level=0.95, resamples=2000, seed=0) -> tuple[float, float]:
    """Percentile bootstrap interval of ``statistic`` over a sample, resampling its elements.

    Parameters
    ----------
    values : array_like, shape (n,)
        The sample, in any unit; NaNs are dropped first.
    statistic : callable
        Sample -> number; called as ``statistic(x, axis=1)`` on a (chunk, n) matrix of
        resamples like a numpy reduction, or row by row when it takes no ``axis``.
    level : float
        Coverage of the interval, in (0, 1).
    resamples : int
        Number of resamples, drawn in chunks of at most 2**20 elements (peak about 25 MB).
    seed : int >= 0 or numpy.random.SeedSequence
        Seed of the ``numpy.random.default_rng`` that draws the resamples.

    Returns
    -------
    (float, float)
        Lower and upper bounds in the unit of ``values``; (nan, nan) below 2 values.
    """
    _check(level, resamples)
    if (x := np.asarray(values, float)).ndim != 1:
        raise InputError(f"bootstrap_ci takes a 1-D array of values, got shape {x.shape}")
    x = x[~np.isnan(x)]
    if (n := len(x)) < 2:
        return np.nan, np.nan
    rng = np.random.default_rng(seed if isinstance(seed, np.random.SeedSequence) else _count(seed, "seed", 0))
    rows, stats = max(1, _CHUNK_ELEMENTS // n), np.empty(resamples)
    for start in range(0, resamples, rows):
        stop = min(resamples, start + rows)
        sample = x[rng.integers(0, n, size=(stop - start, n))]
        try:
            stats[start:stop] = statistic(sample, axis=1)
        except TypeError:  # a statistic without ``axis``: row by row
            stats[start:stop] = [statistic(row) for row in sample]
    lo, hi = np.quantile(stats, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def mae_interval(errors, level=0.95, resamples=2000, seed=0) -> dict:
    """Mean absolute coverage error with its bootstrap interval, resampling segments.

    Parameters
    ----------
    errors : array_like, shape (n,)
        Coverage errors per segment as fractions; NaN (undefined) is left out.
    level, resamples, seed
        As in :func:`bootstrap_ci`.

    Returns
    -------
    dict
        ``mae`` (equal to :func:`~colonbench.benchmark.summary.error_stats`'s), ``mae_lo``,
        ``mae_hi``, all in percentage points; the bounds are NaN below 2 defined errors.
    """
    err = np.asarray(errors, float).ravel()
    lo, hi = bootstrap_ci(100 * np.abs(err), np.mean, level, resamples, seed)
    return {"mae": error_stats(err)["mae"], "mae_lo": lo, "mae_hi": hi}


def paired_difference(a, b, level=0.95, resamples=2000, seed=0) -> dict:
    """Mean difference ``a - b`` over aligned pairs with its bootstrap interval, resampling pairs.

    Parameters
    ----------
    a, b : array_like, shape (n,)
        Values of two methods on the same n segments, in one unit (points for coverage
        errors); pairs where either is NaN are left out.
    level, resamples, seed
        As in :func:`bootstrap_ci`.

    Returns
    -------
    dict
        ``diff`` (mean of ``a - b``), ``diff_lo``, ``diff_hi`` in the unit of the input;
        ``pairs``, the number of pairs used (diff NaN when none, bounds NaN below 2).
    """
    x, y = np.asarray(a, float), np.asarray(b, float)
    if x.ndim != 1 or x.shape != y.shape:
        raise InputError(f"paired_difference takes two 1-D arrays of one length, got shapes {x.shape} and {y.shape}")
    d = (x - y)[~(np.isnan(x) | np.isnan(y))]
    lo, hi = bootstrap_ci(d, np.mean, level, resamples, seed)
    return {"diff": float(d.mean()) if len(d) else np.nan, "diff_lo": lo, "diff_hi": hi, "pairs": int(len(d))}


def paired_against(results: pd.DataFrame, reference: str, level=0.95, resamples=2000, seed=0) -> pd.DataFrame:
    """Each method against a reference: paired difference of absolute coverage errors.

    Parameters
    ----------
    results : DataFrame
        Per-segment rows with ``method``, ``shard``, ``index``, ``noise_mm`` and
        ``coverage_error`` (fraction), failed rows scored by ``error`` and ``true_coverage`` where the results
        have them (:func:`~colonbench.benchmark.summary.scored_errors`); at most one row per method and segment.
    reference : str
        The method every other one is compared with.
    level, resamples, seed
        As in :func:`bootstrap_ci`; each (noise, method) draws from its own stream.

    Returns
    -------
    DataFrame
        Per (noise level, other method): ``noise_mm``, ``method``, ``reference``, ``diff``, ``diff_lo``,
        ``diff_hi`` (points, method minus reference: negative = closer to the truth than the reference),
        ``pairs`` (segments where both have an error); empty if ``reference`` is not in ``results``.
    """
    _check(level, resamples)
    _need(results, ["method", *KEY_COLUMNS, "coverage_error"], "results")
    keys = list(KEY_COLUMNS)
    if results.duplicated(["method", *keys]).any():
        raise InputError("results hold more than one row of a method for one segment (shard, index, noise_mm)")
    is_ref = results["method"] == reference
    if not is_ref.any():
        return pd.DataFrame(columns=PAIRED_COLUMNS).astype({c: float for c in PAIRED_COLUMNS[3:6]} | {"pairs": int})
    points = results[["method", *keys]].assign(_err=100 * np.abs(scored_errors(results)))
    both = points[~is_ref].merge(points.loc[is_ref, keys + ["_err"]], on=keys, how="left", suffixes=("", "_ref"))
    rows = []
    for (noise, method), g in both.groupby(["noise_mm", "method"], sort=True):
        res = paired_difference(g["_err"].to_numpy(float), g["_err_ref"].to_numpy(float), level, resamples,
                                _cell_seed(seed, "paired", repr(float(noise)), method, reference))
        rows.append({"noise_mm": float(noise), "method": method, "reference": reference, **res})
    return pd.DataFrame(rows, columns=PAIRED_COLUMNS)


def best_baseline(table: pd.DataFrame, baselines) -> dict[float, str]:
    """The baseline with the lowest coverage MAE at each noise level.

    Parameters
    ----------
    table : DataFrame
        One row per noise level and method with ``noise_mm``, ``method``, ``coverage_mae``.
    baselines : iterable of str
        Names of the methods that count as baselines (a single str is one name).

    Returns
    -------
    dict
        Noise level (mm) -> name of the baseline with the lowest MAE; a NaN MAE never
        wins, ties go to the first name in sort order, levels with no baseline are left out.
    """
    _need(table, ["noise_mm", "method", "coverage_mae"], "the table")
    names = {baselines} if isinstance(baselines, str) else set(baselines)
    t = table[table["method"].isin(names) & table["coverage_mae"].notna()]
    first = t.sort_values(["noise_mm", "coverage_mae", "method"]).drop_duplicates("noise_mm")
    return {float(n): str(m) for n, m in zip(first["noise_mm"], first["method"])}


def _groups(results: pd.DataFrame, by: str) -> pd.Series:
    """Group label (str) of each row; None where a row belongs to no group."""
    if by == "unseen_end" and "end_unobserved" in results.columns:
        if not (col := results["end_unobserved"]).dropna().isin([True, False]).all():
            raise InputError(f"end_unobserved must be boolean, got values {sorted(set(map(str, col)))}")
        return col.map(lambda v: str(bool(v)), na_action="ignore")
    column = "hole_model" if by == "unseen_end" else by
    _need(results, [column], "results")
    if by == "true_coverage":
        edges = np.asarray(coverage_bins, float)
        v = results[column].to_numpy(float)
        k = np.searchsorted(edges, v, side="right") - 1  # [lo, hi); NaN and > 1 land past the end
        k[v == edges[-1]] = len(edges) - 2  # the last bin holds 1.0
        labels = ["-".join(np.format_float_positional(e, trim="0") for e in pair) for pair in zip(edges, edges[1:])]
        return pd.Series([labels[i] if 0 <= i < len(labels) else None for i in k], results.index, object)
    fmt = {"unseen_end": lambda v: str(str(v).endswith("+end")), "hole_model": str}.get(by, lambda v: f"{float(v):g}")
    return results[column].map(fmt, na_action="ignore")


def breakdown(results: pd.DataFrame, by: str, level=0.95, resamples=1000, seed=0) -> pd.DataFrame:
    """Coverage MAE with its bootstrap interval, and bias, per noise level, method and group.

    Parameters
    ----------
    results : DataFrame
        Per-segment rows with ``noise_mm``, ``method``, ``coverage_error`` (fraction; failed rows scored by
        ``error`` and ``true_coverage`` where the results have them) and the column ``by`` needs: ``hole_model``, ``length_mm`` (mm), ``true_coverage`` (fraction, binned
        by :data:`coverage_bins`; no bin -> row dropped), or for ``unseen_end`` a boolean
        ``end_unobserved`` if present, else ``hole_model`` ending in ``+end``.
    by : str
        One of :data:`BREAKDOWNS`.
    level, resamples, seed
        As in :func:`bootstrap_ci`; each cell draws from its own stream.

    Returns
    -------
    DataFrame
        ``noise_mm``, ``method``, ``by``, ``group`` (str), ``segments`` (all rows of the
        group, undefined errors included), ``mae``, ``mae_lo``, ``mae_hi``, ``bias``
        (percentage points), ``interval_covered`` (%) and ``interval_width`` (points) of a method's
        coverage intervals (NaN for one without, :func:`colonbench.benchmark.summary.interval_stats`);
        sorted by noise level, method, group.
    """
    if by not in BREAKDOWNS:
        raise InputError(f"unknown breakdown {by!r}; expected one of {', '.join(BREAKDOWNS)}")
    _check(level, resamples)
    _need(results, ["noise_mm", "method", "coverage_error"], "results")
    extra = [c for c in ("true_coverage", "interval_low", "interval_high", "error") if c in results.columns]
    frame = results[["noise_mm", "method", "coverage_error", *extra]].assign(_group=_groups(results, by))
    rows = []  # rows in no group (None) are dropped by groupby
    for (noise, method, group), g in frame.groupby(["noise_mm", "method", "_group"], sort=True, dropna=True):
        err = scored_errors(g)
        mae = mae_interval(err, level, resamples, _cell_seed(seed, by, repr(float(noise)), method, group))
        iv = interval_stats(g, failures=True) if "true_coverage" in g.columns else {}
        rows.append({"noise_mm": float(noise), "method": method, "by": by, "group": group, "segments": len(g),
                     **mae, "bias": error_stats(err)["bias"], "interval_covered": iv.get("interval_covered", np.nan),
                     "interval_width": iv.get("interval_width", np.nan)})
    return pd.DataFrame(rows, columns=BREAKDOWN_COLUMNS)
