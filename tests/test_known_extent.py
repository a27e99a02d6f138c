"""Decision record 0168: the known extent's interval with a group of its own for the estimates a given length
shortened (colonbench.completion.known_extent), and the rule in scripts/calibrate_intervals.py that chooses it."""

import json

import numpy as np
import pandas as pd
import pytest

from colonbench.completion import conformal, intervals, known_extent
from colonbench.estimate import Estimate


def _split_data(n_short=120, n_full=300, seed=3):
    """Residuals of two kinds: the shortened estimates (length_share 0.6) off by +0.1 +- 0.05, the rest by 0 +- 0.01."""
    rng = np.random.default_rng(seed)
    short = np.r_[np.ones(n_short, bool), np.zeros(n_full, bool)]
    est = rng.uniform(0.4, 0.8, len(short))
    true = est + np.where(short, rng.normal(0.1, 0.05, len(short)), rng.normal(0.0, 0.01, len(short)))
    sig = [{"length_share": 0.6 if s else 1.0} for s in short]
    return true, est, sig, short


def test_the_shortened_estimates_get_the_conformal_quantiles_of_their_own_residuals():
    true, est, sig, short = _split_data()
    cal = intervals.Intervals("marginal", 0.9, {}, 0.3)
    known_extent.fit_known(cal, true, est, sig, short=True)
    residual = true - est
    ends = lambda g: (g["low"], g["high"])                          # noqa: E731
    assert ends(cal.known) == conformal.conformal_quantiles(residual, 0.9)                 # all: a map's planes
    assert ends(cal.known["short"]) == conformal.conformal_quantiles(residual[short], 0.9)
    assert ends(cal.known["full"]) == conformal.conformal_quantiles(residual[~short], 0.9)
    assert (cal.known["n"], cal.known["short"]["n"], cal.known["full"]["n"]) == (420, 120, 300)
    given = {"extent": "known"}
    assert cal.quantiles(0.7, {**given, "length_share": 0.6}) == ends(cal.known["short"])
    assert cal.quantiles(0.7, {**given, "length_share": 0.95}) == ends(cal.known["full"])    # nothing scaled
    assert cal.quantiles(0.7, given) == ends(cal.known)                 # a map's planes, no length given
    # each group holds its own kind: the pooled interval would miss most shortened estimates' truths
    lo, hi = np.array([cal.interval(e, {**s, "extent": "known"}) for e, s in zip(est, sig)]).T
    inside = (lo <= true) & (true <= hi)
    assert inside[short].mean() >= 0.85 and inside[~short].mean() >= 0.85
    pooled = intervals.Intervals("marginal", 0.9, {}, 0.3)
    known_extent.fit_known(pooled, true, est, sig)
    assert "short" not in pooled.known and ends(pooled.known) == ends(cal.known)
    lo, hi = np.array([pooled.interval(e, {**s, "extent": "known"}) for e, s in zip(est, sig)]).T
    assert ((lo <= true) & (true <= hi))[short].mean() < 0.85


def test_the_short_group_goes_through_the_calibration_file_and_into_an_estimate(tmp_path):
    true, est, sig, short = _split_data()
    cal = intervals.Intervals("marginal", 0.9, {"all": {"low": -0.3, "high": 0.3, "n": 400}}, 0.9)
    known_extent.fit_known(cal, true, est, sig, short=True)
    path = tmp_path / "m.intervals.json"
    path.write_text(json.dumps(cal.to_json()))
    back = intervals.Intervals(**json.loads(path.read_text()))
    assert back.known == cal.known
    shortened = Estimate(0.8, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"span_mm": 30.0})
    known_extent.known_length(shortened, 50.0)           # spans 0.6 of it: scaled to 0.48
    back.apply(shortened)
    assert shortened.coverage == pytest.approx(0.48)
    assert shortened.coverage_interval == pytest.approx((0.48 + cal.known["short"]["low"],
                                                         0.48 + cal.known["short"]["high"]))


