"""Calibrate the completion method's coverage intervals on colons neither the network nor the calibration saw.

    python scripts/calibrate_intervals.py [--remake] [--data data] [--model small] [--level 0.9] [--workers 2]

Calibrates on the model's table of calibration estimates beside it (:mod:`colonbench.completion.caltable`, decision
record 0178): the same table gives the same calibration file on any machine. Where the model has none, or with
``--remake``, the table is made first: the calibration's datasets are generated where missing
(``<data>/<manifest>``, the manifests' validation splits): data_manifests/calibration.yaml's widened colons (``V_wide``:
no manifest trains on them; its segments of the real training colons are left out), calibration-paper.yaml's and
calibration-paper-more.yaml's colons of the paper's generator (``V_paper``) and validation-real.yaml, the real
validation colons gca00020 and gca00070 (``V_real``), with calibration-real.yaml's real training colons, which are
reported, never calibrated on (the network saw them); every segment is estimated by the completion method (its intervals
off, every signal on) at 0 and 0.5 mm noise, as the suites do, and ``--remake`` prints how the new table differs from
the old. The choice is decision records 0172's and 0174's rule. Every scheme is measured leave-one-colon-out (a colon's
estimates get the intervals of a calibration fitted on all the other colons), and so is each known-length candidate on
it (``K0``: the scheme's features, ``K1``: with the share of the length the span covers; ``K2``, ``K3``: the same with a
group of their own for the estimates the length shortened). Each (scheme, known extent) pair has sixteen cells
(``V_wide``, ``V_paper`` and each real colon on its own, at each noise level, for both intervals); a cell holds within
85-95 % inside, each edge moved out by its binomial standard error. Of the pairs whose cells all hold, the scheme
narrowest over the real colons with its narrowest known extent; else, for the shipped model, the scheme in use
(``KEEP``, decision record 0174) with its known extent the least outside, and for a model of your own (``--model``) the
pair the least outside. The review rules, each a score of the interval and its threshold, come from the same held-out
intervals, for the segments and for the known extent (decision record 0163); the segments' review is by the fitted odds
of a far-off estimate instead where, held out, those are right more often by more than 3 points (decision record 0167).
The chosen scheme is fitted on all three sets and written beside the model (``<model>.intervals.json``, every number to
9 significant digits), with the known-length interval fitted on the same segments with their true lengths. Prints every
scheme's held-out table.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion import calfile, caltable, intervals, known_extent, likeness, review
from colonbench.completion.choice import choose_pair, shortfall
from colonbench.completion.method import CompletionMethod, model_path, steps_version
from colonbench.errors import ColonbenchError
from colonbench.shards.dataset import generate
from colonbench.shards.reader import Shard
from colonbench.shards.schema import sha256_file

ROOT = Path(__file__).resolve().parents[1] / "data_manifests"
#: The calibration's datasets: manifest name -> the set its segments belong to (``train_real``: reported only).
MANIFESTS = {"calibration": "V_wide", "calibration-paper": "V_paper", "calibration-paper-more": "V_paper",
             "validation-real": "V_real", "calibration-real": "train_real"}
CALIBRATED = ("V_wide", "V_paper", "V_real")
#: Decision records 0325's, 0161's, 0165's, 0166's, 0170's and 0172's candidates. 0175's three with the rims' fill
#: (``...-depth-fill-shift``) held no more cells and left: the file records every candidate's cells.
SCHEMES = ("scaled", "scaled-colon", "scaled-colon-novel", "scaled-colon-novel-shift", "scaled2-colon-novel",
           "scaled2-colon-novel-shift", "binned-colon-novel", "binned-colon-novel-shift",
           "scaled2-colon-novel-gaps-shift", "binned-colon-novel-gaps-shift", "scaled2-colon-novel-depth-shift",
           "binned-colon-novel-depth-shift", "scaled2-colon-novel-misfit-shift", "binned-colon-novel-misfit-shift",
           "quant95-colon-novel-misfit-shift", "quant90-colon-novel-misfit-shift",
           "like50+binned-colon-novel-depth-shift", "like80+binned-colon-novel-depth-shift",
           "like50+scaled2-colon-novel-misfit-shift", "like80+scaled2-colon-novel-misfit-shift")
#: Decision record 0174: the scheme in use, kept unless some (scheme, known extent) pair holds all sixteen cells.
KEEP = "like50+binned-colon-novel-depth-shift"
#: Decision record 0167: by how many points of the lower real colon's precision the review by odds must beat the
#: interval's score to replace it.
ODDS_GAIN = 3.0
NOISE_MM = (0.0, 0.5)
#: The signals an estimate's interval may be scaled by, as columns of the estimates' table.
SIGNALS = ("rims", "rims_doubtful", "gap_share", "length_mm", "span_mm", "spread", "radius_mm", "extent_mm",
           "hole_depth_mm", "wall_misfit_mm", "rim_fill")
#: The review rule (decision record 0325): flag at least this share of the estimates off by more than BIG in each
#: real colon held out and in V_wide.
REVIEW_RECALL, BIG = 0.75, 0.15
#: The real calibration colons by id (colon_id = 900000 + the atlas number).
REAL_NAMES = {900020: "gca00020", 900070: "gca00070"}
#: Colon ids of real meshes start here (data_manifests: 900000 + the atlas number).
REAL_IDS = 900000


def calibration_data(root: Path, workers: int = 2) -> list[tuple[str, Path]]:
    """(manifest name, folder) of each calibration dataset, generated under ``root`` where missing."""
    root = Path(root)
    if (root / "manifest.yaml").is_file():
        raise SystemExit(f"--data {root} is a single dataset: give the folder that holds (or is to hold) "
                         f"{' and '.join(m + '/' for m in MANIFESTS)}, the calibration's datasets (default: data)")
    out = []
    for name in MANIFESTS:
        data = root / name
        generate(ROOT / f"{name}.yaml", data, workers=workers, splits=["validation"], progress=False)
        out.append((name, data))
    return out


def estimates(data: Path, method: CompletionMethod) -> pd.DataFrame:
    """Completion's estimate of every validation segment of ``data`` at every noise level, with its signals."""
    _, picks = select(data, "validation")
    rows = []
    for name, indices in picks:
        with Shard(data / name) as shard:
            for i in indices:
                geo = shard.geometry(i)
                for sigma in NOISE_MM:
                    try:
                        est = method.estimate(noisy(geo["partial_points"], sigma, 0, name, i))
                    except ColonbenchError as exc:     # counted, not calibrated on
                        print(f"{name} {i} at {sigma:g} mm: no estimate ({exc})", flush=True)
                        continue
                    rows.append({"shard": name, "index": i, "colon_id": geo["colon_id"], "noise_mm": sigma,
                                 "hole_model": geo["hole_model"], "segment_mm": geo["length_mm"],
                                 "true": geo["coverage"], "estimate": est.coverage,
                                 **{k: est.signals.get(k, np.nan) for k in SIGNALS}})
        print(f"{name}: {len(rows)} estimates", flush=True)
    out = pd.DataFrame(rows)
    return out[np.isfinite(out["estimate"])]            # an empty completed surface gives no estimate


