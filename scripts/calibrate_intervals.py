"""Calibrate the completion method's coverage intervals: split-conformal on data_manifests/calibration.yaml.

    python scripts/calibrate_intervals.py [--data data/calibration] [--model small] [--level 0.9]

Generates the calibration set where missing (its validation split: widened colons no manifest trains on, a tenth
video partials, the real training colons), estimates every segment with the completion method (its intervals
off) at 0 and 0.5 mm noise (the suites' levels, the noise drawn as colonbench evaluate draws it), and chooses the
grouping by a rule fixed before the measurement (decision record 0144): each candidate scheme is fitted on the
colons of one half and measured on the other, both ways; of the schemes whose held-out coverage lies within 4
points of the level in every group of at least 30 segments, the one with the smallest mean width wins (else the
marginal one). It is then fitted on all segments and written beside the model (``<model>.intervals.json``).
Prints the held-out coverage and width of every scheme.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion import intervals
from colonbench.completion.method import CompletionMethod, model_path, steps_version
from colonbench.errors import ColonbenchError
from colonbench.shards.dataset import generate
from colonbench.shards.reader import Shard
from colonbench.shards.schema import sha256_file

MANIFEST = Path(__file__).resolve().parents[1] / "data_manifests" / "calibration.yaml"
SCHEMES = ("marginal", "rims", "length", "length+band", "length+rims")
NOISE_MM = (0.0, 0.5)
#: An interval wider than this flags its estimate for review: the truth may lie 20 points or more away (the
#: calibration group of the shortest clouds, whose 90 % interval spans 45 points; the others span 16-34).
REVIEW_WIDTH = 0.4


def estimates(data: Path, method: CompletionMethod, cache: Path) -> pd.DataFrame:
    """Completion's estimate of every validation segment at every noise level (cached in ``cache``)."""
    if cache.is_file():
        return pd.read_csv(cache)
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
                                 "rims": est.signals.get("rims", 0), "length_mm": est.signals.get("length_mm")})
        print(f"{name}: {len(rows)} estimates", flush=True)
    out = pd.DataFrame(rows)
    out = out[np.isfinite(out["estimate"])]             # an empty completed surface gives no estimate
    out.to_csv(cache, index=False)
    return out


def signals_of(row) -> dict:
    return {"rims": int(row["rims"]), "length_mm": float(row["length_mm"])}


def signals(df: pd.DataFrame) -> list[dict]:
    return [signals_of(r) for _, r in df.iterrows()]


def held_out(df: pd.DataFrame, scheme: str, level: float) -> pd.DataFrame:
    """Coverage and width per group of a scheme fitted on one half of the colons and measured on the other."""
    half = df["colon_id"] % 2 == 0
    rows = []
    for fit_on, test_on in ((half, ~half), (~half, half)):
        a, b = df[fit_on], df[test_on]
        cal = intervals.fit(a["true"], a["estimate"], signals(a), scheme, REVIEW_WIDTH, level)
        for _, r in b.iterrows():
            lo, hi = cal.interval(r["estimate"], signals_of(r))
            rows.append({"group": intervals.group_key(r["estimate"], signals_of(r), scheme),
                         "inside": lo - 1e-12 <= r["true"] <= hi + 1e-12, "width": hi - lo})
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data/calibration")
    ap.add_argument("--model", default=None, help="model (default: the shipped one)")
    ap.add_argument("--level", type=float, default=intervals.LEVEL)
    ap.add_argument("--workers", type=int, default=2, help="processes generating the data")
    args = ap.parse_args()
    data = Path(args.data)
    generate(MANIFEST, data, workers=args.workers, splits=["validation"], progress=False)
    method = CompletionMethod(args.model)
    method.intervals = None
    path = model_path(args.model)
    cache = data / f"completion-estimates-{sha256_file(path)[:12]}-{steps_version()}.csv"   # per model and steps
    df = estimates(data, method, cache)
    print(f"{len(df)} estimates of {df[['shard', 'index']].drop_duplicates().shape[0]} segments; MAE "
          f"{100 * (df['estimate'] - df['true']).abs().mean():.2f} points")
    best, best_width = "marginal", np.inf
    summary = {}
    for scheme in SCHEMES:
        h = held_out(df, scheme, args.level)
        per = h.groupby("group").agg(n=("inside", "size"), covered=("inside", "mean"), width=("width", "mean"))
        big = per[per["n"] >= intervals.MIN_GROUP]
        ok = bool((abs(big["covered"] - args.level) <= 0.04).all())
        summary[scheme] = {"covered": float(h["inside"].mean()), "width": float(h["width"].mean()), "ok": ok}
        print(f"\n{scheme}: held-out coverage {100 * h['inside'].mean():.1f} %, mean width "
              f"{100 * h['width'].mean():.1f} points, every group within 4 points of {args.level:.0%}: {ok}")
        print(per.assign(covered=lambda d: (100 * d["covered"]).round(1), width=lambda d: (100 * d["width"]).round(1))
              .to_string())
        if ok and h["width"].mean() < best_width:
            best, best_width = scheme, h["width"].mean()
    source = {"model": path.name, "model_sha256": sha256_file(path), "steps": steps_version(),
              "manifest": MANIFEST.name,
              "manifest_sha256": sha256_file(MANIFEST), "noise_mm": list(NOISE_MM),
              "segments": int(df[["shard", "index"]].drop_duplicates().shape[0]), "estimates": len(df),
              "held_out": summary}
    cal = intervals.fit(df["true"], df["estimate"], signals(df), best, REVIEW_WIDTH, args.level, source)
    # segments whose length is known (colonbench estimate --length-mm, the map's segments): the estimate scaled where
    # the line stops short, as intervals.known_length does, and their own interval
    share = df["length_mm"] / df["segment_mm"]
    known = np.where(share < intervals.SHORT_SHARE, df["estimate"] * share, df["estimate"])
    intervals.fit_known(cal, df["true"], known)
    print(f"\nknown length: MAE {100 * np.abs(known - df['true']).mean():.2f} points (unknown "
          f"{100 * (df['estimate'] - df['true']).abs().mean():.2f}); interval width "
          f"{100 * (cal.known['high'] - cal.known['low']):.1f} points")
    digest = hashlib.sha256(json.dumps(cal.to_json(), sort_keys=True).encode()).hexdigest()[:8]
    cal.source["id"] = f"{best}-{digest}"
    out = intervals.path_for(path)
    out.write_text(json.dumps(cal.to_json(), indent=1) + "\n")
    print(f"\nchosen: {best}; wrote {out} (id {cal.source['id']})")


if __name__ == "__main__":
    main()
