"""How sure the completion method is: a calibrated interval around each coverage estimate, and when to look again.

Split-conformal prediction (Vovk et al.; Angelopoulos and Bates, "A gentle introduction to conformal prediction",
2021), by group (Mondrian): the segments of a calibration set are estimated by the method, and per group the residuals
``true - estimated`` give two quantiles; an estimate ``c`` in that group gets the interval ``[c + q_low, c + q_high]``
(clipped to [0, 1]), which holds the truth for a share ``level`` of segments like the calibration set's (exchangeable
with it). The quantiles are the finite-sample ones: rank ``floor((n + 1) a)`` for the low tail ``a = (1 - level) / 2``
and ``ceil((n + 1) (1 - a))`` for the high one. Intervals are asymmetric: the method over-estimates where most of the
wall is missing, so the interval reaches further down.

A group is a key of the method's own signals (:func:`group_key`): how many of the segment's ends were found at a cut
rim (an end without one is where the segment may go on unseen) and the estimate's band. In a *scaled* scheme
(decision record 0156) the residuals are divided by a scale ``exp(w . f)`` of the estimate's features (:func:`features`)
before their quantiles are taken, and an estimate's quantiles are multiplied by its own scale; each feature is first
clipped into the range the calibration saw (decision record 0160). A two-sided scheme (``scaled2...``, decision record
0158) fits a scale for each end; a ``-colon`` scheme weighs every colon the same (decision record 0325), a ``-shift``
one adds a colon-level shift term; a ``binned`` one takes its quantiles per band of the scale (decision record 0161);
a ``quant<NN>`` one fits each end's scale at the ``NN`` % quantile of the log residual, not by least squares (decision
record 0166). The calibration (its scheme, groups, quantiles, weights, ranges, the data it came from) is a JSON file
beside the model (:mod:`colonbench.completion.calfile`), made by ``scripts/calibrate_intervals.py``, which also chooses
the scheme and the review's rules (:mod:`colonbench.completion.review`).
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from colonbench.completion.conformal import band_of, band_quantiles, log_scale_fit, shifted_quantiles
from colonbench.completion.review import REVIEW_SCORES, review_reason, review_score  # noqa: F401
from colonbench.errors import InputError

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
#: short of an unseen end (:func:`~colonbench.completion.known_extent.known_length`; chosen on the calibration set,
#: decision records 0144 and 0155).
SHORT_SHARE = 0.9
#: A line between the planes longer than this many times the longest the intervals were calibrated on is named in
#: ``review`` whatever the interval's width: a cloud longer than a segment (decision record 0160).
LONG_SHARE = 1.5
#: The features of an estimate its interval is scaled by, per scaled scheme (:func:`features`; decision records 0156
#: and 0158; 0156's measurement also tried features the method does not compute, kept in its session script).
_SIGNALS = ("one", "estimate", "length", "span_ratio", "no_rim", "one_rim", "doubtful")
_NOVEL = _SIGNALS + ("spread", "radius_ratio", "line_extent")     # decision record 0325
_GAPS = _NOVEL + ("log_gap",)                                       # decision record 0161
_DEPTH = _NOVEL + ("depth",)                                        # decision record 0161, round 5
_MISFIT = _NOVEL + ("misfit",)                                      # decision record 0165
_FILL = _DEPTH + ("unfilled",)                                      # decision record 0175
SCALE_FEATURES = {
    "scaled": _SIGNALS, "scaled2": _SIGNALS, "scaled2-gaps": _SIGNALS + ("gap_share",), "scaled-colon": _SIGNALS,
    "scaled-colon-novel": _NOVEL, "scaled-colon-novel-shift": _NOVEL, "scaled2-colon-novel": _NOVEL,
    "scaled2-colon-novel-shift": _NOVEL, "binned-colon-novel": _NOVEL, "binned-colon-novel-shift": _NOVEL,
    "scaled2-colon-novel-gaps-shift": _GAPS, "binned-colon-novel-gaps-shift": _GAPS,
    "scaled2-colon-novel-depth-shift": _DEPTH, "binned-colon-novel-depth-shift": _DEPTH,
    "scaled2-colon-novel-misfit-shift": _MISFIT, "binned-colon-novel-misfit-shift": _MISFIT,
    "quant95-colon-novel-misfit-shift": _MISFIT, "quant90-colon-novel-misfit-shift": _MISFIT,
    "binned-colon-novel-depth-fill-shift": _FILL,
}
#: A ``binned`` scheme's bands of the fitted scale: cut at these colon-weighted quantiles of it (decision 0161).
BAND_QUANTILES = (0.25, 0.5, 0.75)
#: A likeness scheme's name: ``like<NN>+<scheme>``, NN the chance (%) over which an estimate is ``like=1``
#: (:mod:`colonbench.completion.likeness`, decision record 0170).
LIKE = re.compile(r"^like(0[1-9]|[1-9]\d)\+(.+)$")


def features(coverage: float, signals: dict, names) -> np.ndarray:
    """The features ``names`` (:data:`SCALE_FEATURES`) of an estimate, from its coverage and its signals
    (:func:`colonbench.completion.method.from_heatmap`); a signal the estimate lacks counts 0.

    ``one``: 1; ``estimate``: the coverage; ``length``: the line between the planes / 60 mm; ``span_ratio``: the span
    between the planes / that line; ``no_rim``, ``one_rim``: how many cut rims were found; ``doubtful``: a doubtful
    rim; ``gap_share``: the area share of the wall-gap patches; ``spread``: the network's disagreement with itself
    times 10, ``radius_ratio``: the lumen's radius / the line, ``line_extent``: the line / the cloud's extent
    (:mod:`colonbench.completion.novelty`); ``log_gap``: ``log10(gap_share + 0.001)``, -3 where no wall-gap patch
    was found; ``depth``: the holes' depth (``hole_depth_mm``, :func:`colonbench.completion.novelty.hole_depth`) /
    10 mm; ``misfit``: how far the cloud lies from the completed wall's nearest vertices (``wall_misfit_mm``, mm,
    :func:`colonbench.completion.novelty.wall_misfit`); ``unfilled``: ``1 - rim_fill``, how much of a ring the less
    filled cut rim lacks (1 where an end has no rim, 0 where the estimate has no ``rim_fill``: planes the caller gave;
    decision record 0175); ``share_off``: ``|ln(length_share)|``, how far the span between the planes is from a
    length given (``length_share``), 0 where none is (a map's segment, whose planes are known; like every feature,
    then clipped into the range calibrated on)."""
    g = lambda k: float(signals.get(k, 0.0) or 0.0)          # noqa: E731
    length = g("length_mm")
    rims = int(g("rims"))
    value = {"one": 1.0, "estimate": float(coverage), "length": length / 60.0,
             "span_ratio": g("span_mm") / max(length, 1.0), "no_rim": float(rims == 0), "one_rim": float(rims == 1),
             "doubtful": float(g("rims_doubtful") > 0), "gap_share": g("gap_share"), "spread": 10.0 * g("spread"),
             "radius_ratio": g("radius_mm") / max(length, 1.0),
             "line_extent": length / g("extent_mm") if g("extent_mm") > 0 else 0.0,
             "log_gap": math.log10(max(g("gap_share"), 0.0) + 0.001), "depth": g("hole_depth_mm") / 10.0,
             "misfit": g("wall_misfit_mm"),
             "unfilled": 1.0 - float(signals["rim_fill"]) if signals.get("rim_fill") is not None else 0.0,
             "share_off": abs(math.log(g("length_share"))) if g("length_share") > 0 else 0.0}
    out = np.array([value[n] for n in names], float)
    return np.where(np.isfinite(out), out, 0.0)


def _scaled(scheme: str) -> str | None:
    """The scaled factor of a scheme (``scaled``, ``length+scaled`` or ``like<NN>+scaled``), or None."""
    like = LIKE.match(scheme)
    last = like.group(2) if like else scheme.split("+", 1)[-1] if scheme.startswith("length+") else scheme
    return last if last in SCALE_FEATURES else None


def scale_features(scheme: str) -> tuple:
    """The features a scheme's scale reads (:data:`SCALE_FEATURES` of its scaled factor); () where it has none."""
    scaled = _scaled(scheme)
    return SCALE_FEATURES[scaled] if scaled else ()


