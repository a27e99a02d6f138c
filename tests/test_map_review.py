"""The map's own review: its threshold chosen on the validation maps (decision record 0223), and its segments against
the map's typical one (0224)."""

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from colonbench.completion import intervals
from colonbench.estimate import Estimate
from colonbench.mapping.colonmap import for_mapping
from colonbench.mapping.map_review import point_rates, review_by_point_rate


def calibration(map_part: dict) -> intervals.Intervals:
    """+-0.1 for every estimate; the known extent +-0.15, flagged wider than 0.2 (so never); ``map_part``."""
    return intervals.Intervals("marginal", 0.9, {"all": {"low": -0.1, "high": 0.1, "n": 100}}, 0.5,
                               known={"low": -0.15, "high": 0.15, "n": 100}, review_known=0.2, map=map_part)


def test_a_map_segment_is_reviewed_by_the_maps_own_threshold():
    """A known-extent estimate's interval is 30 points wide: the known extent's threshold (20 points) flags it, the
    map's own threshold of 35 points leaves it, one of 25 flags it. Without a map threshold the map gets the
    calibration itself."""
    plain = calibration({})
    assert plain.for_map() is plain
    for width, flagged in ((0.35, False), (0.25, True)):
        cal = calibration({"review_width": width}).for_map()
        assert (cal.review_known, cal.review_by_known) == (width, "width")
        est = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"extent": "known"})
        cal.apply(est)
        assert est.coverage_interval == (pytest.approx(0.35), pytest.approx(0.65))
        assert bool(est.review) == flagged
    seg = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"extent": "known"})
    plain.apply(seg)
    assert seg.review == ["interval 30 points wide (more than 20)"]


def test_mapping_hands_the_method_the_calibration_as_maps_are_reviewed_by_it():
    cal = calibration({"review_width": 0.35})
    method = SimpleNamespace(cut_rims=True, end_level=0.5, intervals=cal)
    mapped = for_mapping(method, 2.5)
    assert mapped is not method and mapped.intervals.review_known == 0.35 and method.intervals is cal
    assert for_mapping(SimpleNamespace(cut_rims=False, intervals=calibration({})), 2.5).intervals.review_known == 0.2


def test_the_threshold_is_the_widest_that_catches_three_quarters_of_each_real_colons_far_off_segments(map_intervals):
    """Two real colons of four far-off segments each (widths 0.5, 0.4, 0.3, 0.2 and 0.45, 0.35, 0.25, 0.1) and near
    ones of width 0.6 and 0.05: three of four caught in each needs a threshold under 0.3 and under 0.25, so 0.25 less
    1e-6. A procedural colon's far-off segment of width 0.01 is not asked for."""
    rows = []
    for colon, widths in (("gca00020", (0.5, 0.4, 0.3, 0.2)), ("gca00070", (0.45, 0.35, 0.25, 0.1))):
        rows += [(colon, "M_real", w, 0.9, 0.5) for w in widths] + [(colon, "M_real", w, 0.5, 0.5) for w in (0.6, 0.05)]
    rows.append(("M_proc", "M_proc", 0.01, 0.9, 0.5))
    held = pd.DataFrame(rows, columns=["cell", "set", "width", "estimate", "true"])
    assert map_intervals.review_threshold(held) == pytest.approx(0.25 - 1e-6)
    report = map_intervals.review_report(held.assign(track_kind="context"), map_intervals.review_threshold(held))
    assert report.loc[("gca00020", "context"), "caught"] == 3 and report.loc[("gca00070", "context"), "caught"] == 3
    assert report.loc[("gca00020", "context"), "flagged"] == 4          # the near one of width 0.6 too


def test_a_map_part_with_only_a_threshold_leaves_the_map_segments_the_known_extents_interval():
    """A calibration whose map part holds a review threshold and no groups: a map segment (its track named) gets the
    known extent's interval, and a reason that says the threshold to a tenth of a point."""
    cal = calibration({"review_width": 0.2037}).for_map()
    est = Estimate(0.5, np.zeros((0, 3)), np.zeros((0, 3)), "m", signals={"extent": "known", "map_track": "context"})
    cal.apply(est)
    assert est.coverage_interval == (pytest.approx(0.35), pytest.approx(0.65))
    assert est.review == ["interval 30 points wide (more than 20.4)"]


def test_mapping_swaps_only_the_calibration_where_nothing_else_changes():
    cal = calibration({"review_width": 0.35})
    method = SimpleNamespace(cut_rims=False, end_level=None, intervals=cal)
    mapped = for_mapping(method, 0.0)
    assert mapped is not method and mapped.intervals.review_known == 0.35 and method.intervals.review_known == 0.2


def test_a_segments_point_rate_is_its_density_along_the_line_against_the_maps_median():
    """Points per mm 10, 10, 20 and 5 (median 10): |ln| 0, 0, ln 2, ln 2."""
    rates = point_rates([100, 200, 200, 50], [0.0, 10.0, 30.0, 40.0], [10.0, 30.0, 40.0, 50.0])
    assert rates == pytest.approx([0.0, 0.0, np.log(2), np.log(2)])
    assert point_rates([], [], []).shape == (0,)


def _seg(i, points, coverage=0.8, interval=(0.7, 0.9)):
    from colonbench.mapping.segments import Segment
    return Segment(i, 0, 10.0 * i, 10.0 * (i + 1), {}, {}, points, coverage=coverage,
                   coverage_interval=None if interval is None else list(interval), review=["its own"] * (i == 0))