def signals_of(row) -> dict:
    return {k: float(row[k]) for k in SIGNALS if k in row and np.isfinite(row[k])}


def signals(df: pd.DataFrame) -> list[dict]:
    return [signals_of(r) for _, r in df.iterrows()]


def known_estimates(df: pd.DataFrame, sig: list[dict] | None = None) -> np.ndarray:
    """The estimates with each segment's true length given, as :func:`known_extent.known_length` scales them
    (``sig``: their :func:`known_signals`, where already made)."""
    share = df["span_mm"] / df["segment_mm"]
    sig = known_signals(df) if sig is None else sig
    return np.where(known_extent.shortened(sig), df["estimate"] * share, df["estimate"]).astype(float)


def unit_weights(df: pd.DataFrame) -> np.ndarray:
    """Each estimate's weight with the colon as the unit (decision record 0325): every set of ``df`` weighs the
    same, every colon of a set the same, every estimate of a colon the same; they sum to 1."""
    n_sets = df["set"].nunique()
    colons_in_set = df.groupby("set")["colon"].transform("nunique")
    per_colon = df.groupby("colon")["colon"].transform("size")
    return (1.0 / (n_sets * colons_in_set * per_colon)).to_numpy(float)


def known_signals(df: pd.DataFrame) -> list[dict]:
    """The estimates' signals with each segment's true length given: ``length_share`` as
    :func:`known_extent.known_length` sets it."""
    return [{**s, "length_share": known_extent.length_share(span, length)}
            for s, span, length in zip(signals(df), df["span_mm"], df["segment_mm"])]