def _binned(scaled: str | None) -> bool:
    """Whether a scaled factor takes its quantiles per band of the fitted scale (``binned...``, decision record
    0161: Mondrian conformal regression over a difficulty estimate, Bostrom and Johansson 2020)."""
    return bool(scaled) and scaled.startswith("binned")


def _two_sided(scaled: str | None) -> bool:
    """Whether a scaled factor fits a scale for each end of the interval (``scaled2...``, ``quant...``)."""
    return bool(scaled) and scaled.startswith(("scaled2", "quant"))


def _tau(scaled: str | None) -> float | None:
    """The quantile a ``quant<NN>-...`` scheme fits each end's log scale at (``NN`` / 100, two digits, decision
    record 0166), else None (a least-squares fit of the log)."""
    if not (scaled and scaled.startswith("quant")):
        return None
    match = re.fullmatch(r"quant(\d{2})-.+", scaled)
    if match is None:
        raise ValueError(f"a quantile scheme is named quant<two digits>-..., not {scaled!r}")
    return int(match.group(1)) / 100.0


def _groups_of(scheme: str) -> str:
    """The scheme whose groups a scaled scheme is fitted within (``marginal`` or ``length``)."""
    return "length" if scheme.startswith("length+") else "marginal"


def group_key(coverage: float, signals: dict, scheme: str) -> str:
    """The calibration group of an estimate under a scheme: ``all``, or its factors joined by ``,``:
    ``rims=<k>`` (cut rims found), ``length<<L>`` (the line between the planes shorter than ``L`` mm of
    :data:`LENGTHS_MM`, or ``length>=<last>``) and ``below=<b>`` (the estimate's band of :data:`BANDS`)."""
    if _scaled(scheme):
        scheme = _groups_of(scheme)
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


