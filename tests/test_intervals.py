"""How sure the completion method is: split-conformal intervals, a segment's known length, and how the benchmark
scores intervals."""

import json

import numpy as np
import pandas as pd
import pytest

from colonbench.cli import main
from colonbench.completion import calfile, conformal, intervals, known_extent
from colonbench.completion.modelfile import model_path
from colonbench.errors import InputError
from colonbench.estimate import Estimate, as_estimate


def test_conformal_quantiles_take_the_finite_sample_ranks():
    r = np.arange(1, 20) / 100.0                       # 19 residuals: ranks floor(20 * 0.05) = 1, ceil(20 * 0.95) = 19
    assert conformal.conformal_quantiles(r, 0.9) == (0.01, 0.19)
    assert conformal.conformal_quantiles(r[:5], 0.9) == (-1.0, 1.0)   # too few for a 90 % interval: everything


def test_a_calibration_covers_its_level_on_fresh_segments_of_the_same_kind():
    rng = np.random.default_rng(0)

    def draw(n):
        length = rng.choice([35.0, 50.0, 65.0], n)
        est = rng.uniform(0.5, 1.0, n)
        spread = np.where(length < 45, 0.15, 0.03)     # short clouds err more, and downwards
        true = np.clip(est - np.abs(rng.normal(0, spread)) + rng.normal(0, 0.01, n), 0, 1)
        return true, est, [{"length_mm": x, "rims": 2} for x in length]

    cal = intervals.fit(*draw(3000), "length", review_width=0.25)
    true, est, signals = draw(4000)
    inside, width = [], []
    for t, c, sig in zip(true, est, signals):
        e = Estimate(c, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals=sig)
        cal.apply(e)
        inside.append(e.coverage_interval[0] <= t <= e.coverage_interval[1])
        width.append(e.coverage_interval[1] - e.coverage_interval[0])
        assert (width[-1] > 0.25) == any("wide" in r for r in e.review)
    inside, width, short = np.array(inside), np.array(width), np.array([s["length_mm"] < 45 for s in signals])
    assert 0.87 <= inside.mean() <= 0.93
    assert 0.85 <= inside[short].mean() <= 0.95 and 0.85 <= inside[~short].mean() <= 0.95   # per group, too
    assert width[short].mean() > 3 * width[~short].mean()                                     # it adapts


def test_a_known_length_counts_what_the_cloud_does_not_reach_as_unobserved():
    est = Estimate(0.9, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"length_mm": 30.0, "span_mm": 30.0})
    known_extent.known_length(est, 60.0)
    assert est.coverage == pytest.approx(0.45) and est.signals["extent"] == "known"
    assert "spans 30 of the segment's 60 mm" in est.review[0]
    near = Estimate(0.9, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"length_mm": 57.0, "span_mm": 57.0})
    known_extent.known_length(near, 60.0)                 # a line a little short of the cut: the cloud reaches it
    assert near.coverage == 0.9 and not near.review
    # the network's line stops short, but the segment's planes (cut rims) lie at its ends: its span is not short
    short_line = Estimate(0.9, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"length_mm": 20.0, "span_mm": 59.0})
    known_extent.known_length(short_line, 60.0)
    assert short_line.coverage == 0.9 and short_line.signals["length_share"] == pytest.approx(59 / 60, abs=1e-4)
    with pytest.raises(ValueError, match="positive"):
        known_extent.known_length(near, -1.0)
    with pytest.raises(InputError, match="cannot be this cloud's: it spans 59 mm.*in cm"):    # 6 cm typed as 6 mm
        known_extent.known_length(Estimate(0.9, np.zeros((0, 3)), np.zeros((0, 3)), "m",
                                        signals={"length_mm": 55.0, "span_mm": 59.0}), 6.0)


