"""The quantile arithmetic and the scale fit of the completion method's intervals
(:mod:`colonbench.completion.intervals`).

Split-conformal quantiles of residuals (Vovk et al.; Angelopoulos and Bates, 2021), the same with weights (each colon
the unit: the pooled-CDF quantile of Dunn, Wasserman and Ramdas, 2022, decision record 0325), with a colon-level
shift term, and per band of a difficulty estimate (Mondrian conformal regression, Bostrom and Johansson, 2020;
decision record 0161); and the scale's log-linear fit to the residuals' size, by least squares or by the linear
quantile regression that fits it at its tail (decision record 0166).
Values are fractions of coverage or residuals over a scale; ``level`` is the nominal coverage.
"""

from __future__ import annotations

import math

import numpy as np

#: Values closer than this share of their size count as tied where a cut is put between values
#: (:func:`weighted_quantile`): another machine's kernels move a value by about 1e-16 of it.
TIED = 1e-9
#: Added to ``|true - estimated|`` before its log is fitted: a floor of the scale (fractions).
SCALE_FLOOR = 0.005


def conformal_quantiles(residuals, level: float) -> tuple[float, float]:
    """The split-conformal low and high quantiles of ``true - estimated`` residuals (fractions)."""
    r = np.sort(np.asarray(residuals, float))
    n = len(r)
    a = (1.0 - level) / 2.0
    lo = math.floor((n + 1) * a + 1e-9)          # (1 - 0.9) / 2 is 0.04999...: ranks at a float near-tie
    hi = math.ceil((n + 1) * (1.0 - a) - 1e-9)
    low = r[lo - 1] if lo >= 1 else -1.0      # too few residuals for the tail: the widest interval
    high = r[hi - 1] if hi <= n else 1.0
    return float(low), float(high)


def band_of(edges, log_scale) -> np.ndarray:
    """The band (0 .. len(edges)) of each log scale: band ``k`` holds those at or below the ``k``-th edge and above
    the one before."""
    return np.searchsorted(np.asarray(edges, float), log_scale, side="left")


def weighted_quantiles(values, weights, level: float) -> tuple[float, float]:
    """:func:`conformal_quantiles` of values carrying weights (colons as the unit, decision record 0325).

    Parameters
    ----------
    values : (n,) float
        Residuals (fractions) or scaled residuals.
    weights : (n,) float
        Each value's weight, >= 0, not all 0 (normalised here).
    level : float

    Returns
    -------
    (float, float)
        The low and high quantiles of the weighted distribution at the split-conformal ranks of the effective sample
        size ``(sum w)^2 / sum w^2`` (Kish's; with equal weights the unweighted ranks' quantiles); -1 or 1 where the
        sample is too small for a tail.
    """
    v, w = np.asarray(values, float), np.asarray(weights, float)
    order = np.argsort(v, kind="stable")
    v, w = v[order], w[order] / w.sum()
    n = 1.0 / float(np.sum(w ** 2))
    a = (1.0 - level) / 2.0
    lo, hi = math.floor((n + 1) * a + 1e-9) / n, math.ceil((n + 1) * (1.0 - a) - 1e-9) / n
    cum = np.cumsum(w)
    low = float(v[min(np.searchsorted(cum, lo - 1e-9), len(v) - 1)]) if lo > 0 else -1.0
    high = float(v[min(np.searchsorted(cum, hi - 1e-9), len(v) - 1)]) if hi <= 1.0 + 1e-9 else 1.0
    return low, high


def effective_size(weights) -> float:
    """Kish's effective sample size of weights ((n,), >= 0): ``(sum w)^2 / sum w^2``; 0 for none."""
    w = np.asarray(weights, float)
    return float(w.sum() ** 2 / max(float(np.sum(w ** 2)), 1e-300))


def weighted_quantile(values, weights, q: float = 0.5, between: bool = False) -> float:
    """The weighted ``q``-quantile of ``values`` (the first value at which the weights below reach ``q``);
    ``between``: the midpoint of it and the next value larger than it by more than :data:`TIED` of its size, a cut
    no value lies on or within float noise of, ties included (the quantile itself plus that margin where no value
    is larger)."""
    v, w = np.asarray(values, float), np.asarray(weights, float)
    order = np.argsort(v, kind="stable")
    ranked, cum = v[order], np.cumsum(w[order]) / w.sum()
    k = min(int(np.searchsorted(cum, q - 1e-12)), len(v) - 1)
    value = float(ranked[k])
    if not between:
        return value
    margin = TIED * max(1.0, abs(value))
    larger = ranked[k + 1:][ranked[k + 1:] > value + margin]
    return float((value + larger[0]) / 2.0) if len(larger) else value + margin


