"""How sure the completion method is: a calibrated interval around each coverage estimate, and when to look again.

Split-conformal prediction (Vovk et al.; Angelopoulos and Bates, "A gentle introduction to conformal prediction",
2021), by group (Mondrian): the segments of a calibration set are estimated by the method, and per group the
residuals ``true - estimated`` give two quantiles; an estimate ``c`` in that group gets the interval
``[c + q_low, c + q_high]`` (clipped to [0, 1]), which holds the truth for a share ``level`` of segments like the
calibration set's (exchangeable with it). The quantiles are the finite-sample ones: rank ``floor((n + 1) a)`` for
the low tail ``a = (1 - level) / 2`` and ``ceil((n + 1) (1 - a))`` for the high one. Intervals are asymmetric: the
method over-estimates where most of the wall is missing, so the interval reaches further down.

A group is a key of the method's own signals (:func:`group_key`): how many of the segment's ends were found at a
cut rim (an end without one is where the segment may go on unseen) and the estimate's band. The calibration
(groups, quantiles, the data it came from) is a JSON file beside the model (``<model>.intervals.json``), made by
``scripts/calibrate_intervals.py``; decision record 0144 says how the scheme and the review width were chosen.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

#: Nominal coverage of the intervals.
LEVEL = 0.9
#: Estimate bands of the groups (upper edges, fractions).
BANDS = (0.8, 1.01)
#: Bands of the segment's length as the method found it (its line between the planes; upper edges, mm): a cloud
#: that spans less than a segment's usual length may stop short of an end nobody saw.
LENGTHS_MM = (45.0, 60.0)
#: Fewest calibration segments a group needs; smaller groups use the group of all segments with their rims.
MIN_GROUP = 30
#: A span between the planes (``signals["span_mm"]``) shorter than this share of the segment's known length stops
#: short of an unseen end (:func:`known_length`; chosen on the calibration set, decision records 0144 and 0155).
SHORT_SHARE = 0.9
#: Suffix of a model's calibration file.
SUFFIX = ".intervals.json"


def group_key(coverage: float, signals: dict, scheme: str) -> str:
    """The calibration group of an estimate under a scheme: ``all``, or its factors joined by ``,``:
    ``rims=<k>`` (cut rims found), ``length<<L>`` (the line between the planes shorter than ``L`` mm of
    :data:`LENGTHS_MM`, or ``length>=<last>``) and ``below=<b>`` (the estimate's band of :data:`BANDS`)."""
    if scheme == "marginal":
        return "all"
    parts = []
    for factor in scheme.split("+"):
        if factor == "rims":
            parts.append(f"rims={int(signals.get('rims', 0))}")
        elif factor == "length":
            length = float(signals.get("length_mm", 0.0))
            edge = next((e for e in LENGTHS_MM if length < e), None)
            parts.append(f"length<{edge:g}" if edge is not None else f"length>={LENGTHS_MM[-1]:g}")
        elif factor == "band":
            parts.append(f"below={next(b for b in BANDS if coverage < b):g}")
        else:
            raise ValueError(f"unknown interval scheme factor {factor!r}")
    return ",".join(parts)


def conformal_quantiles(residuals, level: float = LEVEL) -> tuple[float, float]:
    """The split-conformal low and high quantiles of ``true - estimated`` residuals (fractions)."""
    r = np.sort(np.asarray(residuals, float))
    n = len(r)
    a = (1.0 - level) / 2.0
    lo = math.floor((n + 1) * a + 1e-9)          # (1 - 0.9) / 2 is 0.04999...: ranks at a float near-tie
    hi = math.ceil((n + 1) * (1.0 - a) - 1e-9)
    low = r[lo - 1] if lo >= 1 else -1.0      # too few residuals for the tail: the widest interval
    high = r[hi - 1] if hi <= n else 1.0
    return float(low), float(high)


@dataclass
class Intervals:
    """A calibration: per group the residual quantiles, and the width above which an estimate is to be reviewed.

    Attributes
    ----------
    scheme : str
        ``marginal``, or factors of :func:`group_key` joined by ``+`` (``length+band``).
    level : float
    groups : dict
        Group key -> ``{"low", "high", "n"}`` (fractions, calibration estimates: segments times noise levels).
    review_width : float
        An interval wider than this (fraction) flags the estimate for review.
    source : dict
        What it was calibrated on: model, manifests and their hashes (``known_manifests``: those :attr:`known` was
        fitted on), noise levels, samples.
    known : dict
        ``{"low", "high", "n"}`` of segments whose extent is known (``signals["extent"] == "known"``: a length
        given to :func:`known_length`, or planes the caller clips at, as ``colonbench map`` does).
    """

    scheme: str
    level: float
    groups: dict
    review_width: float
    source: dict = field(default_factory=dict)
    known: dict = field(default_factory=dict)

    def quantiles(self, coverage: float, signals: dict) -> tuple[float, float]:
        """The residual quantiles of an estimate's group (the coarser scheme's group where its own had too few
        calibration segments)."""
        if signals.get("extent") == "known" and self.known:
            return self.known["low"], self.known["high"]
        for scheme in (self.scheme, self.scheme.split("+")[0], "marginal"):
            g = self.groups.get(group_key(coverage, signals, scheme))
            if g is not None:
                return g["low"], g["high"]
        return -1.0, 1.0

    def interval(self, coverage: float, signals: dict) -> tuple[float, float]:
        """The interval (fractions, clipped to [0, 1]) around an estimate with these signals."""
        low, high = self.quantiles(coverage, signals)
        return float(np.clip(coverage + low, 0, 1)), float(np.clip(coverage + high, 0, 1))

    def apply(self, est) -> None:
        """Set an :class:`~colonbench.estimate.Estimate`'s ``coverage_interval``, ``interval_level`` and ``review``
        from its coverage and its signals."""
        if not np.isfinite(est.coverage):
            return
        est.coverage_interval = self.interval(est.coverage, est.signals)
        est.interval_level = self.level
        width = est.coverage_interval[1] - est.coverage_interval[0]
        if width > self.review_width:
            est.review.append(f"interval {100 * width:.0f} points wide (more than {100 * self.review_width:.0f})")
        if int(est.signals.get("rims", 0)) == 0 and est.signals.get("extent") != "known":
            est.review.append("no cut rim at either end: the segment's ends are the line's own, it may go on unseen")
        if int(est.signals.get("rims_doubtful", 0)) and est.signals.get("extent") != "known":
            est.review.append("a cut rim crosses the line well inside the cloud: a cloud seen from one side may have "
                              "had its unseen side clipped off (over-estimated)")

    def to_json(self) -> dict:
        return asdict(self)


def known_length(est, length_mm: float) -> None:
    """Use a segment's known arc length (mm): where the segment's span between its planes (``signals["span_mm"]``:
    the method's line between them, run on straight to a plane beyond its end) is less than :data:`SHORT_SHARE`
    of it, the cloud stops short of an end nobody saw, and the coverage is scaled by the share it spans (the rest
    of the tube counted unobserved; decision record 0155). Marks the estimate's extent as known."""
    if not (length_mm > 0 and np.isfinite(length_mm)):
        raise ValueError(f"a segment's length must be a positive number of mm, got {length_mm}")
    span = float(est.signals["span_mm"])
    share = span / float(length_mm)
    est.signals.update(extent="known", length_share=round(share, 4))
    if share < SHORT_SHARE and np.isfinite(est.coverage):
        est.coverage = float(est.coverage) * share
        est.review.append(f"the cloud spans {span:.0f} of the segment's {length_mm:g} mm: the rest is counted "
                          "unobserved")


def fit(true, estimated, signals: list, scheme: str, review_width: float, level: float = LEVEL,
        source=None) -> Intervals:
    """Calibrate intervals on segments' true and estimated coverages (fractions, (n,)) and their signals (n dicts);
    add :attr:`Intervals.known` with :func:`fit_known`."""
    true, estimated = np.asarray(true, float), np.asarray(estimated, float)
    residual = true - estimated
    groups = {}
    for sch in dict.fromkeys(("marginal", scheme.split("+")[0], scheme)):
        keys = np.array([group_key(c, sig, sch) for c, sig in zip(estimated, signals)])
        for key in np.unique(keys):
            sel = keys == key
            if sel.sum() >= MIN_GROUP:
                low, high = conformal_quantiles(residual[sel], level)
                groups[str(key)] = {"low": low, "high": high, "n": int(sel.sum())}
    return Intervals(scheme, level, groups, review_width, dict(source or {}))


def fit_known(cal: Intervals, true, estimated) -> None:
    """Calibrate :attr:`Intervals.known` on segments estimated with their lengths known (:func:`known_length`)."""
    residual = np.asarray(true, float) - np.asarray(estimated, float)
    low, high = conformal_quantiles(residual, cal.level)
    cal.known = {"low": low, "high": high, "n": int(len(residual))}


def path_for(model: Path) -> Path:
    """The calibration file of a model file: ``<model stem>.intervals.json`` beside it."""
    model = Path(model)
    return model.with_name(model.name.removesuffix(".safetensors") + SUFFIX)


def load(model: Path, steps: str | None) -> Intervals | None:
    """A model's calibration for the steps ``steps`` (``steps=10``, as a method's version names them; None: whatever
    steps), or None where it has none: a user's own model before it is calibrated, or other steps than its own."""
    path = path_for(model)
    if not path.is_file():
        return None
    cal = Intervals(**json.loads(path.read_text()))
    return cal if steps is None or cal.source.get("steps") == steps else None