def test_review_fires_on_a_wide_interval_and_then_names_a_doubtful_rim_unless_the_extent_is_known():
    cal = intervals.fit([0.8] * 40, [0.8] * 40, [{"length_mm": 70.0, "rims": 2}] * 40, "length", 0.4)
    cal.known = {"low": -0.1, "high": 0.1, "n": 40}
    reasons = {}
    for doubtful, extent, width in ((0, None, 0.5), (1, None, 0.5), (1, "known", 0.5), (1, None, 0.3)):
        cal.groups["length>=60"].update(low=-width / 2, high=width / 2)
        signals = {"length_mm": 70.0, "rims": 2, "rims_doubtful": doubtful, **({"extent": extent} if extent else {})}
        est = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals=signals)
        cal.apply(est)
        reasons[(doubtful, extent, width)] = est.review
    assert reasons[(0, None, 0.5)] == ["interval 50 points wide (more than 40)"]
    assert len(reasons[(1, None, 0.5)]) == 2 and "seen from one side" in reasons[(1, None, 0.5)][1]
    assert reasons[(1, "known", 0.5)] == [] and reasons[(1, None, 0.3)] == []   # 20 and 30 points: sure enough
    # a known length's note (known_extent.known_length) is a reason only where the interval is wide, too
    for width, kept in ((0.3, False), (0.5, True)):
        cal.groups["length>=60"].update(low=-width / 2, high=width / 2)
        est = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", review=["the cloud spans 40 of 60 mm"],
                       signals={"length_mm": 70.0, "rims": 2})
        cal.apply(est)
        assert ("the cloud spans 40 of 60 mm" in est.review) == kept


def test_a_known_extent_is_reviewed_against_its_own_width():
    """``review_known`` (decision record 0325): a segment whose planes the caller gives (a map's) or whose length is
    given (0163, round 8) is flagged where its interval is wider than the known extent's review width, not the
    segments' wider one; a calibration without one keeps the segments' width, and its file says nothing of it."""
    cal = intervals.fit([0.8] * 40, [0.8] * 40, [{"length_mm": 70.0, "rims": 2}] * 40, "length", 0.4)
    cal.known = {"low": -0.1, "high": 0.1, "n": 40}                  # a known extent's interval: 20 points
    known = {"length_mm": 70.0, "rims": 2, "extent": "known"}
    est = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals=dict(known))
    cal.apply(est)
    assert est.review == [] and "review_known" not in cal.to_json()
    cal.review_known = 0.15
    est = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals=dict(known))
    cal.apply(est)
    assert est.review == ["interval 20 points wide (more than 15)"] and cal.to_json()["review_known"] == 0.15
    given = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={**known, "length_share": 1.0})
    cal.apply(given)                    # a length given (known_length): the known extent's review width too
    assert given.review == ["interval 20 points wide (more than 15)"]
    segment = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"length_mm": 70.0, "rims": 2})
    cal.groups["length>=60"].update(low=-0.1, high=0.1)             # 20 points, under the segments' 40
    cal.apply(segment)
    assert segment.review == []
    assert intervals.Intervals(**json.loads(json.dumps(cal.to_json()))).review_known == 0.15


def test_intervals_in_the_contract_are_checked():
    est = as_estimate({"coverage": 0.8, "coverage_interval": [0.7, 0.9]}, "m")
    assert est.coverage_interval == (0.7, 0.9) and est.to_json()["coverage_interval"] == [0.7, 0.9]
    assert "coverage_interval" not in as_estimate({"coverage": 0.8}, "m").to_json()
    reviewed = Estimate(0.8, np.zeros((0, 3)), np.zeros((0, 3)), "m", review=["a reason"])
    assert reviewed.to_json()["review"] == ["a reason"]          # a reason to review is said, interval or not
    with pytest.raises(InputError, match="coverage_interval_level"):
        as_estimate({"coverage": 0.8, "coverage_interval": [0.7, 0.9], "coverage_interval_level": 90}, "m")
    for bad in ([0.9, 0.7], [0.5], [0.1, 1.5], "wide"):
        with pytest.raises(InputError, match="coverage_interval"):
            as_estimate({"coverage": 0.8, "coverage_interval": bad}, "m")