def by_colon(df: pd.DataFrame, scheme: str, level: float, known: bool = False, extra=(),
             short: bool = False) -> pd.DataFrame:
    """``df`` with each row's interval (``low``, ``high``) from a calibration fitted on the other colons
    (leave-one-colon-out); ``known``: the known-length interval around the length-scaled estimate, its scale with
    the features ``extra`` too (decision record 0163); ``short``: the estimates the length shortened in a group of
    their own (decision record 0168)."""
    out = df.copy()
    sig = known_signals(df) if known else signals(df)
    est = known_estimates(df, sig) if known else df["estimate"].to_numpy(float)
    out["estimate_used"] = est
    low, high = np.empty(len(df)), np.empty(len(df))
    colons = df["colon"].to_numpy()
    for colon in np.unique(colons):
        fit_on, test_on = np.flatnonzero(colons != colon), np.flatnonzero(colons == colon)
        sig_fit, part = [sig[k] for k in fit_on], df.iloc[fit_on]
        w, c = unit_weights(part), colons[fit_on]
        if known:
            cal = intervals.Intervals(scheme, level, {}, 1.0)
            known_extent.fit_known(cal, df["true"].to_numpy(float)[fit_on], est[fit_on], sig_fit, w, c, extra, short)
        else:
            cal = fit_scheme(part, est[fit_on], sig_fit, scheme, 1.0, level, w, c)
        for k in test_on:
            s = {**sig[k], "extent": "known"} if known else sig[k]
            low[k], high[k] = cal.interval(est[k], s)
    out["low"], out["high"] = low, high
    out["inside"] = (out["low"] - 1e-12 <= out["true"]) & (out["true"] <= out["high"] + 1e-12)
    out["width"] = out["high"] - out["low"]
    return out


def fit_scheme(part: pd.DataFrame, estimated: np.ndarray, sig: list[dict], scheme: str, review_width: float,
               level: float, weights: np.ndarray, colons: np.ndarray) -> intervals.Intervals:
    """A scheme calibrated on ``part``'s estimates (``estimated``, their signals ``sig``, weights and colons); a
    likeness scheme (:mod:`colonbench.completion.likeness`) learns which of them are ``V_paper``'s (decision record
    0170)."""
    true = part["true"].to_numpy(float)
    if likeness.split_scheme(scheme):
        return likeness.fit(true, estimated, sig, scheme, review_width, level, weights, colons,
                            (part["set"] == "V_paper").to_numpy())
    return intervals.fit(true, estimated, sig, scheme, review_width, level, weights=weights, colons=colons)


def cells(held: pd.DataFrame) -> pd.DataFrame:
    """Truth inside (%), mean width (points) and count per cell (a set, or a real colon held out) and noise level of
    held-out intervals."""
    return held.groupby(["cell", "noise_mm"]).agg(n=("inside", "size"), inside=("inside", "mean"),
                                                  width=("width", "mean")).assign(
        inside=lambda d: (100 * d["inside"]).round(1), width=lambda d: (100 * d["width"]).round(1))


def real_width(held: pd.DataFrame) -> float:
    """Mean held-out width (points) over the real colons, each colon counted once."""
    real = held[held["set"] == "V_real"]
    return round(100 * float(real.groupby("cell")["width"].mean().mean()), 2) if len(real) else float("nan")