def shifted_quantiles(z: np.ndarray, level: float, weights, colons) -> tuple[float, float, dict]:
    """The low and high quantiles of scaled residuals ``z``: split-conformal (no weights), weighted, or (``colons``
    given too) those of ``z`` less its colon's median, shifted by the colons' medians' quartiles (the colon-level
    shift term, decision record 0325); and what the shift term recorded."""
    if weights is None:
        return (*conformal_quantiles(z, level), {})
    if colons is None:
        return (*weighted_quantiles(z, weights, level), {})
    colons = np.asarray(colons)
    names, index = np.unique(colons, return_inverse=True)
    medians = np.array([weighted_quantile(z[index == k], weights[index == k]) for k in range(len(names))])
    colon_weight = np.bincount(index, weights=weights)
    q1, q3 = weighted_quantile(medians, colon_weight, 0.25), weighted_quantile(medians, colon_weight, 0.75)
    low, high = weighted_quantiles(z - medians[index], weights, level)
    return low + q1, high + q3, {"shift_low": q1, "shift_high": q3}


def band_quantiles(z: np.ndarray, log_scale: np.ndarray, level: float, weights, colons, min_size: int,
                   cuts=(0.25, 0.5, 0.75)) -> dict:
    """Per band of the fitted scale (:func:`band_of`) the quantiles of the scaled residuals ``z`` in it
    (:func:`shifted_quantiles`). The edges lie between the log scales either side of their quantiles ``cuts``
    (weighted as the fit is), so no calibration estimate lies on one unless tied. A band whose effective size
    (Kish's, as :func:`weighted_quantiles` ranks) is under ``min_size`` gets the quantiles of all of ``z``
    (``low``, ``high``)."""
    w = np.ones(len(z)) if weights is None else np.asarray(weights, float)
    edges = [weighted_quantile(log_scale, w, q, between=True) for q in cuts]
    band = band_of(edges, log_scale)
    out = {"band_edges": edges, "band_low": [], "band_high": [], "band_n": []}
    out["low"], out["high"], _ = shifted_quantiles(z, level, weights, colons)
    for k in range(len(edges) + 1):
        sel = band == k
        low, high = out["low"], out["high"]
        if effective_size(w[sel]) >= min_size:
            low, high, _ = shifted_quantiles(z[sel], level, None if weights is None else w[sel],
                                      None if colons is None else np.asarray(colons)[sel])
        out["band_low"].append(low), out["band_high"].append(high), out["band_n"].append(int(sel.sum()))
    return out


def quantile_regression(x: np.ndarray, y: np.ndarray, tau: float, weights=None) -> np.ndarray:
    """Weighted linear quantile regression (Koenker and Bassett, 1978): the weights ``b`` ((p,)) minimising the
    pinball loss ``sum_i w_i rho_tau(y_i - x_i . b)``, solved as a linear programme (HiGHS, through
    :func:`scipy.optimize.linprog`); ``x . b`` estimates the ``tau``-quantile of ``y`` given ``x``.

    Parameters
    ----------
    x : (n, p) float
        Features (a column of ones for an intercept).
    y : (n,) float
    tau : float
        The quantile, in (0, 1).
    weights : (n,) float, optional
        Each row's weight, >= 0 (default: 1 each).
    """
    from scipy import sparse
    from scipy.optimize import linprog

    if not 0.0 < tau < 1.0:
        raise ValueError(f"a quantile regression's tau must lie in (0, 1), not {tau}")
    x, y = np.asarray(x, float), np.asarray(y, float)
    n, p = x.shape
    w = np.ones(n) if weights is None else np.asarray(weights, float)
    if w.shape != (n,) or not np.isfinite(w).all() or (w < 0).any() or not w.sum() > 0:
        raise ValueError(f"a quantile regression's weights must be {n} finite numbers >= 0, not all 0")
    w = w / float(np.mean(w))
    # variables: b (free), u >= 0 (above the fit), v >= 0 (below); x b + u - v = y
    eye = sparse.identity(n, format="csr")
    a_eq = sparse.hstack([sparse.csr_matrix(x), eye, -eye], format="csr")
    cost = np.concatenate([np.zeros(p), tau * w, (1.0 - tau) * w])
    bounds = [(None, None)] * p + [(0, None)] * (2 * n)
    res = linprog(cost, A_eq=a_eq, b_eq=y, bounds=bounds, method="highs")
    if res.status != 0:
        raise RuntimeError(f"quantile regression did not solve: {res.message}")
    return np.asarray(res.x[:p], float)


def log_scale_fit(x: np.ndarray, magnitude: np.ndarray, weights: np.ndarray | None = None,
                  tau: float | None = None) -> tuple[list, np.ndarray]:
    """(Weighted) least-squares weights of ``log(magnitude + SCALE_FLOOR)`` on ``x`` (``tau``: its ``tau``-quantile's
    linear regression instead, :func:`quantile_regression`), and the scales they give: ``x`` (n, p) features,
    ``magnitude`` (n,) a residual's size (fractions), ``weights`` (n,) or None."""
    if tau is not None:
        w = quantile_regression(x, np.log(magnitude + SCALE_FLOOR), tau, weights)
    else:
        root = np.sqrt(weights)[:, None] if weights is not None else 1.0
        w, *_ = np.linalg.lstsq(x * root, np.log(magnitude + SCALE_FLOOR) * np.ravel(root), rcond=None)
    return [float(v) for v in w], np.exp(np.clip(x @ w, -20, 5))