def test_estimate_writes_the_interval_and_takes_a_known_length(demo_data, tmp_path, capsys):
    from colonbench.completion.method import CompletionMethod, model_path, steps_version
    from colonbench.shards.reader import Shard

    shard = sorted((demo_data / "demo-v1" / "test").glob("*.h5"))[0]
    with Shard(shard) as s:
        np.save(tmp_path / "seg.npy", s.geometry(0)["partial_points"])
    assert main(["estimate", str(tmp_path / "seg.npy"), "--out-dir", str(tmp_path / "a")]) == 0
    a = json.loads((tmp_path / "a" / "seg.json").read_text())
    assert a["coverage_interval"][0] <= a["coverage"] <= a["coverage_interval"][1]
    assert a["coverage_interval_level"] == 0.9 and isinstance(a["review"], list)
    assert a["signals"]["span_mm"] >= a["signals"]["length_mm"] - 0.5     # the line, run on to its planes
    # the costly signals only where the shipped calibration's features use them (its groups', known extent's, odds')
    cal = calfile.load(model_path(None), None)
    used = {f for g in [*cal.groups.values(), cal.known, cal.review_odds] for f in g.get("features", ())}
    for feature, signal in (("spread", "spread"), ("depth", "hole_depth_mm"), ("misfit", "wall_misfit_mm")):
        assert (signal in a["signals"]) == (feature in used), signal
    assert main(["estimate", str(tmp_path / "seg.npy"), "--out-dir", str(tmp_path / "b"), "--length-mm", "500"]) == 0
    b = json.loads((tmp_path / "b" / "seg.json").read_text())
    assert b["coverage"] < 0.2 and b["signals"]["extent"] == "known"
    cal = calfile.load(model_path(None), steps_version())
    assert b["coverage_interval"] == pytest.approx(cal.interval(b["coverage"], b["signals"]), abs=2e-6)
    # the known-extent interval (its own quantiles), not the one of an estimate whose length is unknown
    assert b["coverage_interval"] != pytest.approx(cal.interval(b["coverage"], {**b["signals"], "extent": None}))
    # the note of a length the cloud stops short of is a reason to review where the interval reaches far, as the
    # rims' are; a length given is reviewed by the known extent's rule (decision record 0163)
    score = intervals.review_score(b["coverage"], *b["coverage_interval"], cal.review_by_known or cal.review_by)
    assert bool(b["review"]) == (score > (cal.review_known or cal.review_width))
    assert not b["review"] or "counted unobserved" in b["review"][0]
    assert CompletionMethod().intervals is not None
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["estimate", str(tmp_path / "seg.npy"), "--out-dir", str(tmp_path / "c"), "--length-mm", "-3"])
    assert "--length-mm: must be a positive number" in capsys.readouterr().err
    assert main(["estimate", str(tmp_path / "seg.npy"), "--out-dir", str(tmp_path / "c"), "--length-mm", "60",
                 "--method", "constant"]) == 2
    assert "does not take a segment's length" in capsys.readouterr().err
    assert main(["estimate", str(tmp_path / "seg.npy"), "--out-dir", str(tmp_path / "d"), "--length-mm", "6"]) == 2
    err = capsys.readouterr().err                      # 6 cm typed as mm: refused, never used silently
    assert "seg.npy" in err and "a length in cm, not mm?" in err and not (tmp_path / "d" / "seg.json").exists()


def test_the_benchmark_scores_intervals_and_says_n_a_for_methods_without(demo_data, tmp_path):
    from colonbench.benchmark.evaluate import evaluate
    from colonbench.reports.leaderboard import write_leaderboard

    class Sure:
        name, version = "sure", "1"

        def estimate(self, points):              # flags the clouds with an odd number of points for review
            return {"coverage": 0.8, "coverage_interval": [0.7, 0.9], "review": ["odd"] * (len(points) % 2)}

    class Plain:
        name, version = "plain", "1"

        def estimate(self, points):
            return {"coverage": 0.8}

    run = evaluate(demo_data / "demo-v1", [Sure(), Plain()], tmp_path / "run", noise=[0], progress=False, examples=0)
    rows = pd.read_csv(run / "results" / "sure.csv")
    assert (rows["interval_low"] == 0.7).all() and pd.read_csv(run / "results" / "plain.csv")["interval_low"].isna().all()
    inside = ((rows["true_coverage"] >= 0.7) & (rows["true_coverage"] <= 0.9)).mean()
    assert 0 < inside < 1                              # demo-v1's truths lie on both sides of [0.7, 0.9]
    write_leaderboard([run], tmp_path / "lb", figures=False)
    table = pd.read_csv(tmp_path / "lb" / "leaderboard.csv").set_index("method")
    assert table.loc["sure", "interval_covered"] == pytest.approx(100 * inside)
    assert table.loc["sure", "interval_width"] == pytest.approx(20.0)
    assert np.isnan(table.loc["plain", "interval_covered"]) and table.loc["plain", "interval_segments"] == 0
    flagged, off = rows["review"] > 0, (rows["true_coverage"] - 0.8).abs() > 0.15
    assert set(rows["review"]) <= {0, 1} and 0 < flagged.mean() < 1 and off.any()
    recall, precision = (flagged & off).sum() / off.sum(), (flagged & off).sum() / flagged.sum()
    assert table.loc["sure", "review_flagged"] == pytest.approx(100 * flagged.mean())
    assert table.loc["sure", "review_recall"] == pytest.approx(100 * recall)
    assert table.loc["sure", "review_precision"] == pytest.approx(100 * precision)
    assert np.isnan(table.loc["plain", "review_flagged"])
    md = (tmp_path / "lb" / "leaderboard.md").read_text()
    assert (f"| sure | 24 | {100 * inside:.1f} % | 20.0 | {100 * flagged.mean():.0f} % | {100 * recall:.0f} % | "
            f"{100 * precision:.0f} % |") in md and "| plain | 0 | n/a | n/a | n/a | n/a | n/a |" in md
    bd = (tmp_path / "lb" / "breakdowns.md").read_text()
    assert "| sure: interval |" in bd and "| plain: interval |" not in bd and "% inside, 20.0 wide" in bd


