"""Decision record 0166's probe (a one-off): which band of the shipped scale paper-v1's segments fall in, and how wide
their intervals are against their errors (every fourth test segment of the first shards, noiseless, 120 in all).

    python scripts/probe_0166_paper_bands.py
"""
import numpy as np, pandas as pd, sys, json
from pathlib import Path
from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion.method import CompletionMethod
from colonbench.completion import intervals
from colonbench.shards.reader import Shard
data = Path(sys.argv[1]) if len(sys.argv) > 1 else Path.home() / ".cache/colonbench/suites/paper-v1"
m = CompletionMethod()
cal = m.intervals
g = cal.groups["all"]
_, picks = select(data, "test")
rows = []
k = 0
for name, idx in picks:
    with Shard(data / name) as sh:
        for i in idx[::4]:
            geo = sh.geometry(i)
            est = m.estimate(noisy(geo["partial_points"], 0.0, 0, name, i))
            ls = intervals._log_scale_of(g, est.coverage, est.signals)
            band = int(np.searchsorted(g["band_edges"], ls))
            f = dict(zip(g["features"], intervals.features(est.coverage, est.signals, g["features"])))
            rows.append({"true": geo["coverage"], "est": est.coverage, "log_s": ls, "band": band,
                         "width": est.coverage_interval[1] - est.coverage_interval[0], "hole": geo["hole_model"], **f})
            k += 1
    if k >= 120: break
d = pd.DataFrame(rows)
print(d.groupby("band").agg(n=("est","size"), width=("width","mean"), err=("est", lambda s: 0)).to_string())
d["abs"] = (d.true - d.est).abs()
print(d[["abs","width","log_s"]].describe().round(3).to_string())
print(d.drop(columns=["true","est","hole"]).mean().round(3).to_string())