@dataclass
class Intervals:
    """A calibration: per group the residual quantiles, and when an estimate is to be reviewed.

    Attributes
    ----------
    scheme : str
        ``marginal``, or factors of :func:`group_key` joined by ``+`` (``length+band``).
    level : float
    groups : dict
        Group key -> ``{"low", "high", "n"}`` (fractions, calibration estimates: segments times noise levels); a
        scaled group adds ``features``, ``ranges`` and ``weights`` (``weights_low``, ``weights_high``: two-sided),
        the shift term's ``shift_low``, ``shift_high`` (included in ``low``, ``high``) and a binned one's
        ``band_edges``, ``band_low``, ``band_high``, ``band_n``.
    review_width : float
        An estimate whose score (:attr:`review_by`: its interval's width, or how far it reaches from the estimate, a
        fraction; or the log odds that it is far off) exceeds this flags the estimate for review; only then are its
        rims' notes, and a known length's the cloud stops short of, reasons too (decision record 0156).
    source : dict
        What it was calibrated on: model, manifests and their hashes (``known_manifests``: those :attr:`known` was
        fitted on), noise levels, samples.
    map : dict
        ``{"scheme", "groups"}``: the map's segments' own quantiles per group (``track=context``,
        ``track=segment-only``, ``...,below=<b>``; ``signals["map_track"]`` says a map segment's track), calibrated on
        maps (``scripts/map_intervals.py``); without groups the map's segments get :attr:`known`. ``review_width``:
        the map's segments' own review threshold (a width, fraction), chosen on the validation maps (decision
        record 0223); without it they are reviewed as any estimate of known extent. ``review_point_rate``: a map
        segment is also flagged where its points per mm of the map's line differ from the map's typical segment's by
        more than this in ``|ln|`` (:mod:`colonbench.mapping.map_review`, decision record 0224).
    known : dict
        ``{"low", "high", "n"}`` of segments whose extent is known (``signals["extent"] == "known"``: a length
        given to :func:`known_extent.known_length <colonbench.completion.known_extent.known_length>`, or planes the
        caller clips at, as ``colonbench map`` does); with ``short`` and ``full`` (decision records 0168 and 0222), the
        groups of the estimates a length given shortened (``length_share`` under :data:`SHORT_SHARE`) and left.
    review_by : str
        What the review compares with :attr:`review_width` (:data:`~colonbench.completion.review.REVIEW_SCORES`:
        :func:`~colonbench.completion.review.review_score`'s, or ``odds``).
    review_by_known : str
        What it compares with :attr:`review_known` ("": :attr:`review_by`).
    review_known : float
        The review threshold of the intervals of known extent (fraction; 0: :attr:`review_width`): a segment whose
        planes the caller gives (a map's) or whose length is given (``known_extent.known_length``; decision record
        0163, round 8), chosen as :attr:`review_width` is on the known-length intervals held out (decision record 0325).
    review_odds : dict
        ``{"features", "ranges", "weights"}``: the logistic fit whose log odds (:func:`features` clipped into
        ``ranges``, times ``weights``) a review by ``odds`` compares with :attr:`review_width` (decision record
        0167); empty otherwise.
    like : dict
        A ``like<NN>+...`` scheme's classifier (:mod:`colonbench.completion.likeness`, decision record 0170):
        ``{"features", "ranges", "weights", "threshold"}``; an estimate it finds like the paper's colons
        (:func:`looks_like`) gets the group ``like=1``, any other ``like=0``. Empty otherwise.
    """

    scheme: str
    level: float
    groups: dict
    review_width: float
    source: dict = field(default_factory=dict)
    known: dict = field(default_factory=dict)
    map: dict = field(default_factory=dict)
    review_known: float = 0.0
    review_by: str = "width"
    review_by_known: str = ""
    review_odds: dict = field(default_factory=dict)
    like: dict = field(default_factory=dict)

    def __post_init__(self):
        if "odds" in (self.review_by, self.review_by_known) and not self.review_odds:
            raise InputError("a calibration reviewed by odds must hold its fit (review_odds)")
        if self.review_by == "odds" and self.review_known > 0 and not self.review_by_known:
            raise InputError("a calibration reviewed by odds must name its known extent's score (review_by_known): "
                             "review_known is a width, not log odds")
        if self.scheme.startswith("like") and not LIKE.match(self.scheme):
            raise InputError(f"a calibration's likeness scheme is named like<NN>+<scheme> (NN 01-99), "
                             f"not {self.scheme!r}")
        if not isinstance(self.like, dict) or bool(self.like) != bool(LIKE.match(self.scheme)) or \
                self.like and not _like_fits(self.like):                                 # decision record 0170
            raise InputError(f"a calibration's scheme {self.scheme!r} and its like (features, ranges as [low, high], "
                             "weights, threshold) clash")
        for by in (self.review_by, self.review_by_known or self.review_by):
            if by not in REVIEW_SCORES:
                raise InputError(f"a calibration's review score must be one of {', '.join(REVIEW_SCORES)}, "
                                 f"not {by!r}")

    def quantiles(self, coverage: float, signals: dict) -> tuple[float, float]:
        """The residual quantiles of an estimate's group (the coarser scheme's group where its own had too few
        calibration segments; a likeness scheme's ``like=1`` or ``like=0`` by :func:`looks_like`, else ``all``),
        times the estimate's scale in a scaled scheme."""
        if signals.get("map_track") and self.map.get("groups"):
            key = f"track={signals['map_track']}"
            if self.map.get("scheme") == "track+band":
                key += f",below={next(b for b in BANDS if coverage < b):g}"
            g = self.map["groups"].get(key) or self.map["groups"].get(key.split(",")[0])
            if g is not None:
                return g["low"], g["high"]
        if signals.get("extent") == "known" and self.known:     # a length given: shortened or not (0168, 0222)
            split = "length_share" in signals and "short" in self.known
            g = self.known["short" if shortened_by_length(signals) else "full"] if split else self.known
            return _scale(g, coverage, signals)
        if self.like:                   # decision record 0170
            g = self.groups.get(f"like={int(looks_like(self.like, coverage, signals))}")
            if g is not None:
                return _scale(g, coverage, signals)
        for scheme in (self.scheme, "marginal" if self.like else self.scheme.split("+")[0], "marginal"):
            g = self.groups.get(group_key(coverage, signals, scheme))
            if g is not None:
                return _scale(g, coverage, signals)
        return -1.0, 1.0

    def interval(self, coverage: float, signals: dict) -> tuple[float, float]:
        """The interval (fractions, clipped to [0, 1]) around an estimate with these signals."""
        low, high = self.quantiles(coverage, signals)
        return float(np.clip(coverage + low, 0, 1)), float(np.clip(coverage + high, 0, 1))


    def apply(self, est) -> None:
        """Set an :class:`~colonbench.estimate.Estimate`'s ``coverage_interval``, ``interval_level`` and ``review``
        from its coverage and its signals: an estimate whose score (:attr:`review_by`: of its interval, or its odds of
        being far off) exceeds :attr:`review_width` (:attr:`review_known`, :attr:`review_by_known` where its extent
        is known) is a reason, and then so are
        the rims' notes and a known length's; a line over :data:`LONG_SHARE` times :meth:`longest_mm` always is."""
        if not np.isfinite(est.coverage):
            return
        est.coverage_interval = self.interval(est.coverage, est.signals)
        est.interval_level = self.level
        width = est.coverage_interval[1] - est.coverage_interval[0]
        longest = self.longest_mm()
        line = float(est.signals.get("length_mm", 0.0) or 0.0)
        long = (f"the cloud's line runs {line:.0f} mm between its planes, more than {LONG_SHARE:g} times the longest "
                f"the intervals were calibrated on ({longest:.0f} mm): longer than one segment, outside what the "
                "method and its interval were tested on (cut the reconstruction into segments: colonbench map does)"
                if longest and line > LONG_SHARE * longest else "")
        # planes the caller clips at (a map's segment) or a length given (decision record 0163, round 8)
        known = est.signals.get("extent") == "known" and self.review_known > 0
        review_width = self.review_known if known else self.review_width
        by = (self.review_by_known or self.review_by) if known else self.review_by
        score = (linear_score(self.review_odds, features(est.coverage, est.signals, self.review_odds["features"]))
                 if by == "odds" else review_score(est.coverage, *est.coverage_interval, by))
        if score <= review_width:           # sure enough: the notes (the rims', a known length's) are reasons only
            est.review.clear()              # where it is not
            est.review.extend([long] if long else [])
            return
        est.review.append(review_reason(width, score, review_width, by))
        est.review.extend([long] if long else [])
        if int(est.signals.get("rims", 0)) == 0 and est.signals.get("extent") != "known":
            est.review.append("no cut rim at either end: the segment's ends are the line's own, it may go on unseen")
        if int(est.signals.get("rims_doubtful", 0)) and est.signals.get("extent") != "known":
            est.review.append("a cut rim crosses the line well inside the cloud: a cloud seen from one side may have "
                              "had its unseen side clipped off (over-estimated)")

    def for_map(self) -> "Intervals":
        """The calibration as a map's segments are reviewed by it: where :attr:`map` has a ``review_width`` (decision
        record 0223), a copy whose known extent is reviewed by that width; else this one."""
        width = self.map.get("review_width")
        return replace(self, review_known=float(width), review_by_known="width") if width else self

    def longest_mm(self) -> float:
        """The longest line between the planes (mm) the scaled groups were calibrated on (their ``length``
        feature's range), 0 where none records it."""
        out = 0.0
        for g in [*self.groups.values(), self.known]:
            names = list(g.get("features", ()))
            if "ranges" in g and "length" in names:
                out = max(out, 60.0 * float(g["ranges"][names.index("length")][1]))
        return out

    def to_json(self) -> dict:
        out = asdict(self)
        if not out["map"]:                 # no map part (the map's segments get the known extent): as before it existed
            del out["map"]
        if not out["review_known"]:        # no review width of its own for the known extent: as before it existed
            del out["review_known"]
        if out["review_by"] == "width":    # scored by width, as before a score could be chosen
            del out["review_by"]
        if not out["review_by_known"]:     # the known extent scored as the segments are
            del out["review_by_known"]
        if not out["review_odds"]:         # reviewed by a score of the interval
            del out["review_odds"]
        if not out["like"]:                # no likeness groups (decision record 0170)
            del out["like"]
        return out