def test_the_colon_is_the_unit_of_a_colon_scheme():
    """Weighted quantiles count a colon as one (decision record 0325): a colon of 200 segments at 0 and one of 5 at
    +0.3, each weighing half, put the upper quartile's rank in the small colon; unweighted, the 5 are a tail."""
    values = np.r_[np.zeros(200), np.full(5, 0.3)]
    weights = np.r_[np.full(200, 0.5 / 200), np.full(5, 0.5 / 5)]
    # effective size 1 / (200 (1/400)^2 + 5 (1/10)^2) = 19.51; ranks floor(20.51 * 0.25) = 5 and ceil(20.51 * 0.75)
    # = 16 of 19.51: the cumulated weight reaches 0.256 among the zeros and 0.820 at the small colon's 4th segment
    assert conformal.weighted_quantiles(values, weights, 0.5) == (0.0, 0.3)
    assert conformal.conformal_quantiles(values, 0.5) == (0.0, 0.0)
    # equal weights give the split-conformal ranks
    r = np.linspace(-0.3, 0.3, 61)
    assert conformal.weighted_quantiles(r, np.ones(61), 0.9) == pytest.approx(conformal.conformal_quantiles(r, 0.9))
    # a scheme that weighs colons refuses to fit without the weights
    with pytest.raises(ValueError, match="weight"):
        intervals.fit([0.5] * 40, [0.5] * 40, [{}] * 40, "scaled-colon", 0.3)


def test_the_shift_term_widens_by_the_colons_typical_shift():
    """``-shift``: the quantiles are of the residuals less their colon's median, widened by the quartiles of the
    colons' medians; four colons shifted by -0.2, 0, 0, +0.2, each with the same spread, give exactly that."""
    spread = np.linspace(-0.05, 0.05, 41)
    shifts = np.array([-0.2, 0.0, 0.0, 0.2])
    residual = (shifts[:, None] + spread[None, :]).ravel()
    colons = np.repeat(["a", "b", "c", "d"], 41)
    weights = np.full(len(residual), 1 / len(residual))
    group = intervals._fit_group(residual, None, (), 0.9, weights=weights, colons=colons)
    low, high = conformal.weighted_quantiles(np.tile(spread, 4), weights, 0.9)
    # the colons' medians' weighted quartiles: -0.2 (a quarter of the weight reaches it) and 0 (three quarters)
    assert group["low"] == pytest.approx(low - 0.2) and group["high"] == pytest.approx(high + 0.0)
    # the novelty signals enter a colon scheme's scale as features, a signal the estimate lacks counting 0
    f = intervals.features(0.7, {"length_mm": 50.0, "radius_mm": 25.0, "extent_mm": 100.0, "spread": 0.02},
                           intervals.SCALE_FEATURES["scaled-colon-novel"])
    assert f[-3:] == pytest.approx([0.2, 0.5, 0.5])
    assert intervals.features(0.7, {"length_mm": 50.0}, ("line_extent",))[0] == 0.0