def test_the_map_flags_the_segments_far_from_its_typical_density_and_says_why():
    """Segments of 200, 100, 40 and 100 points per 10 mm (20, 10, 4, 10 per mm; median 10): the 20 (ln 2 = 0.69) and
    the 4 (0.92) lie beyond 0.6 and are flagged with the figures, after any reason of their own. No threshold flags
    nothing."""
    segs = [_seg(0, 200), _seg(1, 100), _seg(2, 40), _seg(3, 100)]
    review_by_point_rate(segs, None)
    assert [s.review for s in segs] == [["its own"], [], [], []]
    review_by_point_rate(segs, 0.6)
    assert [len(s.review) for s in segs] == [2, 0, 1, 0] and segs[0].review[0] == "its own"
    assert segs[0].review[1].startswith("20 points per mm of the map's line against the map's typical 10 (2.00 "
                                        "times as many; flagged beyond 1.82 times either way)")
    assert "(1/2.50 as many" in segs[2].review[0]


def test_the_maps_typical_segment_is_the_median_of_those_with_a_coverage_reviewed_where_an_interval_is():
    """Points per mm 10, 10 and 16 with intervals, 16 and 16 without (a method that gives none), and 1 without a
    coverage: the median of the five with a coverage is 16, so at 0.4 the two tens (ln 1.6 = 0.47) are flagged and
    nothing else. Leaving out those without an interval (median 10) would flag the 16 instead; counting the one
    without a coverage (median 13) would flag none."""
    segs = [_seg(0, 100), _seg(1, 100), _seg(2, 160), _seg(3, 160, interval=None), _seg(4, 160, interval=None),
            _seg(5, 10, coverage=None)]
    review_by_point_rate(segs, 0.4)
    assert [len(s.review) for s in segs] == [2, 1, 0, 0, 0, 0]
    assert "(1/1.60 as many" in segs[1].review[0] and "typical 16 " in segs[1].review[0]


def test_mapping_flags_a_segment_denser_than_the_rest_where_the_calibration_asks():
    """A straight 200 mm tube at 1 point/mm^2 with its middle 40 mm given twice the points: with a map part's
    ``review_point_rate`` of 0.3 the segment holding them is flagged and the others not; without it, none is."""
    from shapes import straight
    from test_map import tube_cloud

    from colonbench.mapping.colonmap import map_colon

    line = straight(200.0)
    pts, s, _ = tube_cloud(line, density=1.0)
    middle = (s > 80.0) & (s < 120.0)
    pts = np.vstack([pts, pts[middle] + 0.05])

    class Method:
        name, version = "m", "1"

        def __init__(self, map_part):
            self.intervals = calibration(map_part)

        def estimate(self, points):
            return {"coverage": 0.8, "coverage_interval": [0.7, 0.9], "review": []}

    flagged = {}
    for part in ({"review_width": 0.5, "review_point_rate": 0.3}, {"review_width": 0.5}):
        segs = map_colon(pts, Method(part), segment_mm=60.0, positions=line.points[::-20], progress=False)["segments"]
        flagged[len(part)] = [bool(x.review) for x in segs]
        holds = [int(((s >= x.start_mm) & (s < x.end_mm) & middle).sum()) for x in segs]
    assert len(holds) == 3 and holds[1] == max(holds) and flagged[2] == [False, True, False]
    assert flagged[1] == [False, False, False]


def test_the_pair_is_the_one_that_flags_fewest_while_catching_three_quarters_of_each_real_colons_far_off(
        map_intervals):
    """Far-off segments (width, point rate): gca00020's (0.5, 0.1), (0.45, 0.1), (0.1, 1.0), (0.1, 0.9), gca00070's
    (0.4, 0.1), (0.35, 0.1), (0.1, 0.8), (0.05, 0.05); near ones (0.3, 0.1) x 3 and (0.05, 0.2), (0.3, 0.1) x 2. The
    width alone must go under 0.1 (12 flags, 7 right); a width above one under 0.35 or a rate above one under 0.8
    catches 4 and 3 with 7 flags, all right, and no fewer flags catch three of four in each. It is adopted unless it flags more than 5 % of
    the procedural maps' segments."""
    rows = [("gca00020", "M_real", w, r, 0.9) for w, r in ((0.5, 0.1), (0.45, 0.1), (0.1, 1.0), (0.1, 0.9))]
    rows += [("gca00020", "M_real", w, r, 0.5) for w, r in ((0.3, 0.1),) * 3 + ((0.05, 0.2),)]
    rows += [("gca00070", "M_real", w, r, 0.9) for w, r in ((0.4, 0.1), (0.35, 0.1), (0.1, 0.8), (0.05, 0.05))]
    rows += [("gca00070", "M_real", 0.3, 0.1, 0.5)] * 2 + [("M_proc", "M_proc", 0.01, 0.01, 0.5)] * 20
    held = pd.DataFrame(rows, columns=["cell", "set", "width", "point_rate", "estimate"]).assign(true=0.5)
    width = map_intervals.review_threshold(held)
    assert width == pytest.approx(0.1 - 1e-6)
    pair = map_intervals.review_pair(held)
    assert pair == (pytest.approx(0.35 - map_intervals.MARGIN), pytest.approx(0.8 - map_intervals.MARGIN))
    assert map_intervals.pair_adopted(held, width, pair)[0]
    report = map_intervals.review_report(held.assign(track_kind="context"), *pair)
    assert list(report["flagged"]) == [0, 4, 3] and list(report["caught"]) == [0, 4, 3]
    ok, said = map_intervals.pair_adopted(held, pair[0], pair)        # against a width already as right: no gain
    assert not ok and said.startswith("flags right 100.0 % against 100.0 % (pooled)")
    noisy = held.copy()
    noisy.loc[noisy.index[-2:], "point_rate"] = 2.0                   # 2 of 20 procedural segments flagged: 10 %
    ok, said = map_intervals.pair_adopted(noisy, width, pair)
    assert not ok and "procedural flagged 10.0 %" in said
