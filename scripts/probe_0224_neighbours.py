"""Decision record 0224's measurement (a one-off probe, removed after it): signals of a map's segment from its
neighbours and its map (`neighbour_gap`, `area_rate`, `point_rate`), screened for the far-off segments of the real
validation colons' maps, and the map's review with them. Run from the repository root (the maps are made where
missing, as scripts/map_intervals.py makes them, into data/):

    python scripts/probe_0224_neighbours.py
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import mannwhitneyu

sys.path.insert(0, str(Path(__file__).resolve().parent))
import map_intervals as mi                                                 # noqa: E402
from colonbench.completion import calfile                                 # noqa: E402
from colonbench.completion.method import model_path                       # noqa: E402

SETS = {"colon-val": "M_proc", "colon-val-real": "M_real", "colon-val-real-more": "M_real"}
NAMES = ("neighbour_gap", "area_rate", "point_rate")
MAP = ["shard", "index", "track", "noise_mm"]


def segments():
    cal = calfile.load(model_path(None), steps=None)
    parts = [mi.map_segments(Path("data"), name, None, cal.source.get("id", "none"), 2).assign(set=s, data=name)
             for name, s in SETS.items()]
    seg = pd.concat(parts, ignore_index=True)
    seg = seg[(seg["set"] == "M_real") | seg["colon"].str.startswith("colon-")].reset_index(drop=True)
    seg["width"] = seg["interval_high"] - seg["interval_low"]
    seg["far"] = (seg["estimate"] - seg["true"]).abs() > mi.BIG
    return seg, float(cal.map["review_width"])


def signals(seg):
    out = seg.copy()
    for n in NAMES:
        out[n] = 0.0
    for _, g in seg.groupby(["data"] + MAP):
        length = (g["end_mm"] - g["start_mm"]).clip(lower=1e-6)
        for n, col in (("area_rate", "area_mm2"), ("point_rate", "points")):
            r = g[col] / length
            out.loc[g.index, n] = np.abs(np.log(r / r.median()))
        for _, p in g.groupby("piece"):
            p = p.sort_values("segment")
            c, s = p["estimate"].to_numpy(), p["segment"].to_numpy()
            for k, i in enumerate(p.index):
                nb = [c[m] for m in (k - 1, k + 1) if 0 <= m < len(p) and abs(s[m] - s[k]) == 1]
                out.loc[i, "neighbour_gap"] = abs(c[k] - np.mean(nb)) if nb else 0.0
    return out


def auc(y, x):
    if y.sum() == 0 or (~y).sum() == 0:
        return float("nan")
    a = mannwhitneyu(x[y], x[~y]).statistic / (y.sum() * (~y).sum())
    return round(float(max(a, 1 - a)), 3)


def flagged(real, w, g=None, t=np.inf):
    f = real["width"].to_numpy() > w
    return f | (real[g].to_numpy() > t) if g else f


def catches(real, f, need=mi.REVIEW_RECALL):
    far = real["far"].to_numpy()
    return all(f[(real["colon"] == c).to_numpy() & far].mean() >= need for c in sorted(real["colon"].unique()))


def score(part, f):
    far = part["far"].to_numpy()
    out = {"n": len(part), "far": int(far.sum()), "flagged": int(f.sum()), "caught": int((f & far).sum())}
    out["right"] = round(100 * out["caught"] / max(out["flagged"], 1), 1)
    return out


def report(seg, name, f):
    print(f"  {name}:")
    for cell, part in seg.assign(cell=np.where(seg["set"] == "M_real", seg["colon"], "procedural")).groupby(
            ["cell", "track"]):
        print(f"    {cell[0]}, {cell[1]}: {score(part, f[part.index])}")
    real = seg["set"] == "M_real"
    for c in sorted(seg.loc[real, "colon"].unique()):
        m = (seg["colon"] == c).to_numpy()
        print(f"    {c}, both tracks: {score(seg[m], f[m])}")
    print(f"    real, pooled: {score(seg[real], f[real.to_numpy()])}")


def width_rule(real):
    """0223's rule: the largest width catching REVIEW_RECALL of each real colon's far-off segments."""
    for w in np.sort(np.unique(real["width"].to_numpy()))[::-1]:
        if catches(real, flagged(real, w - 1e-12)):
            return float(w - 1e-12)
    return None


def pair_rule(real, g):
    best = None
    ws = np.concatenate([np.sort(np.unique(real["width"].to_numpy())) - 1e-12, [np.inf]])
    ts = np.concatenate([np.sort(np.unique(real[g].to_numpy())) - 1e-12, [np.inf]])
    W, G, far = real["width"].to_numpy(), real[g].to_numpy(), real["far"].to_numpy()
    colons = [(real["colon"] == c).to_numpy() & far for c in sorted(real["colon"].unique())]
    for w in ws[::-1]:
        fw = W > w
        for t in ts[::-1]:
            f = fw | (G > t)
            if all(f[c].mean() >= mi.REVIEW_RECALL for c in colons):
                key = (int(f.sum()), -w, -t)
                if best is None or key < best[0]:
                    best = (key, float(w), float(t))
                break                                   # a smaller t only flags more at this w
    return best


def main():
    seg, shipped = segments()
    seg = signals(seg).reset_index(drop=True)
    real = seg[seg["set"] == "M_real"].reset_index(drop=True)
    print(f"{len(seg)} map segments; real: {len(real)} of {real.groupby(['data'] + MAP[:2]).ngroups} maps, "
          f"{int(real['far'].sum())} far off; procedural: {int((seg['set'] == 'M_proc').sum())}")
    print("\nReported: the map's intervals (truth inside, mean width, points) per colon and track")
    seg["inside"] = (seg["true"] >= seg["interval_low"]) & (seg["true"] <= seg["interval_high"])
    cell = np.where(seg["set"] == "M_real", seg["colon"], "procedural")
    print(seg.groupby([cell, "track"]).agg(n=("inside", "size"), inside=("inside", "mean"), width=("width", "mean"))
          .assign(inside=lambda d: (100 * d["inside"]).round(1), width=lambda d: (100 * d["width"]).round(1))
          .to_string())
    print(f"\nReported: the shipped width-only review ({100 * shipped:.1f} points)")
    report(seg, "shipped", seg["width"].to_numpy() > shipped)
    print("\nScreen: AUC for far-off per track (real colons pooled; per colon)")
    entered = []
    for n in NAMES:
        per_track = {t: auc(p["far"].to_numpy(), p[n].to_numpy()) for t, p in real.groupby("track")}
        per_colon = {(c, t): auc(p["far"].to_numpy(), p[n].to_numpy()) for (c, t), p in real.groupby(["colon", "track"])}
        ok = all(v >= 0.75 for v in per_track.values())
        print(f"  {n}: {per_track}; per colon {per_colon}; median far / not "
              f"{real.loc[real['far'], n].median():.3f} / {real.loc[~real['far'], n].median():.3f}; enters: {ok}")
        if ok:
            entered.append(n)
    if not entered:
        print("\nnone enters")
        return
    w0 = width_rule(real)
    print(f"\nReference, 0223's rule on these maps: width above {100 * w0:.2f} points")
    ref = seg["width"].to_numpy() > w0
    report(seg, "reference", ref)
    for g in entered:
        key, w, t = pair_rule(real, g)
        print(f"\nCandidate width above {100 * w:.2f} points or {g} above {t:.4f}")
        report(seg, g, (seg["width"].to_numpy() > w) | (seg[g].to_numpy() > t))


if __name__ == "__main__":
    main()
