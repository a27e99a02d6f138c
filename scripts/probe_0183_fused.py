"""Decision record 0183's measurement (a one-off probe, removed after it): three cloud signals of a fused
reconstruction, screened for the ``video`` estimates, then the known extent ``K3`` with the entered one held out.
Run from the repository root, with the calibration's datasets in data/ (``python scripts/calibrate_intervals.py
--remake`` makes them):

    python scripts/probe_0183_fused.py
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree
from scipy.stats import mannwhitneyu

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci                                          # noqa: E402
from colonbench.benchmark.evaluate import noisy                           # noqa: E402
from colonbench.completion import caltable, choice, intervals, known_extent   # noqa: E402
from colonbench.completion.method import method_cloud, model_path, steps_version   # noqa: E402
from colonbench.completion.surface import DENSITY_POINTS, cloud_density, wall_thickness   # noqa: E402
from colonbench.grid import even_subsample                                 # noqa: E402
from colonbench.shards.reader import Shard                                 # noqa: E402

NAMES = ("thickness_mm", "spacing_cv", "density")
CACHE = Path("runs/probe-0183-signals.csv")


def cloud_signals(points):
    pts = method_cloud(points)
    tree = cKDTree(pts)
    sub = even_subsample(pts, DENSITY_POINTS)
    k = min(16, len(pts))
    near = pts[tree.query(sub, k=k)[1]]
    centred = near - near.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", centred, centred) / k
    thick = np.sqrt(np.maximum(np.linalg.eigvalsh(cov)[:, 0], 0.0))
    nn = tree.query(sub, k=2)[0][:, 1]
    return {"thickness_mm": float(np.median(thick)), "spacing_cv": float(nn.std() / max(nn.mean(), 1e-9)),
            "density": cloud_density(pts, tree=tree)}


def signals_table(df):
    if CACHE.is_file():
        return pd.read_csv(CACHE)
    rows = []
    for (manifest, shard), g in df.groupby(["manifest", "shard"]):
        with Shard(Path("data") / manifest / shard) as s:
            for i in sorted(g["index"].unique()):
                geo = s.geometry(int(i))
                for sigma in sorted(g.loc[g["index"] == i, "noise_mm"].unique()):
                    pts = noisy(geo["partial_points"], float(sigma), 0, shard, int(i))
                    rows.append({"manifest": manifest, "shard": shard, "index": int(i), "noise_mm": float(sigma),
                                 **cloud_signals(pts)})
        print(manifest, shard, len(rows), flush=True)
    out = pd.DataFrame(rows)
    CACHE.parent.mkdir(exist_ok=True)
    out.to_csv(CACHE, index=False)
    return out


def main():
    path = model_path(None)
    df = ci.with_units(ci.with_sets(caltable.read(caltable.path_for(path, steps_version()), ci.SIGNALS,
                                                  ci.table_source(path))))
    cal = df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)
    sig = signals_table(cal)
    cal = cal.merge(sig, on=["manifest", "shard", "index", "noise_mm"], how="left", validate="one_to_one")
    assert cal[list(NAMES)].notna().all().all()
    video = (cal["hole_model"] == "video").to_numpy()
    print("\nscreen: AUC for video (one minus it where below 0.5), by noise level")
    lower = {}
    for n in NAMES:
        aucs = []
        for sigma, g in cal.groupby("noise_mm"):
            y, x = (g["hole_model"] == "video").to_numpy(), g[n].to_numpy()
            a = mannwhitneyu(x[y], x[~y]).statistic / (y.sum() * (~y).sum())
            aucs.append(max(a, 1 - a))
        lower[n] = min(aucs)
        print(f"  {n}: {[round(a, 3) for a in aucs]}; medians video / other "
              f"{cal.loc[video, n].median():.3f} / {cal.loc[~video, n].median():.3f}")
    entered = [n for n in NAMES if lower[n] >= 0.80]
    if not entered:
        print("none enters")
        return
    best = max(lower[n] for n in entered)
    signal = next(n for n in NAMES if n in entered and lower[n] >= best - 0.02)
    print(f"entered: {signal}")
    # the signal as a feature of the known extent's scale: features() reads it as a signal of that name
    value = intervals.features

    def features(coverage, signals, names):
        if "fused" not in names:
            return value(coverage, signals, names)
        base = [n for n in names if n != "fused"]
        out = value(coverage, signals, base)
        return np.insert(out, list(names).index("fused"), float(signals.get(signal, 0.0)))
    intervals.features = features
    known_extent.features = features
    ci.SIGNALS = tuple(ci.SIGNALS) + (signal,)
    known_extent.KNOWN_EXTRA["K4"] = known_extent.KNOWN_EXTRA["K3"] + ("fused",)
    for k in ("K3", "K4"):
        h = ci.by_colon(cal, ci.KEEP.split("+", 1)[1], intervals.LEVEL, known=True,
                        extra=known_extent.KNOWN_EXTRA[k], short=True)
        s = ci.summarise({k: h}, intervals.LEVEL, show=False)[k]
        v = h[h["hole_model"] == "video"]
        print(f"\n[{k}] holds {choice.holds(s)}; shortfall {s['shortfall']}; real width {s['real_width']}")
        print("  " + "; ".join(f"{c} {x['inside']} ({x['width']})" for c, x in s["cells"].items()))
        print(f"  video inside by noise {(100 * v.groupby('noise_mm')['inside'].mean()).round(1).to_dict()}; "
              f"by set {(100 * v.groupby(['set', 'noise_mm'])['inside'].mean()).round(1).to_dict()}")
        print(f"  by hole model {(100 * h.groupby(['hole_model'])['inside'].mean()).round(1).to_dict()}", flush=True)


if __name__ == "__main__":
    main()
