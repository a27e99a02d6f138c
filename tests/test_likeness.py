"""A group of its own for the estimates that look like the paper's colons (decision record 0170)."""

import json

import numpy as np
import pandas as pd
import pytest

from colonbench.completion import calfile, conformal, intervals, likeness
from colonbench.errors import InputError

SCHEME = "like50+binned-colon-novel"


def crossed(n: int = 200):
    """Estimates at 0.5 of two kinds the network's self-disagreement tells apart (``spread`` 0: paper-like, 0.02:
    not), every other signal the same but the line's length: the paper-like kind is off by +-0.01 on a 40 mm line and
    +-0.2 on an 80 mm one, the other kind the other way round (signs alternating). One log-linear scale cannot follow
    a length effect whose sign turns with the kind; a group per kind follows it exactly."""
    k = np.arange(n)
    like, long = k < n // 2, (k // 2) % 2 == 1
    m = np.where(like == long, 0.2, 0.01)
    sign = np.where(k % 2 == 0, 1.0, -1.0)
    sig = [{"length_mm": 80.0 if lo else 40.0, "span_mm": 80.0 if lo else 40.0, "rims": 2,
            "spread": 0.0 if li else 0.02} for li, lo in zip(like, long)]
    return 0.5 + sign * m, np.full(n, 0.5), sig, like


def test_each_kind_gets_its_own_exact_interval_where_one_scale_cannot():
    """Within a kind the fitted scale is its residuals' size plus the floor exactly (two line lengths, two values of
    log(m + 0.005)), each length falls in a band of its own, and the band's quantiles give +-m: every truth inside,
    at the narrowest interval that holds them. One scale over both kinds (``scaled-colon-novel``) fits no length
    effect at all (the two cancel), and gives every estimate +-0.2."""
    true, est, sig, like = crossed()
    w = np.full(len(true), 1.0 / len(true))
    cal = likeness.fit(true, est, sig, SCHEME, 0.3, 0.9, w, None, like)
    assert [intervals.looks_like(cal.like, 0.5, s) for s in sig] == list(like)
    short_like, long_like, short_other = sig[0], sig[2], sig[-4]
    assert (short_like["length_mm"], long_like["length_mm"], short_other["length_mm"]) == (40.0, 80.0, 40.0)
    assert cal.interval(0.5, short_like) == (pytest.approx(0.49), pytest.approx(0.51))
    assert cal.interval(0.5, long_like) == (pytest.approx(0.3), pytest.approx(0.7))
    assert cal.interval(0.5, short_other) == (pytest.approx(0.3), pytest.approx(0.7))
    pooled = intervals.fit(true, est, sig, "scaled-colon-novel", 0.3, weights=w)      # one scale, one quantile
    assert pooled.interval(0.5, short_like) == (pytest.approx(0.3), pytest.approx(0.7))
    back = intervals.Intervals(**json.loads(json.dumps(cal.to_json())))
    assert back.like == cal.like and [back.interval(0.5, s) for s in sig] == [cal.interval(0.5, s) for s in sig]
    assert "like" not in pooled.to_json()          # a calibration without the groups writes no classifier


