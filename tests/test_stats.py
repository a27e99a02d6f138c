"""Bootstrap intervals, paired comparisons and breakdowns (colonbench.benchmark.stats) on numbers with known answers."""

import numpy as np
import pandas as pd
import pytest
from scipy.stats import norm

from colonbench.benchmark import stats
from colonbench.benchmark.stats import (BREAKDOWNS, best_baseline, bootstrap_ci, breakdown, coverage_bins,
                                        mae_interval, paired_against, paired_difference)
from colonbench.errors import InputError


def test_constants():
    assert coverage_bins == (0.0, 0.5, 0.7, 0.8, 0.9, 1.0)
    assert BREAKDOWNS == ("hole_model", "length_mm", "true_coverage", "unseen_end", "noise_mm")


def test_bootstrap_ci_constant_and_too_few_values():
    assert bootstrap_ci(np.full(50, 2.5)) == (2.5, 2.5)
    for few in ([], [4.0], [np.nan, 3.0, np.nan]):
        assert np.isnan(bootstrap_ci(few)).all()


def test_bootstrap_ci_seeded_and_nan_free():
    x = np.random.default_rng(11).normal(10.0, 2.0, 200)
    a = bootstrap_ci(x, seed=3)
    assert bootstrap_ci(x, seed=3) == a
    assert bootstrap_ci(x, seed=4) != a
    assert a[0] < x.mean() < a[1]
    # normal theory: the half width is about 1.96 sd / sqrt(n) = 0.277
    assert (a[1] - a[0]) / 2 == pytest.approx(1.96 * x.std() / np.sqrt(len(x)), rel=0.15)
    assert bootstrap_ci(np.r_[np.nan, x, np.nan], seed=3) == a  # NaNs dropped before drawing
    narrow = bootstrap_ci(x, level=0.5, seed=3)
    assert a[0] < narrow[0] < narrow[1] < a[1]


def test_bootstrap_ci_statistic_without_axis_and_chunks(monkeypatch):
    x = np.random.default_rng(5).exponential(1.0, 300)
    # a statistic that takes no axis is applied row by row to the same draws
    assert bootstrap_ci(x, lambda v: float(np.median(v)), resamples=300, seed=2) == \
        bootstrap_ci(x, np.median, resamples=300, seed=2)
    whole = bootstrap_ci(x, resamples=300, seed=2)
    monkeypatch.setattr(stats, "_CHUNK_ELEMENTS", 7 * len(x))  # 43 chunks of 7 resamples (the last one 6)
    assert bootstrap_ci(x, resamples=300, seed=2) == pytest.approx(whole)


def test_bootstrap_ci_bad_input():
    for kwargs in ({"level": 1.5}, {"level": 0.0}, {"resamples": 0}, {"resamples": 2.5}, {"seed": -1}):
        with pytest.raises(InputError):
            bootstrap_ci([1.0, 2.0, 3.0], **kwargs)
    with pytest.raises(InputError):
        bootstrap_ci(np.ones((3, 2)))


def test_mae_interval_by_hand():
    e = [0.01, -0.03, 0.02, np.nan, -0.05, 0.04]
    r = mae_interval(e, seed=1)
    assert r["mae"] == pytest.approx(3.0, abs=1e-12)  # 100 * mean(0.01, 0.03, 0.02, 0.05, 0.04)
    assert r["mae"] == 100 * np.mean(np.abs([0.01, -0.03, 0.02, -0.05, 0.04]))
    assert r["mae_lo"] <= r["mae"] <= r["mae_hi"]
    assert 1.0 <= r["mae_lo"] and r["mae_hi"] <= 5.0  # within the range of the |errors|
    assert mae_interval(e, seed=1) == r
    one = mae_interval([np.nan, -0.07])
    assert one["mae"] == pytest.approx(7.0) and np.isnan(one["mae_lo"]) and np.isnan(one["mae_hi"])
    assert all(np.isnan(v) for v in mae_interval([np.nan, np.nan]).values())


