"""Decision record 0167: the review by the fitted odds that an estimate is far off (colonbench.completion.review), and
the rule in scripts/calibrate_intervals.py that adopts it."""

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from colonbench.completion import calfile, intervals, known_extent, review
from colonbench.errors import InputError
from colonbench.estimate import Estimate


def test_the_odds_of_an_intercept_alone_are_the_weighted_share_far_off():
    """With the intercept alone (no penalty on it), the fitted log odds are those of the share far off: 30 of 100
    gives ln(0.3 / 0.7); weighing the 30 three times as much gives ln(0.9 / 0.7 * 7 / 9) = ln(90 / 70)."""
    far = np.r_[np.ones(30), np.zeros(70)]
    ones = np.ones((100, 1))
    assert review.fit_odds(ones, far)[0] == pytest.approx(math.log(0.3 / 0.7), abs=1e-4)
    weights = np.r_[np.full(30, 3.0), np.ones(70)]
    assert review.fit_odds(ones, far, weights)[0] == pytest.approx(math.log(90 / 70), abs=1e-4)
    with pytest.raises(ValueError, match="weights"):
        review.fit_odds(ones, far, np.zeros(100))


def test_the_log_odds_keep_each_feature_in_the_range_fitted_on():
    model = {"features": ["one", "length"], "ranges": [[1, 1], [0.5, 1.0]], "weights": [1.0, -2.0]}
    assert intervals.linear_score(model, np.array([1.0, 0.75])) == pytest.approx(-0.5)
    assert intervals.linear_score(model, np.array([1.0, 3.0])) == pytest.approx(-1.0)      # clipped to 1.0


def _estimate(coverage, length_mm):
    return Estimate(coverage, np.zeros((0, 3)), np.zeros((0, 3)), "m",
                    signals={"rims": 2, "length_mm": length_mm, "span_mm": length_mm, "extent_mm": length_mm + 5})


def test_a_calibration_reviewed_by_odds_flags_where_they_exceed_its_threshold():
    """A short line is far off here (the odds fall with the length): the 30 mm segment's log odds are
    2 - 3 * 0.5 = 0.5 > 0, a 62 % chance, and it is flagged with that chance in its reason; the 60 mm one's are -1,
    and it is not. A calibration reviewed by odds without their fit is refused."""
    odds = {"features": ["one", "length"], "ranges": [[1, 1], [0.1, 2.0]], "weights": [2.0, -3.0]}
    cal = intervals.Intervals("marginal", 0.9, {"all": {"low": -0.1, "high": 0.1, "n": 100}}, 0.0,
                              review_by="odds", review_odds=odds)
    short, full = _estimate(0.8, 30.0), _estimate(0.8, 60.0)
    cal.apply(short), cal.apply(full)
    assert short.review and "a 62.2 % chance" in short.review[0] and "flagged over 50.0 %" in short.review[0]
    assert full.review == []
    assert short.coverage_interval == pytest.approx((0.7, 0.9))
    assert intervals.Intervals(**json.loads(json.dumps(cal.to_json()))).review_odds == odds
    assert "review_odds" not in intervals.Intervals("marginal", 0.9, {}, 0.3).to_json()     # as before odds existed
    with pytest.raises(InputError, match="review_odds"):
        intervals.Intervals("marginal", 0.9, {}, 0.0, review_by="odds")
    with pytest.raises(InputError, match="review_odds"):
        intervals.Intervals("marginal", 0.9, {}, 0.3, review_by_known="odds")
    with pytest.raises(InputError, match="review_by_known"):            # a width threshold read as log odds
        intervals.Intervals("marginal", 0.9, {}, 0.0, review_by="odds", review_odds=odds, review_known=0.2)


def test_a_length_given_keeps_the_known_extents_width_rule_under_odds():
    """With the segments reviewed by odds, a length given is reviewed by its interval's width against review_known:
    the short segment, far off by the odds, is not flagged where its known-extent interval is 10 points wide (under
    15), and is where the threshold is 5."""
    odds = {"features": ["one", "length"], "ranges": [[1, 1], [0.1, 2.0]], "weights": [2.0, -3.0]}
    groups = {"all": {"low": -0.1, "high": 0.1, "n": 100}}
    for threshold, flagged in ((0.15, False), (0.05, True)):
        cal = intervals.Intervals("marginal", 0.9, groups, 0.0, known={"low": -0.05, "high": 0.05, "n": 100},
                                  review_known=threshold, review_by="odds", review_by_known="width", review_odds=odds)
        est = _estimate(0.8, 30.0)
        known_extent.known_length(est, 30.0)
        cal.apply(est)
        assert est.coverage_interval == pytest.approx((0.75, 0.85))
        assert bool(est.review) == flagged and (not flagged or "10 points wide" in est.review[0])


