"""Intervals for the segments of whole-colon maps, calibrated on maps of colons the network did not see (decision
record 0221).

    python scripts/map_intervals.py [--data data] [--model small] [--write] [--workers 2]

Maps ``<data>/colon-val``, ``<data>/colon-val-real`` and ``<data>/colon-val-real-more`` (the manifests' validation
splits, generated where missing) with completion as the whole-colon benchmark maps them (``colonbench evaluate --task colon --split
validation``: both tracks, 0 and 0.5 mm noise; each run kept in its dataset folder per model, manifest, steps and
calibration, and read again by the next call), keeps colon-val's procedural colons (``M_proc``: its maps of the real
training colons are left out) and the real validation colons' maps (``M_real``: gca00020, gca00070), and measures
three candidate intervals for a map's segments leave-one-colon-out: ``known``, the known-extent interval the map's
segments get from the model's calibration file, and split-conformal quantiles of ``true - map coverage`` per
``track`` and per ``track+band`` (the map's coverage below 0.8). Of those within 85-95 % in each cell (M_proc and
each real colon, each track, noise levels pooled), the narrowest on ``M_real`` (else the one whose worst cell lies
closest to 90 %). Prints how the map's own ``review`` flags did per cell: the share of the segments off by more
than 15 points it flags, and of its flags right, and chooses the map's own review threshold by decision record 0223's
rule (:func:`review_threshold`), then the pair of a width and a point rate by decision record 0224's
(:func:`review_pair`, :func:`pair_adopted`). With ``--write``, a chosen map candidate is fitted on all the maps and
written into the model's calibration file (``map``), with the review thresholds where they are adopted, which
``colonbench map`` then uses.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.benchmark.colon_evaluate import evaluate_colons
from colonbench.benchmark.runfolder import read_rows
from colonbench.completion import calfile, conformal, intervals
from colonbench.completion.method import model_path, steps_version
from colonbench.mapping.map_review import point_rates
from colonbench.shards.dataset import generate
from colonbench.shards.schema import sha256_file

ROOT = Path(__file__).resolve().parents[1] / "data_manifests"
#: The maps' datasets: manifest name -> the set its maps belong to.
DATASETS = {"colon-val": "M_proc", "colon-val-real": "M_real", "colon-val-real-more": "M_real"}
SCHEMES = ("known", "track", "track+band")
#: Decision record 0223 (0325's rule on the maps): the map's review threshold catches at least this share of the
#: segments off by more than BIG in each real validation colon.
REVIEW_RECALL, BIG = 0.75, 0.15
#: Decision record 0224: the pair (a width, a point rate) replaces the width alone where its flags on the real maps are
#: right this much more often (pooled), on neither real colon less often, and it flags at most PROC_FLAGS of the
#: procedural maps' segments.
PAIR_GAIN, PROC_FLAGS = 0.10, 0.05
#: The columns that tell one map (one reconstruction, track and noise level) from another within a dataset.
MAP = ["shard", "index", "context_mm", "noise_mm"]
#: A threshold of 0224's pair sits this far under a validation map segment's value: segments.csv rounds the planes'
#: arc lengths to 0.01 mm and the intervals to 1e-4, so the value ``colonbench map`` computes lies within it.
MARGIN = 1e-3


def map_segments(root: Path, name: str, model, cal_id: str, workers: int) -> pd.DataFrame:
    """Completion's map segments of ``<root>/<name>`` as the whole-colon benchmark scores them, with a coverage and
    a truth, and their ``point_rate`` within their map as ``colonbench map`` computes it, over every segment with a
    coverage (the run folder is kept per model, manifest, steps and calibration, and read again)."""
    manifest = ROOT / f"{name}.yaml"
    data = Path(root) / name
    generate(manifest, data, workers=workers, splits=["validation"], progress=False)
    key = f"{sha256_file(model_path(model))[:12]}-{sha256_file(manifest)[:8]}-{steps_version()}-{cal_id}"
    run = data / f"completion-maps-{key}"
    if not (run / "results" / "segments.csv").is_file():
        evaluate_colons(data, ["completion"], run, split="validation", model=model, progress=False)
    seg = read_rows(run / "results" / "segments.csv")
    seg = with_point_rates(seg[(seg["method"] == "completion") & np.isfinite(seg["coverage"])])
    seg = seg[np.isfinite(seg["true_coverage"])]
    return seg.rename(columns={"true_coverage": "true", "coverage": "estimate"}).reset_index(drop=True)


def group(row, scheme: str) -> str:
    """A map segment's group: its track kind, and under ``track+band`` the band of the map's coverage of it."""
    key = "track=context" if row["context_mm"] > 0 else "track=segment-only"
    if scheme == "track+band":
        key += f",below={next(b for b in intervals.BANDS if row['estimate'] < b):g}"
    return key


def fit(seg: pd.DataFrame, scheme: str, level: float) -> dict:
    """Each group's ``{"low", "high", "n"}`` residual quantiles, for the groups of ``scheme`` and of ``track`` with
    at least :data:`intervals.MIN_GROUP` rows (the coarser groups are the fallback, as
    :meth:`intervals.Intervals.quantiles` has it)."""
    out = {}
    for sch in dict.fromkeys(("track", scheme)):
        keys = seg.apply(group, axis=1, scheme=sch)
        for k in keys.unique():
            sel = (keys == k).to_numpy()
            if sel.sum() >= intervals.MIN_GROUP:
                low, high = conformal.conformal_quantiles(seg["true"][sel] - seg["estimate"][sel], level)
                out[k] = {"low": low, "high": high, "n": int(sel.sum())}
    return out


def intervals_of(seg: pd.DataFrame, scheme: str, groups: dict) -> np.ndarray:
    """(n, 2) intervals of map segments: ``known`` as the map gave them, else their group's quantiles around the map's
    coverage (the track's where the group had too few)."""
    if scheme == "known":
        return seg[["interval_low", "interval_high"]].to_numpy(float)
    keys = seg.apply(group, axis=1, scheme=scheme)
    q = np.array([[g["low"], g["high"]] for g in (groups.get(k) or groups.get(k.split(",")[0])
                                                  or {"low": -1.0, "high": 1.0} for k in keys)])
    return np.clip(seg["estimate"].to_numpy(float)[:, None] + q, 0, 1)


def by_colon(seg: pd.DataFrame, scheme: str, level: float) -> pd.DataFrame:
    """Each segment's held-out interval: fitted on the other colons' maps (``known``: fitted on no map)."""
    lohi = np.empty((len(seg), 2))
    for colon in seg["colon"].unique():
        test = (seg["colon"] == colon).to_numpy()
        groups = {} if scheme == "known" else fit(seg[~test], scheme, level)
        lohi[test] = intervals_of(seg[test], scheme, groups)
    out = seg.assign(low=lohi[:, 0], high=lohi[:, 1], width=lohi[:, 1] - lohi[:, 0])
    out["inside"] = (out["low"] - 1e-12 <= out["true"]) & (out["true"] <= out["high"] + 1e-12)
    out["track_kind"] = np.where(out["context_mm"] > 0, "context", "segment-only")
    out["cell"] = np.where(out["set"] == "M_real", out["colon"].astype(str), out["set"])
    return out


def flags(seg: pd.DataFrame) -> pd.DataFrame:
    """How the map's own ``review`` did per cell (a real colon, or M_proc) and track: segments, those off by more
    than 15 points, the share of them flagged (recall, %) and the share of flags on them (precision, %)."""
    seg = seg.assign(off=(seg["estimate"] - seg["true"]).abs() > 0.15, flag=seg["review"].fillna(0) > 0)
    seg = seg.assign(caught=seg["off"] & seg["flag"])
    out = seg.groupby(["cell", "track_kind"]).agg(n=("off", "size"), off=("off", "sum"), flagged=("flag", "sum"),
                                                  caught=("caught", "sum"))
    out["recall"] = (100 * out["caught"] / out["off"].clip(lower=1)).round(1)
    out["precision"] = (100 * out["caught"] / out["flagged"].clip(lower=1)).round(1)
    return out


def review_threshold(held: pd.DataFrame) -> float | None:
    """Decision record 0223's map review threshold: the largest interval width (fraction) at which flagging the
    segments of ``held`` (:func:`by_colon`'s) whose interval is wider catches at least :data:`REVIEW_RECALL` of the
    segments off by more than :data:`BIG` in each real validation colon (its tracks and noise levels pooled), less
    1e-6. The widths tried are the segments' to 4 decimals, as the segments' review threshold is chosen
    (``scripts/calibrate_intervals.py``); a width within 5e-5 under one of them may go unflagged. None where no
    width catches that many."""
    big = (held["estimate"] - held["true"]).abs() > BIG
    real = [held["cell"] == c for c in sorted(held.loc[held["set"] == "M_real", "cell"].unique())]
    for w in np.unique(np.round(held["width"], 4))[::-1]:
        flag = held["width"] > w - 1e-12
        if all((flag & big & c).sum() >= REVIEW_RECALL * (big & c).sum() for c in real):
            return float(w) - 1e-6
    return None


def review_report(held: pd.DataFrame, threshold: float, rate: float = np.inf) -> pd.DataFrame:
    """:func:`flags` of ``held`` were its segments flagged where their interval is wider than ``threshold`` (or, with
    ``rate``, their ``point_rate`` above it)."""
    flag = (held["width"] > threshold) | (held["point_rate"] > rate if "point_rate" in held else False)
    return flags(held.assign(review=flag.astype(int)))


def with_point_rates(seg: pd.DataFrame) -> pd.DataFrame:
    """``seg`` (one dataset's map segments with a coverage) with each segment's ``point_rate`` within its map
    (:func:`colonbench.mapping.map_review.point_rates`, as ``colonbench map`` computes it)."""
    rate = pd.Series(0.0, index=seg.index)
    for _, g in seg.groupby(MAP):
        rate[g.index] = point_rates(g["points"], g["start_mm"], g["end_mm"])
    return seg.assign(point_rate=rate)


def _just_under(values: np.ndarray) -> np.ndarray:
    """Thresholds :data:`MARGIN` under each distinct value of ``values`` (flagging it and all above), and infinity."""
    return np.concatenate([np.unique(values) - MARGIN, [np.inf]])


def review_pair(held: pd.DataFrame) -> tuple[float, float] | None:
    """Decision record 0224's pair: of the (width, point rate) thresholds at which flagging a segment whose interval
    is wider or whose ``point_rate`` is higher catches at least :data:`REVIEW_RECALL` of the far-off segments in each
    real validation colon, the one that flags fewest of the real maps' segments (ties: the larger width, then the
    larger rate, so each sits just under a real map segment's value: :data:`MARGIN` under it). None where none
    catches that many."""
    real = held[held["set"] == "M_real"]
    width, rate = real["width"].to_numpy(), real["point_rate"].to_numpy()
    far = ((real["estimate"] - real["true"]).abs() > BIG).to_numpy()
    cells = [(real["cell"] == c).to_numpy() & far for c in sorted(real["cell"].unique())]
    best = None
    for w in _just_under(width)[::-1]:
        by_width = width > w
        for t in _just_under(rate)[::-1]:
            flag = by_width | (rate > t)
            if all(flag[c].sum() >= REVIEW_RECALL * c.sum() for c in cells):
                if best is None or int(flag.sum()) < best[0]:
                    best = (int(flag.sum()), float(w), float(t))
                break                                  # a lower rate only flags more at this width
    return None if best is None else best[1:]


def pair_adopted(held: pd.DataFrame, threshold: float, pair: tuple[float, float]) -> tuple[bool, str]:
    """Decision record 0224's conditions on ``pair`` against the width alone (``threshold``): its flags right, pooled
    over the real colons, at least :data:`PAIR_GAIN` more; on neither real colon fewer; at most :data:`PROC_FLAGS` of
    the procedural maps' segments flagged. Returns the verdict and the figures it read."""
    far = (held["estimate"] - held["true"]).abs() > BIG
    old, new = held["width"] > threshold, (held["width"] > pair[0]) | (held["point_rate"] > pair[1])

    def right(flag, sel):
        return float((flag & far & sel).sum() / max(int((flag & sel).sum()), 1))
    real = held["set"] == "M_real"
    colons = [held["cell"] == c for c in sorted(held.loc[real, "cell"].unique())]
    gain = right(new, real) - right(old, real)
    each = [right(new, c) - right(old, c) for c in colons]
    proc = float(new[~real].mean()) if (~real).any() else 0.0
    ok = gain >= PAIR_GAIN and all(e >= 0 for e in each) and proc <= PROC_FLAGS
    return ok, (f"flags right {100 * right(new, real):.1f} % against {100 * right(old, real):.1f} % (pooled), "
                f"per real colon {', '.join(f'{100 * e:+.1f}' for e in each)} points; procedural flagged "
                f"{100 * proc:.1f} %")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data", help="folder holding (or to hold) the datasets (default: data)")
    ap.add_argument("--model", default=None, help="model (default: the shipped one)")
    ap.add_argument("--write", action="store_true", help="write the chosen map interval into the calibration file")
    ap.add_argument("--workers", type=int, default=2, help="processes generating the data")
    args = ap.parse_args()
    model = model_path(args.model)
    path, cal = calfile.path_for(model), calfile.load(model, steps=None)
    if cal is None or not cal.known:
        raise SystemExit("the model has no calibration file with a known-extent interval: run "
                         "scripts/calibrate_intervals.py first")
    parts = []
    for name, set_ in DATASETS.items():
        seg = map_segments(Path(args.data), name, args.model, cal.source.get("id", "none"), args.workers)
        parts.append(seg.assign(set=set_))
    seg = pd.concat(parts, ignore_index=True)
    seg = seg[(seg["set"] == "M_real") | seg["colon"].str.startswith("colon-")].reset_index(drop=True)
    print(f"{len(seg)} map segments of {seg['colon'].nunique()} colons; MAE per set and track (points):")
    print((100 * (seg["estimate"] - seg["true"]).abs()).groupby([seg["set"], seg["context_mm"] > 0]).mean().round(2)
          .to_string())
    summary, helds = {}, {}
    for scheme in SCHEMES:
        held = helds[scheme] = by_colon(seg, scheme, cal.level)
        cells = held.groupby(["cell", "track_kind"]).agg(n=("inside", "size"), inside=("inside", "mean"),
                                                          width=("width", "mean"))
        ok = bool(((cells["inside"] >= 0.85) & (cells["inside"] <= 0.95)).all())
        summary[scheme] = {"ok": ok, "worst": float((cells["inside"] - cal.level).abs().max()),
                           "real_width": float(held.loc[held["set"] == "M_real", "width"].mean())}
        print(f"\n{scheme}: every cell within 85-95 %: {ok}; M_real mean width "
              f"{100 * summary[scheme]['real_width']:.1f} points")
        print(cells.assign(inside=lambda d: (100 * d["inside"]).round(1), width=lambda d: (100 * d["width"]).round(1))
              .to_string())
        if scheme == "known":
            print(f"the map's review flags (a segment's interval wider than its calibration's):\n"
                  f"{flags(held).to_string()}")
    passing = [s for s in SCHEMES if summary[s]["ok"]]
    best = min(passing, key=lambda s: summary[s]["real_width"]) if passing else \
        min(SCHEMES, key=lambda s: summary[s]["worst"])
    print(f"\nchosen: {best}")
    held = helds[best]                                 # the review threshold on the chosen intervals (0223)
    threshold = review_threshold(held)
    adopted = threshold is not None and threshold > cal.review_known
    print("\nthe map's own review threshold (decision record 0223): "
          + (f"{100 * threshold:.1f} points, against the known extent's {100 * cal.review_known:.1f}: "
             f"{'adopted' if adopted else 'not adopted (no larger)'}\n{review_report(held, threshold).to_string()}"
             if threshold is not None else "none catches 75 % in each real colon"))
    pair = review_pair(held) if adopted else None
    pair_ok, said = pair_adopted(held, threshold, pair) if pair else (False, "no pair catches 75 % in each")
    if pair:
        print(f"\nwith the point rate (decision record 0224): width above {100 * pair[0]:.1f} points or point rate "
              f"above {pair[1]:.4f} ({np.exp(pair[1]):.2f} times): {said}: "
              f"{'adopted' if pair_ok else 'not adopted'}\n{review_report(held, *pair).to_string()}")
    if args.write:
        data = json.loads(path.read_text())
        data["map"] = {} if best == "known" else {"scheme": best, "groups": fit(seg, best, cal.level)}
        if adopted:
            data["map"]["review_width"] = round(min(pair[0], 1.0) if pair_ok else threshold, 6)   # 1: never by width
        if pair_ok:
            data["map"]["review_point_rate"] = round(pair[1], 6)
        data["source"].pop("id", None)                 # the calibration's id covers its map part too
        digest = hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:8]
        data["source"]["id"] = f"{data['scheme']}-{digest}"
        path.write_text(json.dumps(data, indent=1) + "\n")
        print(f"wrote the map interval into {path}")


if __name__ == "__main__":
    main()