def test_mae_interval_covers_the_true_mae():
    mu, sd, n, draws = 0.02, 0.05, 100, 400
    # MAE of a normal error (folded normal mean), in points
    true = 100 * (sd * np.sqrt(2 / np.pi) * np.exp(-mu ** 2 / (2 * sd ** 2)) + mu * (1 - 2 * norm.cdf(-mu / sd)))
    big = np.random.default_rng(99).normal(mu, sd, 1_000_000)
    assert 100 * np.abs(big).mean() == pytest.approx(true, rel=3e-3)  # the closed form is right
    errors = np.random.default_rng(2024).normal(mu, sd, (draws, n))
    hits = 0
    for k, e in enumerate(errors):
        r = mae_interval(e, resamples=500, seed=k)
        hits += r["mae_lo"] <= true <= r["mae_hi"]
    assert 0.90 <= hits / draws <= 0.985


def test_paired_difference_by_hand():
    b = np.array([0.5, 2.0, 3.25, 7.0])
    r = paired_difference(b + 1, b)
    assert r == {"diff": 1.0, "diff_lo": 1.0, "diff_hi": 1.0, "pairs": 4}
    r = paired_difference([1.0, np.nan, 3.0, 4.0, 5.0], [0.0, 1.0, np.nan, 2.0, 2.0], seed=4)
    assert r["pairs"] == 3 and r["diff"] == pytest.approx(2.0)  # pairs 0, 3, 4: differences 1, 2, 3
    assert 1.0 <= r["diff_lo"] <= 2.0 <= r["diff_hi"] <= 3.0
    assert paired_difference([np.nan], [1.0])["pairs"] == 0
    with pytest.raises(InputError):
        paired_difference([1.0, 2.0], [1.0, 2.0, 3.0])


def _pairs_frame():
    segs = [("s0", 0), ("s0", 1), ("s1", 0), ("s1", 1)]
    errs = {("ref", 0.0): [0.02, -0.04, 0.01, np.nan], ("m", 0.0): [0.05, 0.01, -0.03, 0.02],
            ("ref", 0.5): [0.10, 0.00, -0.02, 0.06], ("m", 0.5): [-0.04, 0.03, 0.05, None]}
    rows = [{"method": m, "shard": s, "index": i, "noise_mm": noise, "coverage_error": e}
            for (m, noise), es in errs.items() for (s, i), e in zip(segs, es) if e is not None]
    return pd.DataFrame(rows)  # m misses (s1, 1) at 0.5 mm; ref has no estimate on (s1, 1) at 0 mm


def test_paired_against_by_hand():
    res = _pairs_frame()
    out = paired_against(res, "ref", seed=7)
    assert list(out.columns) == ["noise_mm", "method", "reference", "diff", "diff_lo", "diff_hi", "pairs"]
    assert out["noise_mm"].tolist() == [0.0, 0.5] and set(out["method"]) == {"m"} and set(out["reference"]) == {"ref"}
    assert out["pairs"].tolist() == [3, 3]
    # points, |m| - |ref|: 0 mm: 5-2, 1-4, 3-1 -> 2/3; 0.5 mm: 4-10, 3-0, 5-2 -> 0
    assert out["diff"].tolist() == pytest.approx([2 / 3, 0.0])
    assert (out["diff_lo"] <= out["diff"]).all() and (out["diff"] <= out["diff_hi"]).all()
    assert out.loc[1, "diff_lo"] >= -6 and out.loc[1, "diff_hi"] <= 3
    # each cell has its own stream: row order and the other cells change nothing
    shuffled = paired_against(res.sample(frac=1, random_state=0), "ref", seed=7)
    pd.testing.assert_frame_equal(shuffled, out)
    alone = paired_against(res[res["noise_mm"] == 0.5], "ref", seed=7)
    pd.testing.assert_frame_equal(alone, out.iloc[[1]].reset_index(drop=True))
    swapped = paired_against(res, "m", seed=7)
    assert swapped["method"].tolist() == ["ref", "ref"] and swapped["diff"].tolist() == pytest.approx([-2 / 3, 0.0])