def test_a_map_segment_gets_the_interval_and_review_around_its_own_coverage():
    # the map clips the completed surface to the segment's stretch, or counts a stretch no point reached, so its
    # coverage differs from the estimate's: completion's interval is made again around it (not the estimate's,
    # clipped at 1, moved down), and its review is decided on that interval, the one the map reports
    from colonbench.mapping.colonmap import mapped_interval

    cal = intervals.fit([0.8] * 40, [0.8] * 40, [{"length_mm": 70.0}] * 40, "length", 0.4)
    cal.known = {"low": -0.08, "high": 0.1, "n": 40}
    cal.review_known, cal.review_by_known = 0.2, "width"
    est = Estimate(0.97, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"length_mm": 70.0, "extent": "known"})
    cal.apply(est)
    assert est.coverage_interval == pytest.approx((0.89, 1.0)) and est.review == []    # 0.11 wide: not flagged

    class Method:
        intervals = cal

    low_high, review = mapped_interval(Method, est, 0.95)
    assert low_high == pytest.approx([0.87, 1.0]) and review == []                     # moved, it would end at 0.98
    cal.known = {"low": -0.3, "high": 0.1, "n": 40}         # a segment the map reads at 0.5: [0.2, 0.6], 0.4 wide
    low_high, review = mapped_interval(Method, est, 0.5)
    assert low_high == pytest.approx([0.2, 0.6]) and review == ["interval 40 points wide (more than 20)"]
    assert est.coverage == 0.97 and est.review == [] and est.coverage_interval == pytest.approx((0.89, 1.0))

    class Other:                                                               # a method without a calibration
        pass

    class IntervalOnly:                                       # a calibration that gives intervals and no review
        intervals = type("C", (), {"interval": lambda self, c, s: (c - 0.3, c + 0.3)})()

    est.review = ["its own reason"]
    assert mapped_interval(Other, est, 0.95) == (pytest.approx([0.87, 0.98]), ["its own reason"])
    assert mapped_interval(IntervalOnly, est, 0.5) == (pytest.approx([0.2, 0.8]), ["its own reason"])
    assert mapped_interval(Method, est, float("nan")) == (pytest.approx([0.89, 1.0]), ["its own reason"])


def test_a_calibrated_method_gives_each_segment_its_interval_around_the_maps_coverage():
    """A method with a calibration (``intervals``, as completion's) gives a map segment its interval around the map's
    coverage from that calibration; one without keeps the interval of its estimate."""
    from shapes import straight
    from test_map import tube_cloud

    line = straight(200.0)
    pts, _, _ = tube_cloud(line, density=1.0)

    class Calibration:
        def interval(self, coverage, signals):
            return coverage - 0.05, min(coverage + 0.3, 1.0)

    class Sure:
        name, version = "sure", "1"

        def estimate(self, points):              # flags the clouds with an odd number of points for review
            return {"coverage": 0.8, "coverage_interval": [0.7, 0.9], "review": ["odd"] * (len(points) % 2)}

    class Calibrated(Sure):
        intervals = Calibration()

    from colonbench.mapping.colonmap import map_colon

    class Reviewing(Calibration):                 # a calibration that reviews too (as completion's Intervals)
        def apply(self, est):
            est.coverage_interval = self.interval(est.coverage, est.signals)
            est.review = [f"reviewed at {est.coverage:.2f}, {est.signals['map_track']}"]

    class Reviewed(Sure):
        intervals = Reviewing()

    reviews = {}
    for method, expected in ((Sure(), [0.7, 0.9]), (Calibrated(), [0.75, 1.0]), (Reviewed(), [0.75, 1.0])):
        result = map_colon(pts, method, segment_mm=60.0, positions=line.points[::-20], progress=False)
        assert [s.coverage_interval for s in result["segments"]] == [pytest.approx(expected)] * 3
        reviews[method.__class__.__name__] = [s.review for s in result["segments"]]
    assert reviews["Calibrated"] == reviews["Sure"] and ["odd"] in reviews["Sure"]       # the estimate's, kept
    assert reviews["Reviewed"] == [["reviewed at 0.80, segment-only"]] * 3              # decided by the calibration


