"""Decision record 0166: each end's scale fitted at its tail (weighted linear quantile regression), and the margin a
candidate must beat the scheme in use by in scripts/calibrate_intervals.py."""

import numpy as np
import pytest

from colonbench.completion import conformal, intervals
from colonbench.completion.conformal import quantile_regression


def test_quantile_regression_recovers_a_line_and_a_sample_quantile():
    """Points on the line y = 2 + 3 t, a tenth of them lifted above it: the median's fit is the line itself. With an
    intercept only, the fit is the sample's quantile: of 1..19, the 0.5-quantile is 10 and the 0.9-quantile 18; a
    weight of 30 on the value 1 pulls the median down to it."""
    t = np.linspace(0.0, 1.0, 41)
    y = 2.0 + 3.0 * t
    y[::10] += 5.0
    x = np.c_[np.ones_like(t), t]
    assert quantile_regression(x, y, 0.5) == pytest.approx([2.0, 3.0], abs=1e-9)
    values, ones = np.arange(1.0, 20.0), np.ones((19, 1))
    assert quantile_regression(ones, values, 0.5)[0] == pytest.approx(10.0)
    assert quantile_regression(ones, values, 0.9)[0] == pytest.approx(18.0)
    weights = np.ones(19)
    weights[0] = 30.0
    assert quantile_regression(ones, values, 0.5, weights)[0] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="tau"):
        quantile_regression(ones, values, 1.0)


def _segments(n=400, seed=3):
    """Estimates whose residuals below zero grow with the misfit: 0.02 times it, times a half-normal draw."""
    rng = np.random.default_rng(seed)
    est = rng.uniform(0.4, 0.95, n)
    misfit = rng.uniform(0.5, 3.0, n)
    sig = [{"rims": 2, "length_mm": 50.0, "span_mm": 50.0, "spread": 0.02, "radius_mm": 12.0, "extent_mm": 55.0,
            "wall_misfit_mm": float(m)} for m in misfit]
    true = est - 0.02 * misfit * np.abs(rng.normal(size=n))
    return true, est, sig, misfit


def test_a_tail_fitted_scale_leaves_its_tail_above_it():
    """quant95: the low end's scale is the 0.95-quantile fit of log(max(-r, 0) + floor), so at most 5 % of the
    calibration's low-side magnitudes lie above it (the property of a quantile regression's fit), and the scale grows
    with the misfit as the residuals do; the least-squares scale of scaled2 leaves far more above it."""
    true, est, sig, misfit = _segments()
    n = len(true)
    weights = np.where(np.arange(n) % 8 < 2, 3.0, 1.0)          # two colons of eight weigh three times as much
    weights /= weights.sum()
    above = {}
    for scheme in ("quant95-colon-novel-misfit-shift", "scaled2-colon-novel-misfit-shift"):
        cal = intervals.fit(true, est, sig, scheme, 0.3, weights=weights, colons=np.arange(n) % 8)
        group = cal.groups["all"]
        scale = np.array([intervals._scale_of(group, c, s, "low") for c, s in zip(est, sig)])
        over = np.log(np.maximum(est - true, 0) + conformal.SCALE_FLOOR) > np.log(scale) + 1e-9
        above[scheme] = float(np.sum(weights * over))              # the weighted share above the scale
        assert group["weights_low"][group["features"].index("misfit")] > 0
        low, high = cal.interval(0.8, sig[0])
        assert 0.0 <= low < 0.8 <= high <= 1.0
    assert above["quant95-colon-novel-misfit-shift"] <= 0.05 + 1e-9
    assert above["scaled2-colon-novel-misfit-shift"] > 0.2
    assert intervals._tau("quant90-colon-novel-misfit-shift") == 0.9 and intervals._tau("scaled2") is None
    with pytest.raises(ValueError, match="two digits"):
        intervals._tau("quant975-colon-novel-misfit-shift")
    with pytest.raises(ValueError, match="weights"):
        quantile_regression(np.ones((3, 1)), np.arange(3.0), 0.5, [1.0, -1.0, 1.0])
