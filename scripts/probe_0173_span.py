"""Decision record 0173's one-off probe (removed after): with a length given, scale the coverage by the share of the
segment the cloud spans, counting the cloud the planes clip away. For a sample of cached estimates (at 0 mm), run
the method again, take the share of the cloud's points inside its planes, and compare the known-length MAE of
``coverage * span / length`` (shipped, where under 0.9) with ``coverage * span / length / inside share`` (where
that is under 0.9). Run from the repository root after scripts/calibrate_intervals.py has cached its estimates:
``python scripts/probe_0173_span.py DATASET N``."""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

import colonbench.completion.method as M
from colonbench.completion.method import CompletionMethod
from colonbench.completion.planes import inside_planes
from colonbench.shards.reader import Shard

cap = {}
_fh = M.from_heatmap


def fh(heatmap, grid, points, *a, **k):
    est = _fh(heatmap, grid, points, *a, **k)
    cap["grid"], cap["points"] = grid, np.asarray(points, float)
    return est


M.from_heatmap = fh
_complete = M.complete


def complete(*a, **k):
    comp = _complete(*a, **k)
    cap["planes"] = comp.planes
    return comp


M.complete = complete
ds, n = sys.argv[1], int(sys.argv[2])
d = pd.read_csv(f"data/{ds}/completion-estimates-6d813b3c4351-steps=10-signals4.csv")
d = d[d.noise_mm == 0]
d = d.sample(min(n, len(d)), random_state=1)
m = CompletionMethod(None)
m.intervals = None
rows = []
for _, r in d.iterrows():
    with Shard(Path("data") / ds / r.shard) as s:
        g = s.geometry(int(r["index"]))
    est = m.estimate(g["partial_points"])
    inside = inside_planes(cap["grid"].to_voxel(cap["points"]), cap["planes"]).mean()
    rows.append(dict(colon=r.colon_id, end=r.hole_model.endswith("+end"), L=r.segment_mm, true=r.true,
                     est=est.coverage, span=est.signals["span_mm"], inside=inside, cached=r.estimate))
o = pd.DataFrame(rows)
o.to_csv(f"/tmp/probe0173-{ds}.csv", index=False)
f0 = o.span / o.L
f1 = f0 / o.inside.clip(lower=1e-3)
e0 = np.where(f0 < 0.9, o.est * f0, o.est)
e1 = np.where(f1 < 0.9, o.est * f1, o.est)
o["ae0"], o["ae1"], o["aen"] = 100 * abs(e0 - o.true), 100 * abs(e1 - o.true), 100 * abs(o.est - o.true)
print("same estimate as cached:", np.allclose(o.est, o.cached, atol=1e-6))
print(o.groupby(["colon", "end"])[["aen", "ae0", "ae1", "inside"]].agg(["mean"]).round(2).to_string())
print(o[["aen", "ae0", "ae1"]].mean().round(2).to_string())