def test_paired_against_no_reference_and_duplicates():
    res = _pairs_frame()
    empty = paired_against(res, "absent")
    assert empty.empty and list(empty.columns) == ["noise_mm", "method", "reference", "diff", "diff_lo",
                                                   "diff_hi", "pairs"]
    with pytest.raises(InputError):
        paired_against(pd.concat([res, res.iloc[[0]]]), "ref")
    with pytest.raises(InputError):
        paired_against(res.drop(columns="shard"), "ref")


def test_best_baseline():
    rows = [(0.0, "completion", 1.0), (0.0, "unwrap", 4.0), (0.0, "thresholding", 3.0), (0.0, "constant", 9.0),
            (1.0, "completion", 2.0), (1.0, "unwrap", np.nan), (1.0, "thresholding", 8.0), (1.0, "constant", 6.0),
            (2.0, "completion", 2.0), (3.0, "unwrap", np.nan)]
    table = pd.DataFrame(rows, columns=["noise_mm", "method", "coverage_mae"])
    assert best_baseline(table, ["unwrap", "thresholding", "constant"]) == {0.0: "thresholding", 1.0: "constant"}
    assert best_baseline(table, ("unwrap", "thresholding")) == {0.0: "thresholding", 1.0: "thresholding"}
    assert best_baseline(table, "unwrap") == {0.0: "unwrap"}
    assert best_baseline(table, []) == {}


def _breakdown_frame():
    rows = [  # hole model, length, true coverage, coverage error
        ("camera", 50.0, 0.30, 0.01), ("camera", 50.0, 0.50, -0.02), ("camera", 60.0, 0.70, 0.03),
        ("camera+end", 60.0, 0.95, np.nan), ("camera+end", 50.0, 1.00, 0.04), ("camera+end", 60.0, 0.80, -0.06),
        ("camera", 60.0, np.nan, 0.02), ("camera", 50.0, -0.10, 0.05), ("camera+end", 60.0, 1.20, 0.00)]
    one = pd.DataFrame(rows, columns=["hole_model", "length_mm", "true_coverage", "coverage_error"])
    one["shard"], one["index"], one["error"] = "s0", range(len(one)), ""
    return pd.concat([one.assign(method="m", noise_mm=0.5), one.assign(method="m", noise_mm=0.0)], ignore_index=True)


def _cells(out):
    return {(n, g): s for n, g, s in zip(out["noise_mm"], out["group"], out["segments"])}


def test_breakdown_groups_and_counts():
    res = _breakdown_frame()
    out = breakdown(res, "hole_model", seed=3)
    assert list(out.columns) == ["noise_mm", "method", "by", "group", "segments", "mae", "mae_lo", "mae_hi", "bias",
                                 "interval_covered", "interval_width"]
    assert out["noise_mm"].tolist() == [0.0, 0.0, 0.5, 0.5] and out["group"].tolist() == ["camera", "camera+end"] * 2
    assert out["segments"].tolist() == [5, 4, 5, 4] and set(out["by"]) == {"hole_model"}
    cam, end = out.iloc[0], out.iloc[1]
    assert cam["mae"] == pytest.approx(2.6) and cam["bias"] == pytest.approx(1.8)  # 1, 2, 3, 2, 5 points
    assert end["mae"] == pytest.approx(10 / 3) and end["bias"] == pytest.approx(-2 / 3)  # 4, -6, 0; one NaN
    assert cam["mae_lo"] <= cam["mae"] <= cam["mae_hi"] and end["mae_lo"] <= end["mae"] <= end["mae_hi"]
    assert _cells(breakdown(res, "length_mm")) == {(0.0, "50"): 4, (0.0, "60"): 5, (0.5, "50"): 4, (0.5, "60"): 5}
    cov = breakdown(res, "true_coverage")
    assert cov[cov["noise_mm"] == 0.0]["group"].tolist() == ["0.0-0.5", "0.5-0.7", "0.7-0.8", "0.8-0.9", "0.9-1.0"]
    assert cov[cov["noise_mm"] == 0.0]["segments"].tolist() == [1, 1, 1, 1, 2]  # NaN, -0.1 and 1.2 in no bin
    top = cov[(cov["noise_mm"] == 0.0) & (cov["group"] == "0.9-1.0")].iloc[0]
    assert top["mae"] == pytest.approx(4.0) and np.isnan(top["mae_lo"])  # 0.95 undefined, 1.0 -> 0.04
    noise = breakdown(res, "noise_mm")
    assert noise["group"].tolist() == ["0", "0.5"] and noise["segments"].tolist() == [9, 9]
    assert noise["mae"].tolist() == pytest.approx([23 / 8, 23 / 8])  # 1+2+3+4+6+2+5+0 points over 8 defined
    with pytest.raises(InputError):
        breakdown(res, "colour")
    with pytest.raises(InputError):
        breakdown(res.drop(columns="length_mm"), "length_mm")