def test_a_scaled_interval_follows_the_scale_its_signals_give():
    """Residuals of +-0.2 on short lines and +-0.02 on long ones: the scale, fitted to log(|r| + 0.005), is
    0.205 / 0.025 times larger on the short, and so is the interval, which holds every truth. Two-sided, with
    under-estimates (+0.2) only on short lines, the high end reaches far there and the low end does not."""
    n = 400
    short = np.arange(n) % 4 < 2
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    sig = [{"length_mm": 30.0 if s else 90.0, "span_mm": 30.0 if s else 90.0, "rims": 2} for s in short]
    residual = sign * np.where(short, 0.2, 0.02)
    cal = intervals.fit(0.5 + residual, np.full(n, 0.5), sig, "scaled", 0.4)
    ends = np.array([cal.interval(0.5, s) for s in sig])
    widths = ends[:, 1] - ends[:, 0]
    assert widths[short].mean() / widths[~short].mean() == pytest.approx(0.205 / 0.025, rel=1e-6)
    assert ((ends[:, 0] - 1e-12 <= 0.5 + residual) & (0.5 + residual <= ends[:, 1] + 1e-12)).all()
    skew = np.where(short & (sign < 0), -0.02, residual)
    two = intervals.fit(0.5 + skew, np.full(n, 0.5), sig, "scaled2", 0.4)
    (lo_s, hi_s), (lo_l, hi_l) = two.interval(0.5, sig[0]), two.interval(0.5, sig[2])
    assert hi_s - 0.5 > 2.5 * (hi_l - 0.5) and 0.5 - lo_s < 1.5 * (0.5 - lo_l)
    ends = np.array([two.interval(0.5, s) for s in sig])
    assert ((ends[:, 0] - 1e-12 <= 0.5 + skew) & (0.5 + skew <= ends[:, 1] + 1e-12)).all()


def test_a_scale_is_never_extrapolated_past_the_calibrated_range_and_a_long_cloud_is_named():
    """Calibrated on lines of 30 and 90 mm (wider on the short): a 300 mm line gets the 90 mm line's interval, not
    a narrower one, and its review names a cloud longer than 1.5 times the longest calibrated line; a 120 mm one is
    not named. A calibration file without the ranges (calibrated before them) extrapolates as it did."""
    n = 400
    short = np.arange(n) % 4 < 2
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    sig = [{"length_mm": 30.0 if s else 90.0, "span_mm": 30.0 if s else 90.0, "rims": 2} for s in short]
    cal = intervals.fit(0.5 + sign * np.where(short, 0.2, 0.02), np.full(n, 0.5), sig, "scaled", 0.4)
    assert cal.longest_mm() == pytest.approx(90.0)
    at = {mm: cal.interval(0.5, {"length_mm": mm, "span_mm": mm, "rims": 2}) for mm in (90.0, 120.0, 300.0)}
    assert at[300.0] == at[120.0] == at[90.0] and at[90.0][1] - at[90.0][0] > 0.03
    known_extent.fit_known(cal, 0.5 + sign * np.where(short, 0.2, 0.02), np.full(n, 0.5), sig)   # the known group too
    known = {mm: cal.interval(0.5, {"length_mm": mm, "span_mm": mm, "rims": 2, "extent": "known"}) for mm in (90, 300)}
    assert "ranges" in cal.known and known[300] == known[90]
    for mm, named in ((120.0, False), (300.0, True)):
        est = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"length_mm": mm, "span_mm": mm, "rims": 2})
        cal.apply(est)
        assert any("longer than one segment" in r for r in est.review) is named
        assert not [r for r in est.review if "interval" in r and "wide" in r]     # narrow: no other reason
    old = intervals.Intervals(**json.loads(json.dumps(cal.to_json())))
    for g in old.groups.values():
        del g["ranges"]
    lo, hi = old.interval(0.5, {"length_mm": 300.0, "span_mm": 300.0, "rims": 2})
    assert hi - lo < 0.2 * (at[90.0][1] - at[90.0][0])


def test_a_calibration_with_a_map_part_gives_each_map_track_its_own_interval():
    cal = intervals.fit([0.8] * 40, [0.8] * 40, [{"length_mm": 70.0}] * 40, "length", 0.4)
    cal.known = {"low": -0.08, "high": 0.1, "n": 40}
    cal.map = {"scheme": "track", "groups": {"track=context": {"low": -0.02, "high": 0.03, "n": 300},
                                             "track=segment-only": {"low": -0.3, "high": 0.2, "n": 300}}}
    known = {"length_mm": 70.0, "extent": "known"}
    assert cal.interval(0.5, {**known, "map_track": "context"}) == pytest.approx((0.48, 0.53))
    assert cal.interval(0.5, {**known, "map_track": "segment-only"}) == pytest.approx((0.2, 0.7))
    assert cal.interval(0.5, known) == pytest.approx((0.42, 0.6))             # not a map segment: the known extent
    cal.map = {"scheme": "track+band", "groups": {"track=context": {"low": -0.02, "high": 0.03, "n": 300},
                                                  "track=context,below=1.01": {"low": -0.05, "high": 0.0, "n": 40}}}
    assert cal.interval(0.9, {**known, "map_track": "context"}) == pytest.approx((0.85, 0.9))
    assert cal.interval(0.5, {**known, "map_track": "context"}) == pytest.approx((0.48, 0.53))   # its track's
    again = intervals.Intervals(**json.loads(json.dumps(cal.to_json())))
    assert again.interval(0.9, {**known, "map_track": "context"}) == pytest.approx((0.85, 0.9))