def test_the_classifier_routes_each_estimate_and_a_missing_group_falls_back_to_all():
    """A calibration made by hand: groups of +-0.02 (``like=1``), +-0.2 (``like=0``) and +-0.3 (``all``); log odds
    ``1 - 10 * (10 spread)``: spread 0 is a 73 % chance (``like=1``), spread 0.02 a 27 % one (``like=0``)."""
    groups = {"all": {"low": -0.3, "high": 0.3, "n": 100}, "like=1": {"low": -0.02, "high": 0.02, "n": 50},
              "like=0": {"low": -0.2, "high": 0.2, "n": 50}}
    like = {"features": ["one", "spread"], "ranges": [[1.0, 1.0], [0.0, 1.0]], "weights": [1.0, -10.0],
            "threshold": 0.5}
    cal = intervals.Intervals("like50+binned-colon-novel", 0.9, groups, 0.5, like=like)
    assert cal.interval(0.5, {"spread": 0.0}) == (pytest.approx(0.48), pytest.approx(0.52))
    assert cal.interval(0.5, {"spread": 0.02}) == (pytest.approx(0.3), pytest.approx(0.7))
    without = intervals.Intervals("like50+binned-colon-novel", 0.9, {k: v for k, v in groups.items() if k != "like=1"},
                                  0.5, like=like)
    assert without.interval(0.5, {"spread": 0.0}) == (pytest.approx(0.2), pytest.approx(0.8))
    higher = intervals.Intervals("like80+binned-colon-novel", 0.9, groups, 0.5, like={**like, "threshold": 0.8})
    assert higher.interval(0.5, {"spread": 0.0}) == (pytest.approx(0.3), pytest.approx(0.7))    # 73 % < 80 %
    with pytest.raises(InputError, match="clash"):
        intervals.Intervals("like50+binned-colon-novel", 0.9, groups, 0.5)              # no classifier
    with pytest.raises(InputError, match="clash"):
        intervals.Intervals("binned-colon-novel", 0.9, groups, 0.5, like=like)           # a classifier, no groups
    with pytest.raises(InputError, match="clash"):
        intervals.Intervals("like50+binned-colon-novel", 0.9, groups, 0.5, like={**like, "threshold": 1.0})
    for name in ("like00+binned-colon-novel", "like5+binned-colon-novel", "like+binned-colon-novel"):  # misnamed
        for with_like in ({}, like):
            with pytest.raises(InputError, match="named like<NN>"):
                intervals.Intervals(name, 0.9, groups, 0.5, like=with_like)
    # one short, reversed, not a pair, flat, not numbers, not finite; a classifier that is not an object
    for ranges in ([[1.0, 1.0]], [[1.0, 1.0], [1.0, 0.0]], [[1.0, 1.0], [0.0]], [1.0, 1.0], [["a", "b"], ["c", "d"]],
                   [[1.0, 1.0], [0.0, float("nan")]], "ab"):
        with pytest.raises(InputError, match="ranges as"):
            intervals.Intervals("like50+binned-colon-novel", 0.9, groups, 0.5, like={**like, "ranges": ranges})
    with pytest.raises(InputError, match="ranges as"):
        intervals.Intervals("like50+binned-colon-novel", 0.9, groups, 0.5, like=[like])
    # a threshold in a string, weights not numbers or not finite, a feature the estimate's features do not know
    for bad in ({"threshold": "0.5"}, {"threshold": True}, {"weights": "ab"}, {"weights": [1.0, float("nan")]},
                {"features": ["one", "colour"]}, {"features": "ab"}):
        with pytest.raises(InputError, match="ranges as"):
            intervals.Intervals("like50+binned-colon-novel", 0.9, groups, 0.5, like={**like, **bad})


