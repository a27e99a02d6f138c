"""What the review flag is scored by, and the known extent's share of the length given (decision record 0163)."""

import json
import math

import numpy as np
import pytest

from colonbench.completion import intervals, known_extent
from colonbench.errors import InputError
from colonbench.estimate import Estimate


def _estimate(coverage=0.6, **signals):
    return Estimate(coverage, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"length_mm": 70.0, "rims": 2,
                                                                                  **signals})


def test_the_three_scores_of_an_interval():
    assert intervals.review_score(0.6, 0.3, 0.7, "width") == pytest.approx(0.4)
    assert intervals.review_score(0.6, 0.3, 0.7, "reach") == pytest.approx(0.3)      # the low end is farther
    assert intervals.review_score(0.6, 0.5, 0.95, "reach") == pytest.approx(0.35)    # the high end is farther
    assert intervals.review_score(0.6, 0.5, 0.95, "drop") == pytest.approx(0.1)
    with pytest.raises(ValueError, match="unknown interval review score 'size'"):
        intervals.review_score(0.6, 0.5, 0.95, "size")


def test_review_by_drop_flags_an_interval_reaching_far_below_not_one_as_wide_reaching_up():
    cal = intervals.fit([0.8] * 40, [0.8] * 40, [{"length_mm": 70.0, "rims": 2}] * 40, "length", 0.25)
    flagged = {}
    for by in ("width", "drop"):
        cal.review_by = by
        for low, high in ((-0.3, 0.05), (-0.1, 0.3)):          # 35 and 40 points wide; 30 and 10 below
            cal.groups["length>=60"].update(low=low, high=high)
            est = _estimate()
            cal.apply(est)
            flagged[(by, low)] = est.review
    assert flagged[("width", -0.3)] == ["interval 35 points wide (more than 25)"] and flagged[("width", -0.1)]
    assert flagged[("drop", -0.3)] == ["interval 35 points wide: it reaches down 30 points from the estimate "
                                       "(more than 25)"]
    assert flagged[("drop", -0.1)] == []


def test_a_known_extent_takes_its_own_score_and_a_segment_the_segments():
    """A map's segment and a length given (decision record 0163, round 8) are scored by ``review_by_known`` against
    ``review_known``; a segment of unknown extent with the same interval by ``review_by`` against ``review_width``.
    The interval is 20 points wide, reaching 15 above and 5 below: each case is one that another score would
    decide the other way."""
    cal = intervals.fit([0.8] * 40, [0.8] * 40, [{"length_mm": 70.0, "rims": 2}] * 40, "length", 0.15)
    cal.known = {"low": -0.05, "high": 0.15, "n": 40}
    cal.review_known, cal.review_by = 0.17, "drop"
    for by_known, flagged in (("reach", False), ("width", True)):         # reach 15 <= 17 < width 20
        cal.review_by_known = by_known
        for signals in ({"extent": "known"}, {"extent": "known", "length_share": 1.0}):   # a map's planes, a length
            est = _estimate(**signals)
            cal.apply(est)
            assert bool(est.review) == flagged, (by_known, signals)
    cal.review_known, cal.review_by_known = 0.12, "reach"
    est = _estimate(extent="known")
    cal.apply(est)
    assert est.review == ["interval 20 points wide: it reaches 15 points from the estimate (more than 12)"]
    cal.groups["length>=60"].update(low=-0.05, high=0.15)       # the same interval, extent unknown: drop 5 <= 15,
    segment = _estimate()                                       # though its width (20) is over 15
    cal.apply(segment)
    assert segment.review == []
    cal.review_by = "width"
    cal.apply(segment)
    assert segment.review == ["interval 20 points wide (more than 15)"]


def test_the_scores_survive_the_calibration_file_and_a_wrong_one_is_refused():
    cal = intervals.fit([0.8] * 40, [0.8] * 40, [{"length_mm": 70.0, "rims": 2}] * 40, "length", 0.25)
    assert "review_by" not in cal.to_json() and "review_by_known" not in cal.to_json()   # width, as files before
    for by, by_known in (("drop", "reach"), ("drop", "width"), ("width", "drop"), ("reach", "")):
        cal.review_by, cal.review_by_known = by, by_known
        back = intervals.Intervals(**json.loads(json.dumps(cal.to_json())))
        assert (back.review_by, back.review_by_known) == (by, by_known)     # "width" for the known extent is kept
    with pytest.raises(InputError, match="review score must be one of width, reach, drop, odds, not 'size'"):
        intervals.Intervals(**{**cal.to_json(), "review_by": "size"})


