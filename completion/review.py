"""When to look at an estimate again: the scores its review is decided by (decision records 0163 and 0167).

A review score is either one of the estimate's interval (:data:`INTERVAL_SCORES`: its width, its farther end's
distance from the estimate, its low end's), compared with a threshold in fractions of coverage, or ``odds``: the log
odds that the estimate is off by more than 15 points, from a logistic regression on the estimate's features
(:func:`fit_odds`; read as the scale's fit is, :func:`colonbench.completion.intervals.linear_score`; decision record
0167), compared with a threshold in log odds. The calibration (:class:`colonbench.completion.intervals.Intervals`)
holds the score, its threshold and the fitted odds.
"""

from __future__ import annotations

import math

import numpy as np

#: Scores of an estimate's interval (decision record 0163), on the interval clipped to [0, 1].
INTERVAL_SCORES = ("width", "reach", "drop")
#: Every score a calibration's review may be decided by.
REVIEW_SCORES = INTERVAL_SCORES + ("odds",)
#: The ridge penalty of :func:`fit_odds` on its weights but the intercept (decision record 0167).
RIDGE = 1e-3


def review_score(coverage: float, low: float, high: float, by: str = "width") -> float:
    """What an estimate's review is scored by (decision record 0163): ``width`` ``high - low``, ``reach``
    ``max(coverage - low, high - coverage)`` or ``drop`` ``coverage - low`` (its interval ``[low, high]``, clipped to
    [0, 1]; fractions)."""
    if by == "width":
        return high - low
    if by == "reach":
        return max(coverage - low, high - coverage)
    if by == "drop":
        return coverage - low
    raise ValueError(f"unknown interval review score {by!r}: one of {', '.join(INTERVAL_SCORES)}")


def review_reason(width: float, score: float, threshold: float, by: str) -> str:
    """The review's reason for an estimate whose score exceeds its threshold (interval scores: fractions, said in
    points; ``odds``: log odds, said as a chance)."""
    if by == "width":
        return f"interval {100 * width:.0f} points wide (more than {round(100 * threshold, 1):g})"
    if by == "odds":
        return (f"a {100 * chance(score):.1f} % chance, as the calibration's fit of its signals reads them, that the "
                f"estimate is off by more than 15 points (flagged over {100 * chance(threshold):.1f} %); its interval "
                f"is {100 * width:.0f} points wide")
    what = "reaches" if by == "reach" else "reaches down"
    return (f"interval {100 * width:.0f} points wide: it {what} {round(100 * score, 1):g} points from the estimate "
            f"(more than {round(100 * threshold, 1):g})")


def chance(log_odds: float) -> float:
    """The chance (a fraction) that log odds ``log_odds`` say."""
    return 1.0 / (1.0 + math.exp(-float(np.clip(log_odds, -50, 50))))


def fit_odds(x: np.ndarray, far: np.ndarray, weights: np.ndarray | None = None) -> list[float]:
    """Weighted logistic regression of ``far`` (1: an estimate off by more than 15 points) on features ``x`` ((n, p),
    the first column the intercept's ones), with a ridge penalty :data:`RIDGE` on the other weights; the weights
    ((p,)) whose ``x . b`` is the log odds (L-BFGS-B, through :func:`scipy.optimize.minimize`)."""
    from scipy.optimize import minimize

    x, y = np.asarray(x, float), np.asarray(far, float)
    w = np.ones(len(y)) if weights is None else np.asarray(weights, float)
    if not (w >= 0).all() or not w.sum() > 0:
        raise ValueError("the estimates' weights must be >= 0, not all 0")
    w = w / w.sum()

    def loss(b):
        z = x @ b
        pen = np.r_[0.0, b[1:]]
        grad = x.T @ (w * (1.0 / (1.0 + np.exp(-z)) - y)) + RIDGE * pen
        return float(np.sum(w * (np.logaddexp(0.0, z) - y * z))) + 0.5 * RIDGE * float(pen @ pen), grad

    res = minimize(loss, np.zeros(x.shape[1]), jac=True, method="L-BFGS-B")
    if not res.success:
        raise RuntimeError(f"the review's logistic fit did not converge: {res.message}")
    return [float(v) for v in res.x]
