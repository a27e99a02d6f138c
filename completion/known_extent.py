"""A segment of known extent: its arc length given (``--length-mm``), and the interval calibrated for it.

Where the cloud spans less than :data:`~colonbench.completion.intervals.SHORT_SHARE` of a length given, it stops
short of an end nobody saw, and :func:`known_length` scales the coverage by the share it spans (decision record
0155). :func:`fit_known` calibrates :attr:`~colonbench.completion.intervals.Intervals.known`, the interval of the
estimates whose extent is known (a length given, or a map's planes): one group over all of them, and (decision
records 0168 and 0222) with a length given, a group of the estimates it shortened (``short``) and one of those it
left as they were (``full``).
"""

from __future__ import annotations

import numpy as np

from colonbench.completion.intervals import (SCALE_FEATURES, Intervals, _scaled, _unit_weights, features,
                                             fit_subgroup, shortened_by_length)
from colonbench.errors import InputError

#: A known length shorter than the segment's span between its planes over this share is refused as not the
#: segment's: on the calibration set the span reaches 1.83 times the true length (planes pushed out past a cloud
#: without rims); a length typed in cm for mm is a tenth of the true one.
LONGEST_SHARE = 3.0
#: The known extent's extra features, per candidate (decision records 0163 and 0168; ``K0``: the scheme's own).
KNOWN_EXTRA = {"K0": (), "K1": ("share_off",), "K2": (), "K3": ("share_off",)}
#: The candidates whose estimates a given length shortened get their own group (decision record 0168).
KNOWN_SHORT = ("K2", "K3")


def length_share(span_mm: float, length_mm: float) -> float:
    """``signals["length_share"]`` of a segment spanning ``span_mm`` between its planes whose length ``length_mm`` is
    given (:func:`known_length`), to 4 decimals."""
    return round(float(span_mm) / float(length_mm), 4)


def known_length(est, length_mm: float) -> None:
    """Use a segment's known arc length (mm): where the segment's span between its planes (``signals["span_mm"]``:
    the method's line between them, run on straight to a plane beyond its end) is less than
    :data:`~colonbench.completion.intervals.SHORT_SHARE` of it, the cloud stops short of an end nobody saw, and the
    coverage is scaled by the share it spans (the rest of the tube counted unobserved; decision record 0155). Marks
    the estimate's extent as known."""
    if not (length_mm > 0 and np.isfinite(length_mm)):
        raise InputError(f"a segment's length must be a positive number of mm, got {length_mm}")
    span = float(est.signals["span_mm"])
    if span > LONGEST_SHARE * float(length_mm):
        raise InputError(f"a segment's length of {length_mm:g} mm cannot be this cloud's: it spans {span:.0f} mm "
                         f"between its planes, more than {LONGEST_SHARE:g} times that (a length in cm, not mm?)")
    est.signals.update(extent="known", length_share=length_share(span, length_mm))
    if shortened_by_length(est.signals) and np.isfinite(est.coverage):      # decided on the share as stored
        est.coverage = float(est.coverage) * span / float(length_mm)
        est.review.append(f"the cloud spans {span:.0f} of the segment's {length_mm:g} mm: the rest is counted "
                          "unobserved")


def shortened(signals: list) -> np.ndarray:
    """Whether :func:`known_length` shortened each estimate ((n,) bool;
    :func:`~colonbench.completion.intervals.shortened_by_length`)."""
    return np.array([shortened_by_length(s) for s in signals], bool)


def fit_known(cal: Intervals, true, estimated, signals: list | None = None, weights=None, colons=None,
              extra=(), short: bool = False) -> None:
    """Calibrate :attr:`Intervals.known` on segments estimated with their lengths known (:func:`known_length`),
    scaled and weighted as the calibration's scheme is (``signals``: the estimates' signals, needed then; with
    ``length_share`` where the length was given), its scale with the features ``extra`` too (:data:`KNOWN_EXTRA`).
    ``short``: besides the group of all (``known``, which a map's segments get), the estimates the length shortened
    (:func:`shortened`) get a group of their own, ``known["short"]``, and the rest ``known["full"]`` (decision
    records 0168 and 0222). Each group keeps the estimates' ``weights`` of the whole fit (not made again within
    it), and the features of ``known``, whose ranges hold theirs: what reads a calibration's features (the method's
    costly signals, :meth:`Intervals.longest_mm`) looks at ``known`` only."""
    residual = np.asarray(true, float) - np.asarray(estimated, float)
    scaled = _scaled(cal.scheme)
    if extra and not scaled:
        raise ValueError(f"interval scheme {cal.scheme!r} has no scale for the known extent's features {extra}")
    if short and signals is None:
        raise ValueError("a known extent with a group of its shortened estimates needs the estimates' signals")
    names = SCALE_FEATURES[scaled] + tuple(extra) if scaled else ()
    x = np.array([features(c, sig, names) for c, sig in zip(estimated, signals)]) if scaled else None
    weights, colons = _unit_weights(cal.scheme, weights, colons, len(residual))

    def group(sel):
        return fit_subgroup(residual, x, names, cal.level, scaled, weights, colons, sel)

    cut = shortened(signals) if short else np.zeros(len(residual), bool)
    if short and not (cut.any() and (~cut).any()):
        raise ValueError("a known extent with a group of its shortened estimates needs some of each kind")
    cal.known = group(np.ones(len(residual), bool))
    if short:
        cal.known.update(short=group(cut), full=group(~cut))
