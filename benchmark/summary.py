"""Summary statistics of per-segment results, defined once for run summaries and leaderboards.

Per noise level and method:

* coverage, in percentage points of the absolute error ``|estimated - true|``:
  MAE (mean), median, q95, and the bias (mean signed error). A failed segment
  (a row with an ``error``) is scored as the farther of coverage 0 and 1
  (:func:`scored_errors`): its error, ``max(true, 1 - true)``, is at least that
  of any answer, so failing never improves a statistic. Segments with no error
  to score (no truth) are counted as undefined;
* for each precision / recall column (:func:`metric_columns`): mean, median,
  q25 and q75 over the segments where it is defined, and the count of answered
  segments where it is undefined (one side empty); a failed segment counts 0
  where the method gives the metric on other segments and the truth's side is
  not empty (:func:`scored_metric`);
* coverage intervals (:func:`interval_stats`): a failed segment of a method
  that gives intervals counts as one whose truth lies outside;
* ``seconds``: mean wall time per answered segment (shared steps counted in
  full for every method that uses them);
* ``segments`` and ``failed``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from colonbench.benchmark.metrics import THRESHOLDS_MM

#: Columns of a per-segment result row that identify the sample.
KEY_COLUMNS = ("shard", "index", "noise_mm")
#: Quantiles reported for precision / recall.
QUANTILES = {"median": 0.5, "q25": 0.25, "q75": 0.75}


def metric_columns(thresholds=THRESHOLDS_MM) -> list[str]:
    """Names of the precision / recall columns: ``holes_precision_1mm``, ..., ``centerline_recall_2mm``."""
    return [f"{what}_{pr}_{th:g}mm" for th in thresholds for what in ("holes", "centerline")
            for pr in ("precision", "recall")]


def failed(g: pd.DataFrame) -> np.ndarray:
    """Which rows are failures: a non-empty ``error`` (all False without the column)."""
    if "error" not in g.columns:
        return np.zeros(len(g), bool)
    err = g["error"]
    return (err.notna() & err.astype(str).ne("")).to_numpy()      # an all-empty column may read as float NaN


def failed_every(samples, failures) -> bool:
    """Whether a method failed on every sample it was given, group by group (a noise level of a suite): what
    ``colonbench benchmark`` calls a failed method (it writes no tables) and ``colonbench results check`` refuses.

    Parameters
    ----------
    samples, failures : int or sequence of int
        Each group's samples, and how many of them failed.
    """
    samples, failures = np.atleast_1d(samples), np.atleast_1d(failures)
    return bool(samples.size) and bool((failures >= samples).all())


def fallback_coverage(true_coverage) -> np.ndarray:
    """The coverage a failed segment is scored as: the farther of 0 and 1 from the truth (0 at a truth of 0.5),
    so that its error, ``max(true, 1 - true)``, is at least that of any estimate in [0, 1]."""
    true = np.asarray(true_coverage, float)
    return np.where(true >= 0.5, 0.0, 1.0)


def scored_errors(g: pd.DataFrame) -> np.ndarray:
    """Coverage errors (fractions) as every statistic scores them: ``coverage_error`` of answered rows, and of
    failed rows (:func:`failed`) with a truth ``fallback_coverage - true_coverage``; NaN where there is nothing
    to score (no truth, or rows without a ``true_coverage`` column)."""
    err = g["coverage_error"].to_numpy(float).copy()
    if "true_coverage" in g.columns:
        bad = failed(g)
        true = g["true_coverage"].to_numpy(float)[bad]
        err[bad] = np.where(np.isfinite(true), fallback_coverage(true) - true, np.nan)
    return err


def scored_metric(g: pd.DataFrame, column: str) -> np.ndarray:
    """A precision / recall column as the statistics score it: a failed row counts 0 where the method gives the
    metric on an answered row of ``g`` and the truth's side of it is not known to be empty (``holes_true_n`` or
    ``centerline_true_n`` of 0 leaves it undefined, as for any answer); else NaN, left out."""
    v = g[column].to_numpy(float).copy()
    bad = failed(g)
    if bad.any() and not np.isnan(v[~bad]).all():
        true_n = f"{column.split('_')[0]}_true_n"
        empty = g[true_n].to_numpy(float) == 0 if true_n in g.columns else np.zeros(len(g), bool)
        v[bad] = np.where(empty[bad], np.nan, 0.0)
    return v


def error_stats(errors) -> dict:
    """``mae``, ``median``, ``bias``, ``q95`` in percentage points of coverage errors given as fractions.

    NaN errors (no estimate) are left out; all four are NaN when none is left.
    """
    err = np.asarray(errors, float)
    ok = err[~np.isnan(err)]
    a = np.abs(ok)
    if not len(a):
        return {"mae": np.nan, "median": np.nan, "bias": np.nan, "q95": np.nan}
    return {"mae": 100 * float(a.mean()), "median": 100 * float(np.median(a)), "bias": 100 * float(ok.mean()),
            "q95": 100 * float(np.quantile(a, 0.95))}


def interval_stats(g: pd.DataFrame, failures: bool = False) -> dict:
    """How a method's coverage intervals did on rows with ``true_coverage``, ``interval_low`` and ``interval_high``
    (fractions): ``interval_covered``, the share of the truths inside (%), ``interval_width``, the mean width
    (points, of the intervals given), over ``interval_segments`` rows with an interval and a truth; NaN (n/a) for a
    method that gives none. With ``failures``, failed rows (:func:`failed`) with a truth join those rows as truths
    outside, where the method gives an interval on any row."""
    if "interval_low" not in g.columns:
        return {"interval_covered": np.nan, "interval_width": np.nan, "interval_segments": 0}
    low, high = g["interval_low"].to_numpy(float), g["interval_high"].to_numpy(float)
    # rows with no truth (a whole-colon segment whose region holds no true face) are scored by neither the MAE nor
    # the intervals
    truth = np.isfinite(g["true_coverage"].to_numpy(float))
    have = ~np.isnan(low) & ~np.isnan(high) & truth
    if not have.any():
        return {"interval_covered": np.nan, "interval_width": np.nan, "interval_segments": 0}
    true = g["true_coverage"].to_numpy(float)[have]
    inside = (low[have] - 1e-9 <= true) & (true <= high[have] + 1e-9)
    outside = int((failed(g) & truth).sum()) if failures else 0
    return {"interval_covered": 100 * float(inside.sum()) / (len(inside) + outside),
            "interval_width": 100 * float((high - low)[have].mean()), "interval_segments": int(have.sum()) + outside}


#: An estimate off by more than this (fraction) is one its ``review`` should flag (decision record 0156).
REVIEW_OFF = 0.15


def review_stats(g: pd.DataFrame) -> dict:
    """How a method's ``review`` did, over the answered rows with a truth where it says how sure it is (a ``review``
    count, :attr:`colonbench.estimate.Estimate.review_count`): ``review_flagged``, the share flagged (%);
    ``review_recall``, the share of the estimates off by more than :data:`REVIEW_OFF` that it flagged (%);
    ``review_precision``, the share of its flags on such estimates (%); ``review_off``, how many were off. NaN (n/a)
    for a method that gives none."""
    if "review" not in g.columns:
        g = g.assign(review=np.nan)
    n = g["review"].to_numpy(float)
    have = np.isfinite(n) & np.isfinite(g["coverage_error"].to_numpy(float))
    if not have.any():
        return {"review_flagged": np.nan, "review_recall": np.nan, "review_precision": np.nan, "review_off": 0}
    flag, off = n[have] > 0, np.abs(g["coverage_error"].to_numpy(float)[have]) > REVIEW_OFF
    share = lambda a, b: 100 * float((a & b).sum()) / b.sum() if b.any() else np.nan   # noqa: E731
    return {"review_flagged": 100 * float(flag.mean()), "review_recall": share(flag, off),
            "review_precision": share(off, flag), "review_off": int(off.sum())}


def _stats(g: pd.DataFrame, metrics: list[str]) -> dict:
    err, bad = scored_errors(g), failed(g)
    row = {"segments": len(g), "failed": int(bad.sum()), "coverage_undefined": int(np.isnan(err[~bad]).sum()),
           **{f"coverage_{k}": v for k, v in error_stats(err).items()},
           **interval_stats(g, failures=True), **review_stats(g), "seconds": float(g["seconds"].mean())}
    for m in metrics:
        v = scored_metric(g, m)
        d = v[~np.isnan(v)]
        row[f"{m}_mean"] = float(d.mean()) if len(d) else np.nan
        for q, at in QUANTILES.items():
            row[f"{m}_{q}"] = float(np.quantile(d, at)) if len(d) else np.nan
        row[f"{m}_undefined"] = int(np.isnan(v[~bad]).sum())
    return row


def summarize(results: pd.DataFrame, thresholds=THRESHOLDS_MM) -> pd.DataFrame:
    """One row per (noise level, method) of per-segment results.

    Parameters
    ----------
    results : DataFrame
        Per-segment rows with ``method``, ``noise_mm``, ``true_coverage``, ``coverage_error``
        (fraction), ``seconds``, ``error`` and the :func:`metric_columns`.

    Returns
    -------
    DataFrame
        ``noise_mm``, ``method`` and the statistics above (coverage in points).
    """
    metrics = metric_columns(thresholds)
    rows = []
    for (noise, method), g in results.groupby(["noise_mm", "method"], sort=True):
        rows.append({"noise_mm": float(noise), "method": method, **_stats(g, metrics)})
    return pd.DataFrame(rows)
