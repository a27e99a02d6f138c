"""scripts/calibrate_intervals.py: leave-one-colon-out measurement and the colon as the unit (decision record 0325);
tests/test_pair_choice.py tests the rule that chooses the scheme (0172)."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from colonbench.completion import intervals


def test_the_calibration_is_measured_leaving_each_colon_out(monkeypatch):
    """scripts/calibrate_intervals.py measures every scheme leave-one-colon-out: each colon's intervals come from a
    calibration fitted on all the other colons, and the truth-inside shares are those of the held-out intervals."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "calibrate_intervals", Path(__file__).resolve().parents[1] / "scripts" / "calibrate_intervals.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    ids = np.repeat([3, 900020, 7], 40)
    df = pd.DataFrame({"colon_id": ids, "true": np.tile(np.linspace(0.5, 0.9, 40), 3), "estimate": 0.7,
                       "rims": 2, "length_mm": 50.0, "span_mm": 50.0, "segment_mm": 50.0,
                       "set": np.where(ids == 900020, "V_real", "V_wide"), "noise_mm": 0.0})
    df.loc[df["colon_id"] == 7, "true"] = 0.7              # one colon whose truths all equal its estimates
    fitted_on = []
    real_fit = script.intervals.fit

    def recording_fit(true, estimated, signals, *args, **kwargs):
        fitted_on.append(len(true))
        return real_fit(true, estimated, signals, *args, **kwargs)

    monkeypatch.setattr(script.intervals, "fit", recording_fit)
    held = script.by_colon(script.with_units(df), "length+band", 0.9)
    assert fitted_on == [80, 80, 80]                       # each fit leaves one colon of 40 out
    # colon 7 (truths at the estimate) gets the interval of colons 3 and 900020: their 80 residuals, each of
    # linspace(-0.2, 0.2, 40) twice, have the 4th smallest (rank floor(81 * 0.05)) at the second step
    seven = held[held["colon_id"] == 7]
    assert seven["inside"].all() and seven["low"].iloc[0] == pytest.approx(0.7 - 0.2 + 0.4 / 39, abs=1e-9)
    # colons 3 and 900020 get it from one spread colon and one at zero: narrower than their own spread
    assert 0 < held.loc[held["colon_id"] == 3, "inside"].mean() < 1
    table = script.cells(held)
    assert set(table.index.get_level_values("cell")) == {"V_real gca00020", "V_wide"} and table["n"].sum() == 120


def test_each_colon_weighs_the_same_and_each_set_a_third():
    """calibrate_intervals.unit_weights: within a set every colon weighs the same, every set the same, whatever their
    sizes; with_units names each real colon's cell."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "calibrate_intervals", Path(__file__).resolve().parents[1] / "scripts" / "calibrate_intervals.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    df = script.with_units(pd.DataFrame({"set": ["V_wide"] * 6 + ["V_paper"] * 2 + ["V_real"] * 4,
                                         "colon_id": [1, 1, 1, 1, 2, 2, 3, 4, 900020, 900020, 900020, 900070]}))
    w = script.unit_weights(df)
    assert w.sum() == pytest.approx(1.0)
    per_colon = pd.Series(w).groupby(df["colon"]).sum()
    assert per_colon["V_wide:1"] == pytest.approx(1 / 6) and per_colon["V_wide:2"] == pytest.approx(1 / 6)
    assert per_colon["V_real:900020"] == pytest.approx(1 / 6) and per_colon["V_paper:3"] == pytest.approx(1 / 6)
    assert set(df["cell"]) == {"V_wide", "V_paper", "V_real gca00020", "V_real gca00070"}
    with pytest.raises(ValueError, match="finite numbers"):
        intervals.fit([0.5] * 40, [0.5] * 40, [{}] * 40, "scaled-colon", 0.3, weights=[0.0] * 40)