def _scale_of(group: dict, coverage: float, signals: dict, side: str = "") -> float:
    """``exp(w . f)`` of a scaled group (its ``weights``, or ``weights_low`` / ``weights_high`` by ``side`` in a
    two-sided one, over its ``features``), else 1."""
    return float(np.exp(_log_scale_of(group, coverage, signals, side)))


def _log_scale_of(group: dict, coverage: float, signals: dict, side: str = "") -> float:
    """``w . f`` of :func:`_scale_of`, clipped to [-20, 5]; 0 for a group without weights."""
    if group.get(f"weights_{side}", group.get("weights")) is None:
        return 0.0
    return float(np.clip(linear_score(group, features(coverage, signals, group["features"]), side), -20, 5))


def linear_score(fitted: dict, f: np.ndarray, side: str = "") -> float:
    """``w . f`` of a linear fit on an estimate's features ``f`` ((p,), :func:`features` of ``fitted["features"]``):
    a scaled group's log scale (its ``weights``, or ``weights_<side>``) or the review's log odds
    (:attr:`Intervals.review_odds`); each feature first clipped into ``fitted["ranges"]``, the range calibrated on,
    never extrapolated (decision record 0160)."""
    if "ranges" in fitted:
        lo, hi = np.asarray(fitted["ranges"], float).T
        f = np.clip(f, lo, hi)
    return float(f @ np.asarray(fitted.get(f"weights_{side}", fitted.get("weights")), float))