def test_each_group_of_a_binned_colon_weighted_scheme_is_fitted_on_its_own_estimates():
    """The shipped kind of scheme (scaled, binned, colon-weighted, with the shift term): the shortened group's
    features, weights and colons are its own estimates' (its ranges, band counts and size), not the pool's."""
    rng = np.random.default_rng(5)
    n = 600
    short = rng.uniform(size=n) < 0.3
    share = np.where(short, rng.uniform(0.5, 0.85, n), rng.uniform(0.9, 1.1, n))
    length = np.where(short, rng.uniform(20, 40, n), rng.uniform(40, 70, n))
    sig = [{"length_mm": float(l), "span_mm": float(l), "rims": 2, "length_share": round(float(s), 4)}
           for l, s in zip(length, share)]
    est = rng.uniform(0.4, 0.9, n)
    true = est + rng.normal(0, 0.02, n) + np.where(short, 0.05, 0.0)
    colons = np.arange(n) % 12
    weights = np.full(n, 1.0 / n)
    cal = intervals.Intervals("binned-colon-novel-depth-shift", 0.9, {}, 0.3)
    known_extent.fit_known(cal, true, est, sig, weights, colons, short=True)
    k, names = cal.known, cal.known["features"]
    assert (k["n"], k["short"]["n"], k["full"]["n"]) == (n, int(short.sum()), int((~short).sum()))
    at = names.index("length")
    assert k["short"]["ranges"][at] == pytest.approx([length[short].min() / 60, length[short].max() / 60])
    assert k["full"]["ranges"][at] == pytest.approx([length[~short].min() / 60, length[~short].max() / 60])
    assert sum(k["short"]["band_n"]) == short.sum() and sum(k["full"]["band_n"]) == (~short).sum()
    # the shortened estimates read low by 5 points: their own group's interval reaches higher
    s0 = {**sig[int(np.flatnonzero(short)[0])], "extent": "known"}
    assert cal.quantiles(0.7, s0) == intervals._scale(k["short"], 0.7, s0)
    assert cal.quantiles(0.7, s0)[1] > intervals._scale(k, 0.7, s0)[1]


def test_a_split_needs_both_kinds_of_estimate_and_their_signals():
    true, est, sig, short = _split_data()
    cal = intervals.Intervals("marginal", 0.9, {}, 0.3)
    with pytest.raises(ValueError, match="some of each kind"):
        known_extent.fit_known(cal, true[~short], est[~short], [s for s, k in zip(sig, short) if not k], short=True)
    with pytest.raises(ValueError, match="signals"):
        known_extent.fit_known(cal, true, est, None, short=True)
    assert list(known_extent.shortened([{"length_share": 0.8999}, {"length_share": 0.9}, {}])) == [True, False, False]


def _held(lowest: float, width: float = 0.2) -> pd.DataFrame:
    """Held-out intervals of one candidate: gca00020 holds ``lowest`` % at 0 mm (1000 estimates), every other cell
    90 %."""
    rows = []
    for set_, cell in (("V_real", "V_real gca00020"), ("V_real", "V_real gca00070"), ("V_wide", "V_wide"),
                       ("V_paper", "V_paper")):
        for noise in (0.0, 0.5):
            share = lowest if (cell == "V_real gca00020" and noise == 0.0) else 90.0
            k = int(round(10 * share))
            rows += [{"set": set_, "cell": cell, "noise_mm": noise, "inside": i < k, "width": width}
                     for i in range(1000)]
    return pd.DataFrame(rows)


def test_the_known_extent_in_use_stays_unless_beaten_by_more_than_the_margin(calibrate_intervals):
    ci = calibrate_intervals
    assert ci.KNOWN_INCUMBENT == "K0" and ci.KNOWN_MARGIN == 2.1
    # a gain of the margin (72.2 - 70.1 = 2.1000000000000085 in floats) keeps K0 though 0161's keys rank K2
    # first; a little more replaces it
    assert 72.2 - 70.1 > ci.KNOWN_MARGIN
    assert ci.choose_known({"K0": _held(70.1), "K2": _held(72.2)}, 0.9)[0] == "K0"
    assert ci.choose_known({"K0": _held(70.1), "K2": _held(72.4)}, 0.9)[0] == "K2"
    # a cell at or above 85 % counts as 85: from 84 to 90 is a gain of 1 point, kept
    assert ci.choose_known({"K0": _held(84.0), "K2": _held(90.0, width=0.1)}, 0.9)[0] == "K0"
    # every cell within 85-95 %: the narrowest, without the margin
    assert ci.choose_known({"K0": _held(88.0), "K2": _held(89.0, width=0.1)}, 0.9)[0] == "K2"


def test_a_share_just_under_the_cut_is_decided_once_on_the_share_as_stored():
    """A span of 89.996 mm of 100: the share 0.89996 is stored as 0.9 (4 decimals), so the estimate is left as it is
    and gets the group of those left, as the calibration counts it; one of 89.9 mm is shortened, and gets theirs."""
    cal = intervals.Intervals("marginal", 0.9, {}, 0.3,
                              known={"low": -0.1, "high": 0.1, "n": 9, "short": {"low": -0.2, "high": 0.3, "n": 3},
                                     "full": {"low": -0.05, "high": 0.05, "n": 6}})
    for span, coverage, ends in ((89.996, 0.8, (-0.05, 0.05)), (89.9, 0.8 * 0.899, (-0.2, 0.3))):
        est = Estimate(0.8, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"span_mm": span})
        known_extent.known_length(est, 100.0)
        assert est.coverage == pytest.approx(coverage)
        assert cal.quantiles(est.coverage, est.signals) == ends
        assert known_extent.shortened([est.signals])[0] == (span < 89.99)
