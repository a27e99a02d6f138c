"""Decision record 0186's measurement (a one-off probe, removed after it): completion's disagreement with the
baselines, screened for the review's far-off estimates where both ends were seen. Run from the repository root with
the calibration's datasets in data/:

    python scripts/probe_0186_second.py make PART PARTS     (the baselines' estimates; two processes: PART 0 and 1)
    python scripts/probe_0186_second.py screen
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from scipy.stats import mannwhitneyu

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci                                          # noqa: E402
from colonbench.benchmark.evaluate import noisy                           # noqa: E402
from colonbench.benchmark.registry import load_method                     # noqa: E402
from colonbench.completion import caltable                                # noqa: E402
from colonbench.completion.method import model_path, steps_version       # noqa: E402
from colonbench.shards.reader import Shard                                 # noqa: E402

BASELINES = ("poisson", "unwrap", "thresholding")
CACHE = Path("runs/probe-0186")


def rows():
    path = model_path(None)
    df = ci.with_units(ci.with_sets(caltable.read(caltable.path_for(path, steps_version()), ci.SIGNALS,
                                                  ci.table_source(path))))
    return df[(df["set"] == "V_real") & ~df["hole_model"].str.endswith("+end")].reset_index(drop=True)


def coverage(est):
    return float(est["coverage"] if isinstance(est, dict) else est.coverage)


def make(part, parts):
    torch.set_num_threads(1)
    df = rows()
    methods = {m: load_method(m) for m in BASELINES}
    out = []
    for shard in sorted(df["shard"].unique())[part::parts]:
        g = df[df["shard"] == shard]
        with Shard(Path("data") / "validation-real" / shard) as s:
            for _, r in g.iterrows():
                pts = noisy(s.geometry(int(r["index"]))["partial_points"], float(r["noise_mm"]), 0, shard,
                            int(r["index"]))
                rec = {"shard": shard, "index": int(r["index"]), "noise_mm": float(r["noise_mm"])}
                for m, method in methods.items():
                    try:
                        rec[m] = coverage(method.estimate(pts))
                    except Exception as exc:                  # a baseline that fails has no opinion
                        print(f"{m} {shard} {r['index']}: {exc}", flush=True)
                        rec[m] = np.nan
                out.append(rec)
        print(shard, len(out), flush=True)
    CACHE.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(out).to_csv(CACHE / f"{part}-of-{parts}.csv", index=False)


def screen():
    df = rows().merge(pd.concat([pd.read_csv(p) for p in sorted(CACHE.glob("*.csv"))]),
                      on=["shard", "index", "noise_mm"], how="inner", validate="one_to_one")
    far = ((df["true"] - df["estimate"]).abs() > ci.BIG).to_numpy()
    print(f"{len(df)} estimates without an erased end on the real validation colons, {far.sum()} far off")
    for m in BASELINES:
        gap = (df["estimate"] - df[m]).abs().fillna(1.0).to_numpy()
        aucs = {}
        for colon in sorted(df["cell"].unique()):
            c = (df["cell"] == colon).to_numpy()
            y, x = far[c], gap[c]
            a = mannwhitneyu(x[y], x[~y]).statistic / (y.sum() * (~y).sum())
            aucs[colon] = round(float(max(a, 1 - a)), 3)
        print(f"  |completion - {m}|: AUC {aucs}; median far / not {100 * np.median(gap[far]):.1f} / "
              f"{100 * np.median(gap[~far]):.1f} points; {m} MAE {100 * (df[m] - df['true']).abs().mean():.1f}, "
              f"failed {int(df[m].isna().sum())}")


if __name__ == "__main__":
    if sys.argv[1] == "make":
        make(int(sys.argv[2]), int(sys.argv[3]))
    else:
        screen()