def _like_fits(like: dict) -> bool:
    """Whether a likeness classifier's fields fit together: ``p`` feature names :func:`features` knows, ``p`` finite
    weights, (p, 2) finite ``ranges`` each low <= high, and a number ``threshold`` in (0, 1)."""
    try:
        names, threshold = like.get("features", ()), like.get("threshold")
        ranges, weights = np.asarray(like.get("ranges"), float), np.asarray(like.get("weights"), float)
        features(0.5, {}, names)                        # a name it does not know (a non-string too): KeyError
        return isinstance(threshold, (int, float)) and not isinstance(threshold, bool) and 0 < threshold < 1 and \
            weights.shape == (len(names),) and ranges.shape == (len(names), 2) and \
            bool(np.isfinite(ranges).all() and np.isfinite(weights).all() and (ranges[:, 0] <= ranges[:, 1]).all())
    except (TypeError, ValueError, KeyError):
        return False


def looks_like(like: dict, coverage: float, signals: dict, f: np.ndarray | None = None) -> bool:
    """Whether a likeness classifier (:attr:`Intervals.like`) finds an estimate like the paper's colons: its chance
    over the classifier's ``threshold`` (``f``: its features ``like["features"]``, where already made)."""
    odds = linear_score(like, features(coverage, signals, like["features"]) if f is None else f)
    return odds > math.log(like["threshold"] / (1.0 - like["threshold"]))