def summarise(held: dict, level: float, show: bool = True) -> dict:
    """Each candidate's held-out cells, as :mod:`colonbench.completion.choice` reads them.

    Parameters
    ----------
    held : dict
        Candidate -> its held-out intervals (:func:`by_colon`).
    level : float
        The intervals' level (``worst_off``: the cell furthest from it, points).
    show : bool
        Print each candidate's table too.

    Returns
    -------
    dict
        Candidate -> ``cells`` (truth inside %, width in points and count per calibrated set or real colon and noise
        level, :func:`cells`), ``ok`` (every cell within 85-95 % as 0161 had it), ``worst_off``, ``real_width``
        (points), ``lowest`` (%) and ``shortfall`` (decision record 0172, points).
    """
    summary = {}
    for name, h in held.items():
        c = cells(h[h["set"].isin(CALIBRATED)])
        summary[name] = {"cells": {f"{s} {n:g} mm": {"n": int(r["n"]), "inside": float(r["inside"]),
                                                     "width": float(r["width"])} for (s, n), r in c.iterrows()},
                         "ok": bool(((c["inside"] >= 85) & (c["inside"] <= 95)).all()),
                         "worst_off": round(float((c["inside"] - 100 * level).abs().max()), 1),
                         "real_width": real_width(h), "lowest": float(c["inside"].min())}
        summary[name]["shortfall"] = shortfall(summary[name])
        if show:
            print(f"\n{name}: outside its cells' bands by {summary[name]['shortfall']} points (decision record "
                  f"0172); real colons' mean width {summary[name]['real_width']} points\n{c.to_string()}")
    return summary


def review_cells(held: pd.DataFrame) -> list[str]:
    """The cells the review width must catch in: each real colon held out, and V_wide."""
    return sorted(c for c in held["cell"].unique() if c.startswith("V_real ")) + ["V_wide"]


def review_width(held: pd.DataFrame, by: str = "width", score: pd.Series | None = None) -> tuple[float, dict]:
    """0325's review width: the largest at which the held-out intervals flag at least :data:`REVIEW_RECALL` of the
    estimates off by more than :data:`BIG` in each of :func:`review_cells` (else the one closest in the worst);
    with each cell's recall and precision there. ``by``: what an interval is scored by
    (:func:`intervals.review_score`, decision record 0163); ``score``: each estimate's score, given (the held-out
    log odds of decision record 0167)."""
    big = (held["true"] - held["estimate_used"]).abs() > BIG
    if score is None:
        score = pd.Series([intervals.review_score(c, lo, hi, by) for c, lo, hi in
                           zip(held["estimate_used"], held["low"], held["high"])], index=held.index)
    sets = {name: held["cell"] == name for name in review_cells(held)}
    best, best_recall = 0.0, -1.0
    for w in np.unique(np.round(score, 4))[::-1]:
        flag = score > w - 1e-12
        recall = min(float((flag & big & s).sum() / max((big & s).sum(), 1)) for s in sets.values())
        if recall >= REVIEW_RECALL:
            best = float(w)
            break
        if recall > best_recall:
            best, best_recall = float(w), recall
    flag = score > best - 1e-12
    report = {}
    for name, s in {**sets, **{c: held["cell"] == c for c in held["cell"].unique() if c not in sets}}.items():
        report[name] = {"recall": round(float((flag & big & s).sum() / max((big & s).sum(), 1)), 3),
                        "precision": round(float((flag & big & s).sum() / max((flag & s).sum(), 1)), 3),
                        "flagged": round(float((flag & s).sum() / max(s.sum(), 1)), 3), "off": int((big & s).sum())}
    return best - 1e-6, report


def choose_review(reviews: dict, cells_caught: list[str]) -> str:
    """0163's rule: of the review scores whose threshold flags :data:`REVIEW_RECALL` of the far-off estimates in each
    of ``cells_caught``, the one whose lower precision over the real colons held out is highest; else the one with
    the highest lowest recall; a tie keeps the first (``width``). ``reviews``: score -> (threshold, report)."""
    real = [c for c in cells_caught if c.startswith("V_real ")]
    recall = {by: min(r[c]["recall"] for c in cells_caught) for by, (_, r) in reviews.items()}
    precision = {by: min(r[c]["precision"] for c in real) for by, (_, r) in reviews.items()}
    meets = [by for by in reviews if recall[by] >= REVIEW_RECALL]
    key = precision if meets else recall
    return max(meets or list(reviews), key=lambda by: key[by])       # max keeps the first of equals


def said(report: dict) -> str:
    """A review's held-out report (:func:`review_width`) in words, a cell after another."""
    return "; ".join(f"{k} recall {100 * v['recall']:.0f} % of {v['off']}, precision {100 * v['precision']:.0f} %, "
                     f"flagged {100 * v['flagged']:.0f} %" for k, v in report.items())