def test_the_novelty_signals_measure_the_lumen_and_the_cloud():
    """``novelty.shape`` on a tube of known radius and length: the median distance to its axis is the radius, the
    extent along the principal axis its length; ``spread`` is 0 for a network that agrees with itself."""
    torch = pytest.importorskip("torch")
    from colonbench.completion import novelty

    a, z = np.meshgrid(np.linspace(0, 2 * np.pi, 72, endpoint=False), np.linspace(0, 80, 81))   # a regular tube
    points = np.c_[20 * np.cos(a.ravel()), 20 * np.sin(a.ravel()), z.ravel()]
    line = np.c_[np.zeros(161), np.zeros(161), np.linspace(0, 80, 161)]
    shape = novelty.shape(points, line)
    assert shape["radius_mm"] == pytest.approx(20.0, abs=0.01) and shape["extent_mm"] == pytest.approx(80.0, abs=0.01)
    x = torch.rand(1, 1, 8, 8, 8)
    same = novelty.spread(lambda t: torch.full_like(t, 0.9), x)          # a constant field: the same in any view
    assert same == 0.0
    flipped = novelty.spread(lambda t: t, x, x[0, 0].numpy())          # the identity: the view moved, compared back
    assert flipped == 0.0
    other = novelty.spread(lambda t: 1 - t, x, x[0, 0].numpy())        # a second pass that disagrees everywhere
    assert other > 0