def _scale(group: dict, coverage: float, signals: dict) -> tuple[float, float]:
    """A group's low and high quantiles times the estimate's scale (each end's own in a two-sided group); in a
    binned group, the quantiles of the band the estimate's scale falls in
    (:func:`~colonbench.completion.conformal.band_quantiles`)."""
    if "band_edges" in group:
        log_s = _log_scale_of(group, coverage, signals)
        k, s = int(band_of(group["band_edges"], log_s)), math.exp(log_s)
        return group["band_low"][k] * s, group["band_high"][k] * s
    return (group["low"] * _scale_of(group, coverage, signals, "low"),
            group["high"] * _scale_of(group, coverage, signals, "high"))


def _fit_group(residual: np.ndarray, x: np.ndarray | None, names, level: float, two_sided: bool = False,
               weights: np.ndarray | None = None, colons=None, binned: bool = False, tau: float | None = None) -> dict:
    """A group's quantiles: of the residuals, or (``x``: its features) of the residuals over their fitted scale;
    ``two_sided``: a scale of the residuals below 0 for the low end and one of those above for the high end, each
    end's quantile taken of the residuals over its own scale. ``weights``: each residual's weight in the scale's
    fit and the quantiles (:func:`~colonbench.completion.conformal.weighted_quantiles`); ``colons``: each residual's
    colon, for the shift term; ``binned``: the quantiles per band of the scale
    (:func:`~colonbench.completion.conformal.band_quantiles`); ``tau``: each end's scale fitted at that quantile
    (:func:`~colonbench.completion.conformal.log_scale_fit`)."""
    if x is None:
        low, high, _ = shifted_quantiles(residual, level, weights, colons)
        return {"low": low, "high": high, "n": int(len(residual))}
    out = {"n": int(len(residual)), "features": list(names),
           "ranges": [[float(v) for v in r] for r in np.stack([x.min(axis=0), x.max(axis=0)], axis=1)]}
    if binned:
        out["weights"], s = log_scale_fit(x, np.abs(residual), weights)
        log_s = np.clip(x @ np.asarray(out["weights"]), -20, 5)
        return {**out, **band_quantiles(residual / s, log_s, level, weights, colons, MIN_GROUP, BAND_QUANTILES)}
    if not two_sided:
        out["weights"], s = log_scale_fit(x, np.abs(residual), weights)
        out["low"], out["high"], shift = shifted_quantiles(residual / s, level, weights, colons)
        return {**out, **shift}
    out["weights_low"], s_low = log_scale_fit(x, np.maximum(-residual, 0.0), weights, tau)
    out["weights_high"], s_high = log_scale_fit(x, np.maximum(residual, 0.0), weights, tau)
    low, _, shift_low = shifted_quantiles(residual / s_low, level, weights, colons)
    _, high, shift_high = shifted_quantiles(residual / s_high, level, weights, colons)
    out["low"], out["high"] = low, high
    if shift_low:                        # each end's shift term, in its own scaled units
        out.update(shift_low=shift_low["shift_low"], shift_high=shift_high["shift_high"])
    return out


