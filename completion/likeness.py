"""Whether an estimate looks like one of the paper's simple colons: a Mondrian taxonomy for the intervals.

On the calibration's colons, an estimate of a paper-like colon and one of a real colon may get the same fitted scale
and still be off by different amounts: the scale, log-linear in the features, does not tell them apart, while a
logistic regression on the same features does (decision record 0170). A ``like<NN>+<scheme>`` calibration
(``like50+binned-colon-novel-depth-shift``) fits that regression (:func:`fit_like`: the chance that an estimate is
one of the paper-like calibration set's) and gives the estimates whose chance is over ``NN`` % a group of their own
(``like=1``) and the rest another (``like=0``), each fitted as ``<scheme>`` fits its one group. Any function of an
estimate's features may group it in Mondrian conformal prediction (Vovk, Gammerman and Shafer, *Algorithmic Learning
in a Random World*, 2005, chapter 4): each group's intervals hold for estimates like that group's calibration
estimates. :meth:`colonbench.completion.intervals.Intervals.quantiles` reads the group.
"""

from __future__ import annotations

import numpy as np

from colonbench.completion import intervals
from colonbench.completion.conformal import effective_size
from colonbench.completion.review import fit_odds


def split_scheme(scheme: str) -> tuple[float, str] | None:
    """The threshold (a chance, fraction) and the scheme each group is fitted with, of a ``like<NN>+<scheme>``
    scheme; None for any other scheme."""
    m = intervals.LIKE.match(scheme)
    return (int(m.group(1)) / 100.0, m.group(2)) if m else None


def base(scheme: str) -> str:
    """The scheme a ``like<NN>+<scheme>`` scheme fits each group with (its scale, and its known extent's); any other
    scheme itself."""
    parts = split_scheme(scheme)
    return parts[1] if parts else scheme


def fit_like(x: np.ndarray, like: np.ndarray, weights: np.ndarray, names, threshold: float) -> dict:
    """The likeness classifier: a weighted logistic regression (:func:`colonbench.completion.review.fit_odds`) of
    ``like`` on the features ``x``.

    Parameters
    ----------
    x : (n, p) float
        The estimates' features ``names`` (:func:`~colonbench.completion.intervals.features`; the first ``one``).
    like : (n,) bool
        Whether each estimate is one of the paper-like calibration set's.
    weights : (n,) float
        Each estimate's weight (the colon as the unit).
    names : sequence of str
    threshold : float
        The chance over which an estimate is ``like=1``.

    Returns
    -------
    dict
        ``{"features", "ranges", "weights", "threshold"}``, as :attr:`Intervals.like` holds it: the features are
        clipped into ``ranges`` before ``weights`` score them (:func:`~colonbench.completion.intervals.linear_score`).
    """
    like = np.asarray(like, bool)
    if like.all() or not like.any():
        raise ValueError("the likeness classifier needs estimates of the paper-like set and of others")
    return {"features": list(names), "ranges": [[float(a), float(b)] for a, b in zip(x.min(axis=0), x.max(axis=0))],
            "weights": fit_odds(x, like.astype(float), weights), "threshold": float(threshold)}


def fit(true, estimated, signals: list, scheme: str, review_width: float, level: float, weights, colons,
        like) -> intervals.Intervals:
    """Calibrate a ``like<NN>+<scheme>`` scheme: ``<scheme>``'s calibration (:func:`intervals.fit`, its pooled group
    ``all`` the fallback of a group with too few estimates), the likeness classifier (:func:`fit_like`) and a group
    ``like=1`` and ``like=0`` each fitted as ``<scheme>`` fits its one, with the whole fit's ``weights`` and
    ``colons`` ((n,) each). ``like``: (n,) bool, whether each estimate is one of the paper-like set's."""
    parts = split_scheme(scheme)
    if parts is None:
        raise ValueError(f"not a likeness scheme: {scheme!r} (like<NN>+<scheme>)")
    threshold, base = parts
    if not intervals.scale_features(base) or split_scheme(base):
        raise ValueError(f"a likeness scheme groups a scaled scheme's estimates, not {base!r} ({scheme!r})")
    cal = intervals.fit(true, estimated, signals, base, review_width, level, weights=weights, colons=colons)
    scaled, names = intervals._scaled(base), intervals.scale_features(base)
    estimated = np.asarray(estimated, float)
    x = np.array([intervals.features(c, s, names) for c, s in zip(estimated, signals)])
    w, c = intervals._unit_weights(base, weights, colons, len(estimated))
    cal.scheme, cal.like = scheme, fit_like(x, like, np.ones(len(x)) if w is None else w, names, threshold)
    group = np.array([intervals.looks_like(cal.like, e, s, f) for e, s, f in zip(estimated, signals, x)])
    residual = np.asarray(true, float) - estimated
    for value in (1, 0):
        sel = group == value
        if effective_size(np.ones(sel.sum()) if w is None else w[sel]) >= intervals.MIN_GROUP:
            cal.groups[f"like={value}"] = intervals.fit_subgroup(residual, x, names, level, scaled, w, c, sel)
    return cal
