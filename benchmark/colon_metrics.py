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


#: Width of the band at each end of a segment whose observed share decides whether that end was seen, mm.
END_BAND_MM = 10.0
#: An end band with less of its area observed than this is an *unobserved end*.
END_SEEN = 0.5


def segment_truth(vertices: np.ndarray, faces: np.ndarray, observed: np.ndarray, centerline, segments,
                  area: np.ndarray | None = None, face_s: np.ndarray | None = None) -> dict:
    """True coverage of the region of each map segment, and how well its two ends were seen.

    Parameters
    ----------
    vertices : (v, 3) float
        The true colon surface, mm.
    faces : (f, 3) int
    observed : (f,) bool
        Which faces the reconstruction saw.
    centerline : colonbench.polyline.Centerline
        The true centerline.
    segments : list of dict
        ``segments.json`` rows (``plane_start``, ``plane_end``).
    area : (f,) float, optional
        The faces' areas, mm^2, when the caller has them.
    face_s : (f,) float, optional
        Each face's true arc length (:func:`colonbench.shards.colonshard.face_arclength`), when the caller has it.

    Returns
    -------
    dict of (s,) arrays
        ``truth`` (coverage of the region, fraction; NaN where it holds no face),
        ``true_area_mm2`` (the region's true surface area, mm^2),
        ``true_start_mm``, ``true_end_mm`` (the region on the true centerline),
        ``end_seen`` (the smaller observed share of the two :data:`END_BAND_MM` end bands;
        below :data:`END_SEEN` the segment has an unobserved end).
    """
    from colonbench.meshes import triangle_areas

    tree = cKDTree(centerline.points)
    area = triangle_areas(vertices, faces) if area is None else area
    if face_s is None:
        _, near = tree.query(np.asarray(vertices)[faces].mean(axis=1))
        face_s = centerline.arclength[near]
    n = len(segments)
    out = {k: np.full(n, np.nan) for k in ("truth", "true_area_mm2", "true_start_mm", "true_end_mm", "end_seen")}
    seen_area = area * observed
    for k, seg in enumerate(segments):
        _, (a, b) = tree.query([seg["plane_start"]["point"], seg["plane_end"]["point"]])
        lo, hi = sorted((centerline.arclength[a], centerline.arclength[b]))
        out["true_start_mm"][k], out["true_end_mm"][k] = lo, hi
        inside = (face_s >= lo) & (face_s < hi)
        total = area[inside].sum()
        out["true_area_mm2"][k] = float(total)
        if total > 0:
            out["truth"][k] = float(seen_area[inside].sum() / total)
        shares = []
        for band in ((face_s >= lo) & (face_s < min(lo + END_BAND_MM, hi)),
                     (face_s >= max(hi - END_BAND_MM, lo)) & (face_s < hi)):
            if area[band].sum() > 0:
                shares.append(seen_area[band].sum() / area[band].sum())
        if shares:
            out["end_seen"][k] = float(min(shares))
    return out


def map_metrics(segments, coverage: float | None, map_centerline, vertices, faces, observed, centerline,
                threshold_mm: float = 2.0, face_s: np.ndarray | None = None) -> dict:
    """Segment coverage errors, whole-colon error and centerline precision / recall of one map.

    Parameters
    ----------
    segments : list of dict
        The map's ``segments.json`` rows.
    coverage : float or None
        The map's whole-colon coverage (``summary.json``).
    map_centerline : (m, 3) float
        The map's ``centerline.npy``, mm.
    vertices, faces, observed, centerline
        The truth (see :func:`segment_truth`).
    threshold_mm : float
        Distance within which centerline points count as matched.
    face_s : (f,) float, optional
        Each face's true arc length, when the caller has it.

    Returns
    -------
    dict
        ``segment_truth`` and ``segment_errors`` ((s,) estimated - true, fraction; NaN where either is
        missing), ``end_seen``, ``true_area_mm2``, ``true_start_mm``, ``true_end_mm`` ((s,), see
        :func:`segment_truth`),
        ``segment_mae`` (points), ``whole_truth``, ``whole_error`` (points, estimated - true),
        ``centerline_precision``, ``centerline_recall`` (at ``threshold_mm``).
    """
    from colonbench.polyline import resample
    from colonbench.meshes import triangle_areas

    area = triangle_areas(vertices, faces)
    truth = segment_truth(vertices, faces, observed, centerline, segments, area, face_s)
    est = np.array([np.nan if s["coverage"] is None else s["coverage"] for s in segments], float)
    errors = est - truth["truth"]
    whole = float(area[observed].sum() / area.sum())
    p, r = precision_recall(resample(np.asarray(map_centerline, float), 0.5), centerline.points, threshold_mm)
    return {"segment_truth": truth["truth"], "segment_errors": errors, "end_seen": truth["end_seen"],
            "true_area_mm2": truth["true_area_mm2"],
            "true_start_mm": truth["true_start_mm"], "true_end_mm": truth["true_end_mm"],
            "segment_mae": float(np.nanmean(np.abs(errors)) * 100) if np.isfinite(errors).any() else float("nan"),
            "whole_truth": whole,
            "whole_error": float("nan") if coverage is None else float((coverage - whole) * 100),
            "centerline_precision": p, "centerline_recall": r}