def test_a_calibration_file_colonbench_cannot_read_is_refused_in_one_line(tmp_path):
    """A model's calibration file cut short, with a field it does not know or lacks, with a field of the wrong type,
    with a classifier whose ranges clash, or not a JSON object, is refused with an InputError naming the file, what is
    wrong and the way out, not a traceback from json or the dataclass; a good one loads."""
    model = tmp_path / "mine.safetensors"
    cal = intervals.Intervals("like50+binned-colon-novel", 0.9, {"all": {"low": -0.2, "high": 0.2, "n": 100}}, 0.5,
                              like={"features": ["one"], "ranges": [[1.0, 1.0]], "weights": [0.0], "threshold": 0.5})
    text = json.dumps(cal.to_json())
    path = calfile.path_for(model)
    for bad, why in ((text[: len(text) // 2], "Expecting|Unterminated"),
                     (json.dumps({**cal.to_json(), "colour": 1}), "unknown fields: colour"),
                     (text.replace('"ranges": [[1.0, 1.0]]', '"ranges": []'), "clash"),
                     (json.dumps([cal.to_json()]), "a JSON list, not an object"),
                     (json.dumps({**cal.to_json(), "source": "mine"}), "'source' is not an object"),
                     (json.dumps({k: v for k, v in cal.to_json().items() if k != "level"}), "missing fields: level"),
                     (json.dumps({**cal.to_json(), "scheme": None}), "'scheme' is not a string"),
                     (json.dumps({**cal.to_json(), "level": True}), "'level' is not a number")):
        path.write_text(bad)
        with pytest.raises(InputError, match=f"mine.intervals.json is not a calibration colonbench can read .*({why})"
                                             ".*calibrate_intervals.py --model"):
            calfile.load(model, None)
    path.write_text(text)
    assert calfile.load(model, None).like == cal.like


def test_a_group_is_fitted_as_its_scheme_fits_those_estimates_alone_with_the_whole_fits_weights():
    """With colon weights and the shift term: the ``like=1`` group is exactly what the scheme fits on the paper-like
    estimates alone with their weights and colons; a kind too small in effect (10 estimates, under MIN_GROUP) gets
    no group, and its estimates the pooled group ``all``, the scheme's own fit on all."""
    true, est, sig, like = crossed()
    colons = np.arange(len(true)) // 10
    w = np.full(len(true), 1.0 / len(true))
    scheme = "like50+binned-colon-novel-shift"
    cal = likeness.fit(true, est, sig, scheme, 0.3, 0.9, w, colons, like)
    alone = intervals.fit(true[like], est[like], [s for s, k in zip(sig, like) if k], "binned-colon-novel-shift", 0.3,
                          weights=w[like], colons=colons[like])
    assert cal.groups["like=1"] == alone.groups["all"]
    keep = np.r_[np.arange(10), np.arange(100, 200)]
    few = likeness.fit(true[keep], est[keep], [sig[k] for k in keep], scheme, 0.3, 0.9, w[keep], colons[keep],
                       like[keep])
    assert "like=1" not in few.groups and "like=0" in few.groups
    pooled = intervals.fit(true[keep], est[keep], [sig[k] for k in keep], "binned-colon-novel-shift", 0.3,
                           weights=w[keep], colons=colons[keep])
    assert few.groups["all"] == pooled.groups["all"]
    assert few.interval(0.5, sig[0]) == pooled.interval(0.5, sig[0])


def test_likeness_schemes_are_named_and_fitted_only_with_both_kinds_on_a_scaled_scheme():
    assert likeness.split_scheme("like80+binned-colon-novel-depth-shift") == (0.8, "binned-colon-novel-depth-shift")
    assert likeness.split_scheme("binned-colon-novel-depth-shift") is None
    assert likeness.split_scheme("like00+binned-colon-novel") is None                # a chance of 0 groups nothing
    assert likeness.base("like80+binned-colon-novel-depth-shift") == "binned-colon-novel-depth-shift"
    assert likeness.base("binned-colon-novel-depth-shift") == "binned-colon-novel-depth-shift"
    assert intervals.scale_features("like80+binned-colon-novel-depth-shift") == \
        intervals.scale_features("binned-colon-novel-depth-shift")
    true, est, sig, like = crossed(80)
    w = np.full(80, 1 / 80)
    with pytest.raises(ValueError, match="not a likeness scheme"):
        likeness.fit(true, est, sig, "binned-colon-novel", 0.3, 0.9, w, None, like)
    with pytest.raises(ValueError, match="paper-like set and of others"):
        likeness.fit(true, est, sig, SCHEME, 0.3, 0.9, w, None, np.ones(80, bool))
    with pytest.raises(ValueError, match="scaled scheme"):
        likeness.fit(true, est, sig, "like50+marginal", 0.3, 0.9, w, None, like)
    with pytest.raises(ValueError, match="scaled scheme"):
        likeness.fit(true, est, sig, "like50+like80+binned-colon-novel", 0.3, 0.9, w, None, like)
    with pytest.raises(ValueError, match="likeness.fit"):
        intervals.fit(true, est, sig, SCHEME, 0.3, weights=w)


def test_the_calibration_script_tells_the_classifier_which_estimates_are_paper_like(calibrate_intervals):
    """``fit_scheme`` labels an estimate paper-like by its set (``V_paper``), and fits any other scheme as
    :func:`intervals.fit` does."""
    true, est, sig, like = crossed(120)
    part = pd.DataFrame({"true": true, "set": np.where(like, "V_paper", "V_real")})
    w = np.full(120, 1 / 120)
    cal = calibrate_intervals.fit_scheme(part, est, sig, SCHEME, 0.3, 0.9, w, None)
    assert [intervals.looks_like(cal.like, 0.5, s) for s in sig] == list(like)
    plain = calibrate_intervals.fit_scheme(part, est, sig, "binned-colon-novel", 0.3, 0.9, w, None)
    assert plain.to_json() == intervals.fit(true, est, sig, "binned-colon-novel", 0.3, weights=w).to_json()



def test_a_band_edge_lies_between_distinct_values_even_where_the_quantile_falls_in_a_tie():
    """conformal.weighted_quantile(between=True): where the quantile falls within a run of tied values, the cut lies
    midway to the next distinct value, so an estimate at the tied value, moved by another machine's last bits, keeps
    its band (on one machine a cut on the tie put a test estimate 1e-16 above it into an empty band)."""
    v = np.array([-4.2] * 50 + [-1.6] * 50)
    w = np.full(100, 0.01)
    assert conformal.weighted_quantile(v, w, 0.25, between=True) == pytest.approx(-2.9)
    assert conformal.weighted_quantile(v + np.r_[np.zeros(99), 1e-15], w, 0.25, between=True) == pytest.approx(-2.9)
    top = conformal.weighted_quantile(v, w, 0.75, between=True)               # no larger value: just above the tie
    assert -1.6 < top < -1.6 + 1e-8
    edges = [conformal.weighted_quantile(v, w, q, between=True) for q in (0.25, 0.5, 0.75)]
    moved = np.array([-4.2 * (1 + 1e-16), -4.2 * (1 - 1e-15), -1.6 * (1 + 1e-15), -1.6 * (1 - 1e-15)])
    assert edges[:2] == [pytest.approx(-2.9)] * 2                           # the median falls in the lower tie too
    assert conformal.band_of(edges, moved).tolist() == conformal.band_of(edges, [-4.2, -4.2, -1.6, -1.6]).tolist() \
        == [0, 0, 2, 2]
    assert conformal.weighted_quantile([0.5, 1.5, 2.5, 3.5], [1, 1, 1, 1], 0.25, between=True) == 1.0
