"""Decision record 0173's Context look (one-off, removed after; reconstructed from the session's commands, as run
before the rule): each end of the method's span, run on straight to its plane (reach_planes), found on the truth's
line by its nearest point; the truth's arc between those points against the span. Run from the repository root
after scripts/calibrate_intervals.py has cached its estimates: ``python scripts/probe_0173_context.py
validation-real 900020 50`` and ``... calibration all 50`` (the record's figures; noiseless, both ends seen)."""
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

import colonbench.completion.method as M
from colonbench.completion.method import CompletionMethod
from colonbench.shards.reader import Shard

cap = {}
_fh, _rp = M.from_heatmap, M.reach_planes
def fh(heatmap, grid, *a, **k):
    cap["grid"] = grid
    return _fh(heatmap, grid, *a, **k)
def rp(*a, **k):
    out = _rp(*a, **k); cap["ext"] = out; return out
M.from_heatmap, M.reach_planes = fh, rp

def arc(c):
    return np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))]

ds, colon, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
d = pd.read_csv(f"data/{ds}/completion-estimates-6d813b3c4351-steps=10-signals4.csv")
d = d[(d.noise_mm == 0) & ~d.hole_model.str.endswith("+end")]
if colon != "all":
    d = d[d.colon_id == int(colon)]
d = d.assign(share=d.span_mm / d.segment_mm).sample(n, random_state=0)
m = CompletionMethod(None); m.intervals = None
rows = []
for _, r in d.iterrows():
    with Shard(Path("data") / ds / r.shard) as s:
        g = s.geometry(int(r["index"]))
    est = m.estimate(g["partial_points"])
    tc = np.asarray(g["centerline"], float); ta = arc(tc)
    ext = cap["grid"].to_mm(np.asarray(cap["ext"], float))
    tree = cKDTree(tc)
    _, i0 = tree.query(ext[0]); _, i1 = tree.query(ext[-1])
    lo, hi = sorted((ta[i0], ta[i1]))
    _, ic = tree.query(g["partial_points"])
    rows.append(dict(i=int(r["index"]), seg=r.segment_mm, truth=ta[-1], chord=np.linalg.norm(tc[-1] - tc[0]),
                     span=est.signals["span_mm"], line=est.signals["length_mm"], truth_between=hi - lo,
                     in_start=lo, in_end=ta[-1] - hi, cloud_lo=ta[ic.min()], cloud_hi=ta[-1] - ta[ic.max()],
                     rims=est.signals["rims"], true=r.true, est=est.coverage))
out = pd.DataFrame(rows)
out["r_line"] = out.span / out.truth_between
out["share"] = out.span / out.seg
ok = (out.in_start < 5) & (out.in_end < 5)
print("planes within 5 mm of both ends:", ok.mean().round(2), "of", len(out))
print(out[ok][["truth", "span", "truth_between", "in_start", "in_end", "r_line", "share"]].describe().round(2))
print("all: share<0.9", (out.share < 0.9).mean().round(2), " far-inside planes:", (~ok).mean().round(2))
print("far-inside planes: how far inside (mm):", np.maximum(out.in_start, out.in_end)[~ok].round(1).tolist())
