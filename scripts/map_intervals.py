"""Intervals for the segments of whole-colon maps, calibrated on maps: measured, not shipped (decision record 0220).

    python scripts/map_intervals.py [--data data] [--model small] [--score RUN ...]

Maps ``<data>/colon-val`` (data_manifests/colon-val.yaml's validation split, generated where missing) with completion
as the whole-colon benchmark maps it (``colonbench evaluate --task colon --split validation``: both tracks, 0 and
0.5 mm noise; the run kept in ``<data>/colon-val/completion-maps-<model sha256>-<manifest sha256>-<steps>``, read
again by the next call: remove it after changing the map), and measures three candidate intervals for a map's
segments by the rule of decision record 0144 (as ``scripts/calibrate_intervals.py`` chooses the segments' scheme):
``known``, the known-extent interval the map's segments get (from the model's calibration file, not fitted on
maps), and split-conformal quantiles of ``true - map coverage`` per ``track`` (in context or segment-only) and per
``track+band`` (and the map's coverage below 0.8), each fitted on the colons of one half and measured on the other.
With ``--score``, each candidate fitted on all of colon-val is scored on the completion rows of whole-colon run
folders (such as ``colonbench evaluate --task colon``'s on colon-test.yaml, colon-v1), per track,
noise level and colon source.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.benchmark.colon_evaluate import evaluate_colons
from colonbench.benchmark.runfolder import read_rows
from colonbench.completion import intervals
from colonbench.completion.method import model_path, steps_version
from colonbench.reports.colon_leaderboard import colon_source
from colonbench.shards.dataset import generate
from colonbench.shards.schema import sha256_file

from calibrate_intervals import MANIFESTS, choose, even_half

COLON_MANIFEST = MANIFESTS[0].with_name("colon-val.yaml")
SCHEMES = ("known", "track", "track+band")


def map_segments(root: Path, model, workers: int) -> pd.DataFrame:
    """Completion's map segments of ``<root>/colon-val`` as the whole-colon benchmark scores them (the run folder
    is kept per model and steps and read again)."""
    data = Path(root) / COLON_MANIFEST.stem
    generate(COLON_MANIFEST, data, workers=workers, splits=["validation"], progress=False)
    key = f"{sha256_file(model_path(model))[:12]}-{sha256_file(COLON_MANIFEST)[:8]}-{steps_version()}"
    run = data / f"completion-maps-{key}"
    if not (run / "results" / "segments.csv").is_file():
        evaluate_colons(data, ["completion"], run, split="validation", model=model, progress=False)
    return completion_rows(run)


def completion_rows(run: Path) -> pd.DataFrame:
    """The completion rows of a whole-colon run folder that have a coverage and a truth."""
    seg = read_rows(Path(run) / "results" / "segments.csv")
    seg = seg[(seg["method"] == "completion") & np.isfinite(seg["coverage"]) & np.isfinite(seg["true_coverage"])]
    if seg.empty:
        raise SystemExit(f"{run}: no completion rows with a coverage and a truth (a whole-colon run of completion?)")
    return seg.rename(columns={"true_coverage": "true", "coverage": "estimate"}).reset_index(drop=True)


def group(row, scheme: str) -> str:
    """A map segment's group: its track kind, and under ``track+band`` the band of the map's coverage of it."""
    key = "track=context" if row["context_mm"] > 0 else "track=segment-only"
    if scheme == "track+band":
        key += f",below={next(b for b in intervals.BANDS if row['estimate'] < b):g}"
    return key


def fit(seg: pd.DataFrame, scheme: str, known: dict, level: float) -> dict:
    """Each group's (low, high) residual quantiles (:func:`intervals.conformal_quantiles`), for the groups of
    ``scheme`` and of ``track`` with at least :data:`intervals.MIN_GROUP` rows (as :func:`intervals.fit` keeps the
    coarser scheme's groups); ``known``'s for all rows."""
    if scheme == "known":
        return {"*": (known["low"], known["high"])}
    out = {}
    for sch in dict.fromkeys(("track", scheme)):
        keys = seg.apply(group, axis=1, scheme=sch)
        out.update({k: intervals.conformal_quantiles(seg["true"][keys == k] - seg["estimate"][keys == k], level)
                    for k in keys.unique() if (keys == k).sum() >= intervals.MIN_GROUP})
    return out


def scored(seg: pd.DataFrame, scheme: str, quantiles: dict) -> pd.DataFrame:
    """Per row: its group, whether the truth lies inside its interval (its group's, else its track's, as
    :meth:`intervals.Intervals.quantiles` falls back), and the interval's width (fractions)."""
    keys = seg.apply(group, axis=1, scheme="track" if scheme == "known" else scheme)
    q = np.array([quantiles.get("*") or quantiles.get(k) or quantiles.get(k.split(",")[0], (-1.0, 1.0))
                  for k in keys])
    lo, hi = np.clip(seg["estimate"] + q[:, 0], 0, 1), np.clip(seg["estimate"] + q[:, 1], 0, 1)
    return pd.DataFrame({"group": keys, "inside": (lo - 1e-12 <= seg["true"]) & (seg["true"] <= hi + 1e-12),
                         "width": hi - lo})


def held_out(seg: pd.DataFrame, scheme: str, known: dict, level: float) -> pd.DataFrame:
    """A candidate fitted on the colons of one half and measured on the other, both ways (``known`` on all)."""
    if scheme == "known":
        return scored(seg, scheme, fit(seg, scheme, known, level))
    half = even_half(seg["colon"])
    return pd.concat([scored(seg[b], scheme, fit(seg[a], scheme, known, level)) for a, b in ((half, ~half),
                                                                                            (~half, half))])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data", help="folder holding (or to hold) colon-val (default: data)")
    ap.add_argument("--model", default=None, help="model (default: the shipped one)")
    ap.add_argument("--score", nargs="*", default=[], help="whole-colon run folders to score the candidates on")
    ap.add_argument("--workers", type=int, default=2, help="processes generating the data")
    args = ap.parse_args()
    cal = intervals.load(model_path(args.model), steps=None)
    if cal is None or not cal.known:
        raise SystemExit("the model has no calibration file with a known-extent interval: run "
                         "scripts/calibrate_intervals.py first")
    seg = map_segments(Path(args.data), args.model, args.workers)
    print(f"{len(seg)} map segments of {seg['colon'].nunique()} colons ({COLON_MANIFEST.name}); MAE "
          f"{100 * (seg['estimate'] - seg['true']).abs().mean():.2f} points")
    best, _ = choose("map segments", {s: held_out(seg, s, cal.known, cal.level) for s in SCHEMES}, cal.level)
    print(f"\nthe rule of decision 0144 chooses: {best or 'none'}")
    for run in args.score:
        rows = completion_rows(Path(run))
        rows["source"] = colon_source(rows["colon"])
        for scheme in SCHEMES:
            s = scored(rows, scheme, fit(seg, scheme, cal.known, cal.level))
            table = rows.assign(inside=s["inside"].to_numpy(), width=100 * s["width"].to_numpy())
            for by in (["track", "noise_mm"], ["track", "noise_mm", "source"]):
                print(f"\n{run}, {scheme}, truth inside (%) and mean width (points) by {', '.join(by)}:")
                print(table.groupby(by).agg(n=("inside", "size"), inside=("inside", "mean"), width=("width", "mean"))
                      .assign(inside=lambda d: (100 * d["inside"]).round(1), width=lambda d: d["width"].round(1))
                      .to_string())


if __name__ == "__main__":
    main()