def _held(informative: bool, seed=5):
    """Held-out rows of two real colons and the widened set: a quarter of each far off; every interval the same, so
    no score of the interval tells them apart; the line's length does where ``informative``."""
    rng = np.random.default_rng(seed)
    rows = []
    for cell, colon_ids in (("V_real gca00020", [900020]), ("V_real gca00070", [900070]), ("V_wide", [1, 2, 3, 4])):
        for colon in colon_ids:
            for i in range(120):
                far = i % 4 == 0
                length = (30.0 if far else 60.0) if informative else float(rng.uniform(30, 60))
                rows.append({"set": cell.split()[0], "cell": cell, "colon": f"{cell.split()[0]}:{colon}",
                             "estimate": 0.8, "estimate_used": 0.8, "true": 0.5 if far else 0.8, "low": 0.6,
                             "high": 0.95, "length_mm": length + rng.normal(0, 2), "span_mm": length,
                             "extent_mm": length + 5, "rims": 2})
    return pd.DataFrame(rows)


def test_the_odds_replace_the_intervals_score_only_where_they_are_right_more_often(calibrate_intervals):
    """odds_rule: where the line's length marks the far-off estimates and the intervals do not, the held-out odds
    catch three in four of them and nothing else (precision 100 % against the width's 25 %): adopted. Where the
    length is noise, they gain nothing: not adopted."""
    ci = calibrate_intervals
    names = ("one", "length")
    for informative, adopted in ((True, True), (False, False)):
        held = _held(informative)
        by, width, report, _ = ci.review_rule(held, "test")
        out = ci.odds_rule(held, names, by, report)
        assert (out is not None) == adopted
        if adopted:
            threshold, odds = out
            assert all(odds[c]["precision"] == 1.0 and odds[c]["recall"] >= 0.75 for c in ci.review_cells(held))
            assert min(report[c]["precision"] for c in ci.review_cells(held)) == pytest.approx(0.25)


def test_the_model_card_shows_a_binned_scheme_per_band_and_the_review_odds(tmp_path, monkeypatch):
    """scripts/model_card.py's interval section: a binned calibration's four bands, each its own quantiles, and the
    review's odds with their threshold said as a chance (log odds -1.38: over 20 %)."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "scripts"))
    import model_card

    rng = np.random.default_rng(2)
    n = 240
    est = rng.uniform(0.4, 0.95, n)
    sig = [{"rims": 2, "length_mm": float(v), "span_mm": float(v), "extent_mm": float(v) + 5, "spread": 0.02,
            "radius_mm": 12.0} for v in rng.uniform(30, 70, n)]
    true = est - 0.05 * np.abs(rng.normal(size=n)) * np.array([s["length_mm"] for s in sig]) / 50
    cal = intervals.fit(true, est, sig, "binned-colon-novel-shift", -1.38, weights=np.ones(n) / n,
                        colons=np.arange(n) % 6)
    cal.review_by = "odds"
    cal.review_odds = {"features": ["one", "length"], "ranges": [[1, 1], [0.5, 1.2]], "weights": [1.0, -2.0]}
    cal.source = {"id": "binned-test", "steps": "steps=10", "estimates": n}
    model = tmp_path / "m.safetensors"
    calfile.path_for(model).write_text(json.dumps(cal.to_json()))
    text = "\n".join(model_card.intervals_rows(model))
    group = cal.groups["all"]
    assert len(group["band_low"]) == 4 and f"{group['band_low'][3]:+.2f} s to {group['band_high'][3]:+.2f} s" in text
    assert "per band of log s (cut at " in text and "a chance over 20.1 % that the estimate is off" in text
    row = "| review: odds of off by > 15 points | 240 | flagged above log odds -1.38 | one +1.00, length -2.00 |"
    assert row in text


def test_the_odds_must_gain_more_than_the_margin_at_the_same_catch(calibrate_intervals, monkeypatch):
    """odds_rule on given held-out reports: a gain of exactly 3 points (0.333 against 0.303, as the file rounds them)
    is not more than ODDS_GAIN; 3.1 is; and a gain of 10 with a cell caught under 75 % is not adopted."""
    ci = calibrate_intervals
    held = pd.DataFrame({"cell": ["V_real gca00020", "V_real gca00070", "V_wide"]})
    base = {c: {"precision": 0.303, "recall": 0.8} for c in held["cell"]}

    def with_odds(precision, recall):
        report = {c: {"precision": precision, "recall": recall, "flagged": 0.5, "off": 40} for c in held["cell"]}
        monkeypatch.setattr(ci, "held_odds", lambda h, names: pd.Series(0.0, index=h.index))
        monkeypatch.setattr(ci, "review_width", lambda h, by="width", score=None: (-1.0, report))
        return ci.odds_rule(held, ("one",), "reach", base)

    assert with_odds(0.333, 0.8) is None
    assert with_odds(0.334, 0.8) is not None
    assert with_odds(0.403, 0.74) is None
