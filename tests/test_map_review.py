"""The map's own review threshold, chosen on the validation maps (decision record 0223)."""

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from colonbench.completion import intervals
from colonbench.estimate import Estimate
from colonbench.mapping.colonmap import for_mapping


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