def test_a_binned_scheme_takes_each_band_of_the_scale_its_own_quantiles():
    """Four line lengths, each a quarter of the segments, with residuals of +-m_k where log(m_k + 0.005) is linear in
    the length: the fitted scale is exactly m_k + 0.005, each length its own band, and the band's quantiles give
    the interval +-m_k, which holds every truth exactly; one shared quantile (``scaled-colon-novel``) is as wide as
    the largest ``m_k / (m_k + 0.005)`` makes it. One scale for all: every band but the first is empty and all get
    the pooled quantiles."""
    lengths = np.array([30.0, 50.0, 70.0, 90.0])
    b = (np.log(0.025) - np.log(0.205)) / 60.0
    m = np.exp(np.log(0.205) + b * (lengths - 30.0)) - 0.005          # 0.2 ... 0.02
    n = 400
    k = np.arange(n) % 4
    sign = np.where((np.arange(n) // 4) % 2 == 0, 1.0, -1.0)
    sig = [{"length_mm": lengths[j], "span_mm": lengths[j], "rims": 2} for j in k]
    residual = sign * m[k]
    w = np.full(n, 1.0 / n)
    cal = intervals.fit(0.5 + residual, np.full(n, 0.5), sig, "binned-colon-novel", 0.4, weights=w)
    assert cal.groups["all"]["band_n"] == [100] * 4
    for j in range(4):
        low, high = cal.interval(0.5, sig[j])
        assert (low, high) == (pytest.approx(0.5 - m[j]), pytest.approx(0.5 + m[j]))
    one = intervals.fit(0.5 + residual, np.full(n, 0.5), sig, "scaled-colon-novel", 0.4, weights=w)
    c = m / (m + 0.005)
    assert one.interval(0.5, sig[3])[1] == pytest.approx(0.5 + c.max() * (m[3] + 0.005))
    flat = [{"length_mm": 60.0, "span_mm": 60.0, "rims": 2}] * n
    same = intervals.fit(0.5 + residual, np.full(n, 0.5), flat, "binned-colon-novel", 0.4, weights=w)
    g = same.groups["all"]
    assert g["band_n"] == [n, 0, 0, 0] and g["band_low"] == [g["low"]] * 4 and g["band_high"] == [g["high"]] * 4


def test_the_holes_depth_is_how_far_the_hole_vertices_lie_from_the_cloud():
    """A disk of radius 8 mm cut from a tube's wall: the distances of a disk's area from its rim have their 90th
    percentile at 8 (1 - sqrt(0.1)) = 5.47 mm; no hole vertex: 0. The depth enters the scale as ``depth`` (/ 10 mm), the
    gap share as ``log_gap`` (-3 with none)."""
    from colonbench.completion import novelty

    a, z = np.meshgrid(np.linspace(0, 2 * np.pi, 72, endpoint=False), np.linspace(0, 80, 81))
    wall = np.c_[20 * np.cos(a.ravel()), 20 * np.sin(a.ravel()), z.ravel()]
    dense = np.meshgrid(np.linspace(-np.pi / 4, np.pi / 4, 400), np.linspace(25, 55, 400))
    patch = np.c_[20 * np.cos(dense[0].ravel()), 20 * np.sin(dense[0].ravel()), dense[1].ravel()]
    cut = np.hypot(20 * dense[0].ravel(), dense[1].ravel() - 40) < 8
    seen = np.vstack([wall[np.hypot(20 * np.arctan2(wall[:, 1], wall[:, 0]), wall[:, 2] - 40) >= 8 + 1e-9],
                      patch[~cut]])
    assert novelty.hole_depth(seen, patch[cut]) == pytest.approx(8 * (1 - np.sqrt(0.1)), abs=0.1)
    assert novelty.hole_depth(seen, np.zeros((0, 3))) == 0.0
    f = intervals.features(0.7, {"hole_depth_mm": 12.0, "gap_share": 0.099}, ("depth", "log_gap"))
    assert f == pytest.approx([1.2, -1.0])
    assert intervals.features(0.7, {}, ("log_gap",))[0] == pytest.approx(-3.0)


def test_the_wall_misfit_is_how_far_the_cloud_lies_from_the_completed_wall():
    """A cloud on a tube of radius 20 mm and a completed wall on the same stations 3 mm inside it: every point lies 3
    mm from its nearest vertex, so the 90th percentile is 3; the same wall: 0; no wall: 0. It enters the scale as
    ``misfit`` (mm)."""
    from colonbench.completion import novelty

    a, z = np.meshgrid(np.linspace(0, 2 * np.pi, 72, endpoint=False), np.linspace(0, 80, 81))
    ring = np.c_[np.cos(a.ravel()), np.sin(a.ravel())]
    cloud = np.c_[20 * ring, z.ravel()]
    assert novelty.wall_misfit(cloud, np.c_[17 * ring, z.ravel()]) == pytest.approx(3.0)
    assert novelty.wall_misfit(cloud, cloud) == 0.0 and novelty.wall_misfit(cloud, np.zeros((0, 3))) == 0.0
    assert intervals.features(0.7, {"wall_misfit_mm": 1.25}, ("misfit",))[0] == 1.25


def test_a_band_too_small_in_effect_gets_the_pooled_quantiles():
    """A band's size is its effective one (Kish's): 40 estimates of which one carries nearly all the weight count as
    about one, under MIN_GROUP, and take the quantiles of all the scaled residuals."""
    z = np.linspace(-1, 1, 200)
    log_s = np.repeat([0.0, 1.0, 2.0, 3.0], 50)
    w = np.full(200, 1 / 50)                       # each band weighs 1 in all
    w[:49] = 1e-6
    w[49] = 1 - 49e-6                              # band 0: 50 estimates, effective size about 1
    out = conformal.band_quantiles(z, log_s, 0.9, w, None, 30)
    assert out["band_n"] == [50, 50, 50, 50]
    assert (out["band_low"][0], out["band_high"][0]) == (out["low"], out["high"])
    assert (out["band_low"][1], out["band_high"][1]) == conformal.weighted_quantiles(z[50:100], w[50:100], 0.9)
    assert out["band_edges"] == [0.5, 1.5, 2.5]     # between the order statistics: no estimate lies on an edge


def test_the_calibration_file_stores_numbers_the_last_bits_of_a_kernel_do_not_move():
    """Decision record 0168: another BLAS moves the fits' weights by 1e-15 to 1e-12 of themselves; the file keeps
    9 significant digits, so it and its id come out the same there."""
    r = calfile.rounded
    assert r({"w": [0.1234567891234, -2.0000000000004], "n": 3, "s": "x", "t": (1.0, 5e-20)}) == \
        {"w": [0.123456789, -2.0], "n": 3, "s": "x", "t": [1.0, 5e-20]}
    assert r(0.4516600607761735) == r(0.4516600607761776)            # two kernels' weight, as measured
    shipped = json.loads(calfile.path_for(model_path(None)).read_text())
    assert shipped == r(shipped)