def test_share_off_is_how_far_the_span_is_from_the_length_given_either_way():
    f = lambda sig: float(intervals.features(0.8, sig, ("share_off",))[0])      # noqa: E731
    assert f({"length_share": 0.5}) == pytest.approx(math.log(2)) == pytest.approx(f({"length_share": 2.0}))
    assert f({"length_share": 1.0}) == 0.0 and f({}) == 0.0       # no length given (a map's planes): 0


def test_the_known_extents_scale_learns_the_share_where_its_errors_grow_with_it():
    rng = np.random.default_rng(1)
    n = 600
    share = np.exp(rng.uniform(-0.7, 0.7, n))
    off = np.abs(np.log(share))
    est = rng.uniform(0.5, 0.9, n)
    true = est + rng.normal(0, 0.03 * np.exp(3 * off))           # errors grow with |ln share|
    sig = [{"length_mm": 50.0, "span_mm": 50.0, "rims": 2, "length_share": float(s)} for s in share]
    cal = intervals.Intervals("scaled2", 0.9, {}, 0.3)
    known_extent.fit_known(cal, true, est, sig, extra=known_extent.KNOWN_EXTRA["K1"])
    assert cal.known["features"][-1] == "share_off"
    near = cal.quantiles(0.7, {**sig[0], "length_share": 1.0, "extent": "known"})
    far = cal.quantiles(0.7, {**sig[0], "length_share": 2.0, "extent": "known"})
    # 8 times as wide in truth; each end's scale is fitted to its side's residuals with the other side's at 0,
    # which about halves the slope it finds (the two-sided scale, decision record 0158)
    assert far[1] - far[0] > 2 * (near[1] - near[0])
    same = intervals.Intervals("scaled2", 0.9, {}, 0.3)
    known_extent.fit_known(same, true, est, sig)                   # K0: the share unseen, one interval for both
    assert same.quantiles(0.7, {**sig[0], "length_share": 2.0, "extent": "known"}) == \
        same.quantiles(0.7, {**sig[0], "length_share": 1.0, "extent": "known"})
    with pytest.raises(ValueError, match="no scale for the known extent's features"):
        known_extent.fit_known(intervals.Intervals("length", 0.9, {}, 0.3), true, est, sig, extra=("share_off",))


def test_the_review_score_rule_prefers_precision_among_those_that_catch(calibrate_intervals):
    script = calibrate_intervals
    cells = ["V_real gca00020", "V_real gca00070", "V_wide"]

    def review(recalls, precisions):
        return 0.2, {c: {"recall": r, "precision": p} for c, r, p in zip(cells, recalls, precisions)}

    reviews = {"width": review((0.8, 0.75, 0.8), (0.32, 0.5, 0.1)),
               "reach": review((0.8, 0.74, 0.9), (0.6, 0.6, 0.6)),       # misses the recall on gca00070
               "drop": review((0.8, 0.75, 0.8), (0.33, 0.4, 0.1))}
    assert script.choose_review(reviews, cells) == "drop"                 # 33 % over width's 32 %
    reviews["drop"] = review((0.8, 0.75, 0.8), (0.32, 0.9, 0.1))          # a tie in the lower precision
    assert script.choose_review(reviews, cells) == "width"
    none = {"width": review((0.6, 0.7, 0.8), (0.5,) * 3), "reach": review((0.7, 0.72, 0.9), (0.1,) * 3)}
    assert script.choose_review(none, cells) == "reach"                   # none catches: the higher lowest recall


def test_the_known_length_estimates_carry_the_share_known_length_gives(calibrate_intervals):
    script = calibrate_intervals
    import pandas as pd

    df = pd.DataFrame({"span_mm": [30.0, 66.0], "segment_mm": [60.0, 60.0], "length_mm": [30.0, 70.0],
                       "rims": [2, 2], "estimate": [0.9, 0.8]})
    sig = script.known_signals(df)
    est = Estimate(0.9, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"length_mm": 30.0, "span_mm": 30.0})
    known_extent.known_length(est, 60.0)
    assert sig[0]["length_share"] == est.signals["length_share"] == 0.5 and sig[1]["length_share"] == 1.1
    assert list(script.known_estimates(df)) == [pytest.approx(0.45), 0.8]
