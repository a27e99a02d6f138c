"""A map's review of its segments against the map's typical one (decision record 0224).

A map has what a lone segment lacks: every other segment of the same colon. A segment whose reconstruction holds far
more or far fewer points per mm of the map's line than the map's typical segment is one the map's line cut badly, one
with much of its wall unseen, or one whose lumen is much wider or narrower than the rest (the signal does not tell
these apart); on the real validation colons' maps the estimate is far off there most often. Where the calibration's
map part has a ``review_point_rate`` (``scripts/map_intervals.py --write``), such a segment is flagged for review
beside the ones its interval flags.
"""

from __future__ import annotations

import math

import numpy as np


def point_rates(points, start_mm, end_mm) -> np.ndarray:
    """``point_rate`` of each of a map's segments: ``|ln(r / median(r))|``, ``r`` its points per mm of the line.

    Parameters
    ----------
    points : (n,) int
        Reconstruction points in each segment.
    start_mm, end_mm : (n,) float
        Each segment's arc lengths along the map's centerline, mm.

    Returns
    -------
    (n,) float
        0 for a segment as dense as the map's median one; ``ln 2`` for one twice or half as dense. Empty for no
        segment.
    """
    rate = _per_mm(points, start_mm, end_mm)
    return _against(rate, float(np.median(rate))) if len(rate) else rate


def _per_mm(points, start_mm, end_mm) -> np.ndarray:
    """(n,) points per mm of the map's line of each segment."""
    return np.asarray(points, float) / np.maximum(np.asarray(end_mm, float) - np.asarray(start_mm, float), 1e-6)


def _against(rate: np.ndarray, typical: float) -> np.ndarray:
    """``|ln(rate / typical)|``."""
    return np.abs(np.log(np.maximum(rate, 1e-12) / max(typical, 1e-12)))


def review_by_point_rate(segments: list, threshold: float | None) -> None:
    """Flag the map's estimated segments whose :func:`point_rates` exceeds ``threshold``, in place.

    Parameters
    ----------
    segments : list of colonbench.mapping.segments.Segment
        The map's segments. Those with a coverage are compared with each other; of them, only those with a
        ``coverage_interval`` (a calibrated method's) are reviewed, so a method without intervals gets no reason.
    threshold : float or None
        The calibration's ``map["review_point_rate"]``; None: nothing is flagged.
    """
    if threshold is None:
        return
    done = [s for s in segments if s.coverage is not None and np.isfinite(s.coverage)]
    if not done:
        return
    per_mm = _per_mm([s.points for s in done], [s.start_mm for s in done], [s.end_mm for s in done])
    typical = float(np.median(per_mm))
    for seg, own, rate in zip(done, per_mm, _against(per_mm, typical)):
        if seg.coverage_interval is None or rate <= threshold:
            continue
        times = f"{math.exp(rate):.2f} times as many" if own > typical else f"1/{math.exp(rate):.2f} as many"
        seg.review = [*seg.review, f"{own:.0f} points per mm of the map's line against the map's typical "
                                   f"{typical:.0f} ({times}; flagged beyond {math.exp(threshold):.2f} times either "
                                   "way): a stretch the map's line cut badly, with much of its wall unseen, or of a "
                                   "lumen much wider or narrower than the rest"]
