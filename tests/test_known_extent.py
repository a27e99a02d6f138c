"""Decision record 0168: the known extent's interval with a group of its own for the estimates a given length
shortened (colonbench.completion.known_extent); tests/test_pair_choice.py tests the rule that chooses it (0172)."""

import json

import numpy as np
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