def test_breakdown_unseen_end():
    res = _breakdown_frame()
    out = breakdown(res, "unseen_end")
    assert _cells(out) == {(0.0, "False"): 5, (0.0, "True"): 4, (0.5, "False"): 5, (0.5, "True"): 4}
    flagged = res.assign(end_unobserved=[True, False, False, False, False, True, False, False, False] * 2)
    out = breakdown(flagged, "unseen_end")  # the column wins over the hole model
    assert _cells(out) == {(0.0, "False"): 7, (0.0, "True"): 2, (0.5, "False"): 7, (0.5, "True"): 2}
    assert out.iloc[1]["mae"] == pytest.approx(3.5)  # rows 0 and 5: 1 and 6 points
    with pytest.raises(InputError):
        breakdown(res.assign(end_unobserved="maybe"), "unseen_end")


def test_breakdown_seeds_per_cell():
    res = _breakdown_frame()
    out = breakdown(res, "hole_model", resamples=200, seed=3)
    pd.testing.assert_frame_equal(breakdown(res, "hole_model", resamples=200, seed=3), out)
    alone = breakdown(res[(res["noise_mm"] == 0.5) & (res["hole_model"] == "camera+end")], "hole_model",
                      resamples=200, seed=3)
    pd.testing.assert_frame_equal(alone, out.iloc[[3]].reset_index(drop=True))
    # the two noise levels hold the same errors but draw from different streams
    assert out.iloc[0]["mae_lo"] != out.iloc[2]["mae_lo"] or out.iloc[0]["mae_hi"] != out.iloc[2]["mae_hi"]
    other = breakdown(res, "hole_model", resamples=200, seed=4)
    assert not np.array_equal(other["mae_lo"], out["mae_lo"])


def test_intervals_are_scored_by_the_share_of_truths_inside_and_their_width():
    from colonbench.benchmark.summary import interval_stats

    rows = pd.DataFrame({"true_coverage": [0.5, 0.8, 0.9, 0.2, 0.7],
                         "interval_low": [0.4, 0.85, 0.8, 0.1, np.nan],
                         "interval_high": [0.6, 0.95, 0.9, 0.3, np.nan]})
    got = interval_stats(rows)
    assert got["interval_segments"] == 4                       # the row without an interval is not counted
    assert got["interval_covered"] == pytest.approx(75.0)      # 0.8 lies below [0.85, 0.95]; 0.9 on an edge counts
    assert got["interval_width"] == pytest.approx(100 * (0.2 + 0.1 + 0.1 + 0.2) / 4)
    untrue = interval_stats(pd.concat([rows, pd.DataFrame({"true_coverage": [np.nan], "interval_low": [0.1],
                                                           "interval_high": [0.2]})]))
    assert untrue == got                                       # a row with no truth (a region without a true face)
    none = interval_stats(rows.assign(interval_low=np.nan, interval_high=np.nan))
    assert none["interval_segments"] == 0 and np.isnan(none["interval_covered"])
    grouped = breakdown(_breakdown_frame().assign(true_coverage=0.5, interval_low=0.4, interval_high=0.6),
                        "hole_model", seed=3)
    assert (grouped["interval_covered"] == 100.0).all() and np.allclose(grouped["interval_width"], 20.0)
