"""The benchmark's metrics, defined once (../SPEC conventions).

For a threshold ``th`` (mm)::

    precision = mean over estimated points of [distance to the nearest GT point < th]
    recall    = mean over GT points of [distance to the nearest estimated point < th]

Holes: GT hole points against the method's hole points. Centerline: GT
centerline points (spacing <= 0.5 mm) against the method's centerline points.
Where one side is empty the value is undefined: NaN. Coverage error is
estimated - true, in coverage fraction; tables report percentage points.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

#: Distance thresholds of the precision / recall metrics, mm.
THRESHOLDS_MM = (1.0, 2.0)


def precision_recall(estimated, truth, threshold_mm: float) -> tuple[float, float]:
    """(precision, recall) of point sets at ``threshold_mm``; NaN for both when either set is empty.

    Parameters
    ----------
    estimated : (n, 3) float
        mm.
    truth : (m, 3) float
        mm.
    """
    est = np.asarray(estimated, dtype=float).reshape(-1, 3)
    gt = np.asarray(truth, dtype=float).reshape(-1, 3)
    if len(est) == 0 or len(gt) == 0:
        return float("nan"), float("nan")
    d_est, _ = cKDTree(gt).query(est, k=1)
    d_gt, _ = cKDTree(est).query(gt, k=1)
    return float(np.mean(d_est < threshold_mm)), float(np.mean(d_gt < threshold_mm))


#: Columns of :func:`point_counts`: the number of points behind each precision (estimated) and recall (true).
COUNT_COLUMNS = ("holes_n", "holes_true_n", "centerline_n", "centerline_true_n")


def point_counts(holes, centerline, truth: dict) -> dict:
    """The denominators of a segment's precision and recall: how many estimated and true hole and centerline points
    there are (:data:`COUNT_COLUMNS`). A threshold metric moves by whole points of these when a distance crosses
    its threshold under another machine's float arithmetic; docs/benchmark.md, Reproducing, says by how many."""
    n = lambda p: int(len(np.asarray(p, dtype=float).reshape(-1, 3)))   # noqa: E731
    return {"holes_n": n(holes), "holes_true_n": n(truth["hole_points"]), "centerline_n": n(centerline),
            "centerline_true_n": n(truth["centerline"])}


def segment_metrics(coverage: float, holes, centerline, truth: dict, thresholds=THRESHOLDS_MM) -> dict:
    """All metrics of one segment.

    Parameters
    ----------
    coverage : float
        Estimated coverage (fraction).
    holes, centerline : (n, 3) float
        Estimated hole points and centerline, mm.
    truth : dict
        ``coverage``, ``hole_points``, ``centerline`` (mm).

    Returns
    -------
    dict
        ``coverage_error`` (estimated - true, fraction), and for each threshold
        ``holes_precision_<th>mm``, ``holes_recall_<th>mm``,
        ``centerline_precision_<th>mm``, ``centerline_recall_<th>mm``.
    """
    out = {"coverage_error": float(coverage) - float(truth["coverage"])}
    for th in thresholds:
        tag = f"{th:g}mm"
        p, r = precision_recall(holes, truth["hole_points"], th)
        out[f"holes_precision_{tag}"], out[f"holes_recall_{tag}"] = p, r
        p, r = precision_recall(centerline, truth["centerline"], th)
        out[f"centerline_precision_{tag}"], out[f"centerline_recall_{tag}"] = p, r
    return out
