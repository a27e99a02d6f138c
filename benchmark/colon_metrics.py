"""Scoring a whole-colon coverage map against the exact truth of the colon it was made from.

Each segment the map reports is scored against the ground-truth coverage of
the same region of the true surface: the faces whose nearest point of the
true centerline lies between the true arc lengths at the segment's two plane
points (the faces that belong to that stretch of colon). The whole-colon
coverage is scored against the observed share of the whole true surface, and
the map's centerline with :func:`colonbench.benchmark.metrics.precision_recall`.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from colonbench.benchmark.metrics import precision_recall


def segment_truth(vertices: np.ndarray, faces: np.ndarray, observed: np.ndarray, centerline, segments,
                  area: np.ndarray | None = None) -> np.ndarray:
    """True coverage of the region of each map segment, (s,) float (NaN where the region holds no face).

    Parameters
    ----------
    vertices : (v, 3) float
        The true colon surface, mm.
    faces : (f, 3) int
    observed : (f,) bool
        Which faces the reconstruction saw.
    centerline : colonbench.datagen.centerline.Centerline
        The true centerline.
    segments : list of dict
        ``segments.json`` rows (``plane_start``, ``plane_end``).
    area : (f,) float, optional
        The faces' areas, mm^2, when the caller has them.
    """
    from colonbench.completion.surface import triangle_areas

    tree = cKDTree(centerline.points)
    area = triangle_areas(vertices, faces) if area is None else area
    _, near = tree.query(vertices[faces].mean(axis=1))
    face_s = centerline.arclength[near]
    out = np.full(len(segments), np.nan)
    for k, seg in enumerate(segments):
        _, (a, b) = tree.query([seg["plane_start"]["point"], seg["plane_end"]["point"]])
        lo, hi = sorted((centerline.arclength[a], centerline.arclength[b]))
        inside = (face_s >= lo) & (face_s < hi)
        if area[inside].sum() > 0:
            out[k] = float(area[inside & observed].sum() / area[inside].sum())
    return out


def map_metrics(segments, coverage: float | None, map_centerline, vertices, faces, observed, centerline,
                threshold_mm: float = 2.0) -> dict:
    """Segment coverage errors, whole-colon error and centerline precision / recall of one map.

    Returns
    -------
    dict
        ``segment_errors`` ((s,) estimated - true, fraction; NaN where either is missing),
        ``segment_mae`` (points), ``whole_error`` (points, estimated - true),
        ``centerline_precision``, ``centerline_recall`` (at ``threshold_mm``).
    """
    from colonbench.completion.centerline import resample
    from colonbench.completion.surface import triangle_areas

    area = triangle_areas(vertices, faces)
    truth = segment_truth(vertices, faces, observed, centerline, segments, area)
    est = np.array([np.nan if s["coverage"] is None else s["coverage"] for s in segments], float)
    errors = est - truth
    whole = float(area[observed].sum() / area.sum())
    p, r = precision_recall(resample(np.asarray(map_centerline, float), 0.5), centerline.points, threshold_mm)
    return {"segment_truth": truth, "segment_errors": errors,
            "segment_mae": float(np.nanmean(np.abs(errors)) * 100),
            "whole_truth": whole,
            "whole_error": float("nan") if coverage is None else float((coverage - whole) * 100),
            "centerline_precision": p, "centerline_recall": r}
