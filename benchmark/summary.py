"""Summary statistics of per-segment results, defined once for run summaries and leaderboards.

Per noise level and method:

* coverage, in percentage points of the absolute error ``|estimated - true|``:
  MAE (mean), median, q95, and the bias (mean signed error); segments where a
  method returned no coverage (NaN) or failed are counted as undefined, never
  averaged in silently;
* for each precision / recall column (:func:`metric_columns`): mean, median,
  q25 and q75 over the segments where it is defined, and the count of
  undefined ones (one side empty, or the method failed);
* ``seconds``: mean wall time per segment (shared steps counted in full for
  every method that uses them);
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


def interval_stats(g: pd.DataFrame) -> dict:
    """How a method's coverage intervals did on rows with ``true_coverage``, ``interval_low`` and ``interval_high``
    (fractions): ``interval_covered``, the share of the truths inside (%), ``interval_width``, the mean width
    (points), over ``interval_segments`` rows with an interval and a truth; NaN (n/a) for a method that gives
    none."""
    if "interval_low" not in g.columns:
        return {"interval_covered": np.nan, "interval_width": np.nan, "interval_segments": 0}
    low, high = g["interval_low"].to_numpy(float), g["interval_high"].to_numpy(float)
    # rows with no truth (a whole-colon segment whose region holds no true face) are scored by neither the MAE nor
    # the intervals
    have = ~np.isnan(low) & ~np.isnan(high) & np.isfinite(g["true_coverage"].to_numpy(float))
    if not have.any():
        return {"interval_covered": np.nan, "interval_width": np.nan, "interval_segments": 0}
    true = g["true_coverage"].to_numpy(float)[have]
    inside = (low[have] - 1e-9 <= true) & (true <= high[have] + 1e-9)
    return {"interval_covered": 100 * float(inside.mean()), "interval_width": 100 * float((high - low)[have].mean()),
            "interval_segments": int(have.sum())}


def _stats(g: pd.DataFrame, metrics: list[str]) -> dict:
    err = g["coverage_error"].to_numpy(float)
    row = {"segments": len(g), "failed": int(g["error"].fillna("").astype(str).ne("").sum()),
           "coverage_undefined": int(np.isnan(err).sum()),
           **{f"coverage_{k}": v for k, v in error_stats(err).items()},
           **interval_stats(g), "seconds": float(g["seconds"].mean())}
    for m in metrics:
        v = g[m].to_numpy(float)
        d = v[~np.isnan(v)]
        row[f"{m}_mean"] = float(d.mean()) if len(d) else np.nan
        for q, at in QUANTILES.items():
            row[f"{m}_{q}"] = float(np.quantile(d, at)) if len(d) else np.nan
        row[f"{m}_undefined"] = int(len(v) - len(d))
    return row


def summarize(results: pd.DataFrame, thresholds=THRESHOLDS_MM) -> pd.DataFrame:
    """One row per (noise level, method) of per-segment results.

    Parameters
    ----------
    results : DataFrame
        Per-segment rows with ``method``, ``noise_mm``, ``coverage_error``
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