def review_rule(held: pd.DataFrame, label: str) -> tuple[str, float, dict, dict]:
    """0163's review rule on held-out intervals: each score's threshold (:func:`review_width`), printed, and the score
    :func:`choose_review` takes; returns the score, its threshold, its report, and every score's (threshold,
    report)."""
    reviews = {by: review_width(held, by) for by in review.INTERVAL_SCORES}
    for by, (w_by, r_by) in reviews.items():
        print(f"\n{label}, review by {by}: threshold {100 * w_by:.1f} points: {said(r_by)}")
    by = choose_review(reviews, review_cells(held))
    print(f"\n{label}: reviewed by {by} over {100 * reviews[by][0]:.1f} points")
    return by, reviews[by][0], reviews[by][1], reviews


def odds_features(df: pd.DataFrame, names) -> np.ndarray:
    """The estimates' features ``names`` ((n, p), :func:`intervals.features`), as the review's odds read them."""
    return np.array([intervals.features(c, s, names) for c, s in zip(df["estimate"], signals(df))])


def fit_odds(df: pd.DataFrame, names, x: np.ndarray | None = None) -> dict:
    """Decision record 0167's review odds fitted on ``df``'s estimates, the colon as the unit (``x``: their features
    ``names``, :func:`odds_features`, where already made)."""
    x = odds_features(df, names) if x is None else x
    far = ((df["true"] - df["estimate"]).abs() > BIG).to_numpy(float)
    return {"features": list(names), "ranges": [[float(a), float(b)] for a, b in zip(x.min(axis=0), x.max(axis=0))],
            "weights": review.fit_odds(x, far, unit_weights(df))}


def held_odds(df: pd.DataFrame, names) -> pd.Series:
    """Each estimate's log odds of being far off from a fit on the other colons (leave-one-colon-out)."""
    x, out, colons = odds_features(df, names), np.empty(len(df)), df["colon"].to_numpy()
    for colon in np.unique(colons):
        fit_on = colons != colon
        model = fit_odds(df[fit_on], names, x[fit_on])
        out[~fit_on] = [intervals.linear_score(model, f) for f in x[~fit_on]]
    return pd.Series(out, index=df.index)


def odds_rule(held: pd.DataFrame, names, by: str, report: dict) -> tuple[float, dict] | None:
    """Decision record 0167's rule: the review by odds (its held-out threshold and report) where it catches
    :data:`REVIEW_RECALL` in each of :func:`review_cells` and the lower of the real colons' precision beats the chosen
    score's (``by``, its ``report``) by more than :data:`ODDS_GAIN` points; else None."""
    width, odds = review_width(held, "odds", held_odds(held, names))
    real = [c for c in review_cells(held) if c.startswith("V_real ")]
    gain = 100 * (min(odds[c]["precision"] for c in real) - min(report[c]["precision"] for c in real))
    catches = min(odds[c]["recall"] for c in review_cells(held)) >= REVIEW_RECALL     # at the same catch
    adopted = catches and gain > ODDS_GAIN + 1e-9          # more than the gain: exactly ODDS_GAIN is not
    print(f"\nreview by odds: threshold {width:.3f}: {said(odds)}; against {by}: {gain:+.1f} points of the lower "
          f"real precision ({'adopted' if adopted else 'not adopted'}: more than {ODDS_GAIN:g} needed, at "
          f"{100 * REVIEW_RECALL:.0f} % caught in each cell)")
    return (width, odds) if adopted else None


