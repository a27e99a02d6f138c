"""A group of its own for the estimates that look like the paper's colons (decision record 0170)."""

import json

import numpy as np
import pandas as pd
import pytest

from colonbench.completion import intervals, likeness

SCHEME = "like50+binned-colon-novel"


def population(n_like: int, n_other: int):
    """Estimates at 0.5 of two kinds the network's self-disagreement tells apart (``spread`` 0 or 0.02), every other
    signal the same: the paper-like ones off by exactly +-0.02, the others by +-0.2, signs alternating."""
    n = n_like + n_other
    like = np.arange(n) < n_like
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    m = np.where(like, 0.02, 0.2)
    sig = [{"length_mm": 60.0, "span_mm": 60.0, "rims": 2, "spread": 0.0 if k else 0.02} for k in like]
    return 0.5 + sign * m, np.full(n, 0.5), sig, like


def test_each_group_gets_its_own_quantiles_and_the_file_keeps_the_classifier():
    """Within a group every feature is the same, so its fitted scale is its residuals' size plus the floor exactly,
    and its interval is +-0.02 or +-0.2: each holds every truth of its own kind. The classifier sorts every estimate
    into its kind; the calibration comes back from its JSON the same."""
    true, est, sig, like = population(100, 100)
    w = np.full(len(true), 1.0 / len(true))
    cal = likeness.fit(true, est, sig, SCHEME, 0.3, 0.9, w, None, like)
    assert cal.scheme == SCHEME and cal.like["threshold"] == 0.5
    assert cal.like["features"] == list(intervals.scale_features(SCHEME))
    assert {"all", "like=1", "like=0"} <= set(cal.groups)
    assert [intervals.looks_like(cal.like, 0.5, s) for s in sig] == list(like)
    assert cal.interval(0.5, sig[0]) == (pytest.approx(0.48), pytest.approx(0.52))
    assert cal.interval(0.5, sig[-1]) == (pytest.approx(0.3), pytest.approx(0.7))
    pooled = intervals.fit(true, est, sig, "binned-colon-novel", 0.3, weights=w)
    back = intervals.Intervals(**json.loads(json.dumps(cal.to_json())))
    assert back.like == cal.like
    assert [back.interval(0.5, s) for s in sig[::17]] == [cal.interval(0.5, s) for s in sig[::17]]
    assert "like" not in pooled.to_json()          # a calibration without the groups writes no classifier


def test_the_groups_part_what_one_quantile_pools():
    """One quantile over both kinds (``scaled-colon-novel``): the scale fits each kind's size exactly (``m + 0.005``),
    so the scaled residuals are +-0.8 (paper-like) and +-0.976 (others), and the 90 % quantile is the others'
    0.2 / 0.205, which widens the paper-like interval to +-0.976 * 0.025 = +-0.0244. Grouped, it is +-0.02."""
    true, est, sig, like = population(100, 100)
    w = np.full(len(true), 1.0 / len(true))
    cal = likeness.fit(true, est, sig, "like80+binned-colon-novel", 0.3, 0.9, w, None, like)
    pooled = intervals.fit(true, est, sig, "scaled-colon-novel", 0.3, weights=w)
    assert np.diff(cal.interval(0.5, sig[0]))[0] == pytest.approx(0.04)
    assert np.diff(pooled.interval(0.5, sig[0]))[0] == pytest.approx(2 * 0.2 / 0.205 * 0.025)


def test_a_group_too_small_gets_the_pooled_quantiles():
    """Ten paper-like estimates (effective size 10, under MIN_GROUP) get no group of their own: they take the
    pooled group ``all``, fitted as the scheme without the likeness fits it."""
    true, est, sig, like = population(10, 100)
    w = np.full(len(true), 1.0 / len(true))
    cal = likeness.fit(true, est, sig, SCHEME, 0.3, 0.9, w, None, like)
    assert "like=1" not in cal.groups and "like=0" in cal.groups
    pooled = intervals.fit(true, est, sig, "binned-colon-novel", 0.3, weights=w)
    assert cal.interval(0.5, sig[0]) == pooled.interval(0.5, sig[0])


def test_likeness_schemes_are_named_and_fitted_only_with_both_kinds():
    assert likeness.split_scheme("like80+binned-colon-novel-depth-shift") == (0.8, "binned-colon-novel-depth-shift")
    assert likeness.split_scheme("binned-colon-novel-depth-shift") is None
    assert intervals.scale_features("like80+binned-colon-novel-depth-shift") == \
        intervals.scale_features("binned-colon-novel-depth-shift")
    true, est, sig, like = population(40, 40)
    w = np.full(80, 1 / 80)
    with pytest.raises(ValueError, match="not a likeness scheme"):
        likeness.fit(true, est, sig, "binned-colon-novel", 0.3, 0.9, w, None, like)
    with pytest.raises(ValueError, match="paper-like set and of others"):
        likeness.fit(true, est, sig, SCHEME, 0.3, 0.9, w, None, np.ones(80, bool))


def test_the_calibration_script_tells_the_classifier_which_estimates_are_paper_like(calibrate_intervals):
    """``fit_scheme`` labels an estimate paper-like by its set (``V_paper``), and fits any other scheme as
    :func:`intervals.fit` does."""
    true, est, sig, like = population(60, 60)
    part = pd.DataFrame({"true": true, "set": np.where(like, "V_paper", "V_real")})
    w = np.full(120, 1 / 120)
    cal = calibrate_intervals.fit_scheme(part, est, sig, SCHEME, 0.3, 0.9, w, None)
    assert [intervals.looks_like(cal.like, 0.5, s) for s in sig] == list(like)
    plain = calibrate_intervals.fit_scheme(part, est, sig, "binned-colon-novel", 0.3, 0.9, w, None)
    assert plain.to_json() == intervals.fit(true, est, sig, "binned-colon-novel", 0.3, weights=w).to_json()