def fit_subgroup(residual, x, names, level: float, scaled: str | None, weights, colons, sel) -> dict:
    """:func:`_fit_group` of the estimates ``sel`` ((n,) bool) of a whole fit's ``residual``, ``x``, ``weights`` and
    ``colons`` (each (n, ...) or None), as the scaled factor ``scaled`` fits its groups."""
    return _fit_group(residual[sel], None if x is None else x[sel], names, level, _two_sided(scaled),
                      None if weights is None else weights[sel], None if colons is None else colons[sel],
                      _binned(scaled), _tau(scaled))


def shortened_by_length(signals: dict) -> bool:
    """Whether a length given shortened an estimate (:func:`colonbench.completion.known_extent.known_length`): its
    ``length_share``, as stored (4 decimals), under :data:`SHORT_SHARE`; no length given: no."""
    return "length_share" in signals and float(signals["length_share"]) < SHORT_SHARE


def _unit_weights(scheme: str, weights, colons, n: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The weights and colons a scheme fits with: a ``-colon`` scheme needs weights (the colon as the unit), a
    ``-shift`` one the colons too; any other scheme counts every segment once."""
    if "-colon" not in scheme:
        return None, None
    if weights is None:
        raise ValueError(f"interval scheme {scheme!r} weighs colons: give each segment's weight")
    if scheme.endswith("-shift") and colons is None:
        raise ValueError(f"interval scheme {scheme!r} has a colon-level shift term: give each segment's colon")
    w = np.asarray(weights, float)
    if w.ndim != 1 or len(w) != n or not np.isfinite(w).all() or (w < 0).any() or not w.sum() > 0:
        raise ValueError(f"the segments' weights must be {n} finite numbers >= 0, not all 0 (got shape {w.shape})")
    c = np.asarray(colons) if scheme.endswith("-shift") else None
    if c is not None and c.shape != (n,):
        raise ValueError(f"the segments' colons must be {n} labels (got shape {c.shape})")
    return w, c


def fit(true, estimated, signals: list, scheme: str, review_width: float, level: float = LEVEL,
        source=None, weights=None, colons=None) -> Intervals:
    """Calibrate intervals on segments' true and estimated coverages (fractions, (n,)) and their signals (n dicts);
    add :attr:`Intervals.known` with :func:`colonbench.completion.known_extent.fit_known`. ``weights`` ((n,)) and
    ``colons`` ((n,)): each segment's weight and colon, for the schemes that take the colon as the unit
    (``...-colon...``)."""
    if LIKE.match(scheme):
        raise ValueError(f"a likeness scheme ({scheme!r}) is fitted by colonbench.completion.likeness.fit")
    true, estimated = np.asarray(true, float), np.asarray(estimated, float)
    residual = true - estimated
    scaled = _scaled(scheme)
    names = SCALE_FEATURES[scaled] if scaled else ()
    x = np.array([features(c, sig, names) for c, sig in zip(estimated, signals)]) if scaled else None
    weights, colons = _unit_weights(scheme, weights, colons, len(true))
    groups = {}
    for sch in dict.fromkeys(("marginal", scheme.split("+")[0], scheme)):
        keys = np.array([group_key(c, sig, sch) for c, sig in zip(estimated, signals)])
        for key in np.unique(keys):
            sel = keys == key
            if sel.sum() >= MIN_GROUP and str(key) not in groups:
                groups[str(key)] = fit_subgroup(residual, x, names, level, scaled, weights, colons, sel)
    return Intervals(scheme, level, groups, review_width, dict(source or {}))