def with_units(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with ``colon`` (a set's colon: the unit held out) and ``cell`` (its set, a real colon on its own)."""
    real = df["set"] == "V_real"
    names = df["colon_id"].map(lambda c: REAL_NAMES.get(int(c), str(int(c))))
    return df.assign(colon=df["set"] + ":" + df["colon_id"].astype(int).astype(str),
                     cell=np.where(real, "V_real " + names, df["set"]))


def keep_for(model: str | None) -> str | None:
    """The scheme a calibration keeps where no pair holds (decision record 0174): the shipped model's ``KEEP``; none
    for a model of your own (``--model``), which 0172's rule alone chooses for."""
    return KEEP if model is None else None


def calibrate(df: pd.DataFrame, level: float, source: dict, keep: str | None = None) -> intervals.Intervals:
    """Choose, fit and describe the calibration from the estimates' table (columns of :func:`estimates` and ``set``,
    :data:`MANIFESTS`' values); prints every figure it chooses by. ``keep``: the scheme kept where no pair holds
    (:func:`keep_for`)."""
    df = with_units(df)
    cal_df = df[df["set"].isin(CALIBRATED)].reset_index(drop=True)
    print("estimates per set:", df["set"].value_counts().to_dict())
    for name, g in df.groupby("cell"):
        print(f"{name}: {g['colon_id'].nunique()} colons, {len(g)} estimates, MAE "
              f"{100 * (g['estimate'] - g['true']).abs().mean():.2f} points, bias "
              f"{100 * (g['estimate'] - g['true']).mean():+.2f}")
    held = {scheme: by_colon(cal_df, scheme, level) for scheme in SCHEMES}
    summary = summarise(held, level)
    known_held, known_summaries = {}, {}
    for scheme in SCHEMES:          # the known extent reads the scale of a likeness scheme's base (0170)
        base = likeness.base(scheme)
        if base not in known_held:
            known_held[base] = {k: by_colon(cal_df, base, level, known=True, extra=e,
                                            short=k in known_extent.KNOWN_SHORT)
                                for k, e in known_extent.KNOWN_EXTRA.items()}
            known_summaries[base] = summarise(known_held[base], level, show=False)
        known_summaries[scheme] = known_summaries[base]
    best, known_choice, pairs = choose_pair(summary, known_summaries, keep)
    print("\nthe pairs nearest to holding every cell (decision records 0172 and 0174: shortfall, then real widths, "
          "points):\n"
          + pd.DataFrame(pairs).sort_values(["shortfall", "width", "known_width"], kind="stable").head(12).to_string())
    known_held, known_summary = known_held[likeness.base(best)], known_summaries[best]
    print(f"\nchosen: {best} with the known extent {known_choice}"
          + ("" if any(p["holds"] for p in pairs) or keep is None
             else " (no pair holds: the scheme in use stays, 0174)")
          + "\nknown length, held out:")
    summarise({known_choice: known_held[known_choice]}, level)
    by, width, review_report, reviews = review_rule(held[best], best)
    odds = odds_rule(held[best], intervals.scale_features(best), by, review_report)
    by_known, known_width, known_review, known_reviews = review_rule(known_held[known_choice],
                                                                     f"known length {known_choice}")
    w, c = unit_weights(cal_df), cal_df["colon"].to_numpy()
    cal = fit_scheme(cal_df, cal_df["estimate"].to_numpy(float), signals(cal_df), best, width, level, w, c)
    known_sig = known_signals(cal_df)
    known_extent.fit_known(cal, cal_df["true"], known_estimates(cal_df, known_sig), known_sig, w, c,
                           known_extent.KNOWN_EXTRA[known_choice], known_choice in known_extent.KNOWN_SHORT)
    cal.review_known, cal.review_by, cal.review_by_known = known_width, by, by_known
    if odds is not None:
        cal.review_by, (cal.review_width, review_report) = "odds", odds
        cal.review_odds = fit_odds(cal_df, intervals.scale_features(best))
    reported = df[df["set"] == "train_real"]
    if len(reported):                    # never calibrated on: the calibration's intervals, held out by construction
        lo_hi = np.array([cal.interval(c, s) for c, s in zip(reported["estimate"], signals(reported))])
        inside = (lo_hi[:, 0] - 1e-12 <= reported["true"]) & (reported["true"] <= lo_hi[:, 1] + 1e-12)
        print(f"\nthe real training colons (not calibrated on): truth inside {100 * inside.mean():.1f} %, mean width "
              f"{100 * (lo_hi[:, 1] - lo_hi[:, 0]).mean():.1f} points")
    cal.source = {**source, "held_out": "leave-one-colon-out over the colons of " + ", ".join(CALIBRATED),
                  "colons": {s: sorted(int(c) for c in cal_df.loc[cal_df["set"] == s, "colon_id"].unique())
                             for s in CALIBRATED},
                  "not_calibrated_on": "the real training colons (calibration-real.yaml and calibration.yaml's real "
                                       "segments): the network saw them",
                  "schemes": summary, "review": review_report, "known_review": known_review,
                  "review_scores": {k: {"threshold": round(float(v[0]), 6), "cells": v[1]} for k, v in reviews.items()},
                  "review_odds_held_out": "adopted (decision record 0167)" if odds else "not adopted",
                  "review_known_for": "a map's segments and a length given (decision record 0163, round 8)",
                  "known_features": known_choice, "known_candidates": known_summary,
                  "pairs": "decision record 0172: each (scheme, known extent) pair's cells within their bands",
                  "known_review_scores": {k: {"threshold": round(float(v[0]), 6), "cells": v[1]}
                                          for k, v in known_reviews.items()},
                  "known_held_out": {f"{s} {n:g} mm": {"inside": float(r["inside"]), "width": float(r["width"])}
                                     for (s, n), r in cells(known_held[known_choice]).iterrows()}}
    cal = intervals.Intervals(**calfile.rounded(cal.to_json()))
    digest = hashlib.sha256(json.dumps(cal.to_json(), sort_keys=True).encode()).hexdigest()[:8]
    cal.source["id"] = f"{best}-{digest}"
    return cal


def table(data: list[tuple[str, Path]], method: CompletionMethod) -> pd.DataFrame:
    """Every calibration dataset's estimates (:func:`estimates`), each row with its ``manifest`` first."""
    parts = [estimates(folder, method).assign(manifest=name) for name, folder in data]
    return pd.concat([p[["manifest", *p.columns[:-1]]] for p in parts], ignore_index=True)


def with_sets(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with each row's ``set`` (:data:`MANIFESTS`): the widened manifest's segments of the real training colons
    are ``train_real``."""
    if not df["manifest"].isin(list(MANIFESTS)).all():
        raise ColonbenchError(f"the table's rows must come from {', '.join(MANIFESTS)}, not "
                              f"{', '.join(sorted(set(df['manifest'].astype(str)) - set(MANIFESTS)))}")
    out = df.assign(set=df["manifest"].map(MANIFESTS))
    out.loc[(out["manifest"] == "calibration") & (out["colon_id"] >= REAL_IDS), "set"] = "train_real"
    return out


def table_source(path: Path) -> dict:
    """What a model's table of calibration estimates is made of (:func:`caltable.write`): the model file's and the
    manifests' sha256, the method's steps and the signals."""
    return {"model_sha256": sha256_file(path), "steps": steps_version(), "signals": list(SIGNALS),
            "manifests": {f"{m}.yaml": sha256_file(ROOT / f"{m}.yaml") for m in MANIFESTS}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data", help="folder of the calibration's datasets (default: data)")
    ap.add_argument("--model", default=None, help="model (default: the shipped one)")
    ap.add_argument("--level", type=float, default=intervals.LEVEL)
    ap.add_argument("--workers", type=int, default=2, help="processes generating the data")
    ap.add_argument("--remake", action="store_true", help="generate the data and estimate every segment again, "
                    "though the model has its table of calibration estimates")
    args = ap.parse_args()
    method = CompletionMethod(args.model)
    method.intervals, method.spread, method.hole_depth, method.misfit = None, True, True, True   # every signal
    path = model_path(args.model)
    saved = caltable.path_for(path, steps_version())
    made_of = table_source(path)
    if args.remake or not saved.is_file():        # decision record 0178: calibrated on the table as read back
        made = table(calibration_data(Path(args.data), args.workers), method)
        if saved.is_file():
            try:
                print(f"estimated again, against {saved.name}: {caltable.compare(caltable.read(saved), made)}")
            except ColonbenchError as exc:
                print(f"the table before could not be read ({exc}): not compared")
        caltable.write(made, saved, made_of)
        print(f"wrote {saved}")
    else:
        print(f"calibrating on {saved} (--remake: the segments estimated again)")
    df = with_sets(caltable.read(saved, SIGNALS, made_of))
    source = {"model": path.name, "model_sha256": made_of["model_sha256"], "steps": made_of["steps"],
              "manifests": made_of["manifests"], "noise_mm": list(NOISE_MM),
              "estimates": int(df["set"].isin(CALIBRATED).sum()),
              "estimates_table": saved.name, "estimates_sha256": sha256_file(saved)}
    cal = calibrate(df, args.level, source, keep_for(args.model))
    out = calfile.path_for(path)
    out.write_text(json.dumps(cal.to_json(), indent=1) + "\n")
    print(f"\nwrote {out} (id {cal.source['id']})")


if __name__ == "__main__":
    try:
        main()
    except ColonbenchError as exc:
        raise SystemExit(f"calibrate_intervals: {exc}") from None
